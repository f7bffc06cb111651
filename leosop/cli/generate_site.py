"""One receiver's recording for ``leosop generate``: its channel, truth annotations, SigMF metadata and samples.

The rover and the base station of a differential pair share the satellites'
draws (:class:`Satellites`); :func:`site_recording` builds each receiver's
:class:`~leosop.signal.channel.SiteChannel` and what its SigMF files say of
it, and :func:`sample_chunks` streams its samples through the front end.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..frames import C_e_n, geodetic_to_ecef
from ..progress import progress
from ..signal.channel import OrbitError, SiteChannel, cn0_geometry_dbhz, site_geometry
from ..timebase import format_utc

__all__ = ["Satellites", "SiteRecording", "site_recording", "sample_chunks", "WAVEFORM_TEXT"]

#: Bounds of ``--cn0-dbhz``: beyond them a value is a typo, not an experiment.
_CN0_RANGE_DBHZ = (-20.0, 100.0)
#: What each ``--waveform`` puts in the recording, for its description and the summary.
WAVEFORM_TEXT = {"tones": "pilot combs", "ofdm": "OFDM downlink frames with pilot combs"}
#: Samples synthesised at once (bounded memory).
_CHUNK = 1 << 18


@dataclass(frozen=True)
class Satellites:
    """What every receiver shares: each satellite's oscillator offset [Hz] and drift [Hz/s], orbit error, speed."""

    offset_hz: np.ndarray
    drift_hz_per_s: np.ndarray
    orbit_error: OrbitError
    speed_mps: np.ndarray


@dataclass(frozen=True)
class SiteRecording:
    """One receiver's channel and what its SigMF files say of it."""

    channel: SiteChannel
    rx: tuple  # (offset_hz, drift_hz_per_s, FrontEnd, datatype)
    rng: np.random.Generator
    annotations: list
    satellites: list
    extra: dict
    full_scale: float
    cap_times: list


