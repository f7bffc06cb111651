"""Read time of the 24 h ESBC00DNK day: hatanaka + leosop.gnss.rinex vs hatanaka + georinex.

Run: ``python tools/bench_ppp_readers.py [--georinex]`` (georinex is optional and slow:
113 s on the shared 2-core machine, 2026-11; it is not a dependency of leosop).
"""

import sys
import tempfile
import time
from pathlib import Path

DAY = Path(__file__).resolve().parents[2] / "shared" / "data" / "rinex" / "esbc_2020-177"
OBS = DAY / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"
CODES = {"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]}


def main():
    import gzip

    import hatanaka

    from leosop.gnss.products import read_clk, read_sp3
    from leosop.gnss.rinex import read_obs

    t = time.perf_counter()
    text = hatanaka.decompress(gzip.decompress(OBS.read_bytes()))
    print(f"hatanaka.decompress (gunzipped CRINEX -> RINEX, {len(text) / 1e6:.1f} MB): {time.perf_counter() - t:.2f} s")
    t = time.perf_counter()
    obs = read_obs(OBS, codes=CODES)
    print(f"leosop.gnss.rinex.read_obs (G+E, {len(obs.time_gps)} epochs, incl. hatanaka): "
          f"{time.perf_counter() - t:.2f} s")
    t = time.perf_counter()
    read_sp3(DAY / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz")
    print(f"read_sp3: {time.perf_counter() - t:.2f} s")
    t = time.perf_counter()
    read_clk(DAY / "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz")
    print(f"read_clk: {time.perf_counter() - t:.2f} s")
    if "--georinex" in sys.argv:
        import warnings

        import georinex

        warnings.simplefilter("ignore")
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "esbc.rnx"
            path.write_bytes(text)
            t = time.perf_counter()
            georinex.load(path, use=["G", "E"], meas=[c for c in set(CODES["G"] + CODES["E"])])
            print(f"georinex.load (G+E, same observables): {time.perf_counter() - t:.2f} s")


if __name__ == "__main__":
    main()
