"""The comparison suite (benchmarks/compare, issue 6): methods run, metrics are right.

No timing is asserted. VTK-based checks need the ``bench`` extra and an offscreen OpenGL context
(EGL or OSMesa, from scripts/install_bench.sh); without them they skip with the reason.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.compare import methods as M  # noqa: E402
from benchmarks.compare import metrics, reference, runner, scenes  # noqa: E402
from benchmarks.compare.__main__ import run  # noqa: E402

SIZE = (128, 128)


def _vtk_or_skip() -> None:
    status = M.vtk_status()
    if not status["available"]:
        pytest.skip(status["reason"])


@pytest.fixture(scope="module")
def sphere() -> tuple[scenes.SceneSpec, sc.Volume, sc.Camera]:
    spec = scenes.sdf("sphere", 64)
    vol = spec.make()
    return spec, vol, sc.Camera.orbit(vol, azimuth=30, elevation=20, size=SIZE)


def _analytic_sphere_depth(cam: sc.Camera, radius: float) -> np.ndarray:
    """First intersection of each pixel ray with the sphere |p| = radius (inf on a miss)."""
    o, d = cam.rays()
    b = np.sum(o * d, axis=-1)
    c = np.sum(o * o, axis=-1) - radius**2
    disc = b * b - c
    t = -b - np.sqrt(np.where(disc >= 0, disc, 0.0))
    return np.where(disc >= 0, t, np.inf)


# --------------------------------------------------------------------------- metrics, no VTK

def test_metrics_zero_on_the_exact_surface_and_the_shift_when_shifted(sphere):
    spec, vol, cam = sphere
    radius = 0.6
    depth = _analytic_sphere_depth(cam, radius)
    o, d = cam.rays()
    normals = o + depth[..., None] * d  # radial = exact outward normal
    voxel = vol.spacing[0]
    exact = metrics.surface_quality(depth, normals, cam, spec.truth, 0.0, voxel).summary()
    assert exact["hits"] > 1000
    assert exact["position_voxels_max"] < 1e-9
    assert exact["normal_degrees_max"] < 1e-5
    # A sphere rendered 0.3 voxel too large: every hit is 0.3 voxel from the exact surface.
    shifted = _analytic_sphere_depth(cam, radius + 0.3 * voxel)
    normals = o + np.where(np.isfinite(shifted), shifted, 0)[..., None] * d
    q = metrics.surface_quality(shifted, normals, cam, spec.truth, 0.0, voxel).summary()
    assert q["position_voxels_mean"] == pytest.approx(0.3, abs=1e-6)
    assert q["position_voxels_max"] == pytest.approx(0.3, abs=1e-6)


def test_zbuffer_conversion_inverts_the_projection(sphere):
    _, _, cam = sphere
    near, far = 2.0, 9.0
    depth = _analytic_sphere_depth(cam, 0.6)
    _, d = cam.rays()
    eye_z = depth * (d @ cam.forward)
    # OpenGL perspective depth of eye distance z: zb = (1 + (f + n)/(f - n) - 2fn/((f - n) z)) / 2.
    zn = (far + near) / (far - near) - 2 * far * near / ((far - near) * eye_z)
    zb = np.where(np.isfinite(depth), 0.5 * (zn + 1), 1.0)
    back = metrics.zbuffer_to_depth(zb, cam, near, far)
    hit = np.isfinite(depth)
    assert np.array_equal(np.isfinite(back), hit)
    np.testing.assert_allclose(back[hit], depth[hit], rtol=1e-12)


def test_mesh_normal_interpolation_is_barycentric():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5.0]])
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    vnormals = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [9, 9, 9], [9, 9, 9], [9, 9, 9.0]])
    points = np.array([[0.25, 0.25, 0.0], [0.0, 0.0, 0.0], [1 / 3, 1 / 3, 0]])
    n = metrics.mesh_normals_at(points, verts, tris, vnormals, candidates=2)
    np.testing.assert_allclose(n, [[0.5, 0.25, 0.25], [1, 0, 0], [1 / 3, 1 / 3, 1 / 3]])


# --------------------------------------------------------------------------- methods

def test_splinecast_needs_no_extra_and_meets_the_analytic_sphere(sphere):
    spec, vol, cam = sphere
    method = M.SplinecastIso(vol, SIZE)
    method.new_iso(0.0, cam)
    depth, normals = method.surface(cam)
    q = metrics.surface_quality(depth, normals, cam, spec.truth, 0.0, vol.spacing[0]).summary()
    # Trilinear interpolation of a sampled distance field: well within a tenth of a voxel.
    assert q["hits"] > 1000
    assert q["position_voxels_max"] < 0.05
    assert q["normal_degrees_max"] < 5.0


@pytest.mark.parametrize("key", ["splinecast-s31", "splinecast-bspline3"])
def test_higher_order_splinecast_methods_meet_the_analytic_sphere(sphere, key):
    spec, vol, cam = sphere
    method = M.ISO_METHODS[key](vol, SIZE)
    method.new_iso(0.0, cam)
    depth, normals = method.surface(cam)
    exact = _analytic_sphere_depth(cam, 0.6)
    assert np.count_nonzero(np.isfinite(depth) != np.isfinite(exact)) < 0.01 * depth.size
    q = metrics.surface_quality(depth, normals, cam, spec.truth, 0.0, vol.spacing[0]).summary()
    # Smooth models of a sampled distance field: within a twentieth of a voxel, normals within
    # a degree.
    assert q["hits"] > 1000
    assert q["position_voxels_max"] < 0.05
    assert q["normal_degrees_max"] < 1.0


@pytest.mark.parametrize("key", ["vtk-flying-edges", "vtk-marching-cubes", "skimage-mc",
                                 "vtk-flying-edges-smoothed"])
def test_mesh_methods_render_the_sphere_where_it_is(sphere, key):
    _vtk_or_skip()
    if M.iso_requirements(key):
        pytest.skip(M.iso_requirements(key))
    spec, vol, cam = sphere
    method = M.ISO_METHODS[key](vol, SIZE)
    try:
        method.new_iso(0.0, cam)
        rgba = method.win.render(cam)
        assert rgba.shape == (SIZE[1], SIZE[0], 4) and rgba[..., :3].max() > 0
        depth, normals = method.surface(cam)
    finally:
        method.close()
    exact = _analytic_sphere_depth(cam, 0.6)
    # Coverage agrees with the analytic sphere except on silhouette pixels.
    assert np.count_nonzero(np.isfinite(depth) != np.isfinite(exact)) < 0.01 * depth.size
    q = metrics.surface_quality(depth, normals, cam, spec.truth, 0.0, vol.spacing[0]).summary()
    assert q["position_voxels_max"] < 0.05
    assert q["normal_degrees_p95"] < 3.0


def test_the_floor_is_timed_next_to_every_steady_frame():
    spec = scenes.sdf("sphere", 32)
    r = runner.run_iso_scene(spec, [(64, 48)], ["splinecast"], 2, None, log=lambda *_: None)
    entry = r["sizes"][0]
    assert len(entry["floor_runs_ms"]) == entry["repeats"] == 2
    assert entry["floor_ms"] == np.median(entry["floor_runs_ms"]) > 0.0


def test_exact_sphere_mesh_from_vtk_gives_near_zero_error_and_a_shift_gives_the_shift(sphere):
    """A finely tessellated sphere, rasterized by VTK and read back through the z-buffer."""
    _vtk_or_skip()
    from vtkmodules.vtkFiltersSources import vtkSphereSource
    from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper

    spec, vol, cam = sphere
    voxel = vol.spacing[0]
    for radius, expected in ((0.6, 0.0), (0.6 + 0.5 * voxel, 0.5)):
        source = vtkSphereSource()
        source.SetRadius(radius)
        source.SetThetaResolution(720)
        source.SetPhiResolution(360)
        win = M.VtkWindow(SIZE)
        mapper = vtkPolyDataMapper()
        mapper.SetInputConnection(source.GetOutputPort())
        actor = vtkActor()
        actor.SetMapper(mapper)
        win.renderer.AddActor(actor)
        try:
            depth = win.depth(cam)
        finally:
            win.close()
        o, d = cam.rays()
        normals = o + np.where(np.isfinite(depth), depth, 0)[..., None] * d
        q = metrics.surface_quality(depth, normals, cam, spec.truth, 0.0, voxel).summary()
        assert q["hits"] > 1000
        # Chords of a 720x360 tessellation sag by < 1e-4 voxel; 24-bit depth adds ~1e-5.
        assert q["position_voxels_mean"] == pytest.approx(expected, abs=2e-3)
        assert q["position_voxels_max"] == pytest.approx(expected, abs=1e-2)


def test_splinecast_mip_rows_meet_the_dense_reference():
    """The exact MIP within 1e-3 of the reference (itself dense sampling), the sampled methods
    and the exact one with a tolerance coarser but converging to it; those rows take part in
    MIP only."""
    vol = sc.demo("marschner-lobb", size=32)
    cam = sc.Camera.orbit(vol, size=(64, 48))
    ref = runner.reference_mip(vol, cam)
    exact = M.SplinecastVolume(vol, (64, 48), "mip", 0.5, 0.0).image(cam)
    assert reference.image_error(exact, ref) < 1e-3
    for key in ("splinecast-sampled", "splinecast-slices", "splinecast-tolerance"):
        errors = [reference.image_error(M.VOLUME_METHODS[key](
            vol, (64, 48), "mip", 0.5, step).image(cam), ref) for step in (4.0, 1.0, 0.125)]
        assert errors[0] > errors[1] > errors[2] and errors[2] < 2e-3, key
        assert key in M.volume_keys("mip")
        assert key not in M.volume_keys("dvr")


def test_vtk_mip_matches_the_dense_reference():
    _vtk_or_skip()
    vol = sc.demo("marschner-lobb", size=32)
    cam = sc.Camera.orbit(vol, size=(64, 48))
    ref = runner.reference_mip(vol, cam)
    method = M.VtkVolume(vol, (64, 48), "mip", 0.5, 0.25, "fixed-point")
    try:
        img = method.image(cam)
    finally:
        method.close()
    assert img.shape == ref.shape
    assert np.mean(np.abs(img - ref)) < 0.02


@pytest.fixture(scope="module")
def dvr_case() -> tuple[sc.Volume, float, sc.Camera, np.ndarray]:
    spec = scenes.ml(32)
    vol = spec.make()
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(64, 48))
    ref = reference.reference_dvr(vol, cam, M.dvr_transfer(vol, spec.isos[0]))
    return vol, spec.isos[0], cam, ref


def test_dvr_image_error_is_zero_on_itself_and_the_offset_when_offset(dvr_case):
    _, _, _, ref = dvr_case
    assert ref.shape == (48, 64, 3)
    assert 0.0 < ref.mean() < 1.0 and ref.min() >= 0.0 and ref.max() <= 1.0
    assert reference.image_error(ref, ref) == 0.0
    assert reference.image_error(ref + 0.01, ref) == pytest.approx(0.01, abs=1e-12)
    bumped = ref.copy()
    bumped[..., 0] += 0.03  # one channel of three: a third of it on average
    assert reference.image_error(bumped, ref) == pytest.approx(0.01, abs=1e-12)
    with pytest.raises(ValueError):
        reference.image_error(ref[:-1], ref)


def test_dvr_reference_does_not_depend_on_its_step(dvr_case):
    """Opacity per one-voxel slab, corrected as 1 - (1 - a)^h: halving the step barely moves it."""
    vol, iso, cam, ref = dvr_case
    coarse = reference.reference_dvr(vol, cam, M.dvr_transfer(vol, iso), step=0.125)
    assert reference.image_error(coarse, ref) < 1e-3


def test_splinecast_dvr_meets_the_dense_reference(dvr_case):
    vol, iso, cam, ref = dvr_case
    if M.volume_requirements("splinecast", "dvr"):
        pytest.skip(M.volume_requirements("splinecast", "dvr"))
    for step, bound in ((0.0, 1 / 255), (0.125, 1 / 255)):
        img = M.SplinecastVolume(vol, (64, 48), "dvr", iso, step).image(cam)
        assert reference.image_error(img, ref) < bound


def test_vtk_dvr_matches_the_dense_reference(dvr_case):
    _vtk_or_skip()
    vol, iso, cam, ref = dvr_case
    method = M.VtkVolume(vol, (64, 48), "dvr", iso, 0.25, "gpu")
    try:
        img = method.image(cam)
    finally:
        method.close()
    assert reference.image_error(img, ref) < 0.02


def test_dense_transfers_make_what_they_say_visible():
    """"every voxel": opacity above 0 for every value above the lowest; "automatic": the
    opacity splinecast's automatic transfer function gives, value for value."""
    vol = sc.demo("marschner-lobb", size=32)
    lo, hi = vol.value_range
    dense = M.dense_transfers(vol)
    values = np.linspace(lo, hi, 101)
    every = np.interp(values, *np.asarray(dense["every voxel"]).T)
    assert np.all(every[1:] > 0.0) and every[0] == 0.0
    pts = np.asarray(dense["automatic"]).T
    assert np.allclose(np.interp(values, *pts), sc.auto_transfer_function(vol).opacity(values))


