"""``leosop position MEAS.csv``: Doppler fixes from a measurement table.

The table (CSV with a header row, one Doppler measurement per row): ``time_utc``
(ISO 8601) or ``t_s``, ``sat_id`` (NORAD number, looked up in ``--tle``) and
``doppler_hz`` (received minus nominal carrier, positive when approaching);
optional ``sigma_hz``, ``carrier_hz``, the satellite's ECEF state at the
measurement time ``x_sv_m, y_sv_m, z_sv_m, vx_sv_mps, vy_sv_mps, vz_sv_mps``
(then no element sets are needed) and ``pass_id`` (rows of one pass share a
transmitter frequency offset in a static fix).

Without ``--static`` one snapshot fix per epoch with at least 7 satellites
(position, velocity, frequency offset); with ``--static`` one batch fix of a
receiver at rest from all rows (position, frequency offset and drift),
optionally with a known height (``--alt-m``); when the table has a
``pass_id`` column, each pass gets its own frequency offset polynomial
(cubic) and the position is shared, and the JSON document lists the passes'
polynomials under ``passes`` (the solution's ``t_s``, ``clock_offset_hz``
and drift are those of the pass nearest the middle). Besides the contract's
``solutions``, the JSON document lists the ``rejected`` rows and
``unsolved`` epochs with their reasons; each solution carries a ``status``,
``ok`` only when the toolkit can vouch for the fix (else the reason:
no_redundancy, inconsistent, implausible_height, single_pass, few_passes, ...),
its redundancy ``dof`` and its residual test's ``chi2_p``.

With ``--base BASE.csv --base-site LAT,LON,ALT`` a base at a known site
measuring the same satellites corrects the rover (single differences by
satellite and time, the base interpolated to the rover's rows,
:mod:`leosop.positioning.differential`): one fix with ``--static``, else one
per ``--block-s``; the JSON document adds a ``differential`` block (what was
matched, the model) and each solution's clock is rover minus base.

Rows of several constellations may be mixed: a row's carrier is
its ``carrier_hz``, else its satellite's family's (the ``--tle`` names, the
carrier table), else ``--carrier-hz``; each constellation gets its own
receiver clock (a snapshot epoch then needs 6 + one satellite per
constellation it sees). Solutions of such files carry ``clock_offsets_hz``
(and with ``--static`` ``clock_drifts_hz_per_s``), a mapping from the
constellation (or ``"<carrier> Hz"`` for rows of no known family) to its
clock; ``clock_offset_hz`` is then that of the first one present.
"""

import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import atomic_files, check_output_file, write_csv, write_json
from ..frames import C_e_n, ecef_to_geodetic, geodetic_to_ecef
from ..geometry.doppler import N_DOPPLER_STATES
from ..orbits import load_constellation
from ..positioning.datasets import doptrack_table, read_doptrack, read_fll
from ..positioning.differential import MOTIONS
from ..positioning.differential_pair import solve_pair
from ..positioning.measurements import DEFAULT_CARRIER_HZ, read_measurements
from ..positioning.quality import STATUSES
from ..positioning.solve import position_snapshots, position_static, position_static_passes
from ..timebase import format_utc
from . import add_command
from .options import parse_site

#: The files of ``--out``, written all or none.
OUT_FILES = ("position.json", "fixes.csv", "residuals.csv")

_DESCRIPTION = " ".join(__doc__.split("\n\n")[1:3]).replace("\n", " ")


