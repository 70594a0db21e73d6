"""``benchmarks/tools/sample_breakdown.py``: its probes fit the fixed-step loop's current source,
and the instrumented band renders the same image as the real one with each phase's cycles
inside the ray's."""

from __future__ import annotations

import inspect
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.render import driver, sampler

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "tools"))
import sample_breakdown as sb  # noqa: E402


def _source() -> str:
    return textwrap.dedent(inspect.getsource(sampler.sample_pixel.py_func))


@pytest.mark.parametrize("phase", sorted(sb._PASSES))
def test_the_probes_fit_the_fixed_step_loop(phase):
    """Every anchor occurs once (a loop change that moves one fails here, not in a developer's
    run), and the instrumented source is valid Python returning the phase's counts."""
    text = sb.instrumented_source(_source(), phase)
    compile(text, "<test>", "exec")
    # Two reads per probe pair, one at the ray's start and one at its end.
    assert text.count("_rdtsc()") == len(sb._PASSES[phase]) + 2
    assert "return _ph, _rdtsc() - _c0, evaluated" in text


def test_the_shared_source_guards_every_probe():
    """The band the three passes share: every phase's probes, each under a test of its pass's
    number (read once per ray), and the phase's sum returned."""
    text = sb.instrumented_source(_source(), None)
    compile(text, "<test>", "exec")
    probes = sum(len(p) for p in sb._PASSES.values())
    assert text.count("_rdtsc()") == probes + 2
    assert text.count("_phase = _selected()") == 1
    for number, phase in enumerate(sb._ORDER):
        assert text.count(f"if _phase == {number}:") == len(sb._PASSES[phase])
    assert "return _ph, _rdtsc() - _c0, evaluated" in text


def test_a_missing_anchor_is_named():
    source = _source().replace("                if not known:\n", "                if 1:\n")
    with pytest.raises(ValueError, match="if not known"):
        sb.instrumented_source(source, "skip")


@pytest.mark.parametrize("phase", sorted(sb._PASSES))
def test_the_instrumented_band_renders_the_real_image(monkeypatch, phase):
    """Default DVR of a small Marschner-Lobb volume: the colours are the real kernel's, every
    traced ray has a positive whole, and the phase fits in it."""
    vol = sc.demo("marschner-lobb", size=24)
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(40, 30))
    tf = sc.auto_transfer_function(vol)
    real = scene.render(cam, mode="dvr", tf=tf)
    key = next(k for k in driver._KERNELS if k[1].__name__ == "DvrRayMode"
               and k[0] is type(scene.grid.kernel))
    monkeypatch.setitem(driver._KERNELS, key, driver._KERNELS[key])  # restored afterwards
    sb.install(*key, phase)
    frame = scene.render(cam, mode="dvr", tf=tf)
    np.testing.assert_array_equal(frame.rgba, real.rgba)
    part, whole = frame.cells_visited, frame.cells_tested
    traced = (real.cells_visited + real.blocks_skipped) > 0
    assert traced.sum() > 100
    assert np.all(whole[traced] > 0)
    assert np.all((part[traced] >= 0) & (part[traced] < whole[traced]))
    assert part[traced].sum() > 0
