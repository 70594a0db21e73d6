"""Surface effects: solid procedural textures at the exact hit position, and cel shading.

Textures are *solid* (3D) patterns evaluated at the world position of the hit, so they need no
surface parametrization and stay put on the object when the isovalue changes:

* ``checker``: cubes of edge ``scale`` (world units) alternate between the surface colour and a
  darker tone (``dark`` times the colour);
* ``noise``: seeded gradient noise (a lattice of pseudo-random unit gradients hashed from the
  integer lattice point and the seed, blended with the quintic fade ``6t^5 - 15t^4 + 10t^3``;
  our own hash, not a published permutation table) with feature size ``scale``; the colour is
  multiplied by ``1 + strength * noise`` (noise lies in about [-1, 1]).

Cel shading replaces the smooth diffuse term ``|n . l|`` of the headlight by ``bands`` flat levels
(``floor(|n . l| * bands) / (bands - 1)``, capped at 1) and the specular term by an on/off
highlight, giving the banded look of Koch 2009 (section 4, "N.L looked up in a 1D texture").

Effects for single-isosurface images are applied after tracing, from the Frame's exact hit
positions and normals (:func:`apply_effects`), so they work for every model's iso kernel; the
multi-isosurface kernel calls :func:`surface_rgb` per layer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._jit import jit
from .._jit.work_queue import run_items, take
from ..errors import ParameterError
from .rays import pixel_ray

__all__ = ["SurfaceEffects", "TEXTURES", "noise3", "checker3", "surface_rgb", "apply_effects"]

#: Texture names accepted by :class:`SurfaceEffects` (index = code in the packed parameters).
TEXTURES = (None, "checker", "noise")


@dataclass(frozen=True)
class SurfaceEffects:
    """Procedural texture and shading style of isosurfaces.

    Parameters
    ----------
    texture : {None, "checker", "noise"}
        Solid texture evaluated at the hit position.
    scale : float
        Checker cube edge or noise feature size, in world units.
    seed : int
        Seed of the noise texture.
    strength : float
        Noise amplitude (colour times ``1 + strength * noise``).
    dark : float
        Brightness of the dark checker cubes relative to the surface colour.
    cel_bands : int
        0 for smooth Blinn-Phong; 2 or more for cel shading with that many diffuse levels.
    """

    texture: str | None = None
    scale: float = 0.1
    seed: int = 0
    strength: float = 0.5
    dark: float = 0.45
    cel_bands: int = 0

    def __post_init__(self) -> None:
        if self.texture not in TEXTURES:
            names = ", ".join(t for t in TEXTURES if t)
            raise ParameterError(f"texture must be one of {names} or None, got {self.texture!r}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ParameterError(f"texture scale must be positive, got {self.scale}")
        if not 0 <= self.dark <= 1:
            raise ParameterError(f"dark must be in [0, 1], got {self.dark}")
        if not 0 <= self.strength <= 1:
            raise ParameterError(f"strength must be in [0, 1], got {self.strength}")
        if self.cel_bands == 1 or self.cel_bands < 0 or int(self.cel_bands) != self.cel_bands:
            raise ParameterError(f"cel_bands must be 0 (off) or an integer >= 2, "
                                 f"got {self.cel_bands}")

    @property
    def active(self) -> bool:
        """Whether anything differs from plain Blinn-Phong shading."""
        return self.texture is not None or self.cel_bands > 0

    def as_array(self) -> np.ndarray:
        """Packed parameters for the kernels: texture code, scale, seed, strength, dark, bands."""
        return np.array([TEXTURES.index(self.texture), self.scale, self.seed, self.strength,
                         self.dark, self.cel_bands], dtype=np.float64)


#: Packed parameters meaning "no effect".
NO_EFFECTS = SurfaceEffects().as_array()


@jit(inline="always")
def _hash(ix: int, iy: int, iz: int, seed: int) -> int:
    """A 32-bit integer hash of a lattice point and a seed (multiply-xorshift mixing)."""
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791) ^ (seed * 2654435761)
    h &= 0xFFFFFFFF
    h ^= h >> 16
    h = (h * 0x7FEB352D) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x846CA68B) & 0xFFFFFFFF
    h ^= h >> 16
    return h


@jit(inline="always")
def _grad_dot(ix: int, iy: int, iz: int, seed: int, fx: float, fy: float, fz: float) -> float:
    """Dot product of the lattice point's pseudo-random unit gradient with the offset ``f``."""
    h = _hash(ix, iy, iz, seed)
    # Two uniform numbers from the hash give a uniformly distributed direction on the sphere.
    u = (h & 0xFFFF) / 65535.0 * 2.0 - 1.0
    phi = ((h >> 16) & 0xFFFF) / 65536.0 * 2.0 * math.pi
    s = math.sqrt(max(0.0, 1.0 - u * u))
    return s * math.cos(phi) * fx + s * math.sin(phi) * fy + u * fz


