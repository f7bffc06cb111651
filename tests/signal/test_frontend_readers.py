"""Readers of real front ends' formats: ci8 / cu8 / ci16 / cf32 round trips, raw files and recorder names, the
8-bit sign check, clipping warnings."""

import warnings

import numpy as np
import pytest
from sigmf import sigmffile

from leosop.cli import main
from leosop.errors import InputError
from leosop.signal.iq import FULL_SCALE, open_raw, open_sigmf
from leosop.signal.iq_write import quantise, write_sigmf
from leosop.signal.recorders import name_metadata

FS = 1e6
START = "2025-01-01T19:40:00Z"


def _samples(n, sigma=0.2, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.standard_normal(n) + 1j * rng.standard_normal(n)) * sigma


def _write(tmp_path, x, datatype, name="rec", **kw):
    meta = tmp_path / f"{name}.sigmf-meta"
    write_sigmf(meta, [x], sample_rate_hz=FS, center_hz=11.325e9, start_utc=START, datatype=datatype, **kw)
    return meta


@pytest.mark.parametrize("datatype, bits", [("ci8", 8), ("cu8", 8), ("ci16_le", 16)])
def test_integer_round_trip(tmp_path, datatype, bits):
    x = _samples(4_000)
    rec = open_sigmf(_write(tmp_path, x, datatype, full_scale=1.0))
    got = rec.read(0, x.size)
    assert rec.datatype == datatype and got.dtype == np.complex64
    # Read back in units of full scale: the step is 1/2^(bits-1) of it (cu8: 255 levels over
    # [-127.5, 127.5]/128), the error half a step; 0.2-sigma samples never reach full scale.
    step = 1.0 / 2 ** (bits - 1)
    expect = x * FULL_SCALE[datatype]
    assert np.max(np.abs(got.real - expect.real)) <= 0.5 * step + 1e-6
    assert np.max(np.abs(got.imag - expect.imag)) <= 0.5 * step + 1e-6
    # The sigmf package's own reader as the second implementation: it takes the unsigned zero
    # at 128 (not RTL-SDR's 127.5) and scales by 2^-(bits-1), as we do.
    theirs = sigmffile.fromfile(str(rec.data_path.with_suffix(".sigmf-meta"))).read_samples()
    shift = 0.5 / 128 if datatype == "cu8" else 0.0
    np.testing.assert_allclose(theirs.real + shift, got.real, atol=1e-6)
    np.testing.assert_allclose(theirs.imag + shift, got.imag, atol=1e-6)


def test_quantise_clips_at_the_extremes():
    x = np.array([2.0 + 0j, -2.0 - 2j, 0.0 + 0j])
    np.testing.assert_array_equal(quantise(x, "ci8"), np.array([127, 0, -128, -128, 0, 0], dtype=np.int8))
    np.testing.assert_array_equal(quantise(x, "cu8"), np.array([255, 128, 0, 0, 128, 128], dtype=np.uint8))


@pytest.mark.parametrize("dtype, comp, zero", [("ci8", np.int8, 0.0), ("cu8", np.uint8, 127.5),
                                               ("ci16", np.int16, 0.0), ("cf32", np.float32, 0.0)])
def test_raw_files(tmp_path, dtype, comp, zero):
    rng = np.random.default_rng(1)
    inter = np.clip(np.round(rng.normal(zero, 20.0, 2_000)), -100 + zero, 100 + zero).astype(comp)
    path = tmp_path / f"rec.{dtype}"
    inter.tofile(path)
    rec = open_raw(path, dtype=dtype, sample_rate_hz=FS, start=START)
    scale = {"ci8": 1 / 128, "cu8": 1 / 128, "ci16": 1 / 32768, "cf32": 1.0}[dtype]
    want = (inter.astype(np.float64) - zero) * scale
    got = rec.read(0, 1_000)
    np.testing.assert_allclose(got.real, want[0::2], rtol=1e-6)
    np.testing.assert_allclose(got.imag, want[1::2], rtol=1e-6)


def test_gqrx_name(tmp_path):
    path = tmp_path / "gqrx_20250101_194000_11325000000_2500000_fc.raw"
    _samples(1_000).astype(np.complex64).tofile(path)
    assert name_metadata(path)["center_hz"] == 11.325e9
    rec = open_raw(path)
    assert (rec.datatype, rec.sample_rate_hz, rec.center_hz) == ("cf32_le", 2.5e6, 11.325e9)
    assert rec.start_utc == np.datetime64("2025-01-01T19:40:00", "ns")
    # Options win over the name.
    assert open_raw(path, sample_rate_hz=1e6).sample_rate_hz == 1e6
    assert name_metadata(tmp_path / "capture.raw") == {}
    with pytest.raises(InputError, match="needs dtype and sample_rate_hz"):
        open_raw(tmp_path / "capture.raw")


def test_core_hw_is_kept(tmp_path):
    meta = _write(tmp_path, _samples(100), "ci8", global_extra={"core:hw": "HackRF One + Ku LNB (9.75 GHz PLL)"})
    assert open_sigmf(meta).hw == "HackRF One + Ku LNB (9.75 GHz PLL)"


@pytest.mark.parametrize("written, declared", [("cu8", "ci8"), ("ci8", "cu8")])
def test_wrong_8bit_sign_is_named(tmp_path, capsys, written, declared):
    """An RTL-SDR (cu8) file declared ci8, and the reverse: refused, the right type named, exit 2."""
    meta = _write(tmp_path, _samples(5_000, sigma=0.1), written)
    text = meta.read_text().replace(f'"core:datatype": "{written}"', f'"core:datatype": "{declared}"')
    meta.write_text(text)
    with pytest.raises(InputError, match=f"core:datatype {declared}: .* the file is {written}"):
        open_sigmf(meta, verify=False)
    status = main(["doppler", str(meta)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and f"the file is {written}" in err
    raw = tmp_path / "x.bin"
    raw.write_bytes(meta.with_suffix(".sigmf-data").read_bytes())
    with pytest.raises(InputError, match=f"dtype {declared}: .* the file is {written}"):
        open_raw(raw, dtype=declared, sample_rate_hz=FS)


def test_clipping_warns_once(tmp_path):
    x = _samples(10_000, sigma=0.5)  # 2 sigma of headroom: ~5 % of the values clip
    rec = open_sigmf(_write(tmp_path, x, "ci8", full_scale=1.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec.read(0, 5_000)
        rec.read(5_000, 5_000)
    assert len(caught) == 1 and "clipped at the ci8 full scale" in str(caught[0].message)
    frac = float(str(caught[0].message).split(" % ")[0].split(": ")[-1]) / 100
    # Gaussian with sigma 0.5 per component beyond 127/128 ~ 0.992: 2 Q(1.984) = 4.7 %.
    assert frac == pytest.approx(0.047, abs=0.006)
    clean = open_sigmf(_write(tmp_path, _samples(10_000, sigma=0.1), "ci8", name="clean"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clean.read(0, 10_000)
