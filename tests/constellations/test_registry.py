"""The constellation registry: a family added there is picked up by every stage without other edits."""

import dataclasses
import json

import numpy as np
import pytest

from leosop.cli import main
from leosop.constellations import (
    REGISTRY,
    CombModel,
    Family,
    carriers_hz,
    clock_scale,
    family,
)
from leosop.errors import InputError
from leosop.orbits import DEFAULT_TLE

#: A made-up S-band family with its own mask (20 deg), tone sigma model and, for
#: the signal-level case, a 5-tone comb 30 kHz apart.
NEWSAT = Family("newsat", ("NEWSAT",), 2.2e9, (2.2e9,), None, 50.0, 0.02, 20.0, "test family")
NEWSAT_COMB = dataclasses.replace(NEWSAT, comb=CombModel(n_tones=5, tone_spacing_hz=30e3))


@pytest.fixture
def newsat_tle(tmp_path):
    """Half the bundled Walker set (to parse it fast), every other satellite renamed NEWSAT-...: a mixed file."""
    lines = DEFAULT_TLE.read_text().splitlines()
    records = [lines[i:i + 3] for i in range(0, len(lines) - 2, 3)]
    kept = [[r[0].replace("STARLINK", "NEWSAT") if k % 4 else r[0], *r[1:]] for k, r in enumerate(records) if k % 4 < 2]
    path = tmp_path / "mixed.tle"
    path.write_text("".join(line + "\n" for record in kept for line in record))
    return path


def test_lookups_and_unknown_family():
    assert carriers_hz(["starlink", "", "iridium"]).tolist() == [11.325e9, 11.325e9, 1626.2708e6]
    assert clock_scale("orbcomm") == pytest.approx(137.5e6 / 11.325e9, rel=1e-15)
    with pytest.raises(InputError, match="leo.constellations: unknown constellation 'galileo'; expected one of"):
        family("galileo", "leo.constellations")


def _vis(capsys, *argv):
    # A 10 deg mask: the file's quarter of NEWSAT satellites puts 7 or more above it at the default start.
    assert main(["visibility", "--duration-s", "120", "--step-s", "30", "--mask-deg", "10", "--json", *argv]) == 0
    return json.loads(capsys.readouterr().out)


def test_new_family_flows_through_visibility(monkeypatch, capsys, newsat_tle):
    # Registered, the family is selectable and its carrier is the GDOP's (the Doppler
    # GDOP depends on the carrier): the same run with that carrier given is the reference.
    monkeypatch.setitem(REGISTRY, "newsat", NEWSAT)
    own = _vis(capsys, "--tle", str(newsat_tle), "--constellation", "newsat")
    given = _vis(capsys, "--tle", str(newsat_tle), "--constellation", "newsat", "--carrier-hz", "2.2e9")
    assert own["gdop"] == given["gdop"] and any(g is not None for g in own["gdop"])
    mixed = _vis(capsys, "--tle", str(newsat_tle), "--constellation", "starlink", "newsat")
    assert mixed["families"] == ["starlink", "newsat"]
    both = np.array([mixed["n_visible_by_family"][f] for f in ("starlink", "newsat")])
    np.testing.assert_array_equal(both[1], own["n_visible"])
    assert (both > 0).all()


def _short(tle, constellations, duration_s):
    from leosop.apps.scenarios import XIAN_BAOJI

    leo = dataclasses.replace(XIAN_BAOJI.leo, constellations=constellations)
    return dataclasses.replace(XIAN_BAOJI, duration_s=duration_s, tle=str(tle), leo=leo)


def test_new_family_flows_through_simulate(monkeypatch, newsat_tle):
    # Measurement level: NEWSAT is tracked above its registry mask (20 deg), Starlink
    # above the scenario's 40 deg, counted from elevations computed here.
    from leosop.frames import azimuth_elevation_range
    from leosop.orbits.propagate import state_ecef
    from leosop.apps.simulate import run_scenario
    from leosop.apps.simulate.sky import transmitters

    monkeypatch.setitem(REGISTRY, "newsat", NEWSAT)
    sc = _short(newsat_tle, ("starlink", "newsat"), 30.0)
    r = run_scenario(sc, level="measurement", seed=0)
    constellation, family_sat = transmitters(sc.leo.constellations, sc.tle, r.times_utc[[0, -1]])
    pos_sv, _, _ = state_ecef(constellation, r.times_utc)
    elev_deg = np.degrees(azimuth_elevation_range(pos_sv, r.truth_pos_ecef_m)[1])
    np.testing.assert_array_equal(r.n_visible_by_family[:, 0], (elev_deg[family_sat == 0] >= 40.0).sum(0))
    np.testing.assert_array_equal(r.n_visible_by_family[:, 1], (elev_deg[family_sat == 1] >= 20.0).sum(0))
    assert (r.n_visible_by_family[:, 1] > (elev_deg[family_sat == 1] >= 40.0).sum(0)).any()
    assert np.isfinite(r.fix_pos_ecef_m).all()


def test_new_comb_family_is_simulated_at_signal_level(monkeypatch, newsat_tle):
    # A family with a pilot comb goes through the signal chain (its own comb, generated
    # and estimated by fast); the fixes' error stays at the level of the measurement model's.
    from leosop.apps.simulate import run_scenario

    monkeypatch.setitem(REGISTRY, "newsat", NEWSAT_COMB)
    sc = _short(newsat_tle, ("newsat",), 4.0)
    signal = run_scenario(sc, level="signal", seed=0)
    model = run_scenario(sc, level="measurement", seed=0)
    err = [np.linalg.norm(x.fix_pos_ecef_m - x.truth_pos_ecef_m, axis=1) for x in (signal, model)]
    assert np.isfinite(err[0]).all() and not np.array_equal(err[0], err[1])
    # Same orbit errors and offsets (seeded apart from the noise): the two levels agree within a few times
    # the measurement level's error.
    assert np.median(err[0]) < 5.0 * np.median(err[1]) + 10.0
