"""Multichannel rendering: several channels of one grid drawn together.

References, all computed by the test from renders of single channels (``sc.Scene`` of one
volume, the code path every other test checks):

- MIP: each channel's projected values (``Frame.value``) mapped by the test through the
  channel's window onto a black-to-colour ramp, summed, clipped, put over the background; and,
  for one channel, the kernel's own colormapping with an explicit black-to-colour colormap.
- iso: a depth test done by the test: each pixel takes the colour of the single-channel render
  whose depth is smallest.
- DVR: the single-channel renders on a transparent background, summed by the test.
- A mode defined here with a compositing rule of its own (the "lighten" blend): the
  single-channel projections through their windows, their per-pixel maximum taken by the test.

Files holding channels are written by ome-zarr-py (with its ``omero`` display metadata),
tifffile and vtk from arrays the test holds.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main
from splinecast.multires.scenes.channels import compositing
from splinecast.render.compose import ADDITIVE, NEAREST_HIT, Composite, Compositing

SIZE = (40, 32)
BG = (0.07, 0.07, 0.09, 1.0)


def _blob(centre: tuple[float, float, float], radius: float, shape=(24, 22, 20)) -> np.ndarray:
    x, y, z = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    cx, cy, cz = centre
    return np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / radius**2).astype(
        np.float32)


@pytest.fixture(scope="module")
def pair() -> list[sc.Volume]:
    """Two overlapping blobs on one grid: channel 0 left, channel 1 right and brighter."""
    a = sc.Volume(_blob((-0.25, 0.0, 0.0), 0.45), spacing=(1.0, 1.0, 1.2))
    b = sc.Volume(2.0 * _blob((0.3, 0.1, 0.0), 0.4), spacing=(1.0, 1.0, 1.2))
    return [a, b]


@pytest.fixture(scope="module")
def camera(pair) -> sc.Camera:
    return sc.Camera.orbit(pair[0], azimuth=20, elevation=15, size=SIZE)


def _ramp(value: np.ndarray, window, color) -> np.ndarray:
    lo, hi = window
    t = np.clip((value - lo) / (hi - lo), 0.0, 1.0)
    return np.where(np.isfinite(value), 1.0, 0.0)[..., None] * t[..., None] * np.asarray(color)


# --------------------------------------------------------------------------- MIP
def test_mip_is_the_sum_of_the_single_channel_projections(pair, camera):
    colors, windows = [(1.0, 0.0, 1.0), (0.0, 1.0, 0.0)], [(0.1, 0.9), (0.2, 1.6)]
    scene = sc.Scene(pair, colors=colors, windows=windows)
    assert isinstance(scene, sc.ChannelScene)
    frame = scene.render(camera, "mip")
    assert frame.stats["compositing"] == "additive"
    singles = [sc.Scene(v).render(camera, "mip", window=w, outputs=("value", "depth"))
               for v, w in zip(pair, windows, strict=True)]
    summed = sum(_ramp(f.value, w, c) for f, w, c in zip(singles, windows, colors, strict=True))
    met = np.any([np.isfinite(f.value) for f in singles], axis=0)
    expected = np.where(met[..., None], np.minimum(summed, 1.0), np.asarray(BG[:3]))
    assert met.any() and (~met).any()
    np.testing.assert_allclose(frame.rgba[..., :3], expected, atol=2e-6)
    assert np.all(frame.rgba[..., 3] == 1.0)
    # Both channels show and overlap somewhere: magenta + green adds up to white there.
    both = (singles[0].value > 0.5) & (singles[1].value > 1.0)
    assert both.any() and np.all(frame.rgba[both][:, :3] > 0.4)
    np.testing.assert_array_equal(frame.depth, np.minimum(singles[0].depth, singles[1].depth))


def test_every_projection_mode_composites_as_mip_does(pair, camera):
    """Modes asked of the registry, not listed: each projection through a window (aip too)
    sums its channels' ramps as MIP does."""
    from splinecast.render.modes import MODES

    colors, windows = [(1.0, 0.0, 1.0), (0.0, 1.0, 0.0)], [(0.05, 0.5), (0.1, 0.8)]
    scene = sc.Scene(pair, colors=colors, windows=windows)
    projections = [name for name, mode in MODES.items() if "window" in mode.keywords]
    assert {"mip", "minip", "aip"} <= set(projections)
    for name in projections:
        frame = scene.render(camera, name)
        assert frame.stats["compositing"] == "additive"
        singles = [sc.Scene(v).render(camera, name, window=w, outputs=("value", "depth"))
                   for v, w in zip(pair, windows, strict=True)]
        summed = sum(_ramp(f.value, w, c) for f, w, c in zip(singles, windows, colors,
                                                                strict=True))
        met = np.any([np.isfinite(f.value) for f in singles], axis=0)
        drawn = met & np.any(summed > 0, axis=-1)
        # (The blobs' minima are background everywhere: a minIP draws nothing to compare.)
        assert drawn.any() or name == "minip", name
        np.testing.assert_allclose(frame.rgba[drawn][:, :3], np.minimum(summed, 1.0)[drawn],
                                   atol=2e-6, err_msg=name)


