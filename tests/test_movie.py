"""``splinecast movie`` and the movie writer, rendered in this process (no Dask): files read back
with imageio (an independent reader) have the right frame count and size; PNG frames equal
``Scene.render`` exactly; sweeps and turntables follow their ranges; mistakes are one line with
status 2; an error or Ctrl-C leaves nothing under the final name."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image, ImageSequence

import splinecast as sc
from splinecast.cli import main
from splinecast.cli._progress import Progress
from splinecast.distributed import MovieWriter, orbit_path, ramp
from splinecast.distributed.movie import movie_kind

iio = pytest.importorskip("imageio.v3", reason="needs imageio (test extra) to read movies back")
pytest.importorskip("imageio_ffmpeg", reason="needs the distributed extra (imageio-ffmpeg)")

SRC = "demo:marschner-lobb?size=16"


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _leftovers(folder):
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def test_mp4_has_the_frames_and_size_asked_for(tmp_path, capsys):
    out = tmp_path / "spin.mp4"
    code, stdout, err = _run(["movie", SRC, "--frames", "7", "--size", "48x32", "-o", str(out)],
                             capsys)
    assert code == 0 and stdout.strip() == str(out.resolve())
    assert "7/7" in err  # the progress bar reached the end
    video = iio.imread(out, index=None, plugin="FFMPEG")
    assert video.shape == (7, 32, 48, 3)
    # Lossy, but the picture is the render's: compare the first frame loosely.
    vol = sc.read(SRC)
    first = sc.Scene(vol).render(orbit_path(vol, 7, size=(48, 32))[0]).to_uint8()[..., :3]
    assert np.abs(video[0].astype(int) - first).mean() < 12
    assert not _leftovers(tmp_path)


def _gif_frames(path):
    """Every frame of a GIF (RGB) and its duration in ms, read back with Pillow."""
    with Image.open(path) as image:
        return [(np.asarray(frame.convert("RGB")), frame.info["duration"])
                for frame in ImageSequence.Iterator(image)]


def test_gif_isovalue_sweep_has_every_frame_at_its_fps(tmp_path, capsys):
    """Each frame of the GIF is ``Scene.render`` of that frame's camera and isovalue (the renders
    hold fewer than 256 colours, so the GIF's palette keeps them exactly), shown 1000 / fps ms."""
    out = tmp_path / "sweep.gif"
    code, _, _ = _run(["movie", SRC, "--frames", "5", "--iso", "0.3:0.7", "--size", "40x30",
                       "--fps", "10", "--quiet", "-o", str(out)], capsys)
    assert code == 0
    frames = _gif_frames(out)
    assert iio.imread(out, index=None).shape[:3] == (5, 30, 40)  # a second reader agrees
    vol = sc.read(SRC)
    scene = sc.Scene(vol)
    cams = orbit_path(vol, 5, azimuth=30, size=(40, 30))  # a sweep keeps the azimuth at 30
    assert len(frames) == 5
    for (got, duration), cam, iso in zip(frames, cams, np.linspace(0.3, 0.7, 5), strict=True):
        want = scene.render(cam, iso=float(iso)).to_uint8()[..., :3]
        assert len(np.unique(want.reshape(-1, 3), axis=0)) <= 256
        np.testing.assert_array_equal(got, want)
        assert duration == 100
    # Another rate: 4 frames per second are 250 ms each.
    code, _, _ = _run(["movie", SRC, "--frames", "2", "--iso", "0.3:0.7", "--size", "16x16",
                       "--fps", "4", "--quiet", "-o", str(out)], capsys)
    assert code == 0 and [d for _, d in _gif_frames(out)] == [250, 250]


