"""Direct volume rendering against a dense emission-absorption integral along the same rays.

The reference (``reference.dense_dvr``) samples the trilinear interpolant (``reference.trilinear``,
lerp form) every ``ds`` voxels and integrates optical depth and emitted colour with the trapezoid
rule; the transfer function is evaluated there from the control points written in this file with
``np.interp``, not through ``TransferFunction``, its tables or the renderer's sampling code.

Metric: the largest error over the visible pixels (reference opacity >= 1/255), per RGB channel,
premultiplied over black -- the docs' "within 1/255". Tolerance: 1/255 minus the reference's
own error bound ``ref_err``, the largest change of the reference when its step is doubled (the
trapezoid rule is second order, so its error is about a third of that change); ``ref_err`` is
asserted to stay below 0.1/255.

What holds (docs/accuracy.rst): with 2D pre-integration the largest error is within
1/255 at ``step=0.25`` voxels for transfer functions whose opacity changes gradually over the
data, and at ``step=0.0625, table_size=1024`` for a thin band of high opacity; the default
``step=0.5`` does not reach 1/255 everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from evaluators import model_evaluator
from pairs import MODELS_FOR_MODE
from reference import dense_dvr

import splinecast as sc

BLACK = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))
TARGET = 1 / 255

# Colour control points (position in the domain, r, g, b): a few points of viridis, and grey.
VIRIDIS = [(0.0, 0.267, 0.005, 0.329), (0.5, 0.128, 0.567, 0.551), (1.0, 0.993, 0.906, 0.144)]
GREY = [(0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0)]


@dataclass
class Case:
    """A volume, camera and transfer function (as control points) with its dense reference."""

    volume: sc.Volume
    camera: sc.Camera
    opacity: list
    colors: list
    domain: tuple
    ds: float
    ref: np.ndarray = None
    alpha: np.ndarray = None
    ref_err: float = None

    def __post_init__(self):
        W, U = self.camera.rays()
        args = (self.volume.data, self.volume.spacing, self.volume.origin, W, U, self.opacity,
                self.colors, self.domain)
        self.ref, self.alpha = dense_dvr(*args, ds=self.ds)
        coarse, _ = dense_dvr(*args, ds=2 * self.ds)
        self.ref_err = float(np.abs(coarse - self.ref).max())

    @property
    def tf(self) -> sc.TransferFunction:
        return sc.TransferFunction(self.opacity, domain=self.domain, colormap=self.colors)

    @property
    def visible(self) -> np.ndarray:
        return self.alpha >= TARGET

    def error(self, frame: sc.Frame) -> float:
        """Largest error over the visible pixels."""
        return float(np.abs(frame.rgba[..., :3] - self.ref)[self.visible].max())

    def render(self, scene: sc.Scene, **settings) -> sc.Frame:
        return scene.render(self.camera, mode="dvr", tf=self.tf, shading=BLACK,
                            dvr=sc.DVRSettings(**settings))


def _ml_ramp():
    # The comparison benchmark's transfer function: a shell around the isovalue 0.5 and a denser
    # core (benchmarks/compare/methods.py, dvr_transfer), grey.
    vol = sc.demo("marschner-lobb", size=24)
    lo, hi = vol.value_range
    span = hi - lo
    opacity = [(lo, 0.0), (0.5 - 0.05 * span, 0.0), (0.5 + 0.05 * span, 0.15), (hi, 0.6)]
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(20, 15), zoom=1.6)
    return Case(vol, cam, opacity, GREY, (lo, hi), ds=0.01)


def _noise_ramp():
    vol = sc.demo("noise", size=16)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=30, size=(20, 15))
    return Case(vol, cam, [(0.3, 0.0), (0.6, 0.6), (1.0, 0.8)], VIRIDIS, (0.0, 1.0), ds=0.01)


def _noise_band():
    # A thin, nearly opaque band: 0.06 of the data range wide, opacity 0.9 per voxel at its peak.
    vol = sc.demo("noise", size=16)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=30, size=(16, 12))
    return Case(vol, cam, [(0.47, 0.0), (0.5, 0.9), (0.53, 0.0)], VIRIDIS, (0.0, 1.0), ds=0.002)


@pytest.fixture(scope="module")
def cases():
    return {"ml-ramp": _ml_ramp(), "noise-ramp": _noise_ramp(), "noise-band": _noise_band()}


@pytest.fixture(scope="module")
def scenes(cases):
    return {name: sc.Scene(case.volume) for name, case in cases.items()}


def test_reference_is_converged_and_sees_the_volume(cases):
    for name, case in cases.items():
        assert case.ref_err < 0.1 * TARGET, (name, case.ref_err * 255)
        assert case.visible.mean() > 0.25, name


# The docs' accuracy statement: (case, settings) where the largest error is within 1/255.
MEETS_TARGET = [
    ("ml-ramp", {"step": 0.25}),
    ("noise-ramp", {"step": 0.25}),
    ("noise-band", {"step": 0.0625, "table_size": 1024}),
]


@pytest.mark.parametrize("name, settings", MEETS_TARGET)
def test_largest_error_is_within_1_255(cases, scenes, name, settings):
    case = cases[name]
    err = case.error(case.render(scenes[name], **settings))
    assert err <= TARGET - case.ref_err, f"{name} {settings}: {err * 255:.3f}/255"


def test_default_step_does_not_reach_1_255_everywhere(cases, scenes):
    """Keeps the docs honest: it says the default step (0.5) can miss 1/255. If this fails,
    the default became more accurate: update docs/accuracy.rst's DVR sentence."""
    errors = {name: case.error(case.render(scenes[name])) for name, case in cases.items()
              if name != "noise-band"}
    assert max(errors.values()) > TARGET, {k: v * 255 for k, v in errors.items()}


