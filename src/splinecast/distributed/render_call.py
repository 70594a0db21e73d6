"""A distributed ``render`` call's arguments, checked on the client as a local render checks them.

``render`` of both strategies is the render template's
(:meth:`splinecast.render.template.SceneTemplate.render`), which gathers its arguments into a
:class:`~splinecast.render.template.RenderOptions` on the client. The sort-first scene's other
entry points (:meth:`~splinecast.distributed.DistributedScene.render_tiles`,
:meth:`~splinecast.distributed.DistributedScene.render_many`) take the same arguments after the
camera; binding them here, before any task is submitted, makes a wrong name or count fail on the
client with Python's own message, and gives the workers the same ``RenderOptions``.
"""

from __future__ import annotations

import inspect
from typing import Any

from ..camera import Camera
from ..errors import ParameterError
from ..render.template import RenderOptions
from ..scene import Scene

__all__ = ["RENDER_SIGNATURE", "render_options"]

#: The signature every distributed ``render`` binds its arguments against.
RENDER_SIGNATURE = inspect.signature(Scene.render)


def render_options(camera: Camera, args: tuple, kwargs: dict[str, Any],
                   default_mode: str = "iso") -> RenderOptions:
    """``Scene.render``'s arguments after ``camera``, as the template gathers them.

    Parameters
    ----------
    camera : Camera
        The camera of the render.
    args, kwargs
        The remaining positional and keyword arguments of the call.
    default_mode : str
        The mode when none is given (the scene kind's ``default_mode``).

    Returns
    -------
    RenderOptions
        The arguments, the signature's defaults for those not given.

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
    if options.get("mode") is None:
        options["mode"] = default_mode
    return RenderOptions(**options)
