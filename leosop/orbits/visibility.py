"""Which satellites a receiver sees, epoch by epoch, and their passes.

:func:`compute_visibility` returns every visible (satellite, epoch) pair with
its geometry. For a uniform time grid it screens first, coarse to fine
(:data:`SCREEN_STEPS_S`): every satellite is propagated every 10 min; the
elevation test value cannot change faster than a bound set by the
satellite's and receiver's speeds (:func:`climb_epochs`,
:func:`speed_bound_mps`), so between two samples only a window of epochs can
hold a visible one; the windows are sampled at 60 s, then 10 s, and only the
epochs inside the last windows are propagated at the grid's step (about 1.2x
the visible pairs for Starlink at a 40 deg mask). The result is the same set
as propagating every satellite at every epoch (``screen=False``), at ~1/80
of the cost for a day at 1 s. The screened run goes through the window in
blocks, so its working memory is set by the block, not by the window.
"""

from dataclasses import dataclass, replace

import numpy as np

from ..frames import C_e_n, ecef_to_geodetic
from ..geometry.dop import cofactor, range_dops
from ..geometry.doppler import clock_group_rows, doppler_jacobian
from ..progress import progress
from ..timebase import jd_ut1, jd_utc
from .visibility_screen import (
    CHUNK_POINTS,
    SCREEN_STEPS_S,
    evaluate_pairs,
    propagated_geometry,
    screen_candidates,
    speed_bound_mps,
)

__all__ = ["Visibility", "Pass", "compute_visibility"]


@dataclass(frozen=True)
class Pass:
    """One pass of a satellite above the mask.

    ``rise``/``set`` are the first and last visible epochs of the grid;
    ``truncated`` says the pass was already up at the start or still up at
    the end of the window.
    """

    sat_id: str
    rise_utc: np.datetime64
    culmination_utc: np.datetime64
    set_utc: np.datetime64
    max_elev_deg: float
    truncated: bool


