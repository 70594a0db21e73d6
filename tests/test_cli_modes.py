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
    cam = sc.Camera.orbit(vol, size=(20, 16), fit=sc.content_box(vol))  # --fit content
    frame = sc.Scene(vol).render(cam, mode="mip", window=(-0.5, 0.5))
    np.testing.assert_array_equal(np.asarray(Image.open(png)), frame.to_uint8())


@pytest.mark.parametrize("extra, word", [
    (["--mode", "dvr", "--tf", "no-such-tf.json"], "no-such-tf.json"),
    (["--clip", "1,0,0"], "--clip"),
    (["--iso=0,-0.2", "--opacity", "0.5"], "--opacity"),
    (["--mode", "mip", "--window", "a,b"], "--window"),
    (["--mode", "mip", "--colormap", "rainbo"], "--colormap 'rainbo' is not a known colormap; "
                                                  "did you mean rainbow"),
])
def test_bad_mode_options_are_one_line_errors(tmp_path, capsys, extra, word):
    png = tmp_path / "bad.png"
    code, _, err = _run(["render", SRC, "--quiet", "-o", str(png), *extra], capsys)
    assert code == 2
    assert word in err and err.count("\n") == 1
    assert not png.exists()


@pytest.mark.parametrize("model", ["trilinear", "bspline2", "qss", "s31"])
def test_every_model_in_every_mode_from_the_cli_equals_the_api(tmp_path, capsys, model):
    """--model M --mode X works for every combination and draws what Scene.render draws."""
    tf_path = tmp_path / "tf.json"
    tf = sc.TransferFunction([(-0.2, 0), (0.0, 0.8)], domain=(-0.6, 1.1))
    tf.save(tf_path)
    vol = sc.demo("sphere", size=16)
    cam = sc.Camera.orbit(vol, size=(14, 12))
    scene = sc.Scene(vol, model=model)
    runs = [
        (["--iso", "0"], {"iso": 0.0}),
        (["--iso=-0.3,0", "--opacity", "0.4,0.8"], {"iso": [-0.3, 0.0], "opacity": [0.4, 0.8]}),
        (["--mode", "mip"], {"mode": "mip"}),
        (["--mode", "minip"], {"mode": "minip"}),
        # The API without dvr= uses render.dvr.DEFAULT_SETTINGS (ray, early termination),
        # which the CLI's DVR options do not spell: both sides get the same explicit settings.
        (["--mode", "dvr", "--tf", str(tf_path), "--step", "0.5"],
         {"mode": "dvr", "tf": tf, "dvr": sc.DVRSettings(step=0.5)}),
    ]
    for extra, kwargs in runs:
        png = tmp_path / "x.png"
        code, _, err = _run(["render", SRC, "--model", model, "--size", "14x12", "--quiet",
                             "--fit", "box", "-o", str(png), *extra], capsys)
        assert code == 0, err
        frame = scene.render(cam, **kwargs)
        np.testing.assert_array_equal(np.asarray(Image.open(png)), frame.to_uint8(),
                                      err_msg=f"{model} {extra}")
