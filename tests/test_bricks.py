"""The segment entry point: a volume rendered brick by brick equals the whole-volume render.

For every model and mode, the model's prepared array is cut into bricks of 8^3 and 16^3 cells
(each with the ghost layers the model's support needs, :func:`brick_grid`) and rendered

* chained: the bricks in front-to-back order per ray, the mode state carried from one to the
  next (:func:`trace_segment`), then finished; and
* independently: every brick into a fresh state, the partial states merged in the same order
  with the mode's ``combine`` (the compositing a distributed renderer uses).

Both must equal the whole-volume render: the same hits with depths to 1e-9 voxel, the same MIP
values, DVR within 1e-6. The orthographic cameras put rays exactly on brick faces, edges and
corners (pixel centres on the grid planes, in exact binary arithmetic).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from reference import smooth_noise

import splinecast as sc
from splinecast.render.dvr import Dvr
from splinecast.render.iso import Iso
from splinecast.render.mip import Mip
from splinecast.render.multi_iso import MultiIso
from splinecast.render.segment import (
    brick_grid,
    combine_states,
    counters,
    finish_state,
    new_state,
    render_grid,
    trace_segment,
)

MODELS = ["trilinear", "bspline1", "bspline2", "bspline3", "qss", "s31"]
MODES = ["iso", "multi", "mip", "minip", "dvr"]


@pytest.fixture(scope="module")
def volume():
    # float32, like the demo volumes: the kernels compiled for them serve this test too.
    return sc.Volume(smooth_noise((20, 19, 21), seed=3, sigma=2.0).astype(np.float32))


def _setup(mode: str, vol: sc.Volume):
    if mode == "iso":
        return Iso(0.3)
    if mode == "multi":
        return MultiIso([-0.4, 0.3], opacity=[0.4, 0.6])
    if mode in ("mip", "minip"):
        return Mip(mode, value_range=vol.value_range)
    tf = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)],
                             domain=(-3.0, 3.0))
    return Dvr(tf, sc.DVRSettings(step=0.4))


def _cameras(shift: float):
    """Axis-aligned orthographic rays on the grid planes (x = col - shift exactly), a diagonal
    one through the brick corners, and a perspective one."""
    c = 7.5 - shift
    aligned = sc.Camera((c, c, 60.0), (c, c, 0.0), up=(0.0, 1.0, 0.0), ortho=True,
                        ortho_height=16.0, size=(16, 16))
    p = np.array([8.0, 8.0, 8.0]) - shift
    diagonal = sc.Camera(p + 40.0, p, up=(0.0, 0.0, 1.0), ortho=True, ortho_height=30.0,
                         size=(15, 15))
    persp = sc.Camera((35.0, -20.0, 30.0), (9.0, 10.0, 10.0), size=(14, 12))
    return [aligned, diagonal, persp]


def _bricks(n_cells, size):
    starts = [range(0, n, size) for n in n_cells]
    for lo in itertools.product(*starts):
        yield lo, tuple(min(a + size, n) for a, n in zip(lo, n_cells, strict=True))


def _order(bricks, scene, cam, size):
    """Bricks front to back for every ray of ``cam``: along a ray the brick index moves away
    from the eye's brick on every axis (orthographic: in the direction's signs)."""
    if cam.ortho:
        sign = np.sign(cam.forward)
        return sorted(bricks, key=lambda b: float(np.dot(np.asarray(b[0]) // size, sign)))
    vol = scene.volume
    eye = (cam.position - np.asarray(vol.origin)) / np.asarray(vol.spacing) + scene.model.shift
    eye_brick = np.floor(eye / size)
    return sorted(bricks, key=lambda b: float(np.abs(np.asarray(b[0]) // size - eye_brick).sum()))


def _render_bricks(scene, setup, cam, size, chained):
    model = scene.model
    order = _order(list(_bricks(scene.grid.n_cells, size)), scene, cam, size)
    stats = counters(cam.height, cam.width)
    if chained:
        state = new_state(setup, cam)
        for lo, hi in order:
            trace_segment(brick_grid(model, lo, hi), setup, cam, state, stats)
    else:
        state = None
        for lo, hi in order:
            part = new_state(setup, cam)
            trace_segment(brick_grid(model, lo, hi), setup, cam, part, stats)
            state = part if state is None else combine_states(setup, state, part)
    return finish_state(setup, state, cam)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("mode", MODES)
def test_bricks_equal_the_whole_volume(volume, model, mode):
    scene = sc.Scene(volume, model=model)
    setup = _setup(mode, volume)
    for cam, size in itertools.product(_cameras(scene.model.shift), (8, 16)):
        whole, _ = render_grid(scene.grid, setup, cam)
        for chained in (True, False):
            if mode == "dvr" and not chained and setup.settings.adaptive:
                continue
            bricks = _render_bricks(scene, setup, cam, size, chained)
            what = f"{model} {mode} bricks {size} {'chained' if chained else 'combined'}"
            _assert_same(mode, whole, bricks, what)


def _assert_same(mode, whole, bricks, what):
    if mode in ("mip", "minip"):
        value_w, depth_w, _ = whole
        value_b, depth_b, _ = bricks
        np.testing.assert_array_equal(np.isnan(value_w), np.isnan(value_b), err_msg=what)
        np.testing.assert_allclose(value_b, value_w, rtol=1e-12, atol=1e-12, err_msg=what)
        return
    rgba_w, depth_w = whole[0], whole[1]
    rgba_b, depth_b = bricks[0], bricks[1]
    if mode == "dvr":
        np.testing.assert_allclose(rgba_b, rgba_w, atol=1e-6, err_msg=what)
        return
    hit = np.isfinite(depth_w)
    np.testing.assert_array_equal(hit, np.isfinite(depth_b), err_msg=what)
    assert hit.sum() > 10, what
    np.testing.assert_allclose(depth_b[hit], depth_w[hit], rtol=0, atol=1e-9, err_msg=what)
    np.testing.assert_allclose(rgba_b, rgba_w, atol=1e-6, err_msg=what)
    if mode == "multi":
        np.testing.assert_array_equal(whole[5], bricks[5], err_msg=what)  # crossings per ray


@pytest.mark.parametrize("kind", ["mip", "minip"])
@pytest.mark.parametrize("method, step", [("sampled", 1.5), ("slices", 3.0)])
def test_sampled_projection_in_bricks_lies_between_the_whole_volume_and_the_exact(volume, kind,
                                                                                method, step):
    """The sampled MIP traced brick by brick (chained and combined) also takes the values where
    the ray crosses brick faces: never below the whole-volume sampled projection (its samples
    are all taken too: the slices method's planes are the volume's, not the brick's), never
    above the exact one (every value is one the ray meets), and strictly above the
    whole-volume one somewhere (the face values are new samples)."""
    scene = sc.Scene(volume)
    sampled = Mip(kind, method=method, step=step, value_range=volume.value_range)
    sign = 1.0 if kind == "mip" else -1.0
    raised = 0
    for cam in _cameras(0.0):
        whole = render_grid(scene.grid, sampled, cam)[0][0]
        exact = render_grid(scene.grid, Mip(kind, value_range=volume.value_range), cam)[0][0]
        seen = np.isfinite(whole)
        assert seen.sum() > 50
        for chained in (True, False):
            bricks = _render_bricks(scene, sampled, cam, 8, chained)[0]
            np.testing.assert_array_equal(np.isfinite(bricks), seen)
            gain = sign * (bricks[seen] - whole[seen])
            assert gain.min() >= -1e-12
            assert np.all(sign * (exact[seen] - bricks[seen]) >= -1e-12)
            raised += int((gain > 1e-9).sum())
    assert raised > 0
