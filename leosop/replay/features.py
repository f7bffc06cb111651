"""A Doppler track as the identification sees it: times from the search epoch, reference values, samples."""

from dataclasses import dataclass

import numpy as np

__all__ = ["TrackView", "prepare_track", "FEATURES", "MIN_BLOCKS"]

#: Reference times per track: first, middle, last. Rows: offset at the
#: middle, slope, curvature of the residual at those times.
FEATURES = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 1.0], [-0.5, 1.0, -0.5]])
#: Half-width of the window that smooths a track's value at a reference time [s].
_LOCAL_S = 0.25
#: The fewest blocks a track is identified on (fewer: ``too_short``).
MIN_BLOCKS = 3
#: Samples per track in the least squares and the identification.
_MAX_SAMPLES = 120


@dataclass
class TrackView:
    """One track as the search sees it (times in s from the search epoch)."""

    t_s: np.ndarray
    doppler_hz: np.ndarray
    sigma_hz: np.ndarray
    t_ref_s: np.ndarray  # (3,)
    f_ref_hz: np.ndarray  # (3,)
    feat_sigma: np.ndarray  # (3,) offset, slope, curvature
    sample: np.ndarray  # indices used in the least squares

    @property
    def t_mid_s(self):
        return self.t_ref_s[1]


def _local_value(t, f, sigma, t0, m):
    """Weighted straight line through the ``m`` samples nearest ``t0`` (within ``_LOCAL_S``): value, sigma at ``t0``.

    The window is short so that the curve's own curvature (up to ~50 Hz/s^2) biases the value by
    less than ~1 Hz: snapshot tracks (one capture a second) use the nearest sample alone.
    """
    near = np.argsort(np.abs(t - t0))[:m]
    near = near[np.abs(t[near] - t0) <= _LOCAL_S] if np.abs(t[near[0]] - t0) <= _LOCAL_S else near[:1]
    m = len(near)
    if m == 1 or np.ptp(t[near]) == 0:
        w = 1.0 / sigma[near] ** 2
        return np.sum(w * f[near]) / np.sum(w), 1.0 / np.sqrt(np.sum(w))
    a = np.stack([np.ones(m), t[near] - t0], axis=1) / sigma[near, None]
    cov = np.linalg.inv(a.T @ a)
    coef = cov @ (a.T @ (f[near] / sigma[near]))
    return coef[0], np.sqrt(cov[0, 0])


def prepare_track(track, t0_utc):
    """The track's finite samples in time order, its reference values and feature sigmas; None under
    :data:`MIN_BLOCKS` samples.

    Parameters
    ----------
    track : Track
        ``time_utc``, ``doppler_hz`` and ``sigma_hz`` (n,) are used.
    t0_utc : numpy.datetime64
        The search epoch.

    Returns
    -------
    TrackView or None
    """
    t = (np.asarray(track.time_utc, "datetime64[ns]") - t0_utc) / np.timedelta64(1, "s")
    f = np.asarray(track.doppler_hz, float)
    sigma = np.asarray(track.sigma_hz, float)
    good = np.isfinite(t) & np.isfinite(f)
    if good.sum() < MIN_BLOCKS:
        return None
    t, f, sigma = t[good], f[good], sigma[good]
    fill = np.nanmedian(np.where(sigma > 0, sigma, np.nan)) if np.any(sigma > 0) else 1.0
    sigma = np.where(np.isfinite(sigma) & (sigma > 0), sigma, fill if np.isfinite(fill) else 1.0)
    order = np.argsort(t)
    t, f, sigma = t[order], f[order], sigma[order]
    t_ref = np.array([t[0], t[len(t) // 2], t[-1]])
    m = int(np.clip(len(t) // 3, 1, 5))
    vals = np.array([_local_value(t, f, sigma, tr, m) for tr in t_ref])
    span = max(t_ref[2] - t_ref[0], 1e-3)
    feat = FEATURES / np.array([1.0, span, 1.0])[:, None]
    feat_sigma = np.sqrt((feat**2) @ (vals[:, 1] ** 2))
    sample = np.unique(np.linspace(0, len(t) - 1, min(len(t), _MAX_SAMPLES)).round().astype(int))
    return TrackView(t, f, sigma, t_ref, vals[:, 0], feat_sigma, sample)

