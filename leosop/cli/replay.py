"""``leosop replay REC.sigmf-meta --tle FILE``: satellites heard in a recording, identified, and a fix.

The recording (SigMF, one capture or many snapshot captures; it must carry
``core:datetime``) is read block by block; every pilot comb in a block is
found, the combs are tracked across blocks and capture gaps, each track is
identified against the element sets (with ``--init`` near a prior position,
without it by a global search), and the identified tracks' Doppler gives a
static batch fix (``--static``) or a snapshot fix per block. A track that no
satellite explains keeps a null ``sat_id``. Nothing detected is not an
error: the JSON has empty ``tracks`` and ``solutions``.

With ``--base BASE --base-site LAT,LON,ALT`` (differential, issue 23) the
base's recording is replayed too (a receiver at rest at its known site) and
the satellites identified in both give the rover's differential fix
(:mod:`leosop.replay.differential`): ``solutions`` is that fix,
``solutions_alone`` the rover's own, ``differential`` says which satellites
were matched.

Several recordings (``A B C ...``, or a folder of ``*.sigmf-meta``) are a
batch (:mod:`leosop.replay.batch`): each recording's files go to
``DIR/<name>/`` as a single replay would write them, ``DIR/batch.json``
summarises the batch, recordings already done are skipped, and
``--scheduler`` runs them on Dask as ``leosop study`` does.
"""

import argparse
import functools
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..errors import ExternalError, InputError
from ..fileio import atomic_files, check_input_file, check_output_file, write_csv, write_json
from ..frames import geodetic_to_ecef
from ..orbits import load_constellation
from ..positioning.measurements import DEFAULT_CARRIER_HZ, write_measurements
from ..replay.lo import LO_DRIFT_MAX_HZ_PER_S, LO_OFFSET_MAX_HZ
from ..signal.checksum import sha512_checked
from ..signal.iq import open_sigmf
from ..timebase import format_utc, seconds_since
from . import add_command
from .options import mask_deg, parse_site, positive

#: Bounds of the LO options: beyond them a value is a typo (free-running LNBs are within a few MHz;
#: the band of any SDR recording is below 100 MHz; an LNB drifting 1 kHz/s is broken).
_LO_OFFSET_LIMIT_HZ = 50e6
_LO_DRIFT_LIMIT_HZ_PER_S = 1e3
#: The files ``--out`` may hold, written all or none (measurements, fixes and the spectrogram when there are any;
#: the base's measurements with ``--base``, the carrier tracks with ``--carrier``).
OUT_FILES = ("replay.json", "tracks.csv", "measurements.csv", "fixes.csv", "spectrogram.png", "base_measurements.csv",
             "carrier.csv", "carrier_residuals.png")

_DESCRIPTION = __doc__.split("\n\n")[1].replace("\n", " ")


