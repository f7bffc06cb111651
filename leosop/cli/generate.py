"""``leosop generate``: a SigMF recording of Starlink pilot combs as received at a site.

The satellites above the mask at the start (or ``--sat`` IDs) are propagated
with SGP4; each one's comb follows its exact light-time range at every
sample (:mod:`leosop.signal.channel`, DESIGN 4.2), with

- its own C/N0: by default from the geometry (``--cn0-dbhz`` holds for a
  satellite at zenith at 550 km; free-space loss with range and the cosine
  pattern of a flat receive array, :func:`~leosop.signal.channel.cn0_geometry_dbhz`;
  silent below the horizon), or ``--cn0-model constant`` (one value for all,
  or one per ``--sat``);
- a clock offset drawn uniformly in [0, --sat-offset-max-hz] ([Shen 2024]
  Table 1: 0-5 Hz) plus the receiver's offset ``--rx-offset-hz`` and its
  drift ``--rx-drift-hz-per-s`` (an LNB's LO, common to all satellites:
  truth in ``leosop:rx_offset_hz`` and ``leosop:rx_drift_hz_per_s``);
- optionally an orbit error (truth differs from the TLE the receiver will
  use): along-track, radial and cross-track errors drawn per satellite;
- with ``--waveform ofdm``, optionally frame-timing jumps
  (``--frame-jump-sigma-s``, Qin et al. 2025: the frame start of each
  satellite steps by N(0, sigma) every ``--frame-jump-period-s``; their own
  stream of ``--seed``, so the rest of the recording is unchanged), each
  satellite's in the truth (``frame_jumps``: receive time and step).

``--snapshot-s S --period-s P`` records only S seconds every P seconds, one
SigMF capture per snapshot; the signal's phase runs on through the gaps.
The truth (Doppler at each block centre, its rate, C/N0, satellite id) goes
into the SigMF annotations, the per-satellite draws into ``leosop:satellites``.

``--base-site`` writes a second recording (``--base-output``) at a base
station, static at that site, for differential replay (issue 23): the same
satellites with the same satellite errors (orbit error, oscillator offset
and ``--sat-drift-sigma-hz-per-s`` drift) and the same transmitted carrier
phases, its own receiver clock, LO phase (``leosop:lo_phase_rad``), noise,
geometric C/N0 (``--base-cn0-dbhz``) and capture times (``--base-offset-s``
after the rover's). Each satellite's phases are those of one transmitter
seen at two ranges (``range_ref_m``: the rover's at its first sample, the
nominal tone phases' range), so the double differences of the central
tone's phase between the receivers are their ranges' in cycles. A site option beside ``--site``
fits the command's one-receiver options best: every other setting (band,
snapshots, front end, sample format) is the pair's. The base's draws come
from their own stream of the seed, so the rover's recording is the one the
command writes without ``--base-site``.
"""

import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..apps.scenarios import XIAN_BAOJI
from ..constellations import DEFAULT_FAMILY
from ..errors import InputError
from ..fileio import atomic_files, json_text
from ..frames import azimuth_elevation_range, geodetic_to_ecef
from ..orbits import load_constellation
from ..signal.channel import WAVEFORMS, OrbitError, inertial_speed_mps
from ..signal.frontend import BITS_DATATYPE, PRESETS, FrontEnd
from ..signal.iq_write import write_sigmf_files
from ..signal.ofdm_downlink import FrameTimingJumps
from ..signal.pilot import PilotComb
from ..timebase import format_utc
from . import add_command
from .generate_site import WAVEFORM_TEXT, Satellites, sample_chunks, site_recording
from .options import mask_deg, parse_site, parse_time, parse_velocity, positive, warn_stale

