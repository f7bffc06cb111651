"""Start positions of the Doppler solvers: on the ground below the satellites, across their track, or on a grid."""

import numpy as np

from ..frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef

__all__ = ["subpoint_centroid_ecef_m", "track_starts", "grid_starts", "R_GROUND_M"]

#: Earth radius used to place a start on the ground [m].
R_GROUND_M = 6_371_000.0

def subpoint_centroid_ecef_m(pos_sv_ecef_m, mask=None):
    """Ground point below the mean direction of the satellites, a start for the solvers.

    Parameters
    ----------
    pos_sv_ecef_m : array_like, (..., n_sv, 3)
    mask : array_like of bool, (..., n_sv), optional

    Returns
    -------
    pos_ecef_m : ndarray, (..., 3)
        On the ellipsoid (height 0); NaN where no satellite is unmasked.
    """
    r = np.asarray(pos_sv_ecef_m, dtype=float)
    m = np.isfinite(r).all(-1) if mask is None else np.asarray(mask, bool) & np.isfinite(r).all(-1)
    u = np.where(m[..., None], r / np.linalg.norm(np.where(m[..., None], r, 1.0), axis=-1, keepdims=True), 0.0)
    with np.errstate(invalid="ignore"):
        mean = u.sum(-2) / np.linalg.norm(u.sum(-2), axis=-1, keepdims=True)
    lat, lon, _ = ecef_to_geodetic(np.nan_to_num(mean, nan=1.0) * R_GROUND_M)
    pos = geodetic_to_ecef(lat, lon, 0.0)
    return np.where(m.any(-1)[..., None], pos, np.nan)

def track_starts(pos_sv_ecef_m, vel_sv_ecef_mps, pos0_ecef_m, offsets_m):
    """Starts of a static solve across the mean ground track.

    Without ``pos0_ecef_m``: ground points at ``offsets_m`` across the track
    from the sub-point centroid; with it: ``pos0_ecef_m`` and its reflection.
    """
    centre = subpoint_centroid_ecef_m(pos_sv_ecef_m)
    lat, lon, _ = ecef_to_geodetic(centre)
    C = C_e_n(lat, lon)
    v_enu = np.mean(vel_sv_ecef_mps, axis=0) @ C
    track = np.array([v_enu[0], v_enu[1], 0.0])
    across = C @ np.cross([0.0, 0.0, 1.0], track / np.linalg.norm(track))
    if pos0_ecef_m is not None:
        p0 = np.asarray(pos0_ecef_m, dtype=float).reshape(3)
        return np.array([p0, p0 - 2.0 * ((p0 - centre) @ across) * across])
    la, lo, _ = ecef_to_geodetic(centre + np.multiply.outer(offsets_m, across))
    return geodetic_to_ecef(la, lo, 0.0)

def grid_starts(centre_ecef_m, offset_m):
    """Ground points at ``centre`` and on a 5 x 5 east/north grid of half-width ``offset_m`` around it, (25, 3)."""
    lat, lon, _ = ecef_to_geodetic(centre_ecef_m)
    e, n = np.meshgrid(offset_m * np.array([0.0, -1.0, -1 / 3, 1 / 3, 1.0]),
                       offset_m * np.array([0.0, -1.0, -1 / 3, 1 / 3, 1.0]))
    enu = np.stack([e.ravel(), n.ravel(), np.zeros(e.size)], -1)
    la, lo, _ = ecef_to_geodetic(centre_ecef_m + enu @ C_e_n(lat, lon).T)
    return geodetic_to_ecef(la, lo, 0.0)
