"""Carrier phase of the pilot combs across the blocks of a continuous recording: a Kalman tracker.

Each satellite's central tone is followed by a three-state Kalman filter
(phase [cycles], frequency [Hz], frequency rate [Hz/s] at the block centre;
white noise on the rate's derivative and on the frequency, the continuous
third-order model of Brown and Hwang 2012). Every block, each comb is
correlated coherently with the comb the state predicts: tone k against
``exp(-j 2 pi (k spacing t + s_k Phi(t)))`` with ``Phi`` the predicted
central-tone phase over the block and ``s_k = f_k / f_c`` (the correlation
of :func:`leosop.signal.fine.newton_comb`, at the prediction instead of at
the optimum). The tones keep unknown phases of their own (Newman phases in
``leosop generate``, unknown on a real downlink), so the per-tone sums are
combined against a template, the first locked block's sums: the phase of
``sum_k Y_k conj(template_k)`` is the phase error at the block centre, its
noise ``1 / sqrt(2 snr)`` rad from the block's coherent comb SNR. The
template's own noise is a constant phase: it cancels in phase differences.

That phase error is the mean of the error over the block, not its value at
the centre: a prediction whose rate is off by ``dr`` leaves ``dr T^2 / 24``
in it (mean of ``dr tau^2 / 2``; 4e-4 cycles per Hz/s at T = 0.1 s). The
filter's rate lags a pass's changing Doppler jerk (tens of Hz/s^2 at Ku
band) by Hz/s, so its prediction plus the error is the block's mean phase,
to which the prediction's own rate part is added back (exact); the centre's
phase is that less half the phase's curvature times the block's mean squared
time from its centre, the curvature from a cubic over a second of the
satellite's mean phases (:data:`CURVATURE_WINDOW_S`), not from the lagging
filter. Before, the lag's bias (1e-3 cycles, drifting as the jerk changes
over the pass) was the model error that issue 23's 60 s differential
carrier fixes showed as chi2/dof 1.5-2.

Per block and satellite the result gives the accumulated carrier phase (the
integral of ``doppler_hz``: its change between two blocks is ``-carrier_hz /
c`` times the change of range, plus the clocks' integral), its sigma, the
filter's frequency, a lock indicator (the coherent SNR over :data:`LOCK_SNR`)
and a cycle-slip flag (normalised innovation squared over :data:`SLIP_NIS`:
a phase jump the prediction cannot explain). The whole cycles are continuous
within an ``arc``; a slip, or a prediction whose phase sigma exceeds
:data:`ARC_SIGMA_CYCLES` (the filter's own variance propagated over a gap: a
loss of lock, a missing block), starts a new one. A new arc's phase holds no
frequency (its integer is gone), so its first block re-acquires the frequency
and rate from its own :data:`SEGMENTS` segments (the comb fit at the
prediction; 0.04 Hz and 3 Hz/s at 1e-3 cycles a 0.1 s block): left as
predicted over the gap, they kept every later prediction past
:data:`ARC_SIGMA_CYCLES` and each block started an arc of its own (with the
default process noise one missing 0.1 s block already gives 0.24 cycles).

The phase is the received central tone's, not the template's: tone k of a
comb arrives with the phase of its transmitter, common to every receiver,
plus ``-(f_c + k spacing) range / c``: its own delay. Against the template
the phase error is relative, so the template's central-tone phase is added
back: block by block the central tone's sum, turned back by the block's
phase error, ``Y_0 exp(-j 2 pi z)``, has the template's central-tone phase
(the template's noise cancels: it is in ``z`` too); summed coherently over
every locked block of the satellite, its angle is the constant that turns
the accumulated phase into the received central-tone phase up to whole
cycles (and the transmitted central tone's phase, common to all receivers),
with the sigma of the whole recording's central-tone SNR
(``phase_ref_sigma_cycles``, 2e-3 cycles for 1 s at 35 dB-Hz). The
central tone is the reference because its phase holds no tone-spacing term:
the other tones' ``k spacing range / c`` differ between receivers by
kilometres of range over the 6.8 km wavelength of the spacing. Between two
receivers of the same satellites the phase difference is then the range
difference in cycles plus a clock phase per receiver and whole cycles: the
double differences are integers plus geometry (integer ambiguity fixing,
:mod:`leosop.positioning.differential_carrier`).

Comb crossings: the per-tone sums assume the satellite's comb alone near
its tones. When another satellite's tone sweeps through one of them
(modulo the spacing; their Dopplers differ in rate by 1-2 kHz/s, so the
difference moves 100-200 Hz within a 0.1 s block) its chirp leaks into the
sums (a Fresnel integral of ~``1 / sqrt(rate T^2)`` of a tone, 0.2-0.3)
and the block's phase is off by 10-28 sigma. :func:`comb_crossings`
flags a block where the closest approach over the block comes within
:data:`CROSSING_MARGIN` / T; such a block gives no phase (``crossing``,
not ``lock``). The filter still takes it: its error (at most 0.03 cycles
measured) is well within the prediction's sigma (~0.07 cycles a block with
the default process noise: no slip), and the next blocks' phases are
measured, not predicted. Left out of the filter, the prediction over two
blocks (0.24 cycles) would pass :data:`ARC_SIGMA_CYCLES` and start one new arc.

What cannot be tracked across snapshot gaps: a snapshot recording (20 ms
every second, DESIGN 4.2) gives no accumulated phase. Over a gap of a second
the prediction of a 3-state model carries the Doppler's unmodelled second
derivative (tens of Hz/s^2 on a LEO pass at 11 GHz, ``T^3 / 6`` cycles per
Hz/s^2: several cycles) and the receiver oscillator's phase noise, so the
integer cycle count is lost: each snapshot starts a new arc, and only the
Doppler of each snapshot survives. The ambiguity of each arc (its constant
offset) is never resolved here; positioning uses phase differences within an
arc (:func:`phase_rate_doppler`).
"""