DEFAULT_SITE = "34.342,108.940,400"
#: Bounds of the numeric options: beyond them a value is a typo, not an experiment.
_MAX_SAMPLE_RATE_HZ = 1e10  # above any SDR
_MAX_SAMPLES = 10**11  # 800 GB of cf32
_MAX_ORBIT_ERROR_M = 1e5  # 100 km: beyond it the truth is not the element set's satellite
#: A satellite oscillator drifting faster than this is not a clock [Hz/s].
_MAX_SAT_DRIFT_HZ_PER_S = 100.0
#: The base's default receiver offset is the rover's plus a draw uniform in +-this [Hz] (a different
#: receiver's clock, of the size of [Shen 2024] Table 1's offsets).
_BASE_OFFSET_SPREAD_HZ = 5.0
#: Largest shift of the base's captures against the rover's [s]: beyond it the pair shares little time.
_MAX_BASE_OFFSET_S = 60.0
#: Largest frame-timing jump sigma [s]: 10 us is 2400 samples at 240 MS/s, beyond any measured step.
_MAX_FRAME_JUMP_SIGMA_S = 1e-5


def register(subparsers):
    p = add_command(subparsers, "generate", sys.modules[__name__],
                    help="write a SigMF recording of the Starlink pilot combs received at a site")
    p.add_argument("-o", "--output", required=True, metavar="FILE.sigmf-meta", help="output recording")
    p.add_argument("--tle", metavar="FILE", help="TLE or OMM file (default: bundled Walker set)")
    p.add_argument("--site", default=DEFAULT_SITE, metavar="LAT_DEG,LON_DEG,ALT_M",
                   help=f"receiver at the start (default {DEFAULT_SITE}, Xi'an)")
    p.add_argument("--velocity-enu-mps", default="0,0,0", metavar="VE,VN,VU",
                   help="constant receiver velocity in the start site's east/north/up frame: a straight line "
                        "(default 0,0,0: static)")
    p.add_argument("--start", metavar="ISO",
                   help=f"UTC of the first sample (default {format_utc(XIAN_BAOJI.start_utc)}, the xian-baoji start)")
    p.add_argument("--duration-s", type=float, default=1.0, help="length in seconds (default 1)")
    p.add_argument("--sample-rate-hz", type=float, default=2.5e6, help="complex sample rate (default 2.5e6)")
    p.add_argument("--cn0-model", choices=("geometry", "constant"), default="geometry",
                   help="geometry: C/N0 from range and elevation, --cn0-dbhz at zenith at 550 km; "
                        "constant: --cn0-dbhz for every satellite (default geometry)")
    p.add_argument("--cn0-dbhz", type=float, nargs="+", default=[45.0], metavar="C",
                   help="C/N0 of each tone [dB-Hz] (default 45); with --cn0-model constant one value per --sat "
                        "is accepted")
    p.add_argument("--sat", nargs="+", action="extend", metavar="ID",
                   help="NORAD ids to include (default: all above --mask-deg at the start)")
    p.add_argument("--mask-deg", type=float, default=40.0, help="elevation mask for the default choice (default 40)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of noise, phases, clock offsets and orbit errors (default 0)")
    p.add_argument("--datatype", choices=("cf32_le", "ci16_le", "ci8", "cu8"), default="cf32_le",
                   help="sample format (ci8: HackRF, cu8: RTL-SDR; default cf32_le)")
    p.add_argument("--truth-step-s", type=float, default=0.1,
                   help="block length of the truth annotations (default 0.1, as leosop doppler --block-s)")
    p.add_argument("--sat-offset-max-hz", type=float, default=5.0,
                   help="per-satellite clock offsets drawn in [0, this] (default 5, [Shen 2024] Table 1)")
    p.add_argument("--rx-offset-hz", type=float,
                   help="receiver frequency offset at the first sample, common to all satellites (an LNB's LO "
                        "error enters here; default 5, [Shen 2024] Table 1, or the --front-end preset's)")
    p.add_argument("--rx-drift-hz-per-s", type=float,
                   help="receiver LO frequency ramp common to all satellites [Hz/s]: the offset at t is "
                        "--rx-offset-hz plus this times t (default 0, or the --front-end preset's)")
    _front_end_options(p)
    for axis in ("along", "radial", "cross"):
        p.add_argument(f"--orbit-error-{axis}-m", type=float, default=0.0, metavar="SIGMA",
                       help=f"standard deviation of the {axis}-track orbit error drawn per satellite [m] (default 0)"
                       .replace("radial-track", "radial"))
    p.add_argument("--waveform", choices=WAVEFORMS, default="tones",
                   help="tones: the pilot comb alone; ofdm: the published OFDM downlink frame (240 MHz, "
                        "N = 1024, PSS/SSS/data) with the comb at its centre, limited to the recording's band "
                        "(default tones)")
    p.add_argument("--frame-jump-sigma-s", type=float, default=0.0, metavar="SIGMA",
                   help="with --waveform ofdm: each satellite's frame timing steps by N(0, SIGMA) every "
                        "--frame-jump-period-s (Qin et al. 2025 measured hundreds of ns about once per second on "
                        "Starlink v1.x; default 0: no jumps)")
    p.add_argument("--frame-jump-period-s", type=float, metavar="P",
                   help="time between frame-timing jumps (default 1, with --frame-jump-sigma-s)")
    p.add_argument("--snapshot-s", type=float, metavar="S",
                   help="record only S seconds every --period-s (one SigMF capture each)")
    p.add_argument("--period-s", type=float, metavar="P", help="snapshot period (with --snapshot-s)")
    p.add_argument("--sat-drift-sigma-hz-per-s", type=float, default=0.0, metavar="SIGMA",
                   help="standard deviation of each satellite oscillator's frequency drift [Hz/s] (default 0)")
    _base_options(p)


