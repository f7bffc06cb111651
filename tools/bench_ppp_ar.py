"""Can the GRG products at hand fix ambiguities on real data? Wide-lane and narrow-lane fractional parts, ESBC00DNK.

Wide-lane: per satellite arc (>= 30 min, cycle slips split arcs), the mean Melbourne-Wuebbena
combination plus the satellite wide-lane bias of the GRG clock header; with correct biases every arc
has the same fractional part (the receiver's), so their circular spread measures fixability (< 0.1-0.15
cycle: WL fixing works). Baseline in the same run: the same spread without the biases (a uniform spread
is ~0.29 cycle).
Narrow-lane: per arc, the mean of the phase residual of the 24 h static float PPP (position, clocks
and ZWD fixed at the solution) less beta times the rounded wide-lane, in narrow-lane cycles; same
spread statistic. It needs the satellite antenna offsets the products were computed with
(igs14_2108.atx per the clock header), which are not in the data folder.

Run: ``OPENBLAS_NUM_THREADS=1 python tools/bench_ppp_ar.py``
"""

import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.constants import C_MPS  # noqa: E402
from leosop.gnss.ppp import PppOptions, prepare, run_ppp  # noqa: E402
from leosop.gnss.ppp_obs import SIGNALS  # noqa: E402
from leosop.gnss.products import read_clk, read_sp3, read_wl_biases  # noqa: E402
from leosop.gnss.rinex import read_obs  # noqa: E402

DAY = Path(__file__).resolve().parents[2] / "shared" / "data" / "rinex" / "esbc_2020-177"
OBS = DAY / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"
SP3 = DAY / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz"
CLK = DAY / "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz"
CODES = {"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]}
MIN_ARC = 60  # epochs of 30 s


def spread(values):
    """Circular mean and standard deviation of fractional parts [cycles]."""
    ph = np.exp(2j * np.pi * np.asarray(values))
    mean = np.angle(ph.mean()) / (2 * np.pi)
    dev = (np.asarray(values) - mean + 0.5) % 1.0 - 0.5
    return mean, dev.std()


def arcs(d, j):
    idx = np.flatnonzero(d["ok"][:, j])
    starts = [i for i in idx if d["new_arc"][i, j]]
    for a, b in zip(starts, starts[1:] + [d["ok"].shape[0]]):
        sel = idx[(idx >= a) & (idx < b)]
        if len(sel) >= MIN_ARC:
            yield sel


def main():
    obs = read_obs(OBS, codes=CODES)
    orb, clk = read_sp3(SP3), read_clk(CLK)
    wsb = read_wl_biases(CLK)
    opt = PppOptions(static=True)
    res = run_ppp(obs, orb, clk, opt)
    d = prepare(obs, orb, clk, opt)
    rr = res.pos_ecef_m[-1] + d["arp_ecef"] + d["tide"]
    rho = np.linalg.norm(d["RS"] - rr[:, None, :], axis=-1)
    sysof = np.array([s[0] for s in obs.sv])
    clock = np.where(sysof == "E", res.clock_m[:, 1:2], res.clock_m[:, 0:1])
    resid = d["Lc"] - rho - clock - d["m_wet"] * res.zwd_m[:, None]
    print(f"wide-lane biases in the GRG clock header: {sum(k[0] == 'G' for k in wsb)} GPS, "
          f"{sum(k[0] == 'E' for k in wsb)} Galileo")
    for s in "GE":
        f1, f2 = SIGNALS[s][4], SIGNALS[s][5]
        lam_nl, beta = C_MPS / (f1 + f2), C_MPS * f2 / (f1**2 - f2**2)
        mw_raw, mw, nl = [], [], []
        cols = [j for j, v in enumerate(obs.sv) if v[0] == s and v in wsb]
        for j in cols:
            for sel in arcs(d, j):
                m = np.mean(d["MW"][sel, j])
                mw_raw.append(m)
                mw.append(m + wsb[obs.sv[j]])
        rx_wl, sd_wl = spread(mw)
        for j in cols:
            for sel in arcs(d, j):
                n_wl = np.round(np.mean(d["MW"][sel, j]) + wsb[obs.sv[j]] - rx_wl)
                nl.append((np.mean(resid[sel, j]) - beta * n_wl) / lam_nl)
        _, sd_raw = spread(mw_raw)
        _, sd_nl = spread(nl)
        print(f"{s}: {len(mw)} arcs; WL fractional spread {sd_wl:.3f} cycle with the GRG biases "
              f"(without: {sd_raw:.3f}); NL fractional spread {sd_nl:.3f} cycle (uniform: 0.289)")


if __name__ == "__main__":
    main()