def test_splinecast_dense_dvr_rows_meet_the_reference_and_the_termination_bound():
    """The dense rows' splinecast images: the defaults within 1/255 of the dense reference,
    and VTK's termination changes no channel by more than what it leaves out, 255/32768
    (the bound early termination gives: the rest of the ray carries at most 1 - A of light)."""
    spec = scenes.ml(32)
    vol = spec.make()
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(64, 48))
    transfer = M.dense_transfers(vol)["every voxel"]
    ref = reference.reference_dvr(vol, cam, transfer)
    default = M.SplinecastVolume(vol, (64, 48), "dvr", spec.isos[0], 0.0,
                                 transfer=transfer).image(cam)
    assert reference.image_error(default, ref) < 1.0 / 255.0
    # A volume of 32^3 holds too little of that opacity for rays to end (they stay below
    # 0.95): an opaque ramp ends them, and the bound applies to any transfer function.
    opaque = [(transfer[0][0], 0.0), (transfer[-1][0], 0.6)]
    default, early = (M.SplinecastVolume(vol, (64, 48), "dvr", spec.isos[0], 0.0,
                                         transfer=opaque, termination=t).image(cam)
                      for t in (None, M.VTK_FIXED_POINT_TERMINATION))
    gap = np.abs(early - default)
    assert gap.max() <= 1.0 - M.VTK_FIXED_POINT_TERMINATION + 1e-6
    assert gap.max() > 0.0  # the rays do end by opacity: the termination changed something


