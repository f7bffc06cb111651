"""IQ recordings: SigMF round trips (checked with the sigmf package's own reader), raw files, bad files."""

import json

import numpy as np
import pytest
from sigmf import sigmffile

from leosop.errors import InputError
from leosop.signal.iq import Capture, open_raw, open_sigmf
from leosop.signal.iq_write import write_sigmf

FS = 1e6


def _samples(n, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.standard_normal(n) + 1j * rng.standard_normal(n)) * 0.2


def _write(tmp_path, x, datatype="cf32_le", name="rec", chunk=1000, **kw):
    meta = tmp_path / f"{name}.sigmf-meta"
    chunks = (x[i:i + chunk] for i in range(0, x.size, chunk))
    write_sigmf(meta, chunks, sample_rate_hz=FS, center_hz=11.325e9, start_utc="2025-01-01T19:40:00Z",
                datatype=datatype, annotations=[(0, 100, {"leosop:sat_id": "70001", "leosop:doppler_hz": 1.5})],
                global_extra={"leosop:n_tones": 9}, **kw)
    return meta


def test_cf32_round_trip(tmp_path):
    x = _samples(5_000)
    meta = _write(tmp_path, x)
    rec = open_sigmf(meta)
    assert (rec.n_samples, rec.datatype, rec.sample_rate_hz, rec.center_hz) == (5_000, "cf32_le", FS, 11.325e9)
    assert rec.start_utc == np.datetime64("2025-01-01T19:40:00", "ns")
    # cf32 stores complex64: exact round trip of the complex64 values.
    np.testing.assert_array_equal(rec.read(0, 5_000), x.astype(np.complex64))
    np.testing.assert_array_equal(rec.read(1234, 10), x[1234:1244].astype(np.complex64))
    assert rec.annotations[0]["leosop:doppler_hz"] == 1.5
    # The sigmf package's own reader (checksum verified) sees the same samples, and the
    # leosop: keys are declared as an optional extension that its schema validates.
    theirs = sigmffile.fromfile(str(meta))
    np.testing.assert_array_equal(theirs.read_samples(), x.astype(np.complex64))
    theirs.validate()
    assert theirs.get_global_field("core:extensions") == [{"name": "leosop", "version": "1.0.0", "optional": True}]
    blocks = list(rec.blocks(2_000))
    assert [s for s, _ in blocks] == [0, 2_000]  # whole blocks only


def test_ci16_round_trip(tmp_path):
    x = _samples(3_000)
    meta = _write(tmp_path, x, datatype="ci16_le", full_scale=2.0)
    got = open_sigmf(meta).read(0, 3_000)
    # Read back in units of full scale (SigMF: ci16 / 32768); quantisation is half
    # an LSB, 0.5/32767, plus the 32767-vs-32768 scale (3e-5 relative) and float32 rounding.
    np.testing.assert_allclose(got.real, x.real / 2.0, atol=0.5 / 32767 + 3.1e-5 * 0.5 + 1e-6)
    np.testing.assert_allclose(got.imag, x.imag / 2.0, atol=0.5 / 32767 + 3.1e-5 * 0.5 + 1e-6)
    # The sigmf package scales ci16 by 1/32768 as we do.
    np.testing.assert_allclose(sigmffile.fromfile(str(meta)).read_samples(), got, rtol=1e-6)


@pytest.mark.parametrize("dtype", ["cf32", "ci16"])
def test_raw(tmp_path, dtype):
    x = _samples(2_000)
    path = tmp_path / f"rec.{dtype}"
    if dtype == "cf32":
        x.astype("<c8").tofile(path)
        expect = x.astype(np.complex64)
    else:
        q = np.round(np.stack([x.real, x.imag], axis=1) * 32768).astype("<i2")
        q.tofile(path)
        expect = (q[:, 0] + 1j * q[:, 1]) / 32768
    rec = open_raw(path, dtype=dtype, sample_rate_hz=FS, center_hz=11.325e9, start="2025-01-01T00:00:00Z")
    assert rec.n_samples == 2_000
    np.testing.assert_allclose(rec.read(0, 2_000), expect, rtol=1e-6)


@pytest.mark.parametrize("datatype", ["cf32_le", "ci16_le", "cu8"])
def test_read_into_a_given_buffer(tmp_path, datatype):
    """read(..., out=): the same samples as read() into the caller's buffer (cf32 read straight into it, the
    integer formats converted into it), the buffer returned; a wrong buffer and a file cut short refused."""
    from leosop.signal.fft import empty_aligned

    x = _samples(4_000)
    meta = _write(tmp_path, x, datatype=datatype)
    rec = open_sigmf(meta)
    out = empty_aligned(1_000)
    assert rec.read(1_500, 1_000, out=out) is out
    np.testing.assert_array_equal(out, rec.read(1_500, 1_000))
    with pytest.raises(ValueError, match="complex64 array of shape"):
        rec.read(0, 1_000, out=np.empty(999, np.complex64))
    if datatype == "cf32_le":
        data = rec.data_path.read_bytes()
        rec.data_path.write_bytes(data[:8 * 3_500])
        with pytest.raises(InputError, match="cut short"):
            rec.read(3_000, 1_000, out=out)


