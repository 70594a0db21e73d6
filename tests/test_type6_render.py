"""Type-6 splines: isovalue-change classification and rendered first hits.

References: exhaustive dense evaluation of every patch (classification), dense sampling of the
directly evaluated spline along every ray (first hits), the analytic Marschner–Lobb gradient
(normals).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import main
from splinecast.io.synthetic import marschner_lobb_gradient
from splinecast.models.type6 import evaluate_in_tets
from splinecast.models.type6_geometry import tet_vertices

RNG = np.random.default_rng(99)


def _lattice(d):
    return np.array([mi for mi in itertools.product(range(d + 1), repeat=4) if sum(mi) == d],
                    dtype=float) / d


@pytest.mark.parametrize("model_name, opts", [("s31", {}), ("qss", {}),
                                              ("qss", {"variant": "qss-a"})])
def test_classification_is_conservative(model_name, opts):
    data = RNG.normal(size=(5, 4, 5))
    vol = sc.Volume(data)
    scene = sc.Scene(vol, model=model_name, **opts)
    model = scene.model
    lam = _lattice(8)
    verts = [np.array([[float(c) for c in v] for v in tet_vertices(t)]) for t in range(24)]
    cubes = np.array(list(itertools.product(*(range(n) for n in data.shape))))
    n_c, n_l = len(cubes), len(lam)
    all_cubes = np.repeat(np.repeat(cubes, 24, axis=0), n_l, axis=0)
    all_tets = np.tile(np.repeat(np.arange(24), n_l), n_c)
    all_q = np.tile(np.concatenate([lam @ v for v in verts]), (n_c, 1))
    vals, _ = evaluate_in_tets(model.pad, *model.tables_arrays, model.degree, all_cubes,
                               all_tets, all_q)
    vals = vals.reshape(n_c, 24, n_l)
    vmin, vmax = vals.min(axis=2), vals.max(axis=2)
    n_inactive = 0
    for iso in RNG.uniform(data.min(), data.max(), size=4):
        scene.set_iso(iso)
        act = scene.active_cells
        active = np.zeros((n_c, 24), bool)
        lin = np.ravel_multi_index(cubes.T, data.shape)
        slot_of = {int(c): s for s, c in enumerate(act.cubes)}
        for n, c in enumerate(lin):
            if c in slot_of:
                m = int(act.tet_mask[slot_of[c]])
                active[n] = [(m >> t) & 1 for t in range(24)]
        crossing = (vmin < iso) & (vmax > iso)
        assert not np.any(crossing & ~active)
        n_inactive += int((~active).sum())
        # The compact list of active tetrahedra is the same set.
        listed = {(int(x) // 24, int(x) % 24) for x in act.tets}
        expected = {(s, t) for s, m in enumerate(act.tet_mask) for t in range(24) if m >> t & 1}
        assert listed == expected
        assert scene.iso_stats["tets_active"] == len(listed)
    assert n_inactive > 0  # the test can fail: not everything is active


def _box_interval(o, u, lo, hi):
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - o) / u
        tb = (hi - o) / u
    t0 = np.nanmax(np.minimum(ta, tb), axis=-1)
    t1 = np.nanmin(np.maximum(ta, tb), axis=-1)
    return np.maximum(t0, 0.0), t1


def _brute_force(model, vol, camera, iso, n_samples=1200):
    """First sampled sign change per pixel: (crossing?, t before, t after)."""
    o, u = camera.rays()
    o = o.reshape(-1, 3)
    u = u.reshape(-1, 3)
    sp = np.array(vol.spacing)
    org = np.array(vol.origin)
    lo = org - 0.5 * sp
    hi = org + (np.array(vol.shape) - 0.5) * sp
    t0, t1 = _box_interval(o, u, lo, hi)
    s = np.linspace(0.0, 1.0, n_samples)
    found = np.zeros(len(o), bool)
    ta = np.full(len(o), np.inf)
    tb = np.full(len(o), np.inf)
    for r in np.flatnonzero(t0 < t1):
        ts = t0[r] + s * (t1[r] - t0[r])
        p = (o[r] + ts[:, None] * u[r] - org) / sp
        g = model.evaluate(p) - iso
        change = np.flatnonzero(((g[:-1] < 0) != (g[1:] < 0)) | (g[:-1] == 0))
        if len(change):
            found[r] = True
            ta[r], tb[r] = ts[change[0]], ts[change[0] + 1]
    shape = (camera.height, camera.width)
    return found.reshape(shape), ta.reshape(shape), tb.reshape(shape)


@pytest.mark.parametrize("model_name, opts, demo", [
    ("s31", {}, "sphere"),
    ("s31", {"precompute": True}, "torus"),
    ("qss", {}, "torus"),
    ("qss", {"variant": "qss-a", "precompute": True}, "sphere"),
])
def test_hits_lie_on_the_spline_surface_and_are_first(model_name, opts, demo):
    vol = sc.demo(demo, size=18)
    iso = vol.metadata["default_iso"]
    scene = sc.Scene(vol, model=model_name, **opts)
    cam = sc.Camera.orbit(vol, azimuth=37, elevation=23, size=(28, 24))
    frame = scene.render(cam, iso=iso)
    model = scene.model
    lo, hi = vol.value_range
    hit = frame.hit
    assert 50 < hit.sum() < hit.size
    p = (frame.position[hit] - np.array(vol.origin)) / np.array(vol.spacing)
    assert np.max(np.abs(model.evaluate(p) - iso)) <= 1e-6 * (hi - lo)
    found, ta, tb = _brute_force(model, vol, cam, iso)
    assert np.array_equal(found, hit)
    tol = 1e-9 * float(np.linalg.norm(vol.extent))
    assert np.all(frame.depth[hit] <= tb[hit] + tol)  # no later than the first sampled crossing
    assert np.all(frame.depth[hit] >= ta[hit] - tol)  # no earlier crossing among the samples
    assert frame.stats["cubes_active"] > 0 and "iso_change_ms" in frame.stats


def test_precomputed_and_on_the_fly_agree_and_newton_hits_the_surface():
    vol = sc.demo("torus", size=20)
    iso = vol.metadata["default_iso"]
    cam = sc.Camera.orbit(vol, azimuth=10, elevation=50, size=(32, 32))
    a = sc.Scene(vol, model="s31").render(cam, iso=iso)
    b = sc.Scene(vol, model="s31", precompute=True).render(cam, iso=iso)
    assert np.array_equal(a.hit, b.hit)
    assert np.allclose(a.depth[a.hit], b.depth[b.hit], rtol=0, atol=1e-12)
    assert b.stats["memory_precomputed_bytes"] > b.stats["memory_on_the_fly_bytes"]
    scene = sc.Scene(vol, model="s31", root_finder="newton")
    c = scene.render(cam, iso=iso)
    p = (c.position[c.hit] - np.array(vol.origin)) / np.array(vol.spacing)
    lo, hi = vol.value_range
    assert c.hit.sum() > 0.9 * a.hit.sum()
    assert np.max(np.abs(scene.model.evaluate(p) - iso)) <= 1e-6 * (hi - lo)


def _angles(frame, vol):
    hit = frame.hit
    pos = frame.position[hit]
    g = marschner_lobb_gradient(pos[:, 0], pos[:, 1], pos[:, 2])
    sign = 1.0 if vol.metadata.get("inside", "high") == "high" else -1.0
    expected = -sign * g / np.linalg.norm(g, axis=1, keepdims=True)
    n = frame.normal[hit].astype(np.float64)
    cos = np.clip(np.sum(n * expected, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def test_marschner_lobb_normals_s31_beat_trilinear():
    vol = sc.demo("marschner-lobb", size=64)
    iso = vol.metadata["default_iso"]
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=35, size=(64, 64))
    means = {}
    for name in ("trilinear", "qss", "s31"):
        ang = _angles(sc.Scene(vol, model=name).render(cam, iso=iso, normals="exact"), vol)
        means[name] = (float(ang.mean()), float(np.percentile(ang, 95)))
    print("mean / p95 normal angle (deg):", means)
    assert means["s31"][0] < means["trilinear"][0]
    assert all(math.isfinite(v[0]) for v in means.values())


def test_cli_renders_s31_with_root_finder(tmp_path, capsys):
    out = tmp_path / "s.png"
    rc = main(["render", "demo:sphere?size=12", "--model", "s31", "--root-finder", "newton",
               "--size", "24x16", "--quiet", "-o", str(out)])
    assert rc == 0 and out.exists()
    rc = main(["render", "demo:sphere?size=12", "--model", "trilinear", "--root-finder",
               "newton", "--size", "24x16", "--quiet", "-o", str(tmp_path / "t.png")])
    assert rc == 2
    assert "--root-finder" in capsys.readouterr().err


def test_sampled_method_finds_the_exact_hits_at_a_small_step():
    """The sampled method is a mode option for every model: on s31 it finds the exact first
    hits (to bisection accuracy) wherever no crossing pair lies within one step."""
    import splinecast as sc

    vol = sc.demo("sphere", size=12)
    cam = sc.Camera.orbit(vol, size=(16, 12))
    scene = sc.Scene(vol, model="s31")
    exact = scene.render(cam, iso=0.0)
    sampled = scene.render(cam, iso=0.0, method="sampled", step=0.05)
    np.testing.assert_array_equal(exact.hit, sampled.hit)
    np.testing.assert_allclose(sampled.depth[exact.hit], exact.depth[exact.hit], atol=1e-9)
