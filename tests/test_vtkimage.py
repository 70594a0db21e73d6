"""VTK image data: .vti and legacy .vtk files, vtkImageData and pyvista.ImageData objects.

The reference is VTK itself: the value and world position VTK gives each point
(``GetScalarComponentAsDouble``, ``GetPoint``) must be the value and position splinecast gives
the same voxel, for files written by VTK's writers in every encoding and by splinecast's.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import ParameterError, ReadError
from splinecast.volume import OrientationWarning

vtk_xml = pytest.importorskip("vtkmodules.vtkIOXML", reason="vtk is not installed "
                              "(pip install 'splinecast[vtk]')")
from vtkmodules.util.numpy_support import numpy_to_vtk  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkImageData  # noqa: E402
from vtkmodules.vtkIOLegacy import vtkStructuredPointsWriter  # noqa: E402

SHAPE = (5, 6, 7)  # unequal: a transposed axis cannot go unnoticed
SPACING = (0.5, 0.75, 2.0)
ORIGIN = (-1.0, 2.0, 3.5)


def ramp(dtype=np.int16) -> np.ndarray:
    i, j, k = np.indices(SHAPE)
    return (i + 10 * j + 100 * k).astype(dtype)


def vtk_image(arrays: dict[str, np.ndarray], extent_start=(0, 0, 0), cells=False) -> vtkImageData:
    """A vtkImageData whose point (or cell) arrays are ``arrays`` given as data[i, j, k]."""
    image = vtkImageData()
    dims = np.asarray(next(iter(arrays.values())).shape) + (1 if cells else 0)
    lo = np.asarray(extent_start)
    hi = lo + dims - 1
    image.SetExtent(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
    image.SetSpacing(*SPACING)
    image.SetOrigin(*ORIGIN)
    target = image.GetCellData() if cells else image.GetPointData()
    for name, data in arrays.items():
        arr = numpy_to_vtk(data.ravel(order="F"), deep=True)  # VTK: x varies fastest
        arr.SetName(name)
        target.AddArray(arr)
    return image


def assert_matches_vtk(vol: sc.Volume, image: vtkImageData) -> None:
    """Every voxel's value and world position agree with VTK's own view of the image: the
    point VTK numbers ``ComputePointId(i, j, k)`` has the voxel's position and value."""
    assert vol.shape == image.GetDimensions()
    values = image.GetPointData().GetArray(vol.metadata["array"])
    x0, _, y0, _, z0, _ = image.GetExtent()
    for i, j, k in np.ndindex(vol.shape):
        pid = image.ComputePointId((x0 + i, y0 + j, z0 + k))
        np.testing.assert_array_equal(vol.index_to_world((i, j, k)), image.GetPoint(pid))
        assert vol.data[i, j, k] == values.GetTuple1(pid)


def write_with_vtk(image: vtkImageData, path: Path, encoding: str) -> None:
    if encoding.startswith("legacy"):
        writer = vtkStructuredPointsWriter()
        writer.SetInputData(image)
        writer.SetFileName(str(path))
        (writer.SetFileTypeToBinary if encoding == "legacy-binary" else writer.SetFileTypeToASCII)()
        assert writer.Write() == 1
        return
    writer = vtk_xml.vtkXMLImageDataWriter()
    writer.SetInputData(image)
    writer.SetFileName(str(path))
    writer.SetCompressorTypeToNone()
    if encoding == "ascii":
        writer.SetDataModeToAscii()
    elif encoding == "base64":  # inline binary: base64 inside each DataArray element
        writer.SetDataModeToBinary()
    elif encoding == "appended-raw":
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOff()
    elif encoding == "appended-base64":
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOn()
    elif encoding == "zlib":
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOff()
        writer.SetCompressorTypeToZLib()
    assert writer.Write() == 1


ENCODINGS = ["ascii", "base64", "appended-raw", "appended-base64", "zlib"]


