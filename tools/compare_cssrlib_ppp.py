"""Float PPP of ESBC00DNK (2020-06-25) by leosop and by cssrlib, side by side: same files, same products.

Both get the day's observation file, the GRG (CNES) SP3 orbits and 30 s clocks, and the broadcast
navigation file; the reference is the station's published coordinate mapped to ITRF2014
(``leosop.gnss.etrf``, as ``tools/bench_ppp.py``). Printed per solver: read time, run time, and for
``--mode static`` the final 3-D error and the time from which it stays below 5 cm, for ``kinematic`` the
3-D RMS after ``--converge-min``.

What cssrlib (1.2.1, ``cssrlib.pppssr.pppos`` with ``ephopt = 4``, precise products) needs that the
shared data do not have, and what is given instead:

- an ANTEX file (satellite antenna offsets; without one it skips every satellite): its satellite
  antenna correction is set to zero, which is what leosop does too (no ANTEX, no offsets modelled);
  no receiver antenna model in either;
- a Bias-SINEX file of observable-specific biases (without one its biases are NaN): zero biases are
  given; the GRG clocks refer to the signals both use (GPS C1W/C2W and L1C/L2W, Galileo C1C/C5Q and
  L1C/L5Q), so zero is the consistent value for float PPP;
- the antenna reference point: its PPP reads the header's ``ANTENNA: DELTA H/E/N`` but does not
  apply it, so its solution is of the antenna reference point (0.216 m above the ESBC marker); the
  header's eccentricity is subtracted from its positions here (leosop applies it in the filter);
- plain-text files: the Hatanaka/gzip inputs are expanded to a temporary folder first (counted in its
  read time; leosop reads them as they are).

cssrlib estimates uncombined signals with slant ionosphere states; leosop the ionosphere-free
combination. Elevation mask 10 deg in both. cssrlib is an optional tool dependency, not a runtime
one: ``python -m pip install --target /tmp/cssr_site --no-deps cssrlib==1.2.1`` (its own imports need
numpy, scipy and bitstruct, which are here) and ``--cssrlib-path /tmp/cssr_site``.

With ``--ar`` both get the day's ANTEX subset (satellite and receiver antennas; the satellites without a
block are left out by both; the IGS14 satellite blocks have no PCV rows, zero in both) and fix ambiguities:
leosop its wide-lane/narrow-lane fixing with the GRG
integer clocks and the clock file's wide-lane biases (``leosop.gnss.ar``); cssrlib its own
(``armode = 1``, partial fixing, LAMBDA on the between-satellite single differences of the *uncombined*
L1 and L2 ambiguities), which needs per-signal phase biases (Bias-SINEX or SSR) that the GRG set does not
publish, and its clock reader keeps only the ``AS`` records (the ``WL`` bias lines are skipped). The
phase biases it is given are derived here from the clock file's wide-lane biases ``wsb`` [cycles]: per
satellite, ``d1 = wsb c f2 / (f1 (f1 - f2))`` on L1 and ``d2 = (f1 / f2)^2 d1`` on L2 [m], the pair whose
ionosphere-free combination is zero (the clock holds it) and whose wide-lane is ``-wsb`` (so that
Melbourne-Wuebbena + wsb is integer, as in [Laurichesse 2009]); code biases stay zero. Printed in
addition: time to first fix and the share of epochs fixed after it.

Run: ``OPENBLAS_NUM_THREADS=1 python tools/compare_cssrlib_ppp.py [--hours 24] [--start-h 0]
[--mode static|kinematic] [--ar] [--cssrlib-path DIR] [--save FILE.npz]``
"""

import argparse
import dataclasses
import gzip
import os
import sys
import tempfile
import time
from copy import deepcopy
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from leosop.constants import C_MPS  # noqa: E402
from leosop.frames import C_e_n, ecef_to_geodetic  # noqa: E402
from leosop.gnss.antex import check_antex, read_antex  # noqa: E402
from leosop.gnss.ar import ArOptions  # noqa: E402
from leosop.gnss.etrf import decimal_year, etrf2000_to_itrf2014  # noqa: E402
from leosop.gnss.ppp import PppOptions, run_ppp  # noqa: E402
from leosop.gnss.products import read_clk, read_sp3  # noqa: E402
from leosop.gnss.rinex import read_obs, read_text  # noqa: E402

