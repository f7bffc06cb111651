"""LEO Doppler for ``leosop fuse``: read from a DESIGN 4.3 table or simulated along the GNSS reference (4.5).

Both give a :class:`leosop.positioning.measurements.Measurements` (with
satellite states and UTC times) and :func:`to_aids` turns it into the
engine's :class:`leosop.fusion.aids_leo.LeoDoppler` aids on the run's clock
(seconds after the first epoch of the ``--gnss`` file, GPST); with a base's
table (``--leo-base``) :func:`to_differential_aids` makes the differential
aids of :mod:`leosop.fusion.aids_differential` instead.

Simulation (:func:`simulate`): the reference trajectory is the ``Q = 1``
epochs of the GNSS file, linearly interpolated to the scenario's fix rate
(1 Hz) where a fix lies within :data:`MAX_GAP_S` on both sides; its
velocity is the difference of the interpolated positions 0.5 s either side
(RTK positions are cm-level, so this velocity is good to ~0.02 m/s, 0.7 Hz
of Doppler at 11.3 GHz; the .pos velocities are RTKLIB's Doppler velocities,
several times noisier). That velocity is not the vehicle's to better than
:data:`REF_VEL_SIGMA_MPS` (RTK noise, jerk within the 1 s chord), which the
rows' ``sigma_hz`` carry beside the estimator's noise. The chord is the
mean velocity over that second, as a Doppler estimated over a 1 s
integration measures it: on a turn at rate ``w`` it reads the speed short
by the factor ``sin(w / 2) / (w / 2)`` (0.11 m/s at 10 m/s and 30 deg/s,
RMS 0.04 m/s against a five-point difference of the 4 Hz fixes on the
drive). That velocity, or an exact Doppler without offsets or noise, does
not bring the drive's outage errors inside 3 sigma (docs/fusion-real.md). The Doppler then comes from ``simulate``'s own
measurement level (``leosop.apps.simulate.measure.leo_fixes``, called, not copied) with
the satellite offsets, orbit errors, receiver offsets, masks and C/N0 of
the bundled ``xian-baoji`` scenario and the families asked for.
"""

import dataclasses

import numpy as np

from .. import frames
from ..constants import C_MPS
from ..errors import InputError
from ..fusion.aids_differential import differential_aids
from ..fusion.aids_leo import LeoOptions, leo_aids
from ..gnss.ppp import gps_to_utc
from ..gnss.rtklib_pos import Q_FIX
from ..positioning import measurements as pm
from ..timebase import format_utc
from .scenarios import XIAN_BAOJI

__all__ = ["MAX_GAP_S", "REF_VEL_SIGMA_MPS", "SIM_WINDOW_S", "gpst_to_utc", "read", "reference_track", "simulate",
           "to_aids", "to_differential_aids"]

#: A reference epoch needs a Q = 1 fix at most this far before and after it [s].
MAX_GAP_S = 1.0
#: Uncertainty of the reference velocity per axis [m/s], in the simulated rows' sigma: set where the LEO
#: Doppler innovations' RMS over their predicted sigma is 1 while the GNSS aids are on (the drive: 1.43
#: without it, 1.02 with 0.025 m/s; tools/bench_fuse.py --leo-sim), not on the outage errors.
REF_VEL_SIGMA_MPS = 0.025
#: The simulated Doppler's integration time [s]: its velocity is the chord over [t - 0.5, t + 0.5] s, so the
#: aids that fit it model the mean velocity over this window (``LeoOptions.window_s``).
SIM_WINDOW_S = 1.0


def gpst_to_utc(t_gpst_s):
    """Unix-style GPST seconds -> UTC ``datetime64[ns]`` (leap seconds of :func:`leosop.gnss.ppp.gps_to_utc`)."""
    return gps_to_utc((np.asarray(t_gpst_s, dtype=float) * 1e9).round().astype("datetime64[ns]"))


def _run_seconds(time_utc, sol):
    """UTC times of a table -> seconds after the first GNSS epoch (GPST)."""
    return (time_utc - gpst_to_utc(sol.t_gpst_s[0])) / np.timedelta64(1, "s")


def _check_overlap(meas, t_s, sol):
    """Refuse a table none of whose rows (``t_s`` on the run's clock) falls within the GNSS file's span: its aids
    would all be left unused, as GNSS epochs outside the IMU log are refused. No GNSS file (None): no check."""
    if sol is None:
        return
    span = float(sol.t_gpst_s[-1] - sol.t_gpst_s[0])
    if not np.any((t_s >= 0.0) & (t_s <= span)):
        when = (f"{format_utc(meas.time_utc.min())} .. {format_utc(meas.time_utc.max())}"
                if meas.time_utc is not None else f"t_s {t_s.min():g} .. {t_s.max():g} s")
        gnss = gpst_to_utc(sol.t_gpst_s[[0, -1]])
        raise InputError(f"{meas.source}: no row during the GNSS file {sol.source} (rows {when}; the GNSS file "
                         f"{format_utc(gnss[0])} .. {format_utc(gnss[1])})")