def register(subparsers):
    p = add_command(subparsers, "replay", sys.modules[__name__], description=_DESCRIPTION,
                    help="find, track and identify the satellites of an IQ recording, then fix the receiver")
    p.add_argument("recording", metavar="REC.sigmf-meta", nargs="+",
                   help="SigMF recording with core:datetime; several, or a folder of them, are a batch (needs --out)")
    p.add_argument("--tle", metavar="FILE", help="TLE or OMM snapshot to identify against "
                   "(default: the bundled Walker set)")
    p.add_argument("--init", metavar="LAT_DEG,LON_DEG,ALT_M",
                   help="prior receiver position, within ~100 km (default: global search)")
    p.add_argument("--static", action="store_true", help="one batch fix of a receiver at rest "
                   "(default: a snapshot fix per block with >= 7 identified satellites)")
    p.add_argument("--mask-deg", type=float, default=10.0,
                   help="elevation mask for identification candidates (default %(default)g)")
    p.add_argument("--block-s", type=float, default=0.1,
                   help="block length; shorter captures are one block each (default %(default)g)")
    p.add_argument("--lo-offset-max-hz", type=float, default=LO_OFFSET_MAX_HZ, metavar="HZ",
                   help="largest receiver (LNB local oscillator) offset searched, +- (default %(default)g: PLL "
                        "LNBs; free-running ones need up to 3e6)")
    p.add_argument("--base", metavar="BASE.sigmf-meta",
                   help="a base station's recording of the same satellites (with --base-site): differential fix")
    p.add_argument("--base-site", metavar="LAT_DEG,LON_DEG,ALT_M", help="the base's known position")
    p.add_argument("--lo-drift-max-hz-per-s", type=float, default=LO_DRIFT_MAX_HZ_PER_S, metavar="HZ_PER_S",
                   help="largest drift of that offset searched, +- (default %(default)g)")
    p.add_argument("--carrier", action="store_true",
                   help="continuous recordings: track each identified satellite's carrier phase (carrier.csv); "
                        "with --static the fix takes its phase-rate Doppler in place of the block Doppler")
    p.add_argument("--threads", type=int, metavar="N",
                   help="threads for one recording (N-1 read and clean blocks ahead of the search, which does too "
                        "while it waits; the "
                        "identification's cell vote on N), the same result whatever N (default: the cores, at "
                        f"most {MAX_DEFAULT_THREADS}: {_default_threads()} here)")

    p.add_argument("--workers", type=int, metavar="N",
                   help="batch: workers of the local Dask cluster (default: the cores)")
    p.add_argument("--scheduler", metavar="ADDR", help="batch: Dask scheduler address (default: a local cluster; "
                                                       "'serial' runs in this process)")


def _track_doc(tr):
    return {"sat_id": tr.sat_id, "id_status": tr.id_status, "n_blocks": len(tr),
            "start_utc": format_utc(tr.time_utc[0]), "end_utc": format_utc(tr.time_utc[-1]),
            "cn0_dbhz": float(np.nanmedian(tr.cn0_dbhz)), "match_rms_hz": tr.match_rms_hz,
            "doppler_hz_start": float(tr.doppler_hz[0]), "doppler_hz_end": float(tr.doppler_hz[-1])}


def _lo_doc(lo, lo_max, drift_max):
    """The receiver's common offset and drift keys (null without an estimate)."""
    num = lambda v: float(v) if v is not None and np.isfinite(v) else None  # noqa: E731
    return {"lo_offset_hz": num(lo and lo.offset_hz), "lo_offset_sigma_hz": num(lo and lo.offset_sigma_hz),
            "lo_drift_hz_per_s": num(lo and lo.drift_hz_per_s),
            "lo_drift_sigma_hz_per_s": num(lo and lo.drift_sigma_hz_per_s),
            "lo_ref_utc": format_utc(lo.t_ref_utc) if lo else None, "lo_source": lo.source if lo else None,
            "lo_linewidth_hz": num(lo and lo.linewidth_hz), "lo_offset_max_hz": float(lo_max),
            "lo_drift_max_hz_per_s": float(drift_max)}


def run(args):
    if len(args.recording) > 1 or Path(args.recording[0]).is_dir():
        return _run_batch(args)
    if args.scheduler is not None or args.workers is not None:
        raise InputError("--scheduler and --workers run a batch: give several recordings or a folder")
    return _run_single(args)


def _check_options(args):
    """The checked numeric options: block length, LO bounds, mask, prior position (ECEF or None)."""
    block_s = positive(args.block_s, "--block-s")
    lo_max = positive(args.lo_offset_max_hz, "--lo-offset-max-hz")
    if lo_max > _LO_OFFSET_LIMIT_HZ:
        raise InputError(f"--lo-offset-max-hz {lo_max:g}: beyond {_LO_OFFSET_LIMIT_HZ:g} Hz no LNB is that far off")
    drift_max = args.lo_drift_max_hz_per_s
    if not (np.isfinite(drift_max) and 0 <= drift_max <= _LO_DRIFT_LIMIT_HZ_PER_S):
        raise InputError(f"--lo-drift-max-hz-per-s {drift_max:g}: expected 0 to {_LO_DRIFT_LIMIT_HZ_PER_S:g}")
    mask = mask_deg(args.mask_deg)
    init = None
    if args.init:
        lat, lon, alt = parse_site(args.init, "--init")
        init = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    return block_s, lo_max, drift_max, mask, init


