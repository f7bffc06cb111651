"""Parsing and checking of option values shared by several subcommands."""

import argparse
import math
import warnings

import numpy as np

from ..constants import DAY_S
from ..errors import InputError
from ..timebase import format_utc, parse_utc, seconds_since

#: Element sets older or newer than this at the start time earn a warning:
#: SGP4 errors grow by kilometres per day from the epoch.
STALE_DAYS = 14.0

__all__ = ["STALE_DAYS", "finite_float", "parse_site", "parse_velocity", "parse_time", "positive", "add_raw_options",
           "open_recording", "mask_deg", "warn_stale"]


def finite_float(text):
    """Option value -> float; NaN and infinities are refused (every ``type=float`` option).

    The command-line parser registers this for ``float``, so an option given
    ``nan`` or ``1e999`` is an option error, not a silent NaN result.
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def parse_site(text, option="--site"):
    """``LAT_DEG,LON_DEG,ALT_M`` -> (lat_deg, lon_deg, alt_m), checked."""
    parts = str(text).split(",")
    try:
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"{option} {text!r}: expected LAT_DEG,LON_DEG,ALT_M (three numbers)") from None
    if not all(math.isfinite(v) for v in (lat, lon, alt)):
        raise InputError(f"{option} {text!r}: values must be finite")
    if not -90.0 <= lat <= 90.0:
        raise InputError(f"{option}: latitude {lat:g} deg is outside [-90, 90]")
    if not -180.0 <= lon <= 360.0:
        raise InputError(f"{option}: longitude {lon:g} deg is outside [-180, 360]")
    if not -1.2e4 <= alt <= 1e8:
        raise InputError(f"{option}: altitude {alt:g} m is outside [-12000, 1e8]")
    return lat, lon, alt


def parse_velocity(text, option="--velocity-enu-mps", max_mps=1000.0):
    """``VE,VN,VU`` [m/s] -> ndarray (3,), finite and at most ``max_mps`` in speed."""
    try:
        vel = np.array([float(p) for p in str(text).split(",")])
    except ValueError:
        raise InputError(f"{option} {text!r}: expected VE,VN,VU in m/s (three numbers)") from None
    if vel.shape != (3,) or not np.all(np.isfinite(vel)):
        raise InputError(f"{option} {text!r}: expected VE,VN,VU in m/s (three finite numbers)")
    if np.linalg.norm(vel) > max_mps:
        raise InputError(f"{option} {text!r}: speed {np.linalg.norm(vel):g} m/s exceeds {max_mps:g} m/s")
    return vel


def parse_span(text, option):
    """``START_S,DURATION_S`` -> (start_s, duration_s), start >= 0 and duration > 0."""
    try:
        start, duration = (float(x) for x in text.split(","))
    except ValueError:
        raise InputError(f"{option} {text!r}: expected START_S,DURATION_S") from None
    if not (math.isfinite(start) and math.isfinite(duration) and start >= 0 and duration > 0):
        raise InputError(f"{option} {text!r}: START_S must be >= 0 and DURATION_S > 0")
    return start, duration


def parse_time(text, option="--start"):
    """ISO 8601 UTC text -> datetime64[ns]."""
    return np.datetime64(parse_utc(text, name=option), "ns")


def positive(value, option):
    """``value`` if finite and > 0, else InputError naming ``option``."""
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{option} {value:g}: must be a positive number")
    return value


def add_raw_options(parser):
    """The raw-file options of every command that reads IQ recordings (:func:`open_recording`)."""
    raw = parser.add_argument_group("raw files (a gqrx file name supplies them)")
    raw.add_argument("--dtype", choices=("cf32", "ci16", "ci8", "cu8"),
                     help="sample format of a raw file (ci8: HackRF, cu8: RTL-SDR)")
    raw.add_argument("--sample-rate-hz", type=float, help="sample rate of a raw file")
    raw.add_argument("--center-hz", type=float, help="RF frequency of the comb's central tone (raw file)")
    raw.add_argument("--start", metavar="ISO", help="UTC of the first sample (raw file)")


def open_recording(args, path):
    """``path`` as a SigMF recording, or as a raw file with :func:`add_raw_options`' values."""
    from pathlib import Path

    from ..signal.iq import open_raw, open_sigmf

    path = Path(path)
    if path.suffix in (".sigmf-meta", ".sigmf-data"):
        return open_sigmf(path)
    if args.center_hz is not None:
        positive(args.center_hz, "--center-hz")
    return open_raw(path, dtype=args.dtype, sample_rate_hz=args.sample_rate_hz, center_hz=args.center_hz,
                    start=args.start)


def mask_deg(value, option="--mask-deg"):
    """Elevation mask checked to lie in [0, 90)."""
    if not (math.isfinite(value) and 0.0 <= value < 90.0):
        raise InputError(f"{option} {value:g}: elevation mask must be in [0, 90) deg")
    return value


def warn_stale(const, start, what="start"):
    """Warn when ``start`` is more than :data:`STALE_DAYS` from every element-set epoch of ``const``."""
    age_days = np.abs(seconds_since(const.epochs_utc, start)).min() / DAY_S
    if age_days > STALE_DAYS:
        warnings.warn(f"{what} {format_utc(start)} is {age_days:.0f} days from the nearest element-set epoch; "
                      "positions will be off by many kilometres", stacklevel=3)
