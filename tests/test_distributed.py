"""Sort-first rendering on a Dask LocalCluster (2 worker processes, 1 thread each) against the
local ``Scene.render`` of the same volume: every buffer of the assembled frame, tile by tile
and frame by frame; a worker killed during a batch; a path the workers cannot open; the movie
command on the cluster.

One cluster serves the whole module (starting one costs seconds).
"""

from __future__ import annotations

import inspect
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from dask_faults import hold_worker
from PIL import Image

import splinecast as sc
from splinecast.cli import main
from splinecast.distributed import FrameCanvas, Shot, orbit_path, tile_grid
from splinecast.distributed.tiles import PIXEL_FIELDS

distributed = pytest.importorskip("distributed", reason="needs the distributed extra (Dask)")

SRC = "demo:marschner-lobb?size=20"
MNI = Path(__file__).resolve().parents[2] / "shared" / "data" / "mni152_t1_1mm.nii.gz"
TF = sc.TransferFunction([(0.3, 0.0), (0.5, 0.6), (0.8, 0.9)], domain=(0.0, 1.0))
#: Mode -> Scene.render options of the equality tests.
MODE_OPTIONS = {
    "iso": {"iso": 0.5},
    "multi-iso": {"iso": [0.3, 0.6]},
    "mip": {"mode": "mip"},
    # A value within the tolerance, chosen by what earlier rays of the pixel's tile found.
    "mip-tolerance": {"mode": "mip", "tolerance": 0.05},
    "dvr": {"mode": "dvr", "tf": TF, "dvr": sc.DVRSettings(step=0.5)},
}
#: (model, mode) pairs rendered on the cluster and locally.
CASES = [
    ("trilinear", "iso"),
    ("trilinear", "multi-iso"),
    ("trilinear", "mip"),
    ("trilinear", "mip-tolerance"),
    ("trilinear", "dvr"),
    ("s31", "iso"),
    ("s31", "mip"),
    ("s31", "dvr"),
]


@pytest.fixture(scope="module")
def volume():
    return sc.read(SRC)


@pytest.fixture(scope="module")
def client(volume):
    # Compile every kernel the tests use here first: the workers then load them from Numba's
    # on-disk cache instead of compiling them again, two at a time, from an empty cache.
    cam = sc.Camera.orbit(volume, size=(4, 4))
    for model, mode in CASES:
        sc.Scene(volume, model=model).render(cam, **MODE_OPTIONS[mode])
    cluster = sc.distributed.local_cluster(2)  # every test below runs on its quiet settings
    with cluster, distributed.Client(cluster) as client:
        yield client


@pytest.fixture(scope="module")
def scenes(client):
    """One DistributedScene per model, shared by the tests (workers keep them prepared)."""
    return {model: sc.distributed.DistributedScene(SRC, client, model=model)
            for model in ("trilinear", "s31")}


#: Per-ray work statistics: equal between tilings except where a mode's work on a ray depends
#: on the ray its thread traced before (MIP's lower bound), which a tiling changes.
WORK_FIELDS = ("cells_visited", "cells_tested", "blocks_skipped")


def assert_frames_equal(got: sc.Frame, want: sc.Frame, rgba_atol: float = 0.0,
                        work: bool = True) -> None:
    """Every per-ray buffer equal (NaN where NaN); ``rgba`` within ``rgba_atol``; the work
    statistics only with ``work``."""
    assert got.size == want.size
    for name in PIXEL_FIELDS:
        if name in WORK_FIELDS and not work:
            continue
        a, b = getattr(got, name), getattr(want, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        if name == "rgba" and rgba_atol:
            np.testing.assert_allclose(a, b, rtol=0, atol=rgba_atol)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)
    assert (got.value is None) == (want.value is None)
    if want.value is not None:
        np.testing.assert_array_equal(got.value, want.value)


