"""The :class:`Camera`: a look-at pinhole or orthographic camera and its per-pixel rays.

Image convention: ``rays()`` returns arrays shaped ``(height, width, 3)``; row 0 is the top of the
image and column 0 its left side. Rays go through pixel centres. Directions are unit vectors in
world space, so a ray parameter is a world distance.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from .errors import ParameterError

__all__ = [
    "Camera", "parse_size", "FIT_MARGIN", "BASIS_EYE", "BASIS_FORWARD", "BASIS_RIGHT", "BASIS_UP",
    "BASIS_HALF_WIDTH", "BASIS_HALF_HEIGHT", "BASIS_ORTHO", "BASIS_COL0", "BASIS_ROW0",
    "BASIS_FULL_WIDTH", "BASIS_FULL_HEIGHT", "BASIS_SUBPIXEL", "BASIS_SIZE",
]

# Where each quantity lies in :meth:`Camera.pixel_basis` (a flat float64 array, what compiled
# kernels take): the vectors are x, y, z from their offset on.
BASIS_EYE = 0  #: the eye's world position (3)
BASIS_FORWARD = 3  #: unit viewing direction (3)
BASIS_RIGHT = 6  #: unit image right (3)
BASIS_UP = 9  #: unit image up (3)
BASIS_HALF_WIDTH = 12  #: half the full image's window, at unit distance (world units if ortho)
BASIS_HALF_HEIGHT = 13
BASIS_ORTHO = 14  #: 1.0 for an orthographic camera, else 0.0 (offset 15 holds 0.0)
BASIS_COL0 = 16  #: column of the camera's first pixel in the full image
BASIS_ROW0 = 17  #: row of the camera's first pixel in the full image
BASIS_FULL_WIDTH = 18  #: the full image's width in pixels
BASIS_FULL_HEIGHT = 19  #: the full image's height in pixels
BASIS_SUBPIXEL = 20  #: the rays' shift inside their pixels, columns then rows (2)
BASIS_SIZE = 22  #: length of the array


def parse_size(size: Any) -> tuple[int, int]:
    """Validate an image size given as ``(width, height)`` or ``"WxH"``.

    Raises
    ------
    ParameterError
        If the size is not two positive integers.
    """
    if isinstance(size, str):
        parts = size.lower().split("x")
        if len(parts) != 2:
            raise ParameterError(f"size must look like WIDTHxHEIGHT, got {size!r}")
        try:
            size = (int(parts[0]), int(parts[1]))
        except ValueError:
            raise ParameterError(f"size must look like WIDTHxHEIGHT, got {size!r}") from None
    try:
        width, height = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ParameterError(f"size must be (width, height), got {size!r}") from None
    if width <= 0 or height <= 0:
        raise ParameterError(f"size must be positive, got {width}x{height}")
    if width * height > 64_000_000:
        raise ParameterError(f"size {width}x{height} is too large (more than 64 megapixels)")
    return width, height


#: Room left around a fitted box: its projection spans at most 1 / FIT_MARGIN of the image.
FIT_MARGIN = 1.08


def _fit_box(fit: Any, volume: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``None`` for ``fit="box"``, else the validated world box ``(lo, hi)``.

    ``fit="content"`` asks ``volume`` for its visible content (``volume.content_box()``): a
    :class:`splinecast.Scene` knows its isovalue or transfer function; a bare volume does not,
    and gets ``fit=splinecast.content_box(volume, iso=...)`` instead.
    """
    if isinstance(fit, str):
        if fit == "content":
            content = getattr(volume, "content_box", None)
            if not callable(content):
                raise ParameterError(
                    "fit='content' needs to know what is visible: pass a Scene "
                    "(Camera.orbit(scene, fit='content')) or "
                    "fit=splinecast.content_box(volume, iso=...)"
                )
            fit = content()
        elif fit != "box":
            raise ParameterError(
                f"fit must be 'box', 'content' or a world box (lo, hi) such as "
                f"splinecast.content_box(volume, iso=...), got {fit!r}"
            )
        else:
            return None
    try:
        box = np.asarray(fit, dtype=np.float64)
    except (TypeError, ValueError):
        box = np.zeros(0)
    if box.shape != (2, 3) or not np.all(np.isfinite(box)) or np.any(box[1] < box[0]):
        raise ParameterError(
            f"fit must be 'box' or a world box (lo, hi) with lo <= hi, got {fit!r}"
        )
    return box[0], box[1]