@pytest.mark.parametrize("encoding", [*ENCODINGS, "legacy-ascii", "legacy-binary"])
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32, np.float64])
def test_files_written_by_vtk(tmp_path, encoding, dtype):
    data = ramp(dtype)
    image = vtk_image({"density": data, "temperature": (data * 0.5).astype(np.float32)})
    path = tmp_path / ("v.vtk" if encoding.startswith("legacy") else "v.vti")
    write_with_vtk(image, path, encoding)
    vol = sc.read(path, array="density")
    assert vol.dtype == np.dtype(dtype)
    np.testing.assert_array_equal(vol.data, data)
    assert vol.spacing == SPACING and vol.origin == ORIGIN
    assert vol.metadata["array"] == "density"
    assert_matches_vtk(vol, image)
    other = sc.read(path, array="temperature")
    np.testing.assert_array_equal(other.data, (data * 0.5).astype(np.float32))


@pytest.mark.parametrize("suffix", [".vti", ".vtk"])
def test_two_arrays_need_array(tmp_path, suffix):
    path = tmp_path / f"two{suffix}"
    write_with_vtk(vtk_image({"density": ramp(), "mask": ramp(np.uint8) % 2}), path,
                   "legacy-binary" if suffix == ".vtk" else "zlib")
    with pytest.raises(ReadError, match=rf"two\{suffix}: several data arrays \('density', "
                                        r"'mask'\); choose one with array=NAME"):
        sc.read(path)
    with pytest.raises(ReadError, match=r"no data array 'nope' \(arrays: 'density', 'mask'\)"):
        sc.read(path, array="nope")


def test_our_writer_round_trips_and_vtk_reads_it(tmp_path):
    for dtype in (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.float32,
                  np.float64):
        vol = sc.Volume(ramp(dtype), spacing=SPACING, origin=ORIGIN)
        path = tmp_path / f"{np.dtype(dtype).name}.vti"
        sc.write(vol, path)
        back = sc.read(path)  # one array: no array= needed
        assert back.dtype == np.dtype(dtype)
        np.testing.assert_array_equal(back.data, vol.data)
        assert back.spacing == SPACING and back.origin == ORIGIN
        assert back.metadata["array"] == "values"
        reader = vtk_xml.vtkXMLImageDataReader()
        reader.SetFileName(str(path))
        reader.Update()
        assert_matches_vtk(back, reader.GetOutput())
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        f"{np.dtype(t).name}.vti" for t in (np.uint8, np.int8, np.uint16, np.int16, np.uint32,
                                            np.int32, np.float32, np.float64))


def test_from_vtk_with_an_extent_that_does_not_start_at_zero():
    image = vtk_image({"v": ramp()}, extent_start=(3, -2, 10))
    vol = sc.Volume.from_vtk(image)
    np.testing.assert_array_equal(vol.data, ramp())
    assert_matches_vtk(vol, image)
    assert not vol.data.flags.owndata  # a view of VTK's memory, no copy


def test_from_vtk_cell_data_puts_voxels_at_cell_centres():
    image = vtk_image({"labels": ramp(np.uint8)}, cells=True)
    vol = sc.Volume.from_vtk(image)
    np.testing.assert_array_equal(vol.data, ramp(np.uint8))
    for i, j, k in [(0, 0, 0), (4, 5, 6), (1, 3, 2)]:
        cid = image.ComputeCellId((i, j, k))
        bounds = np.asarray(image.GetCell(cid).GetBounds()).reshape(3, 2)
        np.testing.assert_allclose(vol.index_to_world((i, j, k)), bounds.mean(axis=1))


