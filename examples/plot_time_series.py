"""
A time series: one volume per time point
========================================

A 4D file (a 4D NIfTI or NRRD, an OME-Zarr image with a ``t`` axis, a TIFF hyperstack, a dynamic
DICOM series) holds one 3D volume per time point. ``sc.read(path, timepoint=N)`` reads one of
them (only that one where the format allows), and every scene renders it as any volume. Here a
cell divides: a blob that stretches and splits into two over six time points, written as a 4D
NIfTI and read back one time point at a time, with the isovalue and camera chosen once so that
the frames compare.

From the command line, ``splinecast movie cell.nii.gz --timepoints 0:6 --iso 0.5 -o cell.gif``
makes the movie of these frames, and ``splinecast view cell.nii.gz`` shows a time slider.
"""

import tempfile
from pathlib import Path

import nibabel as nib
import numpy as np

import splinecast as sc

n, steps = 48, 6
x, y, z = np.meshgrid(*(np.linspace(-1.0, 1.0, n),) * 3, indexing="ij")
series = np.empty((n, n, n, steps), dtype=np.float32)
for t in range(steps):
    apart = 0.45 * t / (steps - 1)  # the two daughter cells move apart along x
    left = np.exp(-((x + apart) ** 2 + y**2 + z**2) / 0.12)
    right = np.exp(-((x - apart) ** 2 + y**2 + z**2) / 0.12)
    series[..., t] = left + right

# %%
# Written as a 4D NIfTI (what a microscope or scanner export gives), then read back one time
# point at a time; the metadata says how many there are.
frames = []
with tempfile.TemporaryDirectory() as folder:
    path = Path(folder) / "cell.nii.gz"
    nib.save(nib.Nifti1Image(series, np.diag([0.1, 0.1, 0.1, 1.0])), str(path))
    first = sc.read(path, timepoint=0)
    print(f"{first.metadata['timepoints']} time points of {first.shape}")
    camera = sc.Camera.orbit(first, azimuth=20, elevation=25, size=(200, 160))
    for t in range(0, steps, 2):
        volume = sc.read(path, timepoint=t)
        frames.append(sc.Scene(volume, model="s31").render(camera, iso=0.5))

# %%
# The time points 0, 2 and 4: the same isovalue and camera in every frame, so the frames
# differ only where the data does.
for t, frame in zip(range(0, steps, 2), frames, strict=True):
    print(f"time point {t}: {int(frame.hit.sum())} pixels on the surface")
