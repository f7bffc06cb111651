"""IQ recordings: SigMF (cf32_le, ci16_le, ci8, cu8) and raw files, read in blocks.

Metadata go through the ``sigmf`` package (DESIGN 4.2); samples are
read block by block, so a recording far larger than memory is only ever
touched one block at a time. Integer samples are scaled to [-1, 1): ci16 by
1/32768 (SigMF's convention), ci8 (HackRF, bladeRF) by 1/128, cu8 (RTL-SDR,
unsigned, zero at 127.5) as (x - 127.5) / 128; the estimators do not depend on
the scale. An 8-bit file declared with the wrong sign convention (a cu8 file
as ci8 or the reverse) is refused when opened, by the spread of its first
samples read both ways (:func:`check_8bit_sign`).

Raw files take their parameters from options; a gqrx file name
(``gqrx_YYYYMMDD_HHMMSS_FREQ_RATE_fc.raw``) supplies the start, the centre
frequency and the sample rate (:func:`~.recorders.name_metadata`).
"""

import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np
import numpy.typing as npt

from ..constellations import DEFAULT_FAMILY, REGISTRY, CombModel
from ..errors import InputError
from ..fileio import check_input_file
from ..timebase import format_utc, parse_utc
from .checksum import check_sha512
from .recorders import check_8bit_sign, name_metadata

__all__ = ["DATATYPES", "FULL_SCALE", "Capture", "Recording", "open_sigmf", "open_raw"]

#: Accepted sample formats: SigMF name -> (numpy component dtype, scale to float, zero level in file units).
DATATYPES = {"cf32_le": (np.dtype("<f4"), 1.0, 0.0), "ci16_le": (np.dtype("<i2"), 1.0 / 32768.0, 0.0),
             "ci8": (np.dtype("i1"), 1.0 / 128.0, 0.0), "cu8": (np.dtype("u1"), 1.0 / 128.0, 127.5)}
#: Largest component magnitude of each integer format after scaling (clipping sits there); cf32 has none.
FULL_SCALE = {"ci16_le": 32767.0 / 32768.0, "ci8": 127.0 / 128.0, "cu8": 127.5 / 128.0}
_RAW_NAMES = {"cf32": "cf32_le", "ci16": "ci16_le", "ci8": "ci8", "cu8": "cu8"}
#: Fraction of clipped I/Q values in one read above which :meth:`Recording.read` warns (1e-4: a Gaussian
#: front end with 4 sigmas of headroom clips 6e-5 of its values).
CLIP_WARN_FRACTION = 1e-4
#: Slack of the capture overlap check: writers may round core:datetime to the microsecond.
_OVERLAP_TOL_S = 1e-6
#: A recording's comb unless its metadata say otherwise: the default family's (Starlink's, which has one).
_DEFAULT_COMB = cast(CombModel, REGISTRY[DEFAULT_FAMILY].comb)


@dataclass(frozen=True)
class Capture:
    """One contiguous stretch of samples (a SigMF capture segment).

    Attributes
    ----------
    sample_start : int
        Index of its first sample in the recording.
    n_samples : int
    start_utc : numpy.datetime64 or None
        UTC time of its first sample (``core:datetime``), None when not given.
    """

    sample_start: int
    n_samples: int
    start_utc: np.datetime64 | None


