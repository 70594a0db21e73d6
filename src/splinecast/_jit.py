"""The one place that says how splinecast compiles its kernels.

``error_model="numpy"`` makes a float division by zero give inf/NaN as in numpy instead of raising,
which removes a branch from every division in the hot loops; the kernels handle those values
explicitly. ``cache=True`` stores compiled code on disk so only the first run compiles.
``nogil=True`` releases the GIL while compiled code runs, so a server (the browser viewer) can
render in a worker thread while its event loop keeps answering.
"""

from __future__ import annotations

from functools import partial

from numba import njit

__all__ = ["jit"]

#: Decorator for every compiled function in splinecast (accepts njit keyword arguments).
jit = partial(njit, cache=True, nogil=True, error_model="numpy")
