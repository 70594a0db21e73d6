"""8- and 16-bit integer volumes share the float32 kernels and give the same pictures.

The models that read voxels directly (trilinear, unfiltered B-splines) store such data as
float32 (:mod:`splinecast.models.storage`): exact, so every image must equal the image of the
same values given as float32 bit for bit, and after a float32 render an integer volume must
render without compiling anything. Volumes over the size cap keep their own type.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast._jit import forbidding_compiles
from splinecast.models import storage

DTYPES = [np.uint8, np.int8, np.uint16, np.int16]


def _volume(dtype) -> sc.Volume:
    """Integer data spanning the type's range: a blob plus noise, at 12^3."""
    info = np.iinfo(dtype)
    rng = np.random.default_rng(7)
    x = np.linspace(-1, 1, 12)
    blob = np.exp(-3 * (x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2))
    values = info.min + (info.max - info.min) * np.clip(blob + 0.1 * rng.random(blob.shape), 0, 1)
    return sc.Volume(np.round(values).astype(dtype))


def _images(volume: sc.Volume, model: str, mode: str, dtype) -> dict:
    """The outputs of one small render; the isovalue is set from the integer ``dtype``."""
    cam = sc.Camera.orbit(volume, size=(24, 20), azimuth=30, elevation=20)
    info = np.iinfo(dtype)
    options = {"iso": {"iso": 0.55 * info.min + 0.45 * info.max}, "mip": {}}[mode]
    frame = sc.Scene(volume, model=model).render(cam, mode=mode, **options)
    found = {k: getattr(frame, k) for k in ("rgba", "depth", "normal", "value")}
    return {k: np.asarray(v) for k, v in found.items() if v is not None}


@pytest.mark.parametrize("model", ["trilinear", "bspline1"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_integer_volumes_render_as_their_float32_values_without_compiling(dtype, model) -> None:
    ints = _volume(dtype)
    floats = sc.Volume(ints.data.astype(np.float32))
    for mode in ("iso", "mip"):
        expected = _images(floats, model, mode, dtype)  # compiles the float32 kernels if needed
        with forbidding_compiles():  # the integer volume must find them ready
            got = _images(ints, model, mode, dtype)
        assert got.keys() == expected.keys()
        for key in expected:
            np.testing.assert_array_equal(got[key], expected[key], err_msg=f"{mode} {key}")


def test_the_kernels_read_float32_only_where_it_is_exact() -> None:
    for dtype in DTYPES:
        assert storage.kernel_dtype(np.dtype(dtype), 1000) == np.float32
    for dtype in (np.int32, np.uint32, np.int64, np.float64, np.float32):
        assert storage.kernel_dtype(np.dtype(dtype), 1000) == np.dtype(dtype)
    model = sc.Scene(_volume(np.uint16), model="trilinear").model
    assert model.prepared.dtype == np.float32


def test_volumes_over_the_cap_keep_their_type_and_pictures(monkeypatch) -> None:
    ints = _volume(np.uint16)
    converted = _images(ints, "trilinear", "iso", np.uint16)
    monkeypatch.setattr(storage, "MAX_CONVERTED_BYTES", ints.data.size * 4 - 1)
    assert storage.kernel_dtype(ints.dtype, ints.data.size) == np.uint16
    scene = sc.Scene(ints, model="trilinear")
    assert scene.model.prepared.dtype == np.uint16 and scene.model.nbytes == 0
    native = _images(ints, "trilinear", "iso", np.uint16)
    for key in converted:
        np.testing.assert_array_equal(native[key], converted[key])