def _base_options(p):
    b = p.add_argument_group("base station (a second recording of the same satellites and satellite errors)")
    b.add_argument("--base-site", metavar="LAT_DEG,LON_DEG,ALT_M", help="also write a static base's recording here")
    b.add_argument("--base-output", metavar="FILE.sigmf-meta",
                   help="the base's recording (default: -o's name with -base before .sigmf-meta)")
    b.add_argument("--base-offset-s", type=float, default=0.0, metavar="S",
                   help="the base's captures start S seconds after the rover's, |S| <= 60 (default 0: aligned)")
    b.add_argument("--base-rx-offset-hz", type=float, metavar="HZ",
                   help="base receiver offset (default: the rover's plus a draw uniform in +-5 Hz)")
    b.add_argument("--base-rx-drift-hz-per-s", type=float, metavar="HZ_PER_S",
                   help="base receiver drift (default: the rover's)")
    b.add_argument("--base-cn0-dbhz", type=float, metavar="C", help="the base's --cn0-dbhz (default: the rover's)")


def _front_end_options(p):
    fe = p.add_argument_group("front end (leosop.signal.frontend; each option overrides the preset's value)")
    fe.add_argument("--front-end", choices=("none", *PRESETS), default="none",
                    help="consumer: LNB 620 kHz off drifting 25 Hz/s, phase noise, IQ imbalance, DC, a CW line "
                         "at +700 kHz, 8 bits (docs/replay.md); none: an ideal receiver (default)")
    fe.add_argument("--phase-noise-linewidth-hz", type=float, metavar="HZ",
                    help="Wiener (random-walk) LO phase of this Lorentzian linewidth")
    fe.add_argument("--phase-noise-dbc-hz", type=float, metavar="DBC",
                    help="bounded LO phase noise: flat at this level up to --phase-noise-corner-hz")
    fe.add_argument("--phase-noise-corner-hz", type=float, metavar="HZ", help="corner of that floor (default 30e3)")
    fe.add_argument("--iq-gain-db", type=float, metavar="DB", help="Q branch gain over I")
    fe.add_argument("--iq-phase-deg", type=float, metavar="DEG", help="Q branch phase error from quadrature")
    fe.add_argument("--dc-dbhz", type=float, metavar="DBHZ", help="DC offset power (a line at 0 Hz) [dB-Hz]")
    fe.add_argument("--cw", nargs=2, type=float, action="append", metavar=("HZ", "DBHZ"),
                    help="a CW interferer at baseband frequency HZ of power DBHZ (repeatable; replaces the preset's)")
    fe.add_argument("--agc-step-db", type=float, metavar="DB",
                    help="gain drawn uniformly in +-DB every --agc-period-s (default: the snapshot period, else 1 s)")
    fe.add_argument("--agc-period-s", type=float, metavar="S",
                    help="how often the --agc-step-db gain changes [s] (default: the snapshot period, else 1 s)")
    fe.add_argument("--bits", type=int, choices=(8, 12, 16),
                    help="quantise: 8 (ci8, or cu8 with --datatype cu8), 12 or 16 (ci16)")
    fe.add_argument("--headroom-db", type=float, metavar="DB",
                    help="quantiser full scale over the RMS of a component at nominal gain (default 12)")


