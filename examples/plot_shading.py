"""
Smooth normals and antialiasing
===============================

The hits of an isosurface are exact for the chosen model; the normals it is shaded with need
not be the model's. The trilinear gradient jumps from cell to cell, so by default the trilinear
isosurface is shaded with the gradient of the cubic B-spline of the voxels at each exact hit
(``normals="smooth"``), and the pixels on the edges of the image are traced again with four
more rays (``samples=5``). Left: the model's own normals and one ray per pixel; right: the
defaults.
"""

import splinecast as sc

vol = sc.demo("marschner-lobb", size=48)
scene = sc.Scene(vol)
cam = sc.Camera.orbit(vol, azimuth=30, elevation=35, size=(240, 180), zoom=1.6)

before = scene.render(cam, iso=0.5, normals="exact", samples=1)
after = scene.render(cam, iso=0.5)
print(f"{after.stats['antialiased']} of {cam.width * cam.height} pixels antialiased")
