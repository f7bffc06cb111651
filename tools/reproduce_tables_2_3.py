"""[Shen 2024] Tables 2 and 3: grid ML vs FMLEF run time, ours beside the paper's, plus our fast estimator.

Usage: python tools/reproduce_tables_2_3.py [--table 2|3|both] [--trials N] [--seed S] [--full]

All methods run in this process on the same seeded blocks; seconds are the
median per block, single-threaded (FFTW one thread, OpenBLAS forced to one
thread below so that a loaded machine does not distort the small products).
Also available as ``leosop reproduce table2`` / ``table3``.
"""

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from leosop.apps.repro.doppler_tables import format_table, table2, table3  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--table", choices=("2", "3", "both"), default="both")
    p.add_argument("--trials", type=int, default=3, help="blocks per row (default 3)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--full", action="store_true", help="run the whole ML grid at every resolution (~10 min)")
    args = p.parse_args()
    if args.table in ("2", "both"):
        print(format_table(table2(seed=args.seed, full=args.full, trials=args.trials)))
        print()
    if args.table in ("3", "both"):
        print(format_table(table3(seed=args.seed, full=args.full, trials=args.trials)))


if __name__ == "__main__":
    main()
