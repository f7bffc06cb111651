"""Applications: what the commands run on top of the library.

The library below (``constellations``, ``orbits``, ``signal``, ``replay``,
``geometry``, ``positioning``, ``ins``, ``fusion``, ``gnss`` and the base
modules at the top of :mod:`leosop`) computes; the applications here put it
to a use, as the DESIGN's layout draws them:

:mod:`.scenarios`
    the fusion scenarios (bundled JSON files and built-ins) that ``simulate`` flies
:mod:`.simulate`
    ``leosop simulate``: [Shen 2024]'s experiment end to end (sky, Doppler, fixes, loose or tight EKF)
:mod:`.fuse_leo`
    the LEO Doppler of ``leosop fuse``: read from a table or simulated along the GNSS reference
:mod:`.studies`
    the Dask-parallel grid studies (chunked map over a parameter grid)
:mod:`.montecarlo`
    ``leosop study montecarlo``: study specs, parameter grids and seeds, runs, the NetCDF dataset
:mod:`.repro`
    ``leosop reproduce``: every table and figure of the seed papers, ours beside theirs
:mod:`.export`
    GeoJSON, KML and NMEA writers of ``leosop export`` and ``fuse --out``

Dependencies point one way: an application imports the library (and other
applications, and :mod:`leosop.plots` for its figures); no library module
imports an application, and only :mod:`leosop.cli` imports :mod:`.repro`
(tests/project/test_layers.py holds these rules).
"""