from dataclasses import dataclass

import numpy as np
from scipy.stats import gamma

from ..errors import InputError
from ..signal.fine import comb_phasors
from ..signal.pilot import PilotComb

__all__ = ["CarrierTracks", "track_carrier", "recording_blocks", "phase_rate_doppler", "comb_crossings", "LOCK_SNR",
           "SLIP_NIS", "ARC_SIGMA_CYCLES", "CROSSING_MARGIN"]

#: Coherent comb SNR (|S|^2 over its noise mean) a block needs to update the
#: filter: noise alone exceeds it with probability exp(-LOCK_SNR) = 1e-6.
LOCK_SNR = 13.8
#: Normalised innovation squared flagged as a cycle slip: chi-square with one
#: degree of freedom exceeds it with probability 1e-4 (a few false flags per
#: 10^4 satellite-blocks; a quarter-cycle jump at 1e-2 cycles sigma is 600).
SLIP_NIS = 15.1
#: Predicted phase sigma [cycles] beyond which the integer cycle count is
#: taken as lost: the next locked block starts a new arc.
ARC_SIGMA_CYCLES = 0.1
#: Window [s] of the phase's curvature that turns a block's mean phase into its centre's: a cubic over a second
#: of 0.1 s blocks knows it to ~0.007 Hz/s at 1e-3 cycles (3e-6 cycles of phase).
CURVATURE_WINDOW_S = 1.0
#: Comb crossing: a block is left out when another tracked comb's tone comes within this many 1/T (T the block
#: length) of one of the satellite's tones at some instant of the block (:func:`comb_crossings`). Measured on
#: 60 s pairs (seeds 5 / 6 / 7, 14 400 satellite-blocks): phase errors of 9.8 sigma rms (up to 28) where the tones
#: cross inside the block, 6.0 within 0.5 / T of it, 2.7 at 0.5-1 / T, 1.0-1.9 beyond 1 / T.
CROSSING_MARGIN = 1.0
#: Segments of a block whose phases give the block's own frequency and rate (:func:`_frequency_error`): four
#: leave one degree of freedom over the three of a quadratic phase; more would cost nothing in the correlation
#: but thin each segment's SNR below the linearisation's (a locked block's 13.8 / 4 is 3.5 already).
SEGMENTS = 4
#: Template detection: the tones' incoherent power exceeds this gamma quantile of noise alone with probability 1e-6.
_TEMPLATE_PFA = 1e-6


