"""The Starlink Ku-band OFDM downlink: its frame, its reception, PSS acquisition and tracking, in one place.

The frame (numerology, PSS, SSS stand-in, data; [Humphreys 2023]) is
:mod:`.ofdm_frame`, its reception at a recording's band and Doppler (and
frame-timing jumps) :mod:`.ofdm_downlink`, PSS acquisition :mod:`.pss` and
frame-by-frame tracking :mod:`.pss_track`; their public names are imported here.
"""

from .ofdm_downlink import FrameTimingJumps, OfdmDownlink, ofdm_baseband
from .ofdm_frame import (FRAME_PERIOD_S, FRAME_SAMPLES, FS_HZ, GUTTER_SUBCARRIERS, N_CP, N_DATA_SYMBOLS, N_FFT,
                         N_GUARD, N_PSS_SEGMENTS, N_SYMBOL, N_SYMBOLS_PER_FRAME, OFDM_CENTER_OFFSET_HZ, PSS_SEGMENT_LEN,
                         SUBCARRIER_SPACING_HZ, active_subcarriers, data_symbols, frame, pss_mseq, pss_time,
                         sss_symbol, symbol_time)
from .pss import PSS_DETECT_THRESHOLD, PssAcquisition, acquire_pss
from .pss_track import PssTrack, track_pss

__all__ = [
    "FS_HZ", "N_FFT", "N_CP", "N_SYMBOL", "N_SYMBOLS_PER_FRAME", "N_DATA_SYMBOLS", "N_GUARD",
    "FRAME_SAMPLES", "FRAME_PERIOD_S", "SUBCARRIER_SPACING_HZ", "OFDM_CENTER_OFFSET_HZ",
    "GUTTER_SUBCARRIERS", "N_PSS_SEGMENTS", "PSS_SEGMENT_LEN",
    "active_subcarriers", "pss_mseq", "pss_time", "sss_symbol", "data_symbols", "symbol_time", "frame",
    "OfdmDownlink", "FrameTimingJumps", "ofdm_baseband", "PssAcquisition", "acquire_pss", "PSS_DETECT_THRESHOLD",
    "PssTrack", "track_pss",
]