@pytest.mark.parametrize(("model", "mode"), CASES)
def test_tiled_render_equals_the_local_render(scenes, volume, model, mode):
    # 70x45 in 24-pixel tiles: ragged last row and column of tiles.
    cam = sc.Camera.orbit(volume, azimuth=35, elevation=25, size=(70, 45))
    options = MODE_OPTIONS[mode]
    local = sc.Scene(volume, model=model).render(cam, **options)
    frame = scenes[model].render(cam, tile_size=24, **options)
    # Tiles on the scene's tile grid: every ray follows the same rays of its tile as in the
    # local render, so even the per-ray work of MIP (which starts from the previous ray's
    # answer) is the same.
    assert 24 % sc.Scene(volume).tile_shape[0] == 0
    assert_frames_equal(frame, local, rgba_atol=1e-6 if mode == "dvr" else 0.0)
    assert local.hit.any() and not local.hit.all()  # the comparison covers hits and misses
    st = frame.stats
    assert st["tiles"] == 3 * 2 and st["wall_ms"] > 0
    for key in ("mode", "model", "width", "height", "rays", "hits"):
        assert st[key] == local.stats[key], key
    for key in ("mean_cells_visited", "mean_cells_tested", "mean_blocks_skipped"):
        assert st[key] == pytest.approx(local.stats[key], rel=1e-12), key
    if mode == "dvr":  # per-ray count not kept in the frame: a ray-weighted mean of the tiles
        assert st["mean_samples"] == pytest.approx(local.stats["mean_samples"], rel=1e-12)


@pytest.mark.parametrize("mode", [sc.Iso(0.5), sc.Mip(window=(0.2, 0.9)),
                                  sc.Dvr(TF, sc.DVRSettings(step=0.5))],
                         ids=["iso", "mip", "dvr"])
def test_sort_first_is_the_render_template_and_equals_scene_render_bit_for_bit(
        scenes, volume, mode):
    """``DistributedScene.render`` is the template's (the scene is a ``SceneTemplate`` whose
    frame is made by the workers' scenes): the same camera and mode object give the in-memory
    ``Scene.render``'s frame bit for bit, every buffer and the mode's statistics."""
    from splinecast.render.template import SceneTemplate

    scene = scenes["trilinear"]
    assert isinstance(scene, SceneTemplate)
    params = inspect.signature(type(scene).render).parameters
    assert list(params)[:4] == ["self", "camera", "mode", "iso"]
    assert params["mode"].default == "iso"
    assert {k: params[k].default for k in ("tile_size", "image_only", "on_tile")} == {
        "tile_size": "auto", "image_only": False, "on_tile": None}
    cam = sc.Camera.orbit(volume, azimuth=-50, elevation=30, size=(56, 40))
    local = sc.Scene(volume).render(cam, mode)
    frame = scene.render(cam, mode, tile_size=16)
    assert_frames_equal(frame, local)
    for key, value in local.stats.items():
        if not key.endswith("_ms") and not key.startswith("mean_"):
            assert frame.stats[key] == value, key
    assert frame.stats["tiles"] == 4 * 3


def test_sort_first_refuses_bad_arguments_on_the_client(scenes, volume):
    scene = scenes["trilinear"]
    cam = sc.Camera.orbit(volume, size=(16, 16))
    with pytest.raises(TypeError, match=r"DistributedScene.render\(\) got an unexpected "
                                        r"keyword argument 'tile'"):
        scene.render(cam, tile=16)
    with pytest.raises(sc.ParameterError, match="camera must be a splinecast.Camera"):
        scene.render("camera")
    with pytest.raises(TypeError):
        list(scene.render_many([cam], isovalue=0.5))


def test_tiles_stream_as_they_complete_and_cover_the_image_once(scenes, volume):
    cam = sc.Camera.orbit(volume, size=(50, 40))
    local = sc.Scene(volume).render(cam, iso=0.5)
    seen = np.zeros((40, 50), int)
    tiles = []
    for tile, frame in scenes["trilinear"].render_tiles(cam, iso=0.5, tile_size=16):
        seen[tile.rows, tile.cols] += 1
        np.testing.assert_array_equal(frame.rgba, local.rgba[tile.rows, tile.cols])
        np.testing.assert_array_equal(frame.depth, local.depth[tile.rows, tile.cols])
        tiles.append(tile)
    assert (seen == 1).all()
    assert sorted(tiles, key=lambda t: (t.row0, t.col0)) == sorted(
        tile_grid(cam, 16), key=lambda t: (t.row0, t.col0))
    calls = []
    frame = scenes["trilinear"].render(cam, iso=0.5, tile_size=16,
                                       on_tile=lambda t, f: calls.append(t))
    assert sorted(calls, key=lambda t: (t.row0, t.col0)) == sorted(
        tiles, key=lambda t: (t.row0, t.col0))
    assert_frames_equal(frame, local)
    image = scenes["trilinear"].render(cam, iso=0.5, tile_size=16, image_only=True)
    np.testing.assert_array_equal(image, local.to_uint8())


