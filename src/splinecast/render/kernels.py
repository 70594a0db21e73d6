"""Which compiled kernel renders which model: the one table a new model adds itself to.

Every first-hit isosurface kernel has the signature of
:func:`splinecast.render.iso.trace_trilinear`: ``(arrays, params, act0, act1, act2, iso, basis,
vol_origin, spacing, planes, row_order, method, step, inside_high, shading, rgba, depth,
position, normal, face, cells_visited, cells_tested, blocks_skipped)`` where ``arrays`` and
``params`` come from the model object (``model.arrays``, ``model.params``).
"""

from __future__ import annotations

from .iso import trace_trilinear
from .iso_bspline import trace_bspline
from .iso_type6 import trace_type6

__all__ = ["ISO_KERNELS"]

#: First-hit isosurface kernel by model name (the names of :data:`splinecast.models.MODELS`).
ISO_KERNELS = {
    "trilinear": trace_trilinear,
    "s31": trace_type6,
    "qss": trace_type6,
    "bspline1": trace_bspline,
    "bspline2": trace_bspline,
    "bspline3": trace_bspline,
}
