"""Several translucent isosurfaces: crossings composited in depth order (analytic nested spheres).

The sphere demo is the distance ``|p| - 0.6``; its isovalues -0.4, -0.2 and 0 are spheres of radii
0.2, 0.4 and 0.6 around the origin. With ambient light 1 and no diffuse or specular term a layer's
colour is exactly its base colour, so the expected pixel is the front-to-back composite of the
spheres the ray crosses, in the order geometry dictates.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc

FLAT = sc.Shading(ambient=1.0, diffuse=0.0, specular=0.0, background=(0.0, 0.0, 0.0, 1.0))
ISOS = [-0.4, -0.2, 0.0]                       # radii 0.2, 0.4, 0.6
COLORS = [(0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0)]
OPACITY = [0.7, 0.5, 0.3]


@pytest.fixture(scope="module")
def frame():
    vol = sc.demo("sphere", size=41)
    cam = sc.Camera((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), size=(9, 9), ortho=True,
                    ortho_height=1.6)
    return sc.Scene(vol).render(cam, iso=ISOS, colors=COLORS, opacity=OPACITY, shading=FLAT)


def _composite(layers):
    rgb, a = np.zeros(3), 0.0
    for q in layers:
        rgb += (1 - a) * OPACITY[q] * np.asarray(COLORS[q])
        a += (1 - a) * OPACITY[q]
    return rgb


def _expected(offset):
    """Layers crossed by a ray at distance ``offset`` from the centre: outermost first, in to
    the innermost sphere reached, then out again."""
    radii = [0.2, 0.4, 0.6]
    crossed = [q for q in (2, 1, 0) if offset < radii[q]]
    return _composite(crossed + crossed[::-1])


def test_three_nested_spheres_are_composited_in_depth_order(frame):
    # Row r of the 9-pixel orthographic image is at height (1 - (r + 0.5) / 9 * 2) * 0.8.
    for row in range(9):
        offset = abs((1 - (row + 0.5) / 9 * 2) * 0.8)
        np.testing.assert_allclose(frame.rgba[row, 4, :3], _expected(offset), atol=1e-6)
    # The centre ray's order matters: reversed order would give a different colour.
    assert not np.allclose(_composite([0, 1, 2, 2, 1, 0]), _expected(0.0))


def test_first_crossing_is_the_outer_sphere(frame):
    centre_depth = frame.depth[4, 4]
    assert centre_depth == pytest.approx(3.0 - 0.6, abs=5e-3)
    assert frame.face[4, 4] == 1
    assert np.isinf(frame.depth[0, 4])
    np.testing.assert_allclose(frame.rgba[0, 4, :3], 0.0)


def test_iso_list_validation():
    vol = sc.demo("sphere", size=12)
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, size=(8, 8))
    with pytest.raises(sc.ParameterError, match="opacity"):
        scene.render(cam, iso=[-0.2, 0.0], opacity=[0.5, 0.5, 0.5])
    with pytest.raises(sc.ParameterError, match="outside the data range"):
        scene.render(cam, iso=[0.0, 99.0])
