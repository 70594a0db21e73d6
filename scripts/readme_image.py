"""Render the picture at the top of the README and the documentation's front page.

    python scripts/readme_image.py [OUT.png]

Three panels of the built-in demo volumes, each rendered by splinecast at 320x320 and put side
by side: a smooth C1 spline isosurface of the Marschner-Lobb test signal, a maximum intensity
projection of smooth noise, and a volume rendering of a shell around the Chmutov surface. Writes
``docs/_static/splinecast.png`` by default.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

import splinecast as sc

OUT = Path(__file__).resolve().parents[1] / "docs" / "_static" / "splinecast.png"
SIZE = (320, 320)


def panels() -> list[sc.Frame]:
    ml = sc.demo("marschner-lobb", size=64)
    iso = sc.Scene(ml, model="s31").render(
        sc.Camera.orbit(ml, azimuth=30, elevation=35, size=SIZE,
                        fit=sc.content_box(ml, iso=0.5)),
        mode="iso", iso=0.5)

    noise = sc.demo("noise", size=96, seed=3)
    mip = sc.Scene(noise).render(
        sc.Camera.orbit(noise, azimuth=30, elevation=20, size=SIZE), mode="mip",
        colormap="hot")

    ch = sc.demo("chmutov", size=64)
    tf = sc.TransferFunction([(-0.4, 0.0), (-0.1, 0.3), (0.0, 0.0)], domain=(-0.4, 0.0),
                             colormap="coolwarm")
    dvr = sc.Scene(ch).render(
        sc.Camera.orbit(ch, azimuth=25, elevation=30, size=SIZE, fit=sc.content_box(ch, tf=tf)),
        mode="dvr", tf=tf, dvr=sc.DVRSettings(step=0.25, sampling="pieces"))
    return [iso, mip, dvr]


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else OUT
    images = []
    for frame in panels():
        rgba = np.clip(frame.rgba, 0.0, 1.0)
        # Premultiplied colour over the isosurface's default background.
        rgb = rgba[..., :3] + (1.0 - rgba[..., 3:4]) * np.asarray(sc.Shading().background[:3])
        images.append((255.0 * rgb + 0.5).astype(np.uint8))
    Image.fromarray(np.concatenate(images, axis=1)).save(out, optimize=True)
    print(out)


if __name__ == "__main__":
    main()
