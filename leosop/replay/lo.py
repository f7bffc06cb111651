"""The receiver's common frequency offset and drift (the LNB's local oscillator), as a replay estimates it.

Every track's Doppler carries the same receiver offset: the LNB's local
oscillator error (tens of kHz for PLL types, MHz for free-running ones)
plus the SDR's own, drifting with temperature. The identification searches
it as a nuisance parameter (:mod:`leosop.replay.identify`); the static fix
estimates it with the position (clock ``"common"`` of
:func:`~leosop.positioning.static_passes.solve_static_passes`): one
offset and one drift over the recording.

What is estimated is the common part of all tracks' frequency offsets: the
satellites' own offsets (0-5 Hz for Starlink, [Shen 2024] Table 1) have a
zero-mean prior, so their mean is not separable from the receiver's and
is in the estimate, and its sigma is that of the sum (:func:`lo_estimate`).

The LO also has short-term noise: a Wiener (random-walk) phase of linewidth
beta moves every comb of a block alike by a frequency of variance
``3 beta / (5 pi T)`` over a T-long block
(:func:`~leosop.signal.frontend.wiener_doppler_sigma_hz`), independent from
block to block: 0.31 Hz for a 20 ms snapshot at 0.01 Hz (the ``consumer``
preset), as large as a detection's thermal sigma. The comb fit cannot see it
(any common linear phase is Doppler) and a static fix's clock polynomial does
not absorb it, so it shows as a common part of each block's residuals;
:func:`lo_noise` estimates beta from them, and the replay solves again with
one frequency state per block of that prior variance (``block_id`` of
:func:`~leosop.positioning.static_passes.solve_static_passes`): the
generalised least squares of rows whose covariance within a block is
``diag(sigma^2) + q 1 1^T``. The rows (DESIGN 4.3) keep their own sigmas;
``linewidth_hz`` tells what they share.

Before identification, a continuous recording's tracking blocks fit the
tone model through a rough offset, the median Doppler of the first full
search's combs (:func:`rough_lo_hz`).

A recording whose band cannot hold the combs, its centre too far from
every channel for the offsets searched, is refused before any work
(:func:`check_band`).
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.stats import chi2 as chi2_dist

from ..constellations import DEFAULT_FAMILY, REGISTRY
from ..errors import InputError
from ..signal.coarse import MAX_DOPPLER_HZ
from ..signal.frontend import wiener_doppler_sigma_hz

__all__ = ["LO_DRIFT_MAX_HZ_PER_S", "LO_OFFSET_MAX_HZ", "ROUGH_LO_MIN_COMBS", "ROUGH_LO_MIN_HZ", "LoEstimate",
           "LO_NOISE_PFA", "LoNoise", "check_band", "common_offset_sigma_hz", "lo_estimate", "lo_noise", "rough_lo_hz"]

#: Default bound of the receiver's common offset searched [Hz]: PLL LNBs are within ~+-25 ppm of
#: 10.6-10.75 GHz at the worst (+-270 kHz); typical ones within a few ppm (tens of kHz). Free-running
#: (DRO) LNBs reach +-1-3 MHz: search them with ``lo_offset_max_hz=3e6``.
LO_OFFSET_MAX_HZ = 100e3
#: Default bound of the common offset's drift [Hz/s]: an LNB warming up drifts tens of Hz/s.
LO_DRIFT_MAX_HZ_PER_S = 50.0

#: A continuous recording's tracking blocks fit the tone model through the median Doppler of the first
#: full search's combs when it is beyond this [Hz] (:func:`rough_lo_hz`): satellites' Doppler alone
#: rarely puts the median of a handful of combs this far from 0 Hz.
ROUGH_LO_MIN_HZ = 0.5 * MAX_DOPPLER_HZ
#: Combs a full search must find for :func:`rough_lo_hz` to take their median.
ROUGH_LO_MIN_COMBS = 3
#: :func:`lo_noise` reports LO noise when the blocks' common residuals exceed the ``1 - LO_NOISE_PFA``
#: quantile of their chi-square without it: a recording without LO noise is left alone but this often.
LO_NOISE_PFA = 1e-3


@dataclass(frozen=True)
class LoEstimate:
    """The common receiver offset at ``t_ref_utc`` and its drift, with 1-sigma.

    Attributes
    ----------
    offset_hz, offset_sigma_hz : float
    drift_hz_per_s, drift_sigma_hz_per_s : float
    t_ref_utc : numpy.datetime64
        The instant the offset refers to (``offset + drift * (t - t_ref)``).
    source : str
        ``"static fix"`` or ``"identification"`` (a snapshot replay's joint
        least squares of the identified tracks, or when the fix failed).
    linewidth_hz : float or None
        The LO's Wiener linewidth the static fix's residuals show
        (:func:`lo_noise`; 0 when not significant), None without a static fix.
    """

    offset_hz: float
    offset_sigma_hz: float
    drift_hz_per_s: float
    drift_sigma_hz_per_s: float
    t_ref_utc: np.datetime64
    source: str
    linewidth_hz: float | None = None


def lo_estimate(identification, position=None, measurements=None, noise=None):
    """The best estimate of the common receiver offset a replay has, or None.

    Parameters
    ----------
    identification : Identification or None
    position : PositionResult, optional
        A static fix from several satellites with one receiver clock
        (``clock="common"``) gives the estimate when it solved.
    measurements : Measurements, optional
        The fix's table (its ``epoch_utc`` is the origin of the fix's times).
    noise : LoNoise, optional
        The LO noise the fix's residuals showed (:func:`lo_noise`).

    Returns
    -------
    LoEstimate or None
        None when neither the fix nor the identification found a solution.
    """
    fix = None if position is None else position.fixes
    poly = getattr(fix, "rx_clock_poly_hz", None)
    if poly is not None and len(poly) > 1 and np.all(np.isfinite(poly)) and measurements is not None:
        t_ref = measurements.epoch_utc + np.timedelta64(int(round(fix.rx_t_ref_s * 1e9)), "ns")
        return LoEstimate(float(poly[0]), common_offset_sigma_hz(fix), float(poly[1]), float(np.sqrt(fix.cov[4, 4])),
                          t_ref, "static fix", None if noise is None else noise.linewidth_hz)
    if identification is None or not np.isfinite(identification.lo_offset_hz):
        return None
    ident = identification
    return LoEstimate(ident.lo_offset_hz, ident.lo_offset_sigma_hz, ident.lo_drift_hz_per_s,
                      ident.lo_drift_sigma_hz_per_s, ident.t_ref_utc, "identification")


@dataclass(frozen=True)
class LoNoise:
    """The receiver LO's short-term frequency noise seen in a static fix's residuals.

    Attributes
    ----------
    linewidth_hz : float
        Wiener (Lorentzian) linewidth beta [Hz]; 0 when the residuals show
        none significant (:data:`LO_NOISE_PFA`).
    chi2 : float
        The blocks' weighted mean residuals squared over their variances
        without LO noise: chi-square of ``n_blocks`` degrees of freedom
        when there is none (a little less: the fix absorbs some).
    n_blocks : int
        Blocks (instants) with at least one residual.
    """

    linewidth_hz: float
    chi2: float
    n_blocks: int

    def sigma_hz(self, block_s):
        """Sigma it adds to a block's Doppler [Hz], common to the block's combs, shape of ``block_s``."""
        return wiener_doppler_sigma_hz(self.linewidth_hz, block_s)


def lo_noise(residuals_hz, sigma_hz, block_id, block_s, *, pfa=LO_NOISE_PFA):
    """The LO linewidth the common part of each block's residuals implies.

    Each block's inverse-variance weighted mean residual ``m`` has variance
    ``V = 1 / sum(1 / sigma^2)`` from the rows' own noise, plus
    ``3 beta / (5 pi T)`` from the LO's Wiener phase over the block of
    length T. When ``sum(m^2 / V)`` exceeds the chi-square's ``1 - pfa``
    quantile, beta solves ``sum(m^2 / (V + 3 beta / (5 pi T))) = n_blocks``
    (the moment estimator of a random effect, [Paule 1982]). The
    fix's states absorb a little of the common part (its clock
    polynomial wholly), so beta comes out slightly low. The replay takes
    the residuals of a fix without block states and then solves again with
    one state per block of prior variance ``3 beta / (5 pi T)``: the moment
    estimate feeds the exact model (a likelihood maximised over beta under
    that model would need a fix per trial beta).

    Parameters
    ----------
    residuals_hz, sigma_hz : ndarray, (n,)
        A static fix's residuals of the rows it used and their sigmas.
    block_id : ndarray, (n,)
        The block of each row (its time): rows of one block share the LO's phase.
    block_s : ndarray, (n,)
        Length of each row's block [s].
    pfa : float

    Returns
    -------
    LoNoise
    """
    _, inv = np.unique(block_id, return_inverse=True)
    w = 1.0 / np.asarray(sigma_hz, dtype=float) ** 2
    sw = np.bincount(inv, w)
    m = np.bincount(inv, w * residuals_hz) / sw
    v = 1.0 / sw
    k = wiener_doppler_sigma_hz(1.0, np.bincount(inv, block_s) / np.bincount(inv)) ** 2  # Hz^2 per Hz of beta
    n = m.size
    q = float(np.sum(m**2 / v))
    if n == 0 or q <= chi2_dist.isf(pfa, n):
        return LoNoise(0.0, q, n)
    excess = lambda beta: float(np.sum(m**2 / (v + k * beta))) - n  # noqa: E731
    hi = float(np.max(m**2 / k))  # there every term is below 1
    return LoNoise(float(brentq(excess, 0.0, hi)), q, n)


def common_offset_sigma_hz(fix):
    """Sigma of the common offset a static fix estimates: its receiver offset plus its satellites' mean offset.

    The satellites' offsets have a zero-mean prior, so the fix's receiver
    offset is that sum (module docstring); its own variance would add the
    prior's uncertainty of the mean, which is no error of the sum.

    Parameters
    ----------
    fix : PassesFix
        Clock ``"common"``; its covariance is ordered ``[pos (3), receiver
        polynomials, satellite offsets, time offsets]``.

    Returns
    -------
    float
    """
    n_rx, n_sat = fix.rx_clock_polys_hz.size, len(fix.sat_offset_hz)
    a = np.zeros(len(fix.cov))
    a[3] = 1.0
    a[3 + n_rx:3 + n_rx + n_sat] = 1.0 / n_sat
    return float(np.sqrt(a @ fix.cov @ a))


def rough_lo_hz(doppler_hz):
    """The LO offset a continuous recording's tracking blocks fit their tone model through, from one full search.

    The Doppler-only tone model misplaces a comb's edge tones by 15 Hz at a
    1 MHz LO offset, a cycle and a half over a 0.1 s block: tracked combs
    lose most of their edge tones' power, fall below the detector and their
    tracks break up, and no refit (:func:`~leosop.replay.refit.refit_through_lo`) brings back a
    detection the first pass did not make. The median of the combs'
    Dopplers is the offset to ~100 kHz (their geometric parts spread
    +-200 kHz round it), which leaves the edge tones within 1.5 Hz.

    Parameters
    ----------
    doppler_hz : ndarray, (n_combs,)
        The combs of a full search.

    Returns
    -------
    float or None
        The median when it lies beyond :data:`ROUGH_LO_MIN_HZ`, else 0 (the
        Doppler-only model); None with fewer than :data:`ROUGH_LO_MIN_COMBS`
        combs (the next full search tries again).
    """
    if len(doppler_hz) < ROUGH_LO_MIN_COMBS:
        return None
    median = float(np.median(doppler_hz))
    return median if abs(median) > ROUGH_LO_MIN_HZ else 0.0


def check_band(rec, half_comb_hz, lo_offset_max_hz):
    """Refuse a recording whose band cannot contain the pilot combs at the offsets searched.

    The combs lie at the nearest channel of the default family
    (``channels_hz``) less the recording's centre, within the receiver's
    offset (``lo_offset_max_hz``), the satellites' Doppler
    (:data:`~leosop.signal.coarse.MAX_DOPPLER_HZ`) and the comb's half-width;
    the recording holds its centre +- half its sample rate. A recording
    without a centre frequency is taken to be centred on the comb's carrier.

    Parameters
    ----------
    rec : Recording
        ``center_hz`` (or None), ``sample_rate_hz`` and ``data_path``.
    half_comb_hz : float
        The comb's outermost tone's offset from its carrier.
    lo_offset_max_hz : float
        Bound of the receiver's common offset searched.

    Raises
    ------
    InputError
        When no part of the combs' band lies within the recorded one.
    """
    if rec.center_hz is None:
        return
    channels_hz = np.asarray(REGISTRY[DEFAULT_FAMILY].channels_hz)
    channel_hz = float(channels_hz[np.argmin(np.abs(channels_hz - rec.center_hz))])
    at_hz = channel_hz - rec.center_hz
    reach_hz = lo_offset_max_hz + MAX_DOPPLER_HZ + half_comb_hz
    if abs(at_hz) - reach_hz > 0.5 * rec.sample_rate_hz:
        raise InputError(
            f"{rec.data_path}: its band ({rec.center_hz / 1e6:.4f} MHz +- {0.5e-6 * rec.sample_rate_hz:g} MHz, "
            f"{rec.sample_rate_hz / 1e6:g} MS/s) does not contain the pilot combs: at the channel "
            f"{channel_hz / 1e6:.4f} MHz they would be at {at_hz / 1e6:+.4f} MHz +- {reach_hz / 1e6:.4f} MHz "
            f"(Doppler, comb span and lo_offset_max_hz {lo_offset_max_hz:g})", param="lo_offset_max_hz")
