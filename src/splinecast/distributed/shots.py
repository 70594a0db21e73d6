"""Batches of frames: a :class:`Shot` is one frame's camera and render options.

A camera path (a turntable), an isovalue sweep or a transfer-function sweep is a list of shots;
:meth:`DistributedScene.render_many` renders them as one batch of tasks and
:func:`render_locally` renders the same list in this process, one frame after another.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..camera import Camera
from ..errors import ParameterError
from ..render.frame import Frame
from ..scene import Scene

__all__ = ["Shot", "as_shots", "ramp", "orbit_path", "render_locally"]


@dataclass(frozen=True)
class Shot:
    """One frame of a batch: its camera and its ``Scene.render`` keyword arguments.

    Examples
    --------
    >>> import splinecast as sc
    >>> vol = sc.demo("sphere", size=16)
    >>> cam = sc.Camera.orbit(vol, size=(32, 32))
    >>> sweep = [Shot(cam, {"iso": v}) for v in (-0.2, 0.0, 0.2)]   # an isovalue sweep
    """

    camera: Camera
    options: Mapping[str, Any] = field(default_factory=dict)


def as_shots(cameras: Camera | Shot | Iterable[Camera | Shot], **options: Any) -> list[Shot]:
    """Shots from cameras or shots; ``options`` apply to every frame, a shot's own options
    override them."""
    if isinstance(cameras, (Camera, Shot)):
        cameras = [cameras]
    shots = []
    for item in cameras:
        if isinstance(item, Camera):
            shots.append(Shot(item, dict(options)))
        elif isinstance(item, Shot):
            shots.append(Shot(item.camera, {**options, **item.options}))
        else:
            raise ParameterError(f"expected a Camera or a Shot, got {type(item).__name__}")
    return shots


def ramp(values: float | Sequence[float], frames: int, name: str, periodic: bool = False
         ) -> np.ndarray:
    """``frames`` values from ``start`` to ``stop`` (or a constant for one number).

    With ``periodic=True`` and a range that is a whole number of turns (e.g. azimuth 30 to
    390), the end is left out so a looping movie does not show the same frame twice.
    """
    if frames < 1:
        raise ParameterError(f"frames must be at least 1, got {frames}")
    pair = [values] * 2 if np.isscalar(values) else list(values)
    try:
        start, stop = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number or (start, stop), got {values!r}") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise ParameterError(f"{name} must be finite, got {values!r}")
    turns = (stop - start) / 360.0
    loops = periodic and stop != start and turns == round(turns)
    return np.linspace(start, stop, frames, endpoint=not loops or frames == 1)


def orbit_path(volume: Any, frames: int, azimuth: float | Sequence[float] = (30.0, 390.0),
               elevation: float | Sequence[float] = 20.0, **orbit: Any) -> list[Camera]:
    """Cameras of a turntable: ``Camera.orbit`` at ``frames`` evenly spaced angles.

    Parameters
    ----------
    volume : Volume or VolumeInfo
        What to frame.
    frames : int
        Number of cameras.
    azimuth, elevation : float or (start, stop)
        Degrees; a pair moves linearly from start to stop. The default is one full turn
        (without repeating the first frame at the end).
    **orbit
        Other ``Camera.orbit`` arguments (``size``, ``zoom``, ``fov``, ``ortho``, ...).
    """
    azimuths = ramp(azimuth, frames, "azimuth", periodic=True)
    elevations = ramp(elevation, frames, "elevation")
    return [Camera.orbit(volume, azimuth=float(a), elevation=float(e), **orbit)
            for a, e in zip(azimuths, elevations, strict=True)]


def render_locally(scene: Scene, shots: Iterable[Shot], image_only: bool = False
                   ) -> Iterator[Frame | np.ndarray]:
    """Render ``shots`` in order in this process (each frame on all of Numba's threads).

    Yields a :class:`Frame` per shot, or its 8-bit RGBA image with ``image_only``, exactly as
    :meth:`DistributedScene.render_many` does.
    """
    for shot in shots:
        options = shot.options
        if image_only:  # colour is all that is kept: the other buffers are not even filled
            options = {"outputs": ("rgba",), **options}
        frame = scene.render(shot.camera, **options)
        yield frame.to_uint8() if image_only else frame
