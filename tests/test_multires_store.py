"""OME-Zarr pyramids: the written metadata against the NGFF 0.5 rules, the data read back through
zarr directly against the source and an independent downsampling, foreign stores, the CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

zarr = pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.cli import main  # noqa: E402
from splinecast.io import SeveralVolumesWarning  # noqa: E402
from splinecast.io.omezarr import MultiscaleVolume, open_zarr  # noqa: E402
from splinecast.multires.cut.octree import BrickOctree  # noqa: E402
from splinecast.multires.store.pyramid import build_pyramid  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _volume(shape=(37, 29, 20), dtype=np.uint16, seed=1) -> sc.Volume:
    rng = np.random.default_rng(seed)
    x, y, z = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    smooth = 1000 + 400 * np.sin(x / 5.0) * np.cos(y / 4.0) + 30 * z
    data = (smooth + rng.integers(0, 50, shape)).astype(dtype)
    return sc.Volume(data, spacing=(0.5, 0.5, 1.2), origin=(10.0, -4.0, 2.5),
                     metadata={"units": "mm", "inside": "high"})


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> tuple[sc.Volume, Path]:
    vol = _volume()
    path = tmp_path_factory.mktemp("store") / "vol.zarr"
    build_pyramid(vol, path, brick=8, progress=False)
    return vol, path


def _reference_halve(fine: np.ndarray, halve: tuple[bool, bool, bool]) -> np.ndarray:
    """[1, 2, 1] / 4 at every other voxel, written with np.pad(reflect): the definition in the
    docs, by a second route (pad + slicing instead of the build's mirrored index tables)."""
    out = fine.astype(np.float64)
    for axis in range(3):
        if not halve[axis]:
            continue
        n = out.shape[axis]
        m = n // 2 + 1
        padded = np.pad(out, [(1, 3) if a == axis else (0, 0) for a in range(3)], mode="reflect")
        taps = [np.take(padded, np.arange(s, s + 2 * m, 2), axis=axis) for s in (0, 1, 2)]
        out = 0.25 * taps[0] + 0.5 * taps[1] + 0.25 * taps[2]
    return out


def test_metadata_follows_ngff_05(built):
    vol, path = built
    group = json.loads((path / "zarr.json").read_text())
    assert group["zarr_format"] == 3 and group["node_type"] == "group"
    ome = group["attributes"]["ome"]
    assert ome["version"] == "0.5"
    assert "version" not in ome["multiscales"][0]  # 0.5 moved it up into "ome"
    (ms,) = ome["multiscales"]
    assert [a["name"] for a in ms["axes"]] == ["z", "y", "x"]
    assert all(a["type"] == "space" and a["unit"] == "millimeter" for a in ms["axes"])
    previous_size, previous_scale = None, None
    for n, dataset in enumerate(ms["datasets"]):
        kinds = [t["type"] for t in dataset["coordinateTransformations"]]
        assert kinds == ["scale", "translation"]  # exactly one scale, then one translation
        scale = dataset["coordinateTransformations"][0]["scale"]
        translation = dataset["coordinateTransformations"][1]["translation"]
        assert len(scale) == len(translation) == 3
        array = json.loads((path / dataset["path"] / "zarr.json").read_text())
        assert array["node_type"] == "array" and array["dimension_names"] == ["z", "y", "x"]
        assert array["codecs"][0]["name"] == "sharding_indexed"
        size = np.prod(array["shape"])
        if n:  # finest to coarsest: fewer voxels, larger voxels
            assert size < previous_size
            assert all(a >= b for a, b in zip(scale, previous_scale, strict=True))
        previous_size, previous_scale = size, scale
        # Voxel centres: coarse voxel 0 sits on fine voxel 0 (vertex-centred downsampling).
        assert translation == [2.5, -4.0, 10.0]
    assert ms["datasets"][0]["coordinateTransformations"][0]["scale"] == [1.2, 0.5, 0.5]


def test_level0_reads_back_through_zarr_equal_to_source(built):
    vol, path = built
    level0 = zarr.open_array(str(path / "0"), mode="r")
    assert level0.dtype == vol.dtype
    np.testing.assert_array_equal(np.asarray(level0[...]).transpose(2, 1, 0), vol.data)


def test_coarse_levels_are_the_documented_filter(built):
    vol, path = built
    mv = sc.read(path)
    fine = vol.data
    for level in mv.levels[1:]:
        halve = tuple(level.spacing[a] > mv.levels[level.index - 1].spacing[a] for a in range(3))
        expected = np.rint(_reference_halve(fine, halve)).astype(vol.dtype)
        stored = np.asarray(zarr.open_array(str(path / level.path), mode="r")[...])
        np.testing.assert_array_equal(stored.transpose(2, 1, 0), expected)
        # Coarse voxel c is centred on fine voxel 2c in the world the metadata describes.
        world_fine = np.asarray(mv.levels[level.index - 1].origin)
        world_coarse = np.asarray(level.origin)
        np.testing.assert_allclose(world_coarse, world_fine)
        fine = stored.transpose(2, 1, 0)


@pytest.mark.parametrize("read_bytes", [None, 1])
def test_coarse_levels_across_shards_and_reads(tmp_path, monkeypatch, read_bytes):
    """Many shards per level, level 1 computed from a raw memory-mapped source (x fastest),
    and (read_bytes=1) every fine read split into single slabs: each path gives the documented
    filter of the level above, and level 0 the source."""
    from splinecast.multires.store import pyramid

    if read_bytes is not None:
        monkeypatch.setattr(pyramid, "_READ_BYTES", read_bytes)
    shape = (70, 45, 38)
    data = _volume(shape, np.uint16, seed=3).data
    raw = tmp_path / "v.raw"
    mm = np.memmap(raw, dtype="<u2", mode="w+", shape=shape, order="F")
    mm[...] = data
    mm.flush()
    del mm
    (tmp_path / "v.json").write_text(json.dumps({"shape": list(shape), "dtype": "uint16"}))
    mv = build_pyramid(raw, tmp_path / "v.zarr", brick=8, shard=16, workers=2, progress=False)
    assert len(mv.levels) >= 3
    assert isinstance(sc.read(raw).data, np.memmap)  # the level-1 pass reads the mapping
    fine = data
    np.testing.assert_array_equal(mv.levels[0].read((0, 0, 0), shape), fine)
    for level in mv.levels[1:]:
        halve = tuple(level.spacing[a] > mv.levels[level.index - 1].spacing[a] for a in range(3))
        expected = np.rint(_reference_halve(fine, halve)).astype(np.uint16)
        stored = level.read((0, 0, 0), level.shape)
        np.testing.assert_array_equal(stored, expected)
        fine = stored


def test_minmax_table_bounds_every_brick_window(built):
    vol, path = built
    mv = sc.read(path)
    for level in mv.levels:
        data = level.read((0, 0, 0), level.shape)
        table = mv.table("minmax", level.index)
        for b in np.ndindex(table.shape[:3]):
            lo = np.maximum(np.array(b) * 8 - 2, 0)
            hi = np.minimum((np.array(b) + 1) * 8 + 3, level.shape)
            window = data[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
            assert table[b][0] == window.min() and table[b][1] == window.max()


def test_read_is_lazy_and_gives_the_geometry(built):
    vol, path = built
    # Remove every chunk file of a copy: if read() touched voxels, this would fail or show zeros.
    import shutil

    bare = path.parent / "bare.zarr"
    shutil.copytree(path, bare)
    for level_dir in bare.iterdir():
        if level_dir.name.isdigit():
            shutil.rmtree(level_dir / "c")
    mv = sc.read(bare)
    assert isinstance(mv, MultiscaleVolume)
    assert mv.shape == vol.shape and mv.dtype == vol.dtype
    assert mv.spacing == vol.spacing and mv.origin == vol.origin
    assert mv.value_range == (float(vol.data.min()), float(vol.data.max()))
    assert mv.metadata["units"] == "millimeter" and mv.metadata["inside"] == "high"
    np.testing.assert_allclose(mv.bounds[1], vol.bounds[1])
    cam = sc.Camera.orbit(mv, azimuth=10, size=(64, 48))  # cameras frame it like a Volume
    assert cam.width == 64
    with pytest.raises(sc.ReadError, match="missing"):
        mv.levels[0].read((0, 0, 0), (4, 4, 4))


def _write_level(group, path: str, data_zyx: np.ndarray, **kw) -> None:
    array = group.create_array(path, shape=data_zyx.shape, dtype=data_zyx.dtype,
                               chunks=(16, 16, 16), **kw)
    array[...] = data_zyx


def test_reads_an_ome_zarr_py_style_store(tmp_path):
    """ome-zarr-py 0.18 defaults: NGFF 0.5, paths s0, s1, ..., z not downsampled, level shape
    n // 2, scale = full / level, translation = (scale - 1) / 2, no units."""
    rng = np.random.default_rng(3)
    zyx = rng.integers(0, 255, (12, 40, 33)).astype(np.uint8)
    group = zarr.open_group(str(tmp_path / "omezarrpy.zarr"), mode="w")
    levels = [zyx, zyx[:, ::2, ::2][:, :20, :16]]
    datasets = []
    for n, data in enumerate(levels):
        _write_level(group, f"s{n}", data, dimension_names=("z", "y", "x"))
        scale = [zyx.shape[a] / data.shape[a] for a in range(3)]
        datasets.append({"path": f"s{n}", "coordinateTransformations": [
            {"type": "scale", "scale": scale},
            {"type": "translation", "translation": [s / 2 - 0.5 for s in scale]}]})
    group.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": a, "type": "space"} for a in "zyx"], "datasets": datasets,
        "name": "image"}]}
    mv = sc.read(tmp_path / "omezarrpy.zarr")
    assert [lv.shape for lv in mv.levels] == [(33, 40, 12), (16, 20, 12)]
    assert mv.levels[1].spacing == pytest.approx((33 / 16, 2.0, 1.0))
    assert mv.levels[1].origin == pytest.approx(((33 / 16 - 1) / 2, 0.5, 0.0))
    np.testing.assert_array_equal(mv.levels[1].read((0, 0, 0), (16, 20, 12)),
                                  levels[1].transpose(2, 1, 0))
    octree = BrickOctree(mv, brick=8)
    assert octree.levels == [0, 1]
    assert octree.factors[1].tolist() == [2, 2, 1]
    assert mv.metadata["format"] == "ome-zarr 0.5"


