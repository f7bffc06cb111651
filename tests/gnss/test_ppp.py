"""Readers on the real ESBC00DNK day, a short static float PPP window, bad input."""

import dataclasses
import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.cli import ppp as ppp_cli
from leosop.errors import InputError
from leosop.frames import C_e_n, ecef_to_geodetic
from leosop.gnss.antex import read_antex
from leosop.gnss.etrf import decimal_year, etrf2000_to_itrf2014
from leosop.gnss.ppp import PppOptions, gps_to_utc, prepare, run_ppp
from leosop.gnss.products import read_clk, read_sp3
from leosop.gnss.rinex import check_nav, read_obs, read_text

from tests.helpers import ESBC_ATX, ESBC_CLK, ESBC_CODES, ESBC_DAY, ESBC_NAV, ESBC_OBS, ESBC_SP3

DAY, OBS, NAV, SP3, CLK, CODES = ESBC_DAY, ESBC_OBS, ESBC_NAV, ESBC_SP3, ESBC_CLK, ESBC_CODES
DATA = DAY.parent
HEADER_ECEF_M = np.array([3582105.2910, 532589.7313, 5232754.8054])
#: The header position is the station's ETRF2000 (ETRS89) coordinate; in ITRF2014 (the frame of the GRG
#: products) at the day's epoch it is this (leosop.gnss.etrf, [Altamimi 2018]); the 0.76 m between the two
#: is the Eurasian plate's motion since 1989.
REF_ITRF_ECEF_M = etrf2000_to_itrf2014(HEADER_ECEF_M, decimal_year(np.datetime64("2020-06-25T12:00")))

needs_data = pytest.mark.skipif(not all(p.exists() for p in (OBS, NAV, SP3, CLK)), reason="ESBC data absent")


@pytest.fixture(scope="module")
def day():
    obs = read_obs(OBS, codes=CODES)
    return obs, read_sp3(SP3), read_clk(CLK)


def _window(obs, n):
    return dataclasses.replace(obs, time_gps=obs.time_gps[:n], obs={k: v[:n] for k, v in obs.obs.items()},
                               lli={k: v[:n] for k, v in obs.lli.items()})


@needs_data
def test_readers_on_real_files(day):
    obs, orb, clk = day
    assert obs.version == pytest.approx(3.05) and obs.marker == "ESBC00DNK"
    assert len(obs.time_gps) == 2880 and obs.interval_s == 30.0
    assert obs.time_gps[-1] == np.datetime64("2020-06-25T23:59:30")
    np.testing.assert_allclose(obs.approx_pos_ecef_m, HEADER_ECEF_M, atol=1e-4)
    assert obs.antenna_delta_hen_m[0] == pytest.approx(0.216)
    # First epoch, E01 C1C as printed in the file: 27616185.992 m.
    assert obs.obs["E:C1C"][0, obs.sv.index("E01")] == pytest.approx(27616185.992, abs=1e-3)
    assert orb.pos_ecef_m.shape[0] == 96 and orb.t_s[1] - orb.t_s[0] == 900.0
    # SP3 node reproduced exactly; the record: PE01 -11562.163582 14053.114306 23345.128269 km.
    j = orb.sv.index("E01")
    np.testing.assert_allclose(orb.position(np.array([j]), orb.t_s[:1])[0],
                               [-11562163.582, 14053114.306, 23345128.269], atol=1e-6)
    # Lagrange interpolation of the 30-min subset hits the dropped 15-min nodes within 10 cm.
    sub = dataclasses.replace(orb, t_s=orb.t_s[::2], pos_ecef_m=orb.pos_ecef_m[::2])
    tq = orb.t_s[11:80:2]
    err = sub.position(np.full(len(tq), j), tq) - orb.pos_ecef_m[11:80:2, j]
    assert np.abs(err).max() < 0.1
    assert clk.bias_s.shape[0] == 2880
    assert clk.bias(np.array([clk.sv.index("E01")]), np.array([0.0]))[0] == pytest.approx(-0.884707516318e-3,
                                                                                          abs=1e-15)
    assert check_nav(NAV) == np.datetime64("2020-06-25") or check_nav(NAV) <= np.datetime64("2020-06-25")


