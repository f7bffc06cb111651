"""The figures say what a newcomer needs: checked on the drawn artists, against numbers built independently.

Each test draws a figure from synthetic inputs whose answer is known (a track
ending at a chosen east/north offset, labels whose ends are far apart, a sigma
of a chosen size) and reads it back from matplotlib's artists, so a figure
that hides a line, drops a panel or misplaces a label fails.
"""

from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("matplotlib")
xr = pytest.importorskip("xarray")

from leosop.frames import enu_to_ecef, geodetic_to_ecef  # noqa: E402
from leosop.plots import maps, montecarlo, ppp, simulation, sky, spectra  # noqa: E402
from leosop.plots.core import pyplot  # noqa: E402


@pytest.fixture
def drawn(monkeypatch):
    """Figures the plotting modules would save, kept open for inspection (drawn, so extents are known)."""
    figures = []

    def keep(fig, path, **_):
        fig.canvas.draw()
        figures.append(fig)

    for module in (maps, montecarlo, ppp, simulation, sky, spectra):
        monkeypatch.setattr(module, "save_png", keep)
    yield figures
    for fig in figures:
        pyplot().close(fig)


def _spectrogram_with_tracks(ends_khz, t_end_s=None):
    t = np.linspace(0.0, 60.0, 31)
    f = np.linspace(-500e3, 500e3, 101)
    t_end_s = np.full(len(ends_khz), 60.0) if t_end_s is None else np.asarray(t_end_s)
    tracks = [(np.linspace(0.0, te, 10), np.linspace(end + 40.0, end, 10) * 1e3, f"{70000 + k}")
              for k, (end, te) in enumerate(zip(ends_khz, t_end_s))]
    return t, f, np.ones((f.size, t.size)), tracks


def test_spectrogram_labels_are_not_struck_by_leader_lines(drawn, tmp_path):
    # Ten ends within 120 kHz and some ending early: the crowd the bundled recording gives.
    ends = np.array([-10.0, -45.0, -50.0, -60.0, -95.0, -110.0, -120.0, -150.0, -170.0, -230.0])
    t, f, power, tracks = _spectrogram_with_tracks(ends, t_end_s=[58, 58, 48, 58, 58, 58, 58, 58, 58, 58])
    spectra.plot_spectrogram(tmp_path / "s.png", t, f, power, labelled_tracks=tracks)
    fig, = drawn
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    notes = [a for a in ax.texts if a.get_text() in {lab for _, _, lab in tracks}]
    assert len(notes) == len(tracks)
    boxes = [a.get_bbox_patch().get_window_extent(renderer) for a in notes]  # the label, not its leader
    for a in notes:
        path = a.arrow_patch.get_path().transformed(a.arrow_patch.get_transform())
        p0, p1 = path.vertices[0], path.vertices[-1]
        points = p0 + np.linspace(0.0, 1.0, 400)[:, None] * (p1 - p0)
        for note, box in zip(notes, boxes):
            # One pixel of slack: the own leader ends on its label's edge.
            inside = ((points[:, 0] > box.x0 + 1) & (points[:, 0] < box.x1 - 1)
                      & (points[:, 1] > box.y0 + 1) & (points[:, 1] < box.y1 - 1))
            assert not inside.any(), f"leader of {a.get_text()} crosses label {note.get_text()}"
    # Labels keep the ends' order and do not overlap one another.
    y = {a.get_text(): box.y0 for a, box in zip(notes, boxes)}
    ranked = [tracks[k][2] for k in np.argsort(ends)]
    assert np.all(np.diff([y[lab] for lab in ranked]) > 0)
    heights = sorted(boxes, key=lambda b: b.y0)
    assert all(lo.y1 <= hi.y0 + 0.5 for lo, hi in zip(heights, heights[1:]))