@jit(inline="always")
def _fade(t: float) -> float:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@jit()
def noise3(x: float, y: float, z: float, seed: int) -> float:
    """Seeded gradient noise at ``(x, y, z)`` (lattice spacing 1); 0 on lattice points."""
    x0, y0, z0 = math.floor(x), math.floor(y), math.floor(z)
    fx, fy, fz = x - x0, y - y0, z - z0
    ix, iy, iz = int(x0), int(y0), int(z0)
    u, v, w = _fade(fx), _fade(fy), _fade(fz)
    total = 0.0
    for dz in range(2):
        wz = w if dz else 1.0 - w
        for dy in range(2):
            wy = v if dy else 1.0 - v
            for dx in range(2):
                wx = u if dx else 1.0 - u
                total += wx * wy * wz * _grad_dot(ix + dx, iy + dy, iz + dz, seed,
                                                   fx - dx, fy - dy, fz - dz)
    # The gradient-noise amplitude stays below about 1/sqrt(2) ... 1; scale to about [-1, 1].
    return min(max(total * 1.6, -1.0), 1.0)


@jit(inline="always")
def checker3(x: float, y: float, z: float, scale: float) -> int:
    """1 on the "dark" cubes of a 3D checkerboard with cube edge ``scale``, else 0."""
    s = math.floor(x / scale) + math.floor(y / scale) + math.floor(z / scale)
    return int(s) & 1


@jit(inline="always")
def surface_rgb(shading: np.ndarray, effects: np.ndarray, rgb: tuple, n: tuple, u: tuple,
                p: tuple) -> tuple:
    """Shaded colour of a surface point with base colour ``rgb``, unit normal ``n`` seen along
    ``u``, at world position ``p`` (headlight Blinn-Phong of :mod:`.shading` plus effects; each
    a tuple of three floats)."""
    r, g, b = rgb
    nx, ny, nz = n
    ux, uy, uz = u
    px, py, pz = p
    kind = int(effects[0])
    if kind == 1:
        if checker3(px, py, pz, effects[1]) == 1:
            r, g, b = r * effects[4], g * effects[4], b * effects[4]
    elif kind == 2:
        f = 1.0 + effects[3] * noise3(px / effects[1], py / effects[1], pz / effects[1],
                                      int(effects[2]))
        r, g, b = r * f, g * f, b * f
    cos_theta = abs(nx * ux + ny * uy + nz * uz)
    amb, dif, spe, shin = shading[10], shading[11], shading[12], shading[13]
    bands = int(effects[5])
    if bands >= 2:
        level = min(math.floor(cos_theta * bands), bands - 1) / (bands - 1)
        spec = spe if cos_theta**shin > 0.5 else 0.0
        light = amb + dif * level
    else:
        spec = spe * cos_theta**shin
        light = amb + dif * cos_theta
    return min(r * light + spec, 1.0), min(g * light + spec, 1.0), min(b * light + spec, 1.0)


def apply_effects(basis: np.ndarray, shading: np.ndarray, effects: np.ndarray,
                  position: np.ndarray, normal: np.ndarray, face: np.ndarray,
                  rgba: np.ndarray) -> None:
    """Re-shade every hit pixel of a first-hit frame with ``effects`` (in place).

    Front faces use ``shading``'s front colour, back faces its back colour, as the iso kernels do.
    Rows are spread over threads (:func:`~splinecast._jit.work_queue.run_items`).
    """
    run_items(_effect_rows, face.shape[0], basis, shading, effects, position, normal, face, rgba)


@jit
def _effect_rows(basis, shading, effects, position, normal, face, rgba, counter):
    """One thread's share of :func:`apply_effects`: the rows it takes."""
    height, width = face.shape
    while True:
        row = take(counter)
        if row >= height:
            break
        for col in range(width):
            f = face[row, col]
            if f == 0:
                continue
            _, _, _, ux, uy, uz = pixel_ray(basis, row, col, width, height)
            base = 0 if f > 0 else 3
            r, g, b = surface_rgb(
                shading, effects, (shading[base], shading[base + 1], shading[base + 2]),
                (normal[row, col, 0], normal[row, col, 1], normal[row, col, 2]), (ux, uy, uz),
                (position[row, col, 0], position[row, col, 1], position[row, col, 2]))
            rgba[row, col, 0] = r
            rgba[row, col, 1] = g
            rgba[row, col, 2] = b