def site_recording(args, const, sats, plan, *, site, vel_enu, start, t0_s, rx, cn0_dbhz, phase_rad, rng, n, fs,
                    comb, frame_jumps=None, lo_phase_rad=0.0, range_ref_m=None, what="rover"):
    """One receiver's recording of the shared satellites.

    ``start`` is its first sample, ``t0_s`` seconds after the satellite
    errors' reference (the rover's first sample): a drifting satellite
    oscillator is further off by then. ``plan`` is ``(file_starts,
    signal_starts, lengths, n_step)`` of :func:`_captures` and the truth blocks.
    ``phase_rad`` (n_sats,) is each satellite's transmitted central-tone
    phase at the reference's first sample, the same for every receiver;
    ``lo_phase_rad`` this receiver's LO phase, common to its satellites;
    ``range_ref_m`` (n_sats,) the range of the nominal tone phases
    (:class:`~leosop.signal.channel.SiteChannel`; None: this receiver's at
    its first sample). The satellites' oscillators have run on by ``t0_s``:
    their phase then is added, so that the phase difference between two
    receivers at one instant holds no satellite clock.
    """
    file_starts, signal_starts, lengths, n_step = plan
    lat, lon, alt = site
    rx_offset, rx_drift, fe, _ = rx
    pos_rx = geodetic_to_ecef(np.radians(lat), np.radians(lon), alt)
    clock = sats.offset_hz + sats.drift_hz_per_s * t0_s + rx_offset
    sat_cycles = sats.offset_hz * t0_s + 0.5 * sats.drift_hz_per_s * t0_s**2   # the oscillators' phase at t0_s
    carrier_phase = phase_rad + lo_phase_rad + 2.0 * np.pi * (sat_cycles - np.round(sat_cycles))
    vel_rx = C_e_n(np.radians(lat), np.radians(lon)) @ vel_enu
    t_nodes, range_m, elev = site_geometry(const, pos_rx, start, n / fs, orbit_error=sats.orbit_error,
                                           vel_rx_ecef_mps=vel_rx)
    cn0_nodes = _cn0(cn0_dbhz, args.cn0_model, const, range_m, elev,
                     "--cn0-dbhz" if what == "rover" else "--base-cn0-dbhz")
    if np.isfinite(range_m).all() and not np.isfinite(cn0_nodes).any():  # (SGP4 failures: SiteChannel)
        raise InputError(f"--sat {' '.join(const.sat_ids)}: no satellite is above the horizon at {lat:g},{lon:g} "
                         f"({what}) during the recording from {format_utc(start)}")
    channel = SiteChannel(t_nodes, range_m, fs, cn0_nodes, clock, comb=comb, phase_rad=carrier_phase,
                          waveform=args.waveform, rx_drift_hz_per_s=rx_drift, sat_drift_hz_per_s=sats.drift_hz_per_s,
                          frame_jumps=frame_jumps, range_ref_m=range_ref_m)
    blocks = _truth_blocks(file_starts, signal_starts, lengths, n_step, fs)
    t_c = (blocks[:, 1] + 0.5 * (blocks[:, 2] - 1)) / fs
    dop, rate, cn0 = channel.doppler_hz(t_c), channel.doppler_rate_hz_per_s(t_c), channel.cn0_at(t_c)
    annotations = [
        (f0, m, {"core:label": str(sid), "leosop:sat_id": str(sid), "leosop:t_s": float(t_c[j]),
                 "leosop:doppler_hz": float(dop[i, j]), "leosop:doppler_rate_hz_per_s": float(rate[i, j]),
                 "leosop:cn0_dbhz": float(cn0[i, j])})
        for j, (f0, _, m) in enumerate(blocks) for i, sid in enumerate(const.sat_ids) if np.isfinite(cn0[i, j])
    ]
    cn0_start = channel.cn0_at([0.0])[:, 0]
    err, speed = sats.orbit_error, sats.speed_mps
    satellites = [
        {"sat_id": str(sid), "doppler_hz_start": float(channel.doppler_hz([0.0])[i, 0]),
         "doppler_rate_hz_per_s_start": float(channel.doppler_rate_hz_per_s([0.0])[i, 0]),
         "clock_offset_hz": float(clock[i]), "sat_offset_hz": float(sats.offset_hz[i]),
         "sat_drift_hz_per_s": float(sats.drift_hz_per_s[i]), "cn0_dbhz": _num(cn0_start[i]),
         "orbit_error_along_s": float(err.along_s[i]),
         "orbit_error_along_m": float(err.along_s[i] * speed[i]),
         "orbit_error_radial_m": float(err.radial_m[i]), "orbit_error_cross_m": float(err.cross_m[i]),
         "tx_phase_rad": float(phase_rad[i]), "range_ref_m": float(channel.range_ref_m[i])}
        for i, sid in enumerate(const.sat_ids)
    ]
    if frame_jumps is not None:
        for i, sat in enumerate(satellites):
            t_s, step_s = channel.frame_jumps_truth(i, n / fs)
            sat["frame_jumps"] = [{"t_s": float(t), "jump_s": float(d)} for t, d in zip(t_s, step_s)]
    # Full scale for ci16: tones add to at most sum of amplitudes; OFDM
    # subcarriers and noise are Gaussian-like. Four sigmas above the comb's
    # peak keeps clipping ~1e-7.
    spread = np.hypot(channel.noise_sigma(), np.sqrt(channel.n_subcarriers * len(const))) / np.sqrt(2.0)
    full_scale = comb.n_tones * len(const) + 4.0 * spread
    if fe.active:  # a receiver's quantiser: full scale at --headroom-db over the RMS (clipping possible)
        full_scale = fe.full_scale(fe.rms_component(comb.n_tones * len(const) + channel.n_subcarriers * len(const),
                                                    channel.cn0_ref_dbhz, fs))
    cap_times = [start + np.timedelta64(int(round(s / fs * 1e9)), "ns") for s in signal_starts]
    extra = {"leosop:n_tones": comb.n_tones, "leosop:tone_spacing_hz": comb.tone_spacing_hz,
             "leosop:cn0_model": args.cn0_model, "leosop:satellites": satellites, "leosop:waveform": args.waveform,
             "core:description": f"leosop generate: Starlink {WAVEFORM_TEXT[args.waveform]} of {len(const)} "
                                 f"satellite(s) "
                                 f"at {lat:g},{lon:g},{alt:g}; seed {args.seed}" + ("" if what == "rover" else
                                                                                     f" ({what})"),
             "core:geolocation": {"type": "Point", "coordinates": [lon, lat, alt]},
             "leosop:vel_enu_mps": [float(v) for v in vel_enu],
             "leosop:rx_offset_hz": float(rx_offset),
             "leosop:rx_drift_hz_per_s": float(rx_drift), "leosop:lo_phase_rad": float(lo_phase_rad)}
    if fe.active:
        extra["leosop:front_end"] = dict(fe.metadata(), preset=args.front_end, full_scale=full_scale)
    return SiteRecording(channel, rx, rng, annotations, satellites, extra, full_scale, cap_times)


