"""int64, uint64, bool and float16 voxels: converted to the smallest supported dtype, exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import DataError, ReadError
from splinecast.volume import SUPPORTED_DTYPES, exact_supported


def as_ints(a: np.ndarray) -> list[int]:
    """Every value as a Python int: compared exactly, with no numpy casting in between."""
    return [int(v) for v in a.ravel().tolist()]


def block(values: list[int], dtype: type) -> np.ndarray:
    data = np.zeros((3, 4, 5), dtype=dtype)
    data.flat[: len(values)] = values
    return data


@pytest.mark.parametrize("values, expected", [
    ([0, 1, 255], np.uint8),
    ([-5, 0, 100], np.int8),
    ([0, 256, 65535], np.uint16),
    ([-32768, 0, 32767], np.int16),
    ([-1, 40000], np.int32),
    ([0, 2**32 - 1], np.uint32),
    ([-(2**31), 2**31 - 1], np.int32),
    ([0, 2**31], np.uint32),
    ([-1, 2**31], np.float64),
    ([-(2**53), 2**53], np.float64),
    ([3, 2**62], np.float64),            # a power of two: exactly representable
    ([-(2**63), 0], np.float64),         # the smallest int64 is a power of two too
])
def test_int64_becomes_the_smallest_exact_dtype(values, expected):
    data = block(values, np.int64)
    vol = sc.Volume(data)
    assert vol.dtype == np.dtype(expected)
    assert as_ints(vol.data) == as_ints(data)


@pytest.mark.parametrize("values, expected", [
    ([0, 200], np.uint8),
    ([0, 70000], np.uint32),
    ([0, 2**40 + 1], np.float64),
    ([1, 2**63 + 2**11], np.float64),     # above int64's range, exact in float64
])
def test_uint64_becomes_the_smallest_exact_dtype(values, expected):
    data = block(values, np.uint64)
    vol = sc.Volume(data)
    assert vol.dtype == np.dtype(expected)
    assert as_ints(vol.data) == as_ints(data)


@pytest.mark.parametrize("values, dtype", [
    ([0, 2**53 + 1], np.int64),           # the first integer float64 cannot hold
    ([-(2**62) - 1, 5], np.int64),
    ([2**64 - 1], np.uint64),             # rounds to 2**64, outside uint64
    ([2**63 + 1], np.uint64),
])
def test_values_no_dtype_holds_exactly_are_refused(values, dtype):
    data = block(values, dtype)
    with pytest.raises(DataError, match=rf"labels: {np.dtype(dtype)} values .* cannot be held "
                                        r"exactly by any supported voxel type"):
        sc.Volume(data, metadata={"name": "labels"})


def test_bool_is_a_uint8_view_and_float16_becomes_float32():
    mask = np.zeros((4, 5, 6), dtype=bool)
    mask[1:3, 2:4, 3:5] = True
    vol = sc.Volume(mask)
    assert vol.dtype == np.uint8 and np.shares_memory(vol.data, mask)
    np.testing.assert_array_equal(vol.data.astype(bool), mask)
    half = (np.arange(4 * 5 * 6).reshape(4, 5, 6) / 7).astype(np.float16)
    vol = sc.Volume(half)
    assert vol.dtype == np.float32
    # Every float16 is a float32: converting back loses nothing.
    assert np.array_equal(vol.data.astype(np.float16), half)


def test_supported_dtypes_pass_through_untouched():
    for dtype in SUPPORTED_DTYPES:
        data = np.ones((2, 3, 4), dtype=dtype)
        assert exact_supported(data) is data


def test_unconvertible_dtype_names_what_is_accepted():
    with pytest.raises(DataError, match=r"v: voxel type complex128 is not supported \(use one "
                                        r"of uint8, .*int64"):
        exact_supported(np.zeros((2, 2, 2), complex), "v")


def test_readers_convert_too(tmp_path: Path):
    labels = np.zeros((6, 7, 8), dtype=np.int64)  # numpy's default integer type
    labels[2:4, 1:5, 3:7] = 7
    labels[0, 0, 0] = 1000
    np.save(tmp_path / "labels.npy", labels)
    vol = sc.read(tmp_path / "labels.npy")
    assert vol.dtype == np.uint16
    assert as_ints(vol.data) == as_ints(labels)
    huge = labels.astype(np.uint64)
    huge[0, 0, 0] = 2**64 - 1
    np.save(tmp_path / "huge.npy", huge)
    with pytest.raises(ReadError, match=r"huge\.npy: uint64 values .* cannot be held exactly"):
        sc.read(tmp_path / "huge.npy")


def test_a_pyvista_label_volume_renders(tmp_path: Path):
    """The issue's case: int64 labels render without any conversion by the user."""
    labels = np.zeros((16, 16, 16), dtype=np.int64)
    labels[4:12, 4:12, 4:12] = 3
    frame = sc.Scene(sc.Volume(labels)).render(
        sc.Camera.orbit(sc.Volume(labels), size=(24, 24)))
    assert frame.stats["iso"] == 1.5  # halfway between the background and the only label
    assert frame.hit.any()