def _fit_corners(lo: np.ndarray, hi: np.ndarray, basis: Camera, half_fov: float,
                 aspect: float) -> tuple[float, float]:
    """Distance from the box centre at which a perspective ``basis`` camera sees all eight
    corners of ``[lo, hi]`` (with :data:`FIT_MARGIN`), and the half height of the window an
    orthographic camera needs for the same."""
    center = 0.5 * (lo + hi)
    corners = np.array([[(lo, hi)[b >> a & 1][a] for a in range(3)] for b in range(8)]) - center
    across = np.abs(corners @ basis.right) * FIT_MARGIN  # horizontal offset from the view axis
    above = np.abs(corners @ basis.up) * FIT_MARGIN
    ahead = corners @ basis.forward  # depth relative to the centre, positive away from the eye
    # A corner at depth (d + ahead) is inside the view when |across| <= tan_x (d + ahead) and
    # |above| <= tan_y (d + ahead).
    tan_y = math.tan(half_fov)
    tan_x = tan_y * aspect
    needed = np.maximum(across / tan_x, above / tan_y) - ahead
    depth_room = float(np.max(-ahead)) + 1e-9 * (1.0 + float(np.max(np.abs(corners))))
    distance = max(float(np.max(needed)), depth_room)
    if not distance > 0:  # a single point: frame a unit sphere around it
        distance = 1.0 / math.sin(min(half_fov, math.atan(tan_x)))
    half_height = max(float(np.max(above)), float(np.max(across)) / aspect) or 1.0
    return distance, half_height


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not math.isfinite(n) or n == 0.0:
        raise ParameterError(f"{name} must be a non-zero finite vector, got {v.tolist()}")
    return v / n


