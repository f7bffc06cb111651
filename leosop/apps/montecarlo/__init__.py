"""Monte Carlo sweeps of the ``simulate`` flight over scenario parameters and seeds.

``leosop study montecarlo SPEC.json`` in modules with one job each:

- :mod:`.parameters`: what can be swept (run options, scenario fields, IMU grades);
- :mod:`.spec`: the JSON spec, checked field by field, and the seeds (one
  ``numpy.random.SeedSequence``);
- :mod:`.runs`: one simulation reduced to a row of metrics;
- :mod:`.execute`: chunks run serially or on Dask, bounded in flight, each kept on
  disk when finished (:mod:`leosop.chunkstore`: resume after an interruption);
- :mod:`.dataset`: the xarray Dataset (parameter axes x seed) and its NetCDF file.

Its figures (error against each parameter with its spread over seeds) are in
:mod:`leosop.plots.montecarlo`.
"""

from .dataset import cell_table, to_dataset, write_netcdf
from .execute import StudyRun, chunk_runs, run_study
from .parameters import IMU_GRADES, PARAMETERS
from .runs import METRICS, REPRODUCIBLE
from .spec import StudySpec, bundled_specs, load_spec, run_seeds, spec_from_dict

__all__ = ["IMU_GRADES", "PARAMETERS", "METRICS", "REPRODUCIBLE", "StudySpec", "StudyRun", "load_spec",
           "spec_from_dict", "bundled_specs", "run_seeds", "chunk_runs", "run_study", "to_dataset", "write_netcdf",
           "cell_table"]