def test_bad_files(tmp_path):
    meta = _write(tmp_path, _samples(1_000))
    data = meta.with_suffix(".sigmf-data")
    doc = json.loads(meta.read_text())

    with open(data, "ab") as fh:  # truncated/extended by a partial sample
        fh.write(b"\0\0\0")
    with pytest.raises(InputError, match="whole number"):
        open_sigmf(meta)
    data.write_bytes(data.read_bytes()[:-3 - 8 * 100])  # 100 whole samples short
    with pytest.raises(InputError, match="sha512"):
        open_sigmf(meta)

    for key, value, match in [("core:datatype", "ri16_le", "datatype"), ("core:datatype", "ci32_le", "datatype"),
                              ("core:sample_rate", 0, "sample rate"), ("core:sample_rate", -5.0, "sample rate")]:
        bad = dict(doc, **{"global": dict(doc["global"], **{key: value})})
        meta.write_text(json.dumps(bad))
        with pytest.raises(InputError, match=match):
            open_sigmf(meta, verify=False)

    data.unlink()
    with pytest.raises(InputError, match="missing SigMF data"):
        open_sigmf(meta)
    with pytest.raises(InputError, match="sample rate"):
        open_raw(meta, dtype="cf32", sample_rate_hz=0)


def test_nan_and_range(tmp_path):
    x = _samples(1_000)
    x[500] = np.nan
    rec = open_sigmf(_write(tmp_path, x))
    with pytest.raises(InputError, match="sample 500 is NaN"):
        rec.read(0, 1_000)
    with pytest.raises(InputError, match="outside"):
        rec.read(900, 200)
    with pytest.raises(InputError, match="block of 2000"):
        next(rec.blocks(2_000))


def test_write_is_atomic(tmp_path):
    def failing():
        yield _samples(100)
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_sigmf(tmp_path / "x.sigmf-meta", failing(), sample_rate_hz=FS, center_hz=1e9,
                    start_utc="2025-01-01T00:00:00Z")
    assert list(tmp_path.iterdir()) == []


T0 = np.datetime64("2025-01-01T19:40:00", "ns")


def _write_captures(tmp_path, n_total=3_500):
    x = _samples(n_total)
    meta = tmp_path / "snap.sigmf-meta"
    # Snapshots of 1000 samples (1 ms) every second; the third starts 0.5 us after a whole second.
    caps = [(0, T0), (1_000, T0 + np.timedelta64(1, "s")), (2_000, T0 + np.timedelta64(2_000_000_500, "ns"))]
    write_sigmf(meta, (x[i:i + 700] for i in range(0, n_total, 700)), sample_rate_hz=FS, center_hz=11.325e9,
                captures=caps)
    return meta, x


def test_captures_round_trip(tmp_path):
    meta, x = _write_captures(tmp_path)
    rec = open_sigmf(meta)
    assert [(c.sample_start, c.n_samples) for c in rec.captures] == [(0, 1_000), (1_000, 1_000), (2_000, 1_500)]
    assert [c.start_utc for c in rec.captures] == [T0, T0 + np.timedelta64(1, "s"),
                                                   T0 + np.timedelta64(2_000_000_500, "ns")]  # ns kept
    assert rec.start_utc == T0 and rec.n_samples == 3_500 and rec.center_hz == 11.325e9
    np.testing.assert_array_equal(rec.read(1_995, 10), x[1_995:2_005].astype(np.complex64))
    # The sigmf package sees the same three segments and samples.
    other = sigmffile.fromfile(str(meta))
    assert [c["core:sample_start"] for c in other.get_captures()] == [0, 1_000, 2_000]
    np.testing.assert_array_equal(other.read_samples(), x.astype(np.complex64))
    # Single-capture and raw recordings: one capture of everything.
    single = open_sigmf(_write(tmp_path, x, name="one"))
    assert single.captures == [Capture(0, 3_500, T0)]
    x.astype("<c8").tofile(tmp_path / "r.cf32")
    assert open_raw(tmp_path / "r.cf32", dtype="cf32", sample_rate_hz=FS).captures == [Capture(0, 3_500, None)]