@dataclass(frozen=True)
class CarrierTracks:
    """Carrier tracking of several satellites over the blocks, each array (n_sats, n_blocks) but ``t_s``.

    Attributes
    ----------
    t_s : ndarray, (n_blocks,)
        Block centres [s] on the time base of the blocks' start times.
    phase_cycles : ndarray
        Accumulated central-tone carrier phase at the block centre, the
        integral of ``doppler_hz``: the block's mean phase (the filter's
        prediction plus the block's phase error, the receiver's NCO phase
        plus its discriminator) less the curvature's part (the module's
        note; NaN where not locked). Continuous
        within an arc; its fraction is the received central tone's phase less
        the transmitted one (the module's note), its whole cycles arbitrary per arc.
    phase_sigma_cycles : ndarray
        Its sigma, ``1 / (2 pi sqrt(2 snr))``: the block's own noise,
        independent from block to block (the prediction carries no error
        into it while the phase error stays well within half a cycle; the
        curvature's correction, shared by a second of blocks, adds ~3e-6
        cycles at 1e-3).
    phase_ref_sigma_cycles : ndarray
        Sigma of the constant that refers the phase to the central tone (the
        same in every block of a satellite; NaN where not locked): an error
        common to the satellite's blocks, which a float ambiguity absorbs
        and an integer one must stay well below.
    doppler_hz, doppler_sigma_hz, doppler_rate_hz_per_s : ndarray
        The filter's frequency state (DESIGN 4.2 sign, clocks included), its sigma, its rate.
    snr : ndarray
        Coherent comb SNR of the block's correlation (NaN before the template).
    lock, slip, crossing : ndarray of bool
        ``lock``: the block updated the filter and gives a phase; ``slip``: its innovation failed the test (a
        new arc begins);
        ``crossing``: another tracked comb crossed this one's tones in the block (:func:`comb_crossings`): no
        phase and not ``lock`` whatever its SNR (the filter took it all the same: the module's note).
    arc : ndarray of int
        Arc number, -1 before the first lock; whole cycles are continuous within an arc.
    """

    t_s: np.ndarray
    phase_cycles: np.ndarray
    phase_sigma_cycles: np.ndarray
    phase_ref_sigma_cycles: np.ndarray
    doppler_hz: np.ndarray
    doppler_sigma_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    snr: np.ndarray
    lock: np.ndarray
    slip: np.ndarray
    arc: np.ndarray
    crossing: np.ndarray


def _transition(dt_s, accel_psd, freq_psd):
    """Phi (3, 3) and Q (3, 3) of the (phase, frequency, rate) model over ``dt_s``."""
    Phi = np.array([[1.0, dt_s, 0.5 * dt_s**2], [0.0, 1.0, dt_s], [0.0, 0.0, 1.0]])
    d = dt_s ** np.arange(6)
    Q = accel_psd * np.array([[d[5] / 20, d[4] / 8, d[3] / 6], [d[4] / 8, d[3] / 3, d[2] / 2],
                              [d[3] / 6, d[2] / 2, d[1]]])
    Q[:2, :2] += freq_psd * np.array([[d[3] / 3, d[2] / 2], [d[2] / 2, d[1]]])
    return Phi, Q