DAY = Path(__file__).resolve().parents[2] / "shared" / "data" / "rinex" / "esbc_2020-177"
OBS = DAY / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"
NAV = DAY / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
SP3 = DAY / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz"
CLK = DAY / "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz"
ATX = DAY / "esbc_2020-177.atx"
CODES = {"G": ["C1C", "C1W", "C2W", "L1C", "L2W"], "E": ["C1C", "C5Q", "L1C", "L5Q"]}
CSSR_SIGNALS = ("GC1W", "GC2W", "GL1C", "GL2W", "GS1C", "GS2W", "EC1C", "EC5Q", "EL1C", "EL5Q", "ES1C", "ES5Q")
MASK_DEG = 10.0
EPOCH_S = 30.0
CSSR_FIXED = 4  # its nav.smode of an epoch with fixed ambiguities


def ours(n0, n_epochs, static, ar):
    """leosop PPP of epochs ``n0 : n0 + n_epochs`` (fixed with ``ar``).

    Returns (read s, run s, positions (n, 3), fixed (n,) bool, header position (3,), header H/E/N (3,),
    wide-lane biases {sv: cycles}).
    """
    t0 = time.perf_counter()
    obs = read_obs(OBS, codes=CODES)
    orb, clk = read_sp3(SP3), read_clk(CLK)
    atx = read_antex(ATX) if ar else None
    t1 = time.perf_counter()
    span = slice(n0, n0 + n_epochs)
    obs = dataclasses.replace(obs, time_gps=obs.time_gps[span], obs={k: v[span] for k, v in obs.obs.items()},
                              lli={k: v[span] for k, v in obs.lli.items()})
    opt = PppOptions(static=static, systems="GE", mask_deg=MASK_DEG)
    if ar:
        _, no_ar = check_antex(atx, obs.antenna_type, obs.sv, obs.time_gps[0].astype("datetime64[D]"),
                               clk.pcvs_applied)
        res = run_ppp(obs, orb, clk, opt, atx, ar=ArOptions(), no_ar=no_ar)
    else:
        res = run_ppp(obs, orb, clk, opt)
    return (t1 - t0, time.perf_counter() - t1, res.pos_ecef_m, res.fixed, obs.approx_pos_ecef_m,
            obs.antenna_delta_hen_m, clk.wl_bias_cyc)


class _ZeroBiases:
    """Bias-SINEX stand-in: zero observable-specific biases (see the module notes)."""

    def getosb(self, sat, t, sig):
        return 0.0


class _WideLaneBiases:
    """Bias-SINEX stand-in for cssrlib's AR: phase biases [ns] from the GRG wide-lane biases (module notes).

    Parameters
    ----------
    wl_bias_cyc : dict of str -> float
        Satellite wide-lane biases [cycles] by "G01"-style name (``leosop.gnss.products.Clocks``).
    """

    def __init__(self, wl_bias_cyc):
        self.wl_bias_cyc = wl_bias_cyc

    def getosb(self, sat, t, sig):
        from cssrlib.gnss import rSigRnx, sat2id, uTYP

        wsb = self.wl_bias_cyc.get(sat2id(sat))
        if sig.typ != uTYP.L or wsb is None:
            return 0.0
        sys = sat2id(sat)[0]
        f1, f2 = (rSigRnx(s).frequency() for s in (("GL1C", "GL2W") if sys == "G" else ("EL1C", "EL5Q")))
        d1_m = wsb * C_MPS * f2 / (f1 * (f1 - f2))
        d_m = d1_m if abs(sig.frequency() - f1) < 1.0 else d1_m * (f1 / f2) ** 2
        return d_m / (C_MPS * 1e-9)  # cssrlib adds -osb * c * 1e-9 to its phase model