@dataclass
class Recording:
    """A complex IQ recording on disk.

    Attributes
    ----------
    data_path : Path
    datatype : str
        ``cf32_le``, ``ci16_le``, ``ci8`` or ``cu8``.
    sample_rate_hz : float
    center_hz : float or None
        Nominal RF frequency of the pilot comb's central tone (baseband 0 Hz).
    start_utc : numpy.datetime64 or None
        UTC time of the first sample.
    n_samples : int
    n_tones, tone_spacing_hz : int, float
        The comb as declared by the recording (defaults: the default family's, Starlink).
    annotations : list of dict
        SigMF annotations (``leosop generate`` stores its truth there).
    offset_bytes : int
        Header bytes before the first sample.
    captures : list of Capture
        Contiguous stretches in sample order (snapshot recordings have one per
        snapshot); default one capture of the whole recording at ``start_utc``.
    hw : str or None
        The recorder's hardware as its metadata say (SigMF ``core:hw``).
    sha512 : str or None
        The data file's declared SHA-512 (SigMF ``core:sha512``; :func:`check_sha512`).
    """

    data_path: Path
    datatype: str
    sample_rate_hz: float
    center_hz: float | None
    start_utc: np.datetime64 | None
    n_samples: int
    n_tones: int = _DEFAULT_COMB.n_tones
    tone_spacing_hz: float = _DEFAULT_COMB.tone_spacing_hz
    annotations: list = field(default_factory=list)
    offset_bytes: int = 0
    captures: list = field(default_factory=list)
    hw: str | None = None
    sha512: str | None = None

    def __post_init__(self):
        self._clip_warned = False
        if not self.captures:
            self.captures = [Capture(0, int(self.n_samples), self.start_utc)]

    @property
    def duration_s(self):
        return self.n_samples / self.sample_rate_hz

    def read(self, start: int, count: int, check_finite: bool = True,
             out: npt.NDArray[np.complex64] | None = None) -> npt.NDArray[np.complex64]:
        """Samples ``start .. start+count-1`` as complex64, shape (count,).

        ``out``: a C-contiguous complex64 array (count,) to write them into
        (returned), e.g. an aligned one (:func:`~.fft.empty_aligned`) that
        an FFT then takes where it lies; cf32 files are read straight into
        it. Raises InputError if the range leaves the recording or (with
        ``check_finite``, for a caller that does not detect them itself)
        holds NaN/inf.
        """
        comp, scale, zero = DATATYPES[self.datatype]
        if out is not None and (out.dtype != np.complex64 or out.shape != (count,) or not out.flags.c_contiguous):
            raise ValueError(f"out must be a C-contiguous complex64 array of shape ({count},)")
        if out is not None and comp == np.float32:
            raw = self._read_into(start, count, out.view(np.float32))
        elif out is not None:
            raw = out.view(np.float32)
            np.copyto(raw, self.read_raw(start, count), casting="unsafe")
        else:
            raw = np.asarray(self.read_raw(start, count), dtype=np.float32)
        if zero:
            raw -= np.float32(zero)
        if scale != 1.0:
            raw *= np.float32(scale)
            self._check_clipping(raw, start)
        elif check_finite and not np.all(np.isfinite(raw)):
            bad = start + int(np.flatnonzero(~np.isfinite(raw))[0]) // 2
            raise InputError(f"{self.data_path}: sample {bad} is NaN or inf")
        return raw.view(np.complex64) if out is None else out

    def _check_clipping(self, comps, start):
        """Warn once per recording when more than :data:`CLIP_WARN_FRACTION` of a read's components sit
        at the format's extremes (two reductions; the count only when an extreme is reached)."""
        fs = np.float32(FULL_SCALE[self.datatype])
        if self._clip_warned or comps.size == 0 or (comps.max() < fs and comps.min() > -fs - np.float32(1e-3)):
            return
        frac = np.count_nonzero(np.abs(comps) >= fs) / comps.size
        if frac > CLIP_WARN_FRACTION:
            self._clip_warned = True
            warnings.warn(f"{self.data_path}: {100 * frac:.2g} % of the I/Q values of samples {start}.."
                          f"{start + comps.size // 2 - 1} are clipped at the {self.datatype} full scale: lower "
                          "the receiver's gain (clipping spreads every strong line into spurs and biases C/N0)",
                          stacklevel=3)

    def _read_into(self, start, count, comps):
        """:meth:`read_raw` of a cf32 file straight into ``comps`` (float32, (2 count,)); returns it."""
        self._check_range(start, count)
        with open(self.data_path, "rb") as f:
            f.seek(self.offset_bytes + 8 * start)
            got = f.readinto(memoryview(comps).cast("B"))
        if got != comps.nbytes:
            raise InputError(f"{self.data_path}: ends before sample {start + count} (a file cut short?)")
        return comps

    def _check_range(self, start, count):
        if start < 0 or count < 0 or start + count > self.n_samples:
            raise InputError(f"{self.data_path}: samples {start}..{start + count} are outside the "
                             f"{self.n_samples} samples of the recording")

    def read_raw(self, start, count):
        """Components of samples ``start .. start+count-1`` as stored (I, Q interleaved), shape (2 count,).

        The file's own integers (or floats), for checks that need them. Read
        with one system call (faster than a memory map, whose page faults
        cost more than the copy; 8-bit files move half of ci16's bytes).
        """
        self._check_range(start, count)
        comp = DATATYPES[self.datatype][0]
        return np.fromfile(self.data_path, dtype=comp, count=2 * count,
                           offset=self.offset_bytes + 2 * start * comp.itemsize)

    def capture_samples(self, cap):
        """One capture's samples as a 1-D complex64 array-like to slice, each slice one read of the file."""
        return _CaptureSamples(self, cap)

    def blocks(self, block_len):
        """Iterate ``(start, samples)`` over whole consecutive blocks of ``block_len`` samples."""
        if block_len < 1 or block_len > self.n_samples:
            raise InputError(f"block of {block_len} samples must be between 1 and the recording's "
                             f"{self.n_samples} samples ({self.duration_s:.6g} s)")
        for start in range(0, self.n_samples - block_len + 1, block_len):
            yield start, self.read(start, block_len)