def test_dense_dvr_rows_time_each_method_and_report_the_ratio_to_vtk():
    _vtk_or_skip()
    result = runner.run_dense_dvr_scene(scenes.ml(32), (64, 48), 1, log=lambda *_: None)
    assert [t["transfer"] for t in result["transfers"]] == ["automatic", "every voxel"]
    for t in result["transfers"]:
        assert set(t["methods"]) == {k for k, _ in runner.DENSE_METHODS}
        vtk = t["methods"]["vtk-fixed-point"]
        for e in t["methods"].values():
            assert e["frame_ms"] > 0
            assert e["vtk_ms_over_ms"] == pytest.approx(vtk["frame_ms"] / e["frame_ms"])
        # VTK's caster classifies each sample (no pre-integration): a coarser picture, but
        # the same one (a wrong transfer function or colour would miss by far more).
        assert vtk["mean_abs_error"] < 0.02


def test_only_dense_merges_into_the_stored_results(tmp_path, monkeypatch):
    stored = {"command": "python -m benchmarks.compare --quick", "notes": ["kept note"],
              "iso": [], "volume": [{"scene": "kept", "mode": "dvr", "sizes": [],
                                     "quality": {}, "skipped": {}}],
              "memory": {}, "threads": {}, "vtk": {"available": False}, "machine": {}}
    (tmp_path / "compare_quick.json").write_text(json.dumps(stored))

    def fake(spec, size, repeats, log=print):
        return {"scene": spec.label, "mode": "dvr", "step": 1.0, "skipped": {},
                "termination": {"splinecast": 0.999, "vtk-fixed-point": 0.9922},
                "transfers": [{"transfer": "automatic", "width": 128, "height": 128,
                               "methods": {"splinecast": {"frame_ms": 5.0,
                                                          "mean_abs_error": 0.001,
                                                          "vtk_ms_over_ms": 2.0}}}]}

    monkeypatch.setattr(runner, "run_dense_dvr_scene", fake)
    run(quick=True, repeats=1, out=tmp_path, log=lambda *_: None, only_dense=True)
    saved = json.loads((tmp_path / "compare_quick.json").read_text())
    assert saved["volume"] == stored["volume"]
    assert [r["scene"] for r in saved["dense_dvr"]] == ["marschner-lobb 64^3"]
    text = (tmp_path / "compare_quick.md").read_text()
    assert ("| marschner-lobb 64^3 | automatic | 128x128 | splinecast, default settings | "
            "0.9990 | 0.0010 | 5 | 2.00 |") in text
    assert "kept note" in text


