"""Render modes, shading and the :class:`Frame` buffers; one traversal shared by all models."""

from .frame import Frame
from .shading import Shading

__all__ = ["Frame", "Shading"]
