"""Work items of several bands (``ReconstructionModel.work_rows``): a thread traces such an item
a column of tiles at a time instead of band by band.

Reference: the same scene with items of one band (``work_rows = 0``, the loop every other
model and the isosurfaces run), rendered in the modes that use such items (DVR, MIP), one of
whose rays carry something from one ray to the next of their tile (MIP with a tolerance); the
pixels, depths and per-ray counts must be the same to the bit, on an image whose sides are
multiples of neither the tile nor the item.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc


@pytest.fixture(scope="module")
def scenes():
    vol = sc.demo("marschner-lobb", size=40)
    grouped = sc.Scene(vol)
    banded = sc.Scene(vol)
    banded.grid.work_rows = 0
    return vol, grouped, banded


def test_trilinear_traces_items_of_several_bands(scenes):
    from splinecast.render.dvr import Dvr
    from splinecast.render.iso import Iso
    from splinecast.render.mip import Mip

    _, grouped, banded = scenes
    assert grouped.grid.work_rows >= 2 * grouped.grid.band_rows and grouped.grid.tile > 0
    assert banded.grid.work_rows == 0
    # The modes whose rays go through the volume; a first hit gains nothing.
    assert Dvr.deep_rays and Mip.deep_rays and not Iso.deep_rays
    # The tiles a window of the image must start on are the bands' and tiles', not the items'.
    assert grouped.tile_shape == banded.tile_shape == (grouped.grid.tile,
                                                       grouped.grid.band_rows)


@pytest.mark.parametrize("options", [
    {"mode": "mip"},
    {"mode": "mip", "tolerance": 4 / 255},
    {"mode": "dvr"},
], ids=["mip", "mip-tolerance", "dvr"])
def test_items_of_several_bands_trace_the_same_pixels(scenes, options):
    vol, grouped, banded = scenes
    # 77 rows: ten bands of 8 (the last one short), three items of up to four bands.
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(203, 77))
    a = grouped.render(cam, **options)
    b = banded.render(cam, **options)
    names = ("rgba", "depth", "value", "cells_visited", "cells_tested", "blocks_skipped")
    compared = 0
    for name in names:
        x, y = getattr(a, name, None), getattr(b, name, None)
        if x is None:
            continue
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=name)
        compared += 1
    assert compared >= 3
    shown = np.asarray(a.rgba)[..., 3] > 0 if a.rgba is not None else np.isfinite(a.value)
    # Something on every item's rows (the last item short), so an item left out would show.
    assert all(shown[r0:r0 + 32].any() for r0 in range(0, 77, 32))
