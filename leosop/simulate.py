"""Deprecated alias of :mod:`leosop.apps.simulate`, where this module moved with the applications.

Kept only because the Python API page of 0.1.0 (docs/api.md) gave ``leosop.simulate.run_scenario``,
``metrics``, ``solution_table`` and ``leosop.simulate.tight.run`` as entry points; new code imports from
:mod:`leosop.apps.simulate`.
"""

import warnings

from .apps.simulate import *  # noqa: F403
from .apps.simulate import __all__, tight  # noqa: F401

warnings.warn("leosop.simulate moved to leosop.apps.simulate", DeprecationWarning, stacklevel=2)
