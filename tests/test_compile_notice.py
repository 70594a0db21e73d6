"""The command line says that a wait is a one-time kernel compile, and only then.

A kernel compiled here for the first time (a new function, so neither in memory nor in the
on-disk cache) must be announced with what it is for, followed by the time it took; a kernel
already compiled must announce nothing; a compile that lasts must show its elapsed time while it
runs. The real command, run against kernels the suite has compiled, must print no notice.
"""

from __future__ import annotations

import io
import subprocess
import sys
import threading

import numba
import numpy as np
import pytest

from splinecast._jit import reporting_compiles
from splinecast.cli import _compiling
from splinecast.cli._compiling import CompileNotice


class _Lines(io.StringIO):
    """A stream that sets an event when something matching ``needle`` was written."""

    def __init__(self, needle: str) -> None:
        super().__init__()
        self.needle = needle
        self.seen = threading.Event()

    def write(self, text: str) -> int:
        n = super().write(text)
        if self.needle in self.getvalue():
            self.seen.set()
        return n


def _fresh_kernel():
    """A function numba has never compiled (a new closure each time, no disk cache)."""
    offset = np.random.default_rng().integers(1 << 30)

    @numba.njit(cache=False)
    def kernel(x):
        return x * 2 + offset

    return kernel


def test_a_compile_is_announced_with_its_subject_and_its_time():
    kernel = _fresh_kernel()
    stream = io.StringIO()
    with CompileNotice("s31 / dvr, uint8 data", "s31", stream=stream) as notice:
        assert kernel(3) == 6 + kernel.py_func.__closure__[0].cell_contents
    text = stream.getvalue()
    assert text.startswith("compiling kernels for s31 / dvr, uint8 data (first use; about ")
    assert "compiled in" in text.splitlines()[-1]
    assert notice.compiled_s > 0


def test_a_kernel_already_compiled_announces_nothing():
    kernel = _fresh_kernel()
    kernel(1)  # compiled before the notice
    stream = io.StringIO()
    with CompileNotice("trilinear / iso, float32 data", "trilinear", stream=stream) as notice:
        kernel(2)
    assert stream.getvalue() == ""
    assert notice.compiled_s == 0.0


def test_quiet_prints_nothing_but_still_counts():
    kernel = _fresh_kernel()
    stream = io.StringIO()
    with CompileNotice("x", "trilinear", enabled=False, stream=stream) as notice:
        kernel(1)
    assert stream.getvalue() == "" and notice.compiled_s > 0


def test_a_long_compile_shows_its_elapsed_time_while_it_lasts(monkeypatch):
    """The elapsed-time line appears while a compile is under way (here one held open by
    hand: the start of an outermost compile reported, its end not yet)."""
    monkeypatch.setattr(_compiling, "QUIET_S", 0.0)
    stream = _Lines("compiling... ")
    notice = CompileNotice("bspline3 / mip, int16 data", "bspline3", stream=stream)
    with notice:
        notice._started("band")  # what the compile listener calls when a compile begins
        assert stream.seen.wait(timeout=60), stream.getvalue()
        notice._ended("band", 1.0)
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("compiling kernels for bspline3 / mip, int16 data")
    assert any(line.strip().startswith("compiling... ") for line in lines)
    assert lines[-1].startswith("compiled in")


def test_compiles_of_other_threads_are_not_reported():
    """The viewer compiles on its own threads: a notice reports its own thread's compiles."""
    seen = []
    kernel = _fresh_kernel()
    with reporting_compiles(lambda name: seen.append(name), lambda name, s: None):
        worker = threading.Thread(target=kernel, args=(1,))
        worker.start()
        worker.join()
    assert seen == []
    other = _fresh_kernel()
    with reporting_compiles(lambda name: seen.append(name), lambda name, s: None):
        other(1)
    assert seen and seen[0].endswith("kernel")


@pytest.mark.parametrize("source", ["volume", "pyramid"])
def test_the_command_says_nothing_of_compiling_when_its_kernels_are_cached(tmp_path, source):
    """Two runs of the real command: the second finds every kernel in the disk cache (the
    first may compile them, and then says so) and prints no notice. A pyramid drawn from
    bricks too: nothing it compiles (the typed lists of bricks included) is left out of the
    cache, or every run would compile it again."""
    out = tmp_path / "sphere.png"
    volume = "demo:sphere?size=16"
    if source == "pyramid":
        import splinecast as sc

        volume = str(tmp_path / "sphere.zarr")
        sc.build_pyramid(sc.demo("sphere", size=40), volume, brick=8, shard=16, progress=False)
    command = [sys.executable, "-m", "splinecast.cli", "render", volume,
               "--size", "24x20", "-o", str(out)]
    first = subprocess.run(command, capture_output=True, text=True, timeout=1800)
    assert first.returncode == 0, first.stderr
    if "compiling kernels for" in first.stderr:
        assert "compiled in" in first.stderr
    second = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr
    assert "compil" not in second.stderr, second.stderr
    assert out.exists()
