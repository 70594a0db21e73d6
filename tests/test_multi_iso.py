"""Several translucent isosurfaces: crossings composited in depth order (analytic nested spheres).

The sphere demo is the distance ``|p| - 0.6``; its isovalues -0.4, -0.2 and 0 are spheres of radii
0.2, 0.4 and 0.6 around the origin. With ambient light 1 and no diffuse or specular term a layer's
colour is exactly its base colour, so the expected pixel is the front-to-back composite of the
spheres the ray crosses, in the order geometry dictates.
"""

from __future__ import annotations

import numpy as np
import pytest
from evaluators import model_evaluator
from pairs import MODELS_FOR_MODE
from reference import all_crossings, box_interval, sphere_distance

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
    return sc.Scene(vol).render(cam, iso=ISOS, colors=COLORS, opacity=OPACITY, shading=FLAT,
                                samples=1)  # one ray a pixel, as the reference


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


# ------------------------------------------------------------------ every crossing, dense reference
# The crossings of several isovalues along each ray, from dense sampling (1e-3 voxels) and
# bisection of the reconstruction (``evaluators.py``), composited front to back with the flat
# shading above: a crossing the renderer misses, invents or misorders changes the colour by at
# least opacity * remaining transparency (>= 0.15 * 0.7^12 ~ 2e-3 here), far above the float32
# tolerance of the comparison (1e-5).

DISTINCT = [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
THIN = [0.2, 0.3, 0.15]
STOP = 1.0 - 1e-4  # the kernel stops a ray at this opacity (module docstring of multi_iso)


def _rough_volume():
    """Rough random data: trilinear profiles with several crossings of one isovalue in a cell
    and crossings of all three close isovalues in one cell."""
    rng = np.random.default_rng(5)
    data = rng.uniform(0.0, 1.0, (7, 6, 8)).astype(np.float32)
    return sc.Volume(data, spacing=(1.0, 0.9, 1.2)), [0.42, 0.5, 0.58]


def _shells_volume():
    """Distance to a sphere: isovalues 0, 0.3, 0.6 voxels are nested shells 0.3 voxels apart."""
    data = sphere_distance((12, 12, 12), (5.6, 5.4, 5.7), 3.2).astype(np.float32)
    return sc.Volume(data), [0.0, 0.3, 0.6]


def _composite_crossings(rows, colors, opacity):
    rgb, a = np.zeros(3), 0.0
    for _, k in rows:
        if a >= STOP:
            break
        rgb += (1.0 - a) * opacity[int(k)] * np.asarray(colors[int(k)])
        a += (1.0 - a) * opacity[int(k)]
    return rgb


@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["multi-iso"])
@pytest.mark.parametrize("make", [_rough_volume, _shells_volume], ids=["rough", "shells"])
def test_every_crossing_against_dense_sampling(model_name, make):
    vol, isos = make()
    scene = sc.Scene(vol, model=model_name)
    cam = sc.Camera.orbit(vol, azimuth=28, elevation=33, size=(16, 12), zoom=1.2)
    frame = scene.render(cam, iso=isos, colors=DISTINCT, opacity=THIN, shading=FLAT, samples=1)
    ev = model_evaluator(model_name, vol, scene)
    W, U = (a.reshape(-1, 3) for a in cam.rays())
    o, d = vol.world_to_index(W), U / np.asarray(vol.spacing)
    t0, t1 = box_interval(o, d, ev.lo, ev.hi)
    crossings, ambiguous = all_crossings(ev.value, o, d, t0, t1, isos)
    assert ambiguous.mean() < 0.03
    rgb = frame.rgba[..., :3].reshape(-1, 3)
    depth = frame.depth.reshape(-1)
    speed = np.linalg.norm(d, axis=1)
    same_iso_in_cell = mixed_in_cell = 0
    for r in np.flatnonzero(~ambiguous):
        rows = crossings[r]
        np.testing.assert_allclose(rgb[r], _composite_crossings(rows, DISTINCT, THIN), atol=1e-5,
                                   err_msg=f"ray {r}: {rows}")
        if len(rows) == 0:
            assert np.isinf(depth[r])
            continue
        assert abs(depth[r] - rows[0, 0]) * speed[r] < 1e-9
        cells = np.floor(o[r] + rows[:, :1] * d[r]).astype(int)
        for cell in np.unique(cells, axis=0):
            ks = rows[np.all(cells == cell, axis=1), 1]
            same_iso_in_cell += len(ks) > len(set(ks))
            mixed_in_cell += len(set(ks)) > 1
    # The several-roots-per-cell paths were exercised.
    assert mixed_in_cell > 10
    if make is _rough_volume:
        assert same_iso_in_cell > 10
    else:  # consecutive crossings of the nested shells lie less than a voxel apart
        gaps = [np.diff(c[:, 0]) * s for c, s in zip(crossings, speed, strict=True) if len(c) > 1]
        assert np.median(np.concatenate(gaps)) < 1.0