_FE_FIELDS = ("phase_noise_linewidth_hz", "phase_noise_dbc_hz", "phase_noise_corner_hz", "iq_gain_db",
              "iq_phase_deg", "dc_dbhz", "cw", "agc_step_db", "agc_period_s", "bits", "headroom_db")


def _front_end(args):
    """The receiver's LO offset, drift and :class:`FrontEnd` from the preset and the options; the datatype."""
    preset = dict(PRESETS.get(args.front_end, {}))
    if args.agc_period_s is None and args.period_s is not None:
        args.agc_period_s = args.period_s
    values = {k: getattr(args, k) if getattr(args, k) is not None else preset[k]
              for k in _FE_FIELDS if getattr(args, k) is not None or k in preset}
    fe = FrontEnd(**values)
    offset = args.rx_offset_hz if args.rx_offset_hz is not None else preset.get("rx_offset_hz", 5.0)
    drift = args.rx_drift_hz_per_s if args.rx_drift_hz_per_s is not None else preset.get("rx_drift_hz_per_s", 0.0)
    datatype = args.datatype
    if fe.bits is not None:
        want = BITS_DATATYPE[fe.bits]
        if datatype == "cu8" and fe.bits == 8:
            want = "cu8"
        if datatype not in ("cf32_le", want):
            raise InputError(f"--datatype {datatype} does not hold {fe.bits}-bit samples (use {want})")
        datatype = want
    elif datatype != "cf32_le":
        fe.bits = {"ci16_le": 16, "ci8": 8, "cu8": 8}[datatype]
    return offset, drift, fe, datatype


def _check_rx(offset_hz, drift_hz_per_s, duration_s, fs, offset_option, drift_option):
    """A receiver's offset, and its offset at the end, within half the sample rate."""
    if abs(offset_hz) > fs / 2:
        raise InputError(f"{offset_option} {offset_hz:g}: must be within +-{fs / 2:g} Hz (half the sample rate)")
    end = offset_hz + drift_hz_per_s * duration_s
    if abs(end) > fs / 2:
        raise InputError(f"{drift_option} {drift_hz_per_s:g}: the receiver offset at the end, {end:g} Hz, must be "
                         f"within +-{fs / 2:g} Hz (half the sample rate)")


def _base(args, out):
    """The base's site, output and capture offset from the options: (None, None, 0.0) without ``--base-site``."""
    others = [f"--{k.replace('_', '-')}" for k in ("base_output", "base_rx_offset_hz", "base_rx_drift_hz_per_s",
                                                    "base_cn0_dbhz") if getattr(args, k) is not None]
    if args.base_offset_s != 0.0:
        others.append("--base-offset-s")
    if args.base_site is None:
        if others:
            raise InputError(f"{others[0]} describes a base station: give --base-site too")
        return None, None, 0.0
    site = parse_site(args.base_site, "--base-site")
    base_out = Path(args.base_output) if args.base_output else out.with_name(out.stem + "-base.sigmf-meta")
    if base_out.suffix != ".sigmf-meta":
        raise InputError(f"--base-output {base_out}: the output must end in .sigmf-meta")
    if base_out.resolve() == out.resolve():
        raise InputError(f"--base-output {base_out}: the same file as -o")
    offset_s = args.base_offset_s
    if not (np.isfinite(offset_s) and abs(offset_s) <= _MAX_BASE_OFFSET_S):
        raise InputError(f"--base-offset-s {offset_s:g}: must be within +-{_MAX_BASE_OFFSET_S:g} s")
    return site, base_out, float(offset_s)


