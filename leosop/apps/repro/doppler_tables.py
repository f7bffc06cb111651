"""[Shen 2024] Tables 2 and 3: run time of grid ML vs FMLEF, with our fast estimator beside them.

The paper times its estimators on a simulated pilot of N samples (Table 2:
N = 3e5, resolution 1 .. 1e-4 Hz; Table 3: resolution 0.01 Hz, N = 1e5 ..
5e5). Its ML at 1 Hz costs as much as one FMLEF level (0.041 s both), so the
ML grid spans the same +-10 steps of the first level: +-10 Hz around the
coarse estimate. Here each method gets the same blocks (2.5 MHz, C/N0 45
dB-Hz per tone, steady comb, seeded) and the same coarse estimate (the
block FFT's comb search), and we report its seconds per block and its RMSE
against the truth.

Grid ML at fine resolution is slow by design (2e5 evaluations of eq. 2 at
1e-4 Hz). Unless ``full``, rows with more than ``ML_MAX_EVALS`` grid points
are timed on a subset of the grid and extrapolated linearly (the cost is
exactly proportional to the number of points), and their estimate is the
argmax of the same grid restricted to +-50 steps around the peak (the grid's
argmax lies there for a unimodal peak): the output says which rows.
"""

import time

import numpy as np

from ...signal.channel import doppler_blocks
from ...signal.coarse import coarse_fft
from ...signal.doppler import estimate_block
from ...signal.fine import fine_fmlef, fine_ml, periodogram_grid
from ...signal.fft import fft
from ...signal.pilot import PilotComb

__all__ = ["table2", "table3", "PAPER_TABLE2", "PAPER_TABLE3"]

FS_HZ = 2.5e6
CN0_DBHZ = 45.0
SPAN_HZ = 10.0
ML_MAX_EVALS = 2_001

#: [Shen 2024] Table 2 (N = 3e5): resolution [Hz] -> (ML s, FMLEF s).
PAPER_TABLE2 = {1.0: (0.041, 0.041), 0.1: (0.35, 0.091), 0.01: (3.49, 0.13), 0.001: (34.82, 0.16),
                0.0001: (347.11, 0.20)}
#: [Shen 2024] Table 3 (resolution 0.01 Hz): N -> (ML s, FMLEF s).
PAPER_TABLE3 = {100_000: (1.25, 0.044), 200_000: (2.38, 0.081), 300_000: (3.49, 0.13),
                400_000: (4.77, 0.16), 500_000: (6.11, 0.22)}


def _blocks(n, trials, seed):
    rng = np.random.default_rng(seed)
    truth = rng.uniform(-2e5, 2e5, trials)
    return truth, doppler_blocks(FS_HZ, n, truth, 0.0, CN0_DBHZ, rng=rng)


def _timed(func, *args, **kw):
    t0 = time.perf_counter()
    out = func(*args, **kw)
    return out, time.perf_counter() - t0


def _ml(x, coarse_hz, resolution, full):
    """Grid ML estimate and seconds; (estimate, seconds, extrapolated)."""
    m = int(round(SPAN_HZ / resolution))
    n_evals = 2 * m + 1
    if full or n_evals <= ML_MAX_EVALS:
        est, sec = _timed(fine_ml, x, FS_HZ, coarse_hz, resolution, SPAN_HZ)
        return est, sec, False
    _, sec = _timed(periodogram_grid, x, FS_HZ, coarse_hz - m * resolution, resolution, ML_MAX_EVALS)
    peak = fine_fmlef(x, FS_HZ, coarse_hz, resolution, 1.0)
    local = periodogram_grid(x, FS_HZ, peak - 50 * resolution, resolution, 101)
    return peak + (int(np.argmax(local)) - 50) * resolution, sec * n_evals / ML_MAX_EVALS, True


