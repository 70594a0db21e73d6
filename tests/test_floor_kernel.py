"""The benchmarks' floor kernel (issue 15) marks exactly the pixels whose ray crosses the box."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import splinecast as sc

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from floor_kernel import floor_render  # noqa: E402


def test_floor_colours_the_rays_that_cross_the_box():
    vol = sc.demo("sphere", size=16)
    # Far enough that part of the image misses the box.
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=20, size=(48, 36), distance=4.0)
    rgba = floor_render(cam, vol.bounds)
    # Reference: the slab test in numpy on Camera.rays() (the other ray code path).
    origins, dirs = cam.rays()
    lo, hi = (np.asarray(b, float) for b in vol.bounds)
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - origins) / dirs
        tb = (hi - origins) / dirs
    near = np.maximum(np.nanmax(np.minimum(ta, tb), axis=-1), 0.0)
    far = np.nanmin(np.maximum(ta, tb), axis=-1)
    crosses = near <= far
    assert 0 < crosses.sum() < crosses.size
    assert np.array_equal(rgba[..., 0] == 1.0, crosses)
    assert np.all(rgba[..., 3] == 1.0)