def test_reads_an_ngff_zarr_style_v04_store(tmp_path):
    """ngff-zarr defaults: NGFF 0.4 on Zarr v2, paths scaleN/image, translation (f - 1) / 2."""
    rng = np.random.default_rng(4)
    zyx = rng.random((17, 18, 19)).astype(np.float32)
    group = zarr.open_group(str(tmp_path / "ngffzarr.zarr"), mode="w", zarr_format=2)
    coarse = zyx[::2, ::2, ::2]
    datasets = []
    for n, data in enumerate([zyx, coarse]):
        _write_level(group, f"scale{n}/image", data)
        f = 2**n
        datasets.append({"path": f"scale{n}/image", "coordinateTransformations": [
            {"type": "scale", "scale": [0.3 * f, 0.2 * f, 0.2 * f]},
            {"type": "translation", "translation": [0.3 * (f - 1) / 2 + 1, 0.2 * (f - 1) / 2,
                                                    0.2 * (f - 1) / 2]}]})
    group.attrs["multiscales"] = [{
        "version": "0.4", "name": "image", "datasets": datasets,
        "axes": [{"name": a, "type": "space", "unit": "micrometer"} for a in "zyx"]}]
    mv = sc.read(tmp_path / "ngffzarr.zarr")
    assert mv.metadata["format"] == "ome-zarr 0.4" and mv.metadata["units"] == "micrometer"
    assert mv.shape == (19, 18, 17) and mv.spacing == pytest.approx((0.2, 0.2, 0.3))
    assert mv.origin == pytest.approx((0.0, 0.0, 1.0))
    np.testing.assert_array_equal(mv.levels[0].read((2, 3, 4), (9, 9, 9)),
                                  zyx[4:9, 3:9, 2:9].transpose(2, 1, 0))
    lo, hi = mv.value_range
    assert mv.metadata["value_range_exact"] is False
    assert coarse.min() == lo and coarse.max() == hi


