"""An independent evaluator of the type-6 splines (S31 cubic C1, quadratic super splines QSS-A/B).

Written from the Bernstein-Bezier coefficient rules of the two schemes (a table per scheme below)
and nothing of the package: the rules are given for the class representatives on the reference
tetrahedron ``T0 = [v0, v1, v2, v3]`` (``v0`` the cube centre, ``v1`` the front face centre,
``v2, v3`` the ends of that face's top edge); every other coefficient follows by the 48 symmetries
of the cube, which carry a rule's point and its data offsets alike. A point is evaluated in the
tetrahedron of its cube that holds it: that tetrahedron is the image of ``T0`` under the cube
symmetry that sorts the point's local coordinates into ``|x| <= z <= y``, its coefficients are the
rules of ``T0``'s domain points applied to the data around the cube seen through that symmetry, and
the value comes from de Casteljau's algorithm on them (barycentric coordinates in ``T0``).

Conventions: cube ``c`` centred on voxel ``c`` (index units), side 1; data beyond the volume
repeat the border voxel (the models' edge rule); points are clamped into the domain
``[-0.5, n - 0.5]`` per axis. ``prefilter`` (S31 only) replaces the data by ``f - Delta f / 8``
with the 7-point Laplacian of the edge-extended data.

:func:`check_rules` verifies the transcription: symmetric rules agree wherever two symmetries
send representatives to one point, and each rule's weights sum to one.
"""

from __future__ import annotations

import itertools
from fractions import Fraction as F

import numpy as np

__all__ = ["Type6Reference", "RULES", "check_rules"]

_UNIT = {"i": (0, 0, 0), "r": (1, 0, 0), "l": (-1, 0, 0), "f": (0, 1, 0), "b": (0, -1, 0),
         "t": (0, 0, 1), "d": (0, 0, -1)}


def _offset(name: str) -> tuple[int, int, int]:
    return tuple(int(sum(_UNIT[c][a] for c in name)) for a in range(3))  # type: ignore


def _rule(*terms: tuple[F, str]) -> dict[tuple[int, int, int], F]:
    """``(weight, "i f l t ...")`` terms: each named datum gets the weight."""
    out: dict[tuple[int, int, int], F] = {}
    for weight, names in terms:
        for name in names.split():
            out[_offset(name)] = out.get(_offset(name), F(0)) + weight
    return out