def test_spectrogram_labels_sit_at_their_ends_when_there_is_room(drawn, tmp_path):
    # Ends 200 kHz apart (the gap is 4.5 % of the 1000 kHz axis, 45 kHz): no label needs to move.
    ends = np.array([-300.0, -100.0, 100.0, 300.0])
    t, f, power, tracks = _spectrogram_with_tracks(ends)
    spectra.plot_spectrogram(tmp_path / "s.png", t, f, power, labelled_tracks=tracks)
    fig, = drawn
    label_y = {a.get_text(): a.xyann[1] for a in fig.axes[0].texts}
    np.testing.assert_allclose([label_y[lab] for _, _, lab in tracks], ends, atol=1e-9)


def _sky(n_sats, seed=0):
    """``n_sats`` passes over 10 min: az/elev rad, seconds, ids (highest elevation known: the sorted order)."""
    rng = np.random.default_rng(seed)
    elev0_deg = np.sort(rng.uniform(41.0, 89.0, n_sats))[::-1]  # satellite k is the k-th highest
    az0 = rng.uniform(0.0, 2 * np.pi, n_sats)
    t = np.arange(0.0, 601.0, 60.0)
    az = az0[:, None] + 1e-4 * t
    elev = np.radians(elev0_deg[:, None] - 0.01 * t)
    ids = np.repeat([f"{44000 + k}" for k in range(n_sats)], t.size)
    return az.ravel(), elev.ravel(), np.tile(t, n_sats), ids


def test_skyplot_of_a_crowded_sky_labels_only_the_highest_and_names_its_rings(drawn, tmp_path):
    az, elev, t, ids = _sky(61)
    sky.plot_skyplot(tmp_path / "sky.png", az, elev, t, ids, np.datetime64("2026-04-08T00:00:00"), mask_deg=40)
    fig, = drawn
    ax = fig.axes[0]
    labels = sorted(a.get_text() for a in ax.texts if a.get_text().isdigit())
    assert labels == [f"{44000 + k}" for k in range(sky.MAX_LABELS)]  # the 12 highest, no other
    coloured = [line for line in ax.lines if line.get_color() != "0.55" and line.get_marker() in ("None", "")]
    assert len(coloured) == sky.MAX_LABELS
    rings = [tick.get_text() for tick in ax.get_yticklabels()]
    assert rings == ["60", "30", "40"]
    assert any(a.get_text() == "elevation [deg]" for a in ax.texts)
    assert "61 satellites" in ax.get_title() and "12 highest labelled" in ax.get_title()


def _flight():
    """A 300 s straight flight 30 km east and 40 km north at 1000 m from Xi'an, INS 300 m and fused 2 m east of
    it (in the start's east/north plane, the figure's)."""
    lat0, lon0 = np.radians(34.342), np.radians(108.940)
    frac = np.linspace(0.0, 1.0, 301)
    enu = np.stack([30e3 * frac, 40e3 * frac, np.zeros_like(frac)], axis=1)
    start = geodetic_to_ecef(lat0, lon0, 1000.0)
    truth = start + enu_to_ecef(enu, lat0, lon0)
    run = SimpleNamespace(name="straight")
    return SimpleNamespace(
        truth_pos_ecef_m=truth, ins_pos_ecef_m=truth + enu_to_ecef([300.0, 0.0, 0.0], lat0, lon0),
        fused=SimpleNamespace(pos_ecef_m=truth + enu_to_ecef([2.0, 0.0, 0.0], lat0, lon0)),
        fused_label="Starlink/INS", t_s=300 * frac,
        times_utc=np.datetime64("2025-01-01T00:00:00") + (300e9 * frac).astype("timedelta64[ns]"),
        scenario=run, coupling="loose", level="measurement", seed=0)


