"""Time series and multichannel files: one volume chosen with ``timepoint=`` (``volume=``) and
``channel=`` (CLI ``--timepoint``/``--volume``/``--channel``), and movies over time.

The references are independent of splinecast's readers: the files are written by nibabel,
tifffile, vtk and zarr from arrays the test holds, and each volume read must equal the slice
written; renders of a chosen time point must equal, bit for bit, renders of a 3D file holding the
same slice; every frame of a movie over time must equal the render of its time point.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import main
from splinecast.distributed import orbit_path
from splinecast.io import SeveralVolumesWarning

nib = pytest.importorskip("nibabel")


def _run(argv: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _blobs(n_t: int, shape: tuple[int, int, int] = (20, 18, 16)) -> np.ndarray:
    """``n_t`` float32 volumes (x, y, z, t): a ball whose centre and size change with t, so
    every time point renders differently."""
    x, y, z = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    vols = []
    for t in range(n_t):
        cx, r = -0.3 + 0.2 * t, 0.4 + 0.1 * t
        vols.append(np.exp(-((x - cx) ** 2 + y**2 + (z * 1.2) ** 2) / r**2))
    return np.stack(vols, axis=-1).astype(np.float32)


def _nifti(path: Path, data: np.ndarray, **header: float) -> Path:
    image = nib.Nifti1Image(data, np.eye(4))
    for key, value in header.items():
        image.header[key] = value
    nib.save(image, str(path))
    return path


# --------------------------------------------------------------------------- reading
@pytest.mark.parametrize("name", ["series.nii", "series.nii.gz"])
def test_every_nifti_volume_is_the_slice_written(tmp_path, name):
    rng = np.random.default_rng(1)
    data = rng.integers(-500, 500, (6, 5, 4, 7)).astype(np.int16)
    path = _nifti(tmp_path / name, data)
    for t in range(7):
        vol = sc.read(path, timepoint=t)
        assert vol.dtype == np.int16 and np.array_equal(vol.data, data[..., t])
        assert (vol.metadata["timepoints"], vol.metadata["timepoint"]) == (7, t)
        assert np.array_equal(sc.read(path, volume=t).data, data[..., t])  # the alias
    with pytest.raises(sc.ParameterError, match=r"volume 7 is out of range .*7 time points: "
                                                r"0 to 6"):
        sc.read(path, volume=7)
    with pytest.raises(sc.ParameterError, match="not both"):
        sc.read(path, timepoint=1, volume=1)
    with pytest.raises(sc.ParameterError, match="must be an integer"):
        sc.read(path, timepoint=1.5)


def test_scaled_nifti_volume_equals_the_3d_file_of_its_slice(tmp_path):
    """scl_slope/scl_inter apply to the chosen volume exactly as to a 3D file (float32)."""
    rng = np.random.default_rng(2)
    data = rng.integers(0, 1000, (5, 4, 3, 3)).astype(np.int16)
    for name in ("s.nii", "s.nii.gz"):
        four = _nifti(tmp_path / name, data, scl_slope=0.25, scl_inter=-3.0)
        three = _nifti(tmp_path / f"one-{name}", data[..., 2], scl_slope=0.25, scl_inter=-3.0)
        got = sc.read(four, timepoint=2)
        assert got.dtype == np.float32
        assert np.array_equal(got.data, sc.read(three).data)


def test_nifti_5th_dimension_is_the_channels(tmp_path):
    rng = np.random.default_rng(3)
    data = rng.random((4, 5, 6, 2, 3)).astype(np.float32)  # x, y, z, t, components
    path = _nifti(tmp_path / "vec.nii.gz", data)
    for t in range(2):
        for c in range(3):
            assert np.array_equal(sc.read(path, timepoint=t, channel=c).data, data[..., t, c])
    assert sc.read(path, timepoint=1, channel=2).metadata["channels"] == 3


def test_tiff_hyperstack_time_and_channel(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    rng = np.random.default_rng(4)
    stack = rng.integers(0, 60000, (3, 5, 2, 7, 6)).astype(np.uint16)  # T, Z, C, Y, X
    path = tmp_path / "hyper.tif"
    tifffile.imwrite(path, stack, imagej=True, metadata={"axes": "TZCYX"})
    for t in range(3):
        for c in range(2):
            vol = sc.read(path, timepoint=t, channel=c)
            assert np.array_equal(vol.data, stack[t, :, c].transpose(2, 1, 0))
    with pytest.raises(sc.ParameterError, match=r"hyper\.tif: channel 2 is out of range .*0 to 1"):
        sc.read(path, timepoint=0, channel=2)
    rgb = rng.integers(0, 255, (4, 6, 5, 3)).astype(np.uint8)  # Z, Y, X, S
    tifffile.imwrite(tmp_path / "rgb.tif", rgb, photometric="rgb")
    assert np.array_equal(sc.read(tmp_path / "rgb.tif", channel=2).data,
                          rgb[..., 2].transpose(2, 1, 0))


def _multicomponent_vti(path: Path, values: np.ndarray) -> None:
    """``values`` (n_points, components), x fastest, written by vtk's own writer."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    image = vtkImageData()
    image.SetDimensions(6, 5, 4)
    image.SetSpacing(1.0, 0.5, 2.0)
    array = numpy_to_vtk(values, deep=True)
    array.SetName("velocity")
    image.GetPointData().AddArray(array)
    writer = vtkXMLImageDataWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(image)
    assert writer.Write() == 1