@needs_data
def test_static_window_converges(day):
    obs, orb, clk = day
    obs2 = _window(obs, 480)  # 4 h at 30 s
    res = {s: run_ppp(obs2, orb, clk, PppOptions(static=True, systems=s)) for s in ("GE", "G", "E")}
    final = {s: r.pos_ecef_m[-1] for s, r in res.items()}
    # GPS-only and Galileo-only use disjoint satellites and clocks: agreement within 15 cm after 4 h (4.9 cm).
    assert np.linalg.norm(final["G"] - final["E"]) < 0.15
    # Against the published coordinate: within 10 cm after 4 h (float PPP converges over hours: measured
    # 7.6 cm; the 24 h run of tools/bench_ppp.py stays below 5 cm from 7.3 h on and ends at 1.3 cm).
    assert np.linalg.norm(final["GE"] - REF_ITRF_ECEF_M) < 0.10
    z = res["GE"].zwd_m[-1]
    assert 0.0 < z < 0.4  # zenith wet delay of a mid-latitude summer day
    # With troposphere gradients: the horizontal stays within 1 cm of the run without (measured 0.5 cm east),
    # and the gradients are millimetres (at most 0.9 mm north, 1.3 mm east over these 4 h; 5 mm would take
    # a strong weather front).
    grad = run_ppp(obs2, orb, clk, PppOptions(static=True, gradients=True))
    lat, lon, _ = ecef_to_geodetic(REF_ITRF_ECEF_M)
    d_enu = (grad.pos_ecef_m[-1] - final["GE"]) @ C_e_n(lat, lon)
    assert np.abs(d_enu[:2]).max() < 0.01
    assert np.isfinite(grad.grad_ne_m[-1]).all() and np.abs(grad.grad_ne_m[-1]).max() < 0.005
    assert np.isnan(res["GE"].grad_ne_m).all()


@needs_data
def test_progress_over_the_epochs_and_a_stop_ends_the_run(day, monkeypatch):
    """The day's PPP takes seconds to tens of seconds: a bar over the epochs, whose steps also honour Ctrl-C."""
    import leosop.progress
    from leosop import interrupt

    obs, orb, clk = day
    obs2 = _window(obs, 40)
    steps = []
    real = leosop.progress.progress

    def counting(iterable, **kw):
        steps.append(kw.get("desc"))
        return real(iterable, **kw)

    monkeypatch.setattr(leosop.progress, "progress", counting)
    quiet, shown = (run_ppp(obs2, orb, clk, PppOptions(static=True), show_progress=p) for p in (False, True))
    assert steps == ["ppp"] and np.array_equal(quiet.pos_ecef_m, shown.pos_ecef_m, equal_nan=True)
    monkeypatch.setattr(interrupt, "_requested", True)  # a stop asked for (leosop.interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_ppp(obs2, orb, clk, PppOptions(static=True), show_progress=True)


def test_gps_to_utc():
    assert gps_to_utc(np.datetime64("2020-06-25T00:00:18")) == np.datetime64("2020-06-25T00:00:00")


def _head_lines(n):
    return read_text(OBS)[:n]


@needs_data
def test_truncated_obs(tmp_path):
    lines = _head_lines(100)
    p = tmp_path / "trunc.rnx"
    p.write_text("\n".join(lines[:70]) + "\n")  # cut inside an epoch
    with pytest.raises(InputError, match=r"trunc\.rnx: line \d+: .*truncated"):
        read_obs(p)


@needs_data
def test_mixed_version_obs(tmp_path):
    lines = _head_lines(100)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    rinex2_epoch = " 20  6 25  0  1  0.0000000  0  2G05G07"
    p = tmp_path / "mixed.rnx"
    p.write_text("\n".join(lines[:end + 1] + [rinex2_epoch] + lines[end + 1:]) + "\n")
    with pytest.raises(InputError, match=rf"mixed\.rnx: line {end + 2}: expected an epoch record"):
        read_obs(p)
    p2 = tmp_path / "v2.rnx"
    p2.write_text("     2.11" + lines[0][9:] + "\n" + "\n".join(lines[1:]) + "\n")
    with pytest.raises(InputError, match=r"v2\.rnx: line 1: RINEX version 2.11"):
        read_obs(p2)