def test_mip_does_not_depend_on_the_channel_order(pair, camera):
    colors = [(1.0, 0.2, 0.0), (0.0, 0.6, 1.0)]
    forward = sc.Scene(pair, colors=colors).render(camera, "mip")
    backward = sc.Scene(pair[::-1], colors=colors[::-1]).render(camera, "mip")
    np.testing.assert_allclose(forward.rgba, backward.rgba, atol=1e-6)


def test_one_channel_equals_the_kernels_colormap_of_its_ramp(pair, camera):
    """A second code path: the MIP kernel's own colormapping (1024 entries, nearest) with a
    black-to-colour colormap; misses and background rays on the background in both."""
    color, window = (0.2, 0.9, 0.5), (0.05, 0.8)
    frame = sc.Scene([pair[0]], colors=[color], windows=[window]).render(camera, "mip")
    single = sc.Scene(pair[0]).render(camera, "mip", window=window,
                                      colormap=[(0.0, 0, 0, 0), (1.0, *color)])
    np.testing.assert_allclose(frame.rgba, single.rgba, atol=1.0 / 1023 + 1e-6)


def test_a_hidden_channel_is_left_out(pair, camera):
    scene = sc.Scene(pair, colors=["red", "lime"], windows=[(0.1, 0.9), (0.1, 1.8)])
    scene.channels[1].visible = False
    alone = sc.Scene([pair[0]], colors=["red"], windows=[(0.1, 0.9)]).render(camera, "mip")
    frame = scene.render(camera, "mip")
    np.testing.assert_array_equal(frame.rgba, alone.rgba)
    assert [c["index"] for c in frame.stats["channels"]] == [0]
    scene.channels[0].visible = False
    empty = scene.render(camera, "mip")
    assert np.all(empty.rgba == np.float32(BG)) and not np.isfinite(empty.depth).any()


# --------------------------------------------------------------------------- iso
def test_iso_shows_the_nearest_channel_surface(pair, camera):
    colors, isos = [(0.9, 0.2, 0.2), (0.2, 0.8, 0.3)], [0.5, 1.0]
    frame = sc.Scene(pair, colors=colors, isos=isos).render(camera, "iso", samples=1)
    assert frame.stats["compositing"] == "nearest hit"
    singles = []
    for v, c, iso in zip(pair, colors, isos, strict=True):
        shading = sc.Shading(front_color=c, back_color=tuple(0.6 * x for x in c))
        singles.append(sc.Scene(v).render(camera, "iso", iso=iso, shading=shading, samples=1))
    depth = np.stack([f.depth for f in singles])
    nearest = np.argmin(depth, axis=0)
    hit = np.isfinite(depth).any(axis=0)
    rgba = np.stack([f.rgba for f in singles])
    rows, cols = np.indices(nearest.shape)
    expected = np.where(hit[..., None], rgba[nearest, rows, cols], np.float32(BG))
    # Each channel is nearest somewhere: the depth test really picks.
    assert {0, 1} <= set(np.unique(nearest[hit]).tolist())
    np.testing.assert_allclose(frame.rgba, expected, atol=1e-6)
    np.testing.assert_array_equal(frame.depth, depth.min(axis=0))
    np.testing.assert_array_equal(frame.normal[hit],
                                  np.stack([f.normal for f in singles])[nearest, rows, cols][hit])


