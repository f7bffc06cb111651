"""ANTEX 1.4 antenna calibrations: phase-centre offsets (PCO) and non-azimuthal variations (PCV).

Receiver antennas are found by their 20-character ``TYPE / SERIAL NO``
field (antenna and radome, as the RINEX header ``ANT # / TYPE`` writes it),
satellites by PRN and the block whose ``VALID FROM`` / ``VALID UNTIL``
covers the day. Offsets of receivers are north, east, up from the antenna
reference point; of satellites x, y, z in the satellite body frame (the
file's ``NORTH / EAST / UP`` columns, as the format defines them for
satellites). ``NOAZI`` rows are the variations against the zenith (receiver)
or nadir (satellite) angle; azimuth-dependent rows are not read. A
frequency missing from a receiver block takes the GPS L1 / L2 values, the
IGS convention (``E01`` from ``G01``, ``E05`` from ``G02``).

Strict, not silent (:func:`check_antex`): a receiver antenna without a
calibration is a warning with what it does to the height (the receiver
correction is then zero); a block from another frame than the clock
product's ``SYS / PCVS APPLIED`` (``SINEX CODE`` ``IGS20_2417`` against
``igs14_2108.atx``) is named, and such satellites are left out of
ambiguity fixing; satellites without a block valid on the day are named and
left out of the solution (:func:`antenna_corrections_if`). Antenna names are
matched on antenna and radome (``NONE`` when absent), whatever the spacing.

Use in the ionosphere-free range (``leosop.gnss.ppp``): ``rho`` from the
satellite's antenna phase centre (centre of mass plus the body-frame
offset) to the receiver's (reference point plus the offset), plus the
receiver's ``PCV(zenith)``; both combined over the two frequencies as the
observations are.
"""

import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .models import satellite_axes
from .rinex import read_text

__all__ = ["Antenna", "Antex", "antenna_corrections_if", "antenna_key", "check_antex", "read_antex"]

#: Receiver frequencies standing in for a missing one (the IGS convention).
_FALLBACK = {"E01": "G01", "E05": "G02", "E07": "G02", "E08": "G02", "E06": "G02"}


@dataclass
class Antenna:
    """One antenna block.

    Attributes
    ----------
    pco_m : dict of str -> ndarray, shape (3,)
        Offset per ANTEX frequency code (``G01``): north, east, up (receiver)
        or body x, y, z (satellite), metres.
    zen_deg : ndarray, shape (n_zen,)
        Zenith (receiver) or nadir (satellite) angles of the ``NOAZI`` rows.
    pcv_m : dict of str -> ndarray, shape (n_zen,)
        ``NOAZI`` variations per frequency (zeros when the block has none).
    valid_from, valid_until : numpy.datetime64
        Validity (satellites; open ends are the extreme dates).
    sinex_code : str
        ``SINEX CODE`` (``IGS14_2247``: frame and model week), empty when absent.
    """

    pco_m: dict = field(default_factory=dict)
    zen_deg: np.ndarray = field(default_factory=lambda: np.zeros(1))
    pcv_m: dict = field(default_factory=dict)
    valid_from: np.datetime64 = field(default_factory=lambda: np.datetime64("1900-01-01"))
    valid_until: np.datetime64 = field(default_factory=lambda: np.datetime64("2200-01-01"))
    sinex_code: str = ""

    def pco_pcv(self, freq, *, receiver):
        """Offset (3,) and variation row (n_zen,) of ``freq``; a receiver may fall back to GPS L1/L2."""
        code = freq if freq in self.pco_m or not receiver else _FALLBACK.get(freq, freq)
        if code not in self.pco_m:
            return None
        return self.pco_m[code], self.pcv_m.get(code, np.zeros_like(self.zen_deg))


@dataclass
class Antex:
    """Antenna blocks of one ANTEX file: ``receivers`` by type, ``satellites`` by PRN (several blocks each)."""

    path: str
    receivers: dict
    satellites: dict

    def satellite(self, prn, day):
        """The block of ``prn`` valid on ``day`` (datetime64), or None."""
        for ant in self.satellites.get(prn, []):
            if ant.valid_from <= day < ant.valid_until:
                return ant
        return None

    def receiver(self, antenna_type):
        """The block of ``antenna_type`` (``"ASH701945E_M    SCIS"``, any spacing), or None."""
        return self.receivers.get(antenna_key(antenna_type))


def antenna_key(name):
    """``"ANTENNA RADOME"`` from a 20-character type field or a loosely spaced one (radome ``NONE`` if absent)."""
    words = name.split()
    if not words:
        return ""
    return f"{words[0]} {words[1] if len(words) > 1 else 'NONE'}"


def _frame(code):
    """Frame of a SINEX code or ANTEX file name (``IGS14_2247``, ``igs14_2108.atx`` -> ``IGS14``), or ''."""
    m = re.match(r"([A-Za-z]+\d\d)_\d{4}", code.strip())
    return m.group(1).upper() if m else ""


