"""Fusion of inertial navigation with LEO Doppler.

:mod:`.kalman` is the filter core as plain functions; :mod:`.common` holds
what the filters share (settings, output, INS-error conventions, the LEO
aids' error models); :mod:`.engine` is the one INS error-state filter over
time-ordered aids (:mod:`.aids`; each satellite's Doppler,
:mod:`.aids_leo`, tight coupling, ours; LEO position/velocity fixes, loose
coupling, :mod:`.aids_fix`, [Shen 2024] eq. 13-16; GNSS code and phase,
:mod:`.aids_gnss`), whose result :mod:`.record` keeps.
"""
