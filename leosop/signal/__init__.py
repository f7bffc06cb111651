"""Starlink pilot signals: generation, IQ recordings, Doppler estimation.

The public names, importable from here (``from leosop.signal import
open_sigmf, estimate_blocks``); each is imported from its module on first use
(:mod:`leosop.lazy`), so reading a recording does not load FFTW.

Generating signals:
    ``PilotComb``              the downlink pilot comb ([Shen 2024] eq. 1): tones, spacing, carrier
    ``comb_baseband``          complex baseband samples of a comb from geometry and clock phases
    ``doppler_blocks``         blocks of samples from Doppler, Doppler rate and C/N0 (no geometry)
    ``site_geometry``          light-time range and elevation of every satellite seen from a site
    ``SiteChannel``            the combs of several satellites received at a site, with noise
    ``FrontEnd``               consumer LNB + SDR impairments applied to generated samples
    ``noise_sigma``            per-sample noise standard deviation for a C/N0
    ``add_noise``              complex white noise at a C/N0

Recordings:
    ``open_sigmf``             open a SigMF recording (cf32_le, ci16_le, ci8, cu8) -> ``Recording``
    ``open_raw``               open a headerless IQ file (parameters given or from its name)
    ``Recording``              a recording on disk, read block by block
    ``write_sigmf``            write a SigMF recording from sample chunks, atomically

Doppler estimation:
    ``estimate_block``         Doppler, rate and status of one block (``fast``, ``fmlef``, ``ml``)
    ``estimate_blocks``        the same over a batch of blocks -> ``BlockEstimates``
    ``BlockEstimates``         per-block Doppler, rate, C/N0, sigma and status
    ``METHODS``                the fine methods ``estimate_block`` accepts
    ``coarse_stft``            a short-time Fourier track of the comb over a recording
    ``find_combs``             every pilot comb in a block (interference cancellation) -> ``Combs``
    ``Combs``                  the combs found in one block
    ``doppler_sigma_hz``       error model: a block's Doppler sigma from its C/N0
    ``crlb_frequency_hz2``     Cramér-Rao bound on the comb's frequency [Hz^2]
    ``crlb_rate_hz2``          Cramér-Rao bound on its frequency rate [(Hz/s)^2]

Left in their modules: the coarse and fine stages behind
``estimate_block`` (:mod:`.coarse`, :mod:`.fine`, with :mod:`.quality` for
the status), the multi-comb machinery (:mod:`.comb_grid`, :mod:`.comb_fit`, its
compiled fits, tracking blocks and comb subtraction :mod:`.fitkernels`, with numba),
the OFDM downlink (:mod:`.ofdm`, its own facade over :mod:`.ofdm_frame`,
:mod:`.ofdm_downlink`, :mod:`.pss`, :mod:`.pss_track`), the front-end model of the
generator (:mod:`.frontend`), its compiled comb synthesis (:mod:`.comb_phases`,
:mod:`.combkernels`, with numba), the receiver's cleaning and the recording survey of
``leosop doctor`` (:mod:`.cleaning`, :mod:`.survey`), recorder
conventions (:mod:`.recorders`) and the FFTW plans (:mod:`.fft`). The
spectrogram figure is in :mod:`leosop.plots.spectra`.
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

__all__ = [
    "PilotComb", "comb_baseband", "doppler_blocks", "site_geometry", "SiteChannel", "FrontEnd", "noise_sigma",
    "add_noise",
    "open_sigmf", "open_raw", "Recording", "write_sigmf",
    "estimate_block", "estimate_blocks", "BlockEstimates", "METHODS", "coarse_stft", "find_combs", "Combs",
    "doppler_sigma_hz", "crlb_frequency_hz2", "crlb_rate_hz2",
]

if TYPE_CHECKING:
    from .channel import SiteChannel, doppler_blocks, site_geometry
    from .coarse import coarse_stft
    from .crlb import crlb_frequency_hz2, crlb_rate_hz2
    from .doppler import METHODS, BlockEstimates, estimate_block, estimate_blocks
    from .error_model import doppler_sigma_hz
    from .frontend import FrontEnd
    from .iq import Recording, open_raw, open_sigmf
    from .iq_write import write_sigmf
    from .multicomb import Combs, find_combs
    from .pilot import PilotComb, add_noise, comb_baseband, noise_sigma

__getattr__, __dir__ = lazy_exports(__name__, __file__)
