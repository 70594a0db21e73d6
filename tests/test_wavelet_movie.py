"""``splinecast movie`` of a spline-wavelet store (``--lod`` like ``render``).

Reference: each frame rendered on its own by a fresh ``Scene(store, lod=ε)`` (no bricks reused
from the frames before), against the movie's PNG frames, which come from one scene that reuses
its coarse bricks across frames.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import main
from splinecast.distributed import orbit_path

pytest.importorskip("zarr")
Image = pytest.importorskip("PIL.Image")

SIZE = (24, 20)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    grid = np.stack(np.meshgrid(*[np.arange(26.0)] * 3, indexing="ij"), -1)
    sphere = np.linalg.norm(grid - [12.3, 13.1, 11.7], axis=-1) - 8.0
    path = tmp_path_factory.mktemp("w") / "s.zarr"
    sc.build_pyramid(sc.Volume(sphere.astype(np.float32), metadata={"inside": "low"}), path,
                     kind="wavelet", degree=3, chunk=4, progress=False)
    return path


@pytest.mark.parametrize("lod", [0.0, 0.08])
def test_png_frames_equal_fresh_per_frame_renders(store, tmp_path, lod):
    out = tmp_path / "frames"
    assert main(["movie", str(store), "--frames", "3", "-o", f"{out}/", "--size",
                 f"{SIZE[0]}x{SIZE[1]}", "--iso", "0", "--lod", str(lod), "--quiet"]) == 0
    wv = sc.read(store)
    for i, cam in enumerate(orbit_path(wv, 3, size=SIZE)):
        want = sc.Scene(sc.read(store), lod=lod).render(cam, iso=0.0).to_uint8()
        got = np.asarray(Image.open(out / f"frame_{i:04d}.png"))
        assert (want[..., 3] > 0).any()
        np.testing.assert_array_equal(got, want[..., :got.shape[-1]])


@pytest.mark.parametrize("argv, message", [
    (["--lod=-1"], "--lod"),
    (["--lod", "0.1", "--smooth", "3"], "--smooth"),
    (["--model", "trilinear"], "bspline3"),
    (["--workers", "2"], "--workers"),
])
def test_mistakes_are_one_line_and_write_nothing(store, tmp_path, capsys, argv, message):
    out = tmp_path / "m.gif"
    assert main(["movie", str(store), "--frames", "2", "-o", str(out), "--size", "8x8",
                 "--quiet", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_lod_is_refused_for_other_volumes(tmp_path, capsys):
    out = tmp_path / "m.gif"
    assert main(["movie", "demo:sphere?size=8", "--frames", "2", "-o", str(out), "--lod",
                 "0.1", "--quiet"]) == 2
    assert "--lod applies to spline-wavelet stores only" in capsys.readouterr().err
    assert not out.exists()
