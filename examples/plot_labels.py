"""
Label volumes (segmentations)
=============================

A label volume holds an integer per voxel: 0 is the background, every other value a region
(an organ, a cell, a tumour). ``Scene(vol, labels=True)`` draws each label's boundary as its
own surface, in its own colour: the 0.5 isosurface of the label's indicator under the chosen
model. Colours and names come from a colour table (here a dict; a ``.json`` or ``.csv`` file
works the same way), else from the OME-Zarr ``image-label`` metadata, else from a palette.
``Frame.label`` says which label each pixel shows first, which is what a picker needs.

Left: the trilinear model shows the voxels' facets. Right: the cubic B-spline of each
indicator smoothed first (``smooth=5``) gives smooth organs; the liver is made translucent to
show the tumour inside, and the legend lists the labels in view.
"""

import numpy as np
from PIL import Image, ImageDraw

import splinecast as sc

# A small synthetic abdomen: ellipsoids and a tube of different ids on a 72 x 60 x 48 grid.
shape = (72, 60, 48)
x, y, z = (np.indices(shape) - np.array(shape)[:, None, None, None] / 2) * 1.5  # mm


def ellipsoid(cx, cy, cz, ax, ay, az):
    return ((x - cx) / ax) ** 2 + ((y - cy) / ay) ** 2 + ((z - cz) / az) ** 2 <= 1


labels = np.zeros(shape, np.uint8)
labels[ellipsoid(-12, 6, 4, 22, 15, 13)] = 1                     # liver
labels[ellipsoid(22, -8, -4, 6, 9, 12)] = 2                      # left kidney
labels[ellipsoid(-24, -12, -6, 6, 9, 12)] = 3                    # right kidney
labels[ellipsoid(28, 12, 8, 9, 12, 8)] = 4                       # spleen
labels[(np.hypot(x - 2, y + 2) <= 3.5) & (np.abs(z) < 30)] = 5   # aorta
labels[ellipsoid(-16, 10, 8, 5, 5, 5)] = 6                       # a tumour in the liver
vol = sc.Volume(labels, spacing=1.5, metadata={"name": "abdomen"})

table = {
    1: {"rgba": [176, 90, 70, 255], "name": "liver"},
    2: {"rgba": [230, 170, 60, 255], "name": "kidney (left)"},
    3: {"rgba": [200, 150, 50, 255], "name": "kidney (right)"},
    4: {"rgba": [120, 80, 160, 255], "name": "spleen"},
    5: {"rgba": [210, 40, 40, 255], "name": "aorta"},
    6: {"rgba": [90, 200, 90, 255], "name": "tumour"},
}
faceted_scene = sc.Scene(vol, labels=True, colors=table)
smooth = sc.Scene(vol, model="bspline3", labels=True, smooth=5, colors=table)
cam = sc.Camera.orbit(vol, azimuth=-60, elevation=30, size=(300, 240),
                      fit=smooth.content_box())          # the box around the labels
faceted = faceted_scene.render(cam)


def with_legend(frame, scene):
    """The frame's picture with a legend of the scene's labels (drawn with Pillow)."""
    image = Image.fromarray(frame.to_uint8(), "RGBA")
    draw = ImageDraw.Draw(image)
    for row, value in enumerate(scene.shown):
        style = scene.style(value)
        colour = tuple(int(255 * c) for c in style.rgba[:3])
        top = 6 + 14 * row
        draw.rectangle([6, top, 16, top + 10], fill=colour)
        draw.text((22, top - 1), f"{value} {style.name}", fill=(235, 235, 235))
    rgba = np.asarray(image, np.float32) / 255
    return sc.Frame(rgba=rgba, depth=frame.depth, position=None, normal=None, face=None,
                    cells_visited=None, cells_tested=None, blocks_skipped=None,
                    label=frame.label)


organs = with_legend(smooth.render(cam, opacity={1: 0.35}), smooth)
# Frame.label: the label each pixel shows first (the tumour lies inside the translucent liver).
seen = {smooth.style(v).name: int(np.count_nonzero(organs.label == v)) for v in smooth.labels}
print("pixels showing each label first:", seen)
