"""What the viewer does differently for each kind of data: one small class per kind.

The rest of the viewer never asks which kind of data it shows; it asks the kind
(:attr:`.data.Shown.kind`, a :class:`DataKind`):

* which scene to make of it (:meth:`DataKind.make_scene`), how many scenes to keep
  (:attr:`DataKind.max_scenes`, one when each holds a brick cache) and whether the one dropped
  is closed before another is made (:attr:`DataKind.close_before_open`);
* how a frame is rendered: in stripes a newer request can abandon or whole
  (:attr:`DataKind.stripes`), whether warming one tiny in-memory scene compiles every kernel its
  frames use (:attr:`DataKind.warm_covers`), how long each pass waits for bricks
  (:meth:`DataKind.render_options`);
* what the page may do with it: pick the label under a pixel (:attr:`DataKind.picks_labels`),
  see frames refine as a loader reads bricks (:attr:`DataKind.refreshes_with_bricks`), show
  another time point of the file (:attr:`DataKind.time_series`);
* what ``hello`` says of it (:meth:`DataKind.description`, the ``multires`` entry).

The kinds: :class:`InMemory` (a :class:`~splinecast.Volume` or a prepared
:class:`~splinecast.Scene`), :class:`Multiscale` (an OME-Zarr pyramid), :class:`Wavelet` (a
spline-wavelet store), :class:`Channels` and :class:`ChannelPyramids` (several channels on one
grid, in memory or as pyramids) and :class:`Labels` (a label volume).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from ..multires.scenes.channels import ChannelScene
from ..multires.scenes.labels import LabelScene
from ..scene import Scene

__all__ = ["DataKind", "InMemory", "Multiscale", "Wavelet", "Channels", "ChannelPyramids",
           "Labels", "FULL_WAIT_S"]

#: Longest wait (s) of a full frame for the bricks of its cut; later bricks come as refreshes.
FULL_WAIT_S = 0.5


class DataKind:
    """A kind of data the viewer shows; the defaults are those of one volume in memory.

    Subclasses declare what differs (class attributes) and override the methods whose answer
    depends on the pass or on the data.
    """

    #: The kind's name in messages (``hello.multires.kind`` for the multiresolution kinds).
    name: ClassVar[str] = "volume"
    #: What :meth:`make_scene` calls with the data, ``model=`` and the scene options
    #: (:class:`~splinecast.Scene` dispatches a pyramid or wavelet store to its own scene).
    scene_type: ClassVar[Callable[..., Any]] = Scene
    #: Whether the viewer closes the scene it drops before it opens another: a scene that holds
    #: memory up to a budget (a brick cache, a store's cut, a label pyramid's level) is never
    #: held twice. Otherwise the new scene is made first, so a model whose kernels are not
    #: ready drops nothing.
    close_before_open: ClassVar[bool] = False
    #: Scenes kept at once (each holds its model's arrays; one when each holds a brick cache
    #: or a scene per channel or label).
    max_scenes: ClassVar[int] = 2
    #: Whether a frame may be rendered in horizontal stripes that a newer request abandons.
    #: Not when the scene's work depends on the whole image: a cut chosen for the whole
    #: camera, a label traced in the window its box projects to.
    stripes: ClassVar[bool] = True
    #: Whether warming one tiny in-memory scene of the data's voxel type with the request's
    #: model and mode compiles every kernel a frame uses (otherwise a frame may compile).
    warm_covers: ClassVar[bool] = True
    #: Whether ``pick`` requests name the label under a pixel.
    picks_labels: ClassVar[bool] = False
    #: Whether the scene's loader reads bricks while frames are shown, so the server watches
    #: it and refreshes incomplete frames as the bricks of their view arrive.
    refreshes_with_bricks: ClassVar[bool] = False
    #: Whether another time point of the file the data was read from can be shown.
    time_series: ClassVar[bool] = False

    def make_scene(self, data: Any, model: str, options: dict[str, Any]) -> Any:
        """A scene of ``model`` of ``data`` made with the keyword arguments ``options``."""
        return self.scene_type(data, model=model, **options)

    def render_options(self, step: str) -> dict[str, Any]:
        """Extra keyword arguments of ``scene.render`` for a pass (``interactive``, ``coarse``,
        ``full``, ``refresh`` or ``screenshot``); none by default."""
        return {}

    def description(self, geometry: Any, preview: Any, scene: Any,
                    options: dict[str, Any]) -> dict[str, Any] | None:
        """The ``hello`` message's ``multires`` entry (None: not multiresolution data).

        ``geometry`` is the full-resolution data, ``preview`` the volume in memory, ``scene``
        the scene given or opened first (None if there is none yet) and ``options`` the
        keyword arguments of the scenes the viewer makes.
        """
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class InMemory(DataKind):
    """A volume in memory, or a prepared scene of one."""

    time_series = True


class Multiscale(DataKind):
    """An OME-Zarr pyramid: one brick cache at a time, frames rendered whole from the cut.

    A reduced or refresh frame draws what is resident at once (the loader goes on reading); a
    full frame waits up to :data:`FULL_WAIT_S` for its cut; a screenshot waits for the whole
    cut (a still image, as ``splinecast render``).
    """

    name = "multiscale"
    close_before_open = True
    max_scenes = 1
    stripes = False
    warm_covers = False
    refreshes_with_bricks = True
    time_series = True

    def render_options(self, step: str) -> dict[str, Any]:
        if step == "screenshot":
            return {"complete": True}
        if step == "full":
            return {"wait": True, "timeout": FULL_WAIT_S}
        return {"wait": False}

    def description(self, geometry: Any, preview: Any, scene: Any,
                    options: dict[str, Any]) -> dict[str, Any] | None:
        budget = scene.budget if scene is not None else options.get("budget")
        lod = scene.lod if scene is not None else options.get("lod")
        return {"kind": self.name, "levels": len(geometry.levels), "budget": budget,
                "lod": lod, "preview_shape": list(preview.shape)}


class Wavelet(DataKind):
    """A spline-wavelet store: its one model, frames rendered whole from the selection."""

    name = "wavelet"
    close_before_open = True
    stripes = False
    warm_covers = False

    def description(self, geometry: Any, preview: Any, scene: Any,
                    options: dict[str, Any]) -> dict[str, Any] | None:
        lod = scene.lod if scene is not None else options.get("lod")
        return {"kind": self.name, "degree": geometry.degree,
                "levels": geometry.layout.levels, "lod": lod,
                "preview_shape": list(preview.shape)}


class Channels(DataKind):
    """Several channels in memory on one grid, one set of channel scenes at a time.

    Warming one tiny scene need not cover every kernel the channels' scenes use, so their
    frames may compile.
    """

    name = "channels"
    scene_type = ChannelScene
    max_scenes = 1
    warm_covers = False


class ChannelPyramids(Channels):
    """Several channels as pyramids: a scene per channel, each with its own loader.

    Nothing refreshes as bricks arrive, so a full frame or a screenshot waits for every
    channel's cut; a reduced one draws what is resident.
    """

    close_before_open = True
    stripes = False

    def render_options(self, step: str) -> dict[str, Any]:
        return {"complete": True} if step in ("full", "screenshot") else {"wait": False}


class Labels(DataKind):
    """A label volume: each label its own surface, picked by pixel.

    Each label's scene is a float32 indicator whatever the labels' voxel type, so warming a
    tiny volume of that type does not stand for it; each label is traced in the window its box
    projects to, so frames are rendered whole.
    """

    name = "labels"
    scene_type = LabelScene
    close_before_open = True
    max_scenes = 1
    stripes = False
    warm_covers = False
    picks_labels = True
