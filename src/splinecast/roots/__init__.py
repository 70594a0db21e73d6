"""Univariate polynomial root finding (compiled with Numba).

Only the pieces the trilinear renderer needs live here so far: a stable quadratic solver and a
safeguarded first-root solver for cubics on an interval.
"""

from .cubic import cubic_first_root, quadratic_roots

__all__ = ["cubic_first_root", "quadratic_roots"]