def test_vti_components_are_channels(tmp_path):
    pytest.importorskip("vtkmodules")
    rng = np.random.default_rng(5)
    values = rng.random((6 * 5 * 4, 3)).astype(np.float32)
    path = tmp_path / "vel.vti"
    _multicomponent_vti(path, values)
    for c in range(3):
        vol = sc.read(path, channel=c)
        assert np.array_equal(vol.data, values[:, c].reshape(4, 5, 6).transpose(2, 1, 0))
        assert vol.spacing == (1.0, 0.5, 2.0) and vol.metadata["channels"] == 3
    with pytest.warns(SeveralVolumesWarning, match="holds 3 components; reading the first"):
        assert np.array_equal(sc.read(path).data, sc.read(path, channel=0).data)
    with pytest.raises(sc.ParameterError, match=r"vel\.vti: channel 3 is out of range"):
        sc.read(path, channel=3)


def test_omezarr_time_and_channel_axes(tmp_path):
    zarr = pytest.importorskip("zarr")
    rng = np.random.default_rng(6)
    values = rng.integers(0, 255, (4, 2, 5, 6, 7)).astype(np.uint8)  # t, c, z, y, x
    group = zarr.open_group(str(tmp_path / "tc.zarr"), mode="w")
    group.create_array("0", shape=values.shape, dtype="u1")[...] = values
    group.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}]
        + [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [1, 1, 1, 1, 1]}]}]}]}
    for t in range(4):
        for c in range(2):
            mv = sc.read(tmp_path / "tc.zarr", timepoint=t, channel=c)
            assert np.array_equal(mv.levels[0].read((0, 0, 0), mv.shape),
                                  values[t, c].transpose(2, 1, 0))
            assert (mv.metadata["timepoints"], mv.metadata["channels"]) == (4, 2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mv = sc.read(tmp_path / "tc.zarr")
    assert (mv.metadata["timepoint"], mv.metadata["channel"]) == (0, 0)
    assert sorted(str(w.message).split(": ", 1)[1][:20] for w in caught) == [
        "holds 2 channels; re", "holds 4 time points;"]


def test_single_volume_files_take_index_0_only(tmp_path):
    path = tmp_path / "v.npy"
    np.save(path, np.zeros((3, 3, 3), np.float32))
    assert sc.read(path, timepoint=0, channel=0).shape == (3, 3, 3)
    with pytest.raises(sc.ParameterError, match=r"v\.npy: timepoint 1 is out of range \(it holds "
                                                r"1 time point: 0\)"):
        sc.read(path, timepoint=1)
    with pytest.raises(sc.ParameterError, match="channel 2 is out of range"):
        sc.read("demo:sphere?size=8", channel=2)


# --------------------------------------------------------------------------- command line
def test_info_lists_time_points_and_channels(tmp_path, capsys):
    path = _nifti(tmp_path / "s.nii", _blobs(3))
    code, out, _ = _run(["info", str(path), "--timepoint", "2"], capsys)
    assert code == 0
    assert "timepoints: 3 (this is 2; choose with --timepoint N)" in out
    assert "channels:   1" in out
    code, out, _ = _run(["info", "demo:sphere?size=8"], capsys)
    assert "timepoints: 1\n" in out and "channels:   1\n" in out


def test_no_option_reads_the_first_with_a_note(tmp_path, capsys):
    path = _nifti(tmp_path / "s.nii", _blobs(3))
    code, out, err = _run(["info", str(path)], capsys)
    assert code == 0 and "this is 0" in out
    assert "s.nii: holds 3 time points; reading the first" in err
    assert "--timepoint N" in err


def test_render_of_a_time_point_equals_the_render_of_its_3d_file(tmp_path, capsys):
    """Bit for bit: ``--timepoint 2`` (and ``--volume 2``) of a 4D file and the 3D file holding
    that slice, written by nibabel."""
    from PIL import Image

    data = _blobs(4)
    four = _nifti(tmp_path / "four.nii.gz", data)
    three = _nifti(tmp_path / "three.nii.gz", data[..., 2])
    images = {}
    for name, argv in (("four", [str(four), "--timepoint", "2"]),
                       ("alias", [str(four), "--volume", "2"]),
                       ("three", [str(three)]),
                       ("other", [str(four), "--timepoint", "1"])):
        out = tmp_path / f"{name}.png"
        code, _, err = _run(["render", *argv, "--size", "32x24", "--quiet", "-o", str(out)],
                            capsys)
        assert code == 0, err
        images[name] = np.asarray(Image.open(out))
    assert np.array_equal(images["four"], images["three"])
    assert np.array_equal(images["alias"], images["three"])
    assert not np.array_equal(images["other"], images["three"])


@pytest.mark.parametrize(("argv", "needle"), [
    (["render", "{4d}", "--timepoint", "9"], "timepoint 9 is out of range (it holds 4 time "
                                            "points: 0 to 3)"),
    (["render", "{4d}", "--volume", "-1"], "volume -1 is out of range"),
    (["render", "{4d}", "--channel", "1"], "channel 1 is out of range (it holds 1 channel: 0)"),
    (["info", "{4d}", "--timepoint", "4"], "timepoint 4 is out of range"),
    (["movie", "{4d}", "--frames", "2", "--timepoint", "4"], "timepoint 4 is out of range"),
    (["movie", "{4d}", "--timepoints", "2:9"], "--timepoints 2:9 ends past the end (it holds "
                                              "4 time points; the stop may be at most 4)"),
    (["movie", "{4d}", "--timepoints", "4:"], "--timepoints 4: starts past the end"),
    (["movie", "{4d}", "--timepoints", "3:1"], "--timepoints 3:1 is empty"),
    (["movie", "{4d}", "--timepoints", "0:2:0"], "STEP must be at least 1"),
    (["movie", "{4d}", "--timepoints", "a:b"], "whole numbers"),
    (["movie", "{4d}", "--timepoints", "0:2", "--frames", "3"], "disagree"),
    (["movie", "{4d}", "--timepoints", "0:2", "--timepoint", "1"], "--timepoint does not apply"),
    (["movie", "{4d}"], "--frames N is required"),
])
def test_bad_indices_are_one_line_status_2_and_write_nothing(tmp_path, capsys, argv, needle):
    four = _nifti(tmp_path / "four.nii", _blobs(4))
    out = tmp_path / "out"
    out.mkdir()
    suffix = ".png" if argv[0] == "render" else ".gif"
    argv = [a.replace("{4d}", str(four)) for a in argv]
    if argv[0] != "info":
        argv += ["--size", "32x24", "-o", str(out / f"x{suffix}")]
    code, stdout, err = _run(argv, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    if "out of range" in needle or "past the end" in needle:
        assert str(four) in lines[0]  # the file is named
    assert list(out.iterdir()) == [] and stdout == ""


def test_movie_frames_are_the_renders_of_their_time_points(tmp_path, capsys):
    """``--timepoints 1:4`` to PNG frames, read back with imageio: frame i is time point 1 + i
    rendered with the fixed camera, and the isovalue chosen from time point 1 (not each
    frame's own)."""
    iio = pytest.importorskip("imageio.v3")
    data = _blobs(5)
    data[..., 3] *= 3.0  # time point 3's own automatic isovalue would differ
    four = _nifti(tmp_path / "four.nii", data)
    out = tmp_path / "frames"
    code, _, err = _run(["movie", str(four), "--timepoints", "1:4", "--size", "32x24", "-o",
                         f"{out}/"], capsys)
    assert code == 0, err
    assert "time points 1 to 3 (3 frames); iso, window and colours from time point 1" in err
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:04d}.png" for i in range(3)]
    first = sc.read(four, timepoint=1)
    iso = sc.auto_iso(first)
    cameras = orbit_path(first, 3, azimuth=30.0, elevation=20.0, size=(32, 24))
    for i, t in enumerate((1, 2, 3)):
        want = sc.Scene(sc.read(four, timepoint=t)).render(cameras[i], iso=iso).to_uint8()
        got = iio.imread(out / f"frame_{i:04d}.png")
        assert np.array_equal(got, want), t
    own = sc.read(four, timepoint=3)
    assert sc.auto_iso(own) != iso  # the test would not see a per-frame isovalue otherwise


def test_movie_over_every_other_time_point_as_gif(tmp_path, capsys):
    iio = pytest.importorskip("imageio.v3")
    four = _nifti(tmp_path / "four.nii.gz", _blobs(5))
    out = tmp_path / "time.gif"
    code, _, err = _run(["movie", str(four), "--timepoints", "::2", "--iso", "0.5", "--size",
                         "32x24", "--quiet", "-o", str(out)], capsys)
    assert code == 0, err
    frames = iio.imread(out, index=None)
    assert frames.shape[:3] == (3, 24, 32)  # time points 0, 2, 4
    assert not np.array_equal(frames[0], frames[2])
