"""Array-shape checks shared by every module: check and say, never guess."""

import numpy as np

__all__ = ["as_vec3", "as_dcm"]


def as_vec3(x, name):
    """``x`` as a float array with 3 components in its last axis, else ValueError naming it."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != 3:
        raise ValueError(f"{name} must have 3 components in its last axis, got shape {x.shape}")
    return x


def as_dcm(C, name="C_n_b"):
    """``C`` as a float array of shape (..., 3, 3), else ValueError naming it."""
    C = np.asarray(C, dtype=float)
    if C.ndim < 2 or C.shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (..., 3, 3), got {C.shape}")
    return C
