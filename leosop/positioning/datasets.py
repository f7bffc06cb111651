"""Readers of public real Doppler data sets into :class:`Measurements`.

Each reader returns measurements in the toolkit's convention (DESIGN 4.3:
Doppler = received minus nominal carrier, positive when approaching) with
the data set's ground truth beside them. The data themselves are not part of
the package; see ``PROVENANCE.md`` in each data folder.

* DopTrack (TU Delft): passes of Delfi-C3 over a station at a known position,
  received carrier frequency every 0.5 s, with the element set used for each
  pass. Read straight from the ``data.tar.xz`` and ``metadata.tar.xz`` archives.
* FOX-1D (AO-92) over the Virginia Tech ground station: one pass, 10 Hz FLL
  Doppler offsets.
* Google Smartphone Decimeter Challenge ``device_gnss.csv``: GNSS pseudorange
  rates with satellite states, turned into L1/E1 (1575.42 MHz) Doppler.
"""

import csv
import lzma
import tarfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..constants import C_MPS, OMEGA_E_RAD_PER_S
from ..errors import InputError
from ..fileio import check_input_file
from ..frames import geodetic_to_ecef
from ..orbits.tle import parse_tle_lines
from ..timebase import parse_utc
from .measurements import Measurements

__all__ = ["DopTrackPass", "read_doptrack", "doptrack_table", "read_fll", "GsdcEpochs", "read_gsdc",
           "DELFI_C3_CARRIER_HZ", "GPS_L1_HZ"]

#: Delfi-C3 telemetry downlink, nominal [Hz]; the transmitter's own offset
#: (about -2 kHz in April 2020) is left to the solver's frequency offset.
DELFI_C3_CARRIER_HZ = 145.870e6
#: GPS L1 / Galileo E1 carrier [Hz].
GPS_L1_HZ = 1575.42e6
#: GSDC signal types on the L1/E1 carrier.
_L1_SIGNALS = ("GPS_L1", "GPS_L1_CA", "GAL_E1", "GAL_E1_C_P", "QZS_J1")


@dataclass(frozen=True, eq=False)
class DopTrackPass:
    """One DopTrack pass.

    Attributes
    ----------
    name : str
        File stem, e.g. ``Delfi-C3_32789_202004011044``.
    meas : Measurements
        Doppler against :data:`DELFI_C3_CARRIER_HZ`, sigma unknown (NaN).
    constellation : Constellation
        The element set used for the pass.
    tle_lines : tuple of str
    station_pos_ecef_m : ndarray, (3,)
    station_lat_deg, station_lon_deg, station_alt_m : float
    fca_hz : float
        DopTrack's estimate of the carrier at closest approach.
    tca_utc : datetime64[ns]
    max_elevation_deg : float
        Predicted maximum elevation of the pass.
    """

    name: str
    meas: Measurements
    constellation: object
    tle_lines: tuple
    station_pos_ecef_m: np.ndarray
    station_lat_deg: float
    station_lon_deg: float
    station_alt_m: float
    fca_hz: float
    tca_utc: np.datetime64
    max_elevation_deg: float