def reference_track(sol, rate_hz=1.0):
    """The Q = 1 fixes of ``sol`` at ``rate_hz``: times on the run's clock, antenna position and velocity (ECEF).

    Returns
    -------
    t_s : ndarray, (n,)
        Seconds after the first GNSS epoch, every ``1 / rate_hz`` from the first to the last fix.
    pos_ecef_m, vel_ecef_mps : ndarray, (n, 3)
    valid : ndarray of bool, (n,)
        Fixes within :data:`MAX_GAP_S` on both sides of ``t_s`` and of ``t_s +- 0.5 s``.
    """
    fix = np.flatnonzero(sol.q == Q_FIX)
    if fix.size < 2:
        raise InputError(f"{sol.source}: a reference trajectory needs at least 2 Q = 1 fixes, found {fix.size}")
    tf = sol.t_gpst_s[fix] - sol.t_gpst_s[0]
    pf = frames.geodetic_to_ecef(np.radians(sol.lat_deg[fix]), np.radians(sol.lon_deg[fix]), sol.alt_m[fix])
    t_s = np.arange(tf[0] + 0.5, tf[-1] - 0.5, 1.0 / rate_hz)

    def at(t):
        pos = np.stack([np.interp(t, tf, pf[:, c]) for c in range(3)], axis=-1)
        k = np.clip(np.searchsorted(tf, t), 1, tf.size - 1)
        return pos, (t - tf[k - 1] <= MAX_GAP_S) & (tf[k] - t <= MAX_GAP_S)

    pos, ok = at(t_s)
    (before, ok_b), (after, ok_a) = at(t_s - 0.5 * SIM_WINDOW_S), at(t_s + 0.5 * SIM_WINDOW_S)
    return t_s, pos, (after - before) / SIM_WINDOW_S, ok & ok_b & ok_a


def simulate(sol, *, tle=None, constellations=("starlink",), seed=0):
    """LEO Doppler simulated along the reference trajectory of ``sol`` (module notes).

    Parameters
    ----------
    sol : leosop.gnss.rtklib_pos.PosSolution
    tle : path, optional
        Element sets; default the bundled sky of ``simulate``.
    constellations : sequence of str
        Transmitting families (keys of :data:`leosop.constellations.REGISTRY`).
    seed : int
        Seeds the satellite offsets and orbit errors, and the measurement noise (two streams).

    Returns
    -------
    Measurements
        ``time_utc`` at the reference epochs, satellite states as the
        receiver knows them (with the orbit errors), ``family`` per row.
    """
    from .simulate import measure, sky

    leo = dataclasses.replace(XIAN_BAOJI.leo, constellations=tuple(constellations))
    scenario = dataclasses.replace(XIAN_BAOJI, name="fuse --leo-sim", leo=leo)
    t_s, pos, vel, valid = reference_track(sol, leo.fix_rate_hz)
    times_utc = gpst_to_utc(sol.t_gpst_s[0] + t_s)
    constellation, family_sat = sky.transmitters(leo.constellations, tle, times_utc[[0, -1]])
    models = sky.family_models(leo)
    rng_sat, rng_meas = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    # The scenario's satellite errors, drawn as run_scenario draws them: offsets uniform in [0, max], orbit
    # errors normal per ECEF axis (independent model).
    offset_max = leo.sat_doppler_offset_max_hz * models["clock_scale"][family_sat]
    offset = offset_max * rng_sat.uniform(0.0, 1.0, len(constellation))
    orbit_err = leo.orbit_error_m * rng_sat.standard_normal((len(constellation), 3))
    _, pairs = measure.leo_fixes(scenario, constellation, family_sat, models, times_utc, t_s, pos, vel, pos, vel,
                                 offset, offset_max, orbit_err, level="measurement", coupling="tight",
                                 orbit_error_m=leo.orbit_error_m, orbit_error_model=leo.orbit_error_model,
                                 rng_meas=rng_meas, progress=None)
    ep, sat = pairs["epoch_index"], pairs["sat_index"]
    keep = valid[ep] & np.isfinite(pairs["doppler_hz"])
    ep, sat = ep[keep], sat[keep]
    return pm.Measurements(
        t_s=t_s[ep], time_utc=times_utc[ep], sat_id=np.asarray(constellation.sat_ids)[sat],
        doppler_hz=pairs["doppler_hz"][keep], carrier_hz=pairs["carrier_hz"][keep],
        sigma_hz=np.hypot(pairs["sigma_hz"][keep], REF_VEL_SIGMA_MPS * pairs["carrier_hz"][keep] / C_MPS),
        pos_sv_ecef_m=pairs["pos_sv_ecef_m"][keep], vel_sv_ecef_mps=pairs["vel_sv_ecef_mps"][keep],
        line=np.arange(ep.size) + 2, source="leo-sim",
        family=np.asarray(leo.constellations)[pairs["clock_index"][keep]])


