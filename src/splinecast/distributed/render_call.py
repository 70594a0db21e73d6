"""A distributed ``render`` call's arguments, checked on the client as a local render checks them.

Both strategies (sort-first, :mod:`splinecast.distributed.scene`, and sort-last,
:mod:`splinecast.distributed.sort_last`) accept exactly the arguments of
:meth:`splinecast.Scene.render` after the camera and ship them to the workers as keywords; binding
them here, before any task is submitted, makes a wrong name or count fail on the client with
Python's own message.
"""

from __future__ import annotations

import inspect
from typing import Any

from ..camera import Camera
from ..errors import ParameterError
from ..scene import Scene

__all__ = ["RENDER_SIGNATURE", "render_options"]

#: The signature every distributed ``render`` binds its arguments against.
RENDER_SIGNATURE = inspect.signature(Scene.render)


def render_options(camera: Camera, args: tuple, kwargs: dict[str, Any]) -> dict[str, Any]:
    """``Scene.render``'s arguments after ``camera``, as keywords.

    Parameters
    ----------
    camera : Camera
        The camera of the render.
    args, kwargs
        The remaining positional and keyword arguments of the call.

    Returns
    -------
    dict
        Every argument given, by name (defaults are not filled in).

    Raises
    ------
    ParameterError
        ``camera`` is not a :class:`~splinecast.Camera`.
    TypeError
        An unknown name or too many arguments, exactly as a local render raises it.
    """
    if not isinstance(camera, Camera):
        raise ParameterError(f"camera must be a splinecast.Camera, got {type(camera).__name__}")
    bound = RENDER_SIGNATURE.bind(None, camera, *args, **kwargs)
    options = dict(bound.arguments)
    del options["self"], options["camera"]
    return options