@needs_data
def test_missing_frequency(tmp_path, day):
    _, orb, clk = day
    lines = _head_lines(400)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    # Rename GPS C2W and L2W in the header: no second GPS frequency for the IF combination.
    head = [line.replace("C2W", "C2X").replace("L2W", "L2X") if line.startswith("G   18") else line
            for line in lines[:end + 1]]
    p = tmp_path / "nol2.rnx"
    stop = max(i for i, line in enumerate(lines) if line.startswith(">"))  # whole epochs only
    p.write_text("\n".join(head + lines[end + 1:stop]) + "\n")
    obs = read_obs(p, codes=CODES)
    with pytest.raises(InputError, match=r"nol2\.rnx: system G lacks C2W, L2W"):
        run_ppp(obs, orb, clk, PppOptions(systems="G"))


@needs_data
def test_products_of_another_day(day):
    obs, _, _ = day
    other_sp3 = DATA / "igs_2010-182" / "igs15904.sp3"
    other_clk = DATA / "igs_2010-182" / "igs15904.clk"
    if not other_sp3.exists():
        pytest.skip("igs_2010-182 absent")
    obs2 = _window(obs, 20)
    with pytest.raises(InputError, match=r"igs15904\.sp3: line 1: product covers 2010-07-01"):
        run_ppp(obs2, read_sp3(other_sp3, systems="G"), read_clk(other_clk, systems="G"), PppOptions(systems="G"))


@needs_data
def test_no_common_satellites(day):
    obs, orb, clk = day
    only_e = dataclasses.replace(orb, sv=[s for s in orb.sv if s[0] == "E"],
                                 pos_ecef_m=orb.pos_ecef_m[:, [i for i, s in enumerate(orb.sv) if s[0] == "E"]])
    with pytest.raises(InputError, match="no satellite in common"):
        run_ppp(_window(obs, 20), only_e, clk, PppOptions(systems="G"))