#: ``--threads``' default is the cores available up to this: on idle cores two threads replayed a 120 s
#: recording 1.17x as fast end to end (1.80x the streaming stage) and three slower than two
#: (docs/replay.md, "Threads").
MAX_DEFAULT_THREADS = 2


def _default_threads():
    """``--threads``' default: the cores this process may run on, at most :data:`MAX_DEFAULT_THREADS`."""
    return max(1, min(MAX_DEFAULT_THREADS, len(os.sched_getaffinity(0))))


def _run_single(args):
    options = _check_options(args)
    threads = _default_threads() if args.threads is None else args.threads
    if threads < 1:
        raise InputError(f"--threads {threads}: expected an integer >= 1")
    if (args.base is None) != (args.base_site is None):
        raise InputError("--base needs --base-site, the base's known position" if args.base else
                         "--base-site goes with --base, the base's recording")
    base_pos = None
    if args.base_site:
        lat, lon, alt = parse_site(args.base_site, "--base-site")
        base_pos = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    for name in OUT_FILES if args.out else ():
        check_output_file(Path(args.out) / name, "--out")  # before the work, not after
    path = Path(args.recording[0])
    # Both refuse anything but SigMF (the pipeline refuses a missing core:datetime); their checksums are
    # checked on a background thread while the replay runs, before anything is written.
    rec = open_sigmf(path, verify=False)
    base_rec = open_sigmf(Path(args.base), verify=False) if args.base else None
    with sha512_checked(*(r for r in (rec, base_rec) if r is not None)):
        doc, res, diff, carrier, carrier_pair = _replay_doc(args, options, path, rec, base_rec, base_pos, threads)
    if args.out:
        _write_outputs(Path(args.out), doc, res, path.name, rec.start_utc, diff, carrier, carrier_pair)
    return doc


