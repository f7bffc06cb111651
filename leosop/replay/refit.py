"""The tracked blocks fitted again through the receiver's LO offset, once identification has it."""

import numpy as np

from ..signal.multicomb import find_combs
from .stream import prepared_blocks, track_times
from .tracks import Track

__all__ = ["refit_through_lo", "rows_by_block"]


def rows_by_block(tracks, block_t_s):
    """Which tracks' rows fall in each block.

    Parameters
    ----------
    tracks : list of Track
    block_t_s : ndarray, (n_blocks,)
        The blocks' times as the tracks stamp them (:func:`~leosop.replay.stream.track_times`).

    Returns
    -------
    dict
        Block index -> list of (track index, row), for the blocks that hold any.
    """
    index = {t: k for k, t in enumerate(block_t_s)}
    rows = {}
    for i, tr in enumerate(tracks):
        for j, t in enumerate(tr.t_s):
            rows.setdefault(index[t], []).append((i, j))
    return rows


def refit_through_lo(rec, tracks, blocks, factor, comb, lo, *, gate_hz, threads=1, kernel=None):
    """The tracks' blocks fitted again with the tone model through the receiver's LO offset.

    The first pass models the whole common offset as Doppler, scaled with
    each tone's RF frequency, where an LO offset moves every tone alike
    (:meth:`~leosop.signal.pilot.PilotComb.through_lo`): at 1 MHz the comb's
    edge tones sit 15 Hz off. Once identification has estimated the offset,
    every block a track was detected in is read again and its tracked combs
    fitted at their Doppler and rate (tracking mode, ``gate_hz``) with
    ``lo_offset_hz`` the offset at the block's time. A detection the exact
    model does not confirm (its comb fails the detector) leaves the track.

    Parameters
    ----------
    rec : Recording
    tracks : list of Track
        Raw Dopplers (before the rate-change correction, whose sub-hertz
        change does not matter to the gate).
    blocks : list of Block
    factor : int
        Narrowing factor of the first pass (:func:`~leosop.replay.pipeline.search_band`).
    comb : PilotComb
    lo : LoEstimate
    gate_hz : float
        Half-width of the tracking window round each detection [Hz].
    threads : int
        Threads reading and cleaning blocks (:func:`~leosop.replay.stream.prepared_blocks`).
    kernel : {None, "numba", "numpy"}
        The comb fits' and the cleaning's (:func:`~leosop.signal.multicomb.find_combs`): the replay's, for the
        whole recording.

    Returns
    -------
    list of Track
        New tracks, raw; tracks left with no detection are dropped.
    """
    fs = rec.sample_rate_hz / factor
    members = rows_by_block(tracks, track_times(blocks, factor, rec.sample_rate_hz)[0])
    cols = ("doppler_hz", "doppler_rate_hz_per_s", "cn0_dbhz", "sigma_hz")
    new = [{c: getattr(tr, c).copy() for c in cols} | {"keep": np.zeros(len(tr), bool)} for tr in tracks]
    members = sorted(members.items())
    for (k, rows), block in zip(members, prepared_blocks(rec, [blocks[k] for k, _ in members], factor, comb,
                                                         threads=threads, kernel=kernel)):
        pred = np.array([tracks[i].doppler_hz[j] for i, j in rows])
        rate = np.array([tracks[i].doppler_rate_hz_per_s[j] for i, j in rows])
        lo_hz = lo.offset_hz + lo.drift_hz_per_s * float((tracks[rows[0][0]].time_utc[rows[0][1]] - lo.t_ref_utc)
                                                         / np.timedelta64(1, "s"))
        found = find_combs(None, fs, comb=comb, predicted_hz=pred, predicted_rate_hz_per_s=np.nan_to_num(rate),
                           search=False, gate_hz=gate_hz, max_combs=max(10, len(rows)), lo_offset_hz=lo_hz,
                           clean=False, spectrum=block.iq_fft, kernel=kernel)
        for m, p in enumerate(found.predicted_index):
            i, j = rows[p]
            for c, v in zip(cols, (found.doppler_hz, found.doppler_rate_hz_per_s, found.cn0_dbhz, found.sigma_hz)):
                new[i][c][j] = v[m]
            new[i]["keep"][j] = True
    out = []
    for tr, n in zip(tracks, new):
        keep = n["keep"]
        if keep.any():
            out.append(Track(tr.t_s[keep], tr.time_utc[keep], *(n[c][keep] for c in cols)))
    return out
