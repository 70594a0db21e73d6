"""Synthetic test volumes with known analytic definitions: ``demo(name, size=..., ...)``.

Every volume samples its function at ``size`` points per axis that span the function's domain
exactly (the first and last voxel centres lie on the domain's faces), so world coordinates are the
function's own coordinates. Data are float32; ``metadata`` holds ``default_iso`` (the isovalue
that shows the object), ``inside`` (``"high"``/``"low"``: the side of that isovalue where the
object is) and ``domain``.

================  ==============  ===========  ======  ===========================================
name              domain          default_iso  inside  function
================  ==============  ===========  ======  ===========================================
marschner-lobb    [-1, 1]^3       0.5          high    Marschner & Lobb (1994) test signal
sphere            [-1, 1]^3       0.0          low     ``|p| - 0.6`` (signed distance)
torus             [-1, 1]^3       0.0          low     signed distance, R = 0.6, r = 0.25, axis z
chmutov           [-1.2, 1.2]^3   0.0          low     x^16 + y^16 + z^16 - cos 7x - cos 7y - cos 7z
noise             [0, 1]^3        0.5          high    seeded smooth random field, ~8 lobes per axis
================  ==============  ===========  ======  ===========================================

Marschner-Lobb side: ``rho`` is a density that falls from about 0.8-1.0 at ``z = -1`` to 0-0.2 at
``z = +1``; the 0.5 isosurface is the rippled roof of the dense lower half, so the object is where
``rho > 0.5`` ("high").

Chmutov domain: on the zero set ``x^16 = cos 7x + (cos 7y - y^16) + (cos 7z - z^16) <= cos 7x + 2``,
whose largest root is ``|x| = 1.05727`` (bisection); the cube ``[-1.2, 1.2]^3`` therefore holds the
whole surface with a margin of 0.14, and ``f >= 1.2^16 - 3 > 15`` on its faces.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qsl

import numpy as np

from ..errors import ParameterError, limits
from ..volume import Volume

__all__ = [
    "DEMOS",
    "demo",
    "demo_from_uri",
    "marschner_lobb",
    "marschner_lobb_gradient",
    "sphere_sdf",
    "torus_sdf",
    "chmutov",
    "noise",
]

ML_FM = 6.0
ML_ALPHA = 0.25
SPHERE_RADIUS = 0.6
TORUS_R = 0.6
TORUS_r = 0.25
CHMUTOV_HALF_WIDTH = 1.2
#: Lattice cells per axis of the noise field on [0, 1]: sets the size of its lobes.
NOISE_CELLS = 8
#: Maps the B-spline-smoothed lattice (std about 0.09 around 0.5) to roughly [0, 1]
#: (std about 0.18; about 1 % of the values fall outside [0, 1]).
_NOISE_GAIN = 2.0


# --------------------------------------------------------------------------- analytic functions
def marschner_lobb(
    x: Any, y: Any, z: Any, fm: float = ML_FM, alpha: float = ML_ALPHA
) -> np.ndarray:
    """The Marschner-Lobb test signal on [-1, 1]^3.

    ``rho = (1 - sin(pi z / 2) + alpha (1 + rho_r(sqrt(x^2 + y^2)))) / (2 (1 + alpha))`` with
    ``rho_r(r) = cos(2 pi fm cos(pi r / 2))``.

    Parameters
    ----------
    x, y, z : array_like
        World coordinates (broadcast together).
    fm, alpha : float, optional
        Ripple frequency (default 6) and ripple amplitude (default 0.25).

    Returns
    -------
    ndarray (float64)
        Values in [0, 1].
    """
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    r = np.sqrt(x * x + y * y)
    rho_r = np.cos(2.0 * np.pi * fm * np.cos(0.5 * np.pi * r))
    return (1.0 - np.sin(0.5 * np.pi * z) + alpha * (1.0 + rho_r)) / (2.0 * (1.0 + alpha))


def marschner_lobb_gradient(
    x: Any, y: Any, z: Any, fm: float = ML_FM, alpha: float = ML_ALPHA
) -> np.ndarray:
    """Analytic gradient of :func:`marschner_lobb`.

    Returns
    -------
    ndarray, shape (..., 3)
        ``(d/dx, d/dy, d/dz)`` at the broadcast points. Finite on the z axis: the factor
        ``sin(pi r / 2) / r`` is evaluated as ``(pi / 2) sinc(r / 2)``.
    """
    x, y, z = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, z)))
    r = np.sqrt(x * x + y * y)
    scale = 1.0 / (2.0 * (1.0 + alpha))
    # d rho_r / dr = pi^2 fm sin(pi r / 2) sin(2 pi fm cos(pi r / 2)); divided by r for x/r, y/r.
    per_r = (
        np.pi**2 * fm * (0.5 * np.pi) * np.sinc(0.5 * r)
        * np.sin(2.0 * np.pi * fm * np.cos(0.5 * np.pi * r))
    )
    gx = scale * alpha * per_r * x
    gy = scale * alpha * per_r * y
    gz = -scale * 0.5 * np.pi * np.cos(0.5 * np.pi * z)
    return np.stack([gx, gy, gz], axis=-1)


def sphere_sdf(x: Any, y: Any, z: Any, radius: float = SPHERE_RADIUS) -> np.ndarray:
    """Signed distance to a sphere of ``radius`` centred at the origin (negative inside)."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    return np.sqrt(x * x + y * y + z * z) - radius


