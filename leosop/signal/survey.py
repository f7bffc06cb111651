"""What a recording's front end did and which combs it holds: the findings of ``leosop doctor``.

A few blocks spread over the recording (the first of each capture, up to
``n_blocks``) are read and examined:

- format: datatype, the recorder's hardware (``core:hw``), RMS and peak of a
  component against the format's full scale, the fraction of I/Q values
  clipped at its extremes (counted on the file's own integers);
- front end (:func:`~.cleaning.clean_block`): DC offset, IQ imbalance and
  the image rejection it leaves, CW / narrowband interferers (frequency,
  power in dB-Hz, the unit of a pilot tone's C/N0), the noise density;
- combs (:func:`~.multicomb.find_combs` on the cleaned blocks): the
  strongest, and how many a block holds with a usable sigma.

The receiver's LO offset is common to every satellite and adds to each one's
Doppler: without knowing which satellites these are (identification, ``leosop
replay``) it cannot be told apart from the Doppler. The rough estimate here is
the median of the combs' Dopplers, whose geometric parts, approaching and
receding satellites alike, spread some +-200 kHz around zero: good to
~100 kHz with a handful of combs, enough to centre the search and the tone
model (:meth:`~.pilot.PilotComb.through_lo`), not for navigation.
"""

import numpy as np

from ..errors import InputError
from .coarse import MAX_DOPPLER_HZ
from .cleaning import clean_block
from .comb_fit import fit_kernel
from .frontend import image_rejection_db
from .iq import DATATYPES, FULL_SCALE
from .multicomb import find_combs
from .pilot import PilotComb

__all__ = ["check_band", "survey", "USABLE_SIGMA_HZ"]

#: A comb whose Doppler sigma in one block is below this counts as usable for navigation [Hz]
#: (a few cm/s of range rate at 11.3 GHz).
USABLE_SIGMA_HZ = 1.0
#: Fraction of clipped I/Q values worth a finding.
_CLIP_FINDING = 1e-4
#: Interferers weaker than this [dB-Hz] are not worth a finding (a pilot tone is ~35-50 dB-Hz).
_LINE_FINDING_DBHZ = 30.0


def check_band(sample_rate_hz, comb, lo_offset_hz, max_doppler_hz, where):
    """Refuse a band that cannot hold the combs at the stated LO offset (one-line InputError naming ``where``)."""
    reach = abs(float(lo_offset_hz)) + float(max_doppler_hz) + float(comb.offsets_hz.max())
    if reach >= 0.5 * sample_rate_hz:
        raise InputError(f"{where}: at an LO offset of {lo_offset_hz:+.0f} Hz the combs (+-{comb.offsets_hz.max():.0f} "
                         f"Hz) with +-{max_doppler_hz:.0f} Hz of Doppler reach {reach:.0f} Hz from the centre, beyond "
                         f"the recording's band (+-{0.5 * sample_rate_hz:.0f} Hz at {sample_rate_hz:g} samples/s)")


def _blocks(rec, block_len, n_blocks):
    """Start sample of up to ``n_blocks`` blocks: the first of each capture, then evenly spread."""
    starts = [c.sample_start for c in rec.captures if c.n_samples >= block_len]
    if not starts:
        raise InputError(f"{rec.data_path}: no capture holds a block of {block_len} samples")
    if len(starts) >= n_blocks:
        return [starts[i] for i in np.linspace(0, len(starts) - 1, n_blocks).round().astype(int)]
    cap = max(rec.captures, key=lambda c: c.n_samples)
    more = np.linspace(cap.sample_start, cap.sample_start + cap.n_samples - block_len, n_blocks - len(starts) + 1)
    return sorted(set(starts) | {int(s) for s in more.round()})[:n_blocks]


def _clipped(raw, datatype):
    """Fraction of the stored I/Q values at the format's extremes (None for floats)."""
    comp = DATATYPES[datatype][0]
    if comp.kind == "f":
        return None
    info = np.iinfo(comp)
    return float(np.count_nonzero((raw == info.min) | (raw == info.max)) / max(raw.size, 1))


def _db(x):
    return float(10.0 * np.log10(x)) if x > 0 else None