def test_tiles_carry_only_the_requested_outputs(scenes, volume):
    cam = sc.Camera.orbit(volume, azimuth=35, elevation=25, size=(70, 45))
    everything = sc.Scene(volume).render(cam, iso=0.5)
    frame = scenes["trilinear"].render(cam, iso=0.5, tile_size=24, outputs=("rgba", "depth"))
    np.testing.assert_array_equal(frame.rgba, everything.rgba)
    np.testing.assert_array_equal(frame.depth, everything.depth)
    for name in ("position", "normal", "face", "cells_visited", "cells_tested",
                 "blocks_skipped", "value"):
        assert getattr(frame, name) is None, name
    assert frame.stats["hits"] == everything.stats["hits"]
    assert "mean_cells_visited" not in frame.stats
    mip = scenes["trilinear"].render(cam, mode="mip", tile_size=24, outputs=("value",))
    np.testing.assert_array_equal(mip.value, sc.Scene(volume).render(cam, mode="mip").value)
    assert mip.rgba is None and mip.depth is None


def test_automatic_tiles_and_positional_arguments_match_scene_render(scenes, volume):
    cam = sc.Camera.orbit(volume, size=(160, 128))
    local = sc.Scene(volume).render(cam, "iso", 0.4)
    frame = scenes["trilinear"].render(cam, "iso", 0.4)  # positional, as Scene.render takes
    assert_frames_equal(frame, local)
    assert frame.stats["tiles"] == 3 * 2  # 4 per worker thread wanted, but 64 px at least


def test_a_batch_of_frames_is_a_camera_path_or_a_sweep_in_order(scenes, volume):
    path = orbit_path(volume, 5, azimuth=(0, 120), size=(32, 24))
    scene = sc.Scene(volume)
    frames = list(scenes["trilinear"].render_many(path, iso=0.5, in_flight=2))
    assert len(frames) == 5
    for cam, frame in zip(path, frames, strict=True):
        assert_frames_equal(frame, scene.render(cam, iso=0.5))
    sweep = [Shot(path[0], {"iso": v}) for v in (0.3, 0.5, 0.7)]
    images = list(scenes["trilinear"].render_many(sweep, image_only=True))
    for shot, image in zip(sweep, images, strict=True):
        assert image.dtype == np.uint8
        np.testing.assert_array_equal(image, scene.render(path[0], **shot.options).to_uint8())
    assert not np.array_equal(images[0], images[2])  # the sweep did change the isovalue


def test_the_workers_keep_the_prepared_scene(client, scenes):
    from splinecast.distributed import worker

    counts = client.run(lambda: len(worker._scenes))
    assert len(counts) == 2 and all(n >= 1 for n in counts.values())
    source = scenes["trilinear"].source
    assert all(client.run(lambda: source in worker._scenes).values())


def test_local_cluster_workers_get_the_quiet_settings_and_this_process_keeps_its_own(client):
    import dask

    def settings():
        import dask

        return {key: dask.config.get(key) for key in sc.distributed.QUIET_CONFIG}

    for got in client.run(settings).values():
        assert got == sc.distributed.QUIET_CONFIG
    assert len(client.scheduler_info()["workers"]) == 2
    assert all(w["nthreads"] == 1 for w in client.scheduler_info()["workers"].values())
    # Only the cluster's start-up saw them: this process's configuration is Dask's default.
    assert dask.config.get("distributed.worker.profile.enabled") is True
    assert dask.config.get("distributed.admin.tick.interval") == "20ms"


def test_a_path_the_workers_cannot_open_is_one_clear_error(client, tmp_path):
    missing = tmp_path / "missing.nii.gz"
    with pytest.raises(sc.ReadError) as info:
        sc.distributed.DistributedScene(missing, client)
    message = str(info.value)
    assert str(missing) in message and "worker tcp://" in message and "\n" not in message
    assert info.value.__cause__ is None


def test_bad_render_options_fail_like_a_local_render(scenes, volume):
    cam = sc.Camera.orbit(volume, size=(16, 16))
    with pytest.raises(TypeError):
        scenes["trilinear"].render(cam, isovalue=0.5)  # a name Scene.render does not take
    with pytest.raises(sc.ParameterError, match="outside the data range"):
        scenes["trilinear"].render(cam, iso=7.0)
    with pytest.raises(sc.ParameterError, match="model option"):
        sc.distributed.DistributedScene(SRC, scenes["trilinear"].client, model="trilinear",
                                        prefilter=True)


