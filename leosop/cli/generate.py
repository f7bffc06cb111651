"""``leosop generate``: a SigMF recording of Starlink pilot combs as received at a site.

The satellites above the mask at the start (or ``--sat`` IDs) are propagated
with SGP4; each one's comb follows its range at every sample (DESIGN 4.2),
with a per-satellite clock offset drawn uniformly in [0, --sat-offset-max-hz]
(seed 004 Table 1: 0-5 Hz) plus the receiver's offset. The truth (Doppler at
each block centre, its rate, satellite id) goes into the SigMF annotations.
"""

import sys
from pathlib import Path

import numpy as np

from ..constants import STARLINK_N_TONES, STARLINK_PILOT_HZ, STARLINK_TONE_SPACING_HZ
from ..errors import InputError
from ..fileio import write_json
from ..frames import azimuth_elevation_range, geodetic_to_ecef
from ..orbits import load_constellation
from ..progress import progress
from ..scenarios import XIAN_BAOJI
from ..signal.channel import SiteChannel, site_range_rates
from ..signal.iq import write_sigmf
from ..signal.pilot import PilotComb
from ..timebase import format_utc
from . import add_command
from .options import mask_deg, parse_site, parse_time, positive

DEFAULT_SITE = "34.342,108.940,400"
_CHUNK = 1 << 18


def register(subparsers):
    p = add_command(subparsers, "generate", sys.modules[__name__],
                    help="write a SigMF recording of the Starlink pilot combs received at a site")
    p.add_argument("-o", "--output", required=True, metavar="FILE.sigmf-meta", help="output recording")
    p.add_argument("--tle", metavar="FILE", help="TLE or OMM file (default: bundled Walker set)")
    p.add_argument("--site", default=DEFAULT_SITE, metavar="LAT_DEG,LON_DEG,ALT_M",
                   help=f"static receiver (default {DEFAULT_SITE}, Xi'an)")
    p.add_argument("--start", metavar="ISO",
                   help=f"UTC of the first sample (default {format_utc(XIAN_BAOJI.start_utc)}, the xian-baoji start)")
    p.add_argument("--duration-s", type=float, default=1.0, help="length in seconds (default 1)")
    p.add_argument("--sample-rate-hz", type=float, default=2.5e6, help="complex sample rate (default 2.5e6)")
    p.add_argument("--cn0-dbhz", type=float, default=45.0, help="C/N0 of each tone [dB-Hz] (default 45)")
    p.add_argument("--sat", nargs="+", action="extend", metavar="ID",
                   help="NORAD ids to include (default: all above --mask-deg at the start)")
    p.add_argument("--mask-deg", type=float, default=40.0, help="elevation mask for the default choice (default 40)")
    p.add_argument("--seed", type=int, default=0, help="seed of noise, phases and clock offsets (default 0)")
    p.add_argument("--datatype", choices=("cf32_le", "ci16_le"), default="cf32_le", help="sample format")
    p.add_argument("--truth-step-s", type=float, default=0.1,
                   help="block length of the truth annotations (default 0.1, as leosop doppler --block-s)")
    p.add_argument("--sat-offset-max-hz", type=float, default=5.0,
                   help="per-satellite clock offsets drawn in [0, this] (default 5, seed 004 Table 1)")
    p.add_argument("--rx-offset-hz", type=float, default=5.0,
                   help="receiver frequency offset (default 5, seed 004 Table 1)")


def _select(const, pos_rx, start, ids, mask):
    from ..orbits.propagate import state_ecef

    if ids:
        return const.select_ids(ids)
    pos, _, status = state_ecef(const, np.array([start]))
    _, elev, _ = azimuth_elevation_range(pos[:, 0], pos_rx)
    keep = (status[:, 0] == 0) & (np.degrees(elev) >= mask)
    if not np.any(keep):
        raise InputError(f"no satellite above {mask:g} deg at {format_utc(start)}; choose --start or --sat")
    return const.subset(np.flatnonzero(keep))


