"""Filter consistency of the simulate pipeline over many seeds (issue 6 goal).

Runs the default xian-baoji flight at measurement level for N seeds with
both couplings (Dask-parallel through leosop.apps.studies) and prints, per
coupling: mean fused errors, mean NEES of position and velocity per
dimension (goal: within [0.5, 2]), NIS per degree of freedom with its 99 %
interval, and the lag-1 correlation of the whitened innovations (loose: the
6-vectors; tight: each satellite's normalised Doppler innovation at
consecutive epochs) with its null 3-sigma bound.

The loose filter models the satellites' constant Doppler offsets and orbit
errors behind each fix (leosop.fusion.aids_fix), the tight one behind each
Doppler, both under the run's orbit-error model (per satellite, or one shift
of all); ``--orbit-error-m``/``--orbit-error-model`` run Table 6's cases.

Usage: python tools/fusion_consistency.py [--seeds 20] [--duration-s 782] [--orbit-error-m 30]
       [--orbit-error-model common] [--scheduler serial]
"""

import argparse
import dataclasses

import numpy as np
from scipy import stats

from leosop.apps.scenarios import XIAN_BAOJI
from leosop.apps.simulate import metrics, run_scenario
from leosop.apps.studies import map_chunks


def one(chunk, rng):
    coupling, seed, duration_s, orbit_error_m, orbit_error_model = chunk
    r = run_scenario(dataclasses.replace(XIAN_BAOJI, duration_s=duration_s), level="measurement", seed=seed,
                     coupling=coupling, orbit_error_m=orbit_error_m, orbit_error_model=orbit_error_model)
    m = metrics(r)
    nis, dof = r.nis()
    if r.fused.innovation is not None:
        u = r.fused.updated
        L = np.linalg.cholesky(r.fused.innovation_cov[u])
        white = np.linalg.solve(L, r.fused.innovation[u][..., None])[..., 0]
        pairs = (white[:-1].ravel(), white[1:].ravel())
    else:
        d = np.sort(r.fused.doppler_innovation, order=("sat", "epoch"))
        next_ = (d["sat"][1:] == d["sat"][:-1]) & (d["epoch"][1:] == d["epoch"][:-1] + 1)
        pairs = (d["normalized"][:-1][next_], d["normalized"][1:][next_])
    return m["fused"], r.nees()[1:], nis, dof, pairs


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--duration-s", type=float, default=782.0)
    parser.add_argument("--orbit-error-m", type=float, help="default the scenario's (1 m per axis)")
    parser.add_argument("--orbit-error-model", choices=("independent", "common"))
    parser.add_argument("--scheduler")
    args = parser.parse_args()
    chunks = [(c, s, args.duration_s, args.orbit_error_m, args.orbit_error_model)
              for c in ("loose", "tight") for s in range(args.seeds)]
    results = map_chunks(one, chunks, scheduler=args.scheduler, desc="runs")
    for coupling in ("loose", "tight"):
        rs = [r for chunk, r in zip(chunks, results) if chunk[0] == coupling]
        pos = np.mean([r[0]["pos_err_mean_m"] for r in rs])
        vel = np.mean([r[0]["vel_err_mean_mps"] for r in rs])
        nees = np.concatenate([r[1] for r in rs])
        nis = np.concatenate([r[2] for r in rs])
        dof = np.concatenate([r[3] for r in rs])
        lo, hi = stats.chi2.ppf([0.005, 0.995], dof.sum()) / dof.sum()
        line = (f"{coupling}: {args.seeds} seeds x {args.duration_s:g} s  pos {pos:.2f} m  vel {vel:.4f} m/s  "
                f"NEES/6 {nees.mean() / 6:.2f} (goal 0.5-2)  NIS/dof {nis.sum() / dof.sum():.3f} "
                f"(99% [{lo:.3f}, {hi:.3f}])")
        a = np.concatenate([r[4][0] for r in rs])
        b = np.concatenate([r[4][1] for r in rs])
        line += f"  lag-1 corr {np.corrcoef(a, b)[0, 1]:.3f} (null |r| < {3 / np.sqrt(a.size):.3f})"
        print(line)


if __name__ == "__main__":
    main()