def test_mp4_quality_and_fps(tmp_path, capsys):
    """``--quality`` reaches the encoder: the mean error against the renders falls from 5.90
    (quality 2) to 1.23 (quality 10, the bound is 1.2x), measured; ``--fps`` is the stream's."""
    vol = sc.read(SRC)
    scene = sc.Scene(vol)
    wants = [scene.render(cam).to_uint8()[..., :3].astype(int)
             for cam in orbit_path(vol, 4, size=(48, 32))]
    errors = {}
    for quality in (2, 10):
        out = tmp_path / f"q{quality}.mp4"
        code, _, _ = _run(["movie", SRC, "--frames", "4", "--size", "48x32", "--quality",
                           str(quality), "--fps", "12", "--quiet", "-o", str(out)], capsys)
        assert code == 0
        assert iio.immeta(out, plugin="FFMPEG")["fps"] == 12.0
        video = iio.imread(out, index=None, plugin="FFMPEG")
        assert video.shape == (4, 32, 48, 3)
        errors[quality] = max(float(np.abs(frame.astype(int) - want).mean())
                              for frame, want in zip(video, wants, strict=True))
    assert errors[10] <= 1.5 and errors[2] > 3 * errors[10], errors


def test_png_folder_frames_equal_the_local_renders_of_the_sweep(tmp_path, capsys):
    out = tmp_path / "frames"
    code, _, _ = _run(["movie", SRC, "--frames", "3", "--iso", "0.3:0.6", "--elevation",
                       "10:40", "--size", "24x20", "--quiet", "-o", f"{out}/"], capsys)
    assert code == 0
    vol = sc.read(SRC)
    scene = sc.Scene(vol)
    # Something besides the azimuth sweeps, so the camera stays at azimuth 30.
    cams = orbit_path(vol, 3, azimuth=30, elevation=(10, 40), size=(24, 20))
    for i, (cam, iso) in enumerate(zip(cams, (0.3, 0.45, 0.6), strict=True)):
        got = np.asarray(Image.open(out / f"frame_{i:04d}.png"))
        np.testing.assert_array_equal(got, scene.render(cam, iso=iso).to_uint8())
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:04d}.png" for i in range(3)]
    # Running again replaces the previous frames (a folder holding only frames).
    code, _, _ = _run(["movie", SRC, "--frames", "2", "--size", "24x20", "--quiet",
                       "-o", str(out)], capsys)
    assert code == 0 and len(list(out.iterdir())) == 2 and not _leftovers(tmp_path)


def test_mip_and_dvr_movies_use_the_render_options(tmp_path, capsys):
    tf = tmp_path / "tf.json"
    sc.TransferFunction([(0.3, 0.0), (0.7, 0.8)], domain=(0, 1)).save(tf)
    for argv in (["--mode", "mip", "--colormap", "bone"], ["--mode", "dvr", "--tf", str(tf)]):
        out = tmp_path / f"{argv[1]}"
        code, _, _ = _run(["movie", SRC, "--frames", "2", "--size", "16x16", "--quiet",
                           "-o", f"{out}/", *argv], capsys)
        assert code == 0
        vol = sc.read(SRC)
        cam = orbit_path(vol, 2, size=(16, 16))[1]
        options = {"mode": "mip", "colormap": "bone"} if argv[1] == "mip" else \
            {"mode": "dvr", "tf": sc.TransferFunction.load(tf)}  # no DVR option: no dvr=
        want = sc.Scene(vol).render(cam, **options).to_uint8()
        np.testing.assert_array_equal(np.asarray(Image.open(out / "frame_0001.png")), want)


def test_turntable_leaves_out_the_repeated_last_frame():
    np.testing.assert_allclose(ramp((30, 390), 4, "azimuth", periodic=True), [30, 120, 210, 300])
    np.testing.assert_allclose(ramp((0, 90), 4, "azimuth", periodic=True), [0, 30, 60, 90])
    np.testing.assert_allclose(ramp(0.5, 3, "iso"), [0.5, 0.5, 0.5])
    np.testing.assert_allclose(ramp((30, 390), 1, "azimuth", periodic=True), [30])


