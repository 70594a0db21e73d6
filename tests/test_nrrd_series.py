"""4D NRRD files: time series and channels (lists, vectors) as written by pynrrd, read one volume
at a time; the reference is the 4D array the test wrote, sliced by numpy."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import splinecast as sc
from splinecast.io.selection import SeveralVolumesWarning

nrrd = pytest.importorskip("nrrd", reason="NRRD needs the pynrrd package")

SPACING = (2.0, 3.0, 4.0)
ORIGIN = (10.0, -5.0, 1.5)


def _series(extra: int, count: int = 3) -> np.ndarray:
    """Distinct values everywhere: a (6, 5, 4) volume per entry of the extra axis ``extra``."""
    shape = [6, 5, 4]
    shape.insert(extra, count)
    return np.arange(np.prod(shape), dtype=np.float32).reshape(shape)


def _write(path, data: np.ndarray, extra: int, kind: str | None, encoding: str = "raw") -> None:
    directions = [[SPACING[0], 0, 0], [0, SPACING[1], 0], [0, 0, SPACING[2]]]
    directions.insert(extra, [np.nan] * 3)
    header = {"encoding": encoding, "space": "left-posterior-superior",
              "space directions": np.array(directions, dtype=np.float64),
              "space origin": np.array(ORIGIN)}
    if kind is not None:
        kinds = ["domain"] * 3
        kinds.insert(extra, kind)
        header["kinds"] = kinds
    nrrd.write(str(path), data, header, index_order="F")


@pytest.mark.parametrize("encoding", ["raw", "gzip"])
@pytest.mark.parametrize(("extra", "kind", "option"), [
    (3, "time", "timepoint"),     # a time series, time slowest
    (0, "list", "channel"),       # diffusion-weighted style: the list axis fastest
    (3, "vector", "channel"),
    (3, None, "timepoint"),       # no kinds: the axis whose direction is none, taken for time
])
def test_each_volume_of_a_4d_file_is_the_slice_of_the_array(tmp_path, encoding, extra, kind,
                                                             option):
    data = _series(extra)
    path = tmp_path / "series.nrrd"
    _write(path, data, extra, kind, encoding)
    counts = {"timepoint": "timepoints", "channel": "channels"}
    for index in range(data.shape[extra]):
        vol = sc.read(path, **{option: index})
        np.testing.assert_array_equal(vol.data, np.take(data, index, axis=extra))
        assert vol.spacing == SPACING and vol.origin == ORIGIN
        assert vol.metadata[counts[option]] == data.shape[extra]
        assert vol.metadata[option] == index
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = sc.read(path)
    assert any(issubclass(w.category, SeveralVolumesWarning) for w in caught)
    np.testing.assert_array_equal(first.data, np.take(data, 0, axis=extra))


def test_out_of_range_and_the_wrong_axis_name_the_file_and_option(tmp_path):
    path = tmp_path / "t.nrrd"
    _write(path, _series(3), 3, "time")
    with pytest.raises(sc.ParameterError, match=r"t\.nrrd.*timepoint"):
        sc.read(path, timepoint=3)
    with pytest.raises(sc.ParameterError, match=r"t\.nrrd.*channel"):
        sc.read(path, channel=1)  # the file has time points, not channels


def test_a_4d_file_without_a_non_spatial_axis_is_refused(tmp_path):
    path = tmp_path / "four.nrrd"
    data = _series(3)
    nrrd.write(str(path), data, {"kinds": ["domain"] * 4}, index_order="F")
    with pytest.raises(sc.ReadError, match=r"four\.nrrd: a 4D NRRD needs exactly one axis"):
        sc.read(path)


def test_the_command_line_renders_the_chosen_time_point(tmp_path):
    """`render --timepoint 2` of the series equals `render` of that volume as its own file."""
    from PIL import Image

    from splinecast.cli import main

    x, y, z = np.meshgrid(*(np.linspace(-1, 1, 20),) * 3, indexing="ij")
    radii = np.array([0.4, 0.55, 0.7], dtype=np.float32)
    data = np.stack([np.sqrt(x**2 + y**2 + z**2) - r for r in radii], axis=3).astype(np.float32)
    series, single = tmp_path / "balls.nrrd", tmp_path / "ball2.nrrd"
    _write(series, data, 3, "time")
    nrrd.write(str(single), np.ascontiguousarray(data[..., 2]), {
        "space": "left-posterior-superior", "space directions": np.diag(SPACING),
        "space origin": np.array(ORIGIN), "kinds": ["domain"] * 3}, index_order="F")
    common = ["--iso", "0", "--size", "32x32", "--quiet"]
    assert main(["render", str(series), "--timepoint", "2", "-o", str(tmp_path / "a.png"),
                 *common]) == 0
    assert main(["render", str(single), "-o", str(tmp_path / "b.png"), *common]) == 0
    a, b = (np.asarray(Image.open(tmp_path / n)) for n in ("a.png", "b.png"))
    np.testing.assert_array_equal(a, b)
    assert main(["render", str(series), "--timepoint", "3", "-o", str(tmp_path / "c.png"),
                 *common]) == 2
    assert not (tmp_path / "c.png").exists()
