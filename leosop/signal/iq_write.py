"""Writing IQ recordings: SigMF files (cf32_le, ci16_le, ci8, cu8) from chunks of samples, atomically.

The reader of what is written here is :mod:`leosop.signal.iq`; integer
formats are quantised with the scaling it inverts (:func:`quantise`).
"""

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fileio import atomic_files
from ..timebase import parse_utc
from .checksum import sha512_hex
from .iq import DATATYPES, FULL_SCALE

__all__ = ["quantise", "write_sigmf", "write_sigmf_files", "SIGMF_EXTENSION_VERSION"]

#: Version of the ``leosop:`` SigMF extension (``core:extensions``): the comb's
#: ``leosop:n_tones`` / ``leosop:tone_spacing_hz``, the generator's truth
#: annotations and draws; readers that do not know it may ignore it.
SIGMF_EXTENSION_VERSION = "1.0.0"


def _format_utc_ns(time_utc):
    """ISO 8601 UTC text to the nanosecond, trailing zeros of the fraction dropped (at least seconds)."""
    text = np.datetime_as_string(parse_utc(time_utc), unit="ns")
    return text.rstrip("0").rstrip(".") + "Z" if "." in text else text + "Z"


def quantise(iq, datatype, full_scale=1.0):
    """Complex samples as the interleaved integers of ``datatype`` (clipped, rounded), shape (2 n,).

    Amplitude ``full_scale`` maps to the format's :data:`FULL_SCALE` after
    reading back, so ``read(quantise(x, d, a)) = x / a * FULL_SCALE[d]`` to
    within half a level where not clipped.
    """
    comp, scale, zero = DATATYPES[datatype]
    info = np.iinfo(comp)
    c = np.asarray(iq)
    inter = np.empty(2 * c.size)
    inter[0::2], inter[1::2] = c.real, c.imag
    levels = FULL_SCALE[datatype] / scale / full_scale
    return np.clip(np.round(inter * levels + zero), info.min, info.max).astype(comp)


def write_sigmf(meta_path, chunks, **options):
    """Write a SigMF recording from an iterable of complex sample chunks, atomically.

    The data file and then the metadata are moved into place only when both
    are complete; on any error neither is left. Options as
    :func:`write_sigmf_files`.

    Parameters
    ----------
    meta_path : str or Path
        Output ``.sigmf-meta``; the data go to the ``.sigmf-data`` beside it.
    chunks : iterable of ndarray of complex

    Returns
    -------
    n_samples : int
    """
    meta_path = Path(meta_path)
    if meta_path.suffix != ".sigmf-meta":
        raise InputError(f"{meta_path}: output must end in .sigmf-meta")
    with atomic_files([meta_path.with_suffix(".sigmf-data"), meta_path]) as (tmp_data, tmp_meta):
        return write_sigmf_files(tmp_data, tmp_meta, chunks, **options)


def write_sigmf_files(data_file, meta_file, chunks, *, sample_rate_hz, center_hz, start_utc=None, datatype="cf32_le",
                      annotations=(), global_extra=None, full_scale=1.0, captures=None):
    """Write the data and metadata of a SigMF recording to the files given (not atomic).

    For staged outputs (:func:`leosop.fileio.atomic_files`); most callers
    want :func:`write_sigmf`.

    Parameters
    ----------
    data_file, meta_file : str or Path
        Where the samples and the metadata JSON go.
    chunks : iterable of ndarray of complex
        Consecutive samples; written as they come (never all in memory).
    sample_rate_hz, center_hz : float
    start_utc : datetime64 or str, optional
        UTC time of the first sample (``core:datetime``) of a single-capture
        recording; give either this or ``captures``.
    datatype : {"cf32_le", "ci16_le", "ci8", "cu8"}
    annotations : iterable of (sample_start, sample_count, dict)
    global_extra : dict, optional
        Extra global keys (``leosop:n_tones``, ``core:description``, ...).
    full_scale : float
        Amplitude mapped to the integer formats' largest value (32767 for
        ci16, 127 for ci8, 255 for cu8); values beyond are clipped, values
        are rounded to the nearest level (the reader's scaling inverted).
    captures : sequence of (int, datetime64 or str), optional
        ``(sample_start, UTC of that sample)`` of each capture, the first at
        sample 0, starts increasing (snapshot recordings: one per snapshot,
        DESIGN 4.2); all share ``center_hz``. Times are written to the
        nanosecond.

    Returns
    -------
    n_samples : int
    """
    import sigmf
    from sigmf import SigMFFile

    if datatype not in DATATYPES:
        raise InputError(f"datatype {datatype!r}: expected one of {', '.join(DATATYPES)}")
    if (start_utc is None) == (captures is None):
        raise InputError("write_sigmf: give exactly one of start_utc and captures")
    captures = [(0, start_utc)] if captures is None else [(int(s), t) for s, t in captures]
    starts = [s for s, _ in captures]
    if starts[0] != 0 or np.any(np.diff(starts) <= 0):
        raise InputError(f"write_sigmf: capture starts {starts[:5]}... must begin at 0 and increase")
    n = 0
    with open(data_file, "wb") as fh:
        for chunk in chunks:
            c = np.asarray(chunk)
            if datatype == "cf32_le":
                fh.write(c.astype("<c8").tobytes())
            else:
                fh.write(quantise(c, datatype, full_scale).tobytes())
            n += c.size
    info = {sigmf.DATATYPE_KEY: datatype, sigmf.SAMPLE_RATE_KEY: float(sample_rate_hz),
            sigmf.VERSION_KEY: sigmf.__specification__, sigmf.SHA512_KEY: sha512_hex(data_file)}
    info.update(global_extra or {})
    if any(str(k).startswith("leosop:") for k in info) or any(
            str(k).startswith("leosop:") for _, _, md in annotations for k in md):
        # The leosop: keys (comb layout, truth, draws) are declared as an optional extension.
        info[sigmf.EXTENSIONS_KEY] = [{"name": "leosop", "version": SIGMF_EXTENSION_VERSION, "optional": True}]
    if starts[-1] >= n:
        raise InputError(f"write_sigmf: capture at sample {starts[-1]} but only {n} samples were written")
    # The annotations as SigMFFile.add_annotation writes them (its stable sort by start of the list in order
    # given), sorted once: add_annotation sorts the whole list at each call, quadratic in their number.
    notes = sorted(({**md, sigmf.SAMPLE_START_KEY: int(start), sigmf.SAMPLE_COUNT_KEY: int(count)}
                    for start, count, md in annotations), key=lambda a: a[sigmf.SAMPLE_START_KEY])
    meta = SigMFFile(metadata={SigMFFile.GLOBAL_KEY: {}, SigMFFile.CAPTURE_KEY: [], SigMFFile.ANNOTATION_KEY: notes},
                     global_info=info)
    for start, t in captures:
        meta.add_capture(start, metadata={sigmf.FREQUENCY_KEY: float(center_hz),
                                          sigmf.DATETIME_KEY: _format_utc_ns(t)})
    Path(meta_file).write_text(meta.dumps(pretty=True) + "\n")
    return n
