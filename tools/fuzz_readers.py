"""Coverage-guided fuzzing of every file reader (atheris / libFuzzer).

Each target writes the fuzzer's bytes to a file and calls one reader. The
contract (DESIGN 4.1): a reader either returns or raises
:class:`~leosop.errors.InputError` with a message (the CLI prints it as one
line and exits 2). Any other exception is a finding: the input is saved under
``tests/hardening/fuzz_corpus/<target>/`` (one per distinct exception type and place
not already in the corpus) and fuzzing goes on; ``tests/hardening/test_fuzz_corpus.py``
replays them.

Usage::

    nice -n 10 python tools/fuzz_readers.py TARGET [-runs=100000] [libFuzzer options]
    python tools/fuzz_readers.py --list

The seed corpus is made at start from the shared real data (heads of the
files) and small examples written here. libFuzzer reports the inputs run ("Done N
runs"); each new finding is printed as a ``FINDING`` line with its traceback,
and every 10,000 inputs a ``TALLY`` line counts the inputs run, those that
failed the contract (known findings included) and the distinct findings.
"""

import hashlib
import importlib
import os
import resource
import shutil
import sys
import tempfile
import traceback
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO / "tests" / "hardening" / "fuzz_corpus"
DATA = Path(os.environ.get("LEOSOP_SHARED_DATA", REPO.parent / "shared" / "data"))
_SEED_BYTES = 3000  # heads of real files; libFuzzer's default -max_len is 4096
_TALLY_EVERY = 10_000  # inputs between two TALLY lines (inputs run, failing, distinct findings)
# Address-space cap: an input that makes a reader allocate more fails with MemoryError (a finding, saved as
# oom-*, not replayed by the tests) instead of ending the run at libFuzzer's RSS limit.
_MEMORY_LIMIT_BYTES = 3 << 30

_SIGMF_META = b"""{"global": {"core:datatype": "cf32_le", "core:sample_rate": 1000.0, "core:version": "1.2.0",
 "leosop:n_tones": 9, "leosop:tone_spacing_hz": 43945.3125},
 "captures": [{"core:sample_start": 0, "core:frequency": 11325000000.0, "core:datetime": "2025-01-01T00:00:00Z"},
              {"core:sample_start": 64, "core:frequency": 11325000000.0, "core:datetime": "2025-01-01T00:00:01Z"}],
 "annotations": [{"core:sample_start": 0, "core:sample_count": 64, "leosop:sat_id": "1", "leosop:doppler_hz": 5.0}]}
"""
_MEASUREMENTS = (b"time_utc,sat_id,doppler_hz,sigma_hz,carrier_hz\n"
                 b"2025-01-01T00:00:00Z,44713,-1234.5,1.0,11325000000\n"
                 b"2025-01-01T00:00:01Z,44714,2345.25,,\n")
_MEASUREMENTS_SV = (b"t_s,sat_id,doppler_hz,x_sv_m,y_sv_m,z_sv_m,vx_sv_mps,vy_sv_mps,vz_sv_mps\n"
                    b"0,1,-1000,7000000,0,0,0,7500,0\n1,2,500,0,7000000,0,-7500,0,0\n")
_SCENARIO = (b'{"name": "fuzz", "start_utc": "2025-01-01T00:00:00Z", "speed_mps": 100, "mask_deg": 20,'
             b' "duration_s": 60, "waypoints": [[34.3, 108.9, 400], [34.4, 109.0, 500]],'
             b' "imu": {}, "leo": {}, "init_error": {}}')
_OMM_JSON = (b'[{"OBJECT_NAME": "STARLINK-1007", "NORAD_CAT_ID": 44713, "EPOCH": "2025-01-01T00:00:00.000",'
             b' "MEAN_MOTION": 15.06, "ECCENTRICITY": 0.0001, "INCLINATION": 53.05, "RA_OF_ASC_NODE": 10.0,'
             b' "ARG_OF_PERICENTER": 90.0, "MEAN_ANOMALY": 270.0, "BSTAR": 0.0001, "MEAN_MOTION_DOT": 1e-5,'
             b' "MEAN_MOTION_DDOT": 0}]')
_OMM_CSV = (b"OBJECT_NAME,NORAD_CAT_ID,EPOCH,MEAN_MOTION,ECCENTRICITY,INCLINATION,RA_OF_ASC_NODE,"
            b"ARG_OF_PERICENTER,MEAN_ANOMALY,BSTAR,MEAN_MOTION_DOT,MEAN_MOTION_DDOT\n"
            b"STARLINK-1007,44713,2025-01-01T00:00:00.000,15.06,0.0001,53.05,10,90,270,0.0001,1e-5,0\n")
