"""
Render modes, clipping and several isosurfaces
==============================================

One volume in the modes of :meth:`splinecast.Scene.render`: translucent nested isosurfaces, a
clipped isosurface with a checker texture, and a volume rendering with a hand-made transfer
function (the gallery's "automatic defaults" example shows a maximum intensity projection).
"""

import splinecast as sc

vol = sc.demo("chmutov", size=40)
scene = sc.Scene(vol)
cam = sc.Camera.orbit(vol, azimuth=25, elevation=30, size=(220, 220))

layers = scene.render(cam, iso=[-0.3, 0.0], opacity=[0.35, 1.0])
clipped = scene.render(cam, iso=0.0, clip=[(1, 1, 0, 0)],
                       effects=sc.SurfaceEffects(texture="checker", scale=0.25))

tf = sc.TransferFunction([(-0.4, 0.0), (-0.1, 0.3), (0.0, 0.0)], domain=(-0.4, 0.0),
                         colormap="coolwarm")
dvr = scene.render(cam, mode="dvr", tf=tf)
