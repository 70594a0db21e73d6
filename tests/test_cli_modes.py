"""The render modes of issue 5 from the command line: MIP, DVR, several isosurfaces, clipping,
effects, smoothing; and one-line errors (status 2) for bad mode options."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main

SRC = "demo:sphere?size=16"


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_mip_matches_the_api(tmp_path, capsys):
    png = tmp_path / "mip.png"
    code, out, _ = _run(["render", SRC, "--mode", "mip", "--window=-0.5,0.5", "--size",
                         "20x16", "--quiet", "-o", str(png)], capsys)
    assert code == 0 and out.strip().endswith("mip.png")
    vol = sc.demo("sphere", size=16)
    cam = sc.Camera.orbit(vol, size=(20, 16), fit=sc.content_box(vol))  # --fit content
    frame = sc.Scene(vol).render(cam, mode="mip", window=(-0.5, 0.5))
    np.testing.assert_array_equal(np.asarray(Image.open(png)), frame.to_uint8())


def test_dvr_multi_iso_clip_and_effects_run(tmp_path, capsys):
    tf_path = tmp_path / "tf.json"
    sc.TransferFunction([(-0.2, 0), (0.0, 0.8)], domain=(-0.6, 1.1)).save(tf_path)
    runs = [
        ["--mode", "dvr", "--tf", str(tf_path), "--adaptive", "--termination", "0.98",
         "--step", "0.5"],
        ["--mode", "dvr", "--tf", str(tf_path), "--adaptive", "--table-layout", "exponential",
         "--step", "0.5"],
        ["--iso=-0.3,0", "--opacity", "0.4,0.8", "--clip", "0,0,1,0", "--clip", "1,0,0,0"],
        ["--iso", "0", "--texture", "checker", "--shading", "cel",
         "--crop=-1,0.5,-1,1,-1,1", "--smooth", "3"],
    ]
    for extra in runs:
        png = tmp_path / "x.png"
        code, _, err = _run(["render", SRC, "--size", "12x10", "--quiet", "-o", str(png),
                             *extra], capsys)
        assert code == 0, err
        assert Image.open(png).size == (12, 10)


@pytest.mark.parametrize("extra, word", [
    (["--mode", "dvr", "--tf", "no-such-tf.json"], "no-such-tf.json"),
    (["--clip", "1,0,0"], "--clip"),
    (["--iso=0,-0.2", "--opacity", "0.5"], "--opacity"),
    (["--mode", "mip", "--window", "a,b"], "--window"),
    (["--mode", "mip", "--colormap", "rainbow"], "colormap"),
])
def test_bad_mode_options_are_one_line_errors(tmp_path, capsys, extra, word):
    png = tmp_path / "bad.png"
    code, _, err = _run(["render", SRC, "--quiet", "-o", str(png), *extra], capsys)
    assert code == 2
    assert word in err and err.count("\n") == 1
    assert not png.exists()