# --------------------------------------------------------------------------- DVR
def test_dvr_adds_the_single_channel_renderings(pair, camera):
    tfs = [sc.TransferFunction([(0.2, 0.0), (0.9, 0.3)], (0.2, 0.9),
                               colormap=[(0, 1, 0, 1), (1, 1, 0, 1)]),
           sc.TransferFunction([(0.4, 0.0), (1.8, 0.3)], (0.4, 1.8),
                               colormap=[(0, 0, 1, 0), (1, 0, 1, 0)])]
    frame = sc.Scene(pair, tfs=tfs).render(camera, "dvr")
    clear = sc.Shading(background=(0, 0, 0, 0))
    singles = [sc.Scene(v).render(camera, "dvr", tf=tf, shading=clear).rgba.astype(np.float64)
               for v, tf in zip(pair, tfs, strict=True)]
    colour = np.minimum(singles[0][..., :3] + singles[1][..., :3], 1.0)
    alpha = 1.0 - (1.0 - singles[0][..., 3:]) * (1.0 - singles[1][..., 3:])
    expected = colour + (1.0 - alpha) * np.asarray(BG[:3])
    assert (singles[0][..., 3] > 0.05).any() and (singles[1][..., 3] > 0.05).any()
    np.testing.assert_allclose(frame.rgba[..., :3], expected, atol=2e-6)


def test_a_dvr_mode_object_keeps_its_transfer_function(pair, camera):
    """A ``Dvr(tf)`` object's transfer function is the channels' as the ``tf`` keyword is
    (not replaced by each channel's automatic one)."""
    tf = sc.TransferFunction([(0.2, 0.0), (0.9, 0.4)], (0.2, 0.9),
                             colormap=[(0, 1, 0.5, 0), (1, 1, 0.5, 0)])
    scene = sc.Scene(pair)
    by_object = scene.render(camera, sc.Dvr(tf))
    np.testing.assert_array_equal(by_object.rgba, scene.render(camera, "dvr", tf=tf).rgba)
    assert not np.array_equal(by_object.rgba, scene.render(camera, "dvr").rgba)


def test_dvr_default_transfer_function_takes_the_channel_colour(pair, camera):
    frame = sc.Scene([pair[0]], colors=["red"]).render(camera, "dvr")
    assert frame.rgba[..., 0].max() > 0.3
    np.testing.assert_allclose(frame.rgba[..., 1:3].max(), BG[2], atol=1e-6)


# --------------------------------------------------------------------------- a mode's rule
class Lighten(Compositing):
    """A rule written by the test: per pixel and component, the brightest channel's value
    (the "lighten" blend), the nearest depth."""

    name = "lighten"

    def __init__(self) -> None:
        self.calls: list[tuple[int, frozenset[str]]] = []

    def reads(self, wanted):
        return frozenset({"position"} & wanted)

    def combine(self, layers, frames, wanted):
        self.calls.append((len(layers), frozenset(n for n in ("value", "position", "rgba")
                                                  if getattr(frames[0], n) is not None)))
        return Composite(np.max(layers, axis=0), np.min([f.depth for f in frames], axis=0))


@dataclasses.dataclass(frozen=True)
class LightenMip(sc.Mip):
    """MIP whose channels combine by the test's rule (a mode object of a class that is not in
    the registry: the channel scene asks its class, not its name)."""

    compositing: ClassVar[Compositing] = Lighten()


