"""The scenes of the comparison: a volume, its isovalues and, for analytic volumes, the truth."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import splinecast as sc
from splinecast.io import synthetic

from .._machine import MRI  # the MRI rows' volume (``SPLINECAST_BENCH_MRI``)


@dataclass(frozen=True)
class Truth:
    """The analytic function a synthetic volume samples, for measuring surface errors.

    ``value(points)`` and ``gradient(points)`` take world points shaped ``(..., 3)`` (synthetic
    volumes use the function's own coordinates as world coordinates).
    """

    value: Callable[[np.ndarray], np.ndarray]
    gradient: Callable[[np.ndarray], np.ndarray]


def _central_gradient(func: Callable[..., np.ndarray], h: float = 1e-6):
    """Gradient of an analytic function by central differences in float64.

    With ``h = 1e-6`` on functions of unit scale the truncation error is ~1e-12 and the rounding
    error ~1e-10, far below anything a renderer can resolve; it lets the sphere and torus share
    one code path without hand-derived gradients.
    """

    def gradient(points: np.ndarray) -> np.ndarray:
        x, y, z = np.moveaxis(np.asarray(points, np.float64), -1, 0)
        return np.stack([
            (func(x + h, y, z) - func(x - h, y, z)) / (2 * h),
            (func(x, y + h, z) - func(x, y - h, z)) / (2 * h),
            (func(x, y, z + h) - func(x, y, z - h)) / (2 * h),
        ], axis=-1)

    return gradient


def _pointwise(func: Callable[..., np.ndarray]) -> Callable[[np.ndarray], np.ndarray]:
    return lambda p: func(*np.moveaxis(np.asarray(p, np.float64), -1, 0))


TRUTHS: dict[str, Truth] = {
    "marschner-lobb": Truth(
        _pointwise(synthetic.marschner_lobb),
        _pointwise(synthetic.marschner_lobb_gradient),
    ),
    "sphere": Truth(_pointwise(synthetic.sphere_sdf), _central_gradient(synthetic.sphere_sdf)),
    "torus": Truth(_pointwise(synthetic.torus_sdf), _central_gradient(synthetic.torus_sdf)),
}


@dataclass
class SceneSpec:
    """One comparison scene.

    Attributes
    ----------
    label : str
        Name in tables and plots.
    make : callable
        Builds the :class:`splinecast.Volume` (called once per process that needs it).
    isos : list of float
        ``isos[0]`` is the isovalue of record (quality and steady frames); the others alternate
        for the "new isovalue to first image" timings so every timed run is a real change.
    truth : Truth or None
        Analytic function for the quality metrics (None: timing only).
    kind : str
        ``"ml"``, ``"noise"``, ``"mri"`` or ``"sdf"``: groups the time-vs-size plot.
    size : int
        Samples per axis (the largest axis for the MRI), for plots.
    """

    label: str
    make: Callable[[], sc.Volume]
    isos: list[float]
    truth: Truth | None = None
    kind: str = "ml"
    size: int = 0
    extra: dict = field(default_factory=dict)


def _demo(name: str, size: int, **params: int) -> Callable[[], sc.Volume]:
    return lambda: sc.demo(name, size=size, **params)


def ml(size: int) -> SceneSpec:
    """Marschner-Lobb at ``size``^3, isovalue 0.5."""
    return SceneSpec(f"marschner-lobb {size}^3", _demo("marschner-lobb", size),
                     [0.5, 0.4, 0.45, 0.55, 0.6], TRUTHS["marschner-lobb"], "ml", size)


def noise(size: int) -> SceneSpec:
    """The seeded smooth random field at ``size``^3, isovalue 0.5."""
    return SceneSpec(f"noise {size}^3", _demo("noise", size, seed=0),
                     [0.5, 0.4, 0.45, 0.55, 0.6], None, "noise", size)


def sdf(name: str, size: int) -> SceneSpec:
    """The analytic sphere or torus distance field at ``size``^3, isovalue 0."""
    return SceneSpec(f"{name} SDF {size}^3", _demo(name, size),
                     [0.0, -0.04, -0.02, 0.02, 0.04], TRUTHS[name], "sdf", size)


def mri() -> SceneSpec | None:
    """The MNI152 T1 MRI at isovalue 80, or None when the file is absent."""
    if not MRI.exists():
        return None
    return SceneSpec("MNI152 T1 MRI 197x233x189", lambda: sc.read(MRI),
                     [80.0, 40.0, 60.0, 100.0, 120.0], None, "mri", 233)


def full_suite() -> tuple[list[SceneSpec], list[str]]:
    """The scenes of the issue; returns the scenes and notes about skipped ones."""
    scenes = [ml(64), ml(128), ml(256), sdf("sphere", 128), sdf("torus", 128)]
    notes = []
    brain = mri()
    if brain is None:
        notes.append(f"MRI skipped: {MRI} not found")
    else:
        scenes.append(brain)
    scenes += [noise(256), noise(512)]
    return scenes, notes


def quick_suite() -> tuple[list[SceneSpec], list[str]]:
    """The small suite the tests run: 64^3 volumes."""
    return [ml(64), sdf("sphere", 64), sdf("torus", 64)], []



def by_label(label: str) -> SceneSpec:
    """Rebuild a scene from its label (subprocess workers receive labels, not closures)."""
    name, _, rest = label.partition(" ")
    if label.startswith("MNI152"):
        spec = mri()
        if spec is None:
            raise FileNotFoundError(MRI)
        return spec
    size = int(label.rsplit(" ", 1)[1].split("^")[0])
    if name == "marschner-lobb":
        return ml(size)
    if name == "noise":
        return noise(size)
    if name in ("sphere", "torus"):
        return sdf(name, size)
    raise ValueError(f"unknown scene label {label!r}")
