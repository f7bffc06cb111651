"""Benchmark: the stacked matrix exponential of error_model.propagate against scipy.

Times ``scipy.linalg.expm`` and ``leosop.ins.error_model._expm_stack`` on the
15,000 augmented 10x10 step matrices of [Chu 2009]'s 150 s rolling flight at
100 Hz, prints the ratio and the largest difference.

Usage: python tools/bench_error_model.py
"""

import time

import numpy as np
import scipy.linalg

from leosop.ins import error_model as em
from leosop.apps.repro.error_model import _chu2009_rolling


def main():
    C_n_b, f_n, dt = _chu2009_rolling(100.0)
    F, G = em.model9(C_n_b, f_n)
    u = np.r_[np.full(3, np.radians(10.0) / 3600), np.full(3, 0.01 * 9.80665)]
    A = np.zeros((F.shape[0], 10, 10))
    A[:, :9, :9] = F
    A[:, :9, 9] = G @ u
    A *= dt
    t0 = time.perf_counter()
    E_ref = scipy.linalg.expm(A)
    scipy_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    E = em._expm_stack(A)
    ours_s = time.perf_counter() - t0
    print(f"{A.shape[0]} matrices {A.shape[1]}x{A.shape[2]}")
    print(f"scipy.linalg.expm: {scipy_s:7.3f} s")
    print(f"_expm_stack:       {ours_s:7.3f} s   speed-up {scipy_s / ours_s:6.1f}x")
    print(f"max |difference| / max |E|: {np.abs(E - E_ref).max() / np.abs(E_ref).max():.2e}")


if __name__ == "__main__":
    main()
