"""`splinecast warmup` compiles ahead of use what a later command then loads without compiling.

Run with an empty kernel cache of its own (``NUMBA_CACHE_DIR`` in a temporary folder), so that
what is compiled is only what the commands here compile.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from splinecast.cli import main


def _cli(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "splinecast.cli", *args], capture_output=True,
                          text=True, env=env, timeout=1800)


def test_a_warmed_mode_renders_without_compiling(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    image = tmp_path / "mip.png"
    command = ["render", "demo:marschner-lobb?size=20", "--mode", "mip", "--size", "40x30",
               "-o", str(image)]
    warm = _cli("warmup", "--models", "trilinear", "--modes", "mip", "--jobs", "1", env=env)
    assert warm.returncode == 0, warm.stderr
    assert "[1/1] trilinear / mip, float32: compiled in" in warm.stderr, warm.stderr
    again = _cli("warmup", "--models", "trilinear", "--modes", "mip", "--jobs", "1", env=env)
    assert "[1/1] trilinear / mip, float32: cached" in again.stderr, again.stderr
    # The real command on other data, another size, antialiased: nothing left to compile.
    done = _cli(*command, env=env)
    assert done.returncode == 0, done.stderr
    assert "compil" not in done.stderr and image.exists(), done.stderr


@pytest.mark.parametrize(("args", "words"), [
    (["--models", "trilinear,nope"], "--models: nope is not one of"),
    (["--modes", "iso,volume"], "--modes: volume is not one of"),
    (["--dtypes", "float16"], "--dtypes: float16 is not one of"),
    (["--jobs", "0"], "--jobs must be at least 1"),
])
def test_warmup_mistakes_are_one_line_and_status_2(args, words, capsys):
    assert main(["warmup", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
