"""End-to-end simulation of [Shen 2024]'s experiment: truth flight, IMU, LEO Doppler, fixes, loose or tight EKF.

:func:`run_scenario` is the one entry point; the ``simulate`` command and the
table reproductions call it (:mod:`leosop.apps.simulate.run`). For a scenario it

1. flies the truth trajectory and corrupts its ideal IMU increments
   ([Shen 2024] Table 1; bias signs drawn per run), both made a block at a
   time and consumed as made (the INS alone, then the EKF, read the same
   numbers), so that memory does not grow with the run's duration;
2. finds the visible satellites at the fix rate, 1 Hz (:mod:`leosop.orbits.visibility`),
   each family above its own mask (``leo.mask_deg_by_family``, else
   ``mask_deg``), and their true Doppler, plus a constant clock-induced
   offset per satellite drawn uniformly in [0, max] and the receiver's
   fixed offset (:mod:`leosop.apps.simulate.sky`: which satellites, with which models);
3. measures every Doppler, either at signal level (a pilot block per
   satellite-epoch, estimated by the ``fast`` estimator) or at measurement
   level (the estimator's error model); the families of ``leo.constellations``
   without a pilot comb always at measurement level (the sigma model of
   :mod:`leosop.constellations`), each on its own carrier with its own
   receiver offset (:mod:`leosop.apps.simulate.measure`);
   in an outage (``leo.outage_s``) only the highest few are tracked;
4. solves a snapshot Doppler fix per epoch with 6 + k or more satellites
   (one receiver clock per constellation seen), with
   satellite positions carrying a constant orbit error (one per satellite,
   or one shift of all: ``leo.orbit_error_model``);
5. runs the INS alone and the EKF: loose (the fix aids of
   :mod:`leosop.fusion.aids_fix` in :mod:`leosop.fusion.engine`, each fix
   with its least-squares gain so that the filter can model the
   satellites' constant errors behind them) or tight
   (:mod:`leosop.apps.simulate.tight`, each Doppler an aid of the engine); both
   model the orbit errors as the scenario draws them (independent or common).

Steps 3 and 4 go through the run :data:`~leosop.apps.simulate.measure.FIX_BLOCK_EPOCHS` epochs at a
time, keeping only each epoch's fix and what the EKF needs of it.

Randomness: one ``numpy.random.SeedSequence(seed)`` spawns independent
streams for the IMU, the satellite offsets and orbit errors, and the
measurement noise, so that the IMU errors of a seed are the same at both
levels and for every correction period. The measurement noise is drawn
block by block (in a block, the pilot blocks at signal level first), which
is the same sequence as one block whenever one level measures all pairs.

The fix's weights account for every error source the receiver knows the
size of: estimator noise, the spread of the satellite offsets about their
mean (the mean is absorbed by the receiver offset of the satellite's
constellation) and the orbit error mapped
through the Doppler's sensitivity to the satellite position. The loose EKF
takes only the estimator noise as white (its ``R``) and the offsets and orbit
errors as constant states (:func:`~leosop.apps.simulate.measure.fix_error_model`).

The result, its JSON document and solution table: :mod:`leosop.apps.simulate.result`.
"""

from .result import SimulationResult, aided, fusion_label, metrics, solution_table
from .run import COUPLINGS, LEVELS, run_scenario

__all__ = ["COUPLINGS", "LEVELS", "SimulationResult", "aided", "fusion_label", "metrics", "run_scenario",
           "solution_table"]