def test_reads_plain_zarr_arrays(tmp_path):
    data = np.arange(4 * 5 * 6, dtype=np.int16).reshape(4, 5, 6)
    named = zarr.create_array(str(tmp_path / "named.zarr"), shape=data.shape, dtype=data.dtype,
                              chunks=(2, 2, 2), dimension_names=("x", "y", "z"))
    named[...] = data
    plain = zarr.create_array(str(tmp_path / "plain.zarr"), shape=data.shape, dtype=data.dtype,
                              chunks=(2, 2, 2))
    plain[...] = data
    np.testing.assert_array_equal(sc.read(tmp_path / "named.zarr").levels[0].read(
        (0, 0, 0), (4, 5, 6)), data)
    unnamed = sc.read(tmp_path / "plain.zarr")  # NGFF order: the last axis is x
    assert unnamed.shape == (6, 5, 4)
    np.testing.assert_array_equal(unnamed.levels[0].read((0, 0, 0), (6, 5, 4)),
                                  data.transpose(2, 1, 0))


def test_channel_and_timepoint_select_their_own_voxels(tmp_path):
    """A store written with zarr alone, axes (t, c, z, y, x), two levels, every (t, c) with its
    own values: ``open_zarr(channel=, timepoint=)`` reads exactly that slice on every level
    (in x, y, z order), and an index past the axis is refused naming it."""
    rng = np.random.default_rng(4)
    shapes = [(2, 3, 6, 5, 4), (2, 3, 3, 3, 2)]
    group = zarr.open_group(str(tmp_path / "tc.zarr"), mode="w")
    stored = []
    for level, shape in enumerate(shapes):
        values = rng.integers(0, 60000, shape).astype(np.uint16)
        group.create_array(str(level), shape=shape, dtype="u2")[...] = values
        stored.append(values)
    group.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}]
        + [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [{"path": str(level), "coordinateTransformations": [
            {"type": "scale", "scale": [1, 1, *(2.0**level,) * 3]}]} for level in (0, 1)]}]}
    seen = set()
    for t in range(2):
        for c in range(3):
            mv = open_zarr(tmp_path / "tc.zarr", channel=c, timepoint=t)
            assert len(mv.levels) == 2
            for level, values in enumerate(stored):
                lv = mv.levels[level]
                got = lv.read((0, 0, 0), lv.shape)
                np.testing.assert_array_equal(got, values[t, c].transpose(2, 1, 0))
            seen.add(mv.levels[0].read((0, 0, 0), mv.shape).tobytes())
    assert len(seen) == 6  # six different volumes
    with pytest.raises(sc.ParameterError, match=r"channel 3 is out of range .*3 channels: 0 to 2"):
        open_zarr(tmp_path / "tc.zarr", channel=3, timepoint=0)
    with pytest.raises(sc.ParameterError, match=r"timepoint 2 is out of range .*0 to 1"):
        open_zarr(tmp_path / "tc.zarr", channel=0, timepoint=2)


