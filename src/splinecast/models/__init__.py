"""Continuous reconstructions of the voxel grid, one module per model.

Each model prepares flat arrays from a :class:`~splinecast.volume.Volume` once and supplies
compiled per-cell functions (value bounds, ray restriction, first root, gradient) that the shared
renderer calls. Models know nothing of cameras or images.
"""

from .trilinear import TrilinearModel

#: Models by the name users pass as ``Scene(volume, model=...)``.
MODELS = {"trilinear": TrilinearModel}

__all__ = ["MODELS", "TrilinearModel"]