def check_antex(antex, antenna_type, sv, day, pcvs_applied):
    """What the ANTEX file leaves unmodelled or inconsistent for one run: warnings and satellites not to fix.

    Parameters
    ----------
    antex : Antex
    antenna_type : str
        RINEX ``ANT # / TYPE``.
    sv : list of str
        Observed satellites.
    day : numpy.datetime64
    pcvs_applied : str
        ANTEX file named by the clock product's ``SYS / PCVS APPLIED`` ('' if none).

    Returns
    -------
    messages : list of str
        One line each (the caller shows them as warnings).
    no_ar : dict of str -> str
        Satellites whose block is of another frame than the clocks', with the reason.

    Raises
    ------
    InputError
        No observed satellite has a block valid on ``day`` (an ANTEX file of other dates): every satellite
        would be left out of the solution.
    """
    if sv and not any(antex.satellite(s, day) is not None for s in sv):
        blocks = [b for s in sv for b in antex.satellites.get(s, [])]
        until = max((b.valid_until for b in blocks), default=None)
        span = (f"its blocks of these satellites are valid from {min(b.valid_from for b in blocks)}"
                + (f" until {until}" if until < Antenna().valid_until else "") if blocks
                else "it has no block of these satellites")
        raise InputError(f"{antex.path}: no satellite block valid on {day} for the {len(sv)} observed satellites "
                         f"(VALID FROM / VALID UNTIL; {span}): give the ANTEX file of the data's day")
    messages, no_ar = [], {}
    rx = antex.receiver(antenna_type)
    clk_frame = _frame(pcvs_applied)
    if rx is None:
        messages.append(f"{antex.path}: no calibration for the receiver antenna {antenna_type.strip()!r} (RINEX "
                        f"ANT # / TYPE; the file has {', '.join(sorted(antex.receivers)) or 'none'}): the heights "
                        "are of its ionosphere-free phase centre, off by that offset (several centimetres for "
                        "geodetic antennas, 4.3 cm for the ASH701945E_M) and by its variations")
    elif clk_frame and _frame(rx.sinex_code) != clk_frame:
        messages.append(f"{antex.path}: receiver antenna {antenna_key(antenna_type)!r} is a "
                        f"{rx.sinex_code or 'frame-less'} calibration, the clocks were made with {pcvs_applied}: "
                        "millimetres to a centimetre of height may differ")
    if not clk_frame:
        messages.append(f"{antex.path}: the clock file names no SYS / PCVS APPLIED: the frame of the satellite "
                        "antenna offsets cannot be checked against the clocks'")
        return messages, no_ar
    for s in sv:
        sat = antex.satellite(s, day)
        if sat is not None and _frame(sat.sinex_code) != clk_frame:
            no_ar[s] = f"antenna offsets {sat.sinex_code or 'of no frame'}, clocks {pcvs_applied}"
    if no_ar:
        messages.append(f"{antex.path}: {', '.join(no_ar)}: satellite antenna offsets of another frame than the "
                        f"clocks' ({pcvs_applied}): left out of ambiguity fixing")
    return messages, no_ar


def _date(text, path, lineno):
    try:
        y, mo, d, h, mi = (int(v) for v in text[:30].split()[:5])
        return np.datetime64(f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}")
    except ValueError:
        raise InputError(f"{path}: line {lineno}: expected a date (year month day hour minute)") from None


def read_antex(path):
    """Read an ANTEX 1.4 file (plain or gzip).

    Returns
    -------
    Antex

    Raises
    ------
    InputError
        Not an ANTEX file, or a record that cannot be read (file and line named).
    """
    lines = read_text(path)
    if not lines or "ANTEX VERSION / SYST" not in lines[0][60:]:
        raise InputError(f"{path}: line 1: not an ANTEX file (no ANTEX VERSION / SYST)")
    receivers, satellites = {}, {}
    ant, freq, name, prn, start = None, None, "", "", 0
    for lineno, line in enumerate(lines, 1):
        label, text = line[60:].strip(), line[:60]
        try:
            if label == "START OF ANTENNA":
                if ant is not None:
                    raise InputError(f"{path}: line {lineno}: START OF ANTENNA inside the block of line {start} "
                                     "(no END OF ANTENNA)")
                ant, freq, start = Antenna(), None, lineno
            elif ant is None:
                continue
            elif label == "TYPE / SERIAL NO":
                name, prn = antenna_key(text[:20]), text[20:40].strip()
            elif label == "SINEX CODE":
                ant.sinex_code = text[:10].strip()
            elif label == "ZEN1 / ZEN2 / DZEN":
                z1, z2, dz = (float(v) for v in text.split()[:3])
                ant.zen_deg = np.arange(z1, z2 + 0.5 * dz, dz)
            elif label in ("VALID FROM", "VALID UNTIL"):
                setattr(ant, "valid_from" if label == "VALID FROM" else "valid_until", _date(text, path, lineno))
            elif label == "START OF FREQUENCY":
                freq = text.split()[0]
            elif label == "NORTH / EAST / UP":
                ant.pco_m[freq] = np.array([float(v) for v in text.split()[:3]]) * 1e-3
            elif label == "END OF FREQUENCY":
                freq = None
            elif label == "END OF ANTENNA":
                is_sat = len(prn) == 3 and prn[0].isalpha() and prn[1:].isdigit()
                if is_sat:
                    satellites.setdefault(prn, []).append(ant)
                else:
                    receivers[name] = ant
                ant = None
            elif freq is not None and line[3:8].strip() == "NOAZI":
                vals = np.array([float(v) for v in line[8:].split()]) * 1e-3
                if len(vals) != len(ant.zen_deg):
                    raise InputError(f"{path}: line {lineno}: NOAZI has {len(vals)} values, ZEN1 / ZEN2 / DZEN "
                                     f"gives {len(ant.zen_deg)}")
                ant.pcv_m[freq] = vals
        except InputError:
            raise
        except (ValueError, IndexError):
            raise InputError(f"{path}: line {lineno}: cannot read {label or 'the record'}") from None
    if ant is not None:
        raise InputError(f"{path}: line {len(lines)}: the antenna block of line {start} has no END OF ANTENNA "
                         "(truncated file?)")
    return Antex(str(path), receivers, satellites)