class Camera:
    """A look-at camera.

    Parameters
    ----------
    position : sequence of 3 floats
        Eye position in world coordinates.
    look_at : sequence of 3 floats
        Point the camera looks at (appears in the image centre).
    up : sequence of 3 floats, optional
        Approximate up direction; it is made orthogonal to the viewing direction.
    fov : float, optional
        Vertical field of view in degrees for perspective projection (default 30).
    size : (int, int) or str, optional
        Image ``(width, height)`` in pixels or ``"WxH"``.
    ortho : bool, optional
        Orthographic projection instead of perspective.
    ortho_height : float, optional
        Height of the visible window in world units for orthographic projection; by default the
        height a perspective camera with ``fov`` sees at the look-at distance.
    """

    def __init__(
        self,
        position: Any,
        look_at: Any,
        up: Any = (0.0, 0.0, 1.0),
        fov: float = 30.0,
        size: Any = (512, 512),
        ortho: bool = False,
        ortho_height: float | None = None,
    ) -> None:
        self.position = np.asarray(position, dtype=np.float64).reshape(3)
        self.look_at = np.asarray(look_at, dtype=np.float64).reshape(3)
        self.width, self.height = parse_size(size)
        if not 0.0 < float(fov) < 180.0:
            raise ParameterError(f"fov must be between 0 and 180 degrees, got {fov}")
        self.fov = float(fov)
        self.ortho = bool(ortho)
        forward = _unit(self.look_at - self.position, "look_at - position")
        up_vec = np.asarray(up, dtype=np.float64).reshape(3)
        right = np.cross(forward, up_vec)
        if np.linalg.norm(right) < 1e-9 * max(1.0, float(np.linalg.norm(up_vec))):
            # Looking along `up`: any perpendicular up will do; pick a stable one.
            alt = np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.9 else np.array([1.0, 0, 0])
            right = np.cross(forward, alt)
        self.forward = forward
        self.right = _unit(right, "right")
        self.up = np.cross(self.right, self.forward)
        distance = float(np.linalg.norm(self.look_at - self.position))
        if ortho_height is None:
            ortho_height = 2.0 * distance * math.tan(math.radians(self.fov) / 2.0)
        if not ortho_height > 0:
            raise ParameterError(f"ortho_height must be positive, got {ortho_height}")
        self.ortho_height = float(ortho_height)
        # The window of the full image this camera renders (see tile()): column and row of its
        # top-left pixel and the full image's size. A plain camera renders all of its image.
        self.region = (0, 0, self.width, self.height)
        # Where in its pixel each ray passes (see shifted()): the centre.
        self.subpixel = (0.0, 0.0)

    @property
    def size(self) -> tuple[int, int]:
        """Image ``(width, height)`` in pixels."""
        return self.width, self.height

    @classmethod
    def orbit(
        cls,
        volume: Any,
        azimuth: float = 30.0,
        elevation: float = 20.0,
        distance: float | None = None,
        size: Any = (512, 512),
        fov: float = 30.0,
        ortho: bool = False,
        zoom: float = 1.0,
        fit: Any = "box",
    ) -> Camera:
        """A camera on a sphere around the centre of ``volume``, looking at the centre.

        Parameters
        ----------
        volume : Volume or Scene
            What to frame (anything with world ``bounds``; ``fit="content"`` needs a Scene).
        azimuth, elevation : float
            Angles in degrees. Azimuth 0 looks from +x towards the centre, 90 from +y; elevation
            is measured from the xy-plane towards +z, which is also the up direction.
        distance : float, optional
            Distance from the centre; by default far enough that the whole box fits the view.
        size : (int, int) or str
            Image ``(width, height)``.
        fov : float
            Vertical field of view in degrees (perspective).
        ortho : bool
            Orthographic projection (the window then just fits the box).
        zoom : float
            Magnification (> 1 moves closer / narrows the window).
        fit : "box", "content" or (lo, hi)
            What to frame. ``"box"`` (default): the volume's whole bounding box, through its
            bounding sphere, so the framing is the same from every direction. ``"content"``:
            the part a Scene's isovalue or transfer function makes visible
            (:meth:`Scene.content_box`). A world-space box ``(lo, hi)`` (two 3-vectors),
            typically ``sc.content_box(volume, iso=...)``. For the last two the camera looks at
            the box's centre from just far enough that its eight corners fit the image seen from
            this direction (with a small margin), so the object fills the frame the way VTK's
            ``ResetCamera(bounds)`` does for the visible actors.

        Examples
        --------
        >>> import splinecast as sc
        >>> vol = sc.demo("sphere", size=32)
        >>> cam = sc.Camera.orbit(vol, fit=sc.content_box(vol, iso=0.0), size=(64, 64))
        >>> cam = sc.Camera.orbit(sc.Scene(vol), fit="content", size=(64, 64))
        """
        if not (math.isfinite(azimuth) and math.isfinite(elevation)):
            raise ParameterError("azimuth and elevation must be finite numbers")
        if not (math.isfinite(zoom) and zoom > 0):
            raise ParameterError(f"zoom must be a positive finite number, got {zoom}")
        if not 0.0 < fov < 180.0:  # checked before tan(fov) below, not only in __init__
            raise ParameterError(f"fov must be between 0 and 180 degrees, got {fov}")
        box = _fit_box(fit, volume)
        lo, hi = box if box is not None else volume.bounds
        center = 0.5 * (lo + hi)
        radius = 0.5 * float(np.linalg.norm(hi - lo)) or 1.0
        width, height = parse_size(size)
        half_fov = math.radians(fov) / 2.0
        # The bounding sphere must fit the narrower of the two fields of view.
        half_fov_min = min(half_fov, math.atan(math.tan(half_fov) * width / height))
        if distance is not None and not distance > 0:
            raise ParameterError(f"distance must be positive, got {distance}")
        az, el = math.radians(azimuth), math.radians(elevation)
        direction = np.array(
            [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
        )
        up = np.array([0.0, 0.0, 1.0])
        if abs(math.cos(el)) < 1e-9:
            up = np.array([-math.cos(az), -math.sin(az), 0.0]) * math.copysign(1.0, math.sin(el))
        aspect = width / height
        ortho_height = 2.0 * radius * max(1.0, 1.0 / aspect) / zoom if ortho else None
        fit_distance = radius / math.sin(half_fov_min)
        if box is not None:
            # The view's basis does not depend on the distance: take it from a unit camera.
            basis = cls(center + direction, center, up=up, size=(width, height))
            fit_distance, half_height = _fit_corners(lo, hi, basis, half_fov, aspect)
            if ortho:
                ortho_height = 2.0 * half_height / zoom
        if distance is None:
            distance = fit_distance / zoom
        return cls(center + distance * direction, center, up=up, fov=fov, size=(width, height),
                   ortho=ortho, ortho_height=ortho_height)

    def tile(self, col0: int, row0: int, width: int, height: int) -> Camera:
        """A camera that renders only the ``width x height`` pixels of this camera's image whose
        top-left pixel is ``(row0, col0)``.

        The tile's rays are bit-identical to the same pixels' rays of the full image, so tiles
        rendered separately (on other threads, processes or machines) assemble into exactly the
        full render. Tiles of a tile refer to the full image.

        Raises
        ------
        ParameterError
            If the window does not lie inside the image or is empty.
        """
        c0, r0, w, h = (int(v) for v in (col0, row0, width, height))
        if w < 1 or h < 1 or c0 < 0 or r0 < 0 or c0 + w > self.width or r0 + h > self.height:
            raise ParameterError(
                f"tile ({c0}, {r0}, {w}x{h}) must lie inside the {self.width}x{self.height} image"
            )
        out = copy.copy(self)
        out.width, out.height = w, h
        base_c, base_r, full_w, full_h = self.region
        out.region = (base_c + c0, base_r + r0, full_w, full_h)
        return out

    def box_window(self, lo: Any, hi: Any, pad: int = 2) -> tuple[int, int, int, int] | None:
        """The window of this camera's image (``col0, row0, width, height`` for :meth:`tile`)
        that holds every ray meeting the world box ``[lo, hi]``, ``pad`` pixels wider on each
        side; ``None`` when no ray of the image can meet it.

        The box's eight corners are projected onto the image; when a corner lies behind the
        eye (a perspective camera inside or beside the box) the whole image is returned.
        """
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        corners = np.array([[(lo, hi)[(n >> a) & 1][a] for a in range(3)] for n in range(8)])
        basis = self.pixel_basis()
        half_w, half_h = basis[BASIS_HALF_WIDTH], basis[BASIS_HALF_HEIGHT]
        col_base, row_base, full_w, full_h = self.region
        v = corners - self.position
        z = v @ self.forward
        sx, sy = v @ self.right, v @ self.up
        if not self.ortho:
            if np.any(z <= 1e-9 * max(1.0, float(np.abs(v).max()))):
                return 0, 0, self.width, self.height
            sx, sy = sx / z, sy / z
        # Pixel centres: col + 0.5 = (sx / half_w + 1) / 2 * full_w (the formula of rays()).
        cols = (sx / half_w + 1.0) * 0.5 * full_w - 0.5 - col_base
        rows = (1.0 - sy / half_h) * 0.5 * full_h - 0.5 - row_base
        c0 = max(0, int(math.floor(cols.min())) - pad)
        c1 = min(self.width - 1, int(math.ceil(cols.max())) + pad)
        r0 = max(0, int(math.floor(rows.min())) - pad)
        r1 = min(self.height - 1, int(math.ceil(rows.max())) + pad)
        if c0 > c1 or r0 > r1:
            return None
        return c0, r0, c1 - c0 + 1, r1 - r0 + 1

    def shifted(self, dx: float, dy: float) -> Camera:
        """This camera with every ray moved ``dx`` pixels to the right and ``dy`` pixels down
        inside its pixel (the sub-pixel samples of antialiasing).

        ``|dx|, |dy| <= 1/2``: each ray stays in its own pixel. Shifts do not add up: the
        shifted camera's rays are this camera's unshifted rays moved by ``(dx, dy)``; its tiles
        (:meth:`tile`) keep the shift.

        Raises
        ------
        ParameterError
            If a shift is not a number in ``[-1/2, 1/2]``.
        """
        try:
            shift = (float(dx), float(dy))
        except (TypeError, ValueError):
            raise ParameterError(f"sub-pixel shift must be two numbers, got {dx!r}, {dy!r}"
                                 ) from None
        if not all(-0.5 <= v <= 0.5 for v in shift):
            raise ParameterError(f"sub-pixel shift must lie in [-0.5, 0.5], got {shift}")
        out = copy.copy(self)
        out.subpixel = shift
        return out

    def pixel_basis(self) -> np.ndarray:
        """Packed ray parameters for compiled kernels that generate rays per pixel.

        Returns 22 float64 (at the offsets the module's ``BASIS_*`` constants name): eye (3),
        forward (3), right (3), up (3), half width and half height of the full image's window
        (at unit distance for perspective, in world units for orthographic), an orthographic
        flag, 0, then the column and row of this camera's first pixel in the full image and the
        full image's width and height (see :meth:`tile`), and the rays' shift inside their
        pixels (:meth:`shifted`; 0, 0 through the centres).
        :meth:`rays` and the kernels follow the same formula: pixel ``(row, col)`` has screen
        coordinates ``sx = ((col + col0 + 0.5 + dx) / full_width * 2 - 1) * half_w`` and
        ``sy = (1 - (row + row0 + 0.5 + dy) / full_height * 2) * half_h``.
        """
        col0, row0, full_w, full_h = self.region
        half_h = 0.5 * self.ortho_height if self.ortho else math.tan(math.radians(self.fov) / 2)
        half_w = half_h * full_w / full_h
        dx, dy = getattr(self, "subpixel", (0.0, 0.0))  # cameras pickled before shifts existed
        return np.concatenate(
            [self.position, self.forward, self.right, self.up,
             [half_w, half_h, 1.0 if self.ortho else 0.0, 0.0, col0, row0, full_w, full_h,
              dx, dy]]
        ).astype(np.float64)

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel ray origins and unit directions.

        Returns
        -------
        origins, directions : ndarray, shape (height, width, 3), float64
            Row 0 is the top of the image. For a perspective camera every origin is the eye
            position; for an orthographic one the origins lie on the image plane through the eye.
        """
        w, h = self.width, self.height
        basis = self.pixel_basis()
        half_w, half_h = basis[BASIS_HALF_WIDTH], basis[BASIS_HALF_HEIGHT]
        col0, row0 = basis[BASIS_COL0], basis[BASIS_ROW0]
        full_w, full_h = basis[BASIS_FULL_WIDTH], basis[BASIS_FULL_HEIGHT]
        dx, dy = basis[BASIS_SUBPIXEL], basis[BASIS_SUBPIXEL + 1]
        xs = ((np.arange(w) + col0 + 0.5 + dx) / full_w * 2.0 - 1.0) * half_w
        ys = (1.0 - (np.arange(h) + row0 + 0.5 + dy) / full_h * 2.0) * half_h
        sx = xs[None, :, None]
        sy = ys[:, None, None]
        if self.ortho:
            origins = self.position + sx * self.right + sy * self.up
            directions = np.broadcast_to(self.forward, (h, w, 3)).copy()
        else:
            origins = np.broadcast_to(self.position, (h, w, 3)).copy()
            d = self.forward + sx * self.right + sy * self.up
            directions = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return np.ascontiguousarray(origins), np.ascontiguousarray(directions)

    def __repr__(self) -> str:
        kind = f"ortho_height={self.ortho_height:g}" if self.ortho else f"fov={self.fov:g}"
        return (
            f"Camera(position={self.position.tolist()}, look_at={self.look_at.tolist()}, "
            f"size={self.width}x{self.height}, {kind})"
        )
