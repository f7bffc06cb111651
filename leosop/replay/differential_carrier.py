"""``leosop replay ROVER --base BASE --base-site ... --carrier --static``: the differential carrier-phase fix.

Both recordings' identified satellites are tracked in carrier phase
(:func:`~leosop.replay.carrier_replay.replay_carrier`); the satellites in
both, on the blocks both recordings share (the same UTC block centres,
within :data:`~leosop.positioning.differential_base.TIME_TOL_S`: recordings
that start together at the same rate and block length), go to
:func:`~leosop.positioning.differential_carrier.solve_differential_carrier`
with the element-set states for each receiver (light time from the base's
site and from the rover's first guess).

Two fixes: the joint fit (each receiver's own phase, each satellite's
frequency a line: the base at its known site sees the element-set offsets'
whole range), which is the one reported, and the single differences (no
assumption on the satellites' oscillators) beside it. Each tries integer
ambiguities: the tracker's phase is the received central tone's up to whole
cycles (:mod:`leosop.replay.carrier`), so the double differences are
integers plus geometry; LAMBDA fixes those that pass its ratio test and
success-rate bound, and the float fix stays beside the final one.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..frames import C_e_n, ecef_to_geodetic
from ..positioning.differential_base import TIME_TOL_S
from ..positioning.differential_carrier import CHI2_ALPHA, RATIO_MIN, SUCCESS_MIN, solve_differential_carrier
from ..positioning.measurements import sv_states_from_tle
from ..timebase import format_utc, seconds_since

__all__ = ["INTEGER_NOTE", "SAT_CLOCK_DEGREE", "CarrierPair", "differential_carrier_fix"]

#: Degree of each satellite's frequency polynomial in the joint fit (offset and drift, as
#: :mod:`~leosop.positioning.differential_sim` and ``leosop generate`` model the oscillators).
SAT_CLOCK_DEGREE = 1
#: How the replay's ambiguities are fixed (the JSON says it).
INTEGER_NOTE = (f"integer ambiguities by LAMBDA where the ratio test ({RATIO_MIN:g}) and the bootstrapped success rate "
                f"({SUCCESS_MIN:g}) pass; 'ambiguities' says fixed, partial or float, 'float' holds the float fix")


@dataclass(frozen=True, eq=False)
class CarrierPair:
    """The differential carrier-phase fixes of a rover from a base.

    Attributes
    ----------
    sat_id : tuple of str, (n_sats,)
        Satellites tracked in both recordings.
    time_utc : ndarray of datetime64[ns], (n_epochs,)
        The blocks both share.
    joint, single_difference : CarrierFix
        :func:`~leosop.positioning.differential_carrier.solve_differential_carrier` with
        ``sat_clock_degree`` :data:`SAT_CLOCK_DEGREE` and None.
    """

    sat_id: tuple
    time_utc: np.ndarray
    joint: object
    single_difference: object

    def doc(self):
        """The JSON ``differential_carrier`` block: the joint fix's keys, ``single_difference`` the other's."""
        return {**_fix_doc(self.joint), "model": "joint", "sat_clock_degree": SAT_CLOCK_DEGREE,
                "sat_ids": list(self.sat_id), "start_utc": format_utc(self.time_utc[0]),
                "end_utc": format_utc(self.time_utc[-1]), "integer_note": INTEGER_NOTE,
                "single_difference": _fix_doc(self.single_difference)}


def _position_doc(pos_ecef_m, cov):
    """A position's JSON keys: ECEF, geodetic and the sigmas in east / north / up."""
    lat, lon, alt = ecef_to_geodetic(pos_ecef_m)
    C = C_e_n(lat, lon)
    sig = np.sqrt(np.diag(C.T @ cov @ C))
    return {"x_m": float(pos_ecef_m[0]), "y_m": float(pos_ecef_m[1]), "z_m": float(pos_ecef_m[2]),
            "lat_deg": float(np.degrees(lat)), "lon_deg": float(np.degrees(lon)), "alt_m": float(alt),
            "sigma_enu_m": [float(v) for v in sig], "cov_ecef_m2": [[float(v) for v in row] for row in cov]}


