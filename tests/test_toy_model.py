"""A model defined here, outside the package, renders through every scene kind in memory and
from a pyramid, with no change to the package: the nearest-neighbour reconstruction (each voxel's
value constant over the cube of space nearest to it, ``[v - 1/2, v + 1/2]`` per axis).

It declares its capabilities as every model does (:class:`splinecast.models.base.
ReconstructionModel`: support, border rule, the traversal's shift, its domain) and registers its
compiled ray pieces (:func:`splinecast.models.pieces.register`): one piece per cube, a constant.

References, computed here from the voxels:

- MIP, minIP and AIP: dense sampling (20000 samples per ray) of the nearest voxel's value along
  each ray inside the box ``[-1/2, n - 1/2]``; the maximum the samples see is one the ray meets
  (the exact projection is at least it, and equal unless a cube is grazed between two samples);
- the isosurface of a mask at its value: the ray's entry into the box of the mask's cubes
  (a constant piece equal to the isovalue holds it from its start);
- the pyramid's level 0 drawn from bricks against the in-memory render of the same volume.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
import pytest
from reference import box_interval

import splinecast as sc
from splinecast._jit import jit
from splinecast.models.base import ReconstructionModel
from splinecast.models.pieces import cell_range, register, whole_cell
from splinecast.roots.pieces import PowerCubic

SAMPLES = 20000

#: The kernel grid: the voxels padded by one on every side (cube ``c`` is voxel ``c``, read at
#: ``pad[c + 1]``; the padding keeps the block hierarchy's ranges, which span ``pad[c .. c + 2]``,
#: inside the array).
NearestGrid = namedtuple("NearestGrid", ["pad"])


@jit()
def _cell_count(grid):
    p = grid.pad
    return p.shape[0] - 2, p.shape[1] - 2, p.shape[2] - 2


@jit()
def _new_scratch(grid):
    return np.empty(0)


@jit()
def _cell_load(grid, scratch, i, j, k):
    v = np.float64(grid.pad[i + 1, j + 1, k + 1])
    return v, v


@jit()
def _piece_poly(grid, scratch, ctx, cell, tag, a, b):
    return PowerCubic(ctx[0], 0.0, 0.0, 0.0)


@jit()
def _gradient(grid, scratch, ctx, i, j, k, tag, x, y, z):
    return 0.0, 0.0, 0.0


@jit()
def _value_gradient_at(grid, scratch, x, y, z):
    nx, ny, nz = _cell_count(grid)
    i = min(max(int(np.floor(x)), 0), nx - 1)
    j = min(max(int(np.floor(y)), 0), ny - 1)
    k = min(max(int(np.floor(z)), 0), nz - 1)
    return np.float64(grid.pad[i + 1, j + 1, k + 1]), 0.0, 0.0, 0.0


register(NearestGrid, cell_count=_cell_count, new_scratch=_new_scratch, cell_load=_cell_load,
         cell_pieces=whole_cell, piece_range=cell_range, piece_poly=_piece_poly,
         gradient=_gradient, value_gradient_at=_value_gradient_at)


class NearestModel(ReconstructionModel):
    """Nearest-neighbour reconstruction: constant over each voxel's cube."""

    name = "nearest"
    #: Cube ``c`` is read from ``pad[c .. c + 2]`` (its ghost layers in a brick).
    support = 2
    border_rule = "edge"
    #: The traversal walks cubes in ``voxel index + shift``: cube ``c`` is ``[c - 1/2, c + 1/2]``.
    shift = 0.5
    typical_compile_s = 30

    def __init__(self, volume: sc.Volume) -> None:
        self.volume = volume
        self.pad = np.ascontiguousarray(np.pad(np.asarray(volume.data, np.float64), 1,
                                               mode="edge"))
        self.n_cells = tuple(int(n) for n in volume.shape)

    @property
    def prepared(self) -> np.ndarray:
        return self.pad

    @property
    def coefficients(self) -> np.ndarray:
        return self.pad

    @property
    def nbytes(self) -> int:
        return int(self.pad.nbytes)

    def domain(self) -> tuple[np.ndarray, np.ndarray]:
        return np.full(3, -0.5), np.asarray(self.volume.shape, np.float64) - 0.5

    def kernel_grid(self, array: np.ndarray | None = None, **_: object) -> tuple:
        pad = self.pad if array is None else np.ascontiguousarray(array, np.float64)
        return NearestGrid(pad)


@pytest.fixture()
def nearest(monkeypatch):
    """The toy model in the models' registry for the test's duration."""
    monkeypatch.setitem(sc.MODELS, "nearest", NearestModel)
    return "nearest"


def _volume() -> sc.Volume:
    rng = np.random.default_rng(7)
    data = rng.integers(0, 50, size=(11, 9, 10)).astype(np.float32)
    return sc.Volume(data, spacing=(1.0, 1.2, 0.9), origin=(2.0, -1.0, 0.5))


def _camera(vol: sc.Volume, size: tuple[int, int] = (22, 18)) -> sc.Camera:
    return sc.Camera.orbit(vol, azimuth=35, elevation=25, size=size, fit="box", zoom=0.8)