def test_only_volume_merges_into_the_stored_results(tmp_path, monkeypatch):
    stored = {"command": "python -m benchmarks.compare --quick", "notes": ["kept note"],
              "iso": [{"scene": "kept", "kind": "ml", "size": 64, "sizes": [], "methods": {},
                       "skipped": {}}],
              "volume": [{"scene": "old", "mode": "dvr", "sizes": [], "quality": {},
                          "skipped": {}}],
              "memory": {"kept": {"splinecast": {"peak_mib": 1.0, "increase_mib": 0.5}}},
              "threads": {"splinecast": {"threads": 1}, "splinecast dvr": {"threads": 1}},
              "vtk": {"available": False}, "machine": {}}
    (tmp_path / "compare_quick.json").write_text(json.dumps(stored))

    def fake(spec, mode, sizes, keys, repeats, log=print):
        return {"scene": spec.label, "mode": mode, "shape": [64] * 3, "skipped": {},
                "steps": {"splinecast": 1.0}, "tolerance": 1 / 255, "default_error": 0.001,
                "quality": {"splinecast": {"step": 1.0, "mean_abs_error": 0.002}},
                "sizes": [{"width": 128, "height": 128,
                           "methods": {"splinecast": {"frame_ms": 5.0, "runs_ms": [5.0]}}}],
                "threads": {"splinecast": {"threads": 2}}}

    monkeypatch.setattr(runner, "run_volume_scene", fake)
    results = run(quick=True, repeats=1, out=tmp_path, log=lambda *_: None, only_volume=True)
    saved = json.loads((tmp_path / "compare_quick.json").read_text())
    assert saved["iso"] == stored["iso"] and saved["memory"] == stored["memory"]
    assert [r["scene"] for r in saved["volume"]] == ["marschner-lobb 64^3"] * 2
    assert saved["threads"]["splinecast"] == {"threads": 1}
    assert saved["threads"]["splinecast dvr"] == {"threads": 2}
    assert "kept note" in results["notes"]
    text = (tmp_path / "compare_quick.md").read_text()
    assert "| marschner-lobb 64^3 | dvr | 128x128 | splinecast | 1.0 | 0.0020 | 5 |" in text


