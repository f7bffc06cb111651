"""Doppler tracks: one comb followed across blocks and capture gaps."""

from dataclasses import dataclass

import numpy as np

__all__ = ["Track"]


@dataclass
class Track:
    """The measurements of one comb over a recording.

    Attributes
    ----------
    t_s : ndarray, (n,)
        Block centres, seconds from the recording's first sample.
    time_utc : ndarray of datetime64[ns], (n,)
        The same instants in UTC.
    doppler_hz, doppler_rate_hz_per_s, cn0_dbhz, sigma_hz : ndarray, (n,)
        Central-tone Doppler (DESIGN 4.2 sign, clocks included), its rate,
        C/N0 per tone and the Doppler's standard deviation.
    sat_id : str or None
        NORAD catalogue number once identified; None while unknown or when no
        satellite explains the track.
    match_rms_hz : float or None
        RMS of the identified satellite's Doppler residuals.
    """

    t_s: np.ndarray
    time_utc: np.ndarray
    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray
    sat_id: str | None = None
    match_rms_hz: float | None = None

    def __len__(self):
        return len(self.t_s)