class _CaptureSamples:
    """:meth:`Recording.capture_samples`: ``len``, ``dtype``, ``ndim`` and slicing of one capture."""

    ndim = 1
    dtype = np.dtype(np.complex64)

    def __init__(self, rec, cap):
        self.rec, self.cap = rec, cap

    def __len__(self):
        return self.cap.n_samples

    def __getitem__(self, index):
        start, stop, _ = index.indices(self.cap.n_samples)
        return self.rec.read(self.cap.sample_start + start, max(stop - start, 0))


def _check_rate(sample_rate_hz, where, param=()):
    try:
        fs = float(sample_rate_hz)
    except (TypeError, ValueError):
        raise InputError(f"{where}: sample rate {sample_rate_hz!r} is not a number", param=param) from None
    if not np.isfinite(fs) or fs <= 0:
        raise InputError(f"{where}: sample rate {sample_rate_hz!r} must be a finite number > 0 Hz", param=param)
    return fs


def _count_samples(data_path, datatype, offset_bytes, where):
    sample_bytes = 2 * DATATYPES[datatype][0].itemsize
    size = data_path.stat().st_size - offset_bytes
    if size < 0 or size % sample_bytes:
        raise InputError(f"{where}: {data_path} holds {size} bytes, not a whole number of "
                         f"{sample_bytes}-byte {datatype} samples (truncated?)")
    return size // sample_bytes


def open_sigmf(meta_path: str | os.PathLike[str], *, verify: bool = True) -> Recording:
    """Open a SigMF recording (``.sigmf-meta`` beside its ``.sigmf-data``).

    Parameters
    ----------
    meta_path : str or Path
        The ``.sigmf-meta`` file (a ``.sigmf-data`` path is accepted too).
    verify : bool
        Check ``core:sha512`` when present (streamed; catches truncation). Without it the
        caller checks it later (:func:`check_sha512`, :func:`sha512_checked`).

    Returns
    -------
    Recording
    """
    from sigmf import sigmffile
    from sigmf.error import SigMFError

    meta_path = Path(meta_path)
    if meta_path.suffix == ".sigmf-data":
        meta_path = meta_path.with_suffix(".sigmf-meta")
    if meta_path.suffix != ".sigmf-meta":
        raise InputError(f"{meta_path}: expected a .sigmf-meta file")
    check_input_file(meta_path, "SigMF metadata file")
    data_path = meta_path.with_suffix(".sigmf-data")
    if not data_path.is_file():
        raise InputError(f"{data_path}: missing SigMF data file for {meta_path.name}")
    if data_path.stat().st_size == 0:
        raise InputError(f"{data_path}: empty SigMF data file (no samples for {meta_path.name})")
    _check_structure(meta_path)
    try:
        with warnings.catch_warnings():  # sigmf warns about odd sizes; we raise below
            warnings.simplefilter("ignore")
            meta = sigmffile.fromfile(str(meta_path), skip_checksum=True)
    except (SigMFError, json.JSONDecodeError, KeyError, ValueError, TypeError, AttributeError, IndexError) as exc:
        raise InputError(f"{meta_path}: not valid SigMF metadata ({exc})".replace("\n", " ")) from None
    info = meta.get_global_info()
    datatype = info["core:datatype"]
    fs = _check_rate(info.get("core:sample_rate"), f"{meta_path}: core:sample_rate")
    raw_caps = meta.get_captures() or [{}]
    offset = _int_field(raw_caps[0], "core:header_bytes", 0, f"{meta_path}: capture 0")
    n = _count_samples(data_path, datatype, offset, str(meta_path))
    captures, center_hz = _captures(raw_caps, n, fs, meta_path)
    annotations = meta.get_annotations()
    end = max((a.get("core:sample_start", 0) + a.get("core:sample_count", 0) for a in annotations), default=0)
    if end > n:
        raise InputError(f"{meta_path}: annotations reach sample {end} but {data_path.name} holds {n} (truncated?)")
    rec = Recording(
        data_path=data_path,
        datatype=datatype,
        sample_rate_hz=fs,
        center_hz=center_hz,
        start_utc=captures[0].start_utc,
        n_samples=int(n),
        n_tones=int(info.get("leosop:n_tones", Recording.n_tones)),
        tone_spacing_hz=float(info.get("leosop:tone_spacing_hz", Recording.tone_spacing_hz)),
        annotations=annotations,
        offset_bytes=offset,
        captures=captures,
        hw=info.get("core:hw"),
        sha512=info.get("core:sha512") or None,
    )
    if verify:
        check_sha512(rec)
    check_8bit_sign(rec, f"{meta_path}: core:datatype")
    return rec


