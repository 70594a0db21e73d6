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

from ..errors import ParameterError

__all__ = ["OUTPUTS", "ALL_OUTPUTS", "check_outputs", "buffer"]

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