def _select(const, pos_rx, start, duration_s, ids, mask):
    """The ``--sat`` satellites, else those above ``mask`` at the start; those SGP4 cannot propagate left out."""
    from ..orbits.propagate import drop_failing, state_ecef

    span = np.array([start, start + np.timedelta64(int(round(duration_s * 1e9)), "ns")])
    if ids:
        return drop_failing(const.select_ids(ids), span, what=f"the recording from {format_utc(start)}")
    const = drop_failing(const, span, what=f"the recording from {format_utc(start)}")
    pos, _, status = state_ecef(const, np.array([start]))
    _, elev, _ = azimuth_elevation_range(pos[:, 0], pos_rx)
    keep = (status[:, 0] == 0) & (np.degrees(elev) >= mask)
    if not np.any(keep):
        raise InputError(f"no satellite above {mask:g} deg at {format_utc(start)}; choose --start or --sat")
    return const.subset(np.flatnonzero(keep))


def _frame_jumps(args):
    """The frame-timing jumps of the options (seeded by --seed), or None."""
    sigma, period = args.frame_jump_sigma_s, args.frame_jump_period_s
    if not 0 <= sigma <= _MAX_FRAME_JUMP_SIGMA_S:
        raise InputError(f"--frame-jump-sigma-s {sigma:g}: must be a standard deviation in "
                         f"[0, {_MAX_FRAME_JUMP_SIGMA_S:g}] s")
    if sigma == 0:
        if period is not None:
            raise InputError("--frame-jump-period-s describes frame-timing jumps: give --frame-jump-sigma-s too")
        return None
    if args.waveform != "ofdm":
        raise InputError("--frame-jump-sigma-s: frame-timing jumps need --waveform ofdm (the tones have no frames)")
    return FrameTimingJumps(sigma, positive(1.0 if period is None else period, "--frame-jump-period-s"), (args.seed,))


def _captures(args, n, fs):
    """Sample index on the signal's timeline and length of each capture, ((n_cap,), (n_cap,))."""
    if (args.snapshot_s is None) != (args.period_s is None):
        raise InputError("--snapshot-s and --period-s go together")
    if args.snapshot_s is None:
        return np.array([0]), np.array([n])
    snap = positive(args.snapshot_s, "--snapshot-s")
    period = positive(args.period_s, "--period-s")
    if snap > period:
        raise InputError(f"--snapshot-s {snap:g} is longer than --period-s {period:g}")
    n_snap = int(round(snap * fs))
    if n_snap < 1:
        raise InputError(f"--snapshot-s {snap:g}: shorter than one sample at {fs:g} Hz")
    starts = np.round(np.arange(int(np.floor(n / fs / period)) + 1) * period * fs).astype(np.int64)
    starts = starts[starts + n_snap <= n]
    if starts.size == 0:
        raise InputError(f"--duration-s {n / fs:g} holds no whole snapshot of --snapshot-s {snap:g}")
    return starts, np.full(starts.size, n_snap)


@dataclass(frozen=True)
class _Settings:
    """The checked options of one run (``rx``: the rover's offset [Hz], drift [Hz/s], FrontEnd, datatype)."""

    site: tuple
    vel_enu: np.ndarray
    start: np.datetime64
    duration: float
    fs: float
    mask: float
    rx: tuple
    sigma_orbit_m: dict
    sat_drift_sigma: float
    frame_jumps: FrameTimingJumps | None
    out: Path
    base: tuple
    base_out: Path
    base_offset_s: float
    n: int
    n_step: int
    comb: PilotComb
    signal_starts: np.ndarray
    lengths: np.ndarray
    file_starts: np.ndarray