def survey(rec, *, lo_offset_hz=None, max_doppler_hz=MAX_DOPPLER_HZ, block_s=0.1, n_blocks=5):
    """Findings on a recording's front end and combs (the document of ``leosop doctor``).

    Parameters
    ----------
    rec : Recording
    lo_offset_hz : float, optional
        The LO offset as the user knows it; the band is checked to hold the
        combs there. None: the whole band is searched and a rough offset
        estimated (module docstring).
    max_doppler_hz : float
        Doppler half-width around the stated offset.
    block_s : float
    n_blocks : int

    Returns
    -------
    dict
        JSON-ready; ``blocks`` holds each block's findings, and ``spectrum``
        (not JSON: ``frequency_hz``, ``power_db`` over the noise per bin of
        the first block) feeds the figure.
    """
    fs = rec.sample_rate_hz
    comb = PilotComb(carrier_hz=rec.center_hz or PilotComb.carrier_hz, n_tones=rec.n_tones,
                     tone_spacing_hz=rec.tone_spacing_hz)
    half = float(comb.offsets_hz.max())
    if lo_offset_hz is not None:
        check_band(fs, comb, lo_offset_hz, max_doppler_hz, str(rec.data_path))
        search = float(max_doppler_hz)
    else:
        search = 0.5 * fs - half - 0.02 * fs  # the whole band, a margin for the comb's smear
        if search <= 0:
            raise InputError(f"{rec.data_path}: a band of {fs:g} samples/s cannot hold a comb of +-{half:.0f} Hz")
    block_len = int(round(block_s * fs))
    starts = _blocks(rec, block_len, n_blocks)
    blocks, cleaned, raw_stats = [], [], []
    kernel = fit_kernel(len(starts))
    for s in starts:
        raw = np.asarray(rec.read_raw(s, block_len))
        x = rec.read(s, block_len)
        y, c = clean_block(x, fs, comb, kernel=kernel)
        cleaned.append((s, y, c))
        rms = float(np.sqrt(np.mean(np.abs(x) ** 2) / 2.0))
        peak = float(np.max(np.abs(x.view(np.float32))))
        raw_stats.append((rms, peak, _clipped(raw, rec.datatype)))
    # Pass 1 at the stated offset (or 0 over the whole band); without a stated offset a second pass at
    # the rough estimate, whose tone model fits the combs better.
    lo = 0.0 if lo_offset_hz is None else float(lo_offset_hz)
    found = [find_combs(y, fs, comb=comb, lo_offset_hz=lo, max_doppler_hz=search, clean=False, kernel=kernel)
             for _, y, _ in cleaned]
    lo_rough = None
    all_d = np.concatenate([f.doppler_hz for f in found])
    if lo_offset_hz is None and all_d.size:
        lo_rough = float(np.median(all_d))
        span = min(search, 0.5 * fs - half - abs(lo_rough) - 0.02 * fs)
        if span > 0:
            found = [find_combs(y, fs, comb=comb, lo_offset_hz=lo_rough, max_doppler_hz=span, clean=False,
                                  kernel=kernel)
                     for _, y, _ in cleaned]
            lo_rough = float(np.median(np.concatenate([f.doppler_hz for f in found]) if found else all_d))
    full = FULL_SCALE.get(rec.datatype)
    for (s, _, c), f, (rms, peak, clip) in zip(cleaned, found, raw_stats):
        order = np.argsort(-f.cn0_dbhz)
        blocks.append({
            "t_s": (s + 0.5 * (block_len - 1)) / fs,
            "rms_dbfs": None if full is None else _db((rms / full) ** 2),
            "peak_dbfs": None if full is None else _db((peak / full) ** 2),
            "clipped_fraction": clip,
            "dc_dbhz": c.dc_dbhz if np.isfinite(c.dc_dbhz) else None,
            "iq_gain_db": c.iq_gain_db, "iq_phase_deg": c.iq_phase_deg,
            "interferers": [{"frequency_hz": ln.frequency_hz, "power_dbhz": ln.power_dbhz} for ln in c.lines],
            "n0_dbfs_per_hz": _db(c.noise_density / (full or 1.0) ** 2),
            "combs": [{"doppler_hz": float(f.doppler_hz[i]), "doppler_rate_hz_per_s": float(f.doppler_rate_hz_per_s[i]),
                       "cn0_dbhz": float(f.cn0_dbhz[i]), "sigma_hz": float(f.sigma_hz[i])} for i in order],
            "n_usable": int(np.sum(f.sigma_hz < USABLE_SIGMA_HZ)),
        })
    doc = _summarise(rec, blocks, lo_offset_hz, lo_rough)
    x0 = rec.read(cleaned[0][0], block_len)
    power = np.abs(np.fft.fftshift(np.fft.fft(x0))) ** 2
    n0 = cleaned[0][2].noise_density
    doc["spectrum"] = {"frequency_hz": np.fft.fftshift(np.fft.fftfreq(block_len, 1.0 / fs)),
                       # |X|^2 of white noise is n N0 fs per bin: 0 dB is the noise density
                       "power_db": 10.0 * np.log10(np.maximum(power, 1e-30) / (n0 * block_len * fs))
                       if n0 > 0 else np.zeros(block_len), "t_s": blocks[0]["t_s"], "comb": comb}
    return doc


