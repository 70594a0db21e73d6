"""Brick histograms stored with the pyramid (issue 11, item 1: the ``hist2d`` group).

References, independent of the code under test:

- per brick, the source voxels it owns, their approximation by the brick's level with scipy's
  ``map_coordinates`` (order 1, edge-clamped) at level index ``i / f``, both quantized and
  counted with ``numpy.histogram2d``;
- D(b) summed voxel by voxel (:func:`cut_reference.voxel_distortion`);
- the files the process opens (an audit hook), for "a transfer-function edit reads no voxel";
- the histograms the error cut builds itself from the levels (the path of stores without the
  group), for the fallback.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from cut_reference import voxel_distortion
from reference import smooth_noise
from scipy import ndimage

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.errors import ParameterError  # noqa: E402
from splinecast.multires.cut.colour import classified_luv, distortion_table  # noqa: E402
from splinecast.multires.cut.metric import histogram_distortion  # noqa: E402
from splinecast.multires.cut.octree import BrickOctree  # noqa: E402
from splinecast.multires.cut.policy import ErrorCut, octree_tree  # noqa: E402
from splinecast.multires.store.hist_store import HIST2D, histogram_info  # noqa: E402

B = 8
TF = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)], domain=(-3.0, 3.0))
TF2 = sc.TransferFunction([(-1.5, 0.2), (0.0, 0.0), (1.0, 0.9)], domain=(-3.0, 3.0))

_OPENED: list[str] = []
_RECORD = [False]


def _hook(event: str, args: tuple) -> None:
    if _RECORD[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
        _OPENED.append(os.fsdecode(args[0]))


sys.addaudithook(_hook)


@pytest.fixture(scope="module")
def stored(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise (float64, odd sizes), 8^3 bricks in 16^3 shards: level-2 bricks own 32^3
    source voxels, more than one tile, so their histograms are sums over tiles."""
    vol = sc.Volume(smooth_noise((37, 29, 23), seed=7, sigma=2.0))
    path = tmp_path_factory.mktemp("hist") / "noise.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False, histograms=True)
    return vol, path


