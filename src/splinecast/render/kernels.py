"""Which compiled kernel renders which model: the one table a new model adds itself to.

Every first-hit isosurface kernel has the signature of
:func:`splinecast.render.iso.trace_trilinear`: ``(arrays, params, act0, act1, act2, iso, basis,
vol_origin, spacing, planes, row_order, method, step, inside_high, shading, rgba, depth,
position, normal, face, cells_visited, cells_tested, blocks_skipped)`` where ``arrays`` and
``params`` come from the model object (``model.arrays``, ``model.params``).
"""

from __future__ import annotations

from .iso import trace_trilinear

__all__ = ["ISO_KERNELS"]

#: First-hit isosurface kernel by model name (the names of :data:`splinecast.models.MODELS`).
ISO_KERNELS = {
    "trilinear": trace_trilinear,
}