def test_a_mode_s_declared_rule_composites_the_channels(pair, camera):
    colors, windows = [(1.0, 0.2, 0.0), (0.3, 0.6, 1.0)], [(0.1, 0.9), (0.2, 1.6)]
    scene = sc.Scene(pair, colors=colors, windows=windows)
    rule = LightenMip.compositing
    frame = scene.render(camera, LightenMip(), outputs=("rgba", "depth"))
    assert frame.stats["compositing"] == "lighten" and frame.stats["mode"] == "mip"
    assert rule.calls == [(2, frozenset({"value"}))]  # a projection: layers from the values
    singles = [sc.Scene(v).render(camera, "mip", window=w, outputs=("value", "depth"))
               for v, w in zip(pair, windows, strict=True)]
    layers = [_ramp(f.value, w, c) for f, w, c in zip(singles, windows, colors, strict=True)]
    met = np.any([np.isfinite(f.value) for f in singles], axis=0)
    expected = np.where(met[..., None], np.maximum(*layers), np.asarray(BG[:3]))
    np.testing.assert_allclose(frame.rgba[..., :3], expected, atol=2e-6)
    # Not the additive composite: where both channels show, the sum differs from the maximum.
    both = np.all([lay.sum(axis=-1) > 0.2 for lay in layers], axis=0)
    assert both.any()
    assert np.abs(frame.rgba[both][:, :3] - np.minimum(sum(layers), 1.0)[both]).max() > 0.1
    np.testing.assert_array_equal(frame.depth, np.minimum(singles[0].depth, singles[1].depth))
    # The buffers the rule reads are rendered for it when the frame asks for them.
    scene.render(camera, LightenMip(), outputs=("rgba", "position"))
    assert rule.calls[-1] == (2, frozenset({"value", "position"}))


def test_the_built_in_modes_declare_their_rules():
    from splinecast.render.modes import MODES

    assert MODES["iso"].compositing is NEAREST_HIT and sc.MultiIso.compositing is NEAREST_HIT
    for name in ("mip", "minip", "aip", "dvr"):
        assert MODES[name].compositing is ADDITIVE, name
    assert compositing("iso") == "nearest hit" and compositing(sc.Dvr()) == "additive"


# --------------------------------------------------------------------------- bad input
def test_channels_on_different_grids_are_refused(pair):
    other = sc.Volume(np.zeros((24, 22, 19), np.float32), metadata={"name": "short.nrrd"})
    with pytest.raises(sc.ParameterError, match=r"^short\.nrrd: volumes: shape \(24, 22, 19\) "
                                                r"differs from .*\(24, 22, 20\)"):
        sc.Scene([pair[0], other])
    moved = sc.Volume(pair[1].data, spacing=(1.0, 1.0, 1.2), origin=(0, 0, 3.0),
                      metadata={"name": "moved.nii"})
    with pytest.raises(sc.ParameterError, match=r"^moved\.nii: volumes: origin"):
        sc.ChannelScene([pair[0], moved])


@pytest.mark.parametrize("kwargs, needle", [
    ({"colors": ["red"]}, "colors: 1 given for 2 channels"),
    ({"colors": ["red", "nocolour"]}, "is not a colour"),
    ({"windows": [(1, 0), None]}, "lo < hi"),
])
def test_bad_channel_settings(pair, kwargs, needle):
    with pytest.raises(sc.ParameterError, match=needle):
        sc.Scene(pair, **kwargs)


def test_colormap_is_refused_for_channels(pair, camera):
    with pytest.raises(sc.ParameterError, match="colormap does not apply"):
        sc.Scene(pair).render(camera, "mip", colormap="hot")


# --------------------------------------------------------------------------- files
def _ome_zarr_py_store(path: Path, data: np.ndarray, omero: dict) -> None:
    """An OME-Zarr image written by ome-zarr-py (axes c, z, y, x; no pyramid)."""
    writer = pytest.importorskip("ome_zarr.writer")
    writer.write_image(data, str(path), axes="czyx", scale_factors=[], omero=omero)


OMERO = {"channels": [
    {"label": "DAPI", "color": "0000FF", "active": True,
     "window": {"start": 0.1, "end": 0.9, "min": 0.0, "max": 1.0}},
    {"label": "GFP", "color": "00FF00", "active": True,
     "window": {"start": 0.2, "end": 1.5, "min": 0.0, "max": 2.0}},
    {"label": "RFP", "color": "FF0000", "active": False,
     "window": {"start": 0.0, "end": 1.0, "min": 0.0, "max": 1.0}}]}


