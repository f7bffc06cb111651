"""``leosop doppler``: Doppler of the Starlink pilot comb per block of an IQ recording.

SigMF recordings carry their own parameters; raw files need ``--dtype``,
``--sample-rate-hz`` (and optionally ``--center-hz``, ``--start``). The
recording is read one block at a time. ``ml`` and ``fmlef`` start from the
STFT coarse track ([Shen 2024]); ``fast`` from the block's own FFT. Each
estimate has a ``status``: ``"ok"`` only when it can be vouched for, else the
reason (:mod:`leosop.signal.quality`; ``"joins captures"`` for a block across
a gap between snapshot captures). A block without a detected comb gives null
values and ``"status": "no pilot detected"``. When the recording holds
``leosop generate`` truth for the same blocks, each estimate also names the
nearest true satellite and its Doppler, and the document the RMS error of the
``ok`` estimates and the fraction of them within 3 sigma of the truth.

One comb per block: the strongest. With several satellites of equal power
the estimate may move from one to another between blocks, and their tones
leak into each other's decimated bands (integrate-and-dump has sinc
sidelobes), which lowers the C/N0 estimate and can spoil a block.
"""

import sys
import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import atomic_outputs, write_csv, write_json
from ..progress import progress
from ..signal.coarse import MAX_DOPPLER_HZ, MAX_RATE_HZ_PER_S, coarse_stft
from ..signal.doppler import METHODS, estimate_block, ml_grid_points
from ..signal.fine import cubic_bias_hz, periodogram_grid
from ..signal.pilot import PilotComb
from ..timebase import format_utc
from . import add_command
from .options import add_raw_options, open_recording, positive

_FIG_COLS = 1000  # time columns kept for the spectrogram figure
_FIG_ROWS = 1024  # frequency rows kept
_RESOLUTION_RANGE_HZ = (1e-9, 1e3)
# Ka-band LEO Doppler stays below 1 MHz and its rate below 1e4 Hz/s: larger limits are typos.
_MAX_DOPPLER_LIMIT_HZ = 1e7
_MAX_RATE_LIMIT_HZ_PER_S = 1e6


def register(subparsers):
    p = add_command(subparsers, "doppler", sys.modules[__name__],
                    help="estimate the pilot comb's Doppler per block of an IQ recording")
    p.add_argument("recording", metavar="FILE", help="FILE.sigmf-meta, or a raw cf32/ci16/ci8/cu8 file with --dtype")
    p.add_argument("--block-s", type=float, default=0.1, help="block length in seconds (default 0.1)")
    p.add_argument("--method", choices=METHODS, default="fast", help="fine estimator (default fast)")
    p.add_argument("--resolution-hz", type=float, default=1e-3,
                   help="final frequency step of ml and fmlef (default 1e-3)")
    p.add_argument("--max-doppler-hz", type=float, default=MAX_DOPPLER_HZ,
                   help=f"search half-width for the central tone (default {MAX_DOPPLER_HZ:g})")
    p.add_argument("--max-rate-hz-per-s", type=float, default=MAX_RATE_HZ_PER_S,
                   help=f"largest |Doppler rate| searched by fast (default {MAX_RATE_HZ_PER_S:g})")
    add_raw_options(p)


def _truth(rec, block_len):
    """{sample_start: [(sat_id, doppler_hz), ...]} from generate's annotations on the same blocks."""
    out = {}
    for a in rec.annotations:
        if "leosop:doppler_hz" in a and a.get("core:sample_count") == block_len:
            out.setdefault(a["core:sample_start"], []).append((a.get("leosop:sat_id"), a["leosop:doppler_hz"]))
    return out


def _block_utc(captures, centre_sample, fs):
    """UTC of a block centre (sample index, may be fractional) from the capture that holds it; None if unknown."""
    cap = next((c for c in reversed(captures) if c.sample_start <= centre_sample), captures[0])
    if cap.start_utc is None:
        return None
    return format_utc(cap.start_utc + np.timedelta64(int(round((centre_sample - cap.sample_start) / fs * 1e9)), "ns"))


