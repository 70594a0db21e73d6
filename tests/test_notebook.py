"""Jupyter shows a Frame as its image: ``_repr_png_`` is a PNG of exactly the colour buffer."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

import splinecast as sc


def test_frame_repr_png_is_its_image():
    vol = sc.demo("sphere", size=16)
    frame = sc.Scene(vol).render(sc.Camera.orbit(vol, size=(20, 12)))
    png = frame._repr_png_()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    decoded = np.asarray(Image.open(io.BytesIO(png)))
    np.testing.assert_array_equal(decoded, frame.to_uint8())
