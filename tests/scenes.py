"""Test volumes shared by several test modules (built with splinecast; the references in
``reference.py`` stay free of it)."""

from __future__ import annotations

import numpy as np
from reference import smooth_noise

import splinecast as sc

#: The anisotropic smooth-noise volume: shape, spacing, origin, and an isovalue through it.
NOISE_SHAPE = (12, 11, 13)
NOISE_SPACING = (1.0, 1.3, 0.8)
NOISE_ORIGIN = (0.5, -1.0, 2.0)
NOISE_ISO = 0.2


def noise_volume() -> sc.Volume:
    """Smooth seeded noise (zero mean, unit deviation), float32 like most data (the kernels
    interpolate it in float64, as the references do), with unequal spacing so that the
    index-to-world scaling of depths and gradients is exercised."""
    data = smooth_noise(NOISE_SHAPE, seed=3, sigma=2.0).astype(np.float32)
    return sc.Volume(data, spacing=NOISE_SPACING, origin=NOISE_ORIGIN)
