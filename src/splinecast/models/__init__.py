"""Continuous reconstructions of the voxel grid, one module per model.

Each model prepares flat arrays from a :class:`~splinecast.volume.Volume` once and supplies
compiled ray pieces (:mod:`.pieces`: per-cell value bounds, the reconstruction along a piece of
a ray as a univariate polynomial, gradients) that the render modes consume. Models know nothing
of cameras or images.
"""

# The ray-piece modules register each model's compiled functions (see .pieces) on import.
from . import bspline_ray, type6_ray  # noqa: F401
from .bspline import BSpline1Model, BSpline2Model, BSpline3Model
from .qss import QSSModel
from .s31 import S31Model
from .trilinear import TrilinearModel

#: Models by the name users pass as ``Scene(volume, model=...)``.
#:
#: :meta hide-value:
MODELS = {"trilinear": TrilinearModel, "s31": S31Model, "qss": QSSModel}
MODELS.update(bspline1=BSpline1Model, bspline2=BSpline2Model, bspline3=BSpline3Model)

__all__ = ["MODELS", "QSSModel", "S31Model", "TrilinearModel"]
__all__ += ["BSpline1Model", "BSpline2Model", "BSpline3Model"]