def _warn_straddling(captures, block_len, fs):
    """One stderr line when blocks join samples of different captures (snapshots with gaps between them)."""
    shortest = min(c.n_samples for c in captures)
    if len(captures) > 1 and block_len > shortest:
        print(f"leosop doppler: warning: blocks of {block_len / fs:g} s join {len(captures)} captures of "
              f"{shortest / fs:g} s or less across their time gaps; use --block-s {shortest / fs:g} or less",
              file=sys.stderr)


def _warn_ml_time(rec, block_len, coarse_error_hz, resolution_hz, n_blocks):
    """One stderr line with the expected run time of ``ml``, timed on 50 grid points of the first block."""
    points = ml_grid_points(coarse_error_hz, resolution_hz)
    x = rec.read(0, block_len)
    t0 = time.perf_counter()
    periodogram_grid(x, rec.sample_rate_hz, 0.0, resolution_hz, 50)
    per_block_s = (time.perf_counter() - t0) / 50 * points
    total_s = per_block_s * n_blocks
    if total_s > 10.0:
        print(f"leosop doppler: warning: --method ml evaluates {points:,} frequencies per block: about "
              f"{per_block_s:.3g} s per block, {total_s / 60:.3g} min for {n_blocks} blocks (a coarser "
              f"--resolution-hz or --method fast is quicker)", file=sys.stderr)


def _straddles(captures, start, block_len):
    """True when samples [start, start + block_len) come from more than one capture."""
    return any(start < c.sample_start < start + block_len for c in captures)


