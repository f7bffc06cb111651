"""Constellations: the one registry of family facts (carrier, signal, clock, mask and sigma models).

Imports only the base modules, so that every stage (orbits, signal,
positioning, replay, the applications) can read it. See :mod:`.registry`.
"""

from .registry import (DEFAULT_FAMILY, REGISTRY, CombModel, Family, carriers_hz, clock_scale, family, family_of,
                       tone_sigma_hz)

__all__ = ["DEFAULT_FAMILY", "REGISTRY", "CombModel", "Family", "carriers_hz", "clock_scale", "family", "family_of",
           "tone_sigma_hz"]