def antenna_corrections_if(antex, obs, RS, pos_rx_ecef_m, sun, C_en, elev, freqs_hz):
    """Satellite phase-centre positions and receiver range corrections, ionosphere-free.

    Parameters
    ----------
    antex : Antex
    obs : leosop.gnss.rinex.ObsData
        Its ``sv``, first epoch and ``antenna_type``.
    RS : ndarray, shape (n_epochs, n_sats, 3)
        Satellite centres of mass (ECEF m).
    pos_rx_ecef_m : ndarray, shape (3,)
        A priori receiver position.
    sun : ndarray, shape (n_epochs, 3)
        Sun in ECEF (satellite attitude).
    C_en : ndarray, shape (3, 3)
        ENU axes of the receiver in ECEF (columns).
    elev : ndarray, shape (n_epochs, n_sats)
        Elevations [rad].
    freqs_hz : dict of str -> (float, float)
        The two frequencies per system letter (``G``: L1, L2; ``E``: E1, E5a).

    Returns
    -------
    RS : ndarray, shape (n_epochs, n_sats, 3)
        Satellite antenna phase centres (centre of mass plus the body-frame
        offset; nominal yaw attitude; satellite PCV not applied).
    d_rx_m : ndarray, shape (n_epochs, n_sats)
        To subtract from code and phase: ``-e . PCO + PCV(zenith)`` of the
        receiver antenna (its reference point is what the filter estimates).
    missing : list of str
        Satellites with no block valid on the day (left out).
    rx_calibrated : bool
        False when the receiver antenna has no block (its correction is then zero: :func:`check_antex`).
    """
    day = obs.time_gps[0].astype("datetime64[D]")
    rx = antex.receiver(obs.antenna_type) or Antenna(pco_m={"G01": np.zeros(3), "G02": np.zeros(3)})
    bx, by, bz = satellite_axes(RS, sun)
    RS = RS.copy()
    d_rx = np.full(elev.shape, np.nan)
    missing = []
    for j, s in enumerate(obs.sv):
        if s[0] not in freqs_hz:
            continue
        f1, f2 = freqs_hz[s[0]]
        g1, g2 = f1**2 / (f1**2 - f2**2), f2**2 / (f1**2 - f2**2)
        codes = (f"{s[0]}01", f"{s[0]}02" if s[0] == "G" else f"{s[0]}05")
        sat = antex.satellite(s, day)
        sat_f = None if sat is None else [sat.pco_pcv(c, receiver=False) for c in codes]
        rx_f = [rx.pco_pcv(c, receiver=True) for c in codes]
        if sat_f is None or None in sat_f or None in rx_f:
            missing.append(s)
            continue
        pco_sat = g1 * sat_f[0][0] - g2 * sat_f[1][0]
        RS[:, j] += pco_sat[0] * bx[:, j] + pco_sat[1] * by[:, j] + pco_sat[2] * bz[:, j]
        pco_neu = g1 * rx_f[0][0] - g2 * rx_f[1][0]
        pcv = g1 * rx_f[0][1] - g2 * rx_f[1][1]
        pco_ecef = C_en @ np.array([pco_neu[1], pco_neu[0], pco_neu[2]])
        los = RS[:, j] - pos_rx_ecef_m
        e = los / np.linalg.norm(los, axis=-1, keepdims=True)
        zen = 90.0 - np.degrees(elev[:, j])
        d_rx[:, j] = -e @ pco_ecef + np.interp(zen, rx.zen_deg, pcv)
    return RS, d_rx, missing, antex.receiver(obs.antenna_type) is not None