def test_bad_stores_and_parameters_name_the_problem(tmp_path, built):
    vol, path = built
    group = zarr.open_group(str(tmp_path / "nometa.zarr"), mode="w")
    group.create_array("a", shape=(2, 2, 2), dtype="u1")
    with pytest.raises(sc.ReadError, match="nometa.zarr.*multiscales"):
        sc.read(tmp_path / "nometa.zarr")
    channels = zarr.open_group(str(tmp_path / "chan.zarr"), mode="w")
    channels.create_array("0", shape=(3, 4, 4, 4), dtype="u1")
    channels.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": "c", "type": "channel"}] + [{"name": a, "type": "space"}
                                                      for a in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [1, 1, 1, 1]}]}]}]}
    with pytest.warns(SeveralVolumesWarning, match="holds 3 channels; reading the first"):
        assert sc.read(tmp_path / "chan.zarr").metadata["channel"] == 0
    assert open_zarr(tmp_path / "chan.zarr", channel=2).shape == (4, 4, 4)
    with pytest.raises(sc.ParameterError, match="already exists"):
        build_pyramid(vol, path, progress=False)
    with pytest.raises(sc.ParameterError, match="brick"):
        build_pyramid(vol, tmp_path / "b.zarr", brick=2, progress=False)
    with pytest.raises(sc.ParameterError, match="unit"):
        build_pyramid(vol, tmp_path / "u.zarr", unit="parsec-ish", progress=False)


class _FailingArray:
    """A source that breaks after a few reads, like a disk error half-way through a build."""

    def __init__(self, data: np.ndarray, fail_after: int) -> None:
        self.data, self.shape, self.dtype, self.left = data, data.shape, data.dtype, fail_after

    def __getitem__(self, index):
        self.left -= 1
        if self.left < 0:
            raise OSError("simulated read error")
        return self.data[index]


