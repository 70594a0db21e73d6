"""``benchmarks/tools/cycle_breakdown.py``: its probes fit the driver's current source, the
instrumented band renders the same image as the real one with sensible cycle counts, and its
summary's arithmetic (checked on made-up counters with hand-computed means)."""

from __future__ import annotations

import inspect
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.render import driver

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "tools"))
import cycle_breakdown as cb  # noqa: E402


def _source() -> str:
    return textwrap.dedent(inspect.getsource(driver._trace_pixel.py_func))


@pytest.mark.parametrize("pass_name", sorted(cb.PASSES))
def test_the_probes_fit_the_drivers_pixel_loop(pass_name):
    """Every anchor occurs once in ``_trace_pixel`` (a driver change that moves one fails
    here, not in a developer's run), and the instrumented source is valid Python."""
    text = cb.instrumented_source(_source(), pass_name)
    compile(text, "<test>", "exec")
    # Reads at the ray's start, the set-up's end and the ray's end, and a pair around each
    # leap run, tested cell and the finish: 9 in the source.
    assert text.count("_rdtsc()") == 9
    assert f"return {cb._SLOTS[pass_name]}" in text


def test_a_missing_anchor_is_named():
    source = _source().replace("        open_i = open_j = open_k = -1\n", "")
    with pytest.raises(ValueError, match="open_i = open_j"):
        cb.instrumented_source(source, "A")


def test_the_instrumented_band_renders_the_real_image(monkeypatch):
    """Pass B's band (set-up, finish, whole) on a small torus: the colours are the real
    kernel's, every traced ray has a positive whole, and its set-up and finish fit in it."""
    vol = sc.demo("torus", size=24)
    iso = vol.metadata["default_iso"]
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(40, 30))
    real = scene.render(cam, iso=iso)
    key = next(k for k in driver._KERNELS if k[1].__name__ == "IsoMode"
               and k[0] is type(scene.grid.kernel))
    monkeypatch.setitem(driver._KERNELS, key, driver._KERNELS[key])  # restored afterwards
    cb.install_instrumented_band(*key, "B")
    frame = scene.render(cam, iso=iso)
    np.testing.assert_array_equal(frame.rgba, real.rgba)
    setup, finish, whole = frame.cells_visited, frame.cells_tested, frame.blocks_skipped
    traced = (real.cells_visited + real.blocks_skipped) > 0
    assert traced.sum() > 100
    assert np.all(whole[traced] > 0)
    assert np.all(setup[traced] + finish[traced] <= whole[traced])
    assert np.all(setup[traced] > 0)


def test_the_summary_averages_each_group_and_derives_the_rest():
    counts = {"visited": np.array([4, 2, 0]), "tested": np.array([2, 1, 0]),
              "leapt": np.array([3, 5, 0])}
    cycles = {"A": {"leaps": np.array([300, 100, 0]), "tests": np.array([200, 50, 0]),
                    "whole": np.array([1000, 600, 0])},
              "B": {"setup": np.array([100, 120, 0]), "finish": np.array([40, 20, 0]),
                    "whole": np.array([1010, 590, 0])}}
    groups = {"first": np.array([True, False, False]), "both": np.array([True, True, False]),
              "none": np.zeros(3, bool)}
    out = cb.summarize(counts, cycles, groups)
    assert set(out) == {"first", "both"}  # an empty group is left out
    assert out["first"]["rest"] == 1000 - 300 - 200 - 100 - 40
    both = out["both"]
    assert both["rays"] == 2 and both["visited"] == 3.0 and both["leaps"] == 200.0
    assert both["rest"] == 800 - 200 - 125 - 110 - 30
    assert both["whole_A"] == 800.0 and both["whole_B"] == 800.0
    info = {"scene": "s", "mode": "iso", "model": "trilinear", "size": "4x3", "command": "c",
            "machine": "m", "threads": 1, "ghz": 2.6, "probe": 20.0, "frame_ms": 1.0,
            "frame_a_ms": 1.5, "frame_b_ms": 1.6}
    text = cb.report(out, info)
    # Per event: leaps 200 / 4 leapt = 50; tests 125 / 1.5 tested = 83; rest 335 / 3 visited
    # = 112.
    assert "| both | 2 | 3.00 | 1.50 | 4.00 | 110 | 200 | 125 | 30 | 335 | 800 / 800 | 50 | 83 " \
           "| 112 |" in text