def _replay_doc(args, options, path, rec, base_rec, base_pos, threads):
    """The replay of ``rec`` (and of the base's ``base_rec``) and its document; the outputs left to write.

    ``options`` are :func:`_check_options`' checked values, ``threads`` the replay's.

    Returns
    -------
    doc, res, diff, carrier, carrier_pair
        The document (DESIGN 4.1), the rover's :class:`~leosop.replay.pipeline.ReplayResult`, the
        differential fix, the carrier tracks and the differential carrier fix (None where not run).
    """
    from ..replay.pipeline import replay
    from .position import solutions_doc

    block_s, lo_max, drift_max, mask, init = options
    if args.carrier:
        from ..replay.carrier_replay import check_continuous

        if args.base and not args.static:
            raise InputError("--carrier with --base: the differential carrier-phase fix is of a rover at rest: "
                             "add --static")
        try:
            check_continuous(rec)
        except InputError as exc:
            raise InputError(f"{exc}; replay it without --carrier") from exc
    if base_rec is not None:
        from ..replay.differential import check_pair

        check_pair(rec, base_rec)
        if args.carrier:
            try:
                check_continuous(base_rec)
            except InputError as exc:
                raise InputError(f"{exc}; replay it without --carrier") from exc
    const = load_constellation(args.tle)
    res = replay(rec, const, block_s=block_s, init_pos_ecef_m=init, static=args.static, mask_deg=mask,
                 lo_offset_max_hz=lo_max, lo_drift_max_hz_per_s=drift_max, show_progress=True, threads=threads)
    carrier = None
    if args.carrier:
        from ..replay.carrier_replay import replay_carrier

        carrier = replay_carrier(rec, res, const, block_s=block_s, lo_offset_max_hz=lo_max, static=args.static)
    position, meas = (res.position, res.measurements) if carrier is None or carrier.position is None else \
        (carrier.position, carrier.measurements)
    solutions, passes, _ = ([], None, None) if position is None else solutions_doc(position, meas)

    extra = {} if passes is None else {"passes": passes}
    doc = {"tracks": [_track_doc(tr) for tr in res.tracks], "solutions": solutions,
           "recording": str(path), "n_blocks": len(res.blocks),
           "n_identified": sum(tr.sat_id is not None for tr in res.tracks),
           "mode": "static" if args.static else "snapshot", **_lo_doc(res.lo, lo_max, drift_max), **extra}
    if carrier is not None:
        doc["carrier"] = carrier.doc()
        if carrier.position is not None and res.position is not None:
            doc["solutions_block_doppler"] = solutions_doc(res.position, res.measurements)[0]
    if res.pss is not None:
        acq, cap_utc, track = res.pss

        def utc(t_s):
            return format_utc(cap_utc + np.timedelta64(int(round(t_s * 1e9)), "ns"))

        doc["pss"] = {"detected": bool(acq.detected), "metric": float(acq.metric),
                      "doppler_hz": float(acq.doppler_hz), "frame_period_s": float(acq.frame_period_s),
                      "frame_start_utc": [utc(t) for t in acq.frame_start_s],
                      "track": {"n_frames": int(track.frame_number.size), "n_found": int(track.found.sum()),
                                "frame_jumps": [{"frame": int(m), "time_utc": utc(track.frame_start_s[m]),
                                                 "jump_s": float(track.jump_s[m])}
                                                for m in np.flatnonzero(track.jump)]}}
    if not res.tracks:
        print(f"leosop replay: no pilot comb detected in {len(res.blocks)} block(s) of {path}", file=sys.stderr)
    diff = carrier_pair = None
    if base_rec is not None:
        from ..replay.differential import BASE_PRIOR_RADIUS_M, block_times, differential_fix
        from .position import differential_solutions

        base_res = replay(base_rec, const, block_s=block_s, init_pos_ecef_m=base_pos, static=True, mask_deg=mask,
                          lo_offset_max_hz=lo_max, lo_drift_max_hz_per_s=drift_max, show_progress=True,
                          prior_radius_m=BASE_PRIOR_RADIUS_M, threads=threads)
        diff = differential_fix(res, base_res, const, base_pos, carrier_hz=rec.center_hz or DEFAULT_CARRIER_HZ,
                                static=args.static, block_s=block_s)
        doc["solutions_alone"] = doc["solutions"]
        doc["solutions"] = differential_solutions(diff.fix, *block_times(diff))
        doc["differential"] = {
            "n_common": len(diff.common_sats), "common": list(diff.common_sats),
            "base_only": list(diff.fix.base_only_sats), "rover_only": list(diff.fix.rover_only_sats),
            "n_unmatched_rows": int(diff.fix.n_unmatched_rows), "base_recording": str(args.base),
            "base_site": list(parse_site(args.base_site, "--base-site")),
            "base_tracks": [_track_doc(tr) for tr in base_res.tracks],
            "base_n_identified": sum(tr.sat_id is not None for tr in base_res.tracks)}
        if carrier is not None:
            carrier_pair = _carrier_pair(rec, base_rec, base_res, const, base_pos, carrier, diff, block_s, lo_max)
            doc["differential_carrier"] = carrier_pair.doc()
    return doc, res, diff, carrier, carrier_pair


def _carrier_pair(rec, base_rec, base_res, const, base_pos, carrier, diff, block_s, lo_max):
    """The differential carrier-phase fixes: the base tracked as the rover was, from the differential Doppler fix."""
    from ..replay.carrier_replay import replay_carrier
    from ..replay.differential_carrier import differential_carrier_fix

    base_carrier = replay_carrier(base_rec, base_res, const, block_s=block_s, lo_offset_max_hz=lo_max, static=False)
    pos0 = diff.fix.pos_ecef_m[0]
    if not np.all(np.isfinite(pos0)):
        raise InputError("no differential Doppler fix to start the carrier-phase fix from")
    return differential_carrier_fix(carrier, base_carrier, const, base_pos, pos0,
                                    carrier_hz=rec.center_hz or DEFAULT_CARRIER_HZ)