def register(subparsers):
    p = add_command(subparsers, "position", sys.modules[__name__], help="Doppler positioning from a measurement CSV",
                    description=_DESCRIPTION)
    p.add_argument("--format", choices=("table", "doptrack", "fll"), default="table",
                   help="table: the measurement CSV above (default); doptrack: MEAS is a folder with DopTrack's "
                   "data.tar.xz and metadata.tar.xz (one pass per file, each with its own element set and "
                   "pass_id; use --static); fll: a GNU Radio frequency-locked-loop log, CSV with "
                   "doppler_offset, timestamp (ISO UTC) and measured_freq columns, of the satellite --sat-id")
    p.add_argument("--sat-id", metavar="ID", help="catalogue number of the satellite of a --format fll log")
    p.add_argument("meas", metavar="MEAS.csv",
                   help="Doppler measurements: columns time_utc or t_s, sat_id, doppler_hz; "
                   "optional sigma_hz, carrier_hz, pass_id and the satellite state x_sv_m ... vz_sv_mps")
    p.add_argument("--tle", metavar="FILE", help="element sets for rows without satellite state columns "
                   "(default: the bundled constellation)")
    p.add_argument("--carrier-hz", type=float, metavar="F",
                   help="carrier of rows without carrier_hz and of no known constellation (default "
                   f"{DEFAULT_CARRIER_HZ:g} unless the file mixes carriers)")
    p.add_argument("--static", action="store_true", help="one batch fix of a receiver at rest; with a pass_id "
                   "column a cubic frequency offset per pass, position shared")
    p.add_argument("--clock", choices=("per_pass", "common"), default="per_pass",
                   help="with --static and pass_id: a frequency polynomial per pass (default), or one receiver "
                   "clock (offset, drift) plus a constant offset per satellite (multi-satellite receiver)")
    p.add_argument("--init", metavar="LAT_DEG,LON_DEG,ALT_M", help="start position (default: below the satellites)")
    p.add_argument("--alt-m", type=float, metavar="H", help="known height above the ellipsoid (with --static)")
    p.add_argument("--alt-sigma-m", type=float, default=10.0, metavar="S",
                   help="standard deviation of --alt-m (default %(default)g)")
    p.add_argument("--sigma-hz", type=float, metavar="S",
                   help="sigma of rows without sigma_hz (default: estimated from the residuals)")
    p.add_argument("--alpha", type=float, default=1e-3, metavar="P",
                   help="significance of the chi-square outlier test, 0 to disable (default %(default)g)")
    d = p.add_argument_group("differential", "a base at a known site measuring the same satellites: single "
                             "differences by satellite and time (the base interpolated to the rover's rows)")
    d.add_argument("--base", metavar="BASE.csv", help="the base's measurement table (same columns as MEAS.csv)")
    d.add_argument("--base-site", metavar="LAT_DEG,LON_DEG,ALT_M", help="the base's known position (with --base)")
    d.add_argument("--block-s", type=float, default=10.0, metavar="S",
                   help="without --static: one fix per block of S seconds (default %(default)g)")
    d.add_argument("--motion", choices=MOTIONS, default="rest",
                   help="the rover within a block: at rest (default) or at a constant velocity")
    d.add_argument("--sat-clock-degree", type=int, metavar="D",
                   help="joint fit of the base's and the rover's rows, each satellite's frequency a polynomial "
                   "of degree D over a block (1: offset and drift); stronger over short spans, right only while "
                   "the satellites' oscillators follow it (default: single differences)")
    return p


