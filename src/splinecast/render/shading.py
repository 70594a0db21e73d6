"""Blinn–Phong shading with a headlight, and distinct colours for front and back faces.

With the light at the eye, the light, view and half vectors all equal ``-ray``, so the diffuse term
is ``|n . ray|`` and the specular term ``|n . ray|^shininess``. A face is *front-facing* when the
ray crosses it from outside the object into it ("inside" is the side of the isovalue named by the
volume's ``metadata["inside"]``: ``"high"`` for CT/MRI-like data, ``"low"`` for distance fields).
Back faces appear where the object is cut by the volume box or a clip plane, or when the camera is
inside it.

Normals (``normals=``, :data:`NORMALS`): ``"smooth"`` (the default) shades with the gradient of
the model's shading field at the exact hit, ``"exact"`` with the gradient of the model's own
reconstruction. They differ for the models that are only continuous (trilinear, the linear
B-spline), whose gradient jumps between cells: their shading field is the cubic B-spline of the
voxels (:mod:`splinecast.models.shading_field`). The C1 and C2 models shade with their own
gradient either way. Which side a hit faces is always decided by the model's own gradient
(which way the ray crosses the surface it hit), also where the smooth normal, at a grazing hit,
points the other way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._jit import jit
from ..errors import ParameterError
from ..models.pieces import separate_shading, shading_gradient_at

__all__ = ["Shading", "shade_pixel", "NORMALS", "normals_code", "smooth_gradient"]

#: Normal choices accepted by ``Scene.render(..., normals=...)``: name -> kernel code.
NORMALS = {"smooth": 1, "exact": 0}


def normals_code(normals: str) -> int:
    """The kernel code of a ``normals`` choice.

    Raises
    ------
    ParameterError
        For a name not in :data:`NORMALS`.
    """
    if not isinstance(normals, str) or normals not in NORMALS:
        raise ParameterError(f"normals must be one of {', '.join(NORMALS)}, got {normals!r}")
    return NORMALS[normals]


def _rgb(value: object, name: str, n: int = 3) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size != n or not np.all((arr >= 0) & (arr <= 1)):
        raise ParameterError(f"{name} must be {n} numbers in [0, 1], got {value!r}")
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class Shading:
    """Colours and Blinn–Phong coefficients of the isosurface image.

    Parameters
    ----------
    front_color, back_color : 3 floats in [0, 1]
        Base colours of front and back faces.
    background : 4 floats in [0, 1]
        RGBA of pixels whose ray misses the surface.
    ambient, diffuse, specular : float
        Blinn–Phong weights.
    shininess : float
        Specular exponent.
    """

    front_color: tuple[float, ...] = (0.92, 0.84, 0.70)
    back_color: tuple[float, ...] = (0.35, 0.55, 0.90)
    background: tuple[float, ...] = (0.07, 0.07, 0.09, 1.0)
    ambient: float = 0.12
    diffuse: float = 0.78
    specular: float = 0.25
    shininess: float = 40.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "front_color", _rgb(self.front_color, "front_color"))
        object.__setattr__(self, "back_color", _rgb(self.back_color, "back_color"))
        object.__setattr__(self, "background", _rgb(self.background, "background", 4))
        for name in ("ambient", "diffuse", "specular", "shininess"):
            if not float(getattr(self, name)) >= 0:
                raise ParameterError(f"{name} must be >= 0, got {getattr(self, name)}")

    def as_array(self) -> np.ndarray:
        """Packed parameters for the compiled kernels (16 float64)."""
        return np.array(
            [*self.front_color, *self.back_color, *self.background,
             self.ambient, self.diffuse, self.specular, self.shininess],
            dtype=np.float64,
        )


@jit(inline="always")
def _power(x: float, e: float) -> float:
    """``x ** e`` for ``x`` in [0, 1]: an integral exponent up to 1024 (the usual shininess)
    by repeated squaring, a few multiplications where ``pow`` is a costly library call per pixel;
    within a few units in the last place of ``pow``."""
    n = int(e)
    if n == e and 0 <= n <= 1024:
        result = 1.0
        square = x
        while n > 0:
            if n & 1:
                result *= square
            square *= square
            n >>= 1
        return result
    return x**e


@jit(inline="always")
def shade_pixel(
    params: np.ndarray, front: bool, nx: float, ny: float, nz: float,
    ux: float, uy: float, uz: float,
) -> tuple[float, float, float]:
    """RGB of a hit with unit normal ``n`` seen along unit ray direction ``u``."""
    cos_theta = abs(nx * ux + ny * uy + nz * uz)
    base = 0 if front else 3
    amb, dif, spe, shin = params[10], params[11], params[12], params[13]
    spec = spe * _power(cos_theta, shin)
    r = params[base] * (amb + dif * cos_theta) + spec
    g = params[base + 1] * (amb + dif * cos_theta) + spec
    b = params[base + 2] * (amb + dif * cos_theta) + spec
    return min(r, 1.0), min(g, 1.0), min(b, 1.0)


@jit(inline="always")
def smooth_gradient(normals, grid, scratch, ray, x, y, z, gx, gy, gz):
    """The world gradient a hit is shaded with: the model's own ``g`` (world units), or with
    ``normals == 1`` and a model that shades with a field of its own, that field's gradient at
    the traversal-space point ``(x, y, z)`` (``ray`` as :mod:`.mode_api` gives it)."""
    if normals != 1 or not separate_shading(grid):
        return gx, gy, gz
    hx, hy, hz = shading_gradient_at(grid, scratch, x, y, z)
    return hx / ray.spacing_x, hy / ray.spacing_y, hz / ray.spacing_z
