"""Fusion of inertial navigation with LEO Doppler.

:mod:`.kalman` is the filter core as plain functions; :mod:`.common` holds
what both couplings share (settings, output, INS prediction and feedback,
the satellites' error states); :mod:`.loose` couples the strapdown INS with
Doppler position/velocity fixes ([Shen 2024] eq. 13-16); :mod:`.engine` is
the INS filter that takes time-ordered aids (:mod:`.aids`, and each
satellite's Doppler, :mod:`.aids_leo`: tight coupling, ours).
"""
