"""Optional compiled (numba) kernels: loading a kernel module, and what a ``kernel`` argument picks.

Each compiled path has its numpy twin as fallback and reference: the map's
per-pair work (:mod:`leosop.orbits.gridkernels`), the generator's combs
(:mod:`leosop.signal.combkernels`), the replay's comb fits
(:mod:`leosop.signal.fitkernels`) and its cleaning's line finding
(:mod:`leosop.signal.cleankernels`). A kernel module imports numba at its top,
so it loads only where numba is installed (``pip install leosop[fast]``).
"""

import functools
import importlib

from .errors import InputError

__all__ = ["KERNELS", "compiled", "pick"]

#: The values of a ``kernel`` argument: None (numba when installed), "numba" or "numpy".
KERNELS = (None, "numba", "numpy")


@functools.cache
def compiled(module):
    """The kernel module ``module`` (absolute dotted name), or None when numba is not installed."""
    try:
        return importlib.import_module(module)
    except ImportError:
        return None


def pick(kernel, module):
    """What ``kernel`` picks: ``module``'s kernels for "numba" (None: when installed), None for "numpy".

    Raises
    ------
    InputError
        ``kernel`` not one of :data:`KERNELS`, or "numba" without numba installed.
    """
    if kernel not in KERNELS or (kernel == "numba" and compiled(module) is None):
        raise InputError(f"kernel {kernel!r}: expected 'numpy' or 'numba' (needs numba: pip install leosop[fast])")
    return None if kernel == "numpy" else compiled(module)