def _reduce(power, rows, cols):
    """Sum a spectrogram down to at most rows x cols cells."""
    r = max(1, power.shape[0] // rows)
    c = max(1, power.shape[1] // cols)
    p = power[: power.shape[0] // r * r, : power.shape[1] // c * c]
    return p.reshape(p.shape[0] // r, r, p.shape[1] // c, c).sum(axis=(1, 3)), r, c


def run(args):
    rec = open_recording(args, args.recording)
    fs = rec.sample_rate_hz
    block_s = positive(args.block_s, "--block-s")
    if not _RESOLUTION_RANGE_HZ[0] <= args.resolution_hz <= _RESOLUTION_RANGE_HZ[1]:
        raise InputError(f"--resolution-hz {args.resolution_hz:g}: must be in [{_RESOLUTION_RANGE_HZ[0]:g}, "
                         f"{_RESOLUTION_RANGE_HZ[1]:g}] Hz")
    if not 0 < args.max_doppler_hz <= _MAX_DOPPLER_LIMIT_HZ:
        raise InputError(f"--max-doppler-hz {args.max_doppler_hz:g}: must be in (0, {_MAX_DOPPLER_LIMIT_HZ:g}] Hz")
    if not 0 <= args.max_rate_hz_per_s <= _MAX_RATE_LIMIT_HZ_PER_S:
        raise InputError(f"--max-rate-hz-per-s {args.max_rate_hz_per_s:g}: must be in [0, "
                         f"{_MAX_RATE_LIMIT_HZ_PER_S:g}]")
    if block_s > rec.duration_s:
        raise InputError(f"--block-s {block_s:g} is longer than the recording {rec.data_path} ({rec.n_samples} "
                         f"samples, {rec.duration_s:.6g} s)")
    block_len = int(round(block_s * fs))
    if block_len < 64:
        raise InputError(f"--block-s {block_s:g}: {block_len} samples at {fs:g} Hz; need at least 64")
    if block_len > rec.n_samples:
        raise InputError(f"--block-s {block_s:g} ({block_len} samples) is longer than the recording {rec.data_path} "
                         f"({rec.n_samples} samples, {rec.duration_s:.6g} s)")
    comb = PilotComb(carrier_hz=PilotComb.carrier_hz if rec.center_hz is None else rec.center_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    truth = _truth(rec, block_len)
    _warn_straddling(rec.captures, block_len, fs)
    if args.method != "fast":
        sweep_hz = args.max_rate_hz_per_s * block_len / fs
        print(f"leosop doppler: warning: --method {args.method} assumes a constant tone within a block; at LEO "
              f"Doppler rates up to {args.max_rate_hz_per_s:g} Hz/s a {block_len / fs:g} s block sweeps up to "
              f"{sweep_hz:.0f} Hz and the estimate can be off by half that (fast follows the rate)",
              file=sys.stderr)
    n_blocks = rec.n_samples // block_len
    nperseg = min(4096, block_len // 4)
    if args.method == "ml":
        _warn_ml_time(rec, block_len, fs / nperseg, args.resolution_hz, n_blocks)
    want_fig = args.out is not None
    estimates, starts, fig_cols, fig_t, coarse_t, coarse_f = [], [], [], [], [], []
    cols_per_block = max(1, _FIG_COLS // n_blocks)
    for start, x in progress(rec.blocks(block_len), total=n_blocks, desc="doppler", unit="block"):
        t_c = (start + 0.5 * (block_len - 1)) / fs
        coarse_hz = err = None
        if args.method != "fast" or want_fig:
            t_f, d_f, f_hz, power = coarse_stft(x, fs, comb, nperseg=nperseg, max_doppler_hz=args.max_doppler_hz)
            ok = np.isfinite(d_f)
            if want_fig:
                red, _, c = _reduce(power, _FIG_ROWS, cols_per_block)
                fig_cols.append(red)
                fig_t.extend((start / fs + t_f[: red.shape[1] * c].reshape(-1, c).mean(axis=1)).tolist())
                coarse_t.extend((start / fs + t_f[ok]).tolist())
                coarse_f.extend(d_f[ok].tolist())
            if args.method != "fast":
                # The frame nearest the block centre, good to about one bin.
                coarse_hz = d_f[ok][np.argmin(np.abs(t_f[ok] - (t_c - start / fs)))] if np.any(ok) else np.nan
                err = fs / nperseg
        est = estimate_block(x, fs, method=args.method, comb=comb, resolution_hz=args.resolution_hz,
                             coarse_hz=coarse_hz, coarse_error_hz=err, max_doppler_hz=args.max_doppler_hz,
                             max_rate_hz_per_s=args.max_rate_hz_per_s)
        entry = {
            "t_s": t_c,
            "time_utc": _block_utc(rec.captures, start + 0.5 * (block_len - 1), fs),
            "doppler_hz": est["doppler_hz"],
            "doppler_rate_hz_per_s": est["doppler_rate_hz_per_s"],
            "cn0_dbhz": est["cn0_dbhz"],
            "sigma_hz": est["sigma_hz"],
            "status": "joins captures" if est["detected"] and _straddles(rec.captures, start, block_len)
            else est["status"],
        }
        estimates.append(entry)
        starts.append(start)
    if args.method == "fast":
        _correct_rate_change(estimates, block_len, fs)
    for start, entry in zip(starts, estimates):
        if start in truth and entry["doppler_hz"] is not None and np.isfinite(entry["doppler_hz"]):
            entry["truth_sat_id"], entry["truth_doppler_hz"] = min(
                truth[start], key=lambda sd: abs(sd[1] - entry["doppler_hz"]))
    doc = {"method": args.method, "estimates": estimates, "recording": str(rec.data_path),
           "sample_rate_hz": fs, "block_s": block_len / fs, "n_blocks": len(estimates),
           "n_detected": sum(e["status"] != "no pilot detected" for e in estimates),
           "n_ok": sum(e["status"] == "ok" for e in estimates)}
    truthed = [e for e in estimates if "truth_doppler_hz" in e and e["status"] == "ok"]
    if truthed:
        errs = np.array([e["doppler_hz"] - e["truth_doppler_hz"] for e in truthed])
        doc["truth_rms_error_hz"] = float(np.sqrt(np.mean(np.square(errs))))
        doc["truth_within_3_sigma"] = float(np.mean(np.abs(errs) <= 3 * np.array([e["sigma_hz"] for e in truthed])))
    if args.out:
        f_lim = min(0.5 * fs, args.max_doppler_hz + comb.offsets_hz.max() * 1.2)
        with atomic_outputs(args.out) as stage:
            origin = "" if rec.start_utc is None else f" ({format_utc(rec.start_utc)[:19]}Z)"
            joined = ", captures joined" if len(rec.captures) > 1 else ""
            x_label = f"time from the first sample{origin}{joined} [s]"
            _write_outputs(stage, doc, fig_cols, fig_t, coarse_t, coarse_f, fs, nperseg, f_lim, x_label)
    return doc


def _correct_rate_change(estimates, block_len, fs):
    """Remove the bias of a rate change (cubic phase) using neighbouring blocks' rates.

    Neighbours count when their Doppler continues this block's within 2 Hz
    (same satellite); the rate change is their rates' slope.
    """
    ok = [e["status"] == "ok" for e in estimates]
    t = np.array([e["t_s"] for e in estimates])
    d = np.array([e["doppler_hz"] for e in estimates], dtype=float)
    r = np.array([e["doppler_rate_hz_per_s"] for e in estimates], dtype=float)
    for i, e in enumerate(estimates):
        if not ok[i]:
            continue
        near = [j for j in (i - 1, i + 1) if 0 <= j < len(estimates) and ok[j]
                and abs(d[j] - d[i] - r[i] * (t[j] - t[i])) < 2.0]
        if near:
            j0, j1 = (near[0], near[-1]) if len(near) == 2 else sorted((i, near[0]))
            e["doppler_hz"] = d[i] - float(cubic_bias_hz((r[j1] - r[j0]) / (t[j1] - t[j0]), block_len, fs))


def _write_outputs(out, doc, fig_cols, fig_t, coarse_t, coarse_f, fs, nperseg, f_lim_hz, x_label):
    from ..plots.spectra import plot_spectrogram

    keys = ["t_s", "time_utc", "doppler_hz", "doppler_rate_hz_per_s", "cn0_dbhz", "sigma_hz", "status"]
    write_csv(out / "doppler.csv", keys, [[e[k] for k in keys] for e in doc["estimates"]])
    write_json(out / "doppler.json", doc, compact=True)
    power = np.concatenate(fig_cols, axis=1)
    f_hz = (np.arange(nperseg) - nperseg // 2) * fs / nperseg
    rows = nperseg // power.shape[0]
    f_hz = f_hz[: power.shape[0] * rows].reshape(-1, rows).mean(axis=1)
    ok = [e for e in doc["estimates"] if e["status"] == "ok"]
    plot_spectrogram(out / "spectrogram.png", np.array(fig_t), f_hz, power,
                     track_t_s=np.array([e["t_s"] for e in ok]), track_hz=np.array([e["doppler_hz"] for e in ok]),
                     coarse_t_s=np.array(coarse_t), coarse_hz=np.array(coarse_f), f_lim_hz=f_lim_hz,
                     title=f"{Path(doc['recording']).name}: pilot comb, method {doc['method']}, "
                           f"{doc['block_s']:g} s blocks", x_label=x_label)


def _num(value, spec, unit):
    """``value`` formatted with its unit, or "n/a" for a value the estimator could not give (null in the JSON)."""
    return "n/a" if value is None else f"{format(value, spec)} {unit}"


def summary(doc):
    lines = [f"{doc['n_detected']}/{doc['n_blocks']} blocks with a pilot, {doc['n_ok']} ok "
             f"({doc['method']}, {doc['block_s']:g} s blocks)"]
    for e in doc["estimates"][:20]:
        if e["status"] == "no pilot detected":
            lines.append(f"  t={e['t_s']:.4f} s  no pilot detected")
            continue
        lines.append(f"  t={e['t_s']:.4f} s  Doppler {e['doppler_hz']:+.4f} Hz  "
                     f"sigma {_num(e['sigma_hz'], '.2g', 'Hz')}  "
                     f"rate {_num(e['doppler_rate_hz_per_s'], '+.0f', 'Hz/s')}  "
                     f"C/N0 {_num(e['cn0_dbhz'], '.1f', 'dB-Hz')}  {e['status']}")
    if len(doc["estimates"]) > 20:
        lines.append(f"  ... {len(doc['estimates']) - 20} more blocks (use --json or --out)")
    if "truth_rms_error_hz" in doc:
        lines.append(f"ok estimates against the recording's truth: RMS error {doc['truth_rms_error_hz']:.4g} Hz, "
                     f"{100 * doc['truth_within_3_sigma']:.0f} % within 3 sigma")
    return "\n".join(lines)
