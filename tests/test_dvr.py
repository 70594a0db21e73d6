"""Direct volume rendering against a dense numerical integration of the emission-absorption
integral along the same rays (``reference.trilinear`` sampled every 0.01 voxels, cumulative
trapezoid for the optical depth), written here from the definition."""

from __future__ import annotations

import numpy as np
import pytest
from reference import trilinear
from scipy.integrate import cumulative_trapezoid, trapezoid

import splinecast as sc

BLACK = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))


@pytest.fixture(scope="module")
def setup():
    vol = sc.demo("noise", size=16)
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=30, size=(12, 9))
    # A thin, nearly opaque band: coarse plain sampling steps over it.
    tf = sc.TransferFunction([(0.47, 0.0), (0.5, 0.9), (0.53, 0.0)], domain=(0.0, 1.0),
                             colormap="viridis")
    return vol, scene, cam, tf, _reference(vol, cam, tf)


def _reference(vol, cam, tf, dvox=0.01):
    origins, dirs = cam.rays()
    spacing, origin = np.asarray(vol.spacing), np.asarray(vol.origin)
    lo, hi = vol.bounds
    out = np.zeros((cam.height, cam.width, 3))
    for row in range(cam.height):
        for col in range(cam.width):
            o, u = origins[row, col], dirs[row, col]
            with np.errstate(divide="ignore"):
                ta, tb = (lo - o) / u, (hi - o) / u
            t0 = max(0.0, np.max(np.minimum(ta, tb)))
            t1 = np.min(np.maximum(ta, tb))
            if not t0 < t1:
                continue
            vox_per_world = np.linalg.norm(u / spacing)
            x = np.linspace(0.0, (t1 - t0) * vox_per_world,
                            int((t1 - t0) * vox_per_world / dvox) + 2)
            p = (o + np.multiply.outer(t0 + x / vox_per_world, u) - origin) / spacing
            v = trilinear(vol.data, p)
            tau = tf.extinction(v)
            trans = np.exp(-cumulative_trapezoid(tau, x, initial=0.0))
            c = tf.color(v)
            out[row, col] = [trapezoid(c[:, k] * tau * trans, x) for k in range(3)]
    return out


def _err(frame, ref):
    return float(np.abs(frame.rgba[..., :3] - ref).max())


def test_plain_sampling_converges_to_the_reference(setup):
    vol, scene, cam, tf, ref = setup
    errs = [_err(scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                              dvr=sc.DVRSettings(step=s, preintegration="none")), ref)
            for s in (1.0, 0.25, 0.0625)]
    # Plain sampling with the back-sample rule converges to first order in the step.
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < errs[0] / 10 and errs[2] < 0.05


def test_preintegration_beats_plain_sampling_at_a_coarse_step(setup):
    vol, scene, cam, tf, ref = setup
    for step in (1.0, 0.5):
        plain = _err(scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                                  dvr=sc.DVRSettings(step=step, preintegration="none")), ref)
        pre = _err(scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                                dvr=sc.DVRSettings(step=step, preintegration="2d",
                                                   table_size=512)), ref)
        assert pre < 0.5 * plain
    fine = scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                        dvr=sc.DVRSettings(step=0.125, preintegration="2d", table_size=512))
    assert _err(fine, ref) < 0.01


def test_adaptive_step_with_3d_table_stays_close_and_takes_fewer_samples(setup):
    vol, scene, cam, _, _ = setup
    tf = sc.TransferFunction([(0.3, 0.0), (0.6, 0.6), (1.0, 0.8)], domain=(0.0, 1.0))
    ref = _reference(vol, cam, tf)
    const = scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                         dvr=sc.DVRSettings(step=0.25, preintegration="3d"))
    adapt = scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                         dvr=sc.DVRSettings(step=0.25, preintegration="3d", adaptive=True,
                                            h_max=2.0, exponent=1.0))
    assert adapt.stats["mean_samples"] < 0.8 * const.stats["mean_samples"]
    assert _err(const, ref) < 0.01
    assert _err(adapt, ref) < 0.05