def torus_sdf(
    x: Any, y: Any, z: Any, major: float = TORUS_R, minor: float = TORUS_r
) -> np.ndarray:
    """Signed distance to a torus around the z axis (tube radius ``minor``; negative inside)."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    ring = np.sqrt(x * x + y * y) - major
    return np.sqrt(ring * ring + z * z) - minor


def chmutov(x: Any, y: Any, z: Any) -> np.ndarray:
    """The Chmutov-like field ``x^16 + y^16 + z^16 - cos 7x - cos 7y - cos 7z`` (object: f < 0)."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    return x**16 + y**16 + z**16 - np.cos(7.0 * x) - np.cos(7.0 * y) - np.cos(7.0 * z)


# --------------------------------------------------------------------------- sampling
def _sample(func: Callable[..., np.ndarray], size: int, lo: float, hi: float) -> np.ndarray:
    """Sample ``func`` at ``size`` points per axis spanning [lo, hi], one x-plane at a time.

    Plane by plane keeps the float64 temporaries to one plane (a 512^3 volume never needs more
    than its float32 result), and broadcasting ``y`` as a column and ``z`` as a row lets functions
    of (x, y) only, like the Marschner-Lobb ripples, work on a vector instead of a plane.
    """
    axis = np.linspace(lo, hi, size)
    out = np.empty((size, size, size), dtype=np.float32)
    y = axis[:, None]
    z = axis[None, :]
    for i in range(size):
        out[i] = func(axis[i], y, z)
    return out