@dataclass(frozen=True)
class Visibility:
    """Visible (satellite, epoch) pairs, sorted by epoch then satellite.

    Attributes
    ----------
    times_utc : ndarray of datetime64[ns], (n_epochs,)
    sat_ids : ndarray of str, (n_sats,)
        Catalogue numbers of the constellation searched.
    epoch_index, sat_index : ndarray of int, (m,)
    az_rad, elev_rad, range_m : ndarray, (m,)
    pos_sv_ecef_m, vel_sv_ecef_mps : ndarray, (m, 3)
    pos_rx_ecef_m, vel_rx_ecef_mps : ndarray, (n_epochs, 3)
    """

    times_utc: np.ndarray
    sat_ids: np.ndarray
    epoch_index: np.ndarray
    sat_index: np.ndarray
    az_rad: np.ndarray
    elev_rad: np.ndarray
    range_m: np.ndarray
    pos_sv_ecef_m: np.ndarray
    vel_sv_ecef_mps: np.ndarray
    pos_rx_ecef_m: np.ndarray
    vel_rx_ecef_mps: np.ndarray

    @property
    def n_visible(self):
        """Number of visible satellites per epoch, (n_epochs,)."""
        return np.bincount(self.epoch_index, minlength=len(self.times_utc))

    def visible_ids(self):
        """Catalogue numbers visible at each epoch: list of lists of str."""
        bounds = np.searchsorted(self.epoch_index, np.arange(len(self.times_utc) + 1))
        # One str per satellite, shared by every epoch's list (not one per visible pair).
        ids = self.sat_ids.astype(object)[self.sat_index]
        return [ids[a:b].tolist() for a, b in zip(bounds[:-1], bounds[1:])]

    def epochs(self, start, stop):
        """The pairs of epochs ``start .. stop - 1``: a Visibility of those epochs, indexed from 0.

        Returns
        -------
        Visibility
            Its per-pair arrays are views of this one's.
        """
        a, b = np.searchsorted(self.epoch_index, [start, stop])
        pairs = {f: getattr(self, f)[a:b] for f in (
            "sat_index", "az_rad", "elev_rad", "range_m", "pos_sv_ecef_m", "vel_sv_ecef_mps")}
        return replace(self, times_utc=self.times_utc[start:stop], epoch_index=self.epoch_index[a:b] - start,
                       pos_rx_ecef_m=self.pos_rx_ecef_m[start:stop], vel_rx_ecef_mps=self.vel_rx_ecef_mps[start:stop],
                       **pairs)

    def padded(self, values):
        """Per-pair values laid out per epoch, padded with NaN.

        Parameters
        ----------
        values : ndarray, (m, ...)

        Returns
        -------
        ndarray, (n_epochs, max_visible, ...)
        """
        n = self.n_visible
        width = max(int(n.max(initial=0)), 1)
        slot = np.arange(len(self.epoch_index)) - np.searchsorted(self.epoch_index, self.epoch_index)
        out = np.full((len(self.times_utc), width) + values.shape[1:], np.nan)
        out[self.epoch_index, slot] = values
        return out

    def doppler_cofactor(self, carrier_hz, clock_group=None):
        """``(H^T H)^-1`` of Doppler positioning per epoch ([Shen 2024] eq. 8-10).

        Static or moving receiver as given; NaN at epochs with fewer
        satellites than states or a singular geometry.

        Parameters
        ----------
        carrier_hz : float or array_like, (n_sats,)
            One carrier, or each satellite's (in the order of ``sat_ids``).
        clock_group : array_like of int, (n_sats,), optional
            Receiver clock of each satellite (its constellation): one
            frequency-offset state per group, k groups in all (sorted by
            value). An epoch's states are position, velocity and the clocks
            of the groups it sees (``6 + k_e``, as many satellites needed);
            an absent group's rows and columns are NaN. None: one clock.

        Returns
        -------
        ndarray, (n_epochs, 6 + k, 6 + k)
            k = 1 without ``clock_group``.
        """
        pos = self.padded(self.pos_sv_ecef_m)
        vel = self.padded(self.vel_sv_ecef_mps)
        f0 = carrier_hz if np.ndim(carrier_hz) == 0 else self.padded(np.asarray(carrier_hz, float)[self.sat_index])
        H = doppler_jacobian(pos, vel, self.pos_rx_ecef_m, self.vel_rx_ecef_mps, f0)
        w = np.isfinite(pos[..., 0]).astype(float)
        if clock_group is None:
            return cofactor(H, weights=w)
        labels, code = np.unique(np.asarray(clock_group), return_inverse=True)
        g = self.padded(code.ravel()[self.sat_index].astype(float))
        onehot = (g[..., None] == np.arange(len(labels))) & (w[..., None] > 0)
        present = onehot.any(-2)
        # An absent clock is held by a pseudo-row of its own, so that it neither counts nor breaks the rank.
        Q = cofactor(clock_group_rows(H, onehot), weights=np.concatenate([w, (~present).astype(float)], -1))
        keep = np.concatenate([np.ones(present.shape[:-1] + (6,), bool), present], -1)
        return np.where(keep[..., :, None] & keep[..., None, :], Q, np.nan)

    def doppler_gdop(self, carrier_hz, clock_group=None):
        """GDOP of Doppler positioning per epoch, NaN with too few satellites; (n_epochs,).

        ``sqrt`` of the trace of :meth:`doppler_cofactor` over position
        [m^2/Hz^2], velocity [(m/s)^2/Hz^2] and the receiver clock of every
        constellation seen [1] (eq. 10's mixed-unit sum): below ``6 + k_e``
        satellites of ``k_e`` constellations it is NaN.
        """
        if clock_group is None:
            return np.sqrt(np.trace(self.doppler_cofactor(carrier_hz), axis1=-2, axis2=-1))
        d = np.diagonal(self.doppler_cofactor(carrier_hz, clock_group), axis1=-2, axis2=-1)
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(d[..., 0]), np.sqrt(np.nansum(d, -1)), np.nan)

    def n_visible_by_group(self, group):
        """Visible satellites per epoch and group: ``group`` (n_sats,) int, returns (n_epochs, max(group) + 1)."""
        g = np.asarray(group)[self.sat_index]
        n_g = int(np.max(group, initial=-1)) + 1
        out = np.zeros((len(self.times_utc), n_g), int)
        np.add.at(out, (self.epoch_index, g), 1)
        return out

    def range_dops(self):
        """Classic pseudorange DOPs per epoch (NaN below 4 satellites).

        Returns
        -------
        dict of ndarray, (n_epochs,)
            ``gdop, pdop, hdop, vdop, tdop``.
        """
        ce = np.cos(self.elev_rad)
        los = np.stack([ce * np.sin(self.az_rad), ce * np.cos(self.az_rad), np.sin(self.elev_rad)], axis=-1)
        los = self.padded(los)
        return range_dops(los, weights=np.isfinite(los[..., 0]).astype(float))

    def runs(self):
        """Runs of consecutive visible epochs of each satellite: the passes as index arrays.

        Returns
        -------
        sat, first, last, top : ndarray of int, (n_runs,)
            Satellite index and the first, last and highest epoch of each run
            (the first of equal maxima), sorted by satellite then epoch.
        top_elev_rad : ndarray, (n_runs,)
        """
        order = np.lexsort((self.epoch_index, self.sat_index))
        sat, ep, el = self.sat_index[order], self.epoch_index[order], self.elev_rad[order]
        if len(sat) == 0:
            return sat, ep, ep, ep, el
        starts = np.flatnonzero(np.r_[True, (np.diff(sat) != 0) | (np.diff(ep) != 1)])
        ends = np.r_[starts[1:], len(sat)] - 1
        top_el = np.maximum.reduceat(el, starts)
        run = np.repeat(np.arange(len(starts)), ends - starts + 1)
        top = np.minimum.reduceat(np.where(el == top_el[run], np.arange(len(sat)), len(sat)), starts)
        return sat[starts], ep[starts], ep[ends], ep[top], top_el

    def passes(self):
        """Passes (rise, culmination, set) of every satellite, by rise time."""
        sat, first, last, top, top_el = self.runs()
        end = len(self.times_utc) - 1
        t = self.times_utc
        out = [Pass(str(self.sat_ids[k]), t[a], t[c], t[b], float(np.degrees(e)), bool(a == 0 or b == end))
               for k, a, b, c, e in zip(sat, first, last, top, top_el)]
        return sorted(out, key=lambda p: (p.rise_utc, p.sat_id))