def read_doptrack(folder):
    """All passes of the DopTrack Delfi-C3 archives, sorted by name.

    Parameters
    ----------
    folder : str or Path
        Holds ``data.tar.xz`` (``data/*.csv``) and ``metadata.tar.xz``
        (``metadata/*.yml``).

    Returns
    -------
    list of DopTrackPass
    """
    import yaml  # PyYAML, a dependency of dask

    folder = Path(folder)
    tables, metas = {}, {}
    for archive, suffix, store in (("data.tar.xz", ".csv", tables), ("metadata.tar.xz", ".yml", metas)):
        path = folder / archive
        if not path.is_file():
            raise InputError(f"{path}: no such DopTrack archive")
        try:
            with tarfile.open(path, "r:xz") as tar:
                for member in tar:
                    if member.isfile() and member.name.endswith(suffix):
                        raw = tar.extractfile(member).read()
                        try:
                            store[Path(member.name).stem] = raw.decode("utf-8")
                        except UnicodeDecodeError:
                            raise InputError(f"{path}: {member.name} is not UTF-8 text") from None
        except EOFError:
            raise InputError(f"{path}: truncated: the xz data end before their end-of-stream marker; expected the "
                             f"complete DopTrack archive of {suffix} files") from None
        except (tarfile.TarError, lzma.LZMAError) as exc:
            raise InputError(f"{path}: not an xz-compressed tar archive ({exc}); expected the DopTrack archive of "
                             f"{suffix} files") from None
    passes = []
    for name in sorted(tables):
        if name not in metas:
            raise InputError(f"{folder}: pass {name} has no metadata file")
        try:
            passes.append(_doptrack_pass(folder, name, tables[name], metas[name]))
        except InputError:
            raise
        except (yaml.YAMLError, ValueError, KeyError, TypeError, IndexError) as exc:
            first = " ".join(str(exc).split())[:200]
            raise InputError(f"{folder}: pass {name}: malformed {name}.csv or {name}.yml ({type(exc).__name__}: "
                             f"{first}); expected DopTrack's recording and metadata files") from None
    return passes


def _doptrack_pass(folder, name, table, meta_text):
    """One DopTrack pass from its recording's CSV text and its metadata's YAML text."""
    import yaml

    meta = yaml.safe_load(meta_text)
    data = np.loadtxt(table.splitlines(), delimiter=",", comments="#", ndmin=2)
    epoch = parse_utc(str(meta["tracking"]["epoch"]), name=f"{name}.yml: tracking: epoch")
    time_utc = epoch + np.round(data[:, 0] * 1e9).astype("timedelta64[ns]")
    n = len(data)
    meas = Measurements(
        t_s=data[:, 0] - data[0, 0], time_utc=time_utc, sat_id=np.full(n, str(meta["satellite"]["noradid"])),
        doppler_hz=data[:, 1] - DELFI_C3_CARRIER_HZ, sigma_hz=np.full(n, np.nan),
        carrier_hz=np.full(n, DELFI_C3_CARRIER_HZ), line=np.arange(2, n + 2), source=f"{folder}/{name}.csv",
    )
    tle = (meta["satellite"]["tle"]["line1"], meta["satellite"]["tle"]["line2"])
    site = meta["station"]["position"]
    lat, lon, alt = float(site["latitude"]), float(site["longitude"]), float(site["altitude"])
    return DopTrackPass(
        name=name, meas=meas, constellation=parse_tle_lines(tle, f"{name}.yml"), tle_lines=tle,
        station_pos_ecef_m=geodetic_to_ecef(np.radians(lat), np.radians(lon), alt),
        station_lat_deg=lat, station_lon_deg=lon, station_alt_m=alt,
        fca_hz=float(meta["tracking"]["fca"]),
        tca_utc=parse_utc(str(meta["tracking"]["tca"]), name=f"{name}.yml: tracking: tca"),
        max_elevation_deg=float(meta["prediction"]["max_elevation"]),
    )