def test_failed_build_leaves_nothing_under_the_final_name(tmp_path):
    data = _volume(shape=(40, 40, 40), dtype=np.uint8).data
    with pytest.raises(sc.ReadError, match="array: cannot read voxels.*simulated"):
        build_pyramid(_FailingArray(data, 3), tmp_path / "half.zarr", brick=8, shard=16,
                      workers=1, progress=False)
    assert list(tmp_path.iterdir()) == []  # neither the store nor its temporary


def test_overwrite_replaces_a_store(tmp_path, built):
    vol, path = built
    out = tmp_path / "o.zarr"
    build_pyramid(vol, out, brick=8, progress=False)
    small = sc.Volume(np.ones((5, 5, 5), np.uint8))
    mv = build_pyramid(small, out, brick=8, overwrite=True, progress=False)
    assert mv.shape == (5, 5, 5) and sorted(p.name for p in tmp_path.iterdir()) == ["o.zarr"]


def test_dask_and_zarr_sources(tmp_path):
    import dask.array as da

    data = _volume(shape=(21, 22, 23), dtype=np.float32).data
    mv = build_pyramid(da.from_array(data, chunks=7), tmp_path / "d.zarr", brick=8,
                       progress=False)
    np.testing.assert_array_equal(mv.levels[0].read((0, 0, 0), mv.shape), data)
    source = zarr.create_array(str(tmp_path / "src.zarr"), shape=data.shape[::-1],
                               dtype=data.dtype, chunks=(8, 8, 8))
    source[...] = data.transpose(2, 1, 0)
    mv2 = build_pyramid(source, tmp_path / "z.zarr", brick=8, progress=False)
    np.testing.assert_array_equal(mv2.levels[0].read((0, 0, 0), mv2.shape), data)
    assert mv2.table("minmax", 0).shape == mv.table("minmax", 0).shape