@needs_data
def test_cli_bad_input_exit_2(tmp_path, capsys):
    p = tmp_path / "empty.sp3"
    p.write_text("not an sp3 file\n")
    code = main(["ppp", str(OBS), "--nav", str(NAV), "--sp3", str(p), "--clk", str(CLK), "--static", "--json"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "empty.sp3: line 1: not an SP3" in err[0]
    code = main(["ppp", str(OBS), "--nav", str(NAV), "--sp3", str(SP3), "--clk", str(CLK), "--ar"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "give them with --antex" in err[0]


@needs_data
def test_cli_json_contract(tmp_path, capsys, monkeypatch):
    # A 1-hour observation file keeps the run short.
    lines = read_text(OBS)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    stop = next(i for i, line in enumerate(lines) if line.startswith("> 2020 06 25 01 00"))
    p = tmp_path / "esbc_1h.rnx"
    p.write_text("\n".join(lines[:stop]) + "\n")
    assert end < stop
    code = main(["ppp", str(p), "--nav", str(NAV), "--sp3", str(SP3), "--clk", str(CLK), "--static", "--json",
                 "--out", str(tmp_path / "out")])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    sol = doc["solutions"][-1]
    for key in ("time_utc", "x_m", "y_m", "z_m", "lat_deg", "lon_deg", "alt_m", "fixed", "sigma_enu_m"):
        assert key in sol
    assert sol["time_utc"] == "2020-06-25T00:59:12.000000Z"  # 00:59:30 GPST - 18 s
    assert sol["fixed"] is False and len(sol["sigma_enu_m"]) == 3
    pos = doc["summary"]["position"]
    # One hour of float PPP: decimetres (0.3 m is three times the 4 h bound above).
    assert np.linalg.norm(np.array([pos["x_m"], pos["y_m"], pos["z_m"]]) - REF_ITRF_ECEF_M) < 0.3
    assert all((tmp_path / "out" / f).exists() for f in ("ppp.json", "ppp.csv", "ppp.png"))
    # The header-frame comparison: the metre-level plate motion is gone, decimetres of 1 h float PPP remain.
    assert np.linalg.norm(doc["summary"]["minus_header_approx_m"]) > 0.5
    assert np.linalg.norm(doc["summary"]["minus_header_if_etrf2000_m"]) < 0.3
    # The text says the frame: ENU, the same numbers as the JSON's ENU keys.
    text = ppp_cli.summary(doc)
    d = doc["summary"]["minus_header_if_etrf2000_enu_m"]
    assert "ENU: E " in text and f"U {d[2]:+.4f}" in text
    assert np.isclose(np.linalg.norm(d), np.linalg.norm(doc["summary"]["minus_header_if_etrf2000_m"]))
    # Kinematic: the RMS against the header coordinate (as ETRF2000, in ITRF2014), 3-D and per ENU axis.
    code = main(["ppp", str(p), "--nav", str(NAV), "--sp3", str(SP3), "--clk", str(CLK), "--json"])
    doc = json.loads(capsys.readouterr().out)
    rms = doc["summary"]["kinematic_rms"]["all"]
    e = np.array([[s["x_m"], s["y_m"], s["z_m"]] for s in doc["solutions"]]) - REF_ITRF_ECEF_M
    # The CLI maps the header at the file's mid-epoch (00:30), REF_ITRF_ECEF_M at noon: 0.04 mm of plate motion.
    assert code == 0 and rms["rms_3d_m"] == pytest.approx(np.sqrt(np.mean(np.sum(e**2, axis=1))), abs=1e-4)
    assert np.linalg.norm(rms["rms_enu_m"]) == pytest.approx(rms["rms_3d_m"])
    assert "RMS against the header" in ppp_cli.summary(doc) and "after_1h" not in doc["summary"]["kinematic_rms"]


ATX = ESBC_ATX
#: Epoch-axis errors within 3 sigma after convergence: the project's ~99 % (issue 20 asked 95 %). The reported
#: sigma's floor (PppOptions.floor_enu_m, for the header coordinate's own cm-level uncertainty and what is not
#: modelled) was set from this day, the only one with observations: the test guards that calibration, it is
#: not an independent check of it. Measured 99.0 % with ANTEX, 99.99 % without.
COVERAGE_GOAL = 0.985


def _enu_errors(res):
    lat, lon, _ = ecef_to_geodetic(REF_ITRF_ECEF_M)
    ok = np.isfinite(res.pos_ecef_m).all(axis=1)
    t_s = (res.time_gps - res.time_gps[0]).astype("timedelta64[s]").astype(float)
    return (res.pos_ecef_m - REF_ITRF_ECEF_M) @ C_e_n(lat, lon), res.sigma_enu_m, t_s, ok


@needs_data
def test_antex_receiver_offset_if():
    atx = read_antex(ATX)
    rx = atx.receiver("ASH701945E_M    SCIS")
    # The file's G01 / G02 up offsets, 89.04 and 118.96 mm; Galileo E01 falls back to G01 (IGS convention).
    assert rx.pco_m["G01"][2] == pytest.approx(0.08904) and rx.pco_m["G02"][2] == pytest.approx(0.11896)
    assert rx.pco_pcv("E01", receiver=True)[0] is rx.pco_m["G01"]
    sat = atx.satellite("G01", np.datetime64("2020-06-25"))
    assert sat.pco_m["G01"][2] == pytest.approx(1.5018)
    assert atx.satellite("E13", np.datetime64("2020-06-25")) is None  # no block (PROVENANCE.md)
    assert atx.receiver("TRM59800.00     NONE") is None  # no calibration: check_antex warns (tests/gnss/test_ar.py)
    assert atx.receiver("ASH701945E_M SCIS") is rx  # spacing does not matter, antenna and radome do


@needs_data
def test_antex_receiver_correction_sign_and_fallback():
    """The receiver's ionosphere-free correction against the ANTEX rows combined by hand.

    ANTEX convention (as RTKLIB's ``antmodel``): the range to the reference point is the measured one plus
    ``e . PCO - PCV``, so the correction subtracted from the observations is ``-e . PCO + PCV``. On ESBC00DNK
    its variations move the static height by 2.8 / 4.3 / 6.1 cm at 10 / 15 / 20 deg mask (docs/ppp.md), so
    a sign or fallback error would be centimetres. Satellites due north at 90, 45 and 10 deg elevation.
    """
    from types import SimpleNamespace

    from leosop.gnss.antex import antenna_corrections_if
    from leosop.gnss.ppp_obs import F_L1_HZ, F_L2_HZ, F_L5_HZ

    atx = read_antex(ATX)
    lat, lon, _ = ecef_to_geodetic(REF_ITRF_ECEF_M)
    C_en = C_e_n(lat, lon)
    el = np.radians([90.0, 45.0, 10.0])
    los_enu = np.stack([0 * el, np.cos(el), np.sin(el)], axis=-1)
    sv = ["G01", "E01"]
    RS = np.repeat((REF_ITRF_ECEF_M + 2.0e7 * los_enu @ C_en.T)[:, None, :], len(sv), axis=1)
    obs = SimpleNamespace(sv=sv, time_gps=np.array(["2020-06-25T12:00"], "datetime64[ns]"),
                          antenna_type="ASH701945E_M    SCIS")
    _, d_rx, missing, calibrated = antenna_corrections_if(
        atx, obs, RS, REF_ITRF_ECEF_M, np.tile([1.5e11, 0.0, 0.0], (len(el), 1)), C_en,
        np.repeat(el[:, None], len(sv), axis=1), {"G": (F_L1_HZ, F_L2_HZ), "E": (F_L1_HZ, F_L5_HZ)})
    assert calibrated and not missing
    # The file's G01 / G02 rows [mm]: north and up offsets, NOAZI at zenith 0, 45, 80 deg.
    pco_n = np.array([0.50, -0.60]) * 1e-3
    pco_u = np.array([89.04, 118.96]) * 1e-3
    pcv = np.array([[0.00, -9.90, 3.69], [0.00, -6.23, 2.56]]) * 1e-3
    for j, f2 in enumerate((F_L2_HZ, F_L5_HZ)):  # Galileo E1 / E5a take G01 / G02 (IGS convention)
        g = np.array([F_L1_HZ**2, -f2**2]) / (F_L1_HZ**2 - f2**2)
        expected = -(np.sin(el) * (g @ pco_u) + np.cos(el) * (g @ pco_n)) + g @ pcv
        np.testing.assert_allclose(d_rx[:, j], expected, atol=1e-6)  # 1 um: the angle error of a 1 m PCO shift
    assert d_rx[0, 0] == pytest.approx(-0.0428, abs=1e-4)  # the 4.3 cm IF up offset quoted in the docs


def test_antex_bad_file(tmp_path):
    p = tmp_path / "bad.atx"
    p.write_text("not antex\n")
    with pytest.raises(InputError, match=r"bad\.atx: line 1: not an ANTEX file"):
        read_antex(p)


@needs_data
def test_sigmas_cover_the_errors_on_real_data(day):
    """3-sigma coverage of the real day's errors against the station's ITRF2014 coordinate (24 h, ~10 s).

    Kinematic: after 2 h (taken as converged, as in the issue), per epoch and
    ENU axis; measured 99.0 % with ANTEX (3-D RMS 4.3 cm), 99.99 % without (8.2 cm; a larger floor
    for the unmodelled antenna offsets). White noise alone gave 51 %. Static: the error within 3 sigma at
    1, 3, 6 and 24 h (measured at most 1.4 sigma with ANTEX; white noise alone gave 13 to 40 sigma at 1-6 h).
    """
    obs, orb, clk = day
    atx = read_antex(ATX)
    for antex, rms_max in ((atx, 0.05), (None, 0.09)):
        e, s, t_s, ok = _enu_errors(run_ppp(obs, orb, clk, PppOptions(static=False), antex=antex))
        sel = ok & (t_s >= 7200.0)
        assert np.mean(np.abs(e[sel]) <= 3 * s[sel]) >= COVERAGE_GOAL
        # Not by inflating alone: the 1-sigma band holds about two thirds of them (measured 66 % / 62 %).
        assert np.mean(np.abs(e[sel]) <= s[sel]) < 0.8
        assert np.sqrt(np.mean(np.sum(e[sel] ** 2, axis=1))) < rms_max  # 4.4 / 8.2 cm measured
    e, s, t_s, ok = _enu_errors(run_ppp(obs, orb, clk, PppOptions(static=True), antex=atx))
    for hours in (1, 3, 6, 24):
        k = np.flatnonzero(ok & (t_s < 3600.0 * hours))[-1]
        assert np.all(np.abs(e[k]) <= 3 * s[k]), (hours, e[k], s[k])
    assert np.linalg.norm(e[k]) < 0.02  # final 1.5 cm


@needs_data
def test_galileo_only_static_through_the_sparse_hours(day):
    """Galileo alone, static, 24 h: 8.0-11.5 h have fewer than 5 usable satellites (epochs skipped, ~2 s).

    E09 rises in that span (its arc starts at 10.89 h, an epoch the filter skips) while its ambiguity
    state still held the value of its previous arc (set at 1.9 h): before the fix the first epoch back
    carried a 4.4 m phase misclosure and the solution walked 66 cm away under a 0.7 cm sigma (92 sigma).
    Now every epoch after 2 h is within 3 sigma per ENU axis (measured at most 1.0 sigma) and the final
    error is 1.0 cm (3 cm allowed: the floor of the reported sigma plus the unexplained -1.4 cm up bias).
    """
    obs, orb, clk = day
    # The 10 deg mask the case was found with: at 7 deg (the default since issue 22) E09 does not rise in a
    # skipped epoch, and the case is not in the data.
    opt = PppOptions(static=True, systems="E", mask_deg=10.0)
    atx = read_antex(ATX)
    d = prepare(obs, orb, clk, opt, atx)
    j, skipped = obs.sv.index("E09"), d["ok"].sum(axis=1) < 5
    assert np.any(d["new_arc"][:, j] & skipped)  # the case this test is about is in the data
    e, s, t_s, ok = _enu_errors(run_ppp(obs, orb, clk, opt, antex=atx))
    assert not np.any(ok[(t_s > 8.5 * 3600) & (t_s < 11.5 * 3600)])  # the sparse span is skipped
    sel = ok & (t_s >= 7200.0)
    ratio = np.abs(e[sel]) / s[sel]
    assert np.all(ratio <= 3.0), ratio.max(axis=0)
    assert np.linalg.norm(e[ok][-1]) < 0.03


def _ray_delay(elev_rad, az_rad, k_ne, scale_height_m, n=200_001):
    """Straight-ray integral of the refractivity ``exp(-h / H) (1 + k . d)`` over a spherical Earth [m per unit].

    ``d`` (north, east) is the ground distance along the great circle under the ray, ``h`` the height.
    """
    r_m = 6_371e3
    s_max = np.sqrt((r_m + 20 * scale_height_m) ** 2 - (r_m * np.cos(elev_rad)) ** 2) - r_m * np.sin(elev_rad)
    s = s_max * np.linspace(0.0, 1.0, n) ** 3  # dense near the ground, where the refractivity is
    h = np.sqrt(r_m**2 + s**2 + 2 * r_m * s * np.sin(elev_rad)) - r_m
    d = r_m * np.arctan2(s * np.cos(elev_rad), r_m + s * np.sin(elev_rad))
    n_rel = np.exp(-h / scale_height_m) * (1 + d * (k_ne[0] * np.cos(az_rad) + k_ne[1] * np.sin(az_rad)))
    return np.trapezoid(n_rel, s)


def test_gradient_partials_against_a_ray_traced_slant_delay():
    """[Chen 1997]'s gradient partials against a finite difference of a numerically integrated slant delay.

    An exponential atmosphere (scale height H) whose refractivity varies linearly across the horizon, ``N0
    exp(-h/H) (1 + k . x)``, has the gradient ``G = int h dN/dx dh = N0 k H^2``; so ``d slant / d k`` over
    ``N0 H^2`` is the partial on ``G``. With H = 8 km (the total delay's, for which C = 0.0032 was fitted)
    the straight ray over a spherical Earth gives it within 1.0 % from 5 to 60 deg (measured: 0.16-1.0 %;
    bending, not modelled here, matters below 5 deg); the flat-Earth ``1 / (sin e tan e)`` is 29 % off at 10
    deg, so a missing or wrong curvature term fails. The azimuth is clockwise from north (east at 90 deg).
    """
    from leosop.gnss.models import gradient_mapping

    h_m, k = 8_000.0, 1e-7  # k: 1e-7 per metre, 0.1 % over 10 km; the delay is linear in k
    for elev_deg in (60.0, 30.0, 15.0, 10.0, 5.0):
        el, az = np.radians(elev_deg), np.radians(30.0)
        fd = np.array([_ray_delay(el, az, dk, h_m) - _ray_delay(el, az, -np.array(dk), h_m)
                       for dk in ((k, 0.0), (0.0, k))]) / (2 * k * h_m**2)
        m_g = gradient_mapping(el, az)
        assert m_g == pytest.approx(fd, rel=0.011), elev_deg
    assert gradient_mapping(np.pi / 2, 0.0) == pytest.approx([0.0, 0.0], abs=1e-12)  # no gradient at the zenith
    east = gradient_mapping(np.radians(20.0), np.pi / 2)
    assert east[1] > 6.0 and abs(east[0]) < 1e-12  # a satellite due east sees the east gradient only
