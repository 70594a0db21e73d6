"""The tests' own type-6 evaluator (``type6_reference.py``), the reference of the type-6 models in
``evaluators.py``, checked against what it must reproduce without the package: its coefficient
rules are symmetric and affine (weights summing to one); on quadratic data ``q`` both schemes
give ``q + tr(M) / 4`` (``q + Delta q / 8``, the schemes' property) and S31 with the prefilter
``q`` itself, at every point whose stencils see only real voxels; and it is continuous across
the faces between tetrahedra and between cubes. It is then compared with the model's own point
evaluation (a second code path: the package's derived tables and compiled de Casteljau).
"""

from __future__ import annotations

import numpy as np
import pytest
from type6_reference import RULES, Type6Reference, check_rules

import splinecast as sc

SHAPE = (9, 8, 10)


@pytest.mark.parametrize("scheme", list(RULES))
def test_rules_are_symmetric_and_affine(scheme):
    check_rules(scheme)


def _quadratic(rng):
    m = rng.normal(size=(3, 3))
    m = m + m.T
    centre, slope = np.array([4.1, 3.7, 4.9]), rng.normal(size=3)

    def q(p):
        r = p - centre
        return np.einsum("...i,ij,...j->...", r, m, r) + r @ slope + 0.3

    return q, np.trace(m)


@pytest.mark.parametrize(("scheme", "prefilter"), [("s31", False), ("s31", True),
                                                   ("qss-b", False), ("qss-a", False)])
def test_quadratics_are_reproduced(scheme, prefilter):
    rng = np.random.default_rng(3)
    q, trace = _quadratic(rng)
    data = q(np.moveaxis(np.indices(SHAPE, dtype=float), 0, -1))
    spline = Type6Reference(data, scheme, prefilter=prefilter)
    # Cubes 1 .. n-2 see real voxels only (2 .. n-3 with the prefilter's Laplacian).
    inner = 2.5 if prefilter else 1.5
    points = rng.uniform(inner, np.array(SHAPE) - 1 - inner, size=(4000, 3))
    shift = 0.0 if prefilter else trace / 4.0
    np.testing.assert_allclose(spline(points), q(points) + shift, rtol=0, atol=1e-12)


@pytest.mark.parametrize("scheme", list(RULES))
def test_continuous_across_tetrahedra_and_cubes(scheme):
    """Approached from both sides of a face between tetrahedra (the planes x = +-y, ... through
    a cube centre) or between cubes (half-integer planes), the values agree."""
    rng = np.random.default_rng(5)
    spline = Type6Reference(rng.normal(size=SHAPE), scheme)
    p = rng.uniform(1.0, np.array(SHAPE) - 2.0, size=(3000, 3))
    local = p - np.round(p)
    a, b = rng.integers(0, 3, size=(2, p.shape[0]))
    b = np.where(a == b, (a + 1) % 3, b)
    rows = np.arange(p.shape[0])
    on_inner = p.copy()
    on_inner[rows, b] = np.round(p[rows, b]) + local[rows, a]  # onto x_b - c = x_a - c
    normal = np.zeros_like(p)
    normal[rows, a], normal[rows, b] = 1.0, -1.0
    on_cube = p.copy()
    on_cube[rows, a] = np.floor(p[rows, a]) + 0.5
    axis = np.zeros_like(p)
    axis[rows, a] = 1.0
    for points, across in ((on_inner, normal), (on_cube, axis)):
        gap = np.abs(spline(points + 1e-9 * across) - spline(points - 1e-9 * across))
        assert gap.max() < 1e-7


@pytest.mark.parametrize(("model", "options", "scheme"), [
    ("s31", {}, "s31"), ("s31", {"prefilter": True}, "s31"), ("qss", {}, "qss-b"),
    ("qss", {"variant": "qss-a"}, "qss-a")])
def test_the_models_point_evaluation_agrees(model, options, scheme):
    rng = np.random.default_rng(11)
    data = rng.normal(size=SHAPE)
    scene = sc.Scene(sc.Volume(data), model=model, **options)
    points = rng.uniform(-0.5, np.array(SHAPE) - 0.5, size=(5000, 3))
    got = scene.model.evaluate(points)
    spline = Type6Reference(data, scheme, prefilter=options.get("prefilter", False))
    np.testing.assert_allclose(spline(points), got, rtol=0, atol=1e-12)