def _check(args):
    if args.alt_m is not None and not args.static:
        raise InputError("--alt-m constrains a static fix; add --static")
    for name in ("carrier_hz", "alt_sigma_m", "sigma_hz"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise InputError(f"--{name.replace('_', '-')} {value!r}: expected a positive number")
    if not 0 <= args.alpha < 1:
        raise InputError(f"--alpha {args.alpha!r}: expected a probability in [0, 1)")
    if (args.base is None) != (args.base_site is None):
        raise InputError("--base needs --base-site, the base's known position" if args.base else
                         "--base-site goes with --base, the base's measurement table")
    if args.base and (args.format != "table" or args.alt_m is not None):
        raise InputError("--base takes measurement tables (--format table) and no --alt-m")
    if not args.block_s > 0:
        raise InputError(f"--block-s {args.block_s!r}: expected a positive number")
    if args.sat_clock_degree is not None and not 0 <= args.sat_clock_degree <= 3:
        raise InputError(f"--sat-clock-degree {args.sat_clock_degree!r}: expected 0, 1, 2 or 3")


def _solution(t_s, time_utc, pos, vel, clock_hz, gdop, n_sats, n_used, iterations, rms, status, cov_pos):
    """One solution's JSON keys; ``status`` is ``(label, dof, chi2_p)`` (:func:`_statuses`)."""
    lat, lon, alt = ecef_to_geodetic(pos)
    C = C_e_n(lat, lon)
    sig_enu = np.sqrt(np.diagonal(C.T @ cov_pos @ C)) if np.isfinite(cov_pos).all() else [np.nan] * 3
    label, dof, chi2_p = status
    return {
        "t_s": float(t_s), "time_utc": None if time_utc is None else format_utc(time_utc),
        "lat_deg": float(np.degrees(lat)), "lon_deg": float(np.degrees(lon)), "alt_m": float(alt),
        "x_m": pos[0], "y_m": pos[1], "z_m": pos[2], "vx_mps": vel[0], "vy_mps": vel[1], "vz_mps": vel[2],
        "clock_offset_hz": clock_hz, "gdop": gdop, "n_sats": int(n_sats), "n_used": int(n_used),
        "iterations": int(iterations), "residual_rms_hz": rms, "status": str(label), "dof": int(dof),
        "chi2_p": float(chi2_p) if np.isfinite(chi2_p) else None, "sigma_enu_m": list(sig_enu),
    }


def _statuses(res, alpha=None):
    """``(label, dof, chi2_p)`` of each fix of ``res`` (``res.labels``), a list."""
    labels, chi2_p = res.labels(alpha)
    return list(zip(labels, np.atleast_1d(res.fixes.dof), chi2_p))


def solutions_doc(res, meas, alpha=None):
    """The JSON solutions of a PositionResult, its passes (several passes) and its residual rows.

    ``alpha`` is the significance of the residual test of each solution's
    status (:func:`~leosop.positioning.quality.fix_status`).

    Returns
    -------
    solutions : list of dict
        The contract's keys (DESIGN 4.1) plus ``status`` (see
        :mod:`leosop.positioning.quality`), ``dof``, ``chi2_p`` and ``sigma_enu_m``.
    passes : list of dict or None
        Each pass's frequency polynomial, for fixes from several passes.
    residuals : list of tuple
        ``(line, t_s, sat_id, residual_hz, used)`` per measurement.
    """
    from ..positioning.static import StaticFix
    from ..positioning.static_passes import PassesFix

    f = res.fixes
    utc = (lambda k: None) if res.time_utc is None else (lambda k: res.time_utc[k])  # noqa: E731
    passes = None
    if isinstance(f, PassesFix):
        mid = int(np.argmin(np.abs(res.t_s - 0.5 * (res.t_s.min() + res.t_s.max()))))
        (status,) = _statuses(res, alpha)
        sol = _solution(res.t_s[mid], utc(mid), f.pos_ecef_m, np.zeros(3), float(f.clock_offset_hz[mid]), f.gdop,
                        res.n_sats[0], f.n_used, f.iterations, f.residual_rms_hz, status, f.cov[:3, :3])
        sol["clock_drift_hz_per_s"] = float(f.clock_drift_hz_per_s[mid])
        if len(res.clock_labels) > 1 and f.rx_clock_polys_hz is not None:
            names = [res.clock_labels[j] for j in f.clock_labels]
            sol["clock_offsets_hz"] = dict(zip(names, _floats(f.rx_clock_polys_hz[:, 0])))
            if f.rx_clock_polys_hz.shape[1] > 1:
                sol["clock_drifts_hz_per_s"] = dict(zip(names, _floats(f.rx_clock_polys_hz[:, 1])))
        solutions = [sol]
        sigma_pass = res.sigma_hz_pass if res.sigma_hz_pass is not None else np.full(len(f.pass_ids), np.nan)
        passes = [{"pass_id": str(pid), "t_s": float(t), "clock_poly_hz": [float(c) for c in poly],
                   "sigma_hz": float(sg), "n_used": int(f.used[meas.pass_id == pid].sum())}
                  for pid, t, poly, sg in zip(f.pass_ids, f.t_ref_s, f.clock_poly_hz, sigma_pass)]
    elif isinstance(f, StaticFix):
        (status,) = _statuses(res, alpha)
        sol = _solution(res.t_s[0], utc(0), f.pos_ecef_m, np.zeros(3), f.clock_offset_hz, f.gdop, res.n_sats[0],
                        f.n_used, f.iterations, f.residual_rms_hz, status, f.cov[:3, :3])
        sol["clock_drift_hz_per_s"] = f.clock_drift_hz_per_s
        if len(res.clock_labels) > 1 and f.clock_polys_hz is not None:
            names = [res.clock_labels[j] for j in f.clock_labels]
            sol["clock_offsets_hz"] = dict(zip(names, _floats(f.clock_polys_hz[:, 0])))
            if f.clock_polys_hz.shape[1] > 1:
                sol["clock_drifts_hz_per_s"] = dict(zip(names, _floats(f.clock_polys_hz[:, 1])))
        solutions = [sol]
    else:
        rms = f.residual_rms_hz
        status = _statuses(res, alpha)
        solutions = [
            _solution(res.t_s[k], utc(k), f.pos_ecef_m[k], f.vel_ecef_mps[k], f.clock_offset_hz[k], f.gdop[k],
                      res.n_sats[k], f.n_used[k], f.iterations[k], rms[k], status[k], f.cov[k, :3, :3])
            for k in np.flatnonzero(res.n_sats >= (N_DOPPLER_STATES if res.n_need is None else res.n_need))
        ]
        if len(res.clock_labels) > 1:
            names = [res.clock_labels[j] for j in f.clock_labels]
            for sol, k in zip(solutions, np.flatnonzero(res.n_sats >= res.n_need)):
                sol["clock_offsets_hz"] = {n: v for n, v in zip(names, _floats(f.clock_offsets_hz[k]))
                                           if v is not None}
        ep, sl = np.nonzero(res.rows >= 0)
        residuals = [(int(meas.line[i]), meas.t_s[i], meas.sat_id[i], f.residuals_hz[e, s], bool(f.used[e, s]))
                     for e, s, i in zip(ep, sl, res.rows[ep, sl])]
        return solutions, passes, residuals
    residuals = [(int(meas.line[k]), meas.t_s[k], meas.sat_id[k], f.residuals_hz[k], bool(f.used[k]))
                 for k in range(len(meas))]
    return solutions, passes, residuals


def _floats(values):
    """JSON numbers of an array: floats, None for NaN."""
    return [float(v) if np.isfinite(v) else None for v in values]


def fixes_csv_rows(solutions):
    """Header and rows of fixes.csv: the solution keys, ``sigma_enu_m`` split into three columns.

    Mappings per constellation (``clock_offsets_hz``, ...) become one column
    per constellation, ``clock_offset_hz_<name>`` (``clock_drift_hz_per_s_<name>``).
    """
    keys = [k for k in solutions[0] if k != "sigma_enu_m" and not isinstance(solutions[0][k], dict)] \
        if solutions else []
    header = keys + ["sigma_e_m", "sigma_n_m", "sigma_u_m"]
    maps = {"clock_offsets_hz": "clock_offset_hz", "clock_drifts_hz_per_s": "clock_drift_hz_per_s"}
    extra = [(key, name) for key in maps for name in dict.fromkeys(n for s in solutions for n in s.get(key, {}))]
    header += [f"{maps[key]}_{name.replace(' ', '_')}" for key, name in extra]
    return header, [[s[k] for k in keys] + [float(v) for v in s["sigma_enu_m"]]
                    + [s.get(key, {}).get(name) for key, name in extra] for s in solutions]


def run(args):
    _check(args)
    for name in OUT_FILES if args.out else ():
        check_output_file(Path(args.out) / name, "--out")
    # Element sets give the rows' families (carrier, receiver clock) and, without state columns, the states.
    init = None
    if args.init:
        lat, lon, alt = parse_site(args.init, "--init")
        init = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    constellation = load_constellation(args.tle) if args.tle else None
    if args.format == "doptrack":
        # Each pass's own element set gives its states (light time at --init when given).
        meas = doptrack_table(read_doptrack(args.meas), init)
    elif args.format == "fll":
        if not args.sat_id:
            raise InputError("--format fll: give the satellite's catalogue number with --sat-id")
        meas = read_fll(args.meas, args.sat_id)
        constellation = constellation or load_constellation(None)
    else:
        meas = read_measurements(args.meas, carrier_hz=args.carrier_hz, constellation=constellation)
        if meas.pos_sv_ecef_m is None and constellation is None:
            constellation = load_constellation(None)
            meas = read_measurements(args.meas, carrier_hz=args.carrier_hz, constellation=constellation)
    alpha = args.alpha or None
    if args.base:
        return _run_differential(args, meas, constellation, init, alpha)
    if args.static and meas.pass_id is not None:
        res = position_static_passes(meas, meas.pass_id, constellation=constellation, init_pos_ecef_m=init,
                                     alt_m=args.alt_m, alt_sigma_m=args.alt_sigma_m, sigma_hz=args.sigma_hz,
                                     alpha=alpha, clock=args.clock)
    elif args.static:
        res = position_static(meas, constellation=constellation, init_pos_ecef_m=init, alt_m=args.alt_m,
                              alt_sigma_m=args.alt_sigma_m, sigma_hz=args.sigma_hz, alpha=alpha)
    else:
        res = position_snapshots(meas, constellation=constellation, init_pos_ecef_m=init, sigma_hz=args.sigma_hz,
                                 alpha=alpha)
    solutions, passes, residuals = solutions_doc(res, meas, alpha)
    if solutions and not any(np.isfinite([s["x_m"], s["y_m"], s["z_m"]]).all() for s in solutions):
        one_pass = meas.pass_id is None or np.unique(meas.pass_id).size == 1
        if args.static and args.alt_m is None and max(s["n_sats"] for s in solutions) == 1 and one_pass:
            raise InputError(f"{args.meas}: no finite fix from one satellite's pass, which determines the "
                             "receiver's height weakly at best; give the height with --alt-m")
        raise InputError(f"{args.meas}: no finite fix from {len(solutions)} solve(s) "
                         f"({', '.join(sorted({s['status'] for s in solutions}))}); check the doppler_hz values "
                         "(Hz, sign of DESIGN 4.3), the satellite states and --init")
    for line, reason in res.rejected:
        print(f"leosop position: warning: {meas.source}:{line}: {reason}", file=sys.stderr)
    doc = {
        "solutions": solutions,
        "mode": "static" if args.static else "snapshot",
        "sv_states": res.sv_states,
        "sigma_hz_default": res.sigma_hz_default,
        "rejected": [{"line": line, "reason": reason} for line, reason in res.rejected],
        "unsolved": [{"t_s": t, "time_utc": None if u is None else format_utc(u), "reason": why}
                     for t, u, why in res.unsolved],
    }
    if passes is not None:
        doc["passes"] = passes
    if args.out:
        # All three or none: a file that cannot be written (e.g. a directory in its place) leaves no other.
        with atomic_files([Path(args.out) / name for name in OUT_FILES]) as (doc_path, fixes_path, res_path):
            write_json(doc_path, doc)
            write_csv(fixes_path, *fixes_csv_rows(solutions))
            write_csv(res_path, ["line", "t_s", "sat_id", "residual_hz", "used"], residuals)
    return doc


def _run_differential(args, rover, constellation, init, alpha):
    """The rover's differential fix against ``--base`` (DESIGN 4.1 position keys plus ``differential``)."""
    base = read_measurements(args.base, carrier_hz=args.carrier_hz, constellation=constellation)
    if base.pos_sv_ecef_m is None and constellation is None:
        constellation = load_constellation(None)
    lat, lon, alt = parse_site(args.base_site, "--base-site")
    base_pos = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    pair = solve_pair(rover, base, base_pos, constellation=constellation, pos0_ecef_m=init, sigma_hz=args.sigma_hz,
                      block_s=None if args.static else args.block_s, motion=args.motion,
                      sat_clock_degree=args.sat_clock_degree, alpha=alpha)
    f = pair.fix
    solutions = differential_solutions(f, pair.time_utc, pair.t_s)
    if not solutions:
        raise InputError(f"{args.meas}: no differential fix ({', '.join(sorted(set(f.status.tolist())))}); "
                         f"{int((f.block >= 0).sum())} rover row(s) matched a base row")
    for name, line, reason in pair.rejected:
        print(f"leosop position: warning: {name}:{line}: {reason}", file=sys.stderr)
    solved = np.isfinite(f.pos_ecef_m).all(-1)
    doc = {
        "solutions": solutions,
        "mode": "static" if args.static else "blocks",
        "sv_states": pair.sv_states,
        "sigma_hz_default": args.sigma_hz,
        "rejected": [{"file": name, "line": line, "reason": reason} for name, line, reason in pair.rejected],
        "unsolved": [{"t_s": float(pair.t_s[k]),
                      "time_utc": None if pair.time_utc is None else format_utc(pair.time_utc[k]),
                      "reason": str(f.status[k])} for k in np.flatnonzero(~solved)],
        "differential": {
            "base": str(args.base), "base_site": [lat, lon, alt],
            "model": "single_difference" if args.sat_clock_degree is None else "joint",
            "sat_clock_degree": args.sat_clock_degree, "block_s": None if args.static else args.block_s,
            "motion": args.motion, "n_common": len(pair.common_sats), "common": list(pair.common_sats),
            "base_only": list(f.base_only_sats), "rover_only": list(f.rover_only_sats),
            "n_unmatched_rows": int(f.n_unmatched_rows), "clock": "rover minus base"},
    }
    if args.out:
        residuals = [(int(pair.rover.line[k]), float(pair.rover.t_s[k]), pair.rover.sat_id[k], f.residuals_hz[k],
                      bool(f.used[k])) for k in range(len(pair.rover.t_s))]
        with atomic_files([Path(args.out) / name for name in OUT_FILES]) as (doc_path, fixes_path, res_path):
            write_json(doc_path, doc)
            write_csv(fixes_path, *fixes_csv_rows(solutions))
            write_csv(res_path, ["line", "t_s", "sat_id", "residual_hz", "used"], residuals)
    return doc


def differential_solutions(fix, time_utc, t_s):
    """The solved blocks of a DifferentialFix with the keys of position's solutions (DESIGN 4.1).

    Parameters
    ----------
    fix : DifferentialFix
    time_utc : ndarray of datetime64, (n_b,), or None
    t_s : ndarray, (n_b,)
        Each block's reference time.

    Returns
    -------
    list of dict
        ``clock_offset_hz`` (and ``clock_drift_hz_per_s``) are rover minus
        base; the velocity is the block's (zero at rest).
    """
    out = []
    for k in np.flatnonzero(np.isfinite(fix.pos_ecef_m).all(-1)):
        res = fix.residuals_hz[(fix.block == k) & fix.used]
        rms = float(np.sqrt(np.mean(res**2))) if res.size else None
        vel = np.zeros(3) if fix.vel_ecef_mps is None else fix.vel_ecef_mps[k]
        sol = _solution(t_s[k], None if time_utc is None else time_utc[k], fix.pos_ecef_m[k], vel,
                        float(fix.clock_poly_hz[k, 0]), float(fix.gdop[k]), fix.n_sats[k], fix.n_used[k],
                        fix.iterations[k], rms, (fix.status[k], fix.dof[k], fix.chi2_p[k]), fix.cov[k, :3, :3])
        if fix.clock_poly_hz.shape[1] > 1:
            sol["clock_drift_hz_per_s"] = float(fix.clock_poly_hz[k, 1])
        out.append(sol)
    return out


def format_or_na(value, spec):
    """``value`` formatted with ``spec``, ``n/a`` for None (a JSON null)."""
    return "n/a" if value is None else format(value, spec)


def summary(doc):
    lines = []
    for s in doc["solutions"]:
        f = {k: format_or_na(s[k], spec) for k, spec in (
            ("lat_deg", ".6f"), ("lon_deg", ".6f"), ("alt_m", ".1f"), ("vx_mps", ".3f"), ("vy_mps", ".3f"),
            ("vz_mps", ".3f"), ("clock_offset_hz", ".3f"), ("gdop", ".3g"), ("residual_rms_hz", ".3g"))}
        when = s["time_utc"] or f"t={s['t_s']:.3f} s"
        # A static fix uses rows (measurements) of n_sats satellites; a snapshot fix one row per satellite.
        used = (f"{s['n_used']} measurements of {s['n_sats']} sats" if doc.get("mode") != "snapshot" else
                f"{s['n_used']}/{s['n_sats']} sats")
        lines.append(f"{when}  {f['lat_deg']} {f['lon_deg']} {f['alt_m']} m  "
                     f"v=({f['vx_mps']}, {f['vy_mps']}, {f['vz_mps']}) m/s  clock {f['clock_offset_hz']} Hz  "
                     f"gdop {f['gdop']}  {used}  rms {f['residual_rms_hz']} Hz  {s['status']}")
    if "differential" in doc:
        d = doc["differential"]
        lines.append(f"differential ({d['model'].replace('_', ' ')}) against {d['base']}: {d['n_common']} "
                     f"satellite(s) in common, base only: {', '.join(d['base_only']) or 'none'}, rover only: "
                     f"{', '.join(d['rover_only']) or 'none'}; clock offsets are rover minus base")
    lines.append(f"{status_line(doc['solutions'])}, {len(doc['unsolved'])} epoch(s) unsolved, "
                 f"{len(doc['rejected'])} row(s) rejected")
    return "\n".join(lines)


def status_line(solutions):
    """How many of the solutions are ``ok`` and why the others are not, e.g. ``3 of 5 fix(es) ok (2 inconsistent)``."""
    labels = [s["status"] for s in solutions]
    others = {lab: labels.count(lab) for lab in STATUSES if lab != "ok" and lab in labels}
    why = f" ({', '.join(f'{n} {lab}' for lab, n in others.items())})" if others else ""
    return f"{labels.count('ok')} of {len(labels)} fix(es) ok{why}"