#: Options a batch's results do not depend on (left out of the resume key).
_NOT_IN_KEY = ("command", "json", "out", "recording", "scheduler", "workers", "threads")


def _run_batch(args):
    from ..replay.batch import LEDGER, batch_recordings, run_batch

    _check_options(args)
    if args.base or args.base_site:
        raise InputError("--base and --base-site take one rover recording, not a batch")
    if args.threads is not None:
        raise InputError("--threads runs one recording's blocks in parallel; a batch runs its recordings in "
                         "parallel (--workers)")
    if args.out is None:
        raise InputError("a batch (several recordings, or a folder) needs --out DIR: a folder of results each, "
                         "and batch.json")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers {args.workers}: expected an integer >= 1")
    recordings = batch_recordings(args.recording)
    out = Path(args.out)
    for meta, name in recordings:
        open_sigmf(meta, verify=False)  # every file a recording before any work (its checksum when it runs)
        for f in OUT_FILES:
            check_output_file(out / name / f, "--out")
    if args.tle:
        check_input_file(args.tle, "element-set file")  # refused once, not once per recording
    options = {k: v for k, v in vars(args).items() if not k.startswith("_") and k not in _NOT_IN_KEY}
    if args.tle:
        stat = Path(args.tle).stat()
        options["tle_file"] = [str(Path(args.tle).resolve()), stat.st_size, stat.st_mtime_ns]
    one = argparse.Namespace(**{k: v for k, v in vars(args).items() if not k.startswith("_")})
    doc = run_batch(functools.partial(replay_files, one), recordings, out, options=options,
                    scheduler=args.scheduler, n_workers=args.workers)
    failed = [e for e in doc["recordings"] if e["status"] == "failed"]
    if failed:
        what = (f"{len(failed)} of {len(recordings)} recording(s) failed, first {failed[0]['recording']}: "
                f"{failed[0]['error']} ({len(recordings) - len(failed)} done; see {out / LEDGER})")
        raise InputError(what) if all(e["error_kind"] == "input" for e in failed) else ExternalError(what)
    return doc


def replay_files(args, meta):
    """One recording of a batch, replayed as ``leosop replay META --out DIR`` would into a private folder.

    Parameters
    ----------
    args : argparse.Namespace
        The batch's options (picklable: no module attributes).
    meta : Path
        The recording's ``.sigmf-meta``.

    Returns
    -------
    doc : dict
        The replay document (DESIGN 4.1).
    files : dict
        ``{file name: bytes}`` of the output files, in the order of :data:`OUT_FILES`.
    """
    with tempfile.TemporaryDirectory(prefix="leosop-replay-") as tmp:
        doc = _run_single(argparse.Namespace(**{**vars(args), "recording": [str(meta)], "out": tmp,
                                               "scheduler": None, "workers": None, "threads": 1}))
        files = {n: (Path(tmp) / n).read_bytes() for n in OUT_FILES if (Path(tmp) / n).is_file()}
    return doc, files