def _cn0(cn0_dbhz, cn0_model, const, range_m, elev_rad, option="--cn0-dbhz"):
    """C/N0 per satellite at every node, (n_sats, n_nodes)."""
    values = np.asarray(cn0_dbhz, dtype=float)
    if not np.all((values >= _CN0_RANGE_DBHZ[0]) & (values <= _CN0_RANGE_DBHZ[1])):
        raise InputError(f"{option} {' '.join(f'{v:g}' for v in values)}: must be in "
                         f"[{_CN0_RANGE_DBHZ[0]:g}, {_CN0_RANGE_DBHZ[1]:g}] dB-Hz")
    if values.size not in (1, len(const)) or (values.size > 1 and cn0_model != "constant"):
        raise InputError(f"{option}: {values.size} values; give one, or one per satellite "
                         f"({len(const)}) with --cn0-model constant")
    if cn0_model == "constant":
        return np.broadcast_to(np.broadcast_to(values, (len(const),))[:, None], range_m.shape)
    return cn0_geometry_dbhz(values[0], range_m, elev_rad)


def _truth_blocks(cap_file_starts, cap_signal_starts, cap_lengths, n_step, fs):
    """File start, signal start and length of every truth block (whole blocks within each capture)."""
    rows = []
    for f0, s0, m in zip(cap_file_starts, cap_signal_starts, cap_lengths):
        step = min(n_step, m)
        offs = np.arange(0, m - step + 1, step)
        rows.append(np.stack([f0 + offs, s0 + offs, np.full(offs.size, step)], axis=1))
    return np.concatenate(rows)


def _num(x):
    """JSON number, or None for +-inf / NaN."""
    return float(x) if np.isfinite(x) else None


def sample_chunks(channel, signal_starts, lengths, rng, fe, full_scale, fe_meta):
    """Received samples of every capture through the front end, chunk by chunk (bounded memory).

    The AGC gains drawn go into ``fe_meta`` (the ``leosop:front_end`` dict, written after the data).
    """
    pieces = [(s + i, min(_CHUNK, m - i)) for s, m in zip(signal_starts, lengths) for i in range(0, m, _CHUNK)]
    fs = channel.sample_rate_hz
    for start, count in progress(pieces, desc="generate", unit="chunk"):
        x = channel.samples(start, count, rng)
        if fe.active:
            x = fe.apply(x, (start + np.arange(count)) / fs, fs, channel.cn0_ref_dbhz, rng)
        if fe.bits == 12:  # a 12-bit ADC's levels, stored in ci16
            levels = 2047.0 / full_scale
            x = (np.clip(np.round(x.real * levels), -2048, 2047) + 1j * np.clip(np.round(x.imag * levels), -2048, 2047)
                 ) / levels
        yield x
    if fe.agc_step_db:
        fe_meta["agc_steps"] = fe.agc_steps()
