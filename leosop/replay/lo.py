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
is in the estimate.
"""

from dataclasses import dataclass

import numpy as np

__all__ = ["LO_DRIFT_MAX_HZ_PER_S", "LO_OFFSET_MAX_HZ", "LoEstimate", "lo_estimate"]

#: Default bound of the receiver's common offset searched [Hz]: PLL LNBs are within ~+-25 ppm of
#: 10.6-10.75 GHz at the worst (+-270 kHz); typical ones within a few ppm (tens of kHz). Free-running
#: (DRO) LNBs reach +-1-3 MHz: search them with ``lo_offset_max_hz=3e6``.
LO_OFFSET_MAX_HZ = 100e3
#: Default bound of the common offset's drift [Hz/s]: an LNB warming up drifts tens of Hz/s.
LO_DRIFT_MAX_HZ_PER_S = 50.0


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
    """

    offset_hz: float
    offset_sigma_hz: float
    drift_hz_per_s: float
    drift_sigma_hz_per_s: float
    t_ref_utc: np.datetime64
    source: str


def lo_estimate(identification, position=None, measurements=None):
    """The best estimate of the common receiver offset a replay has, or None.

    Parameters
    ----------
    identification : Identification or None
    position : PositionResult, optional
        A static fix from several satellites with one receiver clock
        (``clock="common"``) gives the estimate when it solved.
    measurements : Measurements, optional
        The fix's table (its ``epoch_utc`` is the origin of the fix's times).

    Returns
    -------
    LoEstimate or None
        None when neither the fix nor the identification found a solution.
    """
    fix = None if position is None else position.fixes
    poly = getattr(fix, "rx_clock_poly_hz", None)
    if poly is not None and len(poly) > 1 and np.all(np.isfinite(poly)) and measurements is not None:
        sd = np.sqrt(np.diag(fix.cov)[3:5])
        t_ref = measurements.epoch_utc + np.timedelta64(int(round(fix.rx_t_ref_s * 1e9)), "ns")
        return LoEstimate(float(poly[0]), float(sd[0]), float(poly[1]), float(sd[1]), t_ref, "static fix")
    if identification is None or not np.isfinite(identification.lo_offset_hz):
        return None
    ident = identification
    return LoEstimate(ident.lo_offset_hz, ident.lo_offset_sigma_hz, ident.lo_drift_hz_per_s,
                      ident.lo_drift_sigma_hz_per_s, ident.t_ref_utc, "identification")
