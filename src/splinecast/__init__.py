"""splinecast: exact, fast isosurface rendering of voxel data.

The public API::

    import splinecast as sc
    vol = sc.read("head.nii.gz")               # or sc.demo("marschner-lobb", size=128)
    scene = sc.Scene(vol, model="trilinear")
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(1024, 768))
    frame = scene.render(cam, mode="iso", iso=80)
    frame.save("head.png")

Coordinate convention: see :mod:`splinecast.volume`.
"""

from .camera import Camera
from .errors import DataError, ParameterError, ReadError, SplinecastError
from .io import demo, read, write
from .io.multichannel import MultichannelVolume
from .io.store_kinds import register_store_kind as _register_store_kind
from .models import MODELS
from .models.smoothing import smooth
from .multires.scenes.channels import Channel, ChannelScene
from .preintegration import preintegrate
from .render.aip import Aip
from .render.defaults import (
    auto_colormap,
    auto_inside,
    auto_iso,
    auto_transfer_function,
    auto_window,
    background_value,
    content_box,
    is_signed,
)
from .render.dvr import DVRSettings
from .render.effects import SurfaceEffects
from .render.frame import Frame
from .render.modes import Dvr, Iso, MinIp, Mip, MultiIso
from .render.shading import Shading
from .scene import LABELS as _LABELS
from .scene import Scene, check_iso, register_scene_type
from .transfer import TransferFunction
from .volume import Volume

__version__ = "0.1.0"

#: Names loaded on first use, so that ``import splinecast`` never imports zarr, dask or the
#: viewer's server.
_LAZY = {
    "build_pyramid": ("splinecast.multires.store.pyramid", "build_pyramid"),
    "MultiscaleVolume": ("splinecast.io.omezarr", "MultiscaleVolume"),
    "MultiscaleScene": ("splinecast.multires.scenes.multiscale", "MultiscaleScene"),
    "LabelScene": ("splinecast.multires.scenes.labels", "LabelScene"),
    "WaveletVolume": ("splinecast.multires.wavelet.store", "WaveletVolume"),
    "WaveletScene": ("splinecast.multires.scenes.wavelet", "WaveletScene"),
    "multires": ("splinecast.multires", None),
    "view": ("splinecast.viewer", "view"),
}


def _multiscale_scene(volume, *args, **kwargs):
    """``Scene(MultiscaleVolume, ...)``: the renderer of cuts (loaded with zarr on first use)."""
    from .multires.scenes.multiscale import MultiscaleScene

    return MultiscaleScene(volume, *args, **kwargs)


register_scene_type("splinecast.io.omezarr.MultiscaleVolume", _multiscale_scene)


# Several channels on one grid: a list of volumes, or what read(path, channel=[0, 2]) gives.
for _kind in ("splinecast.io.multichannel.MultichannelVolume", "builtins.list",
              "builtins.tuple"):
    register_scene_type(_kind, ChannelScene)


def _wavelet_scene(volume, *args, **kwargs):
    """``Scene(WaveletVolume, ...)``: the spline-wavelet renderer (loaded on first use)."""
    from .multires.scenes.wavelet import WaveletScene

    return WaveletScene(volume, *args, **kwargs)


def _open_wavelet_store(path, root, attributes):
    """``read("x.zarr")`` of a spline-wavelet store: a lazy ``WaveletVolume``."""
    from .multires.wavelet.store import open_wavelet_store

    return open_wavelet_store(path, root, attributes)


register_scene_type("splinecast.multires.wavelet.store.WaveletVolume", _wavelet_scene)


def _label_scene(volume, *args, **kwargs):
    """``Scene(volume, labels=True, ...)``: each label's surface in its colour (any volume)."""
    from .multires.scenes.labels import LabelScene

    return LabelScene(volume, *args, **kwargs)


register_scene_type(_LABELS, _label_scene)
_register_store_kind("wavelet", _open_wavelet_store)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        module, attribute = _LAZY[name]
        loaded = importlib.import_module(module)
        return loaded if attribute is None else getattr(loaded, attribute)
    raise AttributeError(f"module 'splinecast' has no attribute {name!r}")


__all__ = [
    "Aip",
    "Camera",
    "Channel",
    "ChannelScene",
    "MODELS",
    "LabelScene",
    "MultichannelVolume",
    "MultiscaleScene",
    "MultiscaleVolume",
    "DVRSettings",
    "Dvr",
    "Iso",
    "MinIp",
    "Mip",
    "MultiIso",
    "DataError",
    "Frame",
    "ParameterError",
    "ReadError",
    "Scene",
    "Shading",
    "SplinecastError",
    "SurfaceEffects",
    "TransferFunction",
    "Volume",
    "WaveletScene",
    "WaveletVolume",
    "auto_colormap",
    "auto_inside",
    "auto_iso",
    "auto_transfer_function",
    "auto_window",
    "background_value",
    "build_pyramid",
    "check_iso",
    "content_box",
    "demo",
    "is_signed",
    "preintegrate",
    "read",
    "smooth",
    "view",
    "write",
]