@pytest.mark.parametrize(("argv", "message"), [
    (["--frames", "0", "-o", "x.mp4"], "--frames must be at least 1"),
    (["--frames", "2", "-o", "x.avi"], "must be .mp4, .gif or a folder"),
    (["--frames", "2", "--size", "15x16", "-o", "x.mp4"], "even width and height"),
    (["--frames", "2", "--azimuth", "1:2:3", "-o", "x.mp4"], "--azimuth must be V or V0:V1"),
    (["--frames", "2", "--iso", "0.2:0.4", "--mode", "mip", "-o", "x.mp4"], "--mode iso"),
    (["--frames", "2", "--iso", "0.2:7", "-o", "x.mp4"], "outside the data range"),
    (["--frames", "2", "--model", "nope", "-o", "x.mp4"], "--model must be one of"),
    (["--frames", "2", "--workers", "0", "-o", "x.mp4"], "--workers must be at least 1"),
    (["--frames", "2", "--quality", "11", "-o", "x.mp4"], "quality must be between 1 and 10"),
    (["--frames", "2", "--quality", "0.5", "-o", "x.mp4"], "quality must be between 1 and 10"),
    (["--frames", "2", "--fps", "0", "-o", "x.gif"], "fps must be positive"),
])
def test_mistakes_are_one_line_and_write_nothing(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    code, _, err = _run(["movie", SRC, "--size", "16x16", *argv], capsys)
    assert code == 2 and message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_a_missing_file_names_the_path(tmp_path, capsys):
    missing = tmp_path / "head.nii.gz"
    code, _, err = _run(["movie", str(missing), "--frames", "2", "-o",
                         str(tmp_path / "m.gif")], capsys)
    assert code == 2 and str(missing) in err and err.count("\n") == 1


def test_a_folder_with_other_files_is_not_overwritten(tmp_path):
    (tmp_path / "notes.txt").write_text("keep me")
    with pytest.raises(sc.ParameterError, match="holds other files"):
        MovieWriter(tmp_path, (8, 8), frames=2)
    assert (tmp_path / "notes.txt").read_text() == "keep me"


@pytest.mark.parametrize("name", ["m.mp4", "m.gif", "m/"])
def test_an_error_mid_movie_leaves_nothing(tmp_path, name):
    target = tmp_path / name
    image = np.zeros((8, 8, 4), np.uint8)
    with pytest.raises(RuntimeError, match="boom"):
        with MovieWriter(target, (8, 8), frames=3) as movie:
            movie.write(image)
            movie.write(image)
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="frame must be"):
        with MovieWriter(target, (8, 8), frames=1) as movie:
            movie.write(np.zeros((8, 9, 4), np.uint8))
    assert list(tmp_path.iterdir()) == []


def test_movie_kind():
    assert movie_kind("a.MP4") == "mp4" and movie_kind("a.gif") == "gif"
    assert movie_kind("frames/") == "png" and movie_kind("frames") == "png"


def test_progress_prints_few_lines_off_a_terminal():
    stream = io.StringIO()
    progress = Progress(100, "frames", stream=stream, interval=3600)
    for _ in range(100):
        progress.update()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2 and lines[0].startswith("frames [") and "1/100" in lines[0]
    assert "100/100" in lines[1] and "#" * 24 in lines[1]
    quiet = io.StringIO()
    Progress(3, "frames", enabled=False, stream=quiet).update(3)
    assert quiet.getvalue() == ""


@pytest.mark.parametrize("name", ["spin.mp4", "frames/"])
def test_ctrl_c_leaves_no_partial_movie(tmp_path, name):
    """SIGINT (Ctrl-C) once the first frames are written: exit status 130, no traceback, and
    nothing under the final name nor any temporary left beside it."""
    target = tmp_path / name
    cmd = [sys.executable, "-m", "splinecast.cli", "movie", SRC, "--frames", "5000",
           "--size", "32x32", "-o", str(target)]
    # As from a terminal: Ctrl-C's default action. The test runner's worker process may ignore
    # SIGINT (pytest-xdist does), and an ignored signal stays ignored across exec, which would
    # keep Python from installing its KeyboardInterrupt handler in the child.
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        for line in proc.stderr:  # the first progress line: frames are being written
            if line.startswith("frames ["):
                break
        else:
            pytest.fail(f"no progress line; exit status {proc.wait()}")
        proc.send_signal(signal.SIGINT)
        rest = proc.stderr.read()
        code = proc.wait(timeout=60)
    finally:
        proc.kill()
    assert code == 130, rest
    assert "Traceback" not in rest
    assert list(tmp_path.iterdir()) == []
