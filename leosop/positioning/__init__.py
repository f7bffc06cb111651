"""Positioning: Doppler least squares and dilution of precision.

The public names, importable from here (``from leosop.positioning import
position_static``); each is imported from its module on first use
(:mod:`leosop.lazy`), so ``import leosop.positioning`` stays light.

Measurement tables:
    ``Measurements``           a Doppler table (DESIGN 4.3): times, satellites, Doppler, sigmas
    ``read_measurements``      read a measurement CSV; bad rows set aside with their reason
    ``write_measurements``     write a measurement CSV (atomically)
    ``sv_states_from_tle``     satellite ECEF states from element sets, with light time
    ``read_doptrack``          DopTrack passes (Delfi-C3) -> ``DopTrackPass`` with ground truth
    ``read_fll``               a GNU Radio FLL Doppler log (e.g. FOX-1D) -> ``Measurements``
    ``read_gsdc``              Google Smartphone Decimeter Challenge L1/E1 rows -> ``GsdcEpochs``
    ``DopTrackPass``           one DopTrack pass: measurements, element set, station position
    ``GsdcEpochs``             GSDC Doppler with the phone's clock-drift estimate

Fixes from a table (what ``leosop position`` runs):
    ``position_snapshots``     one fix per epoch -> ``PositionResult`` of ``SnapshotFixes``
    ``position_static``        a receiver at rest, one clock polynomial -> ``StaticFix``
    ``position_static_passes`` at rest, per-pass clock terms and time offsets -> ``PassesFix``
    ``solve_pair``             differential fix of a rover table against a base table
    ``satellite_states``       the states a table's rows get: its columns, else element sets
    ``PositionResult``         fixes with the rows, rejections and sigmas that produced them
    ``DifferentialPair``       a differential fix with the rows of both tables it used

Solvers on arrays:
    ``solve_snapshots``        snapshot fixes ([Shen 2024] eq. 4-12), many epochs at once
    ``solve_static``           static batch fix (and a single pass's mirror solution)
    ``solve_static_passes``    static fix from several passes, linear terms eliminated
    ``solve_differential``     rover fix from single differences against a known base
    ``solve_differential_carrier`` static rover from carrier phase against a known base (float/fixed)
    ``SnapshotFixes``          snapshot solver output: positions, velocities, clocks, DOPs
    ``StaticFix``              static solver output
    ``PassesFix``              multi-pass solver output, with the passes' disagreement
    ``DifferentialFix``        differential solver output, one fix per block
    ``CarrierFix``             differential carrier-phase solver output
    ``FixStatus``              how the numerics ended (``OK``, ``SINGULAR``, ...)
    ``STATUSES``               the fix labels a user filters on (``ok`` only when vouched for)
    ``gdop``                   geometric dilution of precision of a design matrix

Left in their modules: the robust least-squares core
(:mod:`.robust_ls`), the multi-pass model and noise (:mod:`.passes_model`,
:mod:`.passes_noise`), the differential base and simulation
(:mod:`.differential_base`, :mod:`.differential_sim`) and the fix-status
rules (:mod:`.quality`).
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

__all__ = [
    "Measurements", "read_measurements", "write_measurements", "sv_states_from_tle", "read_doptrack", "read_fll",
    "read_gsdc", "DopTrackPass", "GsdcEpochs",
    "position_snapshots", "position_static", "position_static_passes", "solve_pair", "satellite_states",
    "PositionResult", "DifferentialPair",
    "solve_snapshots", "solve_static", "solve_static_passes", "solve_differential", "SnapshotFixes", "StaticFix",
    "PassesFix", "DifferentialFix", "FixStatus", "STATUSES", "gdop", "solve_differential_carrier", "CarrierFix",
]

if TYPE_CHECKING:
    from ..geometry.dop import gdop
    from .datasets import DopTrackPass, GsdcEpochs, read_doptrack, read_fll, read_gsdc
    from .differential import DifferentialFix, solve_differential
    from .differential_carrier import CarrierFix, solve_differential_carrier
    from .differential_pair import DifferentialPair, solve_pair
    from .measurements import Measurements, read_measurements, sv_states_from_tle, write_measurements
    from .quality import STATUSES
    from .robust_ls import FixStatus
    from .snapshot import SnapshotFixes, solve_snapshots
    from .solve import PositionResult, position_snapshots, position_static, position_static_passes, satellite_states
    from .static import StaticFix, solve_static
    from .static_passes import PassesFix, solve_static_passes

__getattr__, __dir__ = lazy_exports(__name__, __file__)