def test_from_pyvista_image_data_without_importing_pyvista(tmp_path):
    pv = pytest.importorskip("pyvista")
    grid = pv.ImageData(dimensions=SHAPE, spacing=SPACING, origin=ORIGIN)
    grid["labels"] = ramp(np.int64).ravel(order="F")  # int64: NumPy's and PyVista's default
    vol = sc.Volume.from_vtk(grid)
    assert vol.dtype == np.uint16  # the smallest exact dtype
    np.testing.assert_array_equal(vol.data, ramp())
    for i, j, k in [(0, 0, 0), (4, 5, 6), (2, 1, 3)]:
        pid = i + SHAPE[0] * (j + SHAPE[1] * k)
        np.testing.assert_allclose(vol.index_to_world((i, j, k)), grid.points[pid])
    # A file PyVista saves reads the same.
    grid.save(tmp_path / "pv.vti")
    np.testing.assert_array_equal(sc.read(tmp_path / "pv.vti").data, ramp())
    code = ("import sys, splinecast as sc\n"
            "from vtkmodules.vtkCommonDataModel import vtkImageData\n"
            "from vtkmodules.util.numpy_support import numpy_to_vtk\n"
            "im = vtkImageData(); im.SetDimensions(2, 2, 2)\n"
            "im.GetPointData().SetScalars(numpy_to_vtk(list(range(8))))\n"
            "sc.Volume.from_vtk(im)\n"
            "print('pyvista' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_direction_matrix_is_warned_about(tmp_path):
    image = vtk_image({"v": ramp()})
    image.SetDirectionMatrix(0, -1, 0, 1, 0, 0, 0, 0, 1)  # a 90 degree turn about z
    with pytest.warns(OrientationWarning, match=r"direction matrix .* is not applied"):
        sc.Volume.from_vtk(image)
    path = tmp_path / "turned.vti"
    write_with_vtk(image, path, "zlib")
    with pytest.warns(OrientationWarning, match=r"turned\.vti: the direction matrix"):
        sc.read(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sc.Volume.from_vtk(vtk_image({"v": ramp()}))  # the identity: no warning


def test_bad_vtk_input_is_one_clear_line(tmp_path):
    vectors = vtkImageData()
    vectors.SetDimensions(2, 2, 2)
    arr = numpy_to_vtk(np.zeros((8, 3)))
    arr.SetName("velocity")
    vectors.GetPointData().AddArray(arr)
    with pytest.raises(ParameterError, match=r"'velocity' has 3 components"):
        sc.Volume.from_vtk(vectors)
    with pytest.raises(ParameterError, match="expected a vtkImageData or pyvista.ImageData"):
        sc.Volume.from_vtk(np.zeros((2, 2, 2)))
    empty = vtkImageData()
    empty.SetDimensions(2, 2, 2)
    with pytest.raises(ParameterError, match="no numeric point or cell data"):
        sc.Volume.from_vtk(empty)

    good = tmp_path / "good.vti"
    write_with_vtk(vtk_image({"v": ramp(np.float64)}), good, "appended-raw")
    raw = good.read_bytes()
    (tmp_path / "cut.vti").write_bytes(raw[:-40])  # VTK itself reads this without complaint
    with pytest.raises(ReadError, match=r"cut\.vti: truncated: array 'v' needs"):
        sc.read(tmp_path / "cut.vti")
    (tmp_path / "broken.vti").write_bytes(raw[:300])
    with pytest.raises(ReadError, match=r"broken\.vti: "):
        sc.read(tmp_path / "broken.vti")
    (tmp_path / "grid.vti").write_bytes(raw.replace(b'type="ImageData"', b'type="PolyData"'))
    with pytest.raises(ReadError, match=r"grid\.vti: VTK PolyData data, not ImageData"):
        sc.read(tmp_path / "grid.vti")
    (tmp_path / "poly.vtk").write_text("# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\n")
    with pytest.raises(ReadError, match=r"poly\.vtk: legacy VTK POLYDATA, not STRUCTURED_POINTS"):
        sc.read(tmp_path / "poly.vtk")
    np.save(tmp_path / "x.npy", ramp())
    with pytest.raises(ParameterError, match=r"array='v' applies to VTK files"):
        sc.read(tmp_path / "x.npy", array="v")


def test_cli_reads_vti_with_array(tmp_path, capsys):
    from splinecast.cli import main

    path = tmp_path / "two.vti"
    write_with_vtk(vtk_image({"density": ramp(np.float32), "mask": ramp(np.uint8) % 2}), path,
                   "zlib")
    assert main(["info", str(path), "--array", "density"]) == 0
    assert "5 x 6 x 7" in capsys.readouterr().out
    assert main(["render", str(path), "--size", "16x16", "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "several data arrays ('density', 'mask')" in err and err.count("\n") == 1
    assert main(["render", str(path), "--array", "density", "--size", "16x16", "--quiet",
                 "-o", str(tmp_path / "x.png")]) == 0
