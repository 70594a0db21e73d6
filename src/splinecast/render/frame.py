"""The :class:`Frame`: what a render returns (colour, depth, position, normal, statistics)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ParameterError

__all__ = ["Frame"]


@dataclass
class Frame:
    """The buffers of one rendered image.

    Attributes
    ----------
    rgba : ndarray, shape (height, width, 4), float32 in [0, 1]
        Shaded colour; row 0 is the top of the image.
    depth : ndarray, shape (height, width), float64
        World distance from the ray origin to the hit along the unit ray; ``inf`` on a miss.
    position : ndarray, shape (height, width, 3), float64
        World position of the hit; NaN on a miss.
    normal : ndarray, shape (height, width, 3), float32
        Unit outward surface normal in world space (pointing away from the "inside" side of the
        isovalue); NaN on a miss.
    face : ndarray, shape (height, width), int8
        1 for a front face, -1 for a back face, 0 for a miss.
    cells_visited, cells_tested, blocks_skipped : ndarray, shape (height, width), int32
        Per-ray statistics: cells walked one by one, cells whose ray profile was built, blocks of
        empty space leapt over.
    stats : dict
        Summary numbers (timings in ms, counts, parameters).
    value : ndarray, shape (height, width), float64, optional
        Projected data value of ``mode="mip"`` / ``"minip"`` (NaN where the ray misses the
        volume); ``None`` for other modes.
    """

    rgba: np.ndarray
    depth: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    face: np.ndarray
    cells_visited: np.ndarray
    cells_tested: np.ndarray
    blocks_skipped: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)
    value: np.ndarray | None = None

    @property
    def hit(self) -> np.ndarray:
        """Boolean mask of pixels whose ray hit the surface."""
        return np.isfinite(self.depth)

    @property
    def size(self) -> tuple[int, int]:
        """Image ``(width, height)``."""
        return int(self.depth.shape[1]), int(self.depth.shape[0])

    def to_uint8(self) -> np.ndarray:
        """The colour buffer as 8-bit RGBA."""
        return (np.clip(self.rgba, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)

    def _repr_png_(self) -> bytes:
        """PNG bytes of the colour buffer: Jupyter and IPython show a Frame as its image."""
        import io

        from PIL import Image

        buffer = io.BytesIO()
        Image.fromarray(self.to_uint8(), mode="RGBA").save(buffer, format="PNG")
        return buffer.getvalue()

    def save(self, path: str | os.PathLike) -> None:
        """Write the colour buffer as a PNG (written to a temporary file, then moved)."""
        from PIL import Image

        if Path(path).suffix.lower() != ".png":
            raise ParameterError(f"{path}: the image must be saved as .png")
        image = Image.fromarray(self.to_uint8(), mode="RGBA")
        with atomic_outputs(Path(path)) as (tmp,):
            image.save(tmp, format="PNG")

    def save_depth(self, path: str | os.PathLike) -> None:
        """Write the depth buffer as ``.npy`` (float64, ``inf`` on misses)."""
        if Path(path).suffix.lower() != ".npy":
            raise ParameterError(f"{path}: the depth buffer must be saved as .npy")
        with atomic_outputs(Path(path)) as (tmp,):
            with open(tmp, "wb") as f:  # a file object: np.save must not append ".npy"
                np.save(f, self.depth)
