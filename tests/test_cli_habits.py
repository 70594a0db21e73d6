"""Command-line habits: a derived output name, image formats through Pillow, colours, negative
numbers as values, "did you mean" suggestions, and one-line errors that name the option and the
accepted values (status 2, nothing written).

References: ``Scene.render`` with the options set by hand, Pillow reading the files back, the
JPEG composite computed here from the PNG.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main
from splinecast.cli._common import derived_output

SRC = "demo:sphere?size=16"  # |p| - 0.6 in [-0.54, 1.13], default isovalue 0, inside "low"
SIZE = ["--size", "20x16"]


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def api_frame(**render) -> sc.Frame:
    """What ``splinecast render SRC --size 20x16`` draws with the default framing
    (``--fit content``: the box of what the isovalue shows)."""
    vol = sc.demo("sphere", size=16)
    iso = render.get("iso", sc.auto_iso(vol)) if render.get("mode", "iso") == "iso" else None
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(20, 16),
                          fit=sc.content_box(vol, iso=iso))
    return sc.Scene(vol).render(cam, **render)


def test_without_o_the_name_comes_from_the_input(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(["render", SRC, *SIZE], capsys)
    assert code == 0, err
    assert out.strip() == str(tmp_path / "sphere.png")  # printed
    assert "wrote" in err and "set -o" in err
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "sphere.png")),
                                  api_frame().to_uint8())
    code, out, err = run(["render", SRC, *SIZE, "--mode", "mip", "--quiet"], capsys)
    assert code == 0 and out.strip() == str(tmp_path / "sphere-mip.png") and err == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sphere-mip.png", "sphere.png"]


def test_a_derived_name_never_is_the_input(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert derived_output("/data/head.nii.gz", "mip", ".png") == tmp_path / "head-mip.png"
    assert derived_output("demo:torus?size=64", "", ".mp4") == tmp_path / "torus.mp4"
    assert derived_output("scans/series/", "", ".png") == tmp_path / "series.png"
    assert derived_output("s3://bucket/brain.ome.zarr", "dvr", ".png").name == "brain-dvr.png"
    (tmp_path / "head.png").write_bytes(b"the input")
    assert derived_output(str(tmp_path / "head.png"), "", ".png") == tmp_path / "head-render.png"
    assert derived_output("head.png", "", ".png") == tmp_path / "head-render.png"


@pytest.mark.parametrize("suffix", [".png", ".tif", ".tiff", ".webp", ".jpg", ".jpeg"])
def test_every_image_format_through_pillow(tmp_path, capsys, suffix):
    out = tmp_path / f"image{suffix}"
    code, _, err = run(["render", SRC, *SIZE, "--quiet", "-o", str(out)], capsys)
    assert code == 0, err
    expected = api_frame().to_uint8()
    image = Image.open(out)
    assert image.format == {".png": "PNG", ".tif": "TIFF", ".tiff": "TIFF", ".webp": "WEBP",
                            ".jpg": "JPEG", ".jpeg": "JPEG"}[suffix]
    if suffix in (".jpg", ".jpeg"):  # lossy, and no alpha: close to the opaque image
        assert image.mode == "RGB"
        diff = np.abs(np.asarray(image, np.int16) - expected[..., :3].astype(np.int16))
        assert diff.mean() < 4
    else:  # lossless: the same pixels
        np.testing.assert_array_equal(np.asarray(image.convert("RGBA")), expected)


def test_jpeg_composites_a_translucent_background_on_its_colour(tmp_path, capsys):
    """A transparent white background: PNG keeps alpha 0 there, JPEG shows white."""
    png, jpg = tmp_path / "a.png", tmp_path / "a.jpg"
    for out in (png, jpg):
        code, _, err = run(["render", SRC, *SIZE, "--quiet", "--background", "#ffffff00",
                            "-o", str(out)], capsys)
        assert code == 0, err
    rgba = np.asarray(Image.open(png)).astype(np.float64) / 255
    empty = rgba[..., 3] == 0
    assert empty.sum() > 50 and (~empty).sum() > 50
    composite = rgba[..., :3] * rgba[..., 3:] + 1.0 * (1 - rgba[..., 3:])
    got = np.asarray(Image.open(jpg)).astype(np.float64) / 255
    assert np.abs(got - composite).mean() < 4 / 255
    assert got[empty].min() > 0.9  # white where nothing is drawn


def test_negative_windows_and_clips_are_values(tmp_path, capsys):
    """argparse takes "-0.5,0.5" for a value, not an option, in the plain form too."""
    png = tmp_path / "w.png"
    code, _, err = run(["render", SRC, *SIZE, "--quiet", "--mode", "mip", "--window",
                        "-0.5,0.5", "--clip", "-1,0,0,0.2", "-o", str(png)], capsys)
    assert code == 0, err
    expected = api_frame(mode="mip", window=(-0.5, 0.5), clip=[(-1.0, 0.0, 0.0, 0.2)])
    np.testing.assert_array_equal(np.asarray(Image.open(png)), expected.to_uint8())


@pytest.mark.parametrize("args, line", [
    (["--background", "whit"], "--background 'whit' is not a colour; did you mean white"),
    (["--background", "1,0.5"], "--background '1,0.5' is not a colour (accepted: a colour name"),
    (["--color", "2,0,0"], "--color '2,0,0' is not a colour (accepted: a colour name"),
    (["--color", "red", "--color", "blue"], "--color given 2 times for 1 isovalue"),
    (["--iso=-0.2,0", "--color", "red"], "--color given 1 times for 2 isovalues"),
    (["--mode", "mip", "--colormap", "virdis"],
     "--colormap 'virdis' is not a known colormap; did you mean viridis"),
    (["--mode", "mip", "--colormap", "nope"], "(accepted: gray, bone, hot, viridis"),
    (["-o", "{tmp}/out.bmp"], "must end in .png, .jpg, .jpeg, .tif, .tiff or .webp"),
    (["--colr", "red"], "unrecognized arguments: --colr red; did you mean --color"),
    (["--mode", "mipp"], "invalid choice: 'mipp'"),
    (["--model", "trilinaer"], "did you mean trilinear?"),
])
def test_bad_values_are_one_line_naming_the_option(tmp_path, capsys, monkeypatch, args, line):
    monkeypatch.chdir(tmp_path)  # where a derived name would be written
    argv = ["render", SRC, *SIZE, *[a.replace("{tmp}", str(tmp_path)) for a in args]]
    try:
        code, out, err = run(argv, capsys)
    except SystemExit as exc:  # argparse's own errors
        code, (out, err) = exc.code, capsys.readouterr()
    assert code == 2
    assert err.startswith("splinecast: error:") and err.count("\n") == 1, err
    assert line in err
    assert out == "" and list(tmp_path.iterdir()) == []  # nothing written


def test_choice_suggestions_of_the_real_command(tmp_path):
    """The installed command in a subprocess: status 2, one line with the suggestion."""
    proc = subprocess.run([sys.executable, "-m", "splinecast.cli", "render", SRC, "--mode",
                           "mipp"], capture_output=True, text=True, cwd=tmp_path,
                          env={**os.environ, "COLUMNS": "200"})
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "did you mean mip" in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "splinecast.cli", "render", SRC,
                           "--backgroud", "red"], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2 and "did you mean --background?" in proc.stderr
    assert list(Path(tmp_path).iterdir()) == []
