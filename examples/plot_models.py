"""
Reconstruction models
=====================

The same coarse volume through three reconstructions: trilinear interpolation (what most tools
use), a cubic B-spline and the cubic C1 spline ``s31`` on the type-6 tetrahedral partition. The
splines give smooth surfaces where the trilinear surface shows the grid in its outline (its
shading is smooth by default: see the next example).
"""

import splinecast as sc

vol = sc.demo("marschner-lobb", size=20)
cam = sc.Camera.orbit(vol, azimuth=35, elevation=30, size=(200, 200), fit=sc.content_box(vol))

frames = [sc.Scene(vol, model=model).render(cam) for model in ("trilinear", "bspline3", "s31")]
for frame in frames:
    print(frame.stats["model"], f"{frame.stats['trace_ms']:.0f} ms")