def theirs(n0, n_epochs, static, tmp, wl_bias_cyc=None):
    """cssrlib PPP on plain-text copies of the same files, epochs ``n0 : n0 + n_epochs``.

    With ``wl_bias_cyc`` (a dict as ``_WideLaneBiases`` takes) it gets the ANTEX and fixes ambiguities.
    Returns (read s, run s, positions (n, 3), fixed (n,) bool).
    """
    import cssrlib.pppssr as pppssr
    from cssrlib.gnss import Nav, rSigRnx
    from cssrlib.peph import atxdec, peph, searchpcv
    from cssrlib.rinex import rnxdec

    t0 = time.perf_counter()
    files = {}
    for name, src in (("obs.rnx", OBS), ("nav.rnx", NAV), ("orb.sp3", SP3), ("clk.clk", CLK)):
        files[name] = Path(tmp) / name
        if name == "obs.rnx":  # Hatanaka
            files[name].write_text("\n".join(read_text(src)) + "\n")
        else:
            files[name].write_bytes(gzip.decompress(src.read_bytes()))
    rnx = rnxdec()
    rnx.setSignals([rSigRnx(s) for s in CSSR_SIGNALS])
    nav = Nav()
    nav.pmode = 0 if static else 1
    orb = peph()
    nav = rnx.decode_nav(str(files["nav.rnx"]), nav)
    nav = orb.parse_sp3(str(files["orb.sp3"]), nav)
    nav = rnx.decode_clk(str(files["clk.clk"]), nav)
    if rnx.decode_obsh(str(files["obs.rnx"])) < 0:
        raise SystemExit("cssrlib could not read the observation header")
    ar = wl_bias_cyc is not None
    if ar:
        atx = atxdec()
        atx.readpcv(str(ATX))
        for pcv in atx.pcvs:  # the IGS14 satellite blocks have no PCV rows: zero PCV (as leosop), not NaN
            n_zen = int(round((pcv.zen[1] - pcv.zen[0]) / pcv.zen[2])) + 1
            pcv.var = {sig: pcv.var.get(sig, np.zeros(n_zen)) for sig in pcv.off}
    obs = rnx.decode_obs()
    for _ in range(n0):
        obs = rnx.decode_obs()
    t1 = time.perf_counter()
    if not ar:  # No ANTEX: zero satellite antenna correction (as leosop), none for the receiver.
        pppssr.antModelTx = lambda nav_, e, sigs, *args, **kw: np.zeros(len(sigs))
    ppp = pppssr.pppos(nav, rnx.pos, None)
    nav.ephopt, nav.armode = 4, int(ar)
    nav.elmin = np.radians(MASK_DEG)
    nav.cnr_min = nav.cnr_min_gpy = 0.0
    nav.sat_ant, nav.rcv_ant = ([], None) if not ar else (atx.pcvs, searchpcv(atx.pcvr, rnx.ant, obs.t))
    if static:  # its pmode 0 re-estimates the position every epoch (100 m/sqrt(s)); its samples zero that for a station
        nav.q[0:3] = 0.0
    pos = np.full((n_epochs, 3), np.nan)
    fixed = np.zeros(n_epochs, dtype=bool)
    nav.t = deepcopy(obs.t)
    bsx = _WideLaneBiases(wl_bias_cyc) if ar else _ZeroBiases()
    for k in range(n_epochs):
        ppp.process(obs, orb=orb, bsx=bsx)
        fixed[k] = nav.smode == CSSR_FIXED
        pos[k] = nav.xa[0:3] if fixed[k] else nav.x[0:3]
        obs = rnx.decode_obs()
        if obs.t.time == 0:
            break
    rnx.fobs.close()
    return t1 - t0, time.perf_counter() - t1, pos, fixed


def good_last(ok):
    """Index of the last epoch with a solution (ok: (n,) bool)."""
    return np.flatnonzero(ok)[-1]


