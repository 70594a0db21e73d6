"""Continuous reconstructions of the voxel grid, one module per model.

Each model prepares flat arrays from a :class:`~splinecast.volume.Volume` once and supplies
compiled per-cell functions (value bounds, ray restriction, first root, gradient) that the shared
renderer calls. Models know nothing of cameras or images.
"""

from .bspline import BSpline1Model, BSpline2Model, BSpline3Model
from .qss import QSSModel
from .s31 import S31Model
from .trilinear import TrilinearModel

#: Models by the name users pass as ``Scene(volume, model=...)``.
MODELS = {"trilinear": TrilinearModel, "s31": S31Model, "qss": QSSModel}
MODELS.update(bspline1=BSpline1Model, bspline2=BSpline2Model, bspline3=BSpline3Model)

__all__ = ["MODELS", "QSSModel", "S31Model", "TrilinearModel"]
__all__ += ["BSpline1Model", "BSpline2Model", "BSpline3Model"]
