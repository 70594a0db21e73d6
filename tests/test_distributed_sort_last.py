"""Sort-last rendering on a Dask LocalCluster (2 worker processes, 1 thread each).

References, independent of the code under test:

- the in-memory ``Scene.render`` of the rendered level (``sc.read(store).level(k).to_volume()``,
  one grid, no bricks, no compositing): equal to rounding, not bit for bit (a ray restricted to
  a brick parametrizes a cell's polynomial from another point): depths and MIP values to 1e-12
  (measured at most 5.6e-13 and 2.7e-15 over these cases), colours to 1e-6 (float32; measured
  equal except multi-iso's, see below);
- the single-process multiresolution render of the same bricks (``MultiscaleScene`` with a
  level-0 cut: the state carried through the bricks front to back in one process): iso and MIP
  identical bit for bit, DVR within 1e-12;
- the chunk files each worker process opened (an audit hook installed in the workers), against
  the brick boxes the chunks cover;
- the scheduler's task stream: which tasks ran, and that only the last one's result is fetched.

One cluster serves the whole module.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from dask_faults import hold_worker

import splinecast as sc
from splinecast.distributed import DistributedScene, SceneSource, SortLastScene, VolumeInfo
from splinecast.distributed.sort_last import (
    Share,
    combine_partials,
    finish_partial,
    render_share,
    split_bricks,
)
from splinecast.errors import ParameterError

distributed = pytest.importorskip("distributed", reason="needs the distributed extra (Dask)")
pytest.importorskip("zarr", reason="needs the multires extra (zarr)")

B = 8  # cells per brick and chunk (one chunk per shard file: a file name names a chunk)
TF = sc.TransferFunction([(0.3, 0.0), (0.5, 0.6), (0.8, 0.9)], domain=(0.0, 1.0))
MODE_OPTIONS = {
    "iso": {"iso": 0.5},
    "multi-iso": {"iso": [0.3, 0.6], "opacity": [0.4, 0.8]},
    "mip": {"mode": "mip", "window": (0.0, 1.0)},
    "dvr": {"mode": "dvr", "tf": TF, "dvr": sc.DVRSettings(step=0.5)},
}
CASES = [(model, mode) for model in ("trilinear", "s31") for mode in MODE_OPTIONS]


def _camera(vol, azimuth: float = 35, elevation: float = 25, **kw) -> sc.Camera:
    return sc.Camera.orbit(vol, azimuth=azimuth, elevation=elevation, size=(48, 40), **kw)


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    """Marschner-Lobb 33^3 (float32) as a pyramid of 8^3 bricks: levels 33^3 (4x4x4 bricks),
    17^3 (2x2x2), 9^3 (1 brick)."""
    path = tmp_path_factory.mktemp("sortlast") / "ml.zarr"
    sc.build_pyramid(sc.demo("marschner-lobb", size=33), path, brick=B, shard=B, progress=False)
    return path


@pytest.fixture(scope="module")
def levels(store) -> dict[int, sc.Volume]:
    volume = sc.read(store)
    return {k: volume.level(k).to_volume() for k in (0, 1)}


def _count_chunk_reads() -> None:
    """Installed in each worker: record every chunk file the process opens.

    An audit hook sees each ``open`` whatever store class zarr reads through (splinecast's own
    guarded store, or zarr's ``LocalStore``), so the count does not depend on the reading code.
    """
    import builtins
    import os
    import sys

    if getattr(builtins, "_sortlast_opened", None) is not None:
        return
    opened: list[str] = []

    def hook(event: str, args: tuple) -> None:
        if event == "open" and isinstance(args[0], str | bytes | os.PathLike):
            name = os.fsdecode(args[0])
            if "/c/" in name:
                opened.append(name)

    sys.addaudithook(hook)
    builtins._sortlast_opened = opened


def _chunk_keys() -> list[str]:
    import builtins

    return list(builtins._sortlast_opened)


def _warm_up(store: Path, volume: sc.Volume) -> None:
    """Compile every kernel the workers use, in this process, before the cluster starts: the
    workers then load them from Numba's on-disk cache instead of compiling them two at a time.
    The sort-last tasks run here as plain functions (no Dask) on the two halves of level 0."""
    header = VolumeInfo.of(volume)
    cam = sc.Camera.orbit(volume, size=(8, 8))
    tree = split_bricks((4, 4, 4), 2)
    for model, mode in CASES:
        sc.Scene(volume, model=model).render(cam, **MODE_OPTIONS[mode])
        source = SceneSource(store, model)
        token = f"warm-up {model} {mode}"
        low, high = (render_share(Share(source, 0, B, leaf.part, leaf.lo, leaf.hi), cam,
                                  MODE_OPTIONS[mode], header, token) for leaf in tree.leaves())
        both = combine_partials(low, high, cam, MODE_OPTIONS[mode], header, token)
        finish_partial(both, cam, MODE_OPTIONS[mode], header, token)


@pytest.fixture(scope="module")
def client(store, levels):
    _warm_up(store, levels[0])
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=40)
    with cluster, distributed.Client(cluster) as client:
        client.run(_count_chunk_reads)
        yield client


@pytest.fixture(scope="module")
def scenes(client, store):
    """Sort-last scenes per (model, level), made once (the workers keep their bricks)."""
    return {(model, level): DistributedScene(store, client, model=model, strategy="sort-last",
                                             level=level)
            for model in ("trilinear", "s31") for level in (0, 1)}


def _assert_close_to_whole(mode: str, got: sc.Frame, want: sc.Frame) -> None:
    if mode == "mip":
        np.testing.assert_allclose(got.value, want.value, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=1e-6)
        return
    if mode == "dvr":
        np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=1e-6)
        # The depth where the opacity reaches 1/2: a sample position of the whole ray, also
        # where that happens behind the first share (found by the shares' second trace).
        half = np.isfinite(want.depth)
        assert 50 < half.sum() < half.size
        np.testing.assert_array_equal(np.isfinite(got.depth), half)
        np.testing.assert_allclose(got.depth[half], want.depth[half], rtol=0, atol=1e-12)
        return
    hit = np.isfinite(want.depth)
    assert 50 < hit.sum() < hit.size  # hits and misses
    np.testing.assert_array_equal(np.isfinite(got.depth), hit)
    np.testing.assert_allclose(got.depth[hit], want.depth[hit], rtol=0, atol=1e-12)
    # Multi-iso: a ray stops compositing at opacity 1 - 1e-4 (render/multi_iso.OPAQUE), which a
    # back share cannot know; what it adds after that point is below 1e-4 in every channel.
    atol = 1e-4 if mode == "multi-iso" else 1e-6
    np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=atol)


@pytest.mark.parametrize(("model", "mode"), CASES)
def test_sort_last_equals_the_in_memory_render_of_the_level(scenes, levels, model, mode):
    refined = 0
    for level in (0, 1):
        scene = scenes[model, level]
        assert isinstance(scene, SortLastScene)
        assert scene.volume.shape == levels[level].shape
        for cam in (_camera(levels[level]), _camera(levels[level], azimuth=215, elevation=-40)):
            # Sort-last images are not antialiased; the in-memory render is by default.
            want = sc.Scene(levels[level], model=model).render(cam, samples=1,
                                                               **MODE_OPTIONS[mode])
            got = scenes[model, level].render(cam, **MODE_OPTIONS[mode])
            _assert_close_to_whole(mode, got, want)
            assert got.stats["shares"] == 2 and got.stats["composite_levels"] == 1
            refined += got.stats.get("depth_refined_pixels", 0)
    if mode == "dvr":  # some depths lay behind the front share: the second trace was needed
        assert refined > 0


def test_a_mip_tolerance_holds_across_the_shares(scenes, levels):
    """``tolerance=`` reaches the workers: each pixel of the composited MIP lies within it below
    the in-memory exact projection of the level, never above it."""
    tolerance = 0.05
    largest = 0.0
    for cam in (_camera(levels[0]), _camera(levels[0], azimuth=215, elevation=-40)):
        want = sc.Scene(levels[0]).render(cam, **MODE_OPTIONS["mip"])
        got = scenes["trilinear", 0].render(cam, **MODE_OPTIONS["mip"], tolerance=tolerance)
        hit = np.isfinite(want.value)
        np.testing.assert_array_equal(np.isfinite(got.value), hit)
        short = (want.value - got.value)[hit]  # the window is (0, 1)
        assert short.min() >= -1e-9 and short.max() <= tolerance * (1 + 1e-9)
        largest = max(largest, float(short.max()))
    assert largest > 0.0  # the tolerance was used


@pytest.mark.parametrize(("model", "mode"), CASES)
def test_sort_last_equals_the_single_process_brick_render(scenes, store, levels, model, mode):
    """Level 0 bricks traced front to back in one process: the same image, bit for bit for
    the modes whose merge picks one state (iso, MIP)."""
    cams = [_camera(levels[0]), _camera(levels[0], azimuth=120, elevation=60),
            sc.Camera.orbit(levels[0], azimuth=90, elevation=0, ortho=True, size=(48, 40))]
    # The single-process render from bricks (not level 0 held whole): the same bricks, merged
    # in one process instead of on the workers.
    with sc.Scene(sc.read(store), model=model, budget="64MiB", lod=1e-6,
                  whole_level=False) as local:
        for cam in cams:
            want = local.render(cam, complete=True, **MODE_OPTIONS[mode])
            assert want.stats["complete"]
            assert want.stats["cut_levels"] == {0: want.stats["cut_bricks"]}
            got = scenes[model, 0].render(cam, **MODE_OPTIONS[mode])
            if mode == "dvr":
                np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=1e-12)
                continue
            if mode == "multi-iso":  # "over" regroups the sums; the stop at 1 - 1e-4 acts per share
                np.testing.assert_array_equal(got.depth, want.depth)
                np.testing.assert_array_equal(got.normal, want.normal)
                np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=1e-4)
                continue
            np.testing.assert_array_equal(got.rgba, want.rgba)
            np.testing.assert_array_equal(got.depth, want.depth)
            if mode == "mip":
                np.testing.assert_array_equal(got.value, want.value)
            else:
                np.testing.assert_array_equal(got.normal, want.normal)


def test_each_worker_reads_only_its_own_chunks(client, store):
    """A fresh scene of level 0 (33^3 voxels in 5x5x5 chunks of 8^3; bricks of 16 cells, so
    that no worker has read them yet): each worker asks its store for the chunk files of its
    own bricks' voxels and of the chunks their ghost voxels (2 on each side, the widest model
    support) reach into, and for no chunk of another level."""
    before = {w: len(keys) for w, keys in client.run(_chunk_keys).items()}
    scene = DistributedScene(store, client, model="trilinear", strategy="sort-last", level=0,
                             brick=16, parts=2)
    roots = {str(Path(store)) + "/", str(Path(store).resolve()) + "/"}
    read = {w: {k[len(r):] for k in keys[before[w]:] for r in roots if k.startswith(r)}
            for w, keys in client.run(_chunk_keys).items()}
    assert set(read) == set(scene.workers)
    n, chunk, ghost, everything = 33, B, 2, 5 ** 3

    def chunks_of(first: np.ndarray, last: np.ndarray) -> set[tuple[int, ...]]:
        """Chunks holding voxels first..last (inclusive, clipped to the level)."""
        a = np.clip(first, 0, n - 1) // chunk
        b = np.clip(last, 0, n - 1) // chunk
        return {tuple(int(v) for v in a + d) for d in np.ndindex(*(b - a + 1))}

    for part, address in enumerate(scene.workers):
        chunks = set()
        for key in read[address]:
            level, _, z, y, x = key.split("/")
            assert level == "0", key  # only the rendered level's chunks
            chunks.add((int(x), int(y), int(z)))
        share = scene.shares[part]
        cells_lo, cells_hi = np.asarray(share.lo) * 16, np.asarray(share.hi) * 16
        own = chunks_of(cells_lo, cells_hi)
        shell = chunks_of(cells_lo - ghost, cells_hi + ghost)
        assert own <= chunks <= shell, (part, sorted(chunks))
        assert len(chunks) < everything
    assert scene.shares[0].n_bricks + scene.shares[1].n_bricks == 8
    scene.close()


def test_partial_images_are_composited_on_the_workers(client, scenes, levels):
    cam = _camera(levels[0])
    with distributed.get_task_stream(client) as stream:
        frame = scenes["trilinear", 0].render(cam, iso=0.5)
    names = sorted(t["key"].split("-")[0] if isinstance(t["key"], str) else t["key"][0]
                   for t in stream.data)
    assert names.count("render_share") == 2
    assert names.count("combine_partials") == 1
    assert names.count("finish_partial") == 1
    assert {t["worker"] for t in stream.data} <= set(client.nthreads())
    # The client receives the finished frame only: its bytes, not the partial images'.
    st = frame.stats
    assert st["frame_bytes"] == sum(a.nbytes for a in (frame.rgba, frame.depth, frame.position,
                                                        frame.normal, frame.face))
    assert st["partial_bytes"] > 0 and st["composite_ms"] >= 0


def test_the_k_d_split_is_a_partition_into_boxes():
    for counts, parts in [((4, 4, 4), 2), ((5, 3, 2), 7), ((33, 1, 2), 64), ((2, 2, 2), 8)]:
        tree = split_bricks(counts, parts)
        owner = np.full(counts, -1)
        for leaf in tree.leaves():
            box = tuple(slice(a, b) for a, b in zip(leaf.lo, leaf.hi, strict=True))
            assert (owner[box] == -1).all() and owner[box].size > 0
            owner[box] = leaf.part
        assert (owner >= 0).all() and len(tree.leaves()) == parts
        assert tree.depth() == int(np.ceil(np.log2(parts)))
    with pytest.raises(ParameterError, match="parts"):
        split_bricks((2, 2, 1), 5)


def test_bad_input_is_one_line_naming_the_parameter(client, store, tmp_path):
    with pytest.raises(ParameterError, match="^level must be an integer from 0 to 2") as info:
        DistributedScene(store, client, strategy="sort-last", level=3)
    assert "\n" not in str(info.value)
    with pytest.raises(ParameterError, match="^source must be an OME-Zarr store"):
        (tmp_path / "s.nrrd").write_bytes(b"NRRD0004\n")
        DistributedScene(tmp_path / "s.nrrd", client, strategy="sort-last")
    with pytest.raises(ParameterError, match="^source must be the path of an OME-Zarr"):
        DistributedScene("demo:sphere?size=8", client, strategy="sort-last")
    with pytest.raises(ParameterError, match="^strategy must be one of"):
        DistributedScene(store, client, strategy="sort-middle")
    with pytest.raises(ParameterError, match="^level applies to strategy='sort-last'"):
        DistributedScene("demo:sphere?size=8", client, level=1)
    with pytest.raises(ParameterError, match="^iso=7 is outside the data range"):
        scene = DistributedScene(store, client, strategy="sort-last", level=2)
        scene.render(_camera(scene.volume), iso=7.0)


def test_a_worker_killed_during_a_render_is_survived(client, store, levels):
    """Kill the worker that holds a finished partial image (SIGKILL, as a crash or the OOM
    killer would) before the merge: its share is read and traced again on the other worker,
    and the frame still equals the in-memory render of the level. The other worker is held on
    a Dask Event until the kill, so the victim's partial image is surely lost. Runs last in
    this module: the nanny restarts the killed worker afterwards."""
    scene = DistributedScene(store, client, model="trilinear", strategy="sort-last", level=0)
    cam = _camera(levels[0], azimuth=70)
    pids = client.run(os.getpid)
    victim = scene.workers[0]
    survivor = scene.workers[1]

    release, blocker = hold_worker(client, survivor, "release-sort-last-survivor")
    deadline = time.monotonic() + 60
    result: dict[str, object] = {}

    def render() -> None:
        try:
            result["frame"] = scene.render(cam, **MODE_OPTIONS["dvr"])
        except BaseException as exc:  # reported by the assertion below
            result["error"] = exc

    thread = threading.Thread(target=render)
    thread.start()
    # The victim traces its share while the survivor is held; wait until it holds the result.
    while not any(str(k).startswith("render_share") for k in client.has_what()[victim]):
        assert time.monotonic() < deadline, "the victim never finished its share"
        assert thread.is_alive(), result
        time.sleep(0.01)
    os.kill(pids[victim], signal.SIGKILL)
    release.set()
    thread.join(120)
    blocker.result()
    assert not thread.is_alive(), "the render did not finish after the kill"
    assert "error" not in result, result.get("error")
    want = sc.Scene(levels[0]).render(cam, **MODE_OPTIONS["dvr"])
    _assert_close_to_whole("dvr", result["frame"], want)
    scene.close()
    client.wait_for_workers(2, timeout=60)