def doptrack_table(passes, pos_rx_ecef_m=None):
    """One measurement table of several DopTrack passes, states from each pass's own element set.

    Parameters
    ----------
    passes : list of DopTrackPass
    pos_rx_ecef_m : array_like, (3,), optional
        Receiver position for the light time (none without it: ~0.1 Hz at
        145.87 MHz, 3 ms of a ~30 Hz/s Doppler rate).

    Returns
    -------
    Measurements
        With the satellite state columns and ``pass_id`` the pass name; rows
        whose element set cannot be propagated are dropped into ``rejected``.
    """
    from ..timebase import seconds_since
    from .solve import satellite_states

    parts, rejected = [], []
    for p in passes:
        pos, vel, reason = satellite_states(p.meas, p.constellation, pos_rx_ecef_m)[:3]
        ok = reason == ""
        rejected += [(int(line), f"{p.name}: {r}") for line, r in zip(p.meas.line[~ok], reason[~ok])]
        parts.append((p, ok, pos[ok], vel[ok]))
    if not any(ok.any() for _, ok, _, _ in parts):
        raise InputError(f"{passes[0].meas.source if passes else 'DopTrack'}: no row has a usable element set")
    time_utc = np.concatenate([p.meas.time_utc[ok] for p, ok, _, _ in parts])

    def cat(name):
        return np.concatenate([getattr(p.meas, name)[ok] for p, ok, _, _ in parts])

    return Measurements(t_s=seconds_since(time_utc, time_utc.min()), time_utc=time_utc, sat_id=cat("sat_id"),
                        doppler_hz=cat("doppler_hz"), sigma_hz=cat("sigma_hz"), carrier_hz=cat("carrier_hz"),
                        pos_sv_ecef_m=np.concatenate([pos for _, _, pos, _ in parts]),
                        vel_sv_ecef_mps=np.concatenate([vel for _, _, _, vel in parts]), line=cat("line"),
                        pass_id=np.concatenate([np.full(ok.sum(), p.name) for p, ok, _, _ in parts]),
                        rejected=tuple(rejected), source=f"DopTrack passes ({len(passes)})")


def read_fll(csv_path, sat_id):
    """A GNU Radio frequency-locked-loop Doppler log (``doppler_offset, timestamp, measured_freq`` columns).

    The format of the FOX-1D pass recorded at VTGS (``index, doppler_offset,
    timestamp, measured_freq``): ``doppler_offset`` [Hz] is the received
    minus the nominal carrier, ``timestamp`` ISO 8601 UTC, and the carrier
    of each row is ``measured_freq - doppler_offset``.

    Parameters
    ----------
    csv_path : str or Path
    sat_id : str
        Catalogue number to attach (the log does not name its satellite; for
        FOX-1D the first element sets after launch do not tell 43137 =
        2018-004AC from its neighbours 43135/43136, PROVENANCE.md).

    Returns
    -------
    Measurements
        Sigma unknown (NaN).
    """
    path = Path(csv_path)
    check_input_file(path, "FLL log")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            rows = [(reader.line_num, r) for r in reader]
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file; expected a CSV FLL log") from None
    need = {"doppler_offset", "timestamp", "measured_freq"}
    if not rows or not need <= set(rows[0][1]):
        raise InputError(f"{path}: expected columns {', '.join(sorted(need))} and at least one row")
    n = len(rows)
    time_utc = np.empty(n, dtype="datetime64[ns]")
    doppler, freq = np.empty(n), np.empty(n)
    for k, (line, r) in enumerate(rows):
        for key in ("timestamp", "doppler_offset", "measured_freq"):
            if r[key] is None:
                raise InputError(f"{path}:{line}: no {key} field: the line ends early (cut off?), expected the "
                                 f"header's {len(reader.fieldnames)} fields")
        time_utc[k] = parse_utc(r["timestamp"], name=f"{path}:{line}: timestamp")
        for key, out in (("doppler_offset", doppler), ("measured_freq", freq)):
            try:
                out[k] = float(r[key])
            except ValueError:
                raise InputError(f"{path}:{line}: {key} {r[key]!r} is not a number") from None
    carrier = freq - doppler
    bad = np.flatnonzero(~(np.isfinite(doppler) & (carrier > 0)))
    if bad.size:
        line, r = rows[bad[0]]
        raise InputError(f"{path}:{line}: doppler_offset {r['doppler_offset']!r} and measured_freq "
                         f"{r['measured_freq']!r}: the offset must be finite and the frequency less it positive "
                         f"({bad.size} such row(s))")
    return Measurements(
        t_s=(time_utc - time_utc[0]).astype(np.int64) * 1e-9, time_utc=time_utc, sat_id=np.full(n, str(sat_id)),
        doppler_hz=doppler, sigma_hz=np.full(n, np.nan), carrier_hz=carrier,
        line=np.array([line for line, _ in rows]), source=str(path),
    )


