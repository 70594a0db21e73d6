"""Per-model value evaluation for the references, independent of the kernels' ray code.

``model_evaluator(name, volume, scene)`` gives the reconstruction a model renders, as a function
of index-space points, plus where its polynomial pieces meet and the box it covers:

* ``trilinear``: :func:`reference.trilinear` (lerp form), pieces the voxel cells;
* ``bspline1..3``: :func:`reference.bspline` (scipy's ``map_coordinates``), pieces the cells
  between knots (voxel centres for odd degree, half-way between them for even degree);
* ``qss``, ``s31``: :class:`type6_reference.Type6Reference`, written in the tests from the
  Bernstein-Bezier coefficient rules of the two schemes (de Casteljau on the tetrahedron holding
  the point; nothing of the package), for the model's variant and prefilter; pieces the 24
  tetrahedra of each cube centred on a voxel.

(Type-6 hits are also checked without any of the model's arrays in ``test_type6_analytic.py``,
and ``test_type6_reference.py`` checks the reference on quadratics and against the model's own
point evaluation.)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from reference import bspline, trilinear
from type6_reference import Type6Reference


@dataclass
class Evaluator:
    """A model's reconstruction in index space."""

    #: values at points (..., 3)
    value: Callable[[np.ndarray], np.ndarray]
    #: distance (voxels) from points (..., 3) to the nearest boundary between polynomial pieces
    boundary: Callable[[np.ndarray], np.ndarray]
    #: the index-space box the model covers (per-axis lower and upper corners)
    lo: np.ndarray
    hi: np.ndarray


def _to_planes(p: np.ndarray, offset: float) -> np.ndarray:
    """Distance to the nearest plane ``x_a = m + offset`` (integer m) over the three axes."""
    f = p - offset
    return np.min(np.abs(f - np.round(f)), axis=-1)


def _type6_boundary(p: np.ndarray) -> np.ndarray:
    # cube faces at half-integers, and the six planes x = +-y, x = +-z, y = +-z through the cube
    # centre that separate its 24 tetrahedra
    local = p - np.round(p)
    x, y, z = local[..., 0], local[..., 1], local[..., 2]
    inner = np.min(np.abs(np.stack([x - y, x + y, x - z, x + z, y - z, y + z])), axis=0)
    return np.minimum(_to_planes(p, 0.5), inner / np.sqrt(2.0))


def model_evaluator(name: str, volume, scene) -> Evaluator:
    """The :class:`Evaluator` of model ``name`` for ``volume`` (``scene`` renders it)."""
    data = np.asarray(volume.data, np.float64)
    top = np.asarray(volume.shape, float) - 1.0
    if name == "trilinear":
        return Evaluator(lambda p: trilinear(data, p), lambda p: _to_planes(p, 0.0),
                         np.zeros(3), top)
    if name.startswith("bspline"):
        degree = int(name[-1])
        if getattr(scene.model, "prefilter", False):
            raise NotImplementedError("prefiltered B-splines: evaluate scipy's spline_filter")
        offset = 0.5 if degree % 2 == 0 else 0.0
        return Evaluator(lambda p: bspline(data, degree, p), lambda p: _to_planes(p, offset),
                         np.zeros(3), top)
    if name in ("qss", "s31"):
        scheme = getattr(scene.model, "variant", "qss-b") if name == "qss" else "s31"
        spline = Type6Reference(data, scheme, prefilter=getattr(scene.model, "prefilter", False))
        return Evaluator(spline, _type6_boundary, np.full(3, -0.5), top + 0.5)
    raise KeyError(f"no evaluator for model {name!r}")