def test_adaptive_step_with_the_exponential_table_converges_like_the_uniform_one(setup):
    vol, scene, cam, _, _ = setup
    tf = sc.TransferFunction([(0.3, 0.0), (0.6, 0.6), (1.0, 0.8)], domain=(0.0, 1.0))
    ref = _reference(vol, cam, tf)
    errs = {}
    for layout in ("uniform", "exponential"):
        errs[layout] = []
        for step in (1.0, 0.25, 0.0625):
            settings = sc.DVRSettings(step=step, preintegration="3d", table_layout=layout,
                                      adaptive=True, h_max=4 * step, exponent=1.0)
            frame = scene.render(cam, mode="dvr", tf=tf, shading=BLACK, dvr=settings)
            assert frame.stats["table_layout"] == layout
            errs[layout].append(_err(frame, ref))
    for layout, e in errs.items():
        assert e[0] > e[1] > e[2], (layout, e)
        assert e[2] < 0.01 and e[2] < e[0] / 5, (layout, e)
    # The exponential table only holds the lengths 1, 2, 4 steps, so its adaptive step is
    # coarser at times, but it converges at the same rate.
    assert errs["exponential"][2] < 2.0 * errs["uniform"][2] + 1e-3


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


@pytest.mark.parametrize("pre", ["none", "2d", "3d"])
def test_leaping_between_samples_keeps_the_image_where_samples_are_the_same(setup, pre):
    vol, scene, cam, _, _ = setup
    # Visible everywhere: no cell is transparent, so both walks take the same samples.
    tf = sc.TransferFunction([(0.0, 0.02), (0.5, 0.3), (1.0, 0.6)], domain=(0.0, 1.0),
                             colormap="viridis")
    cams = [cam, sc.Camera.orbit(vol, azimuth=90, elevation=0, size=(12, 9)),
            sc.Camera.orbit(vol, azimuth=-140, elevation=-35, size=(12, 9))]
    for c in cams:
        for clip in (None, [(-1.0, 0.3, 0.2, 0.0)]):
            frames = [scene.render(c, mode="dvr", tf=tf, clip=clip,
                                   dvr=sc.DVRSettings(step=0.25, preintegration=pre,
                                                      adaptive=True, h_max=4.0, exponent=1.0,
                                                      leap=leap))
                      for leap in (False, True)]
            walk, leapt = frames
            np.testing.assert_allclose(leapt.rgba, walk.rgba, atol=1e-6)
            np.testing.assert_allclose(leapt.depth, walk.depth, atol=1e-6)
            assert leapt.stats["mean_samples"] == walk.stats["mean_samples"]
            assert leapt.stats["mean_cells_visited"] < 0.8 * walk.stats["mean_cells_visited"]


def test_leaping_over_transparent_cells_stays_close(setup):
    vol, scene, cam, _, _ = setup
    tf = sc.TransferFunction([(0.3, 0.0), (0.6, 0.6), (1.0, 0.8)], domain=(0.0, 1.0))
    ref = _reference(vol, cam, tf)
    frames = [scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                           dvr=sc.DVRSettings(step=0.25, preintegration="3d", adaptive=True,
                                              h_max=2.0, exponent=1.0, leap=leap))
              for leap in (False, True)]
    assert frames[1].stats["mean_cells_visited"] < frames[0].stats["mean_cells_visited"]
    for frame in frames:
        assert _err(frame, ref) < 0.05


@pytest.mark.parametrize("threshold", [0.9, 0.99])
def test_early_termination_changes_pixels_by_at_most_the_remaining_transparency(setup,
                                                                                threshold):
    vol, scene, cam, _, _ = setup
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


def test_dvr_parameter_errors(setup):
    vol, scene, cam, tf, _ = setup
    with pytest.raises(sc.ParameterError, match="tf"):
        scene.render(cam, mode="dvr", tf="bone")
    # No tf: the automatic one (tests/test_defaults.py), not an error.
    np.testing.assert_array_equal(scene.render(cam, mode="dvr").rgba,
                                  scene.render(cam, mode="dvr",
                                               tf=sc.auto_transfer_function(vol)).rgba)
    with pytest.raises(sc.ParameterError, match="preintegration"):
        sc.DVRSettings(preintegration="4d")
    with pytest.raises(sc.ParameterError, match="termination"):
        sc.DVRSettings(termination=1.5)
