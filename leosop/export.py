"""Deprecated alias of :mod:`leosop.apps.export`, where this module moved with the applications.

Kept only because the Python API page of 0.1.0 (docs/api.md) gave ``leosop.export.Layer``, ``to_geojson``,
``to_kml``, ``nmea_gga``, ``nmea_rmc`` and ``nmea_checksum`` as entry points; new code imports from
:mod:`leosop.apps.export`.
"""

import warnings

from .apps.export import *  # noqa: F403
from .apps.export import __all__  # noqa: F401

warnings.warn("leosop.export moved to leosop.apps.export", DeprecationWarning, stacklevel=2)