def _fix_doc(fix):
    """A fix's JSON keys: ``status`` ``ok`` when its residuals pass their chi-square test (else
    ``inconsistent``, its sigmas scaled by ``variance_factor``), the position (fixed where ``ambiguities`` says
    so; ``float`` the float one), sigmas and ECEF covariance, the integer test's ``ratio``, the float
    double-difference ambiguities and their sigmas, and counts."""
    ok = np.isfinite(fix.chi2_p) and fix.chi2_p >= CHI2_ALPHA
    return {"status": "ok" if ok else "inconsistent", "ambiguities": fix.status,
            **_position_doc(fix.pos_ecef_m, fix.cov), "float": _position_doc(fix.pos_float_ecef_m, fix.cov_float),
            "ratio": float(fix.ratio) if np.isfinite(fix.ratio) else None,
            "ambiguity_cycles": [float(v) for v in fix.ambiguity_cycles],
            "ambiguity_sigma_cycles": [float(v) for v in fix.ambiguity_sigma_cycles], "chi2": fix.chi2, "dof": fix.dof,
            "variance_factor": fix.variance_factor,
            "chi2_p": fix.chi2_p, "n_rows": fix.n_rows, "n_epochs": fix.n_epochs, "n_sats": fix.n_sats,
            "n_ambiguities": fix.n_ambiguities, "n_fixed": fix.n_fixed,
            "residual_rms_m": float(np.sqrt(np.nanmean(fix.residuals_m**2)))}


def differential_carrier_fix(rover, base, constellation, base_pos_ecef_m, pos0_ecef_m, *, carrier_hz):
    """The rover's differential carrier-phase fixes from two replays' carrier tracks.

    Parameters
    ----------
    rover, base : ReplayCarrier
        :func:`~leosop.replay.carrier_replay.replay_carrier` of each recording.
    constellation : Constellation
    base_pos_ecef_m, pos0_ecef_m : array_like, (3,)
        The base's known site; the rover's first guess (its differential Doppler fix: metres).
    carrier_hz : float

    Returns
    -------
    CarrierPair

    Raises
    ------
    InputError
        No satellite tracked in both; the two recordings' blocks not at the same instants.
    """
    common = sorted(set(rover.sat_id) & set(base.sat_id))
    if not common:
        raise InputError(f"no satellite tracked in carrier phase by both: the rover {', '.join(rover.sat_id)}, "
                         f"the base {', '.join(base.sat_id) or 'none'}")
    dt_s = seconds_since(base.time_utc, rover.time_utc[0])
    t_s = seconds_since(rover.time_utc, rover.time_utc[0])
    j = np.minimum(np.searchsorted(dt_s, t_s - TIME_TOL_S), dt_s.size - 1)   # the base block at each rover block
    on = np.abs(dt_s[j] - t_s) <= TIME_TOL_S
    if on.sum() < 2:
        raise InputError(f"the base's blocks are not at the rover's instants (first {format_utc(base.time_utc[0])} "
                         f"against {format_utc(rover.time_utc[0])}): differential carrier phase needs recordings "
                         "that start together, at the same sample rate and block length")
    i_r = [rover.sat_id.index(s) for s in common]
    i_b = [base.sat_id.index(s) for s in common]
    k_r, k_b = np.flatnonzero(on), j[on]
    time_utc = rover.time_utc[k_r]
    r, b = (rover.tracks, np.ix_(i_r, k_r)), (base.tracks, np.ix_(i_b, k_b))
    ids = np.repeat(np.array(common), k_r.size)
    times = np.tile(time_utc, len(common))
    shape = (len(common), k_r.size, 3)
    pos0 = np.asarray(pos0_ecef_m, dtype=float)
    p_r, _, _ = sv_states_from_tle(constellation, ids, times, pos0)
    p_b, v_b, _ = sv_states_from_tle(constellation, ids, times, np.asarray(base_pos_ecef_m, dtype=float))
    phases = [getattr(tracks, name)[at] for tracks, at in (r, b)
              for name in ("phase_cycles", "phase_sigma_cycles", "arc")]
    args = (t_s[k_r], *phases, p_r.reshape(shape), p_b.reshape(shape), v_b.reshape(shape), base_pos_ecef_m, pos0)
    fixes = [solve_differential_carrier(*args, carrier_hz=carrier_hz, sat_clock_degree=deg)
             for deg in (SAT_CLOCK_DEGREE, None)]
    return CarrierPair(tuple(common), time_utc, *fixes)
