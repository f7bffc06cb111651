"""Starlink pilot signals: generation, IQ recordings, Doppler estimation.

Modules: :mod:`.pilot` (the comb, eq. 1 of [Shen 2024]), :mod:`.channel`
(geometry to per-sample tone phases, several satellites, noise), :mod:`.ofdm`
(the OFDM downlink: :mod:`.ofdm_frame`, :mod:`.ofdm_downlink`, :mod:`.pss`),
:mod:`.iq` (SigMF and raw recordings, read in blocks) and :mod:`.iq_write`
(SigMF writers), :mod:`.doppler` (coarse STFT/FFT and the fine estimators ml,
fmlef, fast), :mod:`.multicomb` (every comb of a block; :mod:`.comb_grid`,
:mod:`.comb_fit`), :mod:`.crlb` (Cramér-Rao bounds), :mod:`.fft` (FFTW
plans). The spectrogram figure is in :mod:`leosop.plots.spectra`.
"""