def _row(x_blocks, truth, resolution, full):
    comb = PilotComb()
    res = {"ml": [], "fmlef": [], "fast": []}
    sec = {"ml": [], "fmlef": [], "fast": [], "fft": []}
    extrapolated = False
    for x, d in zip(x_blocks, truth):
        coarse = coarse_fft(fft(x), FS_HZ, comb)
        est, s, extrapolated = _ml(x, coarse.doppler_hz, resolution, full)
        res["ml"].append(est - d)
        sec["ml"].append(s)
        est, s = _timed(fine_fmlef, x, FS_HZ, coarse.doppler_hz, resolution, 1.0)
        res["fmlef"].append(est - d)
        sec["fmlef"].append(s)
        out, s = _timed(estimate_block, x, FS_HZ)  # coarse FFT included
        res["fast"].append(out["doppler_hz"] - d)
        sec["fast"].append(s)
        _, s = _timed(fft, x)
        sec["fft"].append(s)
    row = {f"{k}_s": float(np.median(v)) for k, v in sec.items()}
    row.update({f"{k}_rmse_hz": float(np.sqrt(np.mean(np.square(v)))) for k, v in res.items()})
    row["ml_extrapolated"] = extrapolated
    return row


def table2(*, seed=0, full=False, trials=3):
    """Table 2: N = 3e5, resolution 1 .. 1e-4 Hz. Returns the JSON document."""
    truth, x = _blocks(300_000, trials, seed)
    rows = []
    for resolution, (ml_s, fmlef_s) in PAPER_TABLE2.items():
        row = {"resolution_hz": resolution, "paper_ml_s": ml_s, "paper_fmlef_s": fmlef_s}
        row.update(_row(x, truth, resolution, full))
        rows.append(row)
    return {"paper": "[Shen 2024] Table 2", "n_samples": 300_000, "sample_rate_hz": FS_HZ, "cn0_dbhz": CN0_DBHZ,
            "trials": trials, "rows": rows}


def table3(*, seed=0, full=False, trials=3):
    """Table 3: resolution 0.01 Hz, N = 1e5 .. 5e5. Returns the JSON document."""
    rows = []
    for n, (ml_s, fmlef_s) in PAPER_TABLE3.items():
        truth, x = _blocks(n, trials, seed)
        row = {"n_samples": n, "paper_ml_s": ml_s, "paper_fmlef_s": fmlef_s}
        row.update(_row(x, truth, 0.01, full))
        rows.append(row)
    return {"paper": "[Shen 2024] Table 3", "resolution_hz": 0.01, "sample_rate_hz": FS_HZ, "cn0_dbhz": CN0_DBHZ,
            "trials": trials, "rows": rows}


def format_table(doc):
    """Plain-text rendering, paper seconds beside ours."""
    first = "resolution_hz" if "resolution_hz" in doc["rows"][0] else "n_samples"
    head = (f"{first:>13} | paper ML s | ours ML s  | paper FMLEF s | ours FMLEF s | ours fast s | 1 FFT s  "
            f"| RMSE ML / FMLEF / fast [Hz]")
    lines = [f"{doc['paper']}: {doc['trials']} block(s) per row, C/N0 {doc['cn0_dbhz']:g} dB-Hz per tone, "
             f"{doc['sample_rate_hz'] / 1e6:g} MHz", head, "-" * len(head)]
    for r in doc["rows"]:
        star = "*" if r["ml_extrapolated"] else " "
        lines.append(f"{r[first]:>13g} | {r['paper_ml_s']:>10.3f} | {r['ml_s']:>9.4f}{star} | "
                     f"{r['paper_fmlef_s']:>13.3f} | {r['fmlef_s']:>12.4f} | {r['fast_s']:>11.5f} | "
                     f"{r['fft_s']:>8.5f} | {r['ml_rmse_hz']:.2e} / {r['fmlef_rmse_hz']:.2e} / {r['fast_rmse_hz']:.2e}")
    if any(r["ml_extrapolated"] for r in doc["rows"]):
        lines.append(f"* timed on {ML_MAX_EVALS} of the grid's points and scaled to the whole grid; its "
                     "estimate is the argmax of the grid restricted to +-50 steps around the peak (--full runs all)")
    return "\n".join(lines)