@pytest.mark.parametrize("where", ["scheduler", "workers"])
def test_movie_on_the_cluster_writes_the_local_frames(client, tmp_path, capsys, where):
    out = tmp_path / "frames"
    # --workers starts its own local_cluster of one process for the run.
    cluster = (["--scheduler", client.scheduler.address] if where == "scheduler"
               else ["--workers", "1"])
    code = main(["movie", SRC, "--frames", "4", "--azimuth", "10:100", "--iso", "0.5",
                 "--size", "40x30", *cluster, "-o", f"{out}/"])
    _, err = capsys.readouterr()
    assert code == 0 and "4/4" in err
    names = sorted(p.name for p in out.iterdir())
    assert names == [f"frame_{i:04d}.png" for i in range(4)]
    volume = sc.read(SRC)
    scene = sc.Scene(volume)
    for name, cam in zip(names, orbit_path(volume, 4, azimuth=(10, 100), size=(40, 30)),
                         strict=True):
        want = scene.render(cam, iso=0.5).to_uint8()
        np.testing.assert_array_equal(np.asarray(Image.open(out / name)), want)


@pytest.mark.skipif(not MNI.exists(), reason=f"real data not found: {MNI} (../shared/data)")
def test_mri_from_a_file_path_equals_the_local_render(client):
    volume = sc.read(MNI)
    scene = sc.distributed.DistributedScene(MNI, client)
    assert scene.volume.shape == volume.shape and scene.volume.value_range == volume.value_range
    cam = sc.Camera.orbit(scene.volume, azimuth=60, size=(48, 40))
    assert_frames_equal(scene.render(cam, iso=80, tile_size=20),
                        sc.Scene(volume).render(cam, iso=80))
    scene.close()


def test_a_worker_killed_during_a_batch_is_survived(client, scenes, volume):
    """Kill one worker process (SIGKILL, as a crash or the OOM killer would) in the middle of
    a batch: its frames are recomputed on the other worker and every frame still equals the
    local render. The other worker is held on a Dask Event until the kill, so every frame
    starts on the victim and the kill surely loses work. Runs last: the nanny restarts the
    killed worker afterwards."""
    path = orbit_path(volume, 10, azimuth=(0, 300), size=(60, 60))
    pids = client.run(os.getpid)
    victim, survivor = sorted(pids)

    release, blocker = hold_worker(client, survivor, "release-survivor")
    frames = []
    for frame in scenes["s31"].render_many(path, iso=0.5):
        if not frames:
            lost = client.processing(workers=[victim])[victim]
            assert lost, "the victim had no task in flight: the test would prove nothing"
            os.kill(pids[victim], signal.SIGKILL)
            release.set()
        frames.append(frame)
    blocker.result()
    assert len(frames) == 10
    scene = sc.Scene(volume, model="s31")
    for cam, frame in zip(path, frames, strict=True):
        assert_frames_equal(frame, scene.render(cam, iso=0.5))
    client.wait_for_workers(2, timeout=60)


def test_canvas_refuses_an_incomplete_frame(volume):
    cam = sc.Camera.orbit(volume, size=(20, 20))
    canvas = FrameCanvas(cam)
    tile = tile_grid(cam, 10)[0]
    canvas.paste(tile, sc.Scene(volume).render(tile.camera(cam), iso=0.5))
    assert not canvas.complete
    with pytest.raises(ValueError, match="100 of 400 pixels"):
        canvas.frame()


def test_a_url_is_opened_by_every_worker_and_renders_as_the_local_file(client, tmp_path):
    """The workers read the volume over HTTP themselves (a real aiohttp server on 127.0.0.1):
    the assembled frame equals the local render of the same file."""
    pytest.importorskip("fsspec", reason="remote reading needs the remote extra")
    from remote_servers import Faults, FileServer

    volume = sc.read(SRC)
    sc.write(volume, tmp_path / "ml.nrrd")
    local = sc.read(tmp_path / "ml.nrrd")
    cam = sc.Camera.orbit(local, azimuth=40, size=(40, 32))
    with FileServer(tmp_path, Faults()) as server:
        url = f"{server.url}/ml.nrrd"
        scene = sc.distributed.DistributedScene(url, client)
        try:
            assert str(scene.source) == url  # the workers were given the URL, not a path
            assert scene.volume.shape == local.shape
            assert_frames_equal(scene.render(cam, iso=0.5, tile_size=16),
                                sc.Scene(local).render(cam, iso=0.5))
        finally:
            scene.close()
        assert any(path.endswith("/ml.nrrd") for _, path, _ in server.faults.log)
