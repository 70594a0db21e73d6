"""The defaults that ``--help`` states are the ones the commands use.

Every option's help text is read from the real ``--help`` output of ``splinecast render``, ``view``
and ``movie``; the value after its first "default" is compared with the value the code uses: the
parser's default when it has one, else the value computed by the code path that fills the option
in (the model chosen without ``--model``, the viewer's initial isovalue, the shading colours, ...).
An option with a default that its help does not state fails, as does a stated default the code
does not use.
"""

from __future__ import annotations

import argparse
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import _build_parser, main
from splinecast.cli import movie as movie_cli
from splinecast.cli import render as render_cli
from splinecast.cli._common import derived_output
from splinecast.render.defaults import WINDOW_PERCENTILES, otsu_threshold, sample_values
from splinecast.viewer import data as viewer_data
from splinecast.viewer.state import default_state

_DEFAULT = re.compile(r"\bdefault:? ([^;)]*)")


def _subparser(command: str) -> argparse.ArgumentParser:
    parser = _build_parser()
    return parser._subparsers._group_actions[0].choices[command]


def _normalized(text: str) -> str:
    return " ".join(text.split())


def help_output(command: str, capsys) -> str:
    """The ``--help`` output, whitespace collapsed (printed unwrapped: lines as wide as the
    longest, so that no hyphenated word is broken)."""
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    return _normalized(capsys.readouterr().out)


def stated_defaults(command: str, capsys) -> dict[str, tuple[argparse.Action, str | None]]:
    """Option -> (its action, the text after the first "default" of its help, or None)."""
    sub = _subparser(command)
    shown = help_output(command, capsys)
    out = {}
    for action in sub._actions:
        long = [o for o in action.option_strings if o.startswith("--")]
        if not long or long[0] == "--help":
            continue
        text = _normalized(sub._get_formatter()._expand_help(action))
        assert text in shown, f"{command} {long[0]}: help text not in --help"
        match = _DEFAULT.search(text)
        out[long[0]] = (action, match.group(1).strip() if match else None)
    return out


def first(stated: str) -> str:
    """The stated default's first word, without a trailing comma or colon."""
    return stated.split()[0].rstrip(",:")


def numbers_text(values) -> str:
    return ",".join(f"{v:g}" for v in values)


def _small_volume() -> sc.Volume:
    rng = np.random.default_rng(4)
    data = np.zeros((16, 16, 16), np.uint8)
    data[4:12, 4:12, 4:12] = rng.integers(20, 200, (8, 8, 8))
    return sc.Volume(data)


def _signed_volume() -> sc.Volume:
    data = np.zeros((12, 12, 12), np.float32)
    data[2:6, 2:10, 2:10], data[6:10, 2:10, 2:10] = -2.0, 3.0
    return sc.Volume(data)


def _render_args(**given) -> argparse.Namespace:
    """``splinecast render`` arguments parsed with nothing but the file (and ``given``)."""
    args = _build_parser().parse_args(["render", "x.npy"])
    for key, value in given.items():
        setattr(args, key, value)
    return args


def _check_output(stated: str) -> None:
    assert stated.startswith("NAME.png, or NAME-MODE.png")
    assert derived_output("/data/NAME.nii.gz", "", ".png") == Path.cwd() / "NAME.png"
    assert derived_output("/data/NAME.nii.gz", "mip", ".png").name == "NAME-mip.png"


def _check_iso(stated: str) -> None:
    assert "Otsu's threshold of the non-background histogram" in stated
    vol = _small_volume()
    kwargs, _ = render_cli.mode_kwargs(_render_args(), vol)
    assert kwargs["iso"] == sc.auto_iso(vol) == otsu_threshold(sample_values(vol), integer=True)


def _check_view_iso(stated: str) -> None:
    assert "Otsu's threshold of the non-background histogram" in stated
    vol = _small_volume()
    assert default_state(vol)["iso"] == sc.auto_iso(vol)


def _check_model(stated: str) -> None:
    args = _render_args()
    render_cli.model_options(args)
    assert first(stated) == args.model == "trilinear"


def _check_view_model(stated: str) -> None:
    assert first(stated) == viewer_data.shown(_small_volume()).default_model == "trilinear"


def _check_finder_default(stated: str) -> None:
    assert stated in ("the model's", "the finder's")
    assert render_cli.model_options(_render_args()) == {}  # nothing passed: the model decides


def _check_step(stated: str) -> None:
    assert float(first(stated)) == render_cli.SAMPLED_STEP == render_cli.DVR_FALLBACK["step"]


def _check_inside(stated: str) -> None:
    assert "low for isovalues below the background value" in stated and stated.endswith("high")
    assert sc.auto_inside(_signed_volume(), -1.0) == "low"
    assert sc.auto_inside(_small_volume(), 100.0) == "high"


def _check_background(stated: str) -> None:
    assert first(stated) == numbers_text(sc.Shading().background[:3])
    assert sc.Shading().background[3] == 1.0


def _check_color(stated: str) -> None:
    assert first(stated) == numbers_text(sc.Shading().front_color)