def read(path, sol, *, tle=None, site_ecef_m=None):
    """A DESIGN 4.3 table for ``fuse``: satellite states from its columns, else from ``tle`` (needs ``time_utc``).

    A table with ``t_s`` only is taken on the run's clock (seconds after the
    first GNSS epoch). Light time of TLE states: to ``site_ecef_m`` (3,) (a
    base at rest), else to the GNSS antenna interpolated at each row.
    """
    from ..orbits import load_constellation

    constellation = load_constellation(tle) if tle else None
    meas = pm.read_measurements(path, constellation=constellation)
    if meas.pos_sv_ecef_m is not None:
        return meas
    if constellation is None or meas.time_utc is None:
        raise InputError(f"{path}: no satellite state columns ({', '.join(pm.SV_STATE_COLUMNS)}); give tle and "
                         "a time_utc column", param="tle")
    if site_ecef_m is not None:
        rx = np.broadcast_to(np.asarray(site_ecef_m, dtype=float), (len(meas), 3))
    else:
        t = _run_seconds(meas.time_utc, sol)
        t_g = sol.t_gpst_s - sol.t_gpst_s[0]
        p = frames.geodetic_to_ecef(np.radians(sol.lat_deg), np.radians(sol.lon_deg), sol.alt_m)
        rx = np.stack([np.interp(t, t_g, p[:, c]) for c in range(3)], axis=-1)
    pos, vel, reason = pm.sv_states_from_tle(constellation, meas.sat_id, meas.time_utc, rx)
    ok = reason == ""
    if not ok.any():
        raise InputError(f"{path}:{meas.line[0]}: {reason[0]}")
    return dataclasses.replace(meas.take(np.flatnonzero(ok)), pos_sv_ecef_m=pos[ok], vel_sv_ecef_mps=vel[ok])


def to_aids(meas, sol, lever_arm_b_m, options=None):
    """The table's rows as LEO Doppler aids on the run's clock, one receiver clock per constellation.

    Parameters
    ----------
    meas : Measurements
        With satellite states.
    sol : leosop.gnss.rtklib_pos.PosSolution
        Its first epoch is the run's time origin.
    lever_arm_b_m : array_like, (3,)
    options : LeoOptions, optional

    Returns
    -------
    aids : list of leosop.fusion.aids_leo.LeoDoppler (and LeoWindowStart with ``options.window_s``)
    clock_labels : tuple of str
    """
    options = options or LeoOptions()
    index, labels = pm.clock_groups(meas)
    t = meas.t_s if meas.time_utc is None else _run_seconds(meas.time_utc, sol)
    _check_overlap(meas, t, sol)
    aids = leo_aids(t, meas.sat_id, np.asarray(labels)[index], meas.doppler_hz, meas.sigma_hz, meas.carrier_hz,
                    meas.pos_sv_ecef_m, meas.vel_sv_ecef_mps, lever_arm_b_m, options)
    aids.sort(key=lambda a: a.t_s)
    return aids, labels


def to_differential_aids(rover, base, sol, site_ecef_m, lever_arm_b_m, options=None):
    """A rover's and a base's tables as differential aids on the run's clock (Doppler, and carrier with phases).

    Parameters
    ----------
    rover, base : Measurements
        With satellite states; one receiver clock each (one constellation).
    sol : leosop.gnss.rtklib_pos.PosSolution
        Its first epoch is the run's time origin.
    site_ecef_m : array_like, (3,)
        The base's known position.
    lever_arm_b_m : array_like, (3,)
    options : leosop.fusion.aids_differential.DifferentialOptions, optional

    Returns
    -------
    list of Aid
        :func:`leosop.fusion.aids_differential.differential_aids`, sorted by ``t_s``.

    Raises
    ------
    InputError
        A table with several receiver clocks, or no rover row with a base correction.
    """
    for meas in (rover, base):
        labels = pm.clock_groups(meas)[1]
        if len(labels) > 1:
            raise InputError(f"{meas.source}: rows of several receiver clocks ({', '.join(labels)}); a differential "
                             "table has one constellation")
    on_clock = [dataclasses.replace(m, t_s=m.t_s if m.time_utc is None else _run_seconds(m.time_utc, sol))
                for m in (rover, base)]
    _check_overlap(rover, on_clock[0].t_s, sol)
    aids = differential_aids(*on_clock, site_ecef_m, lever_arm_b_m, options)
    if not aids:
        raise InputError(f"{base.source}: no row of {rover.source} has a base correction (no satellite in common "
                         "within the base's time span)")
    return aids