def _reference_histogram(source, level_data, f, lo, hi, q):
    """Dense (bins, bins) counts of (source bin, approximation bin) over voxels [lo, hi)."""
    grids = np.meshgrid(*[np.arange(a, b, dtype=np.float64) for a, b in zip(lo, hi, strict=True)],
                        indexing="ij")
    coords = [np.clip(g / fa, 0, n - 1)
              for g, fa, n in zip(grids, f, level_data.shape, strict=True)]
    approx = ndimage.map_coordinates(level_data.astype(np.float64), coords, order=1,
                                     mode="nearest")
    src = source[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    edges = np.arange(q.bins + 1) - 0.5
    dense, _, _ = np.histogram2d(q.bin_of(src).ravel(), q.bin_of(approx).ravel(),
                                 bins=(edges, edges))
    return dense


def _footprint(mv, level, index):
    """Per-axis factor of ``level`` (from the NGFF scales: axes stop halving once they fit one
    brick) and the level-0 voxels ``[lo, hi)`` brick ``index`` owns."""
    f = np.rint(np.asarray(mv.level(level).spacing) / np.asarray(mv.level(0).spacing))
    f = f.astype(np.int64)
    n0 = np.asarray(mv.shape)
    edge = B * f
    last = -(-(n0 - 1) // edge) - 1
    lo = index * edge
    hi = np.where(index == last, n0, (index + 1) * edge)
    return f, lo, hi


def test_stored_histograms_equal_histograms_counted_from_the_voxels(stored):
    vol, path = stored
    mv = sc.read(path)
    assert HIST2D in mv.attributes
    cut = ErrorCut(BrickOctree(mv))
    assert cut.histogram_source == "store"
    q = cut.quantizer
    levels = [mv.level(i).read((0, 0, 0), mv.level(i).shape) for i in range(len(mv.levels))]
    assert len(levels) >= 3
    for node in range(cut.tree.size):
        level, index = int(cut.keys[node, 0]), cut.keys[node, 1:]
        src_bins, approx_bins, counts = cut.histograms.node(node)
        if level == 0:
            assert counts.size == 0
            continue
        f, lo, hi = _footprint(mv, level, index)
        assert cut.tree.voxels[node] == np.prod(hi - lo)
        got = np.zeros((q.bins, q.bins))
        got[src_bins, approx_bins] = counts
        np.testing.assert_array_equal(got, _reference_histogram(vol.data, levels[level], f, lo,
                                                                hi, q), err_msg=str(cut.keys[node]))


def test_d_from_stored_histograms_equals_d_from_the_voxels(stored):
    vol, path = stored
    mv = sc.read(path)
    cut = ErrorCut(BrickOctree(mv))
    q = cut.quantizer
    got = histogram_distortion(cut.histograms, distortion_table(TF2, q.values))
    luv = classified_luv(TF2, q.values)
    levels = [mv.level(i).read((0, 0, 0), mv.level(i).shape) for i in range(len(mv.levels))]
    for node in range(cut.tree.size):
        level, index = int(cut.keys[node, 0]), cut.keys[node, 1:]
        if level == 0:
            continue
        f, lo, hi = _footprint(mv, level, index)
        ref = voxel_distortion(vol.data, levels[level], level, lo, hi, q.bin_of, luv,
                               index_map=(1.0 / f, 0.0))
        assert got[node] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_stored_histograms_are_those_the_error_cut_builds_without_them(stored):
    _, path = stored
    octree = BrickOctree(sc.read(path))
    a = ErrorCut(octree).histograms
    b = ErrorCut(octree, stored=False).histograms
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_array_equal(a.keys, b.keys)
    np.testing.assert_array_equal(a.counts, b.counts)


def test_uint8_store_with_several_coarsest_bricks(tmp_path):
    """8-bit data (bins over 0..255) and ``levels=2`` (a virtual root above several bricks):
    the stored histograms are those built from the levels."""
    from cut_reference import smooth_volume

    vol = sc.Volume(smooth_volume((30, 20, 18), seed=5))
    path = tmp_path / "u8.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, levels=2, progress=False, histograms=True)
    octree = BrickOctree(sc.read(path))
    a = ErrorCut(octree)
    b = ErrorCut(octree, stored=False)
    assert a.histogram_source == "store" and a.virtual >= 0
    assert a.quantizer == b.quantizer and (a.quantizer.lo, a.quantizer.hi) == (0.0, 255.0)
    np.testing.assert_array_equal(a.histograms.offsets, b.histograms.offsets)
    np.testing.assert_array_equal(a.histograms.keys, b.histograms.keys)
    np.testing.assert_array_equal(a.histograms.counts, b.histograms.counts)
    # Every source voxel is counted once per level above the source.
    h = a.histograms
    level1 = np.flatnonzero(a.tree.level == 1)
    assert level1.size > 1 and np.all(np.diff(level1) == 1)
    assert int(h.counts[h.offsets[level1[0]]:h.offsets[level1[-1] + 1]].sum()) == vol.data.size


def _level_chunks(path: Path) -> list[str]:
    """Chunk files opened inside the store's level arrays (``<store>/<digit>/c/...``; the
    arrays' ``zarr.json`` metadata is not voxels)."""
    root = str(path.resolve())
    out = []
    for name in _OPENED:
        name = str(Path(name).resolve())
        if name.startswith(root + os.sep):
            parts = name[len(root) + 1:].split(os.sep)
            if parts[0].isdigit() and "c" in parts[1:]:
                out.append(name)
    return out


def test_opening_and_a_transfer_function_edit_read_no_voxel(stored):
    vol, path = stored
    cam = sc.Camera((60.0, -30.0, 40.0), (18.0, 14.0, 11.0), size=(8, 8))
    _OPENED.clear()
    _RECORD[0] = True
    try:
        mv = sc.read(path)
        octree = BrickOctree(mv)
        cut = ErrorCut(octree)
        first = cut.update(cam, TF, None, budget=20)
        every = np.arange(cut.tree.size)
        d_before = cut.metric.raw_distortion(every)
        opened_before = len(_OPENED)
        cut.update(cam, TF2, None, budget=20)  # the edit: the hull's D for the new TF
        d_after = cut.metric.raw_distortion(every)  # and every other node's
    finally:
        _RECORD[0] = False
    assert opened_before > 0  # the hook sees the store's files (metadata, tables, hist2d)
    assert _level_chunks(path) == []
    # The hook does see chunk reads: building the histograms from the levels reads them.
    _OPENED.clear()
    _RECORD[0] = True
    try:
        ErrorCut(BrickOctree(sc.read(path)), stored=False)
    finally:
        _RECORD[0] = False
    assert len(_level_chunks(path)) > 0
    assert first.cut.size > 0 and not np.allclose(d_before, d_after)
    # D after the edit is the new transfer function's: a plain sum over the histogram entries.
    table = distortion_table(TF2, cut.quantizer.values).ravel()
    h = cut.histograms
    ref = np.array([float((h.counts[h.offsets[n]:h.offsets[n + 1]].astype(np.float64)
                           * table[h.keys[h.offsets[n]:h.offsets[n + 1]].astype(np.int64)]).sum())
                    for n in every])
    np.testing.assert_allclose(d_after, ref, rtol=1e-12, atol=1e-12)


def test_a_store_without_histograms_warns_once_and_builds_them(stored, tmp_path):
    vol, _ = stored
    path = tmp_path / "plain.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False)
    mv = sc.read(path)
    assert HIST2D not in mv.attributes and histogram_info(mv) is None
    with pytest.warns(UserWarning, match="no stored brick histograms") as record:
        cut = ErrorCut(BrickOctree(mv))
    assert len([w for w in record if "histograms" in str(w.message)]) == 1
    assert cut.histogram_source == "built"


@pytest.mark.parametrize("damage", ["chunk", "metadata", "offsets"])
def test_damaged_histograms_fall_back_with_one_line(stored, tmp_path, damage):
    vol, src = stored
    path = tmp_path / "damaged.zarr"
    shutil.copytree(src, path)
    group = path / "splinecast" / HIST2D / "1"
    if damage == "chunk":
        chunk = next(p for p in (group / "keys").rglob("*") if p.is_file() and "c" in p.parts)
        chunk.write_bytes(b"\x00garbage")
    elif damage == "metadata":
        import json

        meta = path / "zarr.json"
        doc = json.loads(meta.read_text())
        doc["attributes"]["splinecast"][HIST2D]["bins"] = "many"
        meta.write_text(json.dumps(doc))
    else:
        import zarr

        root = zarr.open_group(str(path), mode="r+")
        arr = root[f"splinecast/{HIST2D}/1/offsets"]
        values = arr[...]
        values[1] = values[-1] + 5
        arr[...] = values
    mv = sc.read(path)
    with pytest.warns(UserWarning) as record:
        cut = ErrorCut(BrickOctree(mv))
    messages = [str(w.message) for w in record]
    assert any(HIST2D in m and "\n" not in m for m in messages), messages
    assert cut.histogram_source == "built"
    reference = ErrorCut(BrickOctree(sc.read(src)))
    np.testing.assert_array_equal(cut.histograms.counts, reference.histograms.counts)


def test_info_reports_histogram_size_and_overhead(stored, capsys):
    from splinecast.cli import main

    _, path = stored
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("histograms:"))
    info = histogram_info(sc.read(path))
    mv = sc.read(path)
    assert info["nbytes"] > 0 and info["disk_bytes"] > 0
    assert info["source_nbytes"] == int(np.prod(mv.shape)) * mv.dtype.itemsize
    assert f"{100 * info['nbytes'] / info['source_nbytes']:.1f}%" in line


def test_bad_bins_are_refused_with_one_line(stored, tmp_path):
    vol, _ = stored
    with pytest.raises(ParameterError, match="bins"):
        sc.build_pyramid(vol, tmp_path / "x.zarr", brick=B, histograms=True, bins=1,
                         progress=False)
    assert not (tmp_path / "x.zarr").exists()


def test_cli_pyramid_writes_histograms(tmp_path, stored):
    from splinecast.cli import main

    vol, _ = stored
    npy = tmp_path / "v.npy"
    np.save(npy, vol.data.astype(np.float32))
    out = tmp_path / "v.zarr"
    assert main(["pyramid", str(npy), "-o", str(out), "--brick", "8", "--histograms",
                 "--quiet"]) == 0
    mv = sc.read(out)
    assert mv.attributes[HIST2D]["brick"] == 8
    tree, _, _ = octree_tree(BrickOctree(mv))
    assert ErrorCut(BrickOctree(mv)).histograms.offsets.size == tree.size + 1