def test_cli_pyramid_and_info(tmp_path, capsys):
    src = tmp_path / "v.npy"
    np.save(src, _volume(shape=(30, 20, 10), dtype=np.uint8).data)
    out = tmp_path / "v.zarr"
    assert main(["pyramid", str(src), "-o", str(out), "--brick", "8", "--quiet"]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "levels:    3" in text and "30x20x10" in text and "16x11x6" in text and "9x6x6" in text
    assert main(["pyramid", str(src), "-o", str(out), "--quiet"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["pyramid", str(src), "-o", str(tmp_path / "x.raw"), "--quiet"]) == 2


def _multiscales(store):
    """The store's NGFF ``multiscales`` entry, read from its ``zarr.json`` as plain JSON."""
    return json.loads((store / "zarr.json").read_text())["attributes"]["ome"]["multiscales"][0]


def test_cli_pyramid_levels_unit_and_overwrite(tmp_path, capsys):
    data = _volume(shape=(30, 20, 10), dtype=np.uint8).data
    src = tmp_path / "v.npy"
    np.save(src, data)
    out = tmp_path / "v.zarr"
    # --levels: at most that many (three without it, test_cli_pyramid_and_info).
    assert main(["pyramid", str(src), "-o", str(out), "--brick", "8", "--levels", "2",
                 "--unit", "mm", "--quiet"]) == 0
    meta = _multiscales(out)
    assert [d["path"] for d in meta["datasets"]] == ["0", "1"]
    assert [a["unit"] for a in meta["axes"]] == ["millimeter"] * 3  # --unit, NGFF's name
    mv = sc.read(out)
    assert [lv.shape for lv in mv.levels] == [(30, 20, 10), (16, 11, 6)]
    np.testing.assert_array_equal(mv.levels[0].read((0, 0, 0), mv.shape), data)
    # --overwrite replaces the store: three levels in micrometres now, nothing of the old one.
    other = data[::-1].copy()
    np.save(src, other)
    capsys.readouterr()
    assert main(["pyramid", str(src), "-o", str(out), "--brick", "8", "--unit", "micrometer",
                 "--overwrite", "--quiet"]) == 0
    meta = _multiscales(out)
    assert [d["path"] for d in meta["datasets"]] == ["0", "1", "2"]
    assert [a["unit"] for a in meta["axes"]] == ["micrometer"] * 3
    mv = sc.read(out)
    np.testing.assert_array_equal(mv.levels[0].read((0, 0, 0), mv.shape), other)
    # Going down to one level leaves no array of the old levels behind.
    assert main(["pyramid", str(src), "-o", str(out), "--brick", "8", "--levels", "1",
                 "--overwrite", "--quiet"]) == 0
    assert [d["path"] for d in _multiscales(out)["datasets"]] == ["0"]
    assert not (out / "1").exists() and not (out / "2").exists()
    capsys.readouterr()
    assert main(["pyramid", str(src), "-o", str(tmp_path / "w.zarr"), "--unit", "parsec",
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "unit 'parsec' is not a length unit" in err and err.count("\n") == 1
    assert not (tmp_path / "w.zarr").exists()


@pytest.mark.skipif(not (DATA / "mni152_t1_1mm.nii.gz").is_file(),
                    reason="../shared/data/mni152_t1_1mm.nii.gz not present (real-data test)")
def test_mni_pyramid_level0_equals_the_nifti(tmp_path):
    vol = sc.read(DATA / "mni152_t1_1mm.nii.gz")
    mv = build_pyramid(DATA / "mni152_t1_1mm.nii.gz", tmp_path / "mni.zarr", unit="mm",
                       progress=False)
    assert mv.spacing == pytest.approx(vol.spacing) and mv.origin == pytest.approx(vol.origin)
    np.testing.assert_array_equal(mv.levels[0].read((0, 0, 0), mv.shape), vol.data)
    assert mv.value_range == vol.value_range
    assert mv.metadata["units"] == "millimeter"


_CAPPED_BUILD = textwrap.dedent("""
    import threading
    threading.stack_size(2**20)  # thread stacks count in RLIMIT_DATA: keep them small
    import resource, sys
    import numpy as np, zarr, dask.array  # imported before the cap: their size is not the build's
    from splinecast.multires.store.pyramid import build_pyramid
    build_pyramid(np.zeros((40, 40, 40), np.uint8), sys.argv[2] + ".warm", shard=64, workers=1,
                  progress=False)  # compiled code and zarr's threads, also before the cap
    cap = int(sys.argv[3])
    for line in open("/proc/self/status"):
        if line.startswith("VmData"):
            base = int(line.split()[1]) * 1024
    resource.setrlimit(resource.RLIMIT_DATA, (base + cap, base + cap))
    build_pyramid(sys.argv[1], sys.argv[2], shard=64, workers=1, progress=False)
    print("built")
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_DATA as on Linux")
def test_build_runs_with_a_memory_cap_well_below_the_volume(tmp_path):
    # 85.8 MiB of uint8, built under a cap of 32 MiB above the interpreter's baseline. The build
    # itself needs 12-16 MiB here (one shard's task, zarr's encoding buffers, thread pools), so a
    # 16 MiB cap on a smaller volume failed now and then on a loaded machine.
    n = 448
    raw = tmp_path / "big.raw"
    out = np.memmap(raw, dtype=np.uint8, mode="w+", shape=(n, n, n), order="F")
    x = np.arange(n)
    for k in range(n):  # written slice by slice, never whole in memory
        out[:, :, k] = (np.sin(x[:, None] / 9.0) * np.cos(x[None, :] / 13.0) * np.sin(k / 7.0)
                        * 120 + 128).astype(np.uint8)
    out.flush()
    del out
    (tmp_path / "big.json").write_text(json.dumps({"shape": [n, n, n], "dtype": "uint8"}))
    cap = 32 * 2**20
    assert cap < n**3 / 2.5
    env = dict(os.environ, MALLOC_ARENA_MAX="2")
    result = subprocess.run(
        [sys.executable, "-c", _CAPPED_BUILD, str(raw), str(tmp_path / "big.zarr"), str(cap)],
        capture_output=True, text=True, timeout=600, env=env)
    assert result.returncode == 0 and "built" in result.stdout, result.stderr[-2000:]
    mv = sc.read(tmp_path / "big.zarr")
    source = np.memmap(raw, dtype=np.uint8, mode="r", shape=(n, n, n), order="F")
    for lo in [(0, 0, 0), (100, 200, 300), (n - 40, n - 40, n - 40)]:
        hi = np.minimum(np.array(lo) + 40, n)
        np.testing.assert_array_equal(mv.levels[0].read(lo, hi),
                                      source[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
    assert len(mv.levels) == 5
