"""Fusion of inertial navigation with LEO fixes.

:mod:`.kalman` is the filter core as plain functions; :mod:`.loose` couples
the strapdown INS with Doppler position/velocity fixes (seed 004 eq. 13-16).
"""