def _settings(args):
    """The options checked (InputError naming the first bad one) and what follows from them."""
    lat, lon, alt = parse_site(args.site)
    vel_enu = parse_velocity(args.velocity_enu_mps)
    start = parse_time(args.start) if args.start else XIAN_BAOJI.start_utc
    duration = positive(args.duration_s, "--duration-s")
    fs = positive(args.sample_rate_hz, "--sample-rate-hz")
    step = positive(args.truth_step_s, "--truth-step-s")
    mask = mask_deg(args.mask_deg)
    if fs > _MAX_SAMPLE_RATE_HZ:
        raise InputError(f"--sample-rate-hz {fs:g}: at most {_MAX_SAMPLE_RATE_HZ:g}")
    if duration * fs > _MAX_SAMPLES:
        raise InputError(f"--duration-s {duration:g} at {fs:g} Hz is {duration * fs:.3g} samples; at most "
                         f"{_MAX_SAMPLES:.0e}")
    if not 0 <= args.sat_offset_max_hz <= fs / 2:
        raise InputError(f"--sat-offset-max-hz {args.sat_offset_max_hz:g}: must be in [0, {fs / 2:g}] "
                         "(half the sample rate)")
    rx_offset, rx_drift, fe, datatype = _front_end(args)
    _check_rx(rx_offset, rx_drift, duration, fs, "--rx-offset-hz", "--rx-drift-hz-per-s")
    for f_hz, _ in fe.cw:
        if abs(f_hz) > fs / 2:
            raise InputError(f"--cw {f_hz:g}: the interferer must be within +-{fs / 2:g} Hz (half the sample rate)")
    sigma_orbit_m = {}
    for axis in ("along", "radial", "cross"):
        value = getattr(args, f"orbit_error_{axis}_m")
        if not 0 <= value <= _MAX_ORBIT_ERROR_M:
            raise InputError(f"--orbit-error-{axis}-m {value:g}: must be a standard deviation in "
                             f"[0, {_MAX_ORBIT_ERROR_M:g}] m")
        sigma_orbit_m[f"{axis}_sigma_m"] = value
    sat_drift_sigma = args.sat_drift_sigma_hz_per_s
    if not 0 <= sat_drift_sigma <= _MAX_SAT_DRIFT_HZ_PER_S:
        raise InputError(f"--sat-drift-sigma-hz-per-s {sat_drift_sigma:g}: must be a standard deviation in "
                         f"[0, {_MAX_SAT_DRIFT_HZ_PER_S:g}] Hz/s")
    frame_jumps = _frame_jumps(args)
    out = Path(args.output)
    if out.suffix != ".sigmf-meta":
        raise InputError(f"-o {out}: the output must end in .sigmf-meta")
    base, base_out, base_offset_s = _base(args, out)
    n = int(round(duration * fs))
    n_step = int(round(step * fs))
    if n_step > n and args.snapshot_s is None:
        raise InputError(f"--truth-step-s {step:g} is longer than --duration-s {duration:g}")
    comb = PilotComb.of(DEFAULT_FAMILY)
    if fs <= 2.0 * comb.offsets_hz.max():
        raise InputError(f"--sample-rate-hz {fs:g}: must exceed the comb's width, {2 * comb.offsets_hz.max():.0f} Hz")
    signal_starts, lengths = _captures(args, n, fs)
    file_starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    return _Settings((lat, lon, alt), vel_enu, start, duration, fs, mask, (rx_offset, rx_drift, fe, datatype),
                     sigma_orbit_m, sat_drift_sigma, frame_jumps, out, base, base_out, base_offset_s, n, n_step, comb,
                     signal_starts, lengths, file_starts)