def test_trajectory_has_equal_scales_start_end_and_both_tracks_visible(drawn, tmp_path):
    simulation.trajectory_figure(_flight(), tmp_path / "trajectory.png")
    fig, = drawn
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0
    lines = {line.get_label(): line for line in ax.lines}
    # The flat-earth ENU end of the track is (30, 40) km to the metre over 50 km (curvature: < 0.2 km up).
    np.testing.assert_allclose(lines["start"].get_xydata()[0], [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(lines["end"].get_xydata()[0], [30.0, 40.0], atol=1e-3)
    assert ax.get_xlabel() == "east of the start [km]"
    truth, fused = lines["truth"], lines["Starlink/INS"]
    # The fused track is drawn after (on top of) the truth, thinner and darker, so both show.
    assert ax.lines.index(fused) > ax.lines.index(truth)
    assert fused.get_linewidth() < truth.get_linewidth() / 2
    # The inset shows the end in metres: the fused track 2 m east of the truth, half-width 3 x 2 m.
    inset, = ax.child_axes
    np.testing.assert_allclose(inset.get_xlim(), (-6.0, 6.0))
    np.testing.assert_allclose(inset.lines[2].get_xdata()[-1], 2.0, atol=1e-6)


def _study():
    period = np.array([1.0, 10.0, 30.0])
    seeds = np.arange(3)
    base = np.array([4.5, 19.5, 54.7])[:, None, None] + np.array([0.0, 0.1])[None, :, None] + 0 * seeds
    ds = xr.Dataset(
        {"fused_pos_err_mean_m": (("correction_period_s", "coupling", "seed"), base),
         "fused_vel_err_mean_mps": (("correction_period_s", "coupling", "seed"), base / 100)},
        coords={"correction_period_s": ("correction_period_s", period,
                                        {"units": "s", "long_name": "time between EKF corrections of the INS"}),
                "coupling": ("coupling", np.array(["loose", "tight"]), {"long_name": "INS/LEO coupling of the EKF"}),
                "seed": ("seed", seeds, {"long_name": "seed index", "units": "1"})})
    return ds


def test_montecarlo_lines_that_coincide_stay_apart_with_human_labels(drawn, tmp_path):
    paths = montecarlo.plot_study(_study(), tmp_path, "small")
    assert [p.name for p in paths] == ["error_vs_correction_period_s.png", "error_vs_coupling.png"]
    fig = drawn[0]
    top, bottom = fig.axes[0], fig.axes[1]
    assert bottom.get_xlabel() == "time between EKF corrections of the INS [s]"
    legend = top.get_legend()
    assert legend.get_title().get_text() == "INS/LEO coupling of the EKF"
    assert [t.get_text() for t in legend.get_texts()] == ["loose", "tight"]
    loose, tight = [c.lines[0] for c in top.containers if c.get_label() in ("loose", "tight")]
    # Errors 0.1 m apart on a 4-55 m axis would print as one line: different marker, dash and x positions.
    assert loose.get_marker() != tight.get_marker() and loose.get_linestyle() != tight.get_linestyle()
    assert np.all(np.abs(loose.get_xdata() - tight.get_xdata()) > 0.2)
    assert drawn[1].axes[1].get_xlabel() == "INS/LEO coupling of the EKF"


def test_ppp_figure_in_centimetres_with_a_thin_band_shown_and_integer_satellite_ticks(drawn, tmp_path):
    n = 2880
    time_gps = np.datetime64("2020-06-25T00:00:00") + np.arange(n) * np.timedelta64(30, "s")
    rng = np.random.default_rng(1)
    d_enu_m = 0.02 * np.sin(np.linspace(0, 20, n))[:, None] + 0.003 * rng.standard_normal((n, 3))
    sigma_enu_m = np.full((n, 3), 0.0008)  # 0.8 mm: a band far thinner than the 2 cm wander
    n_sats = 12 + (np.arange(n) // 500) % 2
    ppp.ppp_figure(time_gps, d_enu_m, sigma_enu_m, n_sats, tmp_path / "ppp.png", title="ESBC00DNK kinematic")
    fig, = drawn
    east, sats = fig.axes[0], fig.axes[3]
    assert east.get_ylabel() == "east [cm]"
    lo, hi = east.get_ylim()
    assert 2.0 < hi < 5.0 and lo == -hi  # centimetres: the 2 cm wander plus noise, 99th percentile x 1.2
    notes = [t.get_text() for t in east.texts]
    assert "median 3 sigma 0.24 cm" in notes  # 3 x 0.8 mm
    assert all(float(v).is_integer() for v in sats.get_yticks())
    assert "2020-06-25 00:00:00 GPS time" in sats.get_xlabel()
    np.testing.assert_allclose(sats.lines[0].get_xdata()[-1], (n - 1) * 30 / 3600)


@pytest.mark.parametrize("n_epochs, shown", [(7, 7), (20, maps.MAX_PANELS)])
def test_small_multiples_show_every_epoch_or_say_which(drawn, tmp_path, n_epochs, shown):
    lat, lon = np.arange(-90.0, 91.0, 30.0), np.arange(-180.0, 180.0, 30.0)
    values = np.ones((n_epochs, lat.size, lon.size))
    labels = [f"epoch {k}" for k in range(n_epochs)]
    maps.plot_small_multiples(tmp_path / "m.png", lat, lon, values, labels, cbar_label="n", title="map")
    fig, = drawn
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible() and ax.get_title()]
    assert len(titles) == shown and titles[0] == "epoch 0" and titles[-1] == f"epoch {n_epochs - 1}"
    said = f"{shown} of the {n_epochs} epochs" in fig._suptitle.get_text()
    assert said == (shown < n_epochs)


def test_world_map_cells_cover_every_longitude(drawn, tmp_path):
    # A 5 deg grid of cell centres -180..175: drawn centred, the cells must still reach +180 (the -180 column
    # repeated), or a blank strip runs down the right edge.
    lat, lon = np.arange(-90.0, 91.0, 5.0), np.arange(-180.0, 180.0, 5.0)
    maps.plot_fix_fraction(tmp_path / "f.png", lat, lon, np.full((lat.size, lon.size), 0.5))
    fig, = drawn
    edges_lon = fig.axes[0].collections[0].get_coordinates()[..., 0]
    assert edges_lon.min() <= -180.0 and edges_lon.max() >= 180.0


def test_a_day_at_one_second_draws_through_its_envelope_with_every_extreme_and_gap(drawn, tmp_path):
    from leosop.plots.core import ENVELOPE_BINS, envelope

    n = 86_400
    rng = np.random.default_rng(3)
    times = np.datetime64("2026-04-08T00:00:00", "ns") + np.arange(n) * np.timedelta64(1, "s")
    n_vis = rng.integers(5, 30, n)
    gdop = 3.0 + rng.random(n)
    gdop[n_vis < 7] = np.nan  # the gaps a Doppler fix leaves
    gdop[40_000:50_000] = np.nan  # and a long one
    gdop[12_345] = 250.0  # a one-second spike must still be drawn
    sky.plot_visibility(tmp_path / "v.png", times, n_vis, gdop, gdop / 2, mask_deg=40.0)
    lines = drawn[0].axes[1].get_lines()
    y = np.asarray(lines[0].get_ydata(), float)
    assert y.size == 2 * ENVELOPE_BINS  # bounded by the figure, not the span
    assert np.nanmax(y) == 250.0 and np.nanmin(y) == np.nanmin(gdop)
    # The long gap stays a gap: the envelope's buckets wholly inside it are NaN.
    x, e = envelope(np.arange(n), gdop)
    inside = (x > 40_000 + n / ENVELOPE_BINS) & (x < 50_000 - n / ENVELOPE_BINS)
    assert inside.any() and np.isnan(e[inside]).all()
    # Every sample lies within its bucket's [min, max] (the pixels the full series would cover).
    lo, hi = e[0::2], e[1::2]
    bucket = np.searchsorted(x[0::2], np.arange(n), side="right") - 1
    ok = np.isnan(gdop) | ((gdop >= lo[bucket]) & (gdop <= hi[bucket]))
    assert ok.all()
    # A short span is drawn as it is (the count as steps).
    sky.plot_visibility(tmp_path / "w.png", times[:600], n_vis[:600], gdop[:600], gdop[:600] / 2, mask_deg=40.0)
    assert drawn[1].axes[1].get_lines()[0].get_ydata().size == 600