def run(args):
    lat, lon, alt = parse_site(args.site)
    start = parse_time(args.start) if args.start else XIAN_BAOJI.start_utc
    duration = positive(args.duration_s, "--duration-s")
    fs = positive(args.sample_rate_hz, "--sample-rate-hz")
    step = positive(args.truth_step_s, "--truth-step-s")
    mask = mask_deg(args.mask_deg)
    if not np.isfinite(args.cn0_dbhz):
        raise InputError(f"--cn0-dbhz {args.cn0_dbhz}: must be a finite number")
    if not (np.isfinite(args.sat_offset_max_hz) and args.sat_offset_max_hz >= 0):
        raise InputError(f"--sat-offset-max-hz {args.sat_offset_max_hz}: must be >= 0")
    out = Path(args.output)
    if out.suffix != ".sigmf-meta":
        raise InputError(f"-o {out}: the output must end in .sigmf-meta")
    n = int(round(duration * fs))
    n_step = int(round(step * fs))
    if n_step > n:
        raise InputError(f"--truth-step-s {step:g} is longer than --duration-s {duration:g}")
    comb = PilotComb()
    if fs <= 2.0 * comb.offsets_hz.max():
        raise InputError(f"--sample-rate-hz {fs:g}: must exceed the comb's width, {2 * comb.offsets_hz.max():.0f} Hz")

    rng = np.random.default_rng(args.seed)
    pos_rx = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    const = _select(load_constellation(args.tle), pos_rx, start, args.sat, mask)
    t_nodes, range_rate = site_range_rates(const, pos_rx, start, n / fs)
    clock = rng.uniform(0.0, args.sat_offset_max_hz, len(const)) + args.rx_offset_hz
    channel = SiteChannel(t_nodes, range_rate, fs, args.cn0_dbhz, clock, comb=comb,
                          phase_rad=rng.uniform(0.0, 2.0 * np.pi, len(const)))

    starts = np.arange(0, n - n_step + 1, n_step)
    t_c = (starts + 0.5 * (n_step - 1)) / fs
    dop = channel.doppler_hz(t_c)
    rate = channel.doppler_rate_hz_per_s(t_c)
    annotations = [
        (s, n_step, {"core:label": str(sid), "leosop:sat_id": str(sid), "leosop:t_s": float(t_c[j]),
                     "leosop:doppler_hz": float(dop[i, j]), "leosop:doppler_rate_hz_per_s": float(rate[i, j]),
                     "leosop:cn0_dbhz": float(channel.cn0_dbhz[i])})
        for j, s in enumerate(starts) for i, sid in enumerate(const.sat_ids)
    ]
    # Full scale for ci16: tones add to at most sum of amplitudes; noise is
    # Gaussian. Four noise sigmas above the comb's peak keeps clipping ~1e-7.
    full_scale = comb.n_tones * len(const) + 4.0 * channel.noise_sigma() / np.sqrt(2.0)
    chunks = (channel.samples(i, min(_CHUNK, n - i), rng)
              for i in progress(range(0, n, _CHUNK), desc="generate", unit="chunk"))
    extra = {"leosop:n_tones": STARLINK_N_TONES, "leosop:tone_spacing_hz": STARLINK_TONE_SPACING_HZ,
             "core:description": f"leosop generate: Starlink pilot combs of {len(const)} satellite(s) "
                                 f"at {lat:g},{lon:g},{alt:g}; seed {args.seed}",
             "core:geolocation": {"type": "Point", "coordinates": [lon, lat, alt]}}
    write_sigmf(out, chunks, sample_rate_hz=fs, center_hz=STARLINK_PILOT_HZ, start_utc=start,
                datatype=args.datatype, annotations=annotations, global_extra=extra, ci16_full_scale=full_scale)
    doc = {
        "meta": str(out),
        "data": str(out.with_suffix(".sigmf-data")),
        "datatype": args.datatype,
        "n_samples": n,
        "sample_rate_hz": fs,
        "start_utc": format_utc(start),
        "duration_s": n / fs,
        "satellites": [
            {"sat_id": str(sid), "doppler_hz_start": float(channel.doppler_hz([0.0])[i, 0]),
             "doppler_rate_hz_per_s_start": float(channel.doppler_rate_hz_per_s([0.0])[i, 0]),
             "clock_offset_hz": float(clock[i]), "cn0_dbhz": float(channel.cn0_dbhz[i])}
            for i, sid in enumerate(const.sat_ids)
        ],
    }
    if args.out:
        write_json(Path(args.out) / "generate.json", doc)
    return doc


def summary(doc):
    lines = [f"wrote {doc['meta']} ({doc['n_samples']} {doc['datatype']} samples at {doc['sample_rate_hz']:g} Hz, "
             f"{doc['duration_s']:g} s from {doc['start_utc']})"]
    for s in doc["satellites"]:
        lines.append(f"  sat {s['sat_id']}: Doppler {s['doppler_hz_start']:+.1f} Hz, rate "
                     f"{s['doppler_rate_hz_per_s_start']:+.1f} Hz/s, clock {s['clock_offset_hz']:.2f} Hz, "
                     f"C/N0 {s['cn0_dbhz']:g} dB-Hz")
    return "\n".join(lines)