#: Types of the global keys read here: key -> (types, what the message says is expected).
_NUMBER = ((int, float), "a number")
_GLOBAL_TYPES = {"core:datatype": ((str,), "a string"), "core:sample_rate": _NUMBER,
                 "core:num_channels": ((int,), "an integer"), "core:sha512": ((str,), "a hex string"),
                 "core:hw": ((str,), "a string"),
                 "leosop:n_tones": ((int,), "an odd integer >= 1"), "leosop:tone_spacing_hz": _NUMBER}
#: Types of the annotation keys read here (``leosop generate``'s truth).
_ANNOTATION_TYPES = {"core:sample_start": ((int,), "an integer >= 0"), "core:sample_count": ((int,), "an integer >= 0"),
                     "leosop:sat_id": ((str,), "a string"), "leosop:t_s": _NUMBER, "leosop:doppler_hz": _NUMBER,
                     "leosop:doppler_rate_hz_per_s": _NUMBER, "leosop:cn0_dbhz": _NUMBER}


def _check_types(obj, types, where):
    """Refuse values of the wrong JSON type (booleans are not numbers; numbers must be finite)."""
    for key, (allowed, expected) in types.items():
        if key not in obj:
            continue
        value = obj[key]
        ok = isinstance(value, allowed) and not isinstance(value, bool)
        if ok and isinstance(value, (int, float)):
            # A JSON integer is finite however large (np.isfinite refuses those beyond int64).
            ok = (isinstance(value, int) or np.isfinite(value)) and (allowed != (int,) or value >= 0)
        if not ok:
            raise InputError(f"{where}: {key} {value!r} must be {expected}")


def _check_structure(meta_path):
    """Refuse metadata whose JSON has the wrong shape or types (top-level list, string numbers, ...)."""
    try:
        doc = json.loads(meta_path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"{meta_path}: not valid JSON ({exc})".replace("\n", " ")) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("global"), dict):
        raise InputError(f"{meta_path}: expected a JSON object with a 'global' object (SigMF metadata)")
    for key in ("captures", "annotations"):
        items = doc.get(key, [])
        if not isinstance(items, list) or not all(isinstance(c, dict) for c in items):
            raise InputError(f"{meta_path}: '{key}' must be a list of objects")
    _check_types(doc["global"], _GLOBAL_TYPES, f"{meta_path}: global")
    channels = doc["global"].get("core:num_channels", 1)
    if channels != 1:  # before the sigmf package, which divides by it
        raise InputError(f"{meta_path}: global: core:num_channels {channels} is not supported; expected 1 (one "
                         "channel of interleaved I and Q)")
    datatype = doc["global"].get("core:datatype")
    if datatype not in DATATYPES:  # before the sigmf package, which fails on odd names
        raise InputError(f"{meta_path}: core:datatype {datatype!r} is not supported; expected one of "
                         f"{', '.join(DATATYPES)}")
    n_tones = doc["global"].get("leosop:n_tones", 1)
    spacing = doc["global"].get("leosop:tone_spacing_hz", 1.0)
    if n_tones % 2 != 1:
        raise InputError(f"{meta_path}: global: leosop:n_tones {n_tones} must be an odd integer >= 1")
    if spacing <= 0:
        raise InputError(f"{meta_path}: global: leosop:tone_spacing_hz {spacing!r} must be > 0 Hz")
    for k, ann in enumerate(doc.get("annotations", [])):
        _check_types(ann, _ANNOTATION_TYPES, f"{meta_path}: annotation {k}")


def _int_field(cap, key, default, where):
    value = cap.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError(f"{where}: {key} {value!r} must be an integer >= 0")
    return value