def _write_outputs(out, doc, res, name, start_utc, diff=None, carrier=None, carrier_pair=None):
    from ..plots.carrier import plot_carrier_residuals
    from ..plots.spectra import plot_spectrogram
    from .position import fixes_csv_rows

    # The files this run makes, all or none (a directory in the place of one leaves no other behind).
    names = [n for n, made in zip(OUT_FILES, (True, True, res.measurements is not None, bool(doc["solutions"]),
                                              res.spectrum.shape[1] > 0, diff is not None, carrier is not None,
                                              carrier_pair is not None))
             if made]
    with atomic_files([out / n for n in names]) as tmps:
        path = dict(zip(names, tmps))
        write_json(path["replay.json"], doc)
        keys = ["sat_id", "id_status", "n_blocks", "start_utc", "end_utc", "cn0_dbhz", "match_rms_hz",
                "doppler_hz_start", "doppler_hz_end"]
        write_csv(path["tracks.csv"], keys, [["" if t[k] is None else t[k] for k in keys] for t in doc["tracks"]])
        if "measurements.csv" in path:
            write_measurements(path["measurements.csv"], res.measurements)
        if "fixes.csv" in path:
            write_csv(path["fixes.csv"], *fixes_csv_rows(doc["solutions"]))
        if "base_measurements.csv" in path:
            write_measurements(path["base_measurements.csv"], diff.base)
        if "carrier.csv" in path:
            write_csv(path["carrier.csv"], carrier.CSV_HEADER, carrier.csv_rows())
        if "carrier_residuals.png" in path:
            d = doc["differential_carrier"]
            plot_carrier_residuals(path["carrier_residuals.png"], seconds_since(carrier_pair.time_utc, start_utc),
                                   carrier_pair.joint.residuals_m, carrier_pair.sat_id,
                                   title=f"{name}: differential carrier phase ({d['model']} fit), rover minus base "
                                         f"residuals; fix {d['status']}, ambiguities {d['ambiguities']}")
        if "spectrogram.png" in path:
            labelled = [(tr.t_s, tr.doppler_hz, tr.sat_id or "unidentified") for tr in res.tracks]
            plot_spectrogram(path["spectrogram.png"], res.spectrum_t_s, res.spectrum_f_hz, res.spectrum,
                             labelled_tracks=labelled,
                             x_label=f"time since the first sample, {format_utc(start_utc)[:19]}Z [s]",
                             title=f"{name}: {doc['n_identified']} of {len(res.tracks)} tracks identified, "
                                   f"{doc['mode']} fix")


def _batch_summary(doc):
    from .position import format_or_na

    where = f"on {doc['n_workers']} Dask workers" if doc["n_workers"] else "in this process"
    lines = [f"{doc['out']}: {doc['n_recordings']} recording(s), {doc['n_run']} replayed {where}, "
             f"{doc['n_resumed']} already done, {doc['n_failed']} failed; {doc['elapsed_s']:.1f} s"]
    for e in doc["recordings"]:
        if e["status"] == "failed":
            lines.append(f"  {e['name']}: failed: {e['error']}")
            continue
        fix = e["fix"]
        where = (f"fix {format_or_na(fix['lat_deg'], '.6f')} {format_or_na(fix['lon_deg'], '.6f')} "
                 f"{format_or_na(fix['alt_m'], '.1f')} m {fix['status']}" if fix else
                 f"{e['n_solutions_ok']} of {e['n_solutions']} fix(es) ok")
        lines.append(f"  {e['name']}: {e['n_identified']} of {e['n_tracks']} track(s) identified, {where}, "
                     f"{e['runtime_s']:.1f} s{' (resumed)' if e['resumed'] else ''}")
    return "\n".join(lines)