# --------------------------------------------------------------------------- the whole suite

def test_quick_suite_runs_every_method_and_writes_results(tmp_path):
    results = run(quick=True, repeats=1, out=tmp_path, memory=False, log=lambda *_: None)
    available = [k for k in M.ISO_METHODS if not M.iso_requirements(k)]
    assert "splinecast" in available
    for scene in results["iso"]:
        entry = scene["sizes"][0]
        assert set(entry["methods"]) == set(available)
        # Every method that ran also skipped nothing silently.
        assert set(entry["methods"]) | set(scene["skipped"]) == set(M.ISO_METHODS)
        for key in available:
            assert entry["methods"][key]["first_image_ms"] > 0
            assert scene["methods"][key]["quality"]["hits"] > 100
    saved = json.loads((tmp_path / "compare_quick.json").read_text())
    assert saved["machine"]["cores"] >= 1
    text = (tmp_path / "compare_quick.md").read_text()
    assert "splinecast exact" in text
    for mode in ("mip", "dvr"):
        if mode not in M.splinecast_modes():
            assert f"splinecast {mode.upper()} not available yet" in text


def test_without_the_extra_the_suite_says_what_it_skipped(tmp_path, monkeypatch):
    """Simulate a machine without VTK: splinecast still runs, the skips carry reasons."""
    reason = "VTK not installed (simulated); install the bench extra"
    monkeypatch.setattr(M, "vtk_status", lambda: {"available": False, "reason": reason})
    results = run(quick=True, repeats=1, out=tmp_path, memory=False, log=lambda *_: None)
    for scene in results["iso"]:
        assert set(scene["sizes"][0]["methods"]) == set(M.SPLINECAST_ISO)
        assert scene["skipped"]["vtk-flying-edges"] == reason
        assert "skimage-mc" in scene["skipped"]
    assert any(reason in note for note in results["notes"])
    assert reason in (tmp_path / "compare_quick.md").read_text()