def _bspline_weights(u: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """First lattice index and the 4 uniform cubic B-spline weights at positions ``u`` (cells)."""
    base = np.minimum(np.floor(u), NOISE_CELLS - 1).astype(np.intp)
    t = u - base
    s = 1.0 - t
    w0 = s * s * s / 6.0
    w1 = (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0
    w2 = (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) / 6.0
    w3 = t * t * t / 6.0
    return base, (w0, w1, w2, w3)


def noise(size: int, seed: int = 0) -> np.ndarray:
    """A smooth random field on [0, 1]^3 sampled at ``size`` points per axis (float32).

    A seeded lattice of ``NOISE_CELLS + 3`` uniform random values per axis is interpolated with
    the cubic B-spline (C2, so isosurfaces are smooth), one axis at a time, and mapped to roughly
    [0, 1]. Only elementwise multiply/add in a fixed order is used (no BLAS, no transcendental
    functions), and numpy's PCG64 stream is platform independent, so a given ``(size, seed)``
    gives the same bits on every machine. The lobes scale with the domain, not with ``size``.
    """
    rng = np.random.default_rng(seed)
    # The weights sum to 1, so mapping the lattice maps the field: 0.5 + gain * (field - 0.5).
    lattice = 0.5 + _NOISE_GAIN * (rng.random((NOISE_CELLS + 3,) * 3) - 0.5)
    base, w = _bspline_weights(np.linspace(0.0, float(NOISE_CELLS), size))
    # Contract z, then y, on the small lattice: (L, L, L) -> (L, L, n) -> (L, n, n).
    t = sum(w[k][None, None, :] * lattice[:, :, base + k] for k in range(4))
    t = sum(w[k][None, :, None] * t[:, base + k, :] for k in range(4))
    # The x contraction writes the big result plane by plane in float32, without temporaries.
    t32 = t.astype(np.float32)
    w32 = [wk.astype(np.float32) for wk in w]
    out = np.empty((size, size, size), dtype=np.float32)
    term = np.empty((size, size), dtype=np.float32)
    for i in range(size):
        b = base[i]
        np.multiply(t32[b], w32[0][i], out=out[i])
        for k in range(1, 4):
            np.multiply(t32[b + k], w32[k][i], out=term)
            np.add(out[i], term, out=out[i])
    return out


# --------------------------------------------------------------------------- the registry
def _ml(size: int) -> np.ndarray:
    return _sample(marschner_lobb, size, -1.0, 1.0)


def _sphere(size: int) -> np.ndarray:
    return _sample(sphere_sdf, size, -1.0, 1.0)


def _torus(size: int) -> np.ndarray:
    return _sample(torus_sdf, size, -1.0, 1.0)


def _chmutov(size: int) -> np.ndarray:
    return _sample(chmutov, size, -CHMUTOV_HALF_WIDTH, CHMUTOV_HALF_WIDTH)


#: name -> (generator, domain (lo, hi), default_iso, inside, extra parameters with defaults)
DEMOS: dict[str, tuple[Callable[..., np.ndarray], tuple[float, float], float, str, dict[str, int]]]
DEMOS = {
    "marschner-lobb": (_ml, (-1.0, 1.0), 0.5, "high", {}),
    "sphere": (_sphere, (-1.0, 1.0), 0.0, "low", {}),
    "torus": (_torus, (-1.0, 1.0), 0.0, "low", {}),
    "chmutov": (_chmutov, (-CHMUTOV_HALF_WIDTH, CHMUTOV_HALF_WIDTH), 0.0, "low", {}),
    "noise": (noise, (0.0, 1.0), 0.5, "high", {"seed": 0}),
}


def demo(name: str, size: int = 64, **params: Any) -> Volume:
    """Build a synthetic test volume.

    Parameters
    ----------
    name : str
        One of ``marschner-lobb``, ``sphere``, ``torus``, ``chmutov``, ``noise``.
    size : int, optional
        Samples per axis (default 64, at least 2).
    **params
        Extra parameters of the volume: ``seed`` (int, default 0) for ``noise``.

    Returns
    -------
    Volume
        float32 data on the function's domain, with ``metadata`` ``name``
        (``"demo:<name>?size=N"``), ``default_iso``, ``inside`` and ``domain``.

    Raises
    ------
    ParameterError
        Unknown name, ``size`` below 2 or not an integer, unknown or invalid extra parameter.

    Examples
    --------
    >>> vol = demo("sphere", size=32)
    >>> vol.shape, vol.metadata["inside"]
    ((32, 32, 32), 'low')
    """
    if name not in DEMOS:
        raise ParameterError(
            f"unknown demo volume {limits.shorten(name)} (valid: {', '.join(DEMOS)})"
        )
    generator, (lo, hi), iso, inside, defaults = DEMOS[name]
    size = _as_int(size, "size")
    if size < 2:
        raise ParameterError(f"size must be at least 2 samples per axis, got {size}")
    size = limits.check_count(size, f"demo {name!r}: size", lo=2, hi=limits.MAX_AXIS)
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        valid = ", ".join(["size", *defaults])
        shown = limits.shorten(unknown[0])
        raise ParameterError(f"demo {name!r} has no parameter {shown} (valid: {valid})")
    extra = {key: _as_int(params.get(key, default), key) for key, default in defaults.items()}
    if "seed" in extra:  # numpy's generators take seeds in [0, 2**128)
        limits.check_count(extra["seed"], f"demo {name!r}: seed", lo=0, hi=2**64 - 1)
    # float32 result; the generators' temporaries are planes, small beside it.
    limits.check_memory(limits.nbytes((size, size, size), 4),
                        f"a {size}x{size}x{size} float32 volume", f"demo {name!r}: size")
    data = generator(size, **extra)
    label = f"demo:{name}?size={size}"
    # Only non-default extras are named, so the plain name stays "demo:<name>?size=N".
    label += "".join(f"&{k}={v}" for k, v in extra.items() if v != defaults[k])
    spacing = (hi - lo) / (size - 1)
    return Volume(
        data,
        spacing=spacing,
        origin=lo,
        metadata={
            "name": label,
            "source": label,
            "default_iso": iso,
            "inside": inside,
            "domain": (lo, hi),
            "format": "demo",
        },
    )


def demo_from_uri(uri: str) -> Volume:
    """Build a demo volume from ``"demo:<name>?key=value&..."`` (values parsed as int or float)."""
    body = uri[len("demo:"):] if uri.startswith("demo:") else uri
    name, _, query = body.partition("?")
    params: dict[str, Any] = {}
    for key, value in parse_qsl(query, keep_blank_values=True, strict_parsing=False):
        params[key] = _parse_number(value, key, uri)
    vol = demo(name.strip(), **params)
    vol.metadata["name"] = uri
    vol.metadata["source"] = uri
    return vol


def _parse_number(value: str, key: str, uri: str) -> int | float:
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    raise ParameterError(
        f"{limits.shorten(uri)}: parameter {limits.shorten(key)} must be a number, "
        f"got {limits.shorten(value)}"
    )


def _as_int(value: Any, name: str) -> int:
    return limits.check_count(value, name, lo=None)
