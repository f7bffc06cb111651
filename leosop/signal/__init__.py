"""Starlink pilot signals: generation, IQ recordings, Doppler estimation.

Modules: :mod:`.pilot` (the comb, eq. 1 of [Shen 2024]), :mod:`.channel`
(geometry to per-sample tone phases, several satellites, noise), :mod:`.iq`
(SigMF and raw recordings, read in blocks), :mod:`.doppler` (coarse STFT/FFT
and the fine estimators ml, fmlef, fast), :mod:`.crlb` (Cramér-Rao bounds),
:mod:`.fft` (FFTW plans). The spectrogram figure is in :mod:`leosop.plots.spectra`.
"""
