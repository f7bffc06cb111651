"""OFDM at the full 240 MS/s: acquisition ms per frame and tracking x real time, each beside a baseline, one run.

Usage: python tools/bench_ofdm_track.py [--duration-s D] [--snr-db S] [--repeats R] [--seed N]

The recording (``--duration-s``, default 0.1 s = 75 frames) is one
satellite's OFDM downlink at +300 kHz Doppler, -2 kHz/s, plus a +30 kHz
receiver offset, white noise at ``--snr-db`` per sample, and frame-timing
jumps of 300 ns rms every 40 ms (:class:`~leosop.signal.ofdm.FrameTimingJumps`),
written as cf32 to a temporary file.

Acquisition: :func:`~leosop.signal.ofdm.acquire_pss` on one frame (the
shortest snippet it takes) and on 10 ms (per frame found); baseline: the
brute-force FFT search over a Doppler grid of ``bench_pss.py`` on the same
10 ms. Tracking: :func:`~leosop.signal.ofdm.track_pss` over the whole
recording from RAM and from a memory map of the file (page cache warm: the
disk is not measured); baseline: acquisition block after block (every 10 ms
acquired afresh, what a receiver without a tracker does). Times are best of
``--repeats``, wall clock and processor time (summed over threads); x real
time is recording length over wall time. The machine may be shared: the load
average is printed with the numbers.
"""

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_pss import brute_force
from leosop.signal import ofdm

DOPPLER_HZ, RATE_HZ_PER_S, RX_OFFSET_HZ, OFFSET_S = 3e5, -2e3, 3e4, 0.41e-3
JUMP_SIGMA_S, JUMP_PERIOD_S = 300e-9, 0.04
BLOCK = int(0.01 * ofdm.FS_HZ)  # 10 ms


def recording(duration_s, snr_db, seed, path):
    """Write the recording to ``path`` (cf32) chunk by chunk; return the link."""
    fs = ofdm.FS_HZ
    jumps = ofdm.FrameTimingJumps(JUMP_SIGMA_S, JUMP_PERIOD_S, (seed,))
    link = ofdm.OfdmDownlink(fs, seed=seed, frame_offset_s=OFFSET_S, timing_jumps=jumps)
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(ofdm.active_subcarriers().size / 10 ** (snr_db / 10) / 2)
    n = int(round(duration_s * fs))
    with open(path, "wb") as f:
        for a in range(0, n, BLOCK):
            t = (a + np.arange(min(BLOCK, n - a))) / fs
            clean = link.samples(t, DOPPLER_HZ * t + 0.5 * RATE_HZ_PER_S * t**2, RX_OFFSET_HZ * t)
            noise = sigma * (rng.standard_normal(t.size) + 1j * rng.standard_normal(t.size))
            f.write((clean + noise).astype(np.complex64).tobytes())
    return link


def best_time(fn, repeats):
    """Best wall-clock and processor time [s] of ``repeats`` calls (CPU summed over threads), and the result."""
    wall, cpu = [], []
    for _ in range(repeats):
        tic, cpu0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - tic)
        cpu.append(time.process_time() - cpu0)
    return (min(wall), min(cpu)), out


def ms(t):
    """'wall ms (CPU ms)' of a best_time pair."""
    return f"{t[0] * 1e3:7.1f} ms (CPU {t[1] * 1e3:6.1f} ms)"


def blockwise_acquisition(iq):
    """The tracking baseline: acquire_pss on every 10 ms block; frames found."""
    return sum(ofdm.acquire_pss(iq[a:a + BLOCK]).frame_start_s.size
               for a in range(0, iq.size - BLOCK + 1, BLOCK))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=0.1)
    ap.add_argument("--snr-db", type=float, default=-5.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ofdm.cf32"
        tic = time.perf_counter()
        link = recording(args.duration_s, args.snr_db, args.seed, path)
        t_gen = time.perf_counter() - tic
        mapped = np.memmap(path, dtype=np.complex64, mode="r")
        iq = np.array(mapped)
        duration = iq.size / ofdm.FS_HZ
        one_frame = iq[:ofdm.FRAME_SAMPLES + ofdm.PSS_SEGMENT_LEN + 1024]

        t_acq1, acq1 = best_time(lambda: ofdm.acquire_pss(one_frame), args.repeats)
        t_acq10, acq10 = best_time(lambda: ofdm.acquire_pss(iq[:BLOCK]), args.repeats)
        t_brute, _ = best_time(lambda: brute_force(iq[:BLOCK]), 1)
        t_trk, trk = best_time(lambda: ofdm.track_pss(iq, acq10), args.repeats)
        t_map, trk_map = best_time(lambda: ofdm.track_pss(mapped, acq10), args.repeats)
        t_base, n_base = best_time(lambda: blockwise_acquisition(iq), 1)
    n10 = acq10.frame_start_s.size
    steps = link.timing_jumps.steps_s(int(duration / JUMP_PERIOD_S))
    print(f"{duration:g} s at 240 MS/s ({iq.size} samples, generated in {t_gen:.0f} s), SNR {args.snr_db:g} dB "
          f"per sample; load average {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    print(f"acquisition, one frame ({one_frame.size} samples): {ms(t_acq1)}   "
          f"goal <= 50 ms -> {'met' if t_acq1[0] <= 0.05 else 'MISSED'} (detected {acq1.detected})")
    print(f"acquisition, 10 ms ({n10} frames):             {ms(t_acq10)} = {t_acq10[0] / n10 * 1e3:.1f} ms "
          f"per frame")
    print(f"baseline, brute force on 10 ms:              {ms(t_brute)}   ratio {t_brute[0] / t_acq10[0]:.1f}x")
    print(f"tracking from RAM:        {ms(t_trk)} = {duration / t_trk[0]:6.1f}x real time, "
          f"{int(trk.found.sum())} of {trk.frame_number.size} frames, jumps flagged at frames "
          f"{np.flatnonzero(trk.jump).tolist()} ({', '.join(f'{v * 1e9:+.1f}' for v in trk.jump_s[trk.jump])} ns)")
    print(f"tracking from the file:   {ms(t_map)} = {duration / t_map[0]:6.1f}x real time "
          f"(same track: {np.array_equal(trk.frame_start_s, trk_map.frame_start_s, equal_nan=True)})")
    print(f"baseline, acquisition every 10 ms: {ms(t_base)} = {duration / t_base[0]:6.2f}x real time "
          f"({n_base} frames); tracking {t_base[0] / t_trk[0]:.0f}x faster")
    print(f"truth: jumps of {', '.join(f'{v * 1e9:+.1f}' for v in steps)} ns every {JUMP_PERIOD_S * 1e3:g} ms; "
          f"goal tracking >= 1x real time -> {'met' if duration / t_map[0] >= 1 else 'MISSED'}")

if __name__ == "__main__":
    main()
