"""leosop: navigation with LEO satellite signals of opportunity.

Conventions, written once and followed everywhere
--------------------------------------------------
Units
    SI inside (m, s, rad, Hz). Degrees appear only at the edges (CLI, files,
    JSON) in names ending ``_deg``. Accelerometer and gyro errors are quoted
    in g, deg/h, deg/sqrt(h), g/sqrt(Hz) only in names that say so.
Frames
    ``e`` ECEF (ITRF; polar motion neglected, see :func:`frames.teme_to_ecef`),
    ``t`` TEME (SGP4 output), ``n`` the local navigation frame East-North-Up,
    ``b`` the body frame Right-Forward-Up. Rotations are ``C_to_from`` so that
    ``C_n_b @ f_b`` is ``f_n``. Euler angles: ``C_n_b = Rz(yaw) Rx(pitch)
    Ry(roll)``; pitch nose-up positive, roll right-wing-down positive, yaw
    counter-clockwise from North; the heading reported to users is clockwise
    from North in [0, 360) deg (:mod:`leosop.rotations`). Papers with other
    conventions are converted at the edge of the module that implements them.
Names
    Unit and frame in every name that crosses a module boundary:
    ``pos_ecef_m``, ``vel_enu_mps``, ``doppler_hz``, ``cn0_dbhz``,
    ``pos_sv_ecef_m`` (satellite), ``pos_rx_ecef_m`` (receiver).
Shapes
    Time first, components last: trajectories ``(n_epochs, 3)``,
    constellations ``(n_sats, n_epochs, 3)``, rotation stacks ``(..., 3, 3)``.
Time
    UTC instants are ``numpy.datetime64[ns]`` at the edges (ISO 8601 with
    ``Z`` in files); inside a run, float seconds ``t_s`` since a stated epoch.
    SGP4 gets split UTC Julian dates; Earth rotation uses UT1 from skyfield's
    bundled IERS table (:mod:`leosop.timebase`).
Doppler sign
    Doppler is received minus nominal frequency, positive when the satellite
    approaches: ``doppler_hz = -range_rate_mps * carrier_hz / c`` plus clock
    offsets. For the pilot comb it is that of the central tone.
Errors
    Batch numerics return failures as data (NaN and a status array). Bad user
    input raises :class:`leosop.errors.InputError`; the CLI prints it as one
    line and exits with status 2.
Randomness
    Only through a ``numpy.random.Generator`` passed in or built from a seed.
"""

__version__ = "0.1.0"
