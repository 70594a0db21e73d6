"""Cubic C1 splines on the type-6 partition (S31): the quasi-interpolant of Sorokina &
Zeilfelder 2007 as rendered by Kalbe et al. 2009 and Koch 2009.

Each cube carries 175 distinct Bernstein–Bézier coefficients (20 per tetrahedron), each a fixed
average of the 27 data values around the cube. The rules below give the 13 domain-point classes
of the reference tetrahedron T0 (derived for this project from the C1 conditions in exact
arithmetic and checked by ``tests/test_type6_coefficients.py``; see :mod:`.type6_geometry` for
T0 and the letter names of the data offsets); the
other 162 coefficients follow by the cube's symmetries in :func:`~.type6_geometry.derive_tables`.
Every weight is non-negative and every rule sums to 1, so the patch lies in the range of the 27
data values. The spline is C1 everywhere, reproduces linear functions and gives
``q + Delta q / 8`` (index units) for a quadratic ``q``; ``prefilter=True`` removes that term.
"""

from __future__ import annotations

from fractions import Fraction as F
from functools import lru_cache

from ..volume import Volume
from .type6 import S31Grid, Type6Model, register_scheme
from .type6_geometry import Type6Program, Type6Tables, derive_program, derive_tables, parse_rules

__all__ = ["S31_RULES", "S31_CHAIN", "S31Model", "s31_tables", "s31_program"]

#: Weights of the 13 coefficient classes on T0 (multi-index (i, j, k, l) on [v0, v1, v2, v3]).
S31_RULES = {
    (0, 0, 3, 0): [(F(1, 8), "i f l t fl lt ft flt")],
    (0, 0, 2, 1): [(F(5, 24), "i f t ft"), (F(1, 24), "l fl lt flt")],
    (0, 1, 1, 1): [(F(13, 48), "i f"), (F(7, 48), "t ft"), (F(1, 32), "l r fl fr"),
                   (F(1, 96), "lt rt flt frt")],
    (0, 1, 2, 0): [(F(5, 24), "i f"), (F(1, 8), "l t fl ft"), (F(1, 24), "lt flt")],
    (0, 2, 1, 0): [(F(13, 48), "i f"), (F(17, 192), "l t fl ft"), (F(1, 64), "r d fr fd"),
                   (F(1, 96), "lt flt"), (F(1, 192), "rt ld frt fld")],
    (0, 3, 0, 0): [(F(13, 48), "i f"), (F(5, 96), "l r t d fl fr ft fd"),
                   (F(1, 192), "lt rt ld rd flt frt fld frd")],
    (1, 0, 2, 0): [(F(1, 4), "i"), (F(1, 6), "f l t"), (F(1, 12), "fl ft lt")],
    (1, 0, 1, 1): [(F(1, 3), "i"), (F(5, 24), "f t"), (F(1, 12), "ft"), (F(1, 24), "l r"),
                   (F(1, 48), "fl fr lt rt")],
    (1, 1, 1, 0): [(F(1, 3), "i"), (F(5, 24), "f"), (F(1, 8), "l t"), (F(5, 96), "fl ft"),
                   (F(1, 48), "r d lt"), (F(1, 96), "fr fd rt ld")],
    (1, 2, 0, 0): [(F(1, 3), "i"), (F(5, 24), "f"), (F(7, 96), "l r t d"),
                   (F(1, 32), "fl fr ft fd"), (F(1, 96), "lt rt ld rd")],
    (2, 0, 1, 0): [(F(3, 8), "i"), (F(7, 48), "f l t"), (F(1, 48), "fl ft lt b r d"),
                   (F(1, 96), "bl bt fr fd rt ld")],
    (2, 1, 0, 0): [(F(3, 8), "i"), (F(7, 48), "f"), (F(1, 12), "l r t d"), (F(1, 48), "b"),
                   (F(1, 64), "fl fr ft fd"), (F(1, 96), "lt rt ld rd"),
                   (F(1, 192), "bl br bt bd")],
    (3, 0, 0, 0): [(F(3, 8), "i"), (F(1, 12), "f b l r t d"),
                   (F(1, 96), "fl fr ft fd bl br bt bd lt rt ld rd")],
}