def report(name, t_read, t_run, pos, ref, static, converge_min, fixed=None):
    lat, lon, _ = ecef_to_geodetic(ref)
    C = C_e_n(lat, lon)
    err = pos - ref
    ok = np.isfinite(err).all(axis=1)
    t_h = np.arange(len(pos)) * EPOCH_S / 3600.0
    norm = np.linalg.norm(err, axis=1)
    if static:
        e = err[ok][-1]
        good = np.flatnonzero(ok)
        bad = good[norm[good] >= 0.05]
        later = good[good > bad[-1]] if bad.size else good
        stay = t_h[later[0]] if later.size else None
        at = [h for h in (1, 2, 6, 12) if h < t_h[-1]]
        acc = (f"final 3-D error {100 * np.linalg.norm(e):.1f} cm, ENU {np.round(100 * C.T @ e, 1).tolist()} cm, "
               + (f"below 5 cm from {stay:.2f} h" if stay is not None else "not below 5 cm at the end")
               + "".join(f", {h} h: {100 * norm[int(h * 3600 / EPOCH_S)]:.1f} cm" for h in at))
    else:
        sel = ok & (t_h >= converge_min / 60.0)
        acc = f"3-D RMS after {converge_min:g} min {100 * np.sqrt(np.mean(norm[sel] ** 2)):.1f} cm"
    if fixed is not None:
        first = np.flatnonzero(fixed)
        fx = np.flatnonzero(fixed & ok)
        acc += (f"; first fix after {t_h[first[0]] * 60:.1f} min, fixed {100 * fixed[first[0]:].mean():.1f} % of the "
                f"epochs after it, 3-D RMS after it {100 * np.sqrt(np.mean(norm[fx] ** 2)):.1f} cm, fixed epochs more "
                f"than 5 cm off {np.sum(norm[fx] > 0.05)}; final 3-D error {100 * norm[good_last(ok)]:.1f} cm "
                f"({'fixed' if fixed[good_last(ok)] else 'float'})" if first.size else "; never fixed")
    print(f"{name:8s} {'static' if static else 'kinematic'}: {acc}; read {t_read:.1f} s, run {t_run:.1f} s "
          f"({1e3 * t_run / len(pos):.1f} ms/epoch), epochs without a solution {np.sum(~ok)}", flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--start-h", type=float, default=0.0, help="hours into the day of the first epoch")
    ap.add_argument("--ar", action="store_true", help="ANTEX and ambiguity fixing in both (module notes)")
    ap.add_argument("--mode", choices=("static", "kinematic"), default="static")
    ap.add_argument("--converge-min", type=float, default=60.0)
    ap.add_argument("--cssrlib-path", help="folder cssrlib was installed into (pip install --target)")
    ap.add_argument("--save", metavar="FILE.npz", help="both solutions per epoch and the reference")
    a = ap.parse_args()
    if a.cssrlib_path:
        sys.path.insert(0, a.cssrlib_path)
    try:  # before the leosop run, which would be wasted
        import cssrlib.pppssr  # noqa: F401
    except ImportError as exc:
        raise SystemExit(f"compare_cssrlib_ppp: cannot import cssrlib ({exc}); install it (module notes) and give "
                         "--cssrlib-path") from None
    n0, n = (int(round(h * 3600 / EPOCH_S)) for h in (a.start_h, a.hours))
    static = a.mode == "static"
    t_read, t_run, pos, fixed, header_ecef_m, delta_hen_m, wl_bias_cyc = ours(n0, n, static, a.ar)
    # The header position is the station's ETRF2000 coordinate; the products' frame is ITRF2014.
    ref = etrf2000_to_itrf2014(header_ecef_m, decimal_year(np.datetime64("2020-06-25T12:00")))
    report("leosop", t_read, t_run, pos, ref, static, a.converge_min, fixed if a.ar else None)
    with tempfile.TemporaryDirectory() as tmp:
        c_read, c_run, c_arp, c_fixed = theirs(n0, n, static, tmp, wl_bias_cyc if a.ar else None)
    lat, lon, _ = ecef_to_geodetic(ref)
    c_pos = c_arp - C_e_n(lat, lon) @ delta_hen_m[[1, 2, 0]]  # antenna reference point -> marker
    report("cssrlib", c_read, c_run, c_pos, ref, static, a.converge_min, c_fixed if a.ar else None)
    print(f"run time cssrlib / leosop: {c_run / t_run:.0f}")
    if a.save:
        np.savez(a.save, leosop_ecef_m=pos, cssrlib_ecef_m=c_pos, ref_ecef_m=ref, leosop_fixed=fixed,
                 cssrlib_fixed=c_fixed)


if __name__ == "__main__":
    main()
