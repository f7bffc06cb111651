"""Our LAMBDA (leosop.gnss.lambda_) beside cssrlib's MLAMBDA: same candidates, same norms, time per call.

cssrlib is not a dependency of leosop: ``python -m pip install --target /tmp/cssr_site --no-deps cssrlib==1.2.1
bitstruct`` and ``--cssrlib-path /tmp/cssr_site`` (or ``pip install cssrlib bitstruct``).
Cases: the published 3-ambiguity example ([Teunissen 1995], [de Jonge 1996]) and random
well- and ill-conditioned covariances of 4 to 20 ambiguities (float values with a strong
correlation, as PPP ambiguities are).

Run: ``OPENBLAS_NUM_THREADS=1 python tools/compare_lambda_cssrlib.py [--cssrlib-path DIR]``
"""

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.gnss.lambda_ import ils  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description="leosop's LAMBDA beside cssrlib's MLAMBDA (module notes)")
    ap.add_argument("--cssrlib-path", help="folder cssrlib was installed into (pip install --target)")
    a = ap.parse_args()
    if a.cssrlib_path:
        sys.path.insert(0, a.cssrlib_path)
    try:
        from cssrlib.mlambda import mlambda
    except ImportError as exc:
        raise SystemExit(f"compare_lambda_cssrlib: cannot import cssrlib ({exc}); install it (module notes) and "
                         "give --cssrlib-path") from None

    rng = np.random.default_rng(0)
    cases = [(np.array([5.45, 3.10, 2.97]),
              np.array([[6.290, 5.978, 0.544], [5.978, 6.292, 2.340], [0.544, 2.340, 6.288]]))]
    for _ in range(300):
        n = int(rng.integers(4, 21))
        A = rng.normal(size=(n, n)) + 3.0 * rng.normal(size=(1, n))  # a common part: correlated ambiguities
        Q = A @ A.T * 10.0 ** rng.uniform(-3, -1) + 1e-4 * np.eye(n)
        cases.append((rng.normal(size=n) * 10.0, Q))
    same = 0
    t_ours = t_theirs = 0.0
    worst = 0.0
    for a_hat, Q in cases:
        t = time.perf_counter()
        a, s = ils(a_hat, Q)
        t_ours += time.perf_counter() - t
        t = time.perf_counter()
        b, s2, _, _ = mlambda(a_hat, Q)
        t_theirs += time.perf_counter() - t
        b = np.asarray(b).T if np.asarray(b).shape[0] == len(a_hat) else np.asarray(b)
        same += int(np.array_equal(a[0], np.round(b[0])) and np.array_equal(a[1], np.round(b[1])))
        worst = max(worst, float(np.max(np.abs(np.asarray(s) - np.asarray(s2)) / np.maximum(np.asarray(s2), 1e-12))))
    n = len(cases)
    print(f"{n} cases: identical best and second candidates in {same}; largest relative norm difference {worst:.1e}")
    print(f"time per call: leosop {1e3 * t_ours / n:.2f} ms, cssrlib mlambda {1e3 * t_theirs / n:.2f} ms")


if __name__ == "__main__":
    main()
