"""Which per-pixel outputs a render fills: ``Scene.render(..., outputs=...)``.

Every mode can write colour, depth, world position, normal, face and per-ray statistics; most
callers need only some of them (the viewer and the movie writer show colour; compositing needs
depth). A buffer nobody asked for is handed to the kernel with zero rows: the mode's ``finish``
hook writes a buffer only when it has rows (the same compiled code serves both cases, as the
array's type does not change), so nothing is allocated, written or read for it. The
:class:`~splinecast.Frame` holds ``None`` in its place, the convention ``Frame.value`` already
follows for modes without a projected value.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._jit import jit, overload_jit
from ..errors import ParameterError

__all__ = ["OUTPUTS", "ALL_OUTPUTS", "check_outputs", "buffer", "copy_pixel"]

#: Output names accepted by ``outputs=``: ``"stats"`` stands for the per-ray counters
#: (``cells_visited``, ``cells_tested``, ``blocks_skipped``, and the per-ray DVR sample and
#: multi-iso layer counts behind ``stats["mean_samples"]`` / ``stats["mean_layers"]``).
OUTPUTS = ("rgba", "depth", "position", "normal", "face", "value", "stats")

#: The default: everything.
ALL_OUTPUTS = frozenset(OUTPUTS)


def check_outputs(outputs: Any) -> frozenset[str]:
    """The validated set of requested outputs (``None``: all of them).

    Raises
    ------
    ParameterError
        If ``outputs`` is not a name or a collection of names of :data:`OUTPUTS`, or is empty.
    """
    if outputs is None:
        return ALL_OUTPUTS
    names = (outputs,) if isinstance(outputs, str) else outputs
    try:
        chosen = frozenset(names)
    except TypeError:
        raise ParameterError(f"outputs must be a list of names from {', '.join(OUTPUTS)}, "
                             f"got {outputs!r}") from None
    unknown = sorted(str(n) for n in chosen - ALL_OUTPUTS)
    if unknown:
        raise ParameterError(f"outputs: unknown name(s) {', '.join(unknown)}; "
                             f"choose from {', '.join(OUTPUTS)}")
    if not chosen:
        raise ParameterError("outputs must name at least one output")
    return chosen


def buffer(wanted: bool, shape: tuple[int, ...], dtype: Any = np.float64) -> np.ndarray:
    """An uninitialised output buffer of ``shape``, or one with zero rows when not ``wanted``
    (same dtype and number of dimensions, so the kernel's compiled type is the same)."""
    return np.empty(shape if wanted else (0,) * len(shape), dtype)


def copy_pixel(out, row, col, r0, r1, c0, c1):
    """Copy pixel ``(row, col)`` of every output buffer with rows into rows ``[r0, r1)`` x
    columns ``[c0, c1)`` (compiled code only).

    The driver finishes one pixel of a run of tiles where no ray is traced and copies it to the
    rest: every pixel there is a fresh state finished without a ray, so its outputs do not
    depend on where it is. Writing the colour through the mode's ``finish`` pixel by pixel
    repeats the buffers' checks and the conversions to float32 for every pixel, a visible share
    of a frame where most of the image is background.
    """
    raise NotImplementedError


# A call, not inlined: inlined at Numba's IR level, the generated body lost the store the
# mode's finish had just made to the int8 face buffer (it filled the old byte), a miscompile
# seen with numba 0.68; one call per run of tiles costs nothing.
@overload_jit(copy_pixel)
def _copy_pixel(out, row, col, r0, r1, c0, c1):
    # One call per buffer, by its number of dimensions: the tuple's buffers have different
    # types, so the calls are written out for this tuple (static indices into it).
    fills = {2: _fill_plane, 3: _fill_channels}
    names = {f"fill{i}": fills[kind.ndim] for i, kind in enumerate(out.types)}
    body = "".join(f"    fill{i}(out[{i}], row, col, r0, r1, c0, c1)\n"
                   for i in range(len(out.types)))
    source = f"def copy(out, row, col, r0, r1, c0, c1):\n{body or '    pass'}\n"
    scope: dict = dict(names)
    exec(source, scope)  # noqa: S102 - generated from the tuple's length only
    return scope["copy"]


@jit(inline="always")
def _fill_plane(a, row, col, r0, r1, c0, c1):
    if a.shape[0] == 0:  # not asked for
        return
    v = a[row, col]
    # Unsigned indices: no negative-index wrap-around, so the stores can be vectorized.
    for r in range(np.uint64(r0), np.uint64(r1)):
        for c in range(np.uint64(c0), np.uint64(c1)):
            a[r, c] = v


@jit(inline="always")
def _fill_channels(a, row, col, r0, r1, c0, c1):
    if a.shape[0] == 0:  # not asked for
        return
    n = a.shape[2]
    if n == 4:  # colour: the four values held in registers, stored together
        v0, v1, v2, v3 = a[row, col, 0], a[row, col, 1], a[row, col, 2], a[row, col, 3]
        # Unsigned indices: no negative-index wrap-around, so the stores can be vectorized.
        for r in range(np.uint64(r0), np.uint64(r1)):
            for c in range(np.uint64(c0), np.uint64(c1)):
                a[r, c, np.uint64(0)] = v0
                a[r, c, np.uint64(1)] = v1
                a[r, c, np.uint64(2)] = v2
                a[r, c, np.uint64(3)] = v3
        return
    for r in range(np.uint64(r0), np.uint64(r1)):
        for c in range(np.uint64(c0), np.uint64(c1)):
            for k in range(np.uint64(n)):
                a[r, c, k] = a[row, col, k]