def run(args):
    s = _settings(args)
    recs, b_start = _recordings(args, s)
    doc = _document(args, s, recs, b_start)
    _write(args, s, recs, doc)
    return doc


def _recordings(args, s):
    """The rover's recording and, with ``--base-site``, the base's, from the shared satellite draws.

    Returns the recordings and the base's first sample time (None without a base).
    """
    lat, lon, alt = s.site
    rx_offset, rx_drift, fe, datatype = s.rx
    n, fs, start = s.n, s.fs, s.start
    rng = np.random.default_rng(args.seed)
    pos_rx = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    const = load_constellation(args.tle)
    warn_stale(const, start)
    const = _select(const, pos_rx, start, n / fs, args.sat, s.mask)
    sat_offset = rng.uniform(0.0, args.sat_offset_max_hz, len(const))
    phase = rng.uniform(0.0, 2.0 * np.pi, len(const))
    speed = inertial_speed_mps(const, start)
    sats = Satellites(sat_offset, np.zeros(len(const)), OrbitError.draw(rng, speed, **s.sigma_orbit_m), speed)
    if s.sat_drift_sigma > 0:  # drawn only when asked, so that recordings without it keep their noise
        sats = replace(sats, drift_hz_per_s=rng.normal(0.0, s.sat_drift_sigma, len(const)))
    plan = (s.file_starts, s.signal_starts, s.lengths, s.n_step)
    # ``phase``: each satellite's transmitted carrier phase, as the rover sees it at its first sample (its LO
    # phase zero, its range there the reference of every receiver's geometric phase)
    recs = [site_recording(args, const, sats, plan, site=(lat, lon, alt), vel_enu=s.vel_enu, start=start,
                           t0_s=0.0, rx=(rx_offset, rx_drift, fe, datatype), cn0_dbhz=args.cn0_dbhz,
                           phase_rad=phase, rng=rng, n=n, fs=fs, comb=s.comb, frame_jumps=s.frame_jumps)]
    if s.base is None:
        return recs, None
    brng = np.random.default_rng([args.seed, 1])  # the base's own stream: its clock, LO phase, noise
    b_offset, b_drift, b_fe, _ = _front_end(args)
    b_offset = (rx_offset + brng.uniform(-_BASE_OFFSET_SPREAD_HZ, _BASE_OFFSET_SPREAD_HZ)
                if args.base_rx_offset_hz is None else args.base_rx_offset_hz)
    b_drift = rx_drift if args.base_rx_drift_hz_per_s is None else args.base_rx_drift_hz_per_s
    _check_rx(b_offset, b_drift, s.duration, fs, "--base-rx-offset-hz", "--base-rx-drift-hz-per-s")
    b_start = start + np.timedelta64(round(s.base_offset_s * 1e9), "ns")
    recs.append(site_recording(args, const, sats, plan, site=s.base, vel_enu=np.zeros(3), start=b_start,
                               t0_s=s.base_offset_s, rx=(b_offset, b_drift, b_fe, datatype),
                               cn0_dbhz=args.cn0_dbhz if args.base_cn0_dbhz is None else [args.base_cn0_dbhz],
                               phase_rad=phase, lo_phase_rad=brng.uniform(0.0, 2.0 * np.pi), rng=brng, n=n,
                               fs=fs, comb=s.comb, frame_jumps=s.frame_jumps, range_ref_m=recs[0].channel.range_ref_m,
                               what="base"))
    return recs, b_start


