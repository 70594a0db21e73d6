"""
Quick start
===========

Read a volume (here a synthetic one), prepare a scene once, and render an isosurface. With no
isovalue given, splinecast uses the volume's default (or Otsu's threshold of its histogram), and
``sc.content_box`` frames what that isovalue shows.
"""

import splinecast as sc

vol = sc.demo("marschner-lobb", size=48)   # or sc.read("head.nii.gz")
scene = sc.Scene(vol)                       # the reconstruction, prepared once

cam = sc.Camera.orbit(vol, azimuth=30, elevation=25, size=(320, 240), fit=sc.content_box(vol))
frame = scene.render(cam)                   # a Frame: rgba, depth, position, normal, stats
print(f"isovalue {frame.stats['iso']}, {frame.stats['hits']} pixels hit")

# %%
# The same scene renders other isovalues without preparing anything again (only the min/max
# blocks are re-classified):

frame_low = scene.render(cam, iso=0.3)
