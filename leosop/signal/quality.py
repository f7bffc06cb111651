"""Can a single-comb Doppler estimate be vouched for? The checks behind a block's ``status``.

A block's estimate is ``"ok"`` only when every check passes; otherwise its
status names the first check that fails (:data:`STATUSES`, in this order):

``weak comb``
    The coherent comb power at the fit, ``sum_k |Y_k|^2 / (N sigma^2)``
    (nine unit exponentials under noise alone), is below the detection
    threshold for false alarm ``pfa`` over every frequency and rate cell
    the fit searched: the C/N0 and sigma it implies describe nothing.
``tone ambiguity``
    The comb shifted by one or two tone spacings is not excluded: the
    coherent power of the tones only the fitted comb holds must beat that
    of the tones only the shifted comb holds by :data:`AMBIGUITY_SIGMA`
    standard deviations (:func:`position_margin_sigma`). A one-spacing
    slip (43.9 kHz) fails here.
``overlapping combs``
    The tones' coherent amplitudes do not fit the comb's amplitude profile
    (:func:`tone_spread`): another satellite's comb whose tones nearly
    coincide with these, one or more spacings apart, adds to some tones and
    not to others, and the "comb" fitted may be no satellite's.
``interference``
    The sigma implied by the fit's residual spectrum (another satellite's
    tones in the comb's bands, or a signal the chirp model does not fit) is
    more than :data:`INTERFERENCE_RATIO` times the Cramér-Rao bound: the
    first-order error model behind either is then not to be trusted. Below
    that ratio the reported sigma is the residual one (the larger).
``implausible rate``
    ``|rate|`` beyond the search bound, which is the largest rate a LEO
    pass can give (:func:`zenith_doppler_rate_hz_per_s`) with a margin:
    e.g. a block that joins captures across a gap, or a fit on noise.
``rate too high for a constant tone``
    (``ml``, ``fmlef``) The chirp over the block splits the periodogram's
    peak (its curvature at the centre frequency is not negative): the
    constant-tone estimate is at one of two side maxima.
``disagrees with the comb fit``
    (``ml``, ``fmlef``) The constant-tone estimate differs from the joint
    comb fit of the same block by more than :data:`DISAGREE_SIGMA` of
    their combined sigma (a side tone or another satellite's tone was
    taken for the central tone).

The CLI adds ``joins captures`` for blocks that straddle a gap between
snapshot captures and ``no pilot detected`` where the comb detector found
nothing.
"""

import numpy as np

from ..constants import C_MPS, GM_M3_PER_S2, OMEGA_E_RAD_PER_S, WGS84_A_M

__all__ = ["STATUSES", "AMBIGUITY_SIGMA", "DISAGREE_SIGMA", "INTERFERENCE_RATIO", "zenith_doppler_rate_hz_per_s",
           "position_margin_sigma", "tone_spread", "constant_tone_sigma_hz", "fit_status"]

STATUSES = ("ok", "no pilot detected", "joins captures", "weak comb", "tone ambiguity", "overlapping combs",
            "interference",
            "implausible rate", "rate too high for a constant tone", "disagrees with the comb fit")
#: Margin of the fitted comb position over a shifted one [sigma]. A slipped fit (the wrong position had the
#: larger power) passes with probability ~Phi(-(m + 3)), m the expected margin (about 1 at the detection
#: threshold): < 3e-5 per block. The price: at 30 dB-Hz per tone and 0.02 s (m ~ 3) half the blocks fail.
AMBIGUITY_SIGMA = 3.0
#: Largest accepted |constant-tone - comb fit| [combined sigma]; 5 sigma: ~6e-7 false rejections per block.
DISAGREE_SIGMA = 5.0
#: Largest accepted residual sigma over the Cramér-Rao bound (white noise: ~1, +-15 % at 0.02 s blocks).
INTERFERENCE_RATIO = 3.0


def zenith_doppler_rate_hz_per_s(carrier_hz, altitude_m):
    """Largest |Doppler rate| a circular orbit at ``altitude_m`` gives a receiver on the ground [Hz/s].

    The range acceleration peaks at closest approach, largest for a pass
    through the zenith: ``rho'' = v_rel^2 / h - GM / r^2 + omega^2 R`` (the
    satellite's gravity pulls it towards the receiver along the line of
    sight, the receiver's centripetal acceleration away), with ``v_rel`` at
    most the orbital speed plus the equatorial ground speed (a retrograde
    pass over the equator). Starlink at 550 km, 11.325 GHz: 4.14 kHz/s
    (3.64 kHz/s without the Earth's rotation); at 465 km, 5.0 kHz/s.
    """
    r_m = WGS84_A_M + np.asarray(altitude_m, dtype=float)
    v_rel = np.sqrt(GM_M3_PER_S2 / r_m) + OMEGA_E_RAD_PER_S * WGS84_A_M
    rho_ddot = v_rel**2 / (r_m - WGS84_A_M) - GM_M3_PER_S2 / r_m**2 + OMEGA_E_RAD_PER_S**2 * WGS84_A_M
    return rho_ddot * np.asarray(carrier_hz, dtype=float) / C_MPS


