"""Frame images as bytes for the wire: JPEG while the user drags, lossless PNG when input stops.

Pillow (already a dependency of splinecast) does both. PNG is written with zlib level 1: about
as small as the default level for rendered images and several times faster to encode, which
matters when the full-resolution frame is waited for.
"""

from __future__ import annotations

import io

import numpy as np

__all__ = ["FORMATS", "encode_image", "decode_image"]

#: Image formats of frames: name -> MIME type.
FORMATS = {"jpeg": "image/jpeg", "png": "image/png"}

_JPEG_QUALITY = 85
_PNG_LEVEL = 1


def encode_image(rgba: np.ndarray, fmt: str) -> bytes:
    """Encode an ``(height, width, 4)`` uint8 image.

    ``"png"`` keeps all four channels bit for bit; ``"jpeg"`` drops alpha (the viewer's
    backgrounds are opaque) and is lossy.
    """
    from PIL import Image

    out = io.BytesIO()
    if fmt == "jpeg":
        Image.fromarray(np.ascontiguousarray(rgba[..., :3])).save(
            out, format="JPEG", quality=_JPEG_QUALITY)
    elif fmt == "png":
        Image.fromarray(np.ascontiguousarray(rgba)).save(
            out, format="PNG", compress_level=_PNG_LEVEL)
    else:
        raise ValueError(f"unknown image format {fmt!r}")
    return out.getvalue()


def decode_image(data: bytes) -> np.ndarray:
    """Decode a frame's image to a uint8 array, ``(height, width, 3 or 4)`` (clients, tests)."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as image:
        return np.asarray(image)
