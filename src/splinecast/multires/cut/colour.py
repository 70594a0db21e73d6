"""CIELUV colours of transfer-function-classified values: the distance behind D(b) (eq. 2).

Carmona & Froehlich 2011 measure the distortion of a brick in CIELUV, the colour space in which
Euclidean distance follows perceived difference (a distance below about 6 is not noticeable). Eq.
(2) compares ``L(rgb(f) alpha(f))`` for a source value ``f`` with ``L(rgb(b) alpha(b))`` for its
approximation ``b``: the transfer function's colour premultiplied by its opacity, i.e. the colour a
one-voxel slab of that material shows over black.

Choices made here:

* the transfer function's RGB is read as **sRGB** (the colormaps are display colours, and the
  renderer writes its composited RGB straight into an sRGB PNG), so ``rgb * alpha`` is decoded
  with the sRGB transfer curve, taken to XYZ with the sRGB matrix, and to L*u*v*;
* the white point is **D65**, the reference white of sRGB (Xn, Yn, Zn = 0.95047, 1, 1.08883);
* ``alpha`` is :meth:`splinecast.transfer.TransferFunction.opacity`, the opacity of a slab one
  voxel thick.
"""

from __future__ import annotations

import numpy as np

from ...transfer import TransferFunction

__all__ = ["srgb_to_luv", "classified_luv", "distortion_table", "D65"]

#: Reference white of sRGB (CIE D65, 2-degree observer), XYZ with Y = 1.
D65 = np.array([0.95047, 1.0, 1.08883])

# IEC 61966-2-1 matrix from linear sRGB to CIE XYZ (D65).
_SRGB_TO_XYZ = np.array([
    [0.4124564, 0.3575761, 0.1804375],
    [0.2126729, 0.7151522, 0.0721750],
    [0.0193339, 0.1191920, 0.9503041],
])


def _uv_prime(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CIE 1976 chromaticity (u', v'); black (a zero denominator) maps to (0, 0)."""
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    den = x + 15.0 * y + 3.0 * z
    safe = np.where(den > 0, den, 1.0)
    return np.where(den > 0, 4.0 * x / safe, 0.0), np.where(den > 0, 9.0 * y / safe, 0.0)


def srgb_to_luv(rgb: np.ndarray, white: np.ndarray = D65) -> np.ndarray:
    """CIE L*u*v* of sRGB colours in [0, 1], shape ``(..., 3)``.

    sRGB is decoded to linear light (the piecewise curve of IEC 61966-2-1), taken to XYZ, then
    ``L* = 116 (Y/Yn)^(1/3) - 16`` (linear ``(29/3)^3 Y/Yn`` near black),
    ``u* = 13 L* (u' - u'n)``, ``v* = 13 L* (v' - v'n)``.
    """
    c = np.clip(np.asarray(rgb, np.float64), 0.0, 1.0)
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = linear @ _SRGB_TO_XYZ.T
    yr = xyz[..., 1] / white[1]
    eps = (6.0 / 29.0) ** 3
    lightness = np.where(yr > eps, 116.0 * np.cbrt(yr) - 16.0, (29.0 / 3.0) ** 3 * yr)
    u, v = _uv_prime(xyz)
    un, vn = _uv_prime(np.asarray(white, np.float64))
    return np.stack([lightness, 13.0 * lightness * (u - un), 13.0 * lightness * (v - vn)],
                    axis=-1)


def classified_luv(tf: TransferFunction, values: np.ndarray) -> np.ndarray:
    """``L(rgb(v) alpha(v))`` of eq. (2) for data values ``v``: shape ``(..., 3)``."""
    values = np.asarray(values, np.float64)
    premultiplied = tf.color(values) * tf.opacity(values)[..., None]
    return srgb_to_luv(premultiplied)


def distortion_table(tf: TransferFunction, bin_values: np.ndarray) -> np.ndarray:
    """``D(u, v)`` of eq. (2) for every pair of quantized values: shape ``(n, n)``, float64.

    ``bin_values`` are the data values the ``n`` histogram bins stand for; entry ``[u, v]`` is
    the CIELUV distance between the classified colours of bins ``u`` (source) and ``v``
    (approximation). Built once per transfer function (``n`` = 256: 65536 distances).
    """
    luv = classified_luv(tf, bin_values)
    diff = luv[:, None, :] - luv[None, :, :]
    return np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
