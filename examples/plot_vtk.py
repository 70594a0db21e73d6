"""
VTK and PyVista data
====================

A ``vtkImageData`` (a ``pyvista.ImageData`` works the same way, without splinecast importing
pyvista) becomes a :class:`splinecast.Volume` with :meth:`~splinecast.Volume.from_vtk`: VTK stores
point data x fastest, and the volume is a transposed view of the same memory. ``.vti`` files
round-trip through :func:`splinecast.write` and :func:`splinecast.read`.
"""

import tempfile
from pathlib import Path

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtk
from vtkmodules.vtkCommonDataModel import vtkImageData

import splinecast as sc

# A torus-like field on a 48 x 40 x 24 grid with anisotropic spacing, built as VTK would.
nx, ny, nz = 48, 40, 24
spacing = (0.5, 0.5, 1.0)
i, j, k = np.indices((nx, ny, nz))
x, y, z = (i - nx / 2) * spacing[0], (j - ny / 2) * spacing[1], (k - nz / 2) * spacing[2]
field = (np.hypot(x, y) - 7.0) ** 2 + z**2                      # distance^2 to a ring

image = vtkImageData()
image.SetDimensions(nx, ny, nz)
image.SetSpacing(*spacing)
values = numpy_to_vtk(field.ravel(order="F"), deep=True)        # x fastest, as VTK stores it
values.SetName("ring")
image.GetPointData().SetScalars(values)

vol = sc.Volume.from_vtk(image, metadata={"inside": "low"})     # small values are the object
print(vol, vol.metadata["array"])

with tempfile.TemporaryDirectory() as folder:
    path = Path(folder) / "ring.vti"
    sc.write(vol, path)                                         # ParaView opens this file
    back = sc.read(path)
    assert np.array_equal(back.data, vol.data)

cam = sc.Camera.orbit(vol, azimuth=20, elevation=35, size=(260, 200),
                      fit=sc.content_box(vol, iso=4.0))
frame = sc.Scene(vol).render(cam, iso=4.0)