def _check_colormap(stated: str) -> None:
    assert first(stated) == sc.auto_colormap(_small_volume()) == "gray"
    assert f"{sc.transfer.DIVERGING} for signed data" in stated
    assert sc.auto_colormap(_signed_volume()) == sc.transfer.DIVERGING


def _check_window(stated: str) -> None:
    assert "the {:g}th-{:g}th percentiles".format(*WINDOW_PERCENTILES) in stated
    vol = _small_volume()
    kwargs, _ = render_cli.mode_kwargs(_render_args(mode="mip"), vol)
    assert kwargs["window"] == sc.auto_window(vol, "mip")


def _check_preintegration(stated: str) -> None:
    assert first(stated) == render_cli.DVR_FALLBACK["preintegration"]


def _check_table_layout(stated: str) -> None:
    assert first(stated) == render_cli.DVR_FALLBACK["table_layout"]


def _check_budget(stated: str) -> None:
    assert first(stated) == render_cli.DEFAULT_BUDGET == viewer_data.DEFAULT_BUDGET


def _check_lod(stated: str) -> None:
    assert float(first(stated)) == render_cli.DEFAULT_LOD == viewer_data.DEFAULT_LOD


def _check_wavelet_lod(stated: str) -> None:
    assert stated == "one pixel's angle"


def _check_cut(stated: str) -> None:
    assert first(stated) == render_cli.DEFAULT_CUT


def _check_external(stated: str) -> None:
    assert first(stated) == "refused"
    assert not sc.errors.limits.allow_external_default() or pytest.skip("set in the environment")


def _check_samples(stated: str) -> None:
    from splinecast.render.antialias import DEFAULT_SAMPLES, resolve_samples
    assert first(stated) == str(DEFAULT_SAMPLES) == str(resolve_samples(None, "iso"))
    assert "1 = off for the other modes" in stated
    assert all(resolve_samples(None, mode) == 1 for mode in ("mip", "minip", "dvr"))


def _check_missing(stated: str) -> None:
    # What the error says is run in test_zarr_bounded.py (exit 2, one line naming the chunk, no
    # image); here the help's words for it.
    assert stated == "an error naming the chunk"


def _check_movie_output(stated: str) -> None:
    assert stated.startswith("NAME.mp4, or NAME-MODE.mp4")
    assert derived_output("demo:NAME?size=8", "", ".mp4").name == "NAME.mp4"


def _check_movie_azimuth(stated: str) -> None:
    start = movie_cli.DEFAULT_AZIMUTH
    assert stated.startswith(f"a full turn {start:g}:{start + 360:g}")
    assert stated.endswith(f"else {start:g}")


def _check_movie_elevation(stated: str) -> None:
    assert float(first(stated)) == movie_cli.DEFAULT_ELEVATION


def _check_first_volume(stated: str) -> None:
    from splinecast.io.selection import SeveralVolumesWarning, choose

    assert stated.startswith("the first, with a note")
    with pytest.warns(SeveralVolumesWarning):
        assert choose("f", "time point", 3, None, "timepoint") == 0


