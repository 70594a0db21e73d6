"""The render modes of issue 5 from the command line: MIP against the API, and one-line errors
(status 2) for bad mode options. Every option's effect is compared with the API render, option by
option, in ``test_cli_options.py``."""

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
    cam = sc.Camera.orbit(vol, size=(20, 16))
    frame = sc.Scene(vol).render(cam, mode="mip", window=(-0.5, 0.5))
    np.testing.assert_array_equal(np.asarray(Image.open(png)), frame.to_uint8())


@pytest.mark.parametrize("extra, word", [
    (["--mode", "dvr"], "--tf"),
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
