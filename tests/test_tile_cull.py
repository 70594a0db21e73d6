"""Culled tiles: a tile is skipped only when none of its rays meets the box, and frames with
culling are bit-identical to frames traced ray by ray.

The reference for the verdict is a slab test of every pixel ray of the tile in numpy (t >= 0).
The reference for the frames is the same scene traced in tiles of one pixel, which the test never
culls (one pixel's four corner rays coincide: no plane, no verdict).
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.models.trilinear import TrilinearModel
from splinecast.render.tile_cull import tile_misses_box


def _hits_box(origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - origins) / dirs
        tb = (hi - origins) / dirs
    near = np.where(np.isnan(ta), -np.inf, np.minimum(ta, tb))
    far = np.where(np.isnan(ta), np.inf, np.maximum(ta, tb))
    # A ray parallel to a slab's axis is inside it for all t or for none.
    parallel = dirs == 0
    inside = (origins >= lo) & (origins <= hi)
    near = np.where(parallel, np.where(inside, -np.inf, np.inf), near)
    far = np.where(parallel, np.where(inside, np.inf, -np.inf), far)
    t0 = np.maximum(near.max(axis=-1), 0.0)
    return t0 <= far.min(axis=-1)


@pytest.mark.parametrize("ortho", [False, True])
def test_a_culled_tile_has_no_ray_that_meets_the_box(ortho):
    vol = sc.demo("sphere", size=16)
    rng = np.random.default_rng(3 if ortho else 4)
    culled = kept = 0
    for trial in range(12):
        cam = sc.Camera.orbit(vol, azimuth=float(rng.uniform(0, 360)),
                              elevation=float(rng.uniform(-80, 80)), size=(96, 64),
                              zoom=float(rng.uniform(0.3, 3.0)), ortho=ortho)
        origins, dirs = cam.rays()
        basis = cam.pixel_basis()
        for _ in range(20):
            centre = rng.uniform(-1.5, 1.5, 3)
            half = rng.uniform(0.02, 0.6, 3)
            lo, hi = centre - half, centre + half
            box = np.concatenate([lo, hi])
            hits = _hits_box(origins, dirs, lo, hi)
            for r0 in range(0, 64, 8):
                for c0 in range(0, 96, 8):
                    verdict = tile_misses_box(basis, r0, r0 + 8, c0, c0 + 8, 96, 64, box)
                    if verdict:
                        culled += 1
                        assert not hits[r0:r0 + 8, c0:c0 + 8].any(), (trial, r0, c0)
                    elif not hits[r0:r0 + 8, c0:c0 + 8].any():
                        kept += 1  # conservative: a missing tile may be kept
    # The test means something: most missing tiles are culled.
    assert culled > 5 * kept > 0


def test_one_pixel_tiles_are_never_culled():
    vol = sc.demo("sphere", size=16)
    cam = sc.Camera.orbit(vol, azimuth=10, elevation=10, size=(32, 24), zoom=0.5)
    far_away = np.array([50.0, 50.0, 50.0, 51.0, 51.0, 51.0])
    assert not tile_misses_box(cam.pixel_basis(), 3, 4, 5, 6, 32, 24, far_away)


MODES = {
    "iso": {"iso": 0.0, "inside": "low"},
    "multi-iso": {"iso": [-0.2, 0.1], "opacity": [0.5, 0.7], "inside": "low"},
    "mip": {"mode": "mip"},
    "dvr": {"mode": "dvr", "tf": sc.TransferFunction([(-0.3, 0.4), (0.0, 0.1), (0.3, 0.0)],
                                                     domain=(-1.0, 1.0))},
}


@pytest.mark.parametrize("ortho", [False, True])
@pytest.mark.parametrize("mode", list(MODES))
def test_frames_with_culled_tiles_equal_frames_traced_ray_by_ray(monkeypatch, mode, ortho):
    vol = sc.demo("sphere", size=24)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=15, size=(80, 56), zoom=0.6, ortho=ortho)
    scene = sc.Scene(vol)
    culled_frame = scene.render(cam, **MODES[mode])
    monkeypatch.setattr(TrilinearModel, "band_rows", 1)
    monkeypatch.setattr(TrilinearModel, "tile", 1)
    reference = sc.Scene(vol).render(cam, **MODES[mode])
    for name in ("rgba", "depth", "position", "normal", "face", "value", "cells_visited",
                 "cells_tested", "blocks_skipped"):
        a, b = getattr(culled_frame, name, None), getattr(reference, name, None)
        if a is not None or b is not None:
            np.testing.assert_array_equal(a, b, err_msg=name)
    # Tiles of 8 x 8 were culled around the small volume.
    lo, hi = (np.asarray(v, float) for v in vol.bounds)
    box = np.concatenate([lo, hi])
    basis = cam.pixel_basis()
    culled = sum(tile_misses_box(basis, r, min(r + 8, 56), c, min(c + 8, 80), 80, 56, box)
                 for r in range(0, 56, 8) for c in range(0, 80, 8))
    assert culled > 10