def _document(args, s, recs, b_start):
    """The JSON document of the run (DESIGN's ``generate`` contract)."""
    rover, out = recs[0], s.out
    doc = {
        "meta": str(out),
        "data": str(out.with_suffix(".sigmf-data")),
        "datatype": s.rx[3],
        "n_samples": int(s.lengths.sum()),
        "sample_rate_hz": s.fs,
        "start_utc": format_utc(s.start),
        "duration_s": s.n / s.fs,
        "n_captures": int(s.signal_starts.size),
        "snapshot_s": None if args.snapshot_s is None else float(s.lengths[0] / s.fs),
        "period_s": args.period_s,
        "cn0_model": args.cn0_model,
        "waveform": args.waveform,
        "vel_enu_mps": [float(v) for v in s.vel_enu],
        "rx_offset_hz": float(s.rx[0]),
        "rx_drift_hz_per_s": float(s.rx[1]),
        "front_end": rover.extra.get("leosop:front_end"),
        "satellites": rover.satellites,
    }
    if s.base is not None:
        b = recs[1]
        doc["base"] = {"meta": str(s.base_out), "data": str(s.base_out.with_suffix(".sigmf-data")),
                       "site": list(s.base), "start_utc": format_utc(b_start), "offset_s": s.base_offset_s,
                       "rx_offset_hz": float(b.rx[0]), "rx_drift_hz_per_s": float(b.rx[1]),
                       "lo_phase_rad": b.extra["leosop:lo_phase_rad"], "satellites": b.satellites}
    return doc


def _write(args, s, recs, doc):
    """All outputs or none: each data file, then its metadata, then generate.json."""
    metas = [s.out] + ([s.base_out] if s.base is not None else [])
    paths = [p for m in metas for p in (m.with_suffix(".sigmf-data"), m)]
    paths += [Path(args.out) / "generate.json"] if args.out else []
    with atomic_files(paths) as tmps:
        for k, r in enumerate(recs):
            fe_k = r.rx[2]
            write_sigmf_files(tmps[2 * k], tmps[2 * k + 1],
                              sample_chunks(r.channel, s.signal_starts, s.lengths, r.rng, fe_k, r.full_scale,
                                            r.extra.get("leosop:front_end", {})),
                              sample_rate_hz=s.fs, center_hz=s.comb.carrier_hz,
                              captures=list(zip(s.file_starts, r.cap_times)), datatype=s.rx[3],
                              annotations=r.annotations, global_extra=r.extra, full_scale=r.full_scale)
        if args.out:
            tmps[-1].write_text(json_text(doc) + "\n")


def summary(doc):
    snap = (f", {doc['n_captures']} snapshots of {doc['snapshot_s']:g} s every {doc['period_s']:g} s"
            if doc["snapshot_s"] else "")
    lines = [f"wrote {doc['meta']} ({doc['n_samples']} {doc['datatype']} samples at {doc['sample_rate_hz']:g} Hz, "
             f"{doc['duration_s']:g} s from {doc['start_utc']}{snap}; {WAVEFORM_TEXT[doc['waveform']]}; "
             f"C/N0 model {doc['cn0_model']})"]
    for s in doc["satellites"]:
        cn0 = "below horizon" if s["cn0_dbhz"] is None else f"{s['cn0_dbhz']:.1f} dB-Hz"
        lines.append(f"  sat {s['sat_id']}: Doppler {s['doppler_hz_start']:+.1f} Hz, rate "
                     f"{s['doppler_rate_hz_per_s_start']:+.1f} Hz/s, clock {s['clock_offset_hz']:.2f} Hz, "
                     f"C/N0 {cn0}, orbit error along {s['orbit_error_along_m']:+.1f} m, "
                     f"radial {s['orbit_error_radial_m']:+.1f} m, cross {s['orbit_error_cross_m']:+.1f} m")
    if "base" in doc:
        b = doc["base"]
        heard = sum(s["cn0_dbhz"] is not None for s in b["satellites"])
        lines.append(f"wrote {b['meta']}: base at {','.join(f'{v:g}' for v in b['site'])}, captures from "
                     f"{b['start_utc']} ({b['offset_s']:+g} s), receiver offset {b['rx_offset_hz']:+.2f} Hz, "
                     f"{heard} of {len(b['satellites'])} satellites above its horizon; satellite errors shared")
    return "\n".join(lines)