def test_write_captures_refused(tmp_path):
    with pytest.raises(InputError, match="begin at 0 and increase"):
        write_sigmf(tmp_path / "a.sigmf-meta", [_samples(10)], sample_rate_hz=FS, center_hz=1e9,
                    captures=[(0, T0), (0, T0)])
    with pytest.raises(InputError, match="only 10 samples"):
        write_sigmf(tmp_path / "a.sigmf-meta", [_samples(10)], sample_rate_hz=FS, center_hz=1e9,
                    captures=[(0, T0), (10, T0 + np.timedelta64(1, "s"))])
    assert list(tmp_path.iterdir()) == []


def _edit(meta, case):
    doc = json.loads(meta.read_text())
    caps = doc["captures"]
    if case == "frequency":
        caps[1]["core:frequency"] = 11.3e9
    elif case == "frequency type":
        caps[0]["core:frequency"] = "11.325e9"
    elif case == "overlap":  # capture 0 lasts 1 ms; capture 1 starts 0.5 ms after it began
        caps[1]["core:datetime"] = "2025-01-01T19:40:00.0005Z"
    elif case == "order":
        caps[2]["core:sample_start"] = 1_000
    elif case == "start type":
        caps[1]["core:sample_start"] = "1000"
    elif case == "datetime type":
        caps[1]["core:datetime"] = 5
    elif case == "beyond data":
        caps[2]["core:sample_start"] = 5_000
    elif case == "top-level list":
        doc = [doc]
    elif case == "truncated":
        data = meta.with_suffix(".sigmf-data")
        data.write_bytes(data.read_bytes()[:8 * 1_500])
    meta.write_text(json.dumps(doc))


@pytest.mark.parametrize("case, match", [
    ("frequency", "capture 1: core:frequency"), ("frequency type", "capture 0: core:frequency"),
    ("overlap", "capture 1: core:datetime .* before the end of capture 0"),
    ("order", "capture 2: core:sample_start 1000 does not increase"),
    ("start type", "capture 1: core:sample_start '1000'"), ("datetime type", "capture 1: core:datetime 5"),
    ("beyond data", "capture 2: core:sample_start 5000 is beyond"), ("top-level list", "JSON object"),
    ("truncated", "capture 2: core:sample_start 2000 is beyond the 1500 samples"),
])
def test_capture_refusals(tmp_path, case, match):
    meta, _ = _write_captures(tmp_path)
    _edit(meta, case)
    with pytest.raises(InputError, match=match) as exc:
        open_sigmf(meta, verify=False)
    assert str(meta) in str(exc.value) and "\n" not in str(exc.value)


def test_sha512_checked_refuses_a_modified_file_after_the_body(tmp_path):
    from leosop.signal.checksum import sha512_checked

    meta = _write(tmp_path, _samples(1_000))
    data = meta.with_suffix(".sigmf-data")
    rec = open_sigmf(meta, verify=False)
    with sha512_checked(rec):  # intact: nothing raised
        ran = rec.read(0, 10)
    assert ran.shape == (10,)
    raw = bytearray(data.read_bytes())
    raw[4 * 501] ^= 0x01  # one bit of sample 250's real part: same size, same sample count
    data.write_bytes(bytes(raw))
    rec = open_sigmf(meta, verify=False)
    body_done = []
    with pytest.raises(InputError, match=r"sigmf-data: contents do not match core:sha512"):
        with sha512_checked(rec):
            body_done.append(True)
    assert body_done == [True]  # the body ran; the refusal came on leaving it
    # An error of the body on a modified file gives way to the checksum's (the better explanation).
    with pytest.raises(InputError, match="core:sha512") as info:
        with sha512_checked(rec):
            raise InputError("sample 250 is odd")
    assert "odd" in str(info.value.__cause__)
    with pytest.raises(InputError, match="core:sha512"):
        open_sigmf(meta)  # verify=True checks at once, as before


def test_annotations_in_the_order_sigmf_adds_them(tmp_path):
    # Given out of order and with equal starts: written as sigmf's own add_annotation, one call
    # each (its stable sort at every call), writes them (a second implementation).
    notes = [(300, 10, {"leosop:sat_id": "b"}), (0, 10, {"leosop:sat_id": "a"}), (300, 5, {"leosop:sat_id": "c"}),
             (100, 1, {"leosop:doppler_hz": 2.5})]
    meta = tmp_path / "rec.sigmf-meta"
    write_sigmf(meta, [_samples(400)], sample_rate_hz=FS, center_hz=11.325e9, start_utc="2025-01-01T19:40:00Z",
                annotations=notes)
    ref = sigmffile.SigMFFile()
    for start, count, md in notes:
        ref.add_annotation(start, count, metadata=dict(md))
    assert json.loads(meta.read_text())["annotations"] == ref.get_annotations()