def test_preintegration_is_second_order_and_plain_sampling_first_order(cases, scenes):
    case, scene = cases["noise-ramp"], scenes["noise-ramp"]
    # A 1024-value table: with the default 256 values the table's own interpolation error (about
    # 1e-4 here, summed over the segments a ray is cut into at every cell) is what remains at the
    # finest step, and the step's second order would not show.
    pre = [case.error(case.render(scene, step=h, table_size=1024)) for h in (0.25, 0.125, 0.0625)]
    plain = [case.error(case.render(scene, step=h, preintegration="none"))
             for h in (1.0, 0.25, 0.0625)]
    # Second order: halving the step divides the error by about 4 (3 allows for the kinks of
    # the transfer function and of the trilinear field between samples).
    assert pre[0] / pre[1] > 3 and pre[1] / pre[2] > 3, pre
    # First order (the back-sample rule): dividing the step by 4 divides the error by about 4.
    assert plain[0] / plain[1] > 3 and plain[1] / plain[2] > 3, plain
    # At a coarse step, pre-integration is far more accurate than plain sampling.
    for step in (1.0, 0.5):
        assert (case.error(case.render(scene, step=step))
                < 0.5 * case.error(case.render(scene, step=step, preintegration="none")))


def test_adaptive_step_takes_fewer_samples_and_stays_within_its_largest_step(cases, scenes):
    """The opacity-adaptive step lies between ``step`` and ``h_max``: fewer samples than the
    constant ``step``, and no larger an error than the constant ``h_max``."""
    case, scene = cases["noise-ramp"], scenes["noise-ramp"]
    const = case.render(scene, step=0.25, preintegration="3d")
    adapt = case.render(scene, step=0.25, preintegration="3d", adaptive=True, h_max=2.0,
                        exponent=1.0)
    coarse = case.render(scene, step=2.0, preintegration="3d")
    assert adapt.stats["mean_samples"] < 0.8 * const.stats["mean_samples"]
    assert case.error(const) <= case.error(adapt) <= case.error(coarse)


@pytest.mark.parametrize("layout", ["uniform", "exponential"])
def test_adaptive_step_converges_with_either_table_layout(cases, scenes, layout):
    case, scene = cases["noise-ramp"], scenes["noise-ramp"]
    errs = []
    for step in (1.0, 0.25, 0.0625):
        frame = case.render(scene, step=step, preintegration="3d", table_layout=layout,
                            adaptive=True, h_max=4 * step, exponent=1.0)
        assert frame.stats["table_layout"] == layout
        errs.append(case.error(frame))
    assert errs[0] > errs[1] > errs[2], errs
    # at 1/16 voxel the adaptive step (up to 1/4 voxel) meets the 1/255 target too
    assert errs[2] <= TARGET - case.ref_err, errs


