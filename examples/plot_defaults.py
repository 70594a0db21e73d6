"""
Nothing but the data: automatic isovalue, window and transfer function
======================================================================

A phantom with a large empty background, two nested materials and noise, stored as ``int64``
(NumPy's and PyVista's default integer type; splinecast converts it to the smallest exact type).
No isovalue, window or transfer function is given: each is chosen from the histogram, and the
camera frames what is visible rather than the whole grid.
"""

import numpy as np

import splinecast as sc

rng = np.random.default_rng(0)
n = 64
x, y, z = np.indices((n, n, n)) - np.array([40, 24, 30])[:, None, None, None]
r = np.sqrt(x**2 + (1.3 * y) ** 2 + z**2)
data = np.where(r < 14, 100, 0) + np.where(r < 7, 80, 0)          # shell and core
data = data + (r < 14) * rng.integers(0, 20, (n, n, n))            # noise inside the object
vol = sc.Volume(data.astype(np.int64))
print(vol.dtype, "| automatic isovalue", sc.auto_iso(vol), "| window", sc.auto_window(vol))

scene = sc.Scene(vol)
size = (240, 200)

# %%
# Isosurface at Otsu's threshold of the non-background values:
iso = scene.render(sc.Camera.orbit(vol, size=size, fit=sc.content_box(vol)))

# %%
# Maximum intensity projection with a percentile window:
mip = scene.render(sc.Camera.orbit(vol, size=size, fit=sc.content_box(vol)), mode="mip")

# %%
# Volume rendering with the automatic transfer function (an opacity ramp from the isovalue up,
# viridis colours):
tf = sc.auto_transfer_function(vol)
print(tf)
dvr = scene.render(sc.Camera.orbit(vol, size=size, fit=sc.content_box(vol, tf=tf)), mode="dvr")

# %%
# For comparison, the old framing of the whole grid (``fit="box"``): the object is small.
whole = scene.render(sc.Camera.orbit(vol, size=size, fit="box"))
