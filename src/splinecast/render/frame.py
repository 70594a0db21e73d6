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

    A render fills the buffers its ``outputs`` name (``Scene.render(..., outputs=...)``, default
    all); a buffer that was not requested is ``None``, as ``value`` is for modes without a
    projected value, and what needs it (:attr:`hit` needs ``depth``) raises a
    :class:`~splinecast.errors.ParameterError` that says which output to request.

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
    label : ndarray, shape (height, width), int64, optional
        Label volumes (``Scene(vol, labels=True)``): the value of the label whose surface the
        pixel's ray hit first, 0 on a miss (what a viewer shows under the cursor); ``None``
        for other scenes.
    """

    rgba: np.ndarray | None
    depth: np.ndarray | None
    position: np.ndarray | None
    normal: np.ndarray | None
    face: np.ndarray | None
    cells_visited: np.ndarray | None
    cells_tested: np.ndarray | None
    blocks_skipped: np.ndarray | None
    stats: dict[str, Any] = field(default_factory=dict)
    value: np.ndarray | None = None
    label: np.ndarray | None = None

    def _needs(self, name: str) -> np.ndarray:
        array = getattr(self, name)
        if array is None:
            raise ParameterError(f"this frame has no {name} buffer: render with outputs "
                                 f"including {name!r}")
        return array

    @property
    def hit(self) -> np.ndarray:
        """Boolean mask of pixels whose ray hit the surface (needs the ``depth`` output)."""
        return np.isfinite(self._needs("depth"))

    @property
    def size(self) -> tuple[int, int]:
        """Image ``(width, height)``."""
        for array in (self.rgba, self.depth, self.position, self.normal, self.face,
                      self.cells_visited, self.value):
            if array is not None:
                return int(array.shape[1]), int(array.shape[0])
        return int(self.stats["width"]), int(self.stats["height"])

    def to_uint8(self) -> np.ndarray:
        """The colour buffer as 8-bit RGBA (needs the ``rgba`` output)."""
        # One float temporary, scaled in place (three otherwise: about 10 ms of a 1024x768
        # frame on a busy machine, which a viewer pays per frame); the same operations.
        scaled = np.clip(self._needs("rgba"), 0.0, 1.0)
        scaled *= 255.0
        scaled += 0.5
        return scaled.astype(np.uint8)

    def _repr_png_(self) -> bytes | None:
        """PNG bytes of the colour buffer: Jupyter and IPython show a Frame as its image
        (``None`` without one: they fall back to the text form)."""
        import io

        from PIL import Image

        if self.rgba is None:
            return None
        buffer = io.BytesIO()
        Image.fromarray(self.to_uint8(), mode="RGBA").save(buffer, format="PNG")
        return buffer.getvalue()

    def save(self, path: str | os.PathLike, background: Any = None, quality: int = 95) -> None:
        """Write the colour buffer as an image (to a temporary file, then moved in place).

        The format follows the suffix: ``.png``, ``.tif``/``.tiff`` and ``.webp`` keep the
        alpha channel (WebP losslessly); ``.jpg``/``.jpeg`` has none, so the image is composited
        on ``background`` first (an RGB or RGBA colour in [0, 1], its alpha ignored; default
        black), which changes nothing where the image is opaque, as renders on an opaque
        background (the default :class:`~splinecast.Shading`) are.

        Parameters
        ----------
        path : str or path-like
        background : 3 or 4 floats in [0, 1], optional
            What JPEG composites translucent pixels on.
        quality : int
            JPEG quality, 1 to 95.
        """
        from PIL import Image

        suffix = Path(path).suffix.lower()
        formats = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".tif": "TIFF",
                   ".tiff": "TIFF", ".webp": "WEBP"}
        if suffix not in formats:
            raise ParameterError(f"{path}: the image must be saved as .png, .jpg, .jpeg, .tif, "
                                 ".tiff or .webp")
        rgba = self._needs("rgba")
        options: dict[str, Any] = {}
        if formats[suffix] == "JPEG":
            bg = np.zeros(3) if background is None else np.asarray(background, np.float64)[:3]
            alpha = np.clip(rgba[..., 3:4], 0.0, 1.0)
            rgb = np.clip(rgba[..., :3], 0.0, 1.0) * alpha + bg * (1.0 - alpha)
            image = Image.fromarray((np.clip(rgb, 0, 1) * 255.0 + 0.5).astype(np.uint8), "RGB")
            options = {"quality": int(quality)}
        else:
            image = Image.fromarray(self.to_uint8(), mode="RGBA")
            if formats[suffix] == "WEBP":
                options = {"lossless": True}
            elif formats[suffix] == "TIFF":
                options = {"compression": "tiff_deflate"}
        with atomic_outputs(Path(path)) as (tmp,):
            image.save(tmp, format=formats[suffix], **options)

    def save_depth(self, path: str | os.PathLike) -> None:
        """Write the depth buffer as ``.npy`` (float64, ``inf`` on misses)."""
        if Path(path).suffix.lower() != ".npy":
            raise ParameterError(f"{path}: the depth buffer must be saved as .npy")
        depth = self._needs("depth")
        with atomic_outputs(Path(path)) as (tmp,):
            with open(tmp, "wb") as f:  # a file object: np.save must not append ".npy"
                np.save(f, depth)