def _correlate(iq, t0_s, fs, x, comb):
    """Per-tone sums of the block's :data:`SEGMENTS` segments against the predicted comb of each satellite.

    Returns
    -------
    Ys : ndarray, (n_sats, SEGMENTS, n_tones)
        The segments' sums (the block's is their sum).
    tau_s : ndarray, (SEGMENTS, 3)
        Each segment's share of the samples and its mean of ``tau`` and ``tau^2`` (time from the block centre [s]).
    """
    n = iq.size
    t = t0_s + np.arange(n) / fs
    tau = t - (t0_s + 0.5 * (n - 1) / fs)
    sp = float(comb.tone_spacing_hz)
    ratio = sp / float(comb.carrier_hz)
    dphi = x[:, 1:2] * tau + 0.5 * x[:, 2:3] * tau**2                     # (n_sats, n)
    a = (x[:, :1] - np.round(x[:, :1])) + dphi
    b = sp * t + ratio * (x[:, :1] + dphi)
    phasors = comb_phasors(a.ravel(), b.ravel(), comb.n_tones // 2).reshape(x.shape[0], n, comb.n_tones)
    cuts = (np.arange(SEGMENTS + 1) * n) // SEGMENTS
    seg = [slice(i, j) for i, j in zip(cuts[:-1], cuts[1:])]
    Ys = np.stack([np.einsum("n,snk->sk", iq[g].astype(complex), phasors[:, g]) for g in seg], axis=1)
    return Ys, np.array([[(g.stop - g.start) / n, np.mean(tau[g]), np.mean(tau[g] ** 2)] for g in seg])


def _frequency_error(Ys, template, r, seg):
    """The block's own frequency and rate error of the prediction from its segments' phases: the comb fit at the
    prediction, which needs no earlier block.

    Segment m's phase against the block's, linearised (``Im(s_m e^{-j 2 pi z}) / (2 pi w_m |s|)``, ``w_m`` its
    share of the samples; noise ``r / w_m``), is ``a + b mean(tau) + c mean(tau^2) / 2``: weighted least
    squares give ``b`` [Hz] and ``c`` [Hz/s] with covariance ``r`` times that of the fit. At the 0.1 s blocks'
    1e-3 cycles (4 segments): 0.04 Hz and 3 Hz/s, the steady filter's own prediction to the next block.

    Returns
    -------
    y : ndarray, (n_sats, 2)
    R : ndarray, (n_sats, 2, 2)
    """
    sm = np.einsum("smk,sk->sm", Ys, np.conj(template))
    s = sm.sum(axis=1, keepdims=True)
    w, tau, tau2 = seg.T
    delta = np.imag(sm * np.exp(-1j * np.angle(s))) / (2 * np.pi * w * np.abs(s))
    A = np.stack([np.ones_like(w), tau, 0.5 * tau2], axis=1)                # (SEGMENTS, 3)
    cov = np.linalg.inv(A.T @ (w[:, None] * A))
    est = delta @ (w[:, None] * A) @ cov                                   # (n_sats, 3)
    return est[:, 1:], r[:, None, None] * cov[1:, 1:]


def track_carrier(blocks, sample_rate_hz, doppler0_hz, rate0_hz_per_s, *, comb=None, doppler0_sigma_hz=1.0,
                  rate0_sigma_hz_per_s=100.0, accel_psd_hz2_per_s5=1e3, freq_psd_hz2_per_s=1e-2):
    """Track the carrier phase of several combs over successive blocks.

    Parameters
    ----------
    blocks : iterable of (float, ndarray)
        ``(t0_s, iq)`` per block in time order: the time of its first sample
        [s] (one time base; the tones' nominal phases refer to its origin)
        and its samples, complex, shape (n,) (n may change between blocks).
    sample_rate_hz : float
    doppler0_hz, rate0_hz_per_s : array_like, (n_sats,)
        Each comb's central-tone Doppler and rate at the first block's centre
        (e.g. :func:`~leosop.signal.multicomb.find_combs` on that block).
    comb : PilotComb, optional
        The comb as the receiver sees it (:meth:`~.PilotComb.through_lo` for a large LO offset).
    doppler0_sigma_hz, rate0_sigma_hz_per_s : float
        Their prior sigmas. The first block's phase error is
        ``2 pi sigma_f T / sqrt(12)``: a block of T = 20 ms needs sigma_f below ~5 Hz.
    accel_psd_hz2_per_s5 : float
        Spectral density of the white noise driving the frequency rate
        [Hz^2/s^5]: a LEO pass's Doppler changes its rate by up to ~60
        Hz/s^2 at 11 GHz; the default lets the rate follow that within a
        fraction of a second.
    freq_psd_hz2_per_s : float
        Frequency random walk [Hz^2/s] (receiver and satellite oscillators).

    Returns
    -------
    CarrierTracks
    """
    comb = comb or PilotComb()
    fs = float(sample_rate_hz)
    f0 = np.atleast_1d(np.asarray(doppler0_hz, dtype=float))
    r0 = np.broadcast_to(np.asarray(rate0_hz_per_s, dtype=float), f0.shape)
    if f0.ndim != 1 or not np.all(np.isfinite(f0)) or not np.all(np.isfinite(r0)):
        raise InputError("doppler0_hz and rate0_hz_per_s must be finite, one per satellite")
    n_sats = f0.size
    x = np.stack([np.zeros(n_sats), f0, r0], axis=1)
    P = np.zeros((n_sats, 3, 3))
    P[:, 0, 0] = 1.0
    P[:, 1, 1] = doppler0_sigma_hz**2
    P[:, 2, 2] = rate0_sigma_hz_per_s**2
    template = np.full((n_sats, comb.n_tones), np.nan + 0j)
    arc = np.full(n_sats, -1)
    central = np.zeros(n_sats, dtype=complex)     # sum of Y_0 exp(-j 2 pi z): the template's central-tone phase
    central_noise = np.zeros(n_sats)              # the noise power of that sum
    template_threshold = gamma.isf(_TEMPLATE_PFA, comb.n_tones)
    rows = []
    t_prev = None
    for t0_s, iq in blocks:
        iq = np.asarray(iq)
        t_c = float(t0_s) + 0.5 * (iq.size - 1) / fs
        if t_prev is not None:
            if not t_c > t_prev:
                raise InputError(f"blocks out of time order at t0_s={t0_s:g}")
            Phi, Q = _transition(t_c - t_prev, accel_psd_hz2_per_s5, freq_psd_hz2_per_s)
            x = x @ Phi.T
            P = Phi @ P @ Phi.T + Q
        t_prev = t_c
        Ys, seg = _correlate(iq, float(t0_s), fs, x, comb)
        Y = Ys.sum(axis=1)
        noise = _noise(iq, Y)
        crossing = comb_crossings(x[:, 1], x[:, 2], iq.size / fs, comb)
        new = np.isnan(template[:, 0]) & ~crossing & (np.sum(np.abs(Y) ** 2, axis=1) / noise > template_threshold)
        template[new] = Y[new]
        s = np.sum(Y * np.conj(template), axis=1)
        snr = np.abs(s) ** 2 / (noise * np.sum(np.abs(template) ** 2, axis=1))
        use = snr > LOCK_SNR                      # the blocks the filter takes; a crossing's phase is not reported
        lock = use & ~crossing
        z = np.angle(s) / (2 * np.pi)
        r = 1.0 / (2.0 * snr) / (2 * np.pi) ** 2
        nis = z**2 / (P[:, 0, 0] + r)
        restart = use & ((arc < 0) | (P[:, 0, 0] > ARC_SIGMA_CYCLES**2) | (nis > SLIP_NIS))
        slip = restart & (arc >= 0) & (nis > SLIP_NIS)
        # the block's mean phase: z is the mean of the phase error over the block, and the prediction's mean is its
        # centre phase plus half its rate times the mean squared time from the centre
        half_sq = (iq.size**2 - 1) / (24.0 * fs**2)
        phase = np.where(lock, x[:, 0] + z + x[:, 2] * half_sq, np.nan)
        central += np.where(lock, Y[:, comb.n_tones // 2] * np.exp(-2j * np.pi * z), 0.0)
        central_noise += np.where(lock, noise, 0.0)
        x, P = _update(x, P, np.where(use, z, 0.0), np.where(use, r, np.inf), restart)
        # a new arc after the first: the frequency and rate from the block itself (the phase's integer is gone, so
        # the phase cannot teach them; left as predicted over a gap, every later block would start an arc too).
        # After the restart the phase shares no covariance with them: the update leaves the block's phase as is.
        reacquire = restart & (arc >= 0)
        if reacquire.any():
            x, P = _reacquire(x, P, *_frequency_error(Ys, template, r, seg), reacquire)
        arc = np.where(restart, arc + 1, arc)
        rows.append((t_c, phase, np.where(lock, np.sqrt(r), np.nan), x[:, 1].copy(), np.sqrt(P[:, 1, 1]),
                     x[:, 2].copy(), snr, lock, slip, arc.copy(), crossing, half_sq))
    if not rows:
        raise InputError("no blocks to track")
    (t_s, phase, sigma, doppler, doppler_sigma, rate, snr, lock, slip, arc, crossing, half_sq) = (
        np.array(c) if k in (0, 11) else np.stack(c, axis=1) for k, c in enumerate(zip(*rows)))
    # the block centre's phase: the mean phase less half the phase's curvature times the mean squared time
    phase = phase - _curvature(t_s, phase, arc, lock, rate) * half_sq
    # the central tone's coherent sum over the locked blocks: its angle and its SNR |sum|^2 / sum of noise powers
    ref_cycles = np.angle(central) / (2 * np.pi)
    ref_snr = np.abs(central) ** 2 / np.where(central_noise > 0, central_noise, np.inf)
    ref_sigma = 1.0 / (2 * np.pi * np.sqrt(2.0 * ref_snr))
    return CarrierTracks(t_s, phase + ref_cycles[:, None], sigma, np.where(lock, ref_sigma[:, None], np.nan),
                         doppler, doppler_sigma, rate, snr, lock, slip, arc, crossing)


def comb_crossings(doppler_hz, rate_hz_per_s, block_s, comb, margin=CROSSING_MARGIN):
    """Where another satellite's comb crosses this one's: a tone of it within ``margin / block_s`` of one of
    this one's (modulo the spacing) at some instant of the block.

    Over the block (``tau`` within +-T/2 of its centre) the two central tones' difference ``d + dr tau``
    comes closest to a whole number of spacings at ``max(|d| - |dr| T / 2, 0)``, ``d`` folded into
    +-spacing/2; tone k's Doppler is ``s_k`` times the central one's, which moves the pairs of other tones
    by up to ``max|s_k - 1| (|f_i| + |f_j|)`` (a few hertz), added to the margin.

    Parameters
    ----------
    doppler_hz, rate_hz_per_s : array_like, (n_sats, ...)
        Central-tone Doppler and rate of each satellite at the block centres (NaN: not tracked there).
    block_s : float
        The block length T [s].
    comb : PilotComb
    margin : float
        In units of 1/T (:data:`CROSSING_MARGIN`).

    Returns
    -------
    ndarray of bool, (n_sats, ...)
    """
    f = np.asarray(doppler_hz, dtype=float)
    r = np.asarray(rate_hz_per_s, dtype=float)
    sp = float(comb.tone_spacing_hz)
    d = f[:, None] - f[None, :]
    d -= sp * np.round(d / sp)
    closest = np.maximum(np.abs(d) - 0.5 * np.abs(r[:, None] - r[None, :]) * block_s, 0.0)
    spread = np.max(np.abs(comb.doppler_scale - 1.0)) * (np.abs(f[:, None]) + np.abs(f[None, :]))
    near = closest < margin / block_s + spread                            # NaN compares False
    near[np.arange(f.shape[0]), np.arange(f.shape[0])] = False
    return np.any(near, axis=1)


def _curvature(t_s, phase_cycles, arc, lock, rate_hz_per_s, window_s=CURVATURE_WINDOW_S):
    """Second derivative of the phase at each block [Hz/s]: a cubic fitted to the locked blocks of its arc
    within ``window_s / 2`` (equal weights), (n_sats, n_blocks).

    A block whose window holds fewer than six such blocks (a cubic and two degrees of freedom; the first
    and last blocks of a 0.1 s track have six) takes the filter's rate (``rate_hz_per_s``).
    """
    n_sats, n = phase_cycles.shape
    step = np.median(np.diff(t_s)) if n > 1 else window_s
    h = max(int(np.floor(0.5 * window_s / step + 1e-9)), 0)
    j = np.arange(n)[:, None] + np.arange(-h, h + 1)[None, :]              # (n, 2h+1) neighbours
    inside = (j >= 0) & (j < n)
    jc = np.clip(j, 0, n - 1)
    tau = t_s[jc] - t_s[:, None]
    inside &= np.abs(tau) <= 0.5 * window_s + 1e-9
    use = inside[None] & lock[:, jc] & lock[:, :, None] & (arc[:, jc] == arc[:, :, None])   # (n_sats, n, 2h+1)
    y = np.where(use, phase_cycles[:, jc] - phase_cycles[:, :, None], 0.0)
    A = (tau[..., None] ** np.arange(4)) * np.ones((n_sats, 1, 1, 1))     # (n_sats, n, 2h+1, 4)
    Aw = A * use[..., None]
    N = np.einsum("snki,snkj->snij", Aw, A)
    enough = use.sum(axis=-1) >= 6
    N[~enough] = np.eye(4)
    coef = np.linalg.solve(N, np.einsum("snki,snk->sni", Aw, y)[..., None])[..., 0]
    return np.where(enough, 2.0 * coef[..., 2], rate_hz_per_s)


def _noise(iq, Y):
    """Noise power of the per-tone sums: n times the block's power less the combs' (tone power ``|Y|^2 / n^2``)."""
    n = iq.size
    power = float(np.mean(np.abs(iq) ** 2)) - float(np.sum(np.abs(Y) ** 2)) / n**2
    return n * max(power, 1e-3 * float(np.mean(np.abs(iq) ** 2)), np.finfo(float).tiny)


def _update(x, P, y, r, restart):
    """Scalar phase update of every satellite (Joseph form); ``restart`` rows take the phase afresh.

    A restarted row keeps its frequency and rate, and its phase becomes the
    measurement (a new arc: the old phase's integer is gone). ``r`` inf: no update.
    """
    x = x.copy()
    P = P.copy()
    P[restart, 0, :] = 0.0
    P[restart, :, 0] = 0.0
    P[restart, 0, 0] = np.where(np.isfinite(r[restart]), 1e6, 0.0)
    s = P[:, 0, 0] + r
    k = np.where(np.isfinite(s)[:, None], P[:, :, 0] / np.where(np.isfinite(s), s, 1.0)[:, None], 0.0)
    x += k * y[:, None]
    ikh = np.eye(3) - k[:, :, None] * np.array([1.0, 0.0, 0.0])[None, None, :]
    r_used = np.where(np.isfinite(r), r, 0.0)[:, None, None]
    P = ikh @ P @ np.swapaxes(ikh, 1, 2) + r_used * k[:, :, None] * k[:, None, :]
    return x, 0.5 * (P + np.swapaxes(P, 1, 2))


def _reacquire(x, P, y, R, rows):
    """Update of the frequency and rate of ``rows`` by their measured errors ``y`` (n_sats, 2), covariance ``R``."""
    x = x.copy()
    P = P.copy()
    H = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    K = P[rows] @ H.T @ np.linalg.inv(H @ P[rows] @ H.T + R[rows])         # (n_rows, 3, 2)
    x[rows] += np.einsum("sij,sj->si", K, y[rows])
    ikh = np.eye(3) - K @ H
    P[rows] = ikh @ P[rows] @ np.swapaxes(ikh, 1, 2) + K @ R[rows] @ np.swapaxes(K, 1, 2)
    return x, 0.5 * (P + np.swapaxes(P, 1, 2))


def recording_blocks(rec, block_s, *, factor=1, first=0):
    """``(t0_s, iq)`` of the blocks of a SigMF recording (:func:`~leosop.replay.pipeline.block_plan`), lazily.

    From block ``first`` on, narrowed by ``factor`` as replay narrows them
    (:func:`~leosop.replay.stream.narrow`: sample k of a block is input
    sample ``k factor``, so ``t0_s`` is unchanged and the rate is
    ``sample_rate_hz / factor``).
    """
    from .pipeline import block_plan
    from .stream import narrow

    fs = rec.sample_rate_hz
    for b in block_plan(rec, block_s)[first:]:
        yield b.t_s - 0.5 * (b.n_samples - 1) / fs, narrow(rec.read(b.start, b.n_samples), factor)


def phase_rate_doppler(tracks, window_s=1.0, degree=3):
    """Doppler at every block from the accumulated phase: the slope of a local polynomial over ``window_s``.

    A polynomial of ``degree`` in time is fitted to the phase of the locked
    blocks of one arc within ``window_s / 2`` of each block (the arc's
    unknown offset drops out of the slope); its derivative at the block is
    the Doppler, with the sigma the fit's covariance gives from the blocks'
    phase sigmas (independent from block to block, :class:`CarrierTracks`).

    Returns
    -------
    doppler_hz, sigma_hz : ndarray, (n_sats, n_blocks)
        NaN where the window holds fewer than ``2 degree + 1`` locked blocks of the same arc.
    """
    t = tracks.t_s
    dop = np.full(tracks.phase_cycles.shape, np.nan)
    sig = np.full(tracks.phase_cycles.shape, np.nan)
    for i, j in zip(*np.nonzero(tracks.lock)):
        use = tracks.lock[i] & (tracks.arc[i] == tracks.arc[i, j]) & (np.abs(t - t[j]) <= 0.5 * window_s)
        if use.sum() < 2 * degree + 1:
            continue
        tau = t[use] - t[j]
        A = tau[:, None] ** np.arange(degree + 1)
        w = 1.0 / tracks.phase_sigma_cycles[i, use]
        coef, *_ = np.linalg.lstsq(A * w[:, None], (tracks.phase_cycles[i, use] - tracks.phase_cycles[i, j]) * w,
                                   rcond=None)
        cov = np.linalg.inv((A * w[:, None]).T @ (A * w[:, None]))
        dop[i, j], sig[i, j] = coef[1], np.sqrt(cov[1, 1])
    return dop, sig