def _check_anon(stated: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Without --anon, access is anonymous exactly when no credentials are configured."""
    from splinecast.io import remote

    assert stated == "anonymous unless the environment or ~/.aws, gcloud give some"
    monkeypatch.setenv("HOME", str(tmp_path))
    for name in ("AWS_ACCESS_KEY_ID", "AWS_PROFILE", "AWS_WEB_IDENTITY_TOKEN_FILE",
                 "AWS_CONTAINER_CREDENTIALS_RELATIVE_URI", "AWS_CONTAINER_CREDENTIALS_FULL_URI",
                 "AWS_SHARED_CREDENTIALS_FILE", "AWS_CONFIG_FILE",
                 "GOOGLE_APPLICATION_CREDENTIALS"):
        monkeypatch.delenv(name, raising=False)
    assert not remote._credentials_configured("s3") and not remote._credentials_configured("gcs")
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "x")
    assert remote._credentials_configured("s3")
    monkeypatch.delenv("AWS_ACCESS_KEY_ID")
    (tmp_path / ".config" / "gcloud").mkdir(parents=True)
    (tmp_path / ".config" / "gcloud" / "application_default_credentials.json").write_text("{}")
    assert remote._credentials_configured("gcs")


def _check_cache_dir(stated: str) -> None:
    from splinecast.io import remote

    assert stated == "no disk cache"
    if not os.environ.get(remote.ENV_CACHE_DIR):
        assert remote.RemoteSettings.from_env().cache_dir is None


def _check_cache_size(stated: str) -> None:
    from splinecast.errors.limits import parse_bytes
    from splinecast.io import remote

    if not os.environ.get(remote.ENV_CACHE_SIZE):
        assert remote.RemoteSettings.from_env().cache_bytes == parse_bytes(first(stated))


def _two_labels(metadata=None) -> sc.Volume:
    data = np.zeros((8, 8, 8), np.uint8)
    data[1:4, 1:4, 1:4], data[5:7, 5:7, 5:7] = 2, 9
    return sc.Volume(data, metadata=metadata)


def _check_labels(stated: str) -> None:
    from splinecast.cli.labels import wants_labels

    assert stated.startswith("for OME-Zarr label images")
    args = argparse.Namespace(labels=None, file="x", quiet=True)
    assert wants_labels(args, _two_labels({"image_label": {}}))
    assert not wants_labels(args, _two_labels())  # never guessed from the voxels


def _check_show(stated: str) -> None:
    assert first(stated) == "all"
    assert sc.Scene(_two_labels(), labels=True).shown == (2, 9)


def _check_label_colors(stated: str) -> None:
    from splinecast.io.label_colors import palette_color

    assert stated.startswith("the store's image-label colours, else a palette")
    meta = {"image_label": {"colors": [{"label-value": 2, "rgba": [0, 0, 255, 255]}]}}
    scene = sc.Scene(_two_labels(meta), labels=True)
    assert scene.style(2).rgba == (0.0, 0.0, 1.0, 1.0)
    assert scene.style(9).rgba == palette_color(9)


def _check_label_opacity(stated: str) -> None:
    import inspect

    from splinecast.multires.scenes.labels import LabelScene

    assert float(first(stated)) == inspect.signature(LabelScene).parameters["opacity"].default


#: (command, option) -> check of the stated default against the code, for options whose parser
#: default is None (the code fills them in).
CODE_DEFAULTS: dict[tuple[str, str], Callable[[str], None]] = {
    ("render", "--output"): _check_output,
    ("render", "--iso"): _check_iso,
    ("render", "--model"): _check_model,
    ("render", "--root-finder"): _check_finder_default,
    ("render", "--iterations"): _check_finder_default,
    ("render", "--step"): _check_step,
    ("render", "--inside"): _check_inside,
    ("render", "--background"): _check_background,
    ("render", "--color"): _check_color,
    ("render", "--colormap"): _check_colormap,
    ("render", "--window"): _check_window,
    ("render", "--preintegration"): _check_preintegration,
    ("render", "--table-layout"): _check_table_layout,
    ("render", "--budget"): _check_budget,
    ("render", "--lod"): _check_lod,
    ("render", "--cut"): _check_cut,
    ("render", "--allow-external-data"): _check_external,
    ("render", "--allow-missing"): _check_missing,
    ("render", "--samples"): _check_samples,
    ("render", "--labels"): _check_labels,
    ("view", "--labels"): _check_labels,  # the same wants_labels decides
    ("render", "--show"): _check_show,
    ("render", "--label-colors"): _check_label_colors,
    ("view", "--label-colors"): _check_label_colors,
    ("render", "--label-opacity"): _check_label_opacity,
    ("view", "--model"): _check_view_model,
    ("view", "--iso"): _check_view_iso,
    ("view", "--budget"): _check_budget,
    ("view", "--lod"): _check_lod,
    ("view", "--allow-external-data"): _check_external,
    ("movie", "--output"): _check_movie_output,
    ("movie", "--azimuth"): _check_movie_azimuth,
    ("movie", "--elevation"): _check_movie_elevation,
    ("movie", "--iso"): _check_iso,
    ("movie", "--lod"): _check_wavelet_lod,
    ("movie", "--allow-external-data"): _check_external,
    ("movie", "--allow-missing"): _check_missing,
    **{(command, option): _check_first_volume for command in ("info", "render", "view", "movie")
       for option in ("--timepoint", "--channel")},
    **{(command, "--cache-dir"): _check_cache_dir for command in ("info", "render", "view",
                                                                  "movie")},
    **{(command, "--cache-size"): _check_cache_size for command in ("info", "render", "view",
                                                                    "movie")},
}
for _option in ("--model", "--root-finder", "--iterations", "--step", "--inside", "--background",
                "--color", "--colormap", "--window", "--preintegration", "--table-layout",
                "--samples"):
    CODE_DEFAULTS[("movie", _option)] = CODE_DEFAULTS[("render", _option)]


def _parser_default_text(default: object) -> str:
    return f"{default:g}" if isinstance(default, float) else str(default)


@pytest.mark.parametrize("command", ["render", "view", "movie"])
def test_help_states_the_defaults_the_code_uses(command, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("COLUMNS", "100000")  # argparse's width: no line breaks
    checked = 0
    for option, (action, stated) in stated_defaults(command, capsys).items():
        default = action.default
        has_default = default is not None and default is not False and not isinstance(
            default, list)
        if has_default:
            assert stated is not None, f"{command} {option}: --help does not state {default!r}"
            assert first(stated) == _parser_default_text(default), (command, option, stated)
        elif stated is not None:
            if option == "--anon":  # needs a home folder and environment of its own
                _check_anon(stated, monkeypatch, tmp_path)
                checked += 1
                continue
            check = CODE_DEFAULTS.get((command, option))
            assert check is not None, f"{command} {option}: states {stated!r}, not checked"
            check(stated)
        else:
            continue
        checked += 1
    assert checked >= {"render": 25, "view": 6, "movie": 22}[command]
