"""Spline-wavelet pyramids in a Zarr store: round trip, lazy details, metadata, CLI, mistakes.

References: the source voxels (perfect reconstruction through every level), the in-memory
:func:`decompose` of the same voxels (a second code path that never touches the store) and
bricks of the in-memory reconstructor.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import main
from splinecast.multires.wavelet.lod import select
from splinecast.multires.wavelet.reconstruct import ChunkReconstructor
from splinecast.multires.wavelet.store import WaveletVolume, build_wavelet_pyramid
from splinecast.multires.wavelet.transform import decompose, level0_window, reconstruct

pytest.importorskip("zarr")

SHAPE = (21, 18, 13)


def _data(dtype, shape=SHAPE, seed=3):
    return np.random.default_rng(seed).standard_normal(shape).astype(dtype)


@pytest.mark.parametrize("degree", (1, 2, 3))
@pytest.mark.parametrize("dtype", (np.float32, np.float64))
def test_store_round_trip_equals_in_memory_and_reconstructs_the_source(tmp_path, degree, dtype):
    data = _data(dtype)
    wv = sc.build_pyramid(data, tmp_path / "w.zarr", kind="wavelet", degree=degree,
                          progress=False)
    assert isinstance(wv, WaveletVolume)
    opened = sc.read(tmp_path / "w.zarr")
    assert isinstance(opened, WaveletVolume)
    assert opened.degree == degree and opened.shape == SHAPE and opened.dtype == dtype
    stored = opened.load()
    memory = decompose(data, degree, dtype=dtype)
    for j in memory.coarse:
        np.testing.assert_array_equal(stored.coarse[j], memory.coarse[j])
        for band, array in memory.details[j].items():
            np.testing.assert_array_equal(stored.details[j][band], array)
    for a, b in zip(stored.hull_lo + stored.hull_hi, memory.hull_lo + memory.hull_hi,
                    strict=True):
        np.testing.assert_array_equal(a, b)
    window = level0_window(data, stored.layout)
    error = np.abs(reconstruct(stored) - window).max() / np.abs(window).max()
    assert error < (1e-5 if dtype == np.float32 else 1e-12)
    lo, hi = opened.value_range
    assert lo == float(data.min()) and hi == float(data.max())


def test_blocks_smaller_than_the_level_stream_the_same_store(tmp_path):
    data = _data(np.float64, (27, 22, 19))
    wv = build_wavelet_pyramid(data, tmp_path / "w.zarr", degree=3, chunk=4, block=6)
    stored, memory = wv.load(), decompose(data, 3, chunk=4)
    for j in memory.details:
        for band, array in memory.details[j].items():
            np.testing.assert_array_equal(stored.details[j][band], array)


def test_metadata_names_kind_degree_levels_and_boundary(tmp_path):
    build_wavelet_pyramid(_data(np.float32), tmp_path / "w.zarr", degree=2, levels=2)
    attrs = json.loads((tmp_path / "w.zarr" / "zarr.json").read_text())["attributes"]
    ours = attrs["splinecast"]
    assert ours["kind"] == "wavelet" and ours["degree"] == 2 and ours["levels"] == 2
    assert ours["model"] == "bspline2" and ours["dtype"] == "float32"
    assert set(ours["boundary"]) == {"voxels", "odd degree", "even degree"}


@pytest.mark.parametrize("degree", (1, 3))
def test_lazy_details_give_the_in_memory_bricks_and_read_only_what_is_active(tmp_path, degree):
    data = _data(np.float64, (40, 36, 33))
    wv = build_wavelet_pyramid(data, tmp_path / "w.zarr", degree=degree, chunk=4)
    memory = decompose(data, degree, chunk=4)
    lay = wv.layout
    # Refine only around one corner: far chunks stay coarse and their details unread.
    eye = np.array([-3.0, -3.0, -3.0])
    selection = select(lay, wv.ranges, eye, 0.9)
    assert 0 < sum(a.sum() for a in selection.active) < sum(a.size for a in selection.active)
    lazy = ChunkReconstructor(wv.pyramid, loader=wv.read_detail_block)
    stats = lazy.update(selection)
    ref = ChunkReconstructor(memory)
    ref.update(selection)
    for j, idx, mask in selection.drawn():
        np.testing.assert_array_equal(lazy.brick(j, idx, mask).coeffs,
                                      ref.brick(j, idx, mask).coeffs)
    assert stats.details_read == wv.details_read > 0
    total = sum(int(np.prod(np.ceil(np.asarray(lay.length(j)) / 32))) for j in
                range(1, lay.levels + 1))
    assert wv.details_read <= total
    # The same selection again reads nothing.
    lazy.clear()
    assert lazy.update(selection).details_read == 0


def test_cli_pyramid_wavelet_and_mistakes(tmp_path, capsys):
    src = tmp_path / "v.npy"
    np.save(src, _data(np.float32))
    out = tmp_path / "w.zarr"
    assert main(["pyramid", str(src), "-o", str(out), "--wavelet", "3", "--quiet"]) == 0
    assert isinstance(sc.read(out), WaveletVolume)
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    assert "degree 3 (model bspline3)" in capsys.readouterr().out
    assert main(["pyramid", str(src), "-o", str(tmp_path / "b.zarr"), "--wavelet", "4"]) == 2
    assert "--wavelet" in capsys.readouterr().err
    with pytest.raises(sc.ParameterError, match="kind"):
        sc.build_pyramid(src, tmp_path / "c.zarr", kind="haar")
    with pytest.raises(sc.ParameterError, match="degree"):
        sc.build_pyramid(src, tmp_path / "c.zarr", kind="wavelet", degree=5)
    with pytest.raises(sc.ParameterError, match="dtype"):
        sc.build_pyramid(src, tmp_path / "c.zarr", kind="wavelet", dtype=np.int16)
    with pytest.raises(sc.ParameterError, match="already exists"):
        sc.build_pyramid(src, out, kind="wavelet")
    assert not (tmp_path / "c.zarr").exists()


def test_damaged_store_is_a_read_error(tmp_path):
    build_wavelet_pyramid(_data(np.float32), tmp_path / "w.zarr", degree=1)
    meta = tmp_path / "w.zarr" / "zarr.json"
    attrs = json.loads(meta.read_text())
    attrs["attributes"]["splinecast"]["degree"] = 7
    meta.write_text(json.dumps(attrs))
    with pytest.raises(sc.ReadError, match="w.zarr"):
        sc.read(tmp_path / "w.zarr")


def test_lazy_details_where_a_subband_ends_at_a_block_boundary(tmp_path):
    """65 voxels, degree 3: level 1 has 33 coarse nodes (two 32-node blocks) but 32 detail nodes
    (one): the second block holds coarse-length subbands only."""
    data = _data(np.float32, (65, 12, 10))
    wv = build_wavelet_pyramid(data, tmp_path / "w.zarr", degree=3, chunk=4)
    assert wv.layout.length(1)[0] == 33 and wv.layout.detail_length(1)[0] == 32
    selection = select(wv.layout, wv.ranges, np.zeros(3), 0.0)
    lazy = ChunkReconstructor(wv.pyramid, loader=wv.read_detail_block)
    lazy.update(selection)
    ref = ChunkReconstructor(decompose(data, 3, chunk=4, dtype=np.float32))
    ref.update(selection)
    for j, idx, mask in selection.drawn():
        np.testing.assert_array_equal(lazy.brick(j, idx, mask).coeffs,
                                      ref.brick(j, idx, mask).coeffs)