def compute_visibility(constellation, times_utc, pos_rx_ecef_m, mask_deg, *, vel_rx_ecef_mps=None,
                       screen=True, screen_steps_s=SCREEN_STEPS_S, block_s=3600.0, show_progress=True):
    """Visible satellites above an elevation mask at every epoch.

    Parameters
    ----------
    constellation : Constellation
    times_utc : array_like of datetime64, (n_epochs,)
    pos_rx_ecef_m : array_like, (3,) for a site or (n_epochs, 3) for a trajectory
    mask_deg : float
        Elevation mask in [0, 90).
    vel_rx_ecef_mps : array_like, (3,) or (n_epochs, 3), optional
        Receiver velocity (zero for a site); used by the Doppler GDOP and to
        widen the screening margin.
    screen : bool
        Screen on coarse grids first (identical result, much faster for long
        uniform grids). Non-uniform grids are always evaluated in full.
    screen_steps_s : sequence of float
        Screening grid steps, coarse to fine; steps under two epochs are
        skipped.
    block_s : float or None
        The screened run goes through the window in blocks of about this
        length (whole coarsest steps), so that its working memory does not
        grow with the window: only the visible pairs are kept. None: one
        block. The result does not depend on it.
    show_progress : bool
        Progress bar on stderr (only when it is a terminal).

    Returns
    -------
    Visibility
    """
    t = np.atleast_1d(np.asarray(times_utc, dtype="datetime64[ns]"))
    n_t = len(t)
    pos_rx = np.broadcast_to(np.asarray(pos_rx_ecef_m, dtype=float), (n_t, 3)).copy()
    vel_rx = np.zeros((n_t, 3)) if vel_rx_ecef_mps is None else \
        np.broadcast_to(np.asarray(vel_rx_ecef_mps, dtype=float), (n_t, 3)).copy()
    lat, lon, _ = ecef_to_geodetic(pos_rx)
    enu_e = C_e_n(lat, lon)
    sin_mask = np.sin(np.radians(mask_deg))
    jd, fr = jd_utc(t)
    ujd, ufr = jd_ut1(t)

    steps = np.diff(t).astype(np.int64)
    uniform = n_t > 2 and np.all(steps == steps[0]) and steps[0] > 0
    strides = sorted({round(s * 1e9 / steps[0]) for s in screen_steps_s} - {0, 1}, reverse=True) \
        if screen and uniform else []
    geometry = (jd, fr, ujd, ufr, pos_rx, enu_e[..., 2], sin_mask)
    if strides:
        per_block = n_t if block_s is None else max(1, round(block_s * 1e9 / (strides[0] * steps[0]))) * strides[0]
        rates = (speed_bound_mps(constellation), float(np.linalg.norm(vel_rx, axis=-1).max()), steps[0] * 1e-9)
        starts = range(0, n_t - 1, per_block)
        blocks = []
        for e0 in progress(starts, desc="screening", unit="block") if show_progress else starts:
            cand_sat, cand_ep = screen_candidates(constellation, e0, min(e0 + per_block, n_t - 1), n_t, strides,
                                                  geometry, rates)
            blocks.append(_pairs_geometry(*evaluate_pairs(constellation, cand_sat, cand_ep, geometry),
                                          pos_rx, enu_e))
    else:
        blocks = [_pairs_geometry(*_evaluate_all(constellation, geometry, show_progress), pos_rx, enu_e)]
    return Visibility(times_utc=t, sat_ids=constellation.sat_ids, **_joined(blocks),
                      pos_rx_ecef_m=pos_rx, vel_rx_ecef_mps=vel_rx)


