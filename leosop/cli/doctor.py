"""``leosop doctor``: what a recording's front end did, before anything else is tried.

Datatype and full-scale use, clipping, DC offset, IQ imbalance, interferers,
noise floor, the strongest combs, a rough LO offset and the number of usable
satellites (:func:`leosop.signal.survey.survey`); ``--out`` writes
``doctor.json`` and ``spectrum.png`` (a block's spectrum with the findings
marked).
"""

import sys
from pathlib import Path

from ..fileio import atomic_outputs, write_json
from . import add_command
from .options import add_raw_options, open_recording

_SPECTRUM = "spectrum"


def register(subparsers):
    p = add_command(subparsers, "doctor", sys.modules[__name__],
                    help="say what a recording's front end did: clipping, DC, IQ imbalance, interferers, noise, "
                         "combs, LO offset")
    p.add_argument("recording", metavar="REC", help="REC.sigmf-meta, or a raw file with --dtype")
    p.add_argument("--lo-offset-hz", type=float, metavar="HZ",
                   help="the receiver's LO offset as known (the band is checked to hold the combs there); "
                        "default: searched over the whole band and estimated roughly")
    p.add_argument("--blocks", type=int, default=5, help="blocks of 0.1 s examined (default 5)")
    add_raw_options(p)


def run(args):
    from ..errors import InputError
    from ..signal.survey import survey

    if not 1 <= args.blocks <= 100:
        raise InputError(f"--blocks {args.blocks}: must be in [1, 100]")
    rec = open_recording(args, args.recording)
    doc = survey(rec, lo_offset_hz=args.lo_offset_hz, n_blocks=args.blocks)
    spectrum = doc.pop(_SPECTRUM)
    doc["block_s"] = 0.1
    if args.out:
        from ..plots.spectra import plot_survey

        with atomic_outputs(args.out) as stage:
            write_json(stage / "doctor.json", doc)
            plot_survey(stage / "spectrum.png", dict(doc, spectrum=spectrum),
                        title=f"{Path(doc['recording']).name}: spectrum at t = {spectrum['t_s']:.2f} s "
                              f"({doc['datatype']}, {doc['sample_rate_hz'] / 1e6:g} MS/s)")
    return doc


def _fmt(value, spec, unit, none="n/a"):
    return none if value is None else f"{format(value, spec)}{unit}"


def summary(doc):
    lines = [f"{doc['recording']}: {doc['datatype']}{' from ' + doc['hw'] if doc['hw'] else ''}, "
             f"{doc['sample_rate_hz'] / 1e6:g} MS/s, {doc['duration_s']:.3g} s in {doc['n_captures']} capture(s); "
             f"{doc['n_blocks']} blocks of {doc['block_s']:g} s examined",
             f"  level: RMS {_fmt(doc['rms_dbfs'], '.1f', ' dBFS')}, peak {_fmt(doc['peak_dbfs'], '.1f', ' dBFS')}, "
             f"clipped {_fmt(None if doc['clipped_fraction'] is None else 100 * doc['clipped_fraction'], '.2g', ' %')}"
             f", noise {_fmt(doc['n0_dbfs_per_hz'], '.1f', ' dBFS/Hz')}",
             f"  DC {_fmt(doc['dc_dbhz'], '.1f', ' dB-Hz')}; IQ imbalance {_fmt(doc['iq_gain_db'], '+.2f', ' dB')} / "
             f"{_fmt(doc['iq_phase_deg'], '+.2f', ' deg')} (image rejection "
             f"{_fmt(doc['image_rejection_db'], '.0f', ' dB')})"]
    for ln in doc["interferers"][:5]:
        lines.append(f"  interferer {ln['frequency_hz'] / 1e3:+.2f} kHz, {ln['power_dbhz']:.1f} dB-Hz")
    for c in doc["strongest_combs"][:5]:
        lines.append(f"  comb Doppler {c['doppler_hz']:+.1f} Hz, rate {c['doppler_rate_hz_per_s']:+.0f} Hz/s, "
                     f"C/N0 {c['cn0_dbhz']:.1f} dB-Hz, sigma {c['sigma_hz']:.2g} Hz")
    lo = (f"stated {doc['lo_offset_hz_stated']:+.0f} Hz" if doc["lo_offset_hz_stated"] is not None
          else f"rough {_fmt(doc['lo_offset_hz_rough'], '+.0f', ' Hz')}")
    lines.append(f"  usable satellites per block: {doc['usable_satellites']}; LO offset {lo} ({doc['lo_offset_note']})")
    lines += [f"  finding: {f}" for f in doc["findings"]] or ["  no front-end problem found"]
    return "\n".join(lines)
