"""A chunk of :class:`~leosop.signal.channel.SiteChannel` samples as segments of polynomial phase (compiled comb).

Between two nodes the light-time range is one cubic of the spline, and the
clock phase (offset and drift) a quadratic of time: over the samples of one
node interval each phase of :func:`~leosop.signal.pilot.comb_baseband` is a
cubic in the sample index, and the tone amplitude (linear between nodes) a
line. :func:`comb_segments` writes those per satellite and segment (the
chunk's part within one node interval);
:func:`leosop.signal.combkernels.add_comb_segments` synthesises them
without an exponential per sample (the error bound is there).
"""

import numpy as np
import numpy.typing as npt

from ..constants import C_MPS

__all__ = ["KERNEL_MODULE", "comb_segments"]

#: The compiled synthesis of the segments (:mod:`leosop.kernels`).
KERNEL_MODULE = "leosop.signal.combkernels"


def _frac(cycles):
    """Cycles reduced to [-0.5, 0.5]."""
    return cycles - np.round(cycles)


def comb_segments(channel, start: int, count: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                                                          npt.NDArray[np.int_], npt.NDArray[np.int_]]:
    """Phase polynomials and amplitude lines of samples ``start .. start+count-1`` of a tones channel.

    Parameters
    ----------
    channel : SiteChannel
        Its range spline, node amplitudes, clocks and phases are read (the
        companion of :meth:`~leosop.signal.channel.SiteChannel.samples`).
    start, count : int

    Returns
    -------
    poly : ndarray, (n_segments, n_sats, 2, 4)
        a0..a3 [cycles] of the lead psi = phi - h theta and of the comb phase
        theta in the segment's sample index j: phi = geom + clock + phase / 2 pi,
        theta = spacing t + spacing geom / f_c (as in comb_baseband). A segment
        is the chunk's part within one node interval; only the satellites
        heard somewhere in the chunk are kept.
    amp : ndarray, (n_segments, n_sats, 2)
        Tone amplitude at j = 0 and per sample.
    offset, length : ndarray of int, (n_segments,)
        First sample of each segment within the chunk, and its length.
    """
    fs, comb = float(channel.sample_rate_hz), channel.comb
    t_nodes = channel.t_nodes_s
    t = (start + np.arange(int(count))) / fs
    q = np.clip(np.searchsorted(t_nodes, t, side="right") - 1, 0, t_nodes.size - 2)
    j0 = np.flatnonzero(np.diff(q, prepend=-1))
    length = np.diff(j0, append=t.size)
    qs, t_a = q[j0], t[j0]
    x = t_a - t_nodes[qs]
    c = np.moveaxis(channel._range.c[:, qs, :], 2, 1)  # (4, n_sats, n_seg), highest degree first
    # The range cubic about each piece's first sample, in powers of j / fs.
    d = np.stack([((c[0] * x + c[1]) * x + c[2]) * x + c[3], (3.0 * c[0] * x + 2.0 * c[1]) * x + c[2],
                  3.0 * c[0] * x + c[1], c[0]])
    per_m = -float(comb.carrier_hz) / C_MPS
    per_sample = fs ** -np.arange(4.0)
    geom = d * per_m * per_sample[:, None, None]
    geom[0] = (d[0] - channel.range_ref_m[:, None]) * per_m
    drift = channel._drift_hz_per_s()[:, None]
    clock = channel.clock_offset_hz[:, None]
    spacing, h = float(comb.tone_spacing_hz), comb.n_tones // 2
    phi = geom.copy()
    phi[0] = _frac(geom[0] + clock * t_a + 0.5 * drift * t_a**2) + channel.phase_rad[:, None] / (2.0 * np.pi)
    phi[1] += (clock + drift * t_a) / fs
    phi[2] += 0.5 * drift / fs**2
    theta = geom * (spacing / float(comb.carrier_hz))
    theta[0] = _frac(spacing * t_a + theta[0])
    theta[1] += spacing / fs
    lead = phi - h * theta
    lead[0] = _frac(lead[0])
    a0 = channel.amplitude(t_a)
    slope = (channel._amp[:, qs + 1] - channel._amp[:, qs]) / ((t_nodes[qs + 1] - t_nodes[qs]) * fs)
    live = np.flatnonzero(np.any((a0 != 0) | (a0 + slope * (length - 1) != 0), axis=1))
    poly = np.stack([lead[:, live], theta[:, live]]).transpose(3, 2, 0, 1)
    return np.ascontiguousarray(poly), np.stack([a0[live].T, slope[live].T], axis=-1), j0, length
