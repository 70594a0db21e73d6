"""Quadratic super splines on the type-6 partition (QSS) of Rössl et al. 2004, as rendered by
Kalbe et al. 2009 and Koch 2009, in two variants.

Each cube carries 65 distinct Bernstein–Bézier coefficients (10 per tetrahedron). The boundary
rules (cube corners, cube-edge midpoints, face points) are those of the papers; the interior
rules come in two symmetric variants (derived for this project in exact arithmetic and checked
by ``tests/test_type6_coefficients.py``):

``"qss-b"`` (default)
    The super-spline definition: C1 across cube faces, at cube corners and at face centres, C0
    across the interior faces. Some weights are negative (absolute row sums up to 9/8), so a
    patch is bounded by its own coefficients, not by the data range (see
    :func:`~.type6.cube_bounds`).
``"qss-a"``
    All weights non-negative; C1 across cube faces and across the [centre, face centre, corner]
    faces, only C0 across the [centre, cube-edge] faces and not C1 at cube corners.

Both reproduce linear functions and have approximation order 2. No C1 quadratic quasi-interpolant
with a 27-value stencil exists on this partition, so a QSS is continuous but not smooth
everywhere: expect faint creases in the shading that S31 does not have.
"""

from __future__ import annotations

from fractions import Fraction as F
from functools import lru_cache, partial

from ..errors import ParameterError
from ..volume import Volume
from .type6 import QSSGrid, Type6Model, register_scheme
from .type6_geometry import Type6Program, Type6Tables, derive_program, derive_tables, parse_rules

__all__ = ["QSS_BOUNDARY_RULES", "QSS_B_RULES", "QSS_A_RULES", "QSSModel", "qss_tables",
           "VARIANTS", "CHAINS", "qss_program"]

#: Rules shared by both variants (points on the cube's boundary).
QSS_BOUNDARY_RULES = {
    (0, 0, 2, 0): [(F(1, 8), "i f l t fl lt ft flt")],
    (0, 0, 1, 1): [(F(1, 4), "i f t ft")],
    (0, 1, 1, 0): [(F(1, 4), "i f"), (F(1, 8), "l t fl ft")],
    (0, 2, 0, 0): [(F(1, 4), "i f"), (F(1, 16), "l r t d fl fr ft fd")],
}

#: Interior rules of QSS-B (smooth at cube corners).
QSS_B_RULES = {
    (1, 0, 1, 0): [(F(5, 16), "i"), (F(3, 16), "f l t"), (F(1, 16), "fl ft lt"),
                   (F(-1, 16), "flt")],
    (1, 1, 0, 0): [(F(5, 16), "i"), (F(3, 16), "f"), (F(3, 32), "l r t d"),
                   (F(1, 32), "fl fr ft fd"), (F(1, 64), "lt rt ld rd"),
                   (F(-1, 64), "flt frt fld frd")],
    (2, 0, 0, 0): [(F(5, 16), "i"), (F(3, 32), "f b l r t d"),
                   (F(1, 64), "fl fr ft fd bl br bt bd lt rt ld rd"),
                   (F(-1, 128), "flt frt fld frd blt brt bld brd")],
}

#: Interior rules of QSS-A (all weights non-negative).
QSS_A_RULES = {
    (1, 0, 1, 0): [(F(1, 4), "i f l t")],
    (1, 1, 0, 0): [(F(1, 4), "i f"), (F(1, 8), "l r t d")],
    (2, 0, 0, 0): [(F(1, 4), "i"), (F(1, 8), "f b l r t d")],
}

#: Local averaging chains (the rules' "local form"), verified by ``derive_program``.
QSS_BOUNDARY_CHAIN = [
    ("-1/2 1/2 1/2", [(F(1, 8), "i f l t fl lt ft flt")]),  # b0020 corner
    ("0 1/2 1/2", [(F(1, 4), "i f t ft")]),  # b0011 cube-edge midpoint
    ("-1/4 1/2 1/4", [(F(1, 2), "@0 1/2 1/2"), (F(1, 2), "@-1/2 1/2 0")]),  # b0110
    ("0 1/2 0", [(F(1, 4), "@0 1/2 1/2"), (F(1, 4), "@0 1/2 -1/2"),  # b0200
                 (F(1, 4), "@1/2 1/2 0"), (F(1, 4), "@-1/2 1/2 0")]),
]
QSS_B_CHAIN = [
    ("-1/4 1/4 1/4", [(F(1), "@-1/4 1/2 1/4"), (F(1), "@-1/4 1/4 1/2"),  # b1010
                      (F(-1, 2), "@-1/2 1/2 1/2"), (F(-1, 2), "@0 1/2 1/2")]),
    ("0 1/4 0", [(F(1, 4), "@1/4 1/4 1/4"), (F(1, 4), "@-1/4 1/4 1/4"),  # b1100
                 (F(1, 4), "@1/4 1/4 -1/4"), (F(1, 4), "@-1/4 1/4 -1/4")]),
    ("0 0 0", [(F(1, 8), f"@{x} {y} {z}") for x in ("1/4", "-1/4") for y in ("1/4", "-1/4")
               for z in ("1/4", "-1/4")]),  # b2000
]

#: Variant name -> interior rules.
VARIANTS = {"qss-b": QSS_B_RULES, "qss-a": QSS_A_RULES}
#: Variant name -> evaluation chain (QSS-A's interior points keep their direct rules).
CHAINS = {"qss-b": QSS_BOUNDARY_CHAIN + QSS_B_CHAIN, "qss-a": QSS_BOUNDARY_CHAIN}


@lru_cache(maxsize=2)
def qss_tables(variant: str = "qss-b") -> Type6Tables:
    """The derived tables (65 points per cube) of a variant, computed once per process."""
    return derive_tables(2, parse_rules({**QSS_BOUNDARY_RULES, **VARIANTS[variant]}))


@lru_cache(maxsize=2)
def qss_program(variant: str = "qss-b") -> Type6Program:
    """The verified evaluation program of a variant's chain, computed once per process."""
    return derive_program(qss_tables(variant), CHAINS[variant])


#: Variant name -> its number among the quadratic schemes (:func:`~.type6.register_scheme`).
QSS_SCHEMES = {v: register_scheme(QSSGrid, partial(qss_program, v)) for v in VARIANTS}


class QSSModel(Type6Model):
    """Quadratic super spline on the type-6 partition.

    Parameters
    ----------
    volume : Volume
        The data.
    variant : str, optional
        ``"qss-b"`` (default) or ``"qss-a"``.
    precompute : bool, optional
        Keep the 65 coefficients of every active cube after an isovalue change.
    root_finder : str, optional
        Accepted for a uniform interface; the quadratic's first root is always found in closed
        form (stable quadratic formula on the Bernstein coefficients).
    prefilter : bool, optional
        Not defined for QSS (only ``False`` is accepted).
    """

    name = "qss"
    typical_compile_s = 60
    degree = 2

    def __init__(self, volume: Volume, variant: str = "qss-b", precompute: bool = False,
                 root_finder: str = "bernstein", prefilter: bool = False) -> None:
        if variant not in VARIANTS:
            raise ParameterError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        if prefilter:
            raise ParameterError("prefilter is only available for model s31")
        self.variant = variant
        super().__init__(volume, qss_tables(variant), prefilter=False, precompute=precompute,
                         root_finder=root_finder, scheme=QSS_SCHEMES[variant])