_SF_CSV = b"".join(b"%.3f,0.01,-0.02,1.0,0.001,0.002,-0.001,0,0,0,0\n" % (1.6e9 + 0.01 * k) for k in range(20))


def _head(*parts):
    """First bytes of a shared data file, or None when the data are not here."""
    path = DATA.joinpath(*parts)
    return path.read_bytes()[:_SEED_BYTES] if path.is_file() else None


def _first_records(parts, prefix, n_records):
    """A RINEX-style file up to its ``n_records``-th record (a record starts with a ``prefix`` line).

    The header is kept whole, gzip and Hatanaka compression are undone; None
    when the data are not here.
    """
    path = DATA.joinpath(*parts)
    if not path.is_file():
        return None
    from leosop.gnss.rinex import read_text

    lines = read_text(path)
    starts = [i for i, line in enumerate(lines) if line.startswith(prefix)]
    return "\n".join(lines[:starts[n_records]]).encode() + b"\n"


def _write(tmp, name, data):
    path = Path(tmp) / name
    path.write_bytes(data)
    return path


def _split(data, n):
    """``n`` parts of ``data`` cut at NUL bytes (missing parts are empty)."""
    parts = data.split(b"\0", n - 1)
    return parts + [b""] * (n - len(parts))


def _tle(tmp, data):
    from leosop.orbits import read_tle

    read_tle(_write(tmp, "set.tle", data), skip_bad=bool(data[:1] == b"S"))


def _omm_json(tmp, data):
    from leosop.orbits import read_omm

    read_omm(_write(tmp, "set.json", data))


def _omm_csv(tmp, data):
    from leosop.orbits import read_omm

    read_omm(_write(tmp, "set.csv", data))


def _sigmf(tmp, data):
    from leosop.signal.iq import open_sigmf

    meta, samples = _split(data, 2)
    _write(tmp, "rec.sigmf-data", samples or bytes(1024))
    rec = open_sigmf(_write(tmp, "rec.sigmf-meta", meta))
    for _ in rec.blocks(min(64, rec.n_samples)):
        pass


def _raw_iq(tmp, data):
    from leosop.signal.iq import open_raw

    head, samples = data[:2], data[2:]
    dtype = ("cf32", "ci16", "cf32_le", "bad")[head[0] % 4] if head else "cf32"
    offset = head[1] % 17 if len(head) > 1 else 0
    rec = open_raw(_write(tmp, "rec.iq", samples), dtype=dtype, sample_rate_hz=1000.0, offset_bytes=offset)
    for _ in rec.blocks(max(1, min(16, rec.n_samples))):
        pass


def _measurements(tmp, data):
    from leosop.positioning.measurements import read_measurements

    read_measurements(_write(tmp, "meas.csv", data))


def _scenario(tmp, data):
    from leosop.apps.scenarios import load_scenario

    load_scenario(_write(tmp, "scenario.json", data))


def _psins(tmp, data):
    from leosop.ins.imu_io import read_psins

    read_psins(_write(tmp, "log.imu", data))


def _rtklib_sf(tmp, data):
    from leosop.ins.imu_io import read_rtklib_sf_csv

    read_rtklib_sf_csv(_write(tmp, "imu_sf.csv", data))


def _rtklib_raw(tmp, data):
    from leosop.ins.imu_io import read_rtklib_csv

    csv_bytes, tag = _split(data, 2)
    path = _write(tmp, "imu.csv", csv_bytes)
    _write(tmp, "imu.csv.tag", tag)
    read_rtklib_csv(path)


def _rinex_obs(tmp, data):
    from leosop.gnss.rinex import read_obs

    read_obs(_write(tmp, "obs.rnx", data))


def _sp3(tmp, data):
    from leosop.gnss.products import read_sp3

    read_sp3(_write(tmp, "orb.sp3", data))


def _clk(tmp, data):
    from leosop.gnss.products import read_clk

    read_clk(_write(tmp, "sat.clk", data))


def _seeds_tle():
    return [_head("tle", "starlink_3le_2022-12-02_TrevorBurgoyne.txt"), _head("sgp4-verification", "SGP4-VER.TLE")]