#: The same scheme as a local averaging chain (note, "local averaging chain"), used to compute all
#: 175 coefficients of a cube with about a quarter of the multiply-adds of the direct rules.
#: ``"@x y z"`` refers to the point computed earlier; ``derive_program`` verifies the result
#: against the rules above in exact arithmetic.
S31_CHAIN = [
    ("0 1/2 1/2", [(F(1, 4), "i f t ft")]),  # auxiliary: mean at the cube-edge midpoint
    ("-1/2 1/2 1/2", [(F(1, 8), "i f l t fl lt ft flt")]),  # b0030 corner
    ("-1/6 1/2 1/2", [(F(2, 3), "@0 1/2 1/2"), (F(1, 3), "@-1/2 1/2 1/2")]),  # b0021
    ("0 1/2 1/3", [(F(1, 2), "@0 1/2 1/2"), (F(1, 12), "@-1/2 1/2 0"),  # b0111
                   (F(1, 12), "@1/2 1/2 0"), (F(1, 12), "@-1/2 1/2 1/2"),
                   (F(1, 12), "@1/2 1/2 1/2"), (F(1, 12), "i f")]),
    ("-1/3 1/2 1/3", [(F(1, 2), "@-1/6 1/2 1/2"), (F(1, 2), "@-1/2 1/2 1/6")]),  # b0120
    ("-1/6 1/2 1/6", [(F(1, 2), "@0 1/2 1/3"), (F(1, 2), "@-1/3 1/2 0")]),  # b0210
    ("0 1/2 0", [(F(1, 4), "@1/6 1/2 1/6"), (F(1, 4), "@-1/6 1/2 1/6"),  # b0300
                 (F(1, 4), "@1/6 1/2 -1/6"), (F(1, 4), "@-1/6 1/2 -1/6")]),
    ("-1/3 1/3 1/3", [(F(1), "@-1/3 1/2 1/3"), (F(1), "@-1/3 1/3 1/2"),  # b1020
                      (F(-1, 2), "@-1/2 1/2 1/2"), (F(-1, 2), "@-1/6 1/2 1/2")]),
    ("0 1/3 1/3", [(F(1), "@0 1/2 1/3"), (F(1), "@0 1/3 1/2"),  # b1011
                   (F(-1, 2), "@-1/6 1/2 1/2"), (F(-1, 2), "@1/6 1/2 1/2")]),
    ("-1/6 1/3 1/6", [(F(1, 2), "@0 1/3 1/3"), (F(1, 2), "@-1/3 1/3 0")]),  # b1110
    ("0 1/3 0", [(F(1, 2), "@-1/6 1/3 1/6"), (F(1, 2), "@1/6 1/3 -1/6")]),  # b1200
    ("-1/6 1/6 1/6", [(F(1), "@-1/6 1/3 1/6"), (F(1), "@-1/6 1/6 1/3"),  # b2010
                      (F(-1, 2), "@-1/3 1/3 1/3"), (F(-1, 2), "@0 1/3 1/3")]),
    ("0 1/6 0", [(F(1, 2), "@-1/6 1/6 1/6"), (F(1, 2), "@1/6 1/6 -1/6")]),  # b2100
    ("0 0 0", [(F(1), "@0 1/6 0"), (F(1), "@0 0 1/6"),  # b3000
               (F(-1, 2), "@-1/6 1/6 1/6"), (F(-1, 2), "@1/6 1/6 1/6")]),
]


@lru_cache(maxsize=1)
def s31_tables() -> Type6Tables:
    """The derived S31 tables (175 points per cube), computed once per process."""
    return derive_tables(3, parse_rules(S31_RULES))


@lru_cache(maxsize=1)
def s31_program() -> Type6Program:
    """The verified evaluation program of :data:`S31_CHAIN`, computed once per process."""
    return derive_program(s31_tables(), S31_CHAIN)


#: The S31 scheme's number among the cubic schemes (:func:`~.type6.register_scheme`).
S31_SCHEME = register_scheme(S31Grid, s31_program)


class S31Model(Type6Model):
    """Cubic C1 spline on the type-6 partition.

    Parameters
    ----------
    volume : Volume
        The data.
    prefilter : bool, optional
        Apply ``f - Delta_h f / 8`` to the data first: exact on quadratics, value error of order
        about 3 instead of 2 on smooth data.
    precompute : bool, optional
        Keep the 175 coefficients of every active cube after an isovalue change (faster frames,
        ``n_active * 1400`` bytes) instead of computing them on the fly (default).
    root_finder : str, optional
        ``"bernstein"`` (default: guaranteed first root by Bernstein subdivision) or
        ``"newton"`` (the references' Newton iteration from three starts; can miss a root).

    Examples
    --------
    >>> import splinecast as sc
    >>> model = S31Model(sc.demo("sphere", size=16))
    >>> model.n_points
    175
    """

    name = "s31"
    typical_compile_s = 80
    degree = 3

    def __init__(self, volume: Volume, prefilter: bool = False, precompute: bool = False,
                 root_finder: str = "bernstein") -> None:
        super().__init__(volume, s31_tables(), prefilter=prefilter, precompute=precompute,
                         root_finder=root_finder, scheme=S31_SCHEME)

