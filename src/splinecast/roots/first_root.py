"""The root finders by name: ids for compiled kernels and a convenience front end.

=============  ======================================================  ===========  ==========
name           method                                                  input form   budget
=============  ======================================================  ===========  ==========
``bernstein``  subdivision at the polygon crossing (Lane-Riesenfeld)    Bernstein    subdivisions
``rfbs``       de Casteljau isolation + regula falsi / bisection       Bernstein    per phase
``sturm``      Sturm sequence + bisection                              power        bisections
``newton``     Newton from the segment start (baseline, no guarantee)  power        Newton steps
=============  ======================================================  ===========  ==========

Kernels call :func:`first_root_by_id` with preallocated scratch space; Python code calls
:func:`find_first_root`, which converts the coefficients to the form the method works in.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit
from ..errors import ParameterError
from .bernstein import bernstein_to_power, power_to_bernstein
from .newton import NEWTON_ITERATIONS, newton_root_work
from .rfbs import RFBS_ITERATIONS, rfbs_first_root_work
from .sturm import STURM_ITERATIONS, sturm_first_root_work
from .subdivision import SUBDIVISION_ITERATIONS, subdivision_first_root_work

__all__ = [
    "ROOT_FINDERS",
    "DEFAULT_ITERATIONS",
    "POWER_FORM_FINDERS",
    "finder_id",
    "first_root_by_id",
    "find_first_root",
    "root_workspace",
]

#: Root finder id by name (the id is what compiled kernels receive).
ROOT_FINDERS = {"bernstein": 0, "rfbs": 1, "sturm": 2, "newton": 3}
#: Default iteration budget by name.
DEFAULT_ITERATIONS = {
    "bernstein": SUBDIVISION_ITERATIONS,
    "rfbs": RFBS_ITERATIONS,
    "sturm": STURM_ITERATIONS,
    "newton": NEWTON_ITERATIONS,
}
#: Ids of the finders that take power-form coefficients (the others take Bernstein form).
POWER_FORM_FINDERS = (2, 3)


def finder_id(name: str) -> int:
    """Id of a root finder name; raises :class:`ParameterError` for an unknown one."""
    if name not in ROOT_FINDERS:
        raise ParameterError(
            f"root_finder must be one of {', '.join(ROOT_FINDERS)}, got {name!r}"
        )
    return ROOT_FINDERS[name]


def root_workspace(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Scratch arrays for :func:`first_root_by_id` at degree ``n``: ``(work, degrees)``."""
    return np.empty((n + 1, n + 1)), np.empty(n + 1, dtype=np.int64)


@jit()
def first_root_by_id(
    fid: int, coeffs: np.ndarray, n: int, iterations: int, tol: float, work: np.ndarray,
    degrees: np.ndarray,
) -> float:
    """First root in ``[0, 1]`` with root finder ``fid`` (see :data:`ROOT_FINDERS`).

    ``coeffs`` are control points for ids 0 and 1 and power coefficients for ids 2 and 3;
    ``work`` (shape at least ``(max(n + 1, 2), n + 1)``) and ``degrees`` come from
    :func:`root_workspace`. Returns NaN when no root is found.
    """
    if fid == 0:
        return subdivision_first_root_work(coeffs, n, iterations, tol, work[0], work[1])
    if fid == 1:
        return rfbs_first_root_work(coeffs, n, iterations, tol, work[0], work[1])
    if fid == 2:
        return sturm_first_root_work(coeffs, n, iterations, tol, work, degrees)
    return newton_root_work(coeffs, n, iterations, tol)


def find_first_root(
    coeffs: np.ndarray,
    method: str = "bernstein",
    form: str = "bernstein",
    iterations: int | None = None,
    tol: float = 1e-12,
) -> float:
    """First root in ``[0, 1]`` of a polynomial with any of the root finders.

    Parameters
    ----------
    coeffs : array_like
        The polynomial's coefficients in ``form``.
    method : str
        ``"bernstein"``, ``"rfbs"``, ``"sturm"`` or ``"newton"`` (see the module docstring).
    form : str
        ``"bernstein"`` (control points) or ``"power"`` (ascending powers). The coefficients are
        converted in float64 when the method works in the other form.
    iterations : int, optional
        Iteration budget (default :data:`DEFAULT_ITERATIONS` of the method).
    tol : float
        Convergence tolerance in the parameter.

    Returns
    -------
    float
        The root, or NaN when none is found.

    Examples
    --------
    >>> round(find_first_root([0.25, -1.0, 1.0], method="sturm", form="power"), 9)
    0.5
    """
    fid = finder_id(method)
    if form not in ("bernstein", "power"):
        raise ParameterError(f"form must be 'bernstein' or 'power', got {form!r}")
    c = np.ascontiguousarray(coeffs, dtype=np.float64).reshape(-1)
    if c.size < 1:
        raise ParameterError("coeffs must hold at least one coefficient")
    n = c.size - 1
    wants_power = fid in POWER_FORM_FINDERS
    if wants_power and form == "bernstein":
        converted = np.empty(n + 1)
        bernstein_to_power(c, n, converted)
        c = converted
    elif not wants_power and form == "power":
        converted = np.empty(n + 1)
        power_to_bernstein(c, n, converted)
        c = converted
    if iterations is None:
        iterations = DEFAULT_ITERATIONS[method]
    if int(iterations) < 0:
        raise ParameterError(f"iterations must be >= 0, got {iterations}")
    work, degrees = root_workspace(max(n, 1))
    return float(first_root_by_id(fid, c, n, int(iterations), float(tol), work, degrees))