@pytest.fixture(scope="module")
def store(tmp_path_factory, pair) -> tuple[Path, np.ndarray]:
    folder = tmp_path_factory.mktemp("omero")
    xyz = np.stack([pair[0].data, pair[1].data, 0.5 * pair[0].data])
    czyx = np.ascontiguousarray(xyz.transpose(0, 3, 2, 1))
    path = folder / "cells.ome.zarr"
    _ome_zarr_py_store(path, czyx, OMERO)
    return path, xyz


def test_omero_metadata_gives_the_channel_defaults(store):
    path, xyz = store
    volumes = sc.read(path, channel="all")
    assert isinstance(volumes, sc.MultichannelVolume) and len(volumes) == 3
    for c in range(3):
        assert np.array_equal(volumes[c].levels[0].read((0, 0, 0), volumes.shape), xyz[c])
    with sc.Scene(volumes) as scene:
        got = [(c.label, c.color, c.window, c.visible) for c in scene.channels]
    assert got == [("DAPI", (0.0, 0.0, 1.0), (0.1, 0.9), True),
                   ("GFP", (0.0, 1.0, 0.0), (0.2, 1.5), True),
                   ("RFP", (1.0, 0.0, 0.0), (0.0, 1.0), False)]
    one = sc.read(path, channel=1)
    assert one.metadata["channel_label"] == "GFP"
    assert [c["label"] for c in one.metadata["omero"]] == ["DAPI", "GFP", "RFP"]


def test_ome_zarr_channels_render_as_the_in_memory_channels(store, camera, pair):
    """The store's channels 0 and 1 with their omero colours and windows, rendered from the
    store, against the same arrays in memory with the same settings."""
    path, _ = store
    with sc.Scene(sc.read(path, channel=[0, 1])) as scene:
        frame = scene.render(camera, "mip")
    memory = sc.Scene([sc.Volume(v.data) for v in pair], colors=["blue", "lime"],
                      windows=[(0.1, 0.9), (0.2, 1.5)]).render(camera, "mip")
    np.testing.assert_allclose(frame.rgba, memory.rgba, atol=1e-6)


def test_channel_out_of_range_names_the_file_and_option(store):
    path, _ = store
    with pytest.raises(sc.ParameterError, match=r"cells\.ome\.zarr: channel 3 is out of range "
                                                r"\(it holds 3 channels: 0 to 2\)"):
        sc.read(path, channel=[0, 3])