def position_margin_sigma(power, n_tones, max_shift=2):
    """By how many standard deviations the central comb position beats the positions shifted by whole spacings.

    Parameters
    ----------
    power : ndarray, shape (n_tones + 2 e,)
        Coherent power at each tone position of the fit, the comb's in the
        middle and ``e`` more either side, in units of its noise mean (a
        position without a tone is a unit exponential).
    n_tones : int
    max_shift : int
        Shifts ``+-1 .. +-max_shift`` (at most ``e``) are compared.

    Returns
    -------
    float
        ``min_s (W_0 - W_s) / sd_s`` over the shifts, ``W`` the windowed
        power sums; the variance of a position's power with noncentrality
        ``lambda`` (mean ``1 + lambda``) is ``1 + 2 lambda``.
    """
    p = np.asarray(power, dtype=float)
    extra = (p.size - n_tones) // 2
    var = 1.0 + 2.0 * np.maximum(p - 1.0, 0.0)
    idx = np.arange(p.size)
    centre = (idx >= extra) & (idx < extra + n_tones)
    margins = []
    for s in [s for k in range(1, min(max_shift, extra) + 1) for s in (-k, k)]:
        shifted = (idx >= extra + s) & (idx < extra + s + n_tones)
        only_c, only_s = centre & ~shifted, shifted & ~centre
        diff = p[only_c].sum() - p[only_s].sum()
        margins.append(diff / np.sqrt(var[only_c].sum() + var[only_s].sum()))
    return float(min(margins)) if margins else np.inf


def tone_spread(tone_abs, amplitudes, noise_sum, pfa):
    """Misfit of the tones' coherent amplitudes to the comb's profile, over its threshold (above 1: fails).

    Parameters
    ----------
    tone_abs : ndarray, shape (n_tones,)
        ``|Y_k|``, each tone's coherent sum over the block at the fit.
    amplitudes : ndarray, shape (n_tones,)
        The comb's relative tone amplitudes.
    noise_sum : float
        Noise mean of ``|Y_k|^2`` (``N sigma^2``).
    pfa : float

    Returns
    -------
    float
        ``sum_k (|Y_k| - a c_k)^2 / (noise_sum / 2)`` (``a`` fitted by least
        squares; chi-square with n_tones - 1 degrees of freedom for a strong
        comb, smaller for a weak one) over its ``1 - pfa`` quantile.
    """
    from scipy.stats import chi2

    c = np.asarray(amplitudes, dtype=float)
    a = float(tone_abs @ c / (c @ c))
    stat = float(np.sum((tone_abs - a * c) ** 2) / (0.5 * noise_sum))
    return stat / float(chi2.isf(pfa, c.size - 1)) if c.size > 1 else 0.0


def constant_tone_sigma_hz(n_samples, sample_rate_hz, rate_hz_per_s, cn0_dbhz, *, n_points=8192):
    """Standard deviation of the periodogram maximum (``ml``, ``fmlef``) for a tone chirping at ``rate``.

    The estimate is the zero of ``J'(f)``, ``J = |X(f)|^2`` ([Shen 2024] eq. 2).
    To first order in the noise ``w`` (variance ``sigma^2`` per sample),
    ``var f = 2 sigma^2 sum_n |g_n|^2 / J''^2`` with
    ``g_n = conj(S') + conj(S) (-j 2 pi tau_n)``, ``S``, ``S'``, ``S''`` the
    noise-free sum and its derivatives at the block-centre frequency
    (a centred linear chirp is symmetric: no bias). At ``rate = 0`` this is
    the single-tone Cramér-Rao bound (Rife and Boorstyn 1974). The sums are
    taken on ``n_points`` points spread over the block (the chirp phase is
    smooth) and scaled to ``n_samples``.

    Returns
    -------
    float
        ``inf`` when ``J'' >= 0`` (the chirp has split the peak) or the C/N0 is zero.
    """
    m = int(min(n_samples, n_points))
    dur = n_samples / sample_rate_hz
    tau = (np.arange(m) + 0.5) / m * dur - 0.5 * dur
    s = np.exp(1j * np.pi * rate_hz_per_s * tau**2)
    w = -2j * np.pi * tau
    scale = n_samples / m
    s0, s1, s2 = scale * s.sum(), scale * (w * s).sum(), scale * (w * w * s).sum()
    j2 = 2.0 * (abs(s1) ** 2 + (np.conj(s0) * s2).real)
    if not j2 < 0.0:
        return np.inf
    cn0 = 10.0 ** (float(cn0_dbhz) / 10.0)
    if not cn0 > 0.0:
        return np.inf
    sigma2 = sample_rate_hz / cn0  # noise per sample for a unit tone
    g2 = scale * np.sum(np.abs(np.conj(s1) + np.conj(s0) * w) ** 2)
    return float(np.sqrt(2.0 * sigma2 * g2) / abs(j2))


def fit_status(fit, max_rate_hz_per_s):
    """Status of a joint comb fit (:class:`~.fine.CombFit`): ``"ok"`` or the first failed check."""
    if not fit.snr >= fit.snr_threshold:
        return "weak comb"
    if not fit.position_margin_sigma >= AMBIGUITY_SIGMA:
        return "tone ambiguity"
    if not fit.tone_spread <= 1.0:
        return "overlapping combs"
    if not fit.sigma_hz <= INTERFERENCE_RATIO * fit.crlb_sigma_hz:
        return "interference"
    if not abs(fit.doppler_rate_hz_per_s) <= max_rate_hz_per_s:
        return "implausible rate"
    return "ok"
