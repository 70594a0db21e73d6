"""
Two channels together: a fluorescence-style composite
======================================================

A cell with two stains on one grid: a round nucleus (channel 0) and a ring of spots around it
(channel 1), as a confocal stack with two fluorophores holds them. :class:`splinecast.Scene`
given the list of volumes renders them together, each channel in its own colour
(:class:`splinecast.ChannelScene`).

In a maximum intensity projection each channel's projected value goes through its own window
onto a ramp from black to its colour, and the channels are **added**, as napari's additive
blending and Fiji's "Composite" do: where magenta and green overlap the pixel turns white, and
the order of the channels does not matter. Isosurfaces are composited by the **nearest hit**:
each pixel shows the surface closest to the camera, whichever channel it belongs to.

An OME-Zarr image with a ``c`` axis reads as such a list, with each channel's colour, window,
label and visibility taken from its ``omero`` metadata::

    channels = sc.read("cells.ome.zarr", channel="all")   # or channel=[0, 2]
    frame = sc.Scene(channels).render(cam, "mip")

and from the command line::

    splinecast render cells.ome.zarr --channel 0,2 --channel-colors magenta,00ff00 \\
        --channel-window 0:180,10:250 --mode mip
"""

import numpy as np

import splinecast as sc

n = 64
x, y, z = np.indices((n, n, n), dtype=np.float64) - (n - 1) / 2
rng = np.random.default_rng(3)
nucleus = 200.0 * np.exp(-(x**2 + (y / 1.2) ** 2 + (z / 0.9) ** 2) / 160.0)
spots = np.zeros((n, n, n))
for _ in range(40):  # spots on a shell around the nucleus
    direction = rng.normal(size=3)
    cx, cy, cz = 20.0 * direction / np.linalg.norm(direction)
    spots += 230.0 * np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / 6.0)
noise = rng.normal(0.0, 4.0, (2, n, n, n))
volumes = [sc.Volume(np.clip(c + e + 10, 0, 255).astype(np.uint8), spacing=(0.2, 0.2, 0.25),
                     metadata={"name": name})
           for c, e, name in ((nucleus, noise[0], "nucleus"), (spots, noise[1], "spots"))]

scene = sc.Scene(volumes, colors=["magenta", "lime"], windows=[(10, 180), (10, 250)])
cam = sc.Camera.orbit(volumes[0], azimuth=30, elevation=25, size=(320, 320))

# %%
# The MIP composite: the channels' colours added.
mip = scene.render(cam, "mip")
print(f"{len(mip.stats['channels'])} channels composited ({mip.stats['compositing']})")

# %%
# The same scene as isosurfaces, one isovalue per channel: each pixel shows the nearest surface.
scene.channels[0].iso, scene.channels[1].iso = 90.0, 110.0
iso = scene.render(cam, "iso")

# %%
# Hiding a channel leaves the other one alone.
scene.channels[1].visible = False
nucleus_only = scene.render(cam, "mip")