def _summarise(rec, blocks, lo_stated, lo_rough):
    """The recording-level findings from the blocks' (medians; worst case for clipping)."""
    def med(key):
        vals = [b[key] for b in blocks if b[key] is not None]
        return float(np.median(vals)) if vals else None

    gain, phase = med("iq_gain_db"), med("iq_phase_deg")
    clip = [b["clipped_fraction"] for b in blocks if b["clipped_fraction"] is not None]
    lines = {}
    for b in blocks:
        for ln in b["interferers"]:
            key = round(ln["frequency_hz"] / 100.0)  # the same line in several blocks
            if key not in lines or ln["power_dbhz"] > lines[key]["power_dbhz"]:
                lines[key] = ln
    interferers = sorted(lines.values(), key=lambda ln: -ln["power_dbhz"])
    combs = sorted((c for b in blocks[:1] for c in b["combs"]), key=lambda c: -c["cn0_dbhz"])
    usable = [b["n_usable"] for b in blocks]
    doc = {
        "recording": str(rec.data_path.with_suffix(".sigmf-meta") if rec.data_path.suffix == ".sigmf-data"
                         else rec.data_path),
        "datatype": rec.datatype, "hw": rec.hw, "sample_rate_hz": rec.sample_rate_hz, "center_hz": rec.center_hz,
        "duration_s": rec.duration_s, "n_captures": len(rec.captures), "n_blocks": len(blocks),
        "block_s": None,
        "rms_dbfs": med("rms_dbfs"), "peak_dbfs": max((b["peak_dbfs"] for b in blocks if b["peak_dbfs"] is not None),
                                                      default=None),
        "clipped_fraction": max(clip) if clip else None,
        "dc_dbhz": med("dc_dbhz"),
        "iq_gain_db": gain, "iq_phase_deg": phase,
        "image_rejection_db": None if gain is None else float(min(image_rejection_db(gain, phase), 99.0)),
        "interferers": interferers,
        "n0_dbfs_per_hz": med("n0_dbfs_per_hz"),
        "strongest_combs": combs[:10],
        "usable_satellites": int(np.median(usable)) if usable else 0,
        "lo_offset_hz_stated": lo_stated,
        "lo_offset_hz_rough": lo_rough,
        "lo_offset_note": ("the receiver's LO offset adds to every satellite's Doppler and cannot be told apart from "
                           "it without identifying the satellites (leosop replay); the rough value is the median of "
                           "the combs' Dopplers, good to ~100 kHz"),
        "blocks": blocks,
    }
    doc["findings"] = _findings(doc)
    doc["status"] = "ok" if not doc["findings"] else "warnings"
    return doc


def _findings(doc):
    """One sentence per thing the user should know or fix."""
    out = []
    if doc["clipped_fraction"] is not None and doc["clipped_fraction"] > _CLIP_FINDING:
        out.append(f"{100 * doc['clipped_fraction']:.2g} % of the I/Q values are clipped at full scale: lower the gain")
    if doc["rms_dbfs"] is not None and doc["rms_dbfs"] < -40.0:
        out.append(f"the signal uses little of the {doc['datatype']} range (RMS {doc['rms_dbfs']:.0f} dBFS): "
                   "raise the gain")
    if doc["dc_dbhz"] is not None and doc["dc_dbhz"] > _LINE_FINDING_DBHZ:
        out.append(f"DC offset of {doc['dc_dbhz']:.0f} dB-Hz (removed per block)")
    if doc["image_rejection_db"] is not None and doc["image_rejection_db"] < 40.0:
        out.append(f"IQ imbalance {doc['iq_gain_db']:+.2f} dB / {doc['iq_phase_deg']:+.2f} deg: images "
                   f"{doc['image_rejection_db']:.0f} dB below each line (corrected per block)")
    for ln in doc["interferers"]:
        if ln["power_dbhz"] > _LINE_FINDING_DBHZ:
            out.append(f"interferer at {ln['frequency_hz'] / 1e3:+.1f} kHz, {ln['power_dbhz']:.0f} dB-Hz (excised)")
    if doc["usable_satellites"] == 0:
        out.append("no usable pilot comb found")
    return out