def _pairs_geometry(sat_i, ep_i, pos_sv, vel_sv, pos_rx, enu_e):
    """Visible pairs of one block sorted by epoch then satellite, with azimuth, elevation and range.

    Parameters
    ----------
    sat_i, ep_i : ndarray of int, (m,)
    pos_sv, vel_sv : ndarray, (m, 3)
    pos_rx : ndarray, (n_epochs, 3)
    enu_e : ndarray, (n_epochs, 3, 3)
        ``C_e_n`` of every epoch: its columns are the East, North, Up axes.

    Returns
    -------
    dict of ndarray
        The per-pair fields of :class:`Visibility`, (m,) or (m, 3).
    """
    order = np.lexsort((sat_i, ep_i))
    sat_i, ep_i, pos_sv, vel_sv = sat_i[order], ep_i[order], pos_sv[order], vel_sv[order]
    los_n = np.einsum("...ji,...j->...i", enu_e[ep_i], pos_sv - pos_rx[ep_i])
    rng = np.linalg.norm(los_n, axis=-1)
    return dict(epoch_index=ep_i, sat_index=sat_i, az_rad=np.mod(np.arctan2(los_n[:, 0], los_n[:, 1]), 2 * np.pi),
                elev_rad=np.arcsin(np.clip(los_n[:, 2] / np.where(rng > 0, rng, 1.0), -1, 1)), range_m=rng,
                pos_sv_ecef_m=pos_sv, vel_sv_ecef_mps=vel_sv)


def _joined(blocks):
    """The blocks' fields end to end, each output filled in place while the blocks are let go.

    Parameters
    ----------
    blocks : list of dict of ndarray
        Emptied on return.

    Returns
    -------
    dict of ndarray
        Indices as ``np.intp``.
    """
    m = sum(len(b["epoch_index"]) for b in blocks)
    out = {key: np.empty((m,) + v.shape[1:], np.intp if key.endswith("index") else v.dtype)
           for key, v in blocks[0].items()}
    i = 0
    while blocks:
        b = blocks.pop(0)
        n = len(b["epoch_index"])
        for key, v in b.items():
            out[key][i:i + n] = v
        i += n
    return out


def _evaluate_all(constellation, geometry, show_progress):
    """Brute force: every satellite at every epoch, SatrecArray in chunks.

    Returns
    -------
    sat_i, ep_i : ndarray of int, (m,)
    pos_sv, vel_sv : ndarray, (m, 3)
    """
    jd, fr = geometry[:2]
    ep = np.arange(len(jd))
    chunk = max(1, CHUNK_POINTS // len(jd))
    starts = range(0, len(constellation), chunk)
    found = [(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3)))]
    for s0 in progress(starts, desc="propagating", unit="chunk") if show_progress else starts:
        sub = constellation.subset(slice(s0, s0 + chunk))
        err, r_km, v_kmps = sub.satrec_array.sgp4(jd, fr)
        pos, vel, up, rng = propagated_geometry(r_km, v_kmps, err, ep, geometry)
        k, j = np.nonzero(up >= geometry[-1] * rng)
        found.append((k + s0, j, pos[k, j], vel[k, j]))
    return tuple(np.concatenate(x) for x in zip(*found))


