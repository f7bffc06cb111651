"""What recorders write: 8-bit sign conventions and file names that carry metadata.

RTL-SDR writes unsigned 8-bit samples (cu8, zero at 127.5), HackRF and
bladeRF signed ones (ci8); a file declared with the other convention reads
as noise piled at full scale, which :func:`check_8bit_sign` refuses. gqrx
names its raw recordings after their start, centre frequency and rate
(:func:`name_metadata`).
"""

import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..timebase import parse_utc

__all__ = ["check_8bit_sign", "name_metadata"]

#: Samples read at the start of an 8-bit file to check its sign convention.
_SIGN_CHECK_SAMPLES = 1 << 16
#: gqrx's raw file name: gqrx_YYYYMMDD_HHMMSS_<centre Hz>_<rate Hz>_fc.raw (cf32, UTC time).
_GQRX_NAME = re.compile(r"gqrx_(\d{8})_(\d{6})_(\d+)_(\d+)_fc\.raw$")


def check_8bit_sign(rec, where, *, param=()):
    """Refuse an 8-bit recording read with the wrong sign convention (cu8 declared ci8 or the reverse).

    The first :data:`_SIGN_CHECK_SAMPLES` samples' bytes are read as signed
    and as unsigned-minus-127.5. A receiver's samples spread around their
    zero; read the wrong way, every value near zero lands near +-128 (a DC of
    127.5 that no signal has, or values piled at both ends), and the spread
    grows to ~127 full-scale units. Declared and other reading are compared:
    the other one four times tighter (in variance) is taken as the truth.
    (A recording driven hard to full scale looks alike both ways and passes.)

    Parameters
    ----------
    rec : Recording
    where : str
        Names the file and field in the message.
    param : str or tuple of str, optional
        The parameter ``where`` names, for the error (:class:`~leosop.errors.InputError`).
    """
    if rec.datatype not in ("ci8", "cu8"):
        return
    raw = np.asarray(rec.read_raw(0, min(rec.n_samples, _SIGN_CHECK_SAMPLES)))
    if raw.size < 64:
        return
    signed = raw.view(np.int8).astype(np.float32)
    unsigned = raw.view(np.uint8).astype(np.float32) - np.float32(127.5)
    declared, other = (signed, unsigned) if rec.datatype == "ci8" else (unsigned, signed)
    var_declared = float(np.mean(declared**2))  # about the format's zero: a DC offset counts
    var_other = float(np.mean(other**2))
    if var_other < 0.25 * var_declared:
        right = "cu8" if rec.datatype == "ci8" else "ci8"
        what = ("sit around 127.5 (unsigned 8-bit, as RTL-SDR writes)" if right == "cu8"
                else "sit around 0 (signed 8-bit, as HackRF writes)")
        raise InputError(f"{where} {rec.datatype}: the samples {what}, an RMS of {np.sqrt(var_declared):.0f} "
                         f"read as {rec.datatype} against {np.sqrt(var_other):.1f} as {right}: the file is {right}",
                         param=param)


def name_metadata(path):
    """What a recorder's file name says: ``{"dtype", "sample_rate_hz", "center_hz", "start_utc"}`` or {}.

    Only gqrx's raw recordings are recognised (``gqrx_20250101_194000_11325000000_2500000_fc.raw``:
    UTC date and time, centre frequency and sample rate in Hz, complex float32).
    """
    m = _GQRX_NAME.search(Path(path).name)
    if not m:
        return {}
    day, hms, centre, rate = m.groups()
    iso = f"{day[:4]}-{day[4:6]}-{day[6:]}T{hms[:2]}:{hms[2:4]}:{hms[4:]}Z"
    try:
        start = parse_utc(iso, name="file name")
    except ValueError:
        return {}
    return {"dtype": "cf32", "sample_rate_hz": float(rate), "center_hz": float(centre), "start_utc": start}