def _dense(vol: sc.Volume, cam: sc.Camera) -> dict[str, np.ndarray]:
    """Max, min and mean of the nearest voxel's value along each ray (NaN: a miss), and the
    ray's interval in the box."""
    W, U = cam.rays()
    W, U = W.reshape(-1, 3), U.reshape(-1, 3)
    o = (W - np.asarray(vol.origin)) / np.asarray(vol.spacing)
    d = U / np.asarray(vol.spacing)
    shape = np.asarray(vol.shape)
    t0, t1 = box_interval(o, d, np.full(3, -0.5), shape - 0.5)
    data = np.asarray(vol.data, np.float64)
    out = {k: np.full(len(o), np.nan) for k in ("mip", "minip", "aip")}
    s = (np.arange(SAMPLES) + 0.5) / SAMPLES
    for r in np.flatnonzero(t1 > t0):
        p = o[r] + (t0[r] + s * (t1[r] - t0[r]))[:, None] * d[r]
        idx = np.clip(np.floor(p + 0.5).astype(int), 0, shape - 1)
        v = data[idx[:, 0], idx[:, 1], idx[:, 2]]
        out["mip"][r], out["minip"][r], out["aip"][r] = v.max(), v.min(), v.mean()
    hw = (cam.height, cam.width)
    return {**{k: v.reshape(hw) for k, v in out.items()}, "t0": t0.reshape(hw),
            "t1": t1.reshape(hw)}


def test_the_toy_model_projects_as_dense_sampling_says(nearest):
    vol = _volume()
    cam = _camera(vol)
    scene = sc.Scene(vol, model=nearest)
    want = _dense(vol, cam)
    hit = np.isfinite(want["aip"])
    assert 50 < hit.sum() < hit.size
    for mode, sign in (("mip", 1.0), ("minip", -1.0)):
        got = scene.render(cam, mode=mode, window=(0.0, 50.0)).value
        np.testing.assert_array_equal(np.isfinite(got), hit)
        # Never short of what the samples saw; equal but where a cube is barely grazed.
        assert np.all(sign * (got[hit] - want[mode][hit]) >= 0.0)
        assert np.mean(got[hit] == want[mode][hit]) > 0.95
    aip = scene.render(cam, sc.Aip(window=(0.0, 50.0)))
    np.testing.assert_allclose(aip.value[hit], want["aip"][hit], rtol=0, atol=50 * 2e-4)
    np.testing.assert_allclose(aip.depth[hit], want["t0"][hit], rtol=0, atol=1e-9)


def _mask() -> tuple[sc.Volume, np.ndarray, np.ndarray]:
    data = np.zeros((12, 10, 11), np.float32)
    data[3:8, 2:7, 4:9] = 1.0
    lo, hi = np.array([3, 2, 4]) - 0.5, np.array([7, 6, 8]) + 0.5  # the cubes' box
    return sc.Volume(data), lo, hi


def test_the_toy_models_isosurface_is_its_cubes_faces(nearest):
    vol, lo, hi = _mask()
    cam = _camera(vol, size=(32, 26))
    frame = sc.Scene(vol, model=nearest).render(cam, iso=1.0, inside="high", samples=1)
    W, U = cam.rays()
    t0, t1 = box_interval(W.reshape(-1, 3), U.reshape(-1, 3), lo, hi)
    t0, t1 = t0.reshape(cam.height, cam.width), t1.reshape(cam.height, cam.width)
    # Rays that cross the box (not those that graze an edge of it).
    through, away = t1 - t0 > 1e-6, t1 < t0
    assert 30 < through.sum() and away.sum() > 30
    np.testing.assert_allclose(frame.depth[through], t0[through], rtol=0, atol=1e-9)
    assert np.all(np.isinf(frame.depth[away]))


@pytest.mark.parametrize("mode", ["iso", "mip", "aip"])
def test_the_toy_model_renders_from_a_pyramid_as_in_memory(nearest, mode, tmp_path):
    pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
    vol, _, _ = _mask() if mode == "iso" else (_volume(), None, None)
    path = tmp_path / "toy.zarr"
    sc.build_pyramid(vol, path, brick=4, shard=4, progress=False)
    cam = _camera(vol, size=(32, 26))
    options = ({"iso": 1.0, "inside": "high"} if mode == "iso"
               else {"mode": mode, "window": (0.0, 50.0)})
    whole = sc.Scene(vol, model=nearest).render(cam, samples=1, **options)
    with sc.Scene(sc.read(path), model=nearest, budget="64MiB", lod=1e-6,
                  whole_level=False) as bricks:
        drawn = bricks.render(cam, complete=True, **options)
    st = drawn.stats
    assert st["complete"] and st["cut_levels"] == {0: st["cut_bricks"]} and st["cut_bricks"] > 4
    hit = np.isfinite(whole.depth)
    assert 30 < hit.sum() < hit.size
    np.testing.assert_array_equal(np.isfinite(drawn.depth), hit)
    np.testing.assert_allclose(drawn.depth[hit], whole.depth[hit], rtol=0, atol=1e-9)
    if mode != "iso":
        np.testing.assert_allclose(drawn.value[hit], whole.value[hit], rtol=0, atol=1e-9)
