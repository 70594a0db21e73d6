"""Univariate polynomial root finding (compiled with Numba).

Only the pieces the trilinear renderer needs live here so far: a stable quadratic solver and a
safeguarded first-root solver for cubics on an interval.
"""

# First roots of general polynomials on [0, 1] (bernstein .. subdivision): the B-spline renderer's.
from .bernstein import bernstein_eval, bernstein_to_power, power_to_bernstein, split
from .cubic import cubic_first_root, quadratic_roots
from .first_root import DEFAULT_ITERATIONS, ROOT_FINDERS, find_first_root
from .newton import newton_root
from .rfbs import rfbs_first_root
from .sturm import sturm_first_root
from .subdivision import subdivision_first_root

__all__ = ["cubic_first_root", "quadratic_roots"]
__all__ += [
    "DEFAULT_ITERATIONS", "ROOT_FINDERS", "bernstein_eval", "bernstein_to_power",
    "find_first_root", "newton_root", "power_to_bernstein", "rfbs_first_root", "split",
    "sturm_first_root", "subdivision_first_root",
]
