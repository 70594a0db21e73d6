"""The element type of the arrays a model's kernels read.

Every element type of the voxels is a separate specialisation of the compiled kernels, and each
costs a first-use compile of tens of seconds. 8- and 16-bit integers are exactly representable
in float32, so the models that read the voxels directly (trilinear, unfiltered B-splines) store
such data as float32: the pictures are identical (the kernels compute in float64 from either),
and the kernels compiled for the float32 demo volumes serve the uint8 MRI, the int16 CT and the
uint16 microscopy stack too. The copy costs memory (two or four times the voxels), so volumes
whose float32 copy would exceed :data:`MAX_CONVERTED_BYTES` keep their own type and compile for
it instead, as do volumes whose copy would take more than a quarter of the memory available now.
"""

from __future__ import annotations

import numpy as np

from ..errors.limits import memory_limit

__all__ = ["MAX_CONVERTED_BYTES", "kernel_dtype", "kernel_array", "coefficient_dtype"]

#: Largest float32 copy made to share kernels (512 MiB: a 512^3 volume); larger volumes keep
#: their element type, where memory matters more than one compile.
MAX_CONVERTED_BYTES = 512 << 20


def kernel_dtype(dtype: np.dtype, voxels: int) -> np.dtype:
    """The element type the kernels read for ``voxels`` voxels of ``dtype``.

    float32 for 8- and 16-bit integers (exact) when the copy is at most
    :data:`MAX_CONVERTED_BYTES` and a quarter of :func:`~splinecast.errors.limits.memory_limit`;
    otherwise ``dtype`` itself.
    """
    dtype = np.dtype(dtype)
    exact = dtype.kind in "ui" and dtype.itemsize <= 2
    if exact and voxels * 4 <= min(MAX_CONVERTED_BYTES, memory_limit()[0] // 4):
        return np.dtype(np.float32)
    return dtype


def kernel_array(data: np.ndarray) -> np.ndarray:
    """``data`` as a C-contiguous array of :func:`kernel_dtype` (no copy when it already is)."""
    return np.ascontiguousarray(data, dtype=kernel_dtype(data.dtype, int(data.size)))


def coefficient_dtype(dtype: np.dtype) -> np.dtype:
    """The element type of values computed from voxels of ``dtype`` (a prefilter's output,
    clamped padding of a type-6 spline): float32 for float32 and 8- or 16-bit integer voxels,
    whose precision float32 holds, float64 otherwise.

    The filters compute in float64; storing their result at the voxels' own precision halves
    its memory for float32 and integer data and lets it share the kernels compiled for float32
    volumes instead of compiling float64 ones on first use.
    """
    dtype = np.dtype(dtype)
    exact_in_float32 = dtype.kind in "ui" and dtype.itemsize <= 2 or dtype == np.float32
    return np.dtype(np.float32) if exact_in_float32 else np.dtype(np.float64)