_EDGES = "fl fr ft fd bl br bt bd lt rt ld rd"
_CORNERS = "flt frt fld frd blt brt bld brd"
_S31 = {  # point (x, y, z) on T0 -> rule
    (F(-1, 2), F(1, 2), F(1, 2)): _rule((F(1, 8), "i f l t fl lt ft flt")),
    (F(-1, 6), F(1, 2), F(1, 2)): _rule((F(5, 24), "i f t ft"), (F(1, 24), "l fl lt flt")),
    (F(0), F(1, 2), F(1, 3)): _rule((F(13, 48), "i f"), (F(7, 48), "t ft"),
                                    (F(1, 32), "l r fl fr"), (F(1, 96), "lt rt flt frt")),
    (F(-1, 3), F(1, 2), F(1, 3)): _rule((F(5, 24), "i f"), (F(1, 8), "l t fl ft"),
                                        (F(1, 24), "lt flt")),
    (F(-1, 6), F(1, 2), F(1, 6)): _rule((F(13, 48), "i f"), (F(17, 192), "l t fl ft"),
                                        (F(1, 64), "r d fr fd"), (F(1, 96), "lt flt"),
                                        (F(1, 192), "rt ld frt fld")),
    (F(0), F(1, 2), F(0)): _rule((F(13, 48), "i f"), (F(5, 96), "l r t d fl fr ft fd"),
                                 (F(1, 192), "lt rt ld rd flt frt fld frd")),
    (F(-1, 3), F(1, 3), F(1, 3)): _rule((F(1, 4), "i"), (F(1, 6), "f l t"),
                                        (F(1, 12), "fl ft lt")),
    (F(0), F(1, 3), F(1, 3)): _rule((F(1, 3), "i"), (F(5, 24), "f t"), (F(1, 12), "ft"),
                                    (F(1, 24), "l r"), (F(1, 48), "fl fr lt rt")),
    (F(-1, 6), F(1, 3), F(1, 6)): _rule((F(1, 3), "i"), (F(5, 24), "f"), (F(1, 8), "l t"),
                                        (F(5, 96), "fl ft"), (F(1, 48), "r d lt"),
                                        (F(1, 96), "fr fd rt ld")),
    (F(0), F(1, 3), F(0)): _rule((F(1, 3), "i"), (F(5, 24), "f"), (F(7, 96), "l r t d"),
                                 (F(1, 32), "fl fr ft fd"), (F(1, 96), "lt rt ld rd")),
    (F(-1, 6), F(1, 6), F(1, 6)): _rule((F(3, 8), "i"), (F(7, 48), "f l t"),
                                        (F(1, 48), "fl ft lt b r d"),
                                        (F(1, 96), "bl bt fr fd rt ld")),
    (F(0), F(1, 6), F(0)): _rule((F(3, 8), "i"), (F(7, 48), "f"), (F(1, 12), "l r t d"),
                                 (F(1, 48), "b"), (F(1, 64), "fl fr ft fd"),
                                 (F(1, 96), "lt rt ld rd"), (F(1, 192), "bl br bt bd")),
    (F(0), F(0), F(0)): _rule((F(3, 8), "i"), (F(1, 12), "f b l r t d"), (F(1, 96), _EDGES)),
}
_QSS_BOUNDARY = {
    (F(-1, 2), F(1, 2), F(1, 2)): _rule((F(1, 8), "i f l t fl lt ft flt")),
    (F(0), F(1, 2), F(1, 2)): _rule((F(1, 4), "i f t ft")),
    (F(-1, 4), F(1, 2), F(1, 4)): _rule((F(1, 4), "i f"), (F(1, 8), "l t fl ft")),
    (F(0), F(1, 2), F(0)): _rule((F(1, 4), "i f"), (F(1, 16), "l r t d fl fr ft fd")),
}
_QSS_B = {
    **_QSS_BOUNDARY,
    (F(-1, 4), F(1, 4), F(1, 4)): _rule((F(5, 16), "i"), (F(3, 16), "f l t"),
                                        (F(1, 16), "fl ft lt"), (F(-1, 16), "flt")),
    (F(0), F(1, 4), F(0)): _rule((F(5, 16), "i"), (F(3, 16), "f"), (F(3, 32), "l r t d"),
                                 (F(1, 32), "fl fr ft fd"), (F(1, 64), "lt rt ld rd"),
                                 (F(-1, 64), "flt frt fld frd")),
    (F(0), F(0), F(0)): _rule((F(5, 16), "i"), (F(3, 32), "f b l r t d"), (F(1, 64), _EDGES),
                              (F(-1, 128), _CORNERS)),
}
_QSS_A = {
    **_QSS_BOUNDARY,
    (F(-1, 4), F(1, 4), F(1, 4)): _rule((F(1, 4), "i f l t")),
    (F(0), F(1, 4), F(0)): _rule((F(1, 4), "i f"), (F(1, 8), "l r t d")),
    (F(0), F(0), F(0)): _rule((F(1, 4), "i"), (F(1, 8), "f b l r t d")),
}
#: (degree, rules) per scheme.
RULES = {"s31": (3, _S31), "qss-b": (2, _QSS_B), "qss-a": (2, _QSS_A)}

_T0 = (np.array([F(0)] * 3), np.array([F(0), F(1, 2), F(0)]),
       np.array([F(-1, 2), F(1, 2), F(1, 2)]), np.array([F(1, 2), F(1, 2), F(1, 2)]))


def _symmetries() -> list[np.ndarray]:
    """The 48 signed permutation matrices."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            g = np.zeros((3, 3), dtype=int)
            for row, (col, s) in enumerate(zip(perm, signs, strict=True)):
                g[row, col] = s
            out.append(g)
    return out


def _all_points(rules: dict) -> dict[tuple, dict]:
    """Every image of every rule under the cube's symmetries: point -> rule (checked to agree
    where two symmetries meet)."""
    table: dict[tuple, dict] = {}
    for point, rule in rules.items():
        for g in _symmetries():
            image = tuple(g @ np.array(point, dtype=object))
            moved = {tuple(int(v) for v in g @ np.array(o)): w for o, w in rule.items()}
            if image in table and table[image] != moved:
                raise AssertionError(f"rules disagree at {image}")
            table[image] = moved
    return table


def check_rules(scheme: str) -> None:
    """The rules of ``scheme`` are consistent under the symmetries and sum to one."""
    _, rules = RULES[scheme]
    for rule in _all_points(rules).values():
        assert sum(rule.values()) == 1


_OFFSETS = np.array(list(itertools.product((-1, 0, 1), repeat=3)))  # C order, as the weights


def _multi_indices(degree: int) -> list[tuple[int, int, int, int]]:
    return [m for m in itertools.product(range(degree + 1), repeat=4) if sum(m) == degree]


def _t0_matrix(scheme: str) -> tuple[int, list, np.ndarray]:
    """Degree, multi-indices of T0's domain points and their weights over the 27 data offsets
    ``(ox, oy, oz)`` in {-1, 0, 1}^3 (C order), in T0's frame."""
    degree, rules = RULES[scheme]
    table = _all_points(rules)
    indices = _multi_indices(degree)
    weights = np.zeros((len(indices), 27))
    for row, m in enumerate(indices):
        point = tuple(sum(m[v] * _T0[v][a] for v in range(4)) / degree for a in range(3))
        for (ox, oy, oz), w in table[point].items():
            weights[row, (ox + 1) * 9 + (oy + 1) * 3 + (oz + 1)] = float(w)
    return degree, indices, weights