def summary(doc):
    from .position import format_or_na, status_line

    if "recordings" in doc:
        return _batch_summary(doc)
    lines = [f"{len(doc['tracks'])} track(s) in {doc['n_blocks']} block(s), {doc['n_identified']} identified"]
    for t in doc["tracks"]:
        rms = "n/a" if t["match_rms_hz"] is None else f"{t['match_rms_hz']:.2f} Hz"
        cn0 = "n/a" if t["cn0_dbhz"] is None else f"{t['cn0_dbhz']:.1f} dB-Hz"
        name = t["sat_id"] or f"unidentified ({t['id_status']})"
        lines.append(f"  {name:>12}  {t['n_blocks']:4d} blocks  {t['start_utc']} .. "
                     f"{t['end_utc']}  C/N0 {cn0}  match rms {rms}")
    for s in doc["solutions"][:10]:
        sig = s.get("sigma_enu_m") or [None] * 3
        sig_txt = "n/a" if None in sig else "/".join(f"{v:.1f}" for v in sig)
        lat, lon, alt = (format_or_na(s[k], spec)
                         for k, spec in (("lat_deg", ".6f"), ("lon_deg", ".6f"), ("alt_m", ".1f")))
        lines.append(f"fix {s['time_utc']}: {lat} {lon} {alt} m  "
                     f"sigma E/N/U {sig_txt} m  {s['n_used']} measurements used  {s['status']}")
    if doc["lo_offset_hz"] is not None:
        lines.append(f"receiver offset {doc['lo_offset_hz']:+.2f} +- {doc['lo_offset_sigma_hz']:.2f} Hz at "
                     f"{doc['lo_ref_utc']}, drift {doc['lo_drift_hz_per_s']:+.3f} +- "
                     f"{doc['lo_drift_sigma_hz_per_s']:.3f} Hz/s ({doc['lo_source']}; searched +-"
                     f"{doc['lo_offset_max_hz']:g} Hz, +-{doc['lo_drift_max_hz_per_s']:g} Hz/s)")
    if doc.get("lo_linewidth_hz"):
        lines.append(f"receiver LO noise: Wiener linewidth {doc['lo_linewidth_hz']:.2g} Hz, common to each block's "
                     "combs, in every measurement's sigma")
    if "pss" in doc:
        p = doc["pss"]
        first = p["frame_start_utc"][0] if p["frame_start_utc"] else "n/a"
        lines.append(f"PSS: {'detected' if p['detected'] else 'not detected'} (metric {p['metric']:.2f}), "
                     f"{len(p['frame_start_utc'])} frames from {first}, "
                     f"OFDM centre offset {p['doppler_hz']:+.0f} Hz")
        tr = p["track"]
        jumps = ", ".join(f"{j['jump_s'] * 1e9:+.0f} ns at {j['time_utc']}" for j in tr["frame_jumps"])
        lines.append(f"PSS track over the first capture: {tr['n_found']} of {tr['n_frames']} frames, "
                     f"{len(tr['frame_jumps'])} frame-timing jump(s){': ' + jumps if jumps else ''}")
    if "differential" in doc:
        d = doc["differential"]
        lines.append(f"differential against {d['base_recording']}: {d['n_common']} satellite(s) in common, "
                     f"base only: {', '.join(d['base_only']) or 'none'}, rover only: "
                     f"{', '.join(d['rover_only']) or 'none'}; the fixes above are the rover's differential fixes")
        for s in doc["solutions_alone"][:1]:
            lines.append(f"rover alone: {format_or_na(s['lat_deg'], '.6f')} {format_or_na(s['lon_deg'], '.6f')} "
                         f"{format_or_na(s['alt_m'], '.1f')} m  {s['status']}")
    if "differential_carrier" in doc:
        d = doc["differential_carrier"]
        lines.append(f"differential carrier phase ({d['model']} fit, {d['n_sats']} satellites, {d['n_epochs']} "
                     f"blocks): {d['lat_deg']:.7f} {d['lon_deg']:.7f} {d['alt_m']:.2f} m  sigma E/N/U "
                     + "/".join(f"{v:.2f}" for v in d["sigma_enu_m"]) + f" m  {d['status']}, ambiguities "
                     f"{d['ambiguities']}" + ("" if d["ratio"] is None else f" (ratio {d['ratio']:.1f})"))
    for c in doc.get("carrier", {}).get("satellites", []):
        rms = "n/a" if c["phase_rate_vs_block_rms_hz"] is None else f"{c['phase_rate_vs_block_rms_hz']:.3f} Hz"
        lines.append(f"carrier {c['sat_id']}: {c['arcs']} arc(s), {c['slips']} slip(s), locked "
                     f"{100 * c['locked_fraction']:.0f} %, phase-rate vs block Doppler rms {rms}")
    if "solutions_block_doppler" in doc:
        lines.append("the fix above takes the phase-rate Doppler; from the block Doppler: "
                     + "; ".join(f"{format_or_na(s['lat_deg'], '.6f')} {format_or_na(s['lon_deg'], '.6f')} "
                                 f"{format_or_na(s['alt_m'], '.1f')} m {s['status']}"
                                 for s in doc["solutions_block_doppler"]))
    if len(doc["solutions"]) > 10:
        lines.append(f"... {len(doc['solutions']) - 10} more fixes (use --json or --out)")
    if doc["solutions"]:
        lines.append(status_line(doc["solutions"]))
    return "\n".join(lines)
