"""The command line: outputs, timings on stderr, one-line errors with exit status 2."""

from __future__ import annotations

import gc
import json
import subprocess
import sys
import weakref

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main


def run(args: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_render_writes_png_and_depth(tmp_path, capsys):
    png, depth = tmp_path / "s.png", tmp_path / "d.npy"
    code, out, err = run(["render", "demo:sphere?size=24", "--iso", "0", "--size", "40x30",
                          "--elevation", "10", "-o", str(png), "--depth", str(depth),
                          "--samples", "1"], capsys)  # one ray a pixel: no blended edges
    assert code == 0
    assert out.strip() == str(png.resolve())
    assert "rendered 40x30" in err
    image = np.asarray(Image.open(png))
    assert image.shape == (30, 40, 4)
    d = np.load(depth)
    assert d.shape == (30, 40)
    # The same render through the API gives the same depth buffer.
    vol = sc.demo("sphere", size=24)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=10, size=(40, 30),
                          fit=sc.content_box(vol, iso=0.0))  # the CLI's default --fit content
    np.testing.assert_array_equal(sc.Scene(vol).render(cam, iso=0.0).depth, d)
    # Hits are exactly where the image is not background.
    background = np.all(image == image[0, 0], axis=-1)
    assert np.isfinite(d).sum() > 50
    np.testing.assert_array_equal(np.isfinite(d), ~background)


def test_quiet_silences_stderr(tmp_path, capsys):
    code, _, err = run(["render", "demo:sphere?size=16", "--size", "8x8", "--quiet",
                        "-o", str(tmp_path / "q.png")], capsys)
    assert code == 0 and err == ""


def test_info_reports_shape_dtype_spacing_and_range(tmp_path, capsys):
    data = np.arange(4 * 5 * 6, dtype=np.int16).reshape(4, 5, 6)
    path = tmp_path / "v.mhd"
    sc.write(sc.Volume(data, spacing=(0.5, 1.0, 2.0)), path)
    code, out, _ = run(["info", str(path)], capsys)
    assert code == 0
    assert "4 x 5 x 6" in out and "int16" in out
    assert "0.5, 1, 2" in out
    assert "0 .. 119" in out
    assert f"50%  {np.percentile(data, 50):g}" in out


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["render", "MISSING.nii", "-o", "{tmp}/a.png"], "MISSING.nii"),
        (["render", "demo:sphere?size=16", "--iso", "9", "-o", "{tmp}/a.png"], "iso"),
        (["render", "demo:sphere?size=16", "--size", "0x4", "-o", "{tmp}/a.png"], "size"),
        (["render", "demo:sphere?size=16", "--size=-3x4", "-o", "{tmp}/a.png"], "size"),
        (["render", "demo:sphere?size=16", "-o", "{tmp}/a.bmp"], "-o"),
        (["render", "demo:sphere?size=16", "-o", "{tmp}/nofolder/a.png"], "does not exist"),
        (["render", "demo:sphere?size=16", "--depth", "{tmp}/d.txt", "-o", "{tmp}/a.png"],
         "--depth"),
        (["render", "demo:sphere?size=16", "--method", "sampled", "--step", "0",
          "-o", "{tmp}/a.png"], "step"),
        (["render", "demo:sphere?size=16", "--model", "cubic", "-o", "{tmp}/a.png"], "model"),
        (["render", "demo:bogus", "-o", "{tmp}/a.png"], "bogus"),
    ],
)
def test_user_mistakes_give_one_line_and_status_2(tmp_path, capsys, args, needle):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    code, out, err = run(args, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("splinecast: error:") and needle in lines[0]
    assert list(tmp_path.rglob("*")) == []  # nothing written, no temporary left behind


def test_truncated_raw_file_is_rejected_before_rendering(tmp_path, capsys):
    raw = tmp_path / "v.raw"
    raw.write_bytes(np.zeros(10 * 10 * 9, np.uint8).tobytes())  # one slice short
    (tmp_path / "v.json").write_text(json.dumps({"shape": [10, 10, 10], "dtype": "uint8"}))
    code, _, err = run(["render", str(raw), "-o", str(tmp_path / "out.png")], capsys)
    assert code == 2 and "v.raw" in err and "truncated" in err
    assert not (tmp_path / "out.png").exists()


def test_nan_in_data_is_a_clear_error(tmp_path, capsys):
    data = np.zeros((8, 8, 8), np.float32)
    data[3, 3, 3] = np.nan
    path = tmp_path / "nan.npy"
    np.save(path, data)
    code, _, err = run(["render", str(path), "--iso", "0", "-o", str(tmp_path / "o.png")], capsys)
    assert code == 2 and "NaN" in err and "nan.npy" in err
    assert not (tmp_path / "o.png").exists()


class _Cycle:
    """An object in a reference cycle: only the cycle collector frees it."""

    def __init__(self) -> None:
        self.me = self


def test_a_failure_collects_its_own_garbage_and_not_the_callers(monkeypatch, capsys):
    from splinecast.cli import COMMANDS

    made: list[weakref.ref] = []

    def failing_run(args):
        made.append(weakref.ref(_Cycle()))
        raise sc.SplinecastError("broken on purpose")

    monkeypatch.setattr(COMMANDS["info"], "run", failing_run)
    enabled = gc.isenabled()
    gc.disable()  # no automatic collection may interfere
    try:
        callers = weakref.ref(_Cycle())
        gc.freeze()
        gc.unfreeze()  # moved to the oldest generation (the young ones are collected first)
        assert gc.get_freeze_count() == 0
        code, _, err = run(["info", "demo:sphere"], capsys)
        assert code == 2 and "broken on purpose" in err
        assert made and made[0]() is None  # the command's garbage: collected before returning
        assert callers() is not None  # the caller's heap was not walked
        assert gc.get_freeze_count() == 0  # and is collectable again
        gc.collect()
        assert callers() is None
        # A caller that froze its own objects keeps them frozen.
        gc.freeze()
        frozen = gc.get_freeze_count()
        assert run(["info", "demo:sphere"], capsys)[0] == 2
        # (a frozen object whose last reference goes is still freed: allow for a few)
        assert frozen * 0.99 < gc.get_freeze_count() <= frozen
    finally:
        gc.unfreeze()
        if enabled:
            gc.enable()


def test_a_serving_command_releases_the_frozen_objects(monkeypatch, capsys):
    from splinecast.cli import COMMANDS
    from splinecast.cli._common import uncaptured

    counts = {}

    def serving_run(args):
        counts["command"] = gc.get_freeze_count()
        with uncaptured(args):
            counts["serving"] = gc.get_freeze_count()
        return 0

    monkeypatch.setattr(COMMANDS["info"], "run", serving_run)
    assert gc.get_freeze_count() == 0
    assert run(["info", "demo:sphere"], capsys)[0] == 0
    assert counts["command"] > 0  # the command ran with what existed before it frozen
    assert counts["serving"] == 0  # a server does not keep it frozen for its whole life
    assert gc.get_freeze_count() == 0


def test_argparse_errors_are_one_line_status_2():
    proc = subprocess.run([sys.executable, "-m", "splinecast.cli", "render"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1


def test_import_does_not_load_heavy_optional_libraries():
    # (scipy is left out: numba itself imports it when it is installed.)
    code = ("import sys, splinecast; heavy = [m for m in ('nibabel', 'pydicom', "
            "'tifffile', 'nrrd', 'PIL') if m in sys.modules]; print(heavy)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "[]"