@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["dvr"])
def test_clipped_dvr_integrates_only_the_kept_interval(cases, model_name):
    """Clip plane and crop box, per ray: the dense integral over the kept interval (two-sided:
    dropping kept material or keeping clipped material both move pixels by far more than the
    1/255 the settings reach)."""
    case = cases["noise-ramp"]
    vol, cam = case.volume, case.camera
    c, ext = vol.center, np.asarray(vol.extent)
    n = np.array([0.5, -0.7, 0.5]) / np.linalg.norm([0.5, -0.7, 0.5])
    plane = (*n, -float(n @ c))
    lo, hi = c - 0.35 * ext, c + 0.4 * ext
    crop = (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
    crop_planes = [row for a in range(3) for row in ((*np.eye(3)[a], -lo[a]),
                                                    (*(-np.eye(3)[a]), hi[a]))]
    W, U = cam.rays()
    scene = sc.Scene(vol, model=model_name)
    ev = model_evaluator(model_name, vol, scene)
    ref, alpha = dense_dvr(vol.data, vol.spacing, vol.origin, W, U, case.opacity, case.colors,
                           case.domain, ds=case.ds, planes=[plane, *crop_planes],
                           value=ev.value, box=(ev.lo, ev.hi))
    frame = scene.render(cam, mode="dvr", tf=case.tf, shading=BLACK,
                         dvr=sc.DVRSettings(step=0.25), clip=[plane], crop=crop)
    err = np.abs(frame.rgba[..., :3] - ref).max()  # every pixel, visible or not
    assert err <= TARGET - case.ref_err, err * 255
    assert np.abs(ref - case.ref).max() > 20 * TARGET  # the clipping matters


def test_exponential_settings_hold_powers_of_two():
    s = sc.DVRSettings(step=0.5, preintegration="3d", table_layout="exponential",
                       adaptive=True, h_max=4.0)
    assert s.table_steps == 4 and s.pi_mode == 3  # lengths 0.5, 1, 2, 4
    assert sc.DVRSettings(step=0.5, preintegration="3d", table_layout="exponential",
                          adaptive=True, h_max=3.9).table_steps == 3
    assert sc.DVRSettings(step=0.5, preintegration="3d", adaptive=True,
                          h_max=4.0).table_steps == 8
    with pytest.raises(sc.ParameterError, match="table_layout"):
        sc.DVRSettings(table_layout="log")


@pytest.mark.parametrize("threshold", [0.9, 0.99])
def test_early_termination_changes_pixels_by_at_most_the_remaining_transparency(cases, scenes,
                                                                                threshold):
    scene, cam = scenes["noise-ramp"], cases["noise-ramp"].camera
    tf = sc.TransferFunction([(0.2, 0.0), (0.6, 0.5), (1.0, 0.9)], domain=(0.0, 1.0),
                             colormap="bone")
    base = sc.DVRSettings(step=0.25, preintegration="2d")
    full = scene.render(cam, mode="dvr", tf=tf, dvr=base)
    cut = scene.render(cam, mode="dvr", tf=tf,
                       dvr=sc.DVRSettings(step=0.25, preintegration="2d", termination=threshold))
    diff = np.abs(full.rgba - cut.rgba).max()
    assert diff <= (1.0 - threshold) + 1e-6
    assert diff > 0.0  # some rays did stop early
    assert cut.stats["mean_samples"] < full.stats["mean_samples"]


def test_dvr_parameter_errors(cases, scenes):
    scene, cam = scenes["noise-ramp"], cases["noise-ramp"].camera
    with pytest.raises(sc.ParameterError, match="tf"):
        scene.render(cam, mode="dvr", tf="bone")
    # No tf: the automatic one (tests/test_defaults.py), not an error.
    np.testing.assert_array_equal(scene.render(cam, mode="dvr").rgba,
                                  scene.render(cam, mode="dvr",
                                               tf=sc.auto_transfer_function(
                                                   cases["noise-ramp"].volume)).rgba)
    with pytest.raises(sc.ParameterError, match="preintegration"):
        sc.DVRSettings(preintegration="4d")
    with pytest.raises(sc.ParameterError, match="termination"):
        sc.DVRSettings(termination=1.5)


def test_table_rgba_is_table_channel_to_the_last_bit():
    """The vector lookup of all four channels (the fixed-step loop's) gives exactly the values
    of the per-channel bilinear lookup, for float32 and float64 tables, with four channels and
    with the pieces sampling's fifth, at random points, on cell edges and at the table's top."""
    import numba

    from splinecast.preintegration import table_cell, table_channel, table_rgba

    @numba.njit
    def both(table, k, points):
        out = np.empty((points.shape[0], 2, 4))
        for p in range(points.shape[0]):
            cell = table_cell(table, points[p, 0], points[p, 1])
            out[p, 0, 0], out[p, 0, 1], out[p, 0, 2], out[p, 0, 3] = table_rgba(table, k, cell)
            for c in range(4):
                out[p, 1, c] = table_channel(table, k, cell, c)
        return out

    rng = np.random.default_rng(5)
    n = 64
    points = rng.uniform(0.0, n - 1.0, size=(4000, 2))
    points[:200] = np.round(points[:200])
    points[200:220] = n - 1.0
    for dtype in (np.float32, np.float64):
        for channels in (4, 5):
            table = rng.uniform(0.0, 1.0, size=(3, n, n, channels)).astype(dtype)
            for k in (0, 2):
                out = both(table, k, points)
                np.testing.assert_array_equal(out[:, 0], out[:, 1])
                # And against numpy's own bilinear of the table (an independent reference).
                u, v = points[:, 0], points[:, 1]
                i = np.minimum(u.astype(int), n - 2)
                j = np.minimum(v.astype(int), n - 2)
                fx, fy = (u - i)[:, None], (v - j)[:, None]
                t = table[k, ..., :4].astype(np.float64)
                ref = ((1 - fx) * (1 - fy) * t[i, j] + fx * (1 - fy) * t[i + 1, j]
                       + (1 - fx) * fy * t[i, j + 1] + fx * fy * t[i + 1, j + 1])
                np.testing.assert_allclose(out[:, 0], ref, rtol=1e-12, atol=1e-15)