def test_tiff_channels_are_read_together(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    rng = np.random.default_rng(7)
    stack = rng.integers(0, 60000, (5, 3, 7, 6)).astype(np.uint16)  # Z, C, Y, X
    path = tmp_path / "cells.tif"
    tifffile.imwrite(path, stack, imagej=True, metadata={"axes": "ZCYX"})
    volumes = sc.read(path, channel=[2, 0])
    assert volumes.indices == [2, 0] and volumes.labels == ["channel 2", "channel 0"]
    for volume, c in zip(volumes, (2, 0), strict=True):
        assert np.array_equal(volume.data, stack[:, c].transpose(2, 1, 0))


def test_vti_components_are_read_as_channels(tmp_path):
    pytest.importorskip("vtkmodules")
    from test_timepoints import _multicomponent_vti

    values = np.random.default_rng(8).random((6 * 5 * 4, 3)).astype(np.float32)
    path = tmp_path / "vel.vti"
    _multicomponent_vti(path, values)
    volumes = sc.read(path, channel="all")
    assert len(volumes) == 3 and volumes.spacing == (1.0, 0.5, 2.0)
    for c, volume in enumerate(volumes):
        assert np.array_equal(volume.data, values[:, c].reshape(4, 5, 6).transpose(2, 1, 0))


# --------------------------------------------------------------------------- command line
def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def npy_files(tmp_path_factory, pair) -> tuple[Path, Path, Path]:
    """The pair as two .npy files, and a third on a grid one voxel shorter."""
    folder = tmp_path_factory.mktemp("npy")
    paths = folder / "a.npy", folder / "b.npy", folder / "short.npy"
    sc.write(sc.Volume(pair[0].data), paths[0])
    sc.write(sc.Volume(pair[1].data), paths[1])
    sc.write(sc.Volume(pair[1].data[:, :, :-1].copy()), paths[2])
    return paths


def _assert_additive_composite(png, files, mode, windows, colors=((1, 0, 0), (0, 1, 0))):
    """The command line's PNG of two channels is the sum of each file's own single-channel
    ``mode`` render, windowed and coloured by the test (background where neither is met)."""
    volumes = [sc.read(f) for f in files]
    camera = sc.Camera.orbit(volumes[0], azimuth=30, elevation=20, size=(40, 32))
    values = [sc.Scene(v).render(camera, mode, window=w, outputs=("value",)).value
              for v, w in zip(volumes, windows, strict=True)]
    summed = np.minimum(sum(_ramp(v, w, c) for v, w, c in zip(values, windows, colors,
                                                              strict=True)), 1.0)
    met = np.isfinite(values[0]) | np.isfinite(values[1])
    expected = np.where(met[..., None], summed, np.asarray(BG[:3]))
    got = np.asarray(Image.open(png), np.float64)[..., :3] / 255.0
    np.testing.assert_allclose(got, expected, atol=0.5 / 255 + 1e-6)


def test_cli_mip_of_channel_files_is_the_composite_of_single_renders(npy_files, tmp_path,
                                                                       capsys):
    a, b, _ = npy_files
    png = tmp_path / "mip.png"
    code, out, err = _run(["render", str(a), "--channel-file", str(b), "--mode", "mip",
                           "--size", "40x32", "--fit", "box", "--channel-colors", "red,00FF00",
                           "--channel-window", "0.1:0.9,0.2:1.6", "-o", str(png)], capsys)
    assert code == 0, err
    assert "channel 0 'a.npy': #ff0000, window 0.1..0.9" in err
    _assert_additive_composite(png, [a, b], "mip", [(0.1, 0.9), (0.2, 1.6)])


def test_cli_aip_takes_a_window_per_channel_and_the_shared_window(npy_files, tmp_path, capsys):
    """``--channel-window`` follows the mode (every mode with a window, aip too), and
    ``--window`` is the window of a channel given none of its own."""
    a, b, _ = npy_files
    png = tmp_path / "aip.png"
    code, out, err = _run(["render", str(a), "--channel-file", str(b), "--mode", "aip",
                           "--size", "40x32", "--fit", "box", "--channel-colors", "red,00FF00",
                           "--window", "0.05,0.3", "--channel-window", "auto,0.1:0.9",
                           "-o", str(png)], capsys)
    assert code == 0, err
    assert "channel 1 'b.npy': #00ff00, window 0.1..0.9" in err
    _assert_additive_composite(png, [a, b], "aip", [(0.05, 0.3), (0.1, 0.9)])


@pytest.mark.parametrize("mode", ["iso", "dvr"])
def test_cli_channel_window_is_refused_for_a_mode_without_a_window(mode, npy_files, tmp_path,
                                                                  capsys):
    a, b, _ = npy_files
    png = tmp_path / "bad.png"
    code, _, err = _run(["render", str(a), "--channel-file", str(b), "--mode", mode,
                         "--channel-window", "0:1,0:1", "-o", str(png)], capsys)
    assert code == 2 and err.count("\n") == 1 and not png.exists()
    assert (f"--channel-window does not apply to --mode {mode} (only to --mode "
            f"{'/'.join(sc.render.modes.modes_reading('window'))})") in err, err


def test_cli_iso_takes_one_isovalue_per_channel(npy_files, tmp_path, capsys):
    a, b, _ = npy_files
    png = tmp_path / "iso.png"
    code, _, err = _run(["render", str(a), "--channel-file", str(b), "--size", "40x32",
                         "--fit", "box", "--samples", "1", "--channel-iso", "0.5,1.0",
                         "--channel-colors", "auto,blue", "-o", str(png)], capsys)
    assert code == 0, err
    camera = sc.Camera.orbit(sc.read(a), azimuth=30, elevation=20, size=(40, 32))
    scene = sc.Scene([sc.read(a), sc.read(b)], isos=[0.5, 1.0], colors=[None, "blue"])
    expected = scene.render(camera, "iso", samples=1)
    assert [c["iso"] for c in expected.stats["channels"]] == [0.5, 1.0]
    np.testing.assert_array_equal(np.asarray(Image.open(png)), expected.to_uint8())


def test_cli_ome_zarr_channels_with_their_omero_settings(store, tmp_path, capsys, camera):
    path, _ = store
    png = tmp_path / "cells.png"
    code, _, err = _run(["render", str(path), "--channel", "all", "--mode", "mip",
                         "--size", "40x32", "--fit", "box", "-o", str(png)], capsys)
    assert code == 0, err
    assert "channel 2 'RFP': #ff0000, window 0..1 (hidden: inactive" in err
    assert "2 channels composited (additive)" in err
    code, out, _ = _run(["info", str(path), "--channel", "1"], capsys)
    assert code == 0
    assert "  channel 0: 'DAPI' #0000ff, window 0.1..0.9\n" in out
    assert "  channel 2: 'RFP' #ff0000, window 0..1 (inactive)\n" in out


@pytest.mark.parametrize("args, needle", [
    (["--channel", "0,5"], r"cells\.ome\.zarr: channel 5 is out of range \(it holds 3 "
                           r"channels: 0 to 2\)"),
    (["--channel", "0,1", "--channel-colors", "red"],
     r"--channel-colors: 1 value for 2 channels"),
    (["--channel", "0,1", "--channel-window", "0:1,3:2"], r"--channel-window: 3:2 must be "
                                                          r"LO:HI with LO < HI"),
    (["--channel-colors", "red,blue"], r"--channel-colors needs several channels"),
    (["--channel", "0,1", "--colormap", "hot"], r"--colormap does not apply to several"),
    (["--channel", "0,x"], r"argument --channel: must be an index"),
])
def test_cli_bad_channel_input_is_one_line(store, tmp_path, capsys, args, needle):
    path, _ = store
    png = tmp_path / "bad.png"
    try:
        code, _, err = _run(["render", str(path), "--mode", "mip", "-o", str(png), *args],
                            capsys)
    except SystemExit as exit_info:  # argparse's own errors
        code, err = exit_info.code, capsys.readouterr().err
    assert code == 2
    assert err.startswith("splinecast: error:") and err.count("\n") == 1, err
    assert re.search(needle, err), err
    assert not png.exists()


def test_cli_channel_file_on_another_grid_is_one_line(npy_files, tmp_path, capsys):
    a, _, short = npy_files
    png = tmp_path / "bad.png"
    code, _, err = _run(["render", str(a), "--channel-file", str(short), "--mode", "mip",
                         "-o", str(png)], capsys)
    assert code == 2 and err.count("\n") == 1 and not png.exists()
    assert re.search(r"^splinecast: error: .*short\.npy: --channel-file: shape "
                     r"\(24, 22, 19\) differs from a\.npy's \(24, 22, 20\)", err), err


def test_default_colours_are_napari_s():
    from splinecast.multires.scenes.channels import default_colors

    assert default_colors(1) == [(1.0, 1.0, 1.0)]
    assert default_colors(2) == [(1.0, 0.0, 1.0), (0.0, 1.0, 0.0)]
    assert default_colors(4) == [(0.0, 1.0, 1.0), (1.0, 1.0, 0.0), (1.0, 0.0, 1.0),
                                 (1.0, 0.0, 0.0)]


def test_channel_settings_are_checked_when_changed(pair, camera):
    scene = sc.Scene(pair)
    scene.channels[0].color = "00FFFF"  # bare hex, as omero writes it
    scene.channels[0].window = [0.1, 0.9]
    assert scene.channels[0].color == (0.0, 1.0, 1.0) and scene.channels[0].window == (0.1, 0.9)
    with pytest.raises(sc.ParameterError, match="color 'teal-ish' is not a colour"):
        scene.channels[0].color = "teal-ish"
    with pytest.raises(sc.ParameterError, match="visible must be True or False"):
        scene.channels[1].visible = "no"
    frame = scene.render(camera, "mip")  # the refused values left the settings usable
    assert frame.stats["channels"][0]["window"] == (0.1, 0.9)


def test_malformed_omero_fields_are_left_out():
    from splinecast.io.ngff import omero_channels

    attrs = {"omero": {"channels": [
        {"label": "ok", "color": "00FF00", "window": {"start": 1, "end": 5}, "active": False},
        {"label": 7, "color": "green", "window": {"start": 5, "end": 1}, "active": "yes"},
        "not a dict"]}}
    assert omero_channels(attrs, 3) == [
        {"label": "ok", "color": (0.0, 1.0, 0.0), "window": (1.0, 5.0), "active": False},
        {"label": None, "color": None, "window": None, "active": True},
        {"label": None, "color": None, "window": None, "active": True}]
    assert omero_channels(attrs, 2) is None  # a list for another number of channels
    assert omero_channels({"omero": "x"}, 1) is None
    ome = {"ome": {"omero": {"channels": [{"label": "a\nb" * 50, "color": "#FF0000"}]}}}
    (entry,) = omero_channels(ome, 1)
    assert entry["color"] == (1.0, 0.0, 0.0)
    assert "\n" not in entry["label"] and len(entry["label"]) == 80


def test_nearest_hit_over_against_a_per_pixel_sort():
    """Translucent layers too (antialiased edges): "over" in depth order, checked pixel by
    pixel with Python's sort; ties and misses (inf, NaN) keep the layers' order."""
    from splinecast.render.compose import nearest_hit_over

    rng = np.random.default_rng(11)
    n, h, w = 3, 6, 7
    alpha = rng.choice([0.0, 0.3, 1.0], size=(n, h, w))
    layers = np.concatenate([rng.random((n, h, w, 3)) * alpha[..., None], alpha[..., None]],
                            axis=-1).astype(np.float32)
    depth = rng.choice([1.0, 2.0, 2.0, np.inf, np.nan], size=(n, h, w))
    got, nearest = nearest_hit_over(list(layers), list(depth))
    for r in range(h):
        for c in range(w):
            keys = [d if np.isfinite(d) else np.inf for d in depth[:, r, c]]
            order = sorted(range(n), key=lambda k: keys[k])
            acc = np.zeros(4)
            for k in order:
                acc += (1.0 - acc[3]) * layers[k, r, c].astype(np.float64)
            np.testing.assert_allclose(got[r, c], acc, atol=1e-6)
            assert nearest[r, c] == (order[0] if keys[order[0]] < np.inf else -1)


@pytest.mark.parametrize("command", ["info", "movie"])
def test_commands_reading_one_channel_say_where_several_render(command, npy_files, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, str(npy_files[0]), "--channel", "0,1"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1
    assert ("argument --channel: takes one channel index here, got '0,1' (several channels "
            "render together with 'splinecast render')") in err


def test_a_pyramid_and_an_in_memory_volume_are_channels_of_one_scene(store, camera, pair):
    """Keywords only a multiscale scene takes (complete=) go to its channel alone."""
    path, _ = store
    lazy = sc.read(path, channel=0)
    with sc.Scene([lazy, sc.Volume(pair[1].data)], colors=["red", "lime"],
                  windows=[(0.1, 0.9), (0.2, 1.6)]) as scene:
        frame = scene.render(camera, "mip", complete=True)
    memory = sc.Scene([sc.Volume(v.data) for v in pair], colors=["red", "lime"],
                      windows=[(0.1, 0.9), (0.2, 1.6)]).render(camera, "mip")
    np.testing.assert_allclose(frame.rgba, memory.rgba, atol=1e-6)