class Type6Reference:
    """The spline of ``scheme`` ("s31", "qss-b", "qss-a") over ``data``, at index points."""

    def __init__(self, data: np.ndarray, scheme: str, prefilter: bool = False,
                 chunk: int = 8192):
        data = np.asarray(data, np.float64)
        if prefilter:
            if scheme != "s31":
                raise ValueError("the prefilter belongs to S31")
            e = np.pad(data, 1, mode="edge")
            lap = (e[2:, 1:-1, 1:-1] + e[:-2, 1:-1, 1:-1] + e[1:-1, 2:, 1:-1] + e[1:-1, :-2, 1:-1]
                   + e[1:-1, 1:-1, 2:] + e[1:-1, 1:-1, :-2] - 6.0 * data)
            data = data - lap / 8.0
        self.shape = np.asarray(data.shape)
        self.pad = np.pad(data, 1, mode="edge")
        self.degree, indices, self.weights = _t0_matrix(scheme)
        # de Casteljau's steps on the coefficient list: from degree r to r - 1, the entry of
        # multi-index m is sum_a lambda_a b_{m + e_a}; ``steps`` holds the four source columns.
        self.steps = []
        current = indices
        for r in range(self.degree, 0, -1):
            lower = _multi_indices(r - 1)
            at = {m: n for n, m in enumerate(current)}
            self.steps.append(np.array([[at[tuple(v + (a == b) for b, v in enumerate(m))]
                                         for a in range(4)] for m in lower]))
            current = lower
        self.chunk = chunk
        self.lo, self.hi = np.full(3, -0.5), self.shape - 0.5

    def __call__(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, np.float64)
        flat = points.reshape(-1, 3)
        out = np.empty(flat.shape[0])
        for start in range(0, flat.shape[0], self.chunk):
            out[start:start + self.chunk] = self._values(flat[start:start + self.chunk])
        return out.reshape(points.shape[:-1])

    def _values(self, p: np.ndarray) -> np.ndarray:
        n = p.shape[0]
        p = np.clip(p, self.lo, self.hi)
        cube = np.clip(np.floor(p + 0.5), 0, self.shape - 1).astype(np.int64)
        q = p - cube
        # The symmetry: T0's y axis onto the largest |q| (with its sign), z onto the middle one,
        # x onto the smallest (sign +): then q' = (x', y', z') has |x'| <= z' <= y'.
        order = np.argsort(-np.abs(q), axis=1, kind="stable")
        rows = np.arange(n)
        ax_y, ax_z, ax_x = order[:, 0], order[:, 1], order[:, 2]
        s_y = np.where(q[rows, ax_y] < 0, -1, 1)
        s_z = np.where(q[rows, ax_z] < 0, -1, 1)
        x, y, z = q[rows, ax_x], s_y * q[rows, ax_y], s_z * q[rows, ax_z]
        # Barycentric coordinates in T0: q' = l1 v1 + l2 v2 + l3 v3.
        lam = np.stack([1.0 - 2.0 * y, 2.0 * (y - z), z - x, z + x], axis=1)
        # The 27 data around the cube, in T0's frame: offset o there is g o in the cube.
        strides = np.array([self.pad.shape[1] * self.pad.shape[2], self.pad.shape[2], 1])
        base = (cube + 1) @ strides  # the padded array's flat index of the cube centre
        per_axis = np.stack([strides[ax_x], s_y * strides[ax_y], s_z * strides[ax_z]], axis=1)
        flat = base[:, None] + sum(per_axis[:, a, None] * _OFFSETS[:, a] for a in range(3))
        gathered = self.pad.reshape(-1)[flat]  # (n, 27)
        coef = gathered @ self.weights.T  # (n, n_coef): the tetrahedron's coefficients
        for step in self.steps:  # de Casteljau
            coef = np.einsum("na,nka->nk", lam, coef[:, step])
        return coef[:, 0]
