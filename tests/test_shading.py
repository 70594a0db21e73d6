"""The headlight Blinn-Phong of isosurface hits (``render/shading.shade_pixel``) against the
formula evaluated in Python with ``**``: the kernel raises to an integral shininess by repeated
squaring, so it must agree with ``pow`` to rounding, for integral and fractional exponents."""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.render.shading import shade_pixel


def _expected(shading: sc.Shading, front: bool, cos_theta: float) -> np.ndarray:
    color = np.array(shading.front_color if front else shading.back_color)
    spec = shading.specular * cos_theta**shading.shininess
    return np.minimum(color * (shading.ambient + shading.diffuse * cos_theta) + spec, 1.0)


@pytest.mark.parametrize("shininess", [0.0, 1.0, 3.0, 40.0, 128.0, 1024.0, 7.5, 2000.0])
def test_shading_equals_the_formula_with_pow(shininess):
    shading = sc.Shading(specular=0.6, shininess=shininess)
    params = shading.as_array()
    rng = np.random.default_rng(7)
    for _ in range(200):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        front = bool(rng.integers(2))
        got = np.array(shade_pixel(params, front, *n, *u))
        want = _expected(shading, front, abs(float(n @ u)))
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    # Along the normal the specular term is the whole weight, whatever the exponent.
    got = shade_pixel(params, True, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0)
    np.testing.assert_allclose(got, _expected(shading, True, 1.0), rtol=1e-15)
