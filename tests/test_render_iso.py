"""First-hit isosurface rendering of the trilinear interpolant, against an independent reference.

The reference (:class:`reference.RefIsoCaster`) maps every pixel ray to index space, clips it to
the reconstruction box and finds the first sign change of ``f - iso`` along it with a branch and
bound search on the numpy trilinear interpolant (dense sampling made as dense as needed where a
crossing could hide, bisected to 1e-12 voxel; see its docstring). It shares no code with
splinecast.

Mismatches between the exact method and the reference are tolerated only where floating point
cannot decide (never by loosening the depth tolerance):

* the renderer reports a hit where the reference sees no crossing yet: allowed only if the
  interpolant at the reported point is within ``EPS_TOUCH`` of the isovalue (a tangential
  near-touch that rounding turned into a root);
* the renderer misses the reference's first crossing: allowed only if that excursion beyond the
  isovalue is at most ``EPS_TOUCH`` deep (its width times the Lipschitz bound of the ray).

``EPS_TOUCH`` is 1e-10 of the data range, far above the rounding level of the per-cell cubics
(~1e-15) and far below anything visible. The number of such pixels is reported and bounded.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from reference import (
    RefIsoCaster,
    exact_walk,
    marschner_lobb,
    smooth_noise,
    sphere_distance,
    trilinear,
)

import splinecast as sc
from splinecast import Camera, DataError, ParameterError, Scene, Volume

EPS_TOUCH = 1e-10  # relative to the data range, see the module docstring
DEPTH_TOL_VOXELS = 1e-4
TAN_DIAG = math.degrees(math.atan(1 / math.sqrt(2)))  # 35.264...: the body-diagonal elevation


# =============================================================================== volumes
@functools.cache
def ml_volume() -> Volume:
    data, spacing, origin = marschner_lobb(41)
    return Volume(data, spacing=spacing, origin=origin, metadata={"name": "ml41"})


@functools.cache
def ml_uint8() -> Volume:
    data, spacing, origin = marschner_lobb(41)
    return Volume(np.round(data * 255).astype(np.uint8), spacing=spacing, origin=origin)


@functools.cache
def ml_dyadic() -> Volume:
    # the same samples with dyadic, anisotropic spacing and origin: grid-aligned cameras exact
    data, _, _ = marschner_lobb(41)
    return Volume(data, spacing=(0.5, 0.5, 0.25), origin=(-10.0, -10.0, -5.0))


@functools.cache
def sphere_volume() -> Volume:
    # signed distance (world units) to a sphere, unit spacing; "inside" is the low side
    data = sphere_distance((33, 33, 33), (16.3, 15.8, 16.1), 11.0)
    return Volume(data, metadata={"inside": "low"})


@functools.cache
def noise_volume() -> Volume:
    # anisotropic spacing and an offset origin (dyadic values, so grid-aligned cameras are exact)
    return Volume(smooth_noise((40, 36, 32), seed=3), spacing=(0.75, 1.25, 0.5),
                  origin=(-3.0, 2.0, 5.0))


@functools.cache
def noise_int16() -> Volume:
    data = np.round(smooth_noise((36, 32, 28), seed=5) * 3000).astype(np.int16)
    return Volume(data, spacing=(1.0, 0.75, 1.25), origin=(2.0, -1.0, 0.5))


VOLUMES = {
    "ml": (ml_volume, 0.5),
    "ml-uint8": (ml_uint8, 127.5),
    "ml-dyadic": (ml_dyadic, 0.5),
    "sphere": (sphere_volume, 0.0),
    "noise": (noise_volume, 0.3),
    "noise-int16": (noise_int16, 250.5),
}


@pytest.fixture(scope="module")
def scenes():
    cache = {}

    def get(key):
        if key not in cache:
            cache[key] = Scene(VOLUMES[key][0]())
        return cache[key]

    return get


@functools.cache
def reference_for(key) -> RefIsoCaster:
    return RefIsoCaster.of(VOLUMES[key][0]())


# =============================================================================== cameras
def grid_camera(vol, axis, offsets=(0.0, 0.0), pitch=None, size=32, sign=-1.0):
    """Orthographic camera looking along ``sign * axis`` whose pixel centres fall on chosen index
    coordinates. ``offsets`` (for the two other axes, in voxels) place the pixel grid relative to
    the voxel planes (0.0: on the planes); ``pitch`` is the world distance between pixel
    centres (an integer number of voxels on both axes keeps every ray on a plane). With a power
    of two ``size`` and dyadic spacing and origin everything is exact in floating point."""
    assert size & (size - 1) == 0
    spacing = np.asarray(vol.spacing)
    others = [a for a in range(3) if a != axis]
    if pitch is None:
        pitch = float(spacing[others].max())
    lo, hi = vol.bounds
    centre_idx = np.floor((np.asarray(vol.shape) - 1) / 2.0)
    pos = np.asarray(vol.origin) + centre_idx * spacing
    # pixel centres sit at +-(m + 1/2) pitch from the eye: shift the eye by half a pitch
    for a, off in zip(others, offsets, strict=True):
        pos[a] += off * spacing[a] + 0.5 * pitch
    pos[axis] = (hi[axis] + 7.0) if sign < 0 else (lo[axis] - 7.0)
    look = pos.copy()
    look[axis] += sign * 10.0
    up = np.zeros(3)
    up[others[1]] = 1.0
    return Camera(pos, look, up=up, size=(size, size), ortho=True, ortho_height=size * pitch)


def cameras_for(key):
    vol = VOLUMES[key][0]()
    cams = {
        "orbit": Camera.orbit(vol, azimuth=37, elevation=23, size=(48, 48), zoom=1.5),
        "diagonal": Camera.orbit(vol, azimuth=45, elevation=TAN_DIAG, size=(40, 40), zoom=1.3),
        "ortho-x": Camera.orbit(vol, azimuth=0, elevation=0, size=(40, 40), ortho=True),
        "orbit-el90": Camera.orbit(vol, azimuth=20, elevation=90, size=(40, 40), zoom=1.2),
        "ortho-el90": Camera.orbit(vol, azimuth=0, elevation=90, size=(40, 40), ortho=True),
        "below": Camera.orbit(vol, azimuth=-120, elevation=-30, size=(40, 40), zoom=1.4),
    }
    return cams


def _grid_cameras():
    # (volume key, camera id, builder): rays along grid lines (through voxel centres and cell
    # corners) or lying in grid planes
    return [
        ("ml-dyadic", "edges-z", lambda v: grid_camera(v, 2)),
        ("ml-dyadic", "edges-x", lambda v: grid_camera(v, 0, pitch=0.5)),
        ("ml-dyadic", "faces-y", lambda v: grid_camera(v, 1, (0.5, 0.0), pitch=0.5)),
        ("sphere", "edges-z", lambda v: grid_camera(v, 2)),
        ("sphere", "edges-y+", lambda v: grid_camera(v, 1, sign=1.0)),
        ("sphere", "faces-x", lambda v: grid_camera(v, 0, (0.5, 0.0))),
        # anisotropic: x spacing 0.75 and z spacing 0.5; pitch 1.5 = 2 voxels in x, 3 in z
        ("noise", "edges-y", lambda v: grid_camera(v, 1, pitch=1.5, size=16)),
        ("noise", "faces-z+", lambda v: grid_camera(v, 2, (0.0, 0.5), pitch=3.75, size=8,
                                                    sign=1.0)),
    ]


def _inside_cameras():
    return [
        ("ml", "inside", lambda v: Camera((0.1, -0.2, 0.15), (1.0, 0.7, -0.4), fov=70,
                                          size=(40, 40))),
        ("noise", "inside", lambda v: Camera(v.center + 0.3, v.center + (-1.0, 2.0, 0.5), fov=80,
                                             size=(40, 40))),
    ]


CASES = (
    [(k, c) for k in ("ml", "sphere", "noise") for c in cameras_for(k)]
    + [(k, "orbit") for k in ("ml-uint8", "noise-int16")]
    + [(k, "diagonal") for k in ("ml-uint8", "noise-int16")]
    + [(k, c) for k, c, _ in _grid_cameras()]
    + [(k, c) for k, c, _ in _inside_cameras()]
)


def camera(key, cam_id):
    vol = VOLUMES[key][0]()
    for k, c, build in _grid_cameras() + _inside_cameras():
        if (k, c) == (key, cam_id):
            return build(vol)
    return cameras_for(key)[cam_id]


# =============================================================================== comparison
def index_dir_norm(vol, U):
    return np.linalg.norm(np.asarray(U) / np.asarray(vol.spacing), axis=-1)


def compare_depths(vol, ref, cam, iso, depth, allow_fraction=0.005):
    """Check a depth buffer against the reference (rules in the module docstring).

    Returns ``(depth_ref, n_exceptions)``.
    """
    W, U = cam.rays()
    depth_ref, unresolved = ref.first_hits(W, U, iso)
    assert not unresolved.any(), "the reference could not decide some rays"
    dn = index_dir_norm(vol, U)
    tol = DEPTH_TOL_VOXELS / dn
    hit_c, hit_r = np.isfinite(depth), np.isfinite(depth_ref)
    with np.errstate(invalid="ignore"):
        close = hit_c & hit_r & (np.abs(depth - depth_ref) <= tol)
    agree = close | (~hit_c & ~hit_r)
    eps = EPS_TOUCH * ref.range
    problems = []
    n_exceptions = 0
    for r, c in zip(*np.nonzero(~agree), strict=True):
        o, d = ref.to_index(W[r, c][None], U[r, c][None])
        if hit_c[r, c] and (not hit_r[r, c] or depth[r, c] < depth_ref[r, c]):
            # the renderer hit before any crossing of the interpolant
            g = float(ref.g(o, d, np.array([depth[r, c]]), iso)[0])
            ok = abs(g) <= eps
            why = f"renderer hit at t={depth[r, c]!r} where f - iso = {g:.3e} (reference: " \
                  f"{depth_ref[r, c]!r})"
        else:
            # the renderer missed (or passed) the reference's first crossing
            width = float(ref.excursion_width(W[r, c], U[r, c], iso, depth_ref[r, c])[0])
            L, _ = ref.lipschitz(d)
            ok = L[0] * width / 2 <= eps
            why = f"renderer {'missed' if not hit_c[r, c] else 'passed'} the crossing at " \
                  f"t={depth_ref[r, c]!r} (renderer: {depth[r, c]!r}); excursion width " \
                  f"{width:.3e}"
        n_exceptions += 1
        if not ok:
            problems.append(f"pixel ({r}, {c}): {why}")
    assert not problems, f"{len(problems)} pixels disagree with the reference:\n" + "\n".join(
        problems[:10])
    assert n_exceptions <= max(2, allow_fraction * depth.size), n_exceptions
    return depth_ref, n_exceptions


def normal_candidates(ref, P, inside, h=1e-6):
    """Outward unit normals from finite differences of the reference interpolant at world
    points ``P`` (m, 3); shape (8, m, 3): one per choice of one-sided derivative on each axis.

    Inside a cell the trilinear interpolant is linear along each axis, so a difference taken
    within one cell is exact up to rounding. On a cell face normal to axis ``a`` the derivative
    along ``a`` jumps; both one-sided values are legitimate, so both are offered (away from
    faces both "choices" are the same central difference).
    """
    p = (np.asarray(P, np.float64) - ref.origin) / ref.spacing
    n = ref.shape - 1.0
    fwd = np.empty_like(p)
    bwd = np.empty_like(p)
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        near = np.abs(p[:, a] - np.round(p[:, a])) <= 2 * h
        q = p.copy()
        q[near, a] = np.round(p[near, a])
        central = (trilinear(ref.data, p + e) - trilinear(ref.data, p - e)) / (2 * h)
        f_fwd = (trilinear(ref.data, q + e) - trilinear(ref.data, q)) / h
        f_bwd = (trilinear(ref.data, q) - trilinear(ref.data, q - e)) / h
        # one-sided differences that would leave the box are replaced by the other side
        f_fwd = np.where(q[:, a] + h > n[a], f_bwd, f_fwd)
        f_bwd = np.where(q[:, a] - h < 0, f_fwd, f_bwd)
        fwd[:, a] = np.where(near, f_fwd, central)
        bwd[:, a] = np.where(near, f_bwd, central)
    sign = -1.0 if inside == "high" else 1.0
    out = []
    for combo in range(8):
        g = np.where([(combo >> a) & 1 for a in range(3)], fwd, bwd) / ref.spacing
        out.append(sign * g / np.linalg.norm(g, axis=1, keepdims=True))
    grad_norm = np.linalg.norm(fwd / ref.spacing, axis=1)
    return np.stack(out), grad_norm


def check_positions_and_normals(vol, ref, cam, iso, frame, inside):
    W, U = cam.rays()
    hit = frame.hit
    assert np.all(np.isnan(frame.position[~hit])) and np.all(np.isnan(frame.normal[~hit]))
    assert np.all(frame.face[~hit] == 0)
    if not hit.any():
        return
    depth = frame.depth[hit]
    P = frame.position[hit]
    scale = max(1.0, float(np.abs(W).max()) + float(depth.max()))
    np.testing.assert_allclose(P, W[hit] + depth[:, None] * U[hit], rtol=0, atol=1e-12 * scale)
    # the interpolant equals the isovalue at the reported positions
    residual = np.abs(ref.value_world(P) - iso)
    assert residual.max() <= 1e-9 * ref.range, residual.max()
    # normals: unit, and equal to the outward finite-difference normal of the reference
    N = frame.normal[hit].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-6)
    cands, grad_norm = normal_candidates(ref, P, inside)
    err = np.min(np.linalg.norm(cands - N[None], axis=2), axis=0)
    # a vanishing gradient has no direction: skip nearly flat points
    steep = grad_norm > 1e-4 * ref.range / min(vol.spacing)
    assert steep.mean() > 0.9
    bad = steep & ~(err <= 2e-5)
    assert not bad.any(), f"{bad.sum()} normals differ, worst {err[steep].max():.3e}"
    # face: front when the ray enters the inside, i.e. n . u <= 0
    dots = np.einsum("ij,ij->i", N, U[hit])
    face = frame.face[hit]
    assert np.all(face[dots < -1e-6] == 1) and np.all(face[dots > 1e-6] == -1)


# =============================================================================== tests
def test_reference_against_dense_sampling():
    """The reference itself, against the plain method: map_coordinates (order 1) sampled every
    1e-3 voxel along each ray, first sign change. (Dense sampling can step over a crossing pair
    thinner than 1e-3 voxel; none occurs on these rays, which the comparison confirms.)"""
    from scipy.ndimage import map_coordinates

    vol = ml_volume()
    ref = reference_for("ml")
    cam = Camera.orbit(vol, azimuth=-60, elevation=40, size=(48, 48), zoom=1.6)
    W, U = cam.rays()
    rng = np.random.default_rng(0)
    pick = rng.choice(W.shape[0] * W.shape[1], 150, replace=False)
    W, U = W.reshape(-1, 3)[pick], U.reshape(-1, 3)[pick]
    depth, _ = ref.first_hits(W, U, 0.5)
    o, d = ref.to_index(W, U)
    t0, t1 = ref.clip(o, d)
    n_hits = 0
    for r in range(len(pick)):
        dense = math.inf
        if t0[r] <= t1[r]:
            dn = float(np.linalg.norm(d[r]))
            ts = np.linspace(t0[r], t1[r], int(math.ceil((t1[r] - t0[r]) * dn / 1e-3)) + 2)
            g = map_coordinates(ref.data, (o[r] + ts[:, None] * d[r]).T, order=1,
                                mode="nearest") - 0.5
            change = np.nonzero(np.sign(g[1:]) != np.sign(g[0]))[0]
            if change.size:
                dense = ts[change[0] + 1]  # first sample past the crossing
                assert ts[change[0]] <= depth[r] <= dense + 1e-12
                n_hits += 1
        if dense == math.inf:
            assert depth[r] == math.inf
    assert n_hits > 50
    # and the numpy trilinear is map_coordinates' order-1 interpolation
    p = rng.uniform(0, 40, (2000, 3))
    np.testing.assert_allclose(trilinear(ref.data, p), map_coordinates(ref.data, p.T, order=1),
                               atol=1e-15)


def test_reference_on_a_linear_field():
    # f = x + 2y - 3z is reproduced exactly by trilinear interpolation: analytic intersections
    shape = (9, 10, 11)
    i, j, k = np.meshgrid(*[np.arange(n, dtype=np.float64) for n in shape], indexing="ij")
    ref = RefIsoCaster(i + 2 * j - 3 * k)
    rng = np.random.default_rng(1)
    W = rng.uniform(-3, 12, (200, 3))
    U = rng.uniform(0, 1, (200, 3)) * (np.array(shape) - 1) - W  # aimed into the box
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    depth, _ = ref.first_hits(W, U, 1.5)
    a = np.array([1.0, 2.0, -3.0])
    t = (1.5 - W @ a) / (U @ a)
    t0, t1 = ref.clip(W, U)
    expected = np.where((t >= t0) & (t <= t1), t, np.inf)
    np.testing.assert_allclose(depth, expected, rtol=0, atol=1e-11)
    assert np.isfinite(depth).sum() > 30


def test_comparison_catches_mismatches(scenes):
    """The checker above is not lenient: a dropped hit, an invented hit and a depth moved by
    more than the tolerance are all reported."""
    vol, iso = ml_volume(), 0.5
    cam = camera("ml", "orbit")
    good = scenes("ml").render(cam, iso=iso).depth
    ref = reference_for("ml")
    compare_depths(vol, ref, cam, iso, good)
    hit_pixels = np.argwhere(np.isfinite(good))
    miss_pixels = np.argwhere(~np.isfinite(good))
    dn = index_dir_norm(vol, cam.rays()[1])
    r, c = hit_pixels[len(hit_pixels) // 2]
    for change in ("drop", "invent", "move"):
        bad = good.copy()
        if change == "drop":
            bad[r, c] = np.inf
        elif change == "invent":
            rm, cm = miss_pixels[len(miss_pixels) // 2]
            bad[rm, cm] = 10.0
        else:
            bad[r, c] += 3 * DEPTH_TOL_VOXELS / dn[r, c]
        with pytest.raises(AssertionError, match="disagree"):
            compare_depths(vol, ref, cam, iso, bad)


@pytest.mark.parametrize("key, cam_id", CASES, ids=[f"{k}-{c}" for k, c in CASES])
def test_exact_method_matches_reference(scenes, key, cam_id):
    vol = VOLUMES[key][0]()
    iso = VOLUMES[key][1]
    inside = vol.metadata.get("inside", "high")
    cam = camera(key, cam_id)
    # The reference's normals are the trilinear gradient's: the model's own shading normals.
    frame = scenes(key).render(cam, iso=iso, normals="exact")
    ref = reference_for(key)
    depth_ref, _ = compare_depths(vol, ref, cam, iso, frame.depth)
    n_hits = int(frame.hit.sum())
    # (seen edge-on, as from the side for Marschner-Lobb, few rays hit: still worth checking)
    assert n_hits >= 0.02 * frame.depth.size, f"only {n_hits} hits: a useless view"
    assert frame.stats["hits"] == n_hits
    check_positions_and_normals(vol, ref, cam, iso, frame, inside)


def test_grid_camera_rays_are_on_voxel_planes():
    # the grazing cameras really put their rays on grid lines / in grid planes
    for key, cam_id, build in _grid_cameras():
        vol = VOLUMES[key][0]()
        cam = build(vol)
        W, U = cam.rays()
        o = vol.world_to_index(W)
        axis = int(np.argmax(np.abs(cam.forward)))
        assert np.count_nonzero(cam.forward) == 1
        others = [a for a in range(3) if a != axis]
        frac = o[..., others] - np.floor(o[..., others])
        on_plane = np.any(frac == 0.0, axis=-1)
        assert on_plane.all(), (key, cam_id)
        if "edges" in cam_id:
            assert np.all(frac == 0.0), (key, cam_id)


@pytest.mark.parametrize("key", ["ml", "noise-int16"])
def test_sampled_method_small_step(scenes, key):
    """At step 0.05 voxel the sampled method finds the same first crossing as the exact one
    wherever the excursion beyond the isovalue is longer than two steps (it then cannot step
    over it), and every sampled hit is a crossing of the interpolant to bisection accuracy."""
    vol = VOLUMES[key][0]()
    iso = VOLUMES[key][1]
    step = 0.05
    cam = camera(key, "orbit")
    scene = scenes(key)
    exact = scene.render(cam, iso=iso)
    sampled = scene.render(cam, iso=iso, method="sampled", step=step)
    assert sampled.stats["method"] == "sampled"
    ref = reference_for(key)
    W, U = cam.rays()
    dn = index_dir_norm(vol, U)
    hs, he = sampled.hit, exact.hit
    # every sampled hit is a sign change of the interpolant within 1e-9 voxel
    r, c = np.nonzero(hs)
    o, d = ref.to_index(W[r, c], U[r, c])
    t = sampled.depth[r, c]
    delta = 1e-9 / dn[r, c]
    g_before = ref.g(o, d, t - delta, iso)
    g_after = ref.g(o, d, t + delta, iso)
    assert np.all((np.sign(g_before) != np.sign(g_after)) | (g_after == 0) | (g_before == 0))
    # never before the exact method's first crossing
    assert np.all(sampled.depth[hs] >= exact.depth[hs] - DEPTH_TOL_VOXELS / dn[hs])
    # where the first excursion is resolved at this step: the same crossing, and a hit
    r, c = np.nonzero(he)
    width = ref.excursion_width(W[r, c], U[r, c], iso, exact.depth[r, c], window=3 * step)
    resolved = np.zeros_like(he)
    resolved[r, c] = width * dn[r, c] >= 2 * step
    assert resolved.sum() >= 0.8 * he.sum()
    assert np.all(hs[resolved])
    diff = np.abs(sampled.depth[resolved] - exact.depth[resolved]) * dn[resolved]
    assert diff.max() <= 1e-8, diff.max()
    # no sampled hit where the exact method sees no crossing
    assert not np.any(hs & ~he)


@functools.cache
def thin_shell_volume() -> Volume:
    # The walls of a hollow cube, one voxel thick: the interpolant exceeds 0.5 only within half
    # a voxel of the planes x = 10, x = 30 (and the same for y, z).
    data = np.zeros((41, 41, 41), np.float32)
    s = slice(10, 31)
    for plane in (10, 30):
        data[plane, s, s] = 1.0
        data[s, plane, s] = 1.0
        data[s, s, plane] = 1.0
    return Volume(data)


def test_sampled_method_misses_thin_shell_at_large_step(scenes):
    vol = thin_shell_volume()
    scene = Scene(vol)
    # orthographic, looking along +x from x = -20: the ray enters the box at x = 0, so a step of
    # 4 voxels samples x = 0, 4, 8, 12, ... 28, 32: never inside (9.5, 10.5) or (29.5, 30.5)
    cam = Camera((-20.0, 20.25, 20.25), (0.0, 20.25, 20.25), up=(0, 0, 1), size=(32, 32),
                 ortho=True, ortho_height=40.0)
    exact = scene.render(cam, iso=0.5)
    coarse = scene.render(cam, iso=0.5, method="sampled", step=4.0)
    fine = scene.render(cam, iso=0.5, method="sampled", step=0.05)
    centre = (16, 16)
    assert exact.depth[centre] == pytest.approx(29.5, abs=1e-12)  # x = 9.5
    assert not coarse.hit[centre]
    assert fine.depth[centre] == pytest.approx(29.5, abs=1e-9)
    # the whole face-on part of the wall is missed at step 4 and found at step 0.05
    W, _ = cam.rays()
    face_on = (np.abs(W[..., 1] - 20) < 9) & (np.abs(W[..., 2] - 20) < 9)
    assert face_on.sum() > 100
    assert np.all(exact.hit[face_on]) and not np.any(coarse.hit[face_on])
    assert np.all(fine.hit[face_on])
    np.testing.assert_allclose(exact.depth[face_on], 29.5, atol=1e-12)
    # and the exact method agrees with the reference everywhere
    compare_depths(vol, RefIsoCaster.of(vol), cam, 0.5, exact.depth)


@functools.cache
def blob_volume() -> Volume:
    # mostly empty: a small sphere (distance field, radius 5) in an 81^3 grid
    return Volume(sphere_distance((81, 81, 81), (23.3, 30.7, 27.9), 5.0).astype(np.float32),
                  metadata={"inside": "low"})


def render_all_active(scene, cam, iso, **kw):
    scene.render(cam, iso=iso, **kw)  # classifies the blocks for iso
    saved = scene.hierarchy.active
    scene.hierarchy.active = tuple(np.ones_like(a) for a in saved)
    try:
        return scene.render(cam, iso=iso, **kw)  # same iso: the forced flags are used
    finally:
        scene.hierarchy.active = saved


@pytest.mark.parametrize("key", ["blob", "ml"])
def test_empty_space_skipping_changes_nothing(scenes, key):
    if key == "blob":
        vol, iso = blob_volume(), 0.0
        scene = Scene(vol)
        cam = Camera.orbit(vol, azimuth=-25, elevation=15, size=(64, 64), zoom=2.5)
    else:
        vol, iso = ml_volume(), 0.5
        scene = scenes("ml")
        cam = camera("ml", "orbit")
    skipping = scene.render(cam, iso=iso)
    full = render_all_active(scene, cam, iso)
    assert skipping.hit.any()
    np.testing.assert_array_equal(skipping.depth, full.depth)
    np.testing.assert_array_equal(skipping.position, full.position)
    np.testing.assert_array_equal(skipping.normal, full.normal)
    np.testing.assert_array_equal(skipping.face, full.face)
    assert np.all(full.blocks_skipped == 0)
    # forcing the flags really took effect, and the skipping render did skip
    assert skipping.blocks_skipped.sum() > 0
    assert full.cells_visited.sum() > skipping.cells_visited.sum()


def test_skipping_statistics_on_a_mostly_empty_volume():
    vol = blob_volume()
    scene = Scene(vol)
    cam = Camera.orbit(vol, azimuth=-25, elevation=15, size=(48, 48), zoom=1.0)
    frame = scene.render(cam, iso=0.0)
    full = render_all_active(scene, cam, 0.0)
    W, U = cam.rays()
    n_cells = np.asarray(vol.shape) - 1
    o_all = vol.world_to_index(W)
    d_all = U / np.asarray(vol.spacing)
    t0, t1 = RefIsoCaster.of(vol).clip(o_all.reshape(-1, 3), d_all.reshape(-1, 3))
    crosses_box = (t1 - t0).reshape(W.shape[:2]) > 1.0
    # cells on each ray, from the exact reference walk (a sample of the rays that cross the box
    # but miss the surface)
    rows, cols = np.nonzero(~frame.hit & crosses_box)
    pick = np.random.default_rng(0).choice(rows.size, 40, replace=False)
    on_ray = []
    for r, c in zip(rows[pick], cols[pick], strict=True):
        o, d = vol.world_to_index(W[r, c]), U[r, c] / np.asarray(vol.spacing)
        cells = exact_walk(o, d, n_cells)
        on_ray.append(len(cells))
        # without skipping the renderer walks exactly those cells
        assert full.cells_visited[r, c] == len(cells)
    on_ray = np.array(on_ray)
    visited = frame.cells_visited[rows[pick], cols[pick]]
    skipped = frame.blocks_skipped[rows[pick], cols[pick]]
    # every such ray either leapt over empty blocks or was cut off entirely by the clip to the
    # box of active blocks (then it walked nothing)
    assert np.all((skipped > 0) | (visited == 0))
    assert on_ray.mean() > 40
    assert visited.sum() <= 0.1 * on_ray.sum(), (visited.sum(), on_ray.sum())
    assert frame.stats["mean_cells_visited"] == pytest.approx(frame.cells_visited.mean())
    assert frame.stats["mean_blocks_skipped"] > 0
    # every tested cell was visited
    assert np.all(frame.cells_tested <= frame.cells_visited)


def test_front_and_back_faces_on_a_sphere(scenes):
    vol = sphere_volume()
    scene = scenes("sphere")
    centre = np.array([16.3, 15.8, 16.1])
    outside = Camera.orbit(vol, azimuth=70, elevation=-20, size=(40, 40), zoom=1.3)
    low = scene.render(outside, iso=0.0, inside="low")
    assert low.hit.sum() > 300
    assert np.all(low.face[low.hit] == 1)
    P = low.position[low.hit]
    # outward normals point away from the centre
    assert np.all(np.einsum("ij,ij->i", low.normal[low.hit], P - centre) > 0)
    high = scene.render(outside, iso=0.0, inside="high")
    np.testing.assert_array_equal(high.depth, low.depth)
    np.testing.assert_array_equal(high.normal[low.hit], -low.normal[low.hit])
    assert np.all(high.face[high.hit] == -1)
    # the default comes from the volume metadata ("low")
    default = scene.render(outside, iso=0.0)
    np.testing.assert_array_equal(default.normal, low.normal)
    # from inside the sphere every ray leaves through a back face
    inside_cam = Camera(centre + (1.0, -2.0, 0.5), centre + (5.0, 3.0, -1.0), fov=90,
                        size=(32, 32))
    fr = scene.render(inside_cam, iso=0.0, inside="low", normals="exact")
    assert fr.hit.all()
    assert np.all(fr.face == -1)
    assert np.all(np.einsum("ij,ij->i", fr.normal.reshape(-1, 3),
                            fr.position.reshape(-1, 3) - centre) > 0)
    compare_depths(vol, reference_for("sphere"), inside_cam, 0.0, fr.depth)
    check_positions_and_normals(vol, reference_for("sphere"), inside_cam, 0.0, fr, "low")


def test_float32_volume_is_interpolated_in_float64():
    """A float32 volume and its exact float64 copy hold the same numbers, hence define the same
    interpolant: their renders must agree to rounding (the models module promises "All arithmetic
    is float64; voxels stay in their stored dtype and are converted on load").

    Regression test: ``cell_monomials`` used to convert voxels with ``float(data[i, j, k])``,
    which numba types as float32 for a float32 array, so the monomial coefficients (and the cubic
    along the ray) were float32-rounded; depths moved by ~3e-7 voxel and |f(hit) - iso| reached
    ~5e-9 of the data range instead of ~1e-14.
    """
    data32 = sphere_distance((33, 33, 33), (16.3, 15.8, 16.1), 11.0).astype(np.float32)
    v32 = Volume(data32, metadata={"inside": "low"})
    v64 = Volume(data32.astype(np.float64), metadata={"inside": "low"})
    cam = Camera.orbit(v32, azimuth=37, elevation=23, size=(48, 48), zoom=1.5)
    f32 = Scene(v32).render(cam, iso=0.0)
    f64 = Scene(v64).render(cam, iso=0.0)
    np.testing.assert_array_equal(f32.hit, f64.hit)
    hit = f64.hit
    assert hit.sum() > 500
    ref = RefIsoCaster.of(v64)
    # the float64 render is exact to rounding; the float32 one must be too
    assert np.abs(ref.value_world(f64.position[hit])).max() <= 1e-12 * ref.range
    residual32 = np.abs(ref.value_world(f32.position[hit])).max()
    depth_diff = np.abs(f32.depth[hit] - f64.depth[hit]).max()
    assert depth_diff <= 1e-10 and residual32 <= 1e-12 * ref.range, (
        f"float32 volume: depths differ from the float64 copy by up to {depth_diff:.3e}, "
        f"|f(hit) - iso| up to {residual32:.3e} (data range {ref.range:.3g})")


@pytest.mark.parametrize("name", ["sphere", "torus", "marschner-lobb", "noise", "chmutov"])
def test_demo_volumes_match_reference(name):
    vol = sc.demo(name, size=32)
    assert vol.shape == (32, 32, 32)
    iso = float(vol.metadata["default_iso"])
    inside = vol.metadata["inside"]
    scene = Scene(vol)
    cam = Camera.orbit(vol, azimuth=33, elevation=27, size=(32, 32))
    # default iso and inside from the metadata; the model's own normals, as the reference's
    frame = scene.render(cam, normals="exact")
    assert frame.stats["iso"] == iso
    assert frame.hit.sum() > 20
    ref = RefIsoCaster.of(vol)
    compare_depths(vol, ref, cam, iso, frame.depth)
    check_positions_and_normals(vol, ref, cam, iso, frame, inside)


# =============================================================================== bad input
def test_iso_outside_the_value_range(scenes):
    scene = scenes("ml")
    cam = Camera.orbit(ml_volume(), size=(8, 8))
    lo, hi = ml_volume().value_range
    for bad in (hi + 1e-3, lo - 1.0, float("nan"), float("inf")):
        with pytest.raises(ParameterError, match="iso"):
            scene.render(cam, iso=bad)
    with pytest.raises(ParameterError, match="iso"):
        scene.render(cam, iso="half")
    # No default_iso in the metadata: the automatic isovalue (tests/test_defaults.py).
    assert lo < scene.render(cam).stats["iso"] < hi
    scene.render(cam, iso=hi)  # the ends of the range are allowed
    scene.render(cam, iso=lo)


def test_nan_in_data_raises_on_scene():
    data = np.zeros((5, 6, 7))
    data[2, 3, 4] = np.nan
    with pytest.raises(DataError):
        Scene(Volume(data))
    data32 = np.ones((4, 4, 4), np.float32)
    data32[0, 0, 0] = np.nan
    with pytest.raises(DataError):
        Scene(Volume(data32))


def test_unknown_method_mode_model(scenes):
    scene = scenes("ml")
    cam = Camera.orbit(ml_volume(), size=(8, 8))
    with pytest.raises(ParameterError, match="method"):
        scene.render(cam, iso=0.5, method="analytic")
    with pytest.raises(ParameterError, match="mode"):
        scene.render(cam, mode="hologram", iso=0.5)
    with pytest.raises(ParameterError, match="model"):
        Scene(ml_volume(), model="no-such-model")
    with pytest.raises(ParameterError, match="inside"):
        scene.render(cam, iso=0.5, inside="outside")
    for bad_step in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ParameterError, match="step"):
            scene.render(cam, iso=0.5, method="sampled", step=bad_step)