@dataclass(frozen=True, eq=False)
class GsdcEpochs:
    """GSDC L1/E1 Doppler with the phone's own clock drift.

    Attributes
    ----------
    meas : Measurements
        Satellite states rotated into the ECEF frame of reception.
    clock_drift_hz : ndarray, (n,)
        ``-DriftNanosPerSecond * 1e-9 * f``: the frequency offset the
        receiver's clock drift puts on an L1 Doppler (the chipset's estimate).
    """

    meas: Measurements
    clock_drift_hz: np.ndarray


def read_gsdc(device_gnss_csv):
    """GSDC ``device_gnss.csv`` rows on 1575.42 MHz as Doppler measurements.

    Doppler is ``-(PseudorangeRate + SvClockDrift) * f / c``: the satellite
    clock drift is removed, the receiver's stays in (the solver's frequency
    offset). Satellite positions are given at transmit time in the ECEF
    frame of that time; they are turned by ``omega_e * tau`` (tau from the
    raw pseudorange) into the frame of reception, as DESIGN 4.3 expects.

    Parameters
    ----------
    device_gnss_csv : str or Path

    Returns
    -------
    GsdcEpochs
    """
    path = Path(device_gnss_csv)
    with open(path, newline="", encoding="utf-8-sig") as fh:
        numbered = [(k + 2, r) for k, r in enumerate(csv.DictReader(fh)) if r.get("SignalType", "") in _L1_SIGNALS]
    rows = [r for _, r in numbered]
    need = ("utcTimeMillis", "Svid", "ConstellationType", "PseudorangeRateMetersPerSecond",
            "PseudorangeRateUncertaintyMetersPerSecond", "SvClockDriftMetersPerSecond", "RawPseudorangeMeters",
            "DriftNanosPerSecond", *(f"SvPosition{a}EcefMeters" for a in "XYZ"),
            *(f"SvVelocity{a}EcefMetersPerSecond" for a in "XYZ"))
    if not rows:
        raise InputError(f"{path}: no GPS L1 / Galileo E1 rows")
    missing = [k for k in need if k not in rows[0]]
    if missing:
        raise InputError(f"{path}: missing column {missing[0]}")
    num = lambda key: np.array([float(r[key]) if r[key] else np.nan for r in rows])  # noqa: E731
    prr = num("PseudorangeRateMetersPerSecond") + num("SvClockDriftMetersPerSecond")
    pos = np.stack([num(f"SvPosition{a}EcefMeters") for a in "XYZ"], -1)
    vel = np.stack([num(f"SvVelocity{a}EcefMetersPerSecond") for a in "XYZ"], -1)
    angle = OMEGA_E_RAD_PER_S * num("RawPseudorangeMeters") / C_MPS
    c, s = np.cos(angle), np.sin(angle)
    rot = lambda v: np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]], -1)  # noqa: E731
    time_utc = np.array([int(r["utcTimeMillis"]) for r in rows]).astype("datetime64[ms]").astype("datetime64[ns]")
    n = len(rows)
    sat_id = np.array([f"{r['ConstellationType']}-{r['Svid']}" for r in rows])
    meas = Measurements(
        t_s=(time_utc - time_utc.min()).astype(np.int64) * 1e-9, time_utc=time_utc, sat_id=sat_id,
        doppler_hz=-prr * GPS_L1_HZ / C_MPS,
        sigma_hz=num("PseudorangeRateUncertaintyMetersPerSecond") * GPS_L1_HZ / C_MPS,
        carrier_hz=np.full(n, GPS_L1_HZ), pos_sv_ecef_m=rot(pos), vel_sv_ecef_mps=rot(vel),
        line=np.array([k for k, _ in numbered]), source=str(path),
    )
    return GsdcEpochs(meas, -num("DriftNanosPerSecond") * 1e-9 * GPS_L1_HZ)
