"""Deprecated alias of :mod:`leosop.apps.scenarios`, where this module moved with the applications.

Kept only because the Python API page of 0.1.0 (docs/api.md) gave ``leosop.scenarios.load_scenario`` and
``scenario_from_dict`` as entry points; new code imports from :mod:`leosop.apps.scenarios`.
"""

import warnings

from .apps.scenarios import *  # noqa: F403
from .apps.scenarios import __all__  # noqa: F401

warnings.warn("leosop.scenarios moved to leosop.apps.scenarios", DeprecationWarning, stacklevel=2)
