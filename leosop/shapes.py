"""Array-shape checks shared by every module: check and say, never guess."""

import numpy as np

__all__ = ["as_vec3", "as_dcm", "stack_last"]


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


def stack_last(parts, ndim=1):
    """Same-shape arrays (...) nested ``ndim`` lists deep as one array, the lists' axes last.

    ``stack_last([x, y, z])`` is ``np.stack([x, y, z], axis=-1)``, shape (..., 3);
    ``stack_last(rows, 2)`` is ``np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)``,
    shape (..., n, m): the same values in a C-contiguous array, without the cost of ``np.stack``
    on the small arrays of a filter's step.
    """
    arr = np.array(parts, dtype=float)
    if arr.ndim == ndim:
        return arr
    return np.ascontiguousarray(arr.transpose(tuple(range(ndim, arr.ndim)) + tuple(range(ndim))))