def _captures(raw_caps, n_samples, sample_rate_hz, meta_path):
    """Validated :class:`Capture` list and the common ``core:frequency`` of SigMF capture segments."""
    caps, freqs = [], []
    for k, cap in enumerate(raw_caps):
        where = f"{meta_path}: capture {k}"
        start = _int_field(cap, "core:sample_start", 0 if k == 0 else None, where)
        if k and _int_field(cap, "core:header_bytes", 0, where):
            raise InputError(f"{where}: core:header_bytes is only supported on the first capture")
        if k == 0 and start != 0:
            raise InputError(f"{where}: core:sample_start {start} must be 0 for the first capture")
        if k and start <= caps[-1][0]:
            raise InputError(f"{where}: core:sample_start {start} does not increase (previous {caps[-1][0]})")
        if start >= n_samples:
            raise InputError(f"{where}: core:sample_start {start} is beyond the {n_samples} samples of the data "
                             "file (truncated?)")
        freq = cap.get("core:frequency")
        if freq is not None and (isinstance(freq, bool) or not isinstance(freq, (int, float))
                                 or not np.isfinite(freq) or freq <= 0):
            raise InputError(f"{where}: core:frequency {freq!r} must be a positive number [Hz]")
        if k and freq != freqs[0]:
            raise InputError(f"{where}: core:frequency {freq!r} differs from capture 0's {freqs[0]!r}")
        text = cap.get("core:datetime")
        if text is not None and not isinstance(text, str):
            raise InputError(f"{where}: core:datetime {text!r} must be an ISO 8601 string")
        try:
            start_utc = parse_utc(text, name="core:datetime") if text else None
        except ValueError as exc:
            raise InputError(f"{where}: {exc}") from None
        caps.append((start, start_utc))
        freqs.append(freq)
    ends = [s for s, _ in caps[1:]] + [n_samples]
    out = [Capture(int(s), int(e - s), t) for (s, t), e in zip(caps, ends)]
    for k in range(1, len(out)):
        prev, cap = out[k - 1], out[k]
        if prev.start_utc is None or cap.start_utc is None:
            continue
        gap_s = (cap.start_utc - prev.start_utc) / np.timedelta64(1, "s") - prev.n_samples / sample_rate_hz
        if gap_s < -_OVERLAP_TOL_S:
            raise InputError(f"{meta_path}: capture {k}: core:datetime {format_utc(cap.start_utc)} is before the end "
                             f"of capture {k - 1} ({-gap_s:.6g} s overlap)")
    return out, (None if freqs[0] is None else float(freqs[0]))


def open_raw(path: str | os.PathLike[str], *, dtype: str | None = None, sample_rate_hz: float | None = None,
             center_hz: float | None = None, start: str | np.datetime64 | None = None,
             offset_bytes: int = 0) -> Recording:
    """Open a headerless interleaved I/Q file with explicit parameters.

    Parameters not given are taken from the file name when a recorder's
    naming is recognised (:func:`~.recorders.name_metadata`); given ones win.

    Parameters
    ----------
    path : str or Path
    dtype : {"cf32", "ci16", "ci8", "cu8"} (or the SigMF names), optional
    sample_rate_hz : float, optional
    center_hz : float, optional
    start : str or datetime64, optional
        UTC time of the first sample.
    offset_bytes : int
        Bytes to skip before the first sample.
    """
    path = Path(path)
    named = name_metadata(path)
    dtype = dtype if dtype is not None else named.get("dtype")
    sample_rate_hz = sample_rate_hz if sample_rate_hz is not None else named.get("sample_rate_hz")
    center_hz = center_hz if center_hz is not None else named.get("center_hz")
    start = start if start is not None else named.get("start_utc")
    if dtype is None or sample_rate_hz is None:
        raise InputError(f"{path}: a raw file needs dtype and sample_rate_hz (its name says neither)",
                         param=("dtype", "sample_rate_hz"))
    datatype = _RAW_NAMES.get(dtype, dtype)
    if datatype not in DATATYPES:
        raise InputError(f"dtype {dtype!r}: expected one of {', '.join(_RAW_NAMES)}", param="dtype")
    fs = _check_rate(sample_rate_hz, "sample_rate_hz", param="sample_rate_hz")
    check_input_file(path, "raw IQ file")
    try:
        start_utc = parse_utc(start, name="start") if start is not None else None
    except ValueError as exc:
        raise InputError(str(exc), param="start") from None
    n = _count_samples(path, datatype, offset_bytes, str(path))
    rec = Recording(path, datatype, fs, center_hz, start_utc, int(n), offset_bytes=int(offset_bytes))
    check_8bit_sign(rec, f"{path}: dtype", param="dtype")
    return rec