#: target name -> (reader call, seed inputs)
TARGETS = {
    "tle": (_tle, _seeds_tle),
    "omm_json": (_omm_json, lambda: [_OMM_JSON]),
    "omm_csv": (_omm_csv, lambda: [_OMM_CSV]),
    "sigmf": (_sigmf, lambda: [_SIGMF_META + b"\0" + bytes(range(256)) * 4]),
    "raw_iq": (_raw_iq, lambda: [b"\0\0" + bytes(256), b"\1\3" + bytes(range(256))]),
    "measurements": (_measurements, lambda: [_MEASUREMENTS, _MEASUREMENTS_SV]),
    "scenario": (_scenario, lambda: [_SCENARIO]),
    "psins": (_psins, lambda: [_head("gnss-ins", "psins_lasergyro", "lasergyro.imu")]),
    "rtklib_sf_csv": (_rtklib_sf, lambda: [_SF_CSV, _head("gnss-ins", "rtklibexplorer_walk_0827", "imu_1730_sf.csv")]),
    "rtklib_csv": (_rtklib_raw, lambda: [
        (_head("gnss-ins", "rtklibexplorer_walk_0827", "imu_1730.csv") or b"") + b"\0"
        + (_head("gnss-ins", "rtklibexplorer_walk_0827", "imu_1730.csv.tag") or b"")]),
    "rinex_obs": (_rinex_obs, lambda: [
        _first_records(("rinex", "esbc_2020-177", "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"), ">", 2)]),
    "sp3": (_sp3, lambda: [_first_records(("rinex", "igs_2010-182", "igs15904.sp3"), "*", 3)]),
    "clk": (_clk, lambda: [_first_records(("rinex", "igs_2010-182", "igs15904.clk"), "AS ", 70)]),
}


def check_one(target, data, tmp):
    """Run ``target`` on ``data``; None if it kept the contract, else the traceback text.

    Keeping the contract: returning, or raising InputError (the CLI prints
    its message as one line, exit 2).
    """
    from leosop.errors import InputError

    call = TARGETS[target][0]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            call(tmp, data)
    except InputError as exc:
        return None if str(exc).strip() else "InputError without a message"
    except Exception:
        return traceback.format_exc()
    return None


def _signature(tb):
    """Exception type and innermost leosop frame of a traceback: one finding each."""
    lines = tb.strip().splitlines()
    places = [ln.strip() for ln in lines if ln.strip().startswith("File ") and "leosop" in ln]
    return (places[-1] if places else "") + " | " + lines[-1].split(":")[0]


def main():
    if sys.argv[1:2] == ["--list"]:
        print("\n".join(TARGETS))
        return
    if len(sys.argv) < 2 or sys.argv[1] not in TARGETS:
        sys.exit(f"usage: {sys.argv[0]} TARGET [libFuzzer options]; targets: {', '.join(TARGETS)}")
    target, fuzzer_args = sys.argv[1], [sys.argv[0], *sys.argv[2:]]
    import atheris

    with atheris.instrument_imports(include=["leosop", "sigmf"]):
        for module in ("leosop.gnss.products", "leosop.gnss.rinex", "leosop.ins.imu_io", "leosop.orbits",
                       "leosop.positioning.measurements", "leosop.apps.scenarios", "leosop.signal.iq",
                       "sigmf.sigmffile"):
            importlib.import_module(module)
    out = CORPUS / target
    # One scratch directory per target, emptied at start (libFuzzer exits without Python's clean-up).
    tmp = Path("/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()) / f"leosop_fuzz_{target}"
    shutil.rmtree(tmp, ignore_errors=True)
    seed_dir = tmp / "seeds"
    seed_dir.mkdir(parents=True)
    for k, seed in enumerate(s for s in TARGETS[target][1]() if s):
        (seed_dir / f"seed{k}").write_bytes(seed)
    work = tmp / "work"
    work.mkdir()
    # Findings already in the corpus are not saved again.
    seen = {_signature(tb) for tb in (check_one(target, p.read_bytes(), work) for p in sorted(out.glob("*-*")))
            if tb is not None}

    tally = {"inputs": 0, "failures": 0}

    def one_input(data):
        tb = check_one(target, data, work)
        tally["inputs"] += 1
        tally["failures"] += tb is not None
        if tally["inputs"] % _TALLY_EVERY == 0:
            print(f"TALLY {target}: {tally['inputs']} inputs, {tally['failures']} failing "
                  f"({len(seen)} distinct)", file=sys.stderr, flush=True)
        if tb is not None:
            sig = _signature(tb)
            if sig not in seen:
                seen.add(sig)
                out.mkdir(parents=True, exist_ok=True)
                kind = "oom" if sig.endswith("MemoryError") else "crash"
                (out / f"{kind}-{hashlib.sha1(data).hexdigest()[:16]}").write_bytes(data)
                print(f"FINDING {target}: {sig}\n{tb}", file=sys.stderr, flush=True)

    (tmp / "corpus").mkdir()
    resource.setrlimit(resource.RLIMIT_AS, (_MEMORY_LIMIT_BYTES, resource.getrlimit(resource.RLIMIT_AS)[1]))
    atheris.Setup([*fuzzer_args, str(tmp / "corpus"), str(seed_dir)], one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
