"""Synthetic demo volumes against their analytic definitions (written out again here)."""

from __future__ import annotations

import numpy as np
import pytest

from splinecast.errors import ParameterError
from splinecast.io import demo, read
from splinecast.io.synthetic import marschner_lobb, marschner_lobb_gradient

RNG = np.random.default_rng(12345)


def sample_voxels(vol, count: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Random voxel indices (count, 3) and their world positions."""
    idx = RNG.integers(0, vol.shape[0], size=(count, 3))
    return idx, vol.index_to_world(idx)


def values_at(vol, idx: np.ndarray) -> np.ndarray:
    return vol.data[idx[:, 0], idx[:, 1], idx[:, 2]].astype(np.float64)


def ml_reference(x: float, y: float, z: float) -> float:
    """Marschner & Lobb (1994), fM = 6, alpha = 0.25, written independently of the package."""
    fm, alpha = 6.0, 0.25
    r = np.hypot(x, y)
    rho_r = np.cos(2 * np.pi * fm * np.cos(np.pi * r / 2))
    return (1 - np.sin(np.pi * z / 2) + alpha * (1 + rho_r)) / (2 * (1 + alpha))


# --------------------------------------------------------------------------- values
def test_sphere_is_the_signed_distance() -> None:
    vol = demo("sphere", size=33)
    idx, p = sample_voxels(vol)
    np.testing.assert_allclose(values_at(vol, idx), np.linalg.norm(p, axis=1) - 0.6, atol=1e-6)
    assert vol.dtype == np.float32
    assert vol.metadata["default_iso"] == 0.0 and vol.metadata["inside"] == "low"
    # The centre voxel is inside, a corner outside.
    assert vol.data[16, 16, 16] == pytest.approx(-0.6) and vol.data[0, 0, 0] > 0


def test_torus_is_the_signed_distance() -> None:
    vol = demo("torus", size=41)
    idx, p = sample_voxels(vol)
    ring = np.hypot(p[:, 0], p[:, 1]) - 0.6
    np.testing.assert_allclose(values_at(vol, idx), np.hypot(ring, p[:, 2]) - 0.25, atol=1e-6)
    assert vol.metadata["inside"] == "low"
    assert vol.data[20, 20, 20] > 0  # the hole of the torus
    assert vol.data[20 + 12, 20, 20] == pytest.approx(-0.25)  # x = 0.6 lies on the tube's core


def test_chmutov_values_and_domain() -> None:
    vol = demo("chmutov", size=49)
    idx, p = sample_voxels(vol)
    x, y, z = p.T
    expected = x**16 + y**16 + z**16 - np.cos(7 * x) - np.cos(7 * y) - np.cos(7 * z)
    np.testing.assert_allclose(values_at(vol, idx), expected, rtol=1e-6, atol=1e-5)
    lo, hi = vol.bounds
    np.testing.assert_allclose(lo, -1.2)
    np.testing.assert_allclose(hi, 1.2)
    # Largest |x| on the zero set: root of x^16 = 2 + cos 7x (bisection).
    a, b = 1.0, 1.2
    for _ in range(60):
        m = 0.5 * (a + b)
        a, b = (m, b) if m**16 - 2 - np.cos(7 * m) < 0 else (a, m)
    assert a == pytest.approx(1.0573, abs=1e-4)
    assert hi[0] - a > 0.1  # a real margin around the surface
    faces = [vol.data[0], vol.data[-1], vol.data[:, 0], vol.data[:, -1], vol.data[..., 0],
             vol.data[..., -1]]
    assert min(float(f.min()) for f in faces) > 0  # the surface never touches the box
    assert vol.data.min() < 0


def test_marschner_lobb_against_the_formula() -> None:
    vol = demo("marschner-lobb", size=41)
    idx, p = sample_voxels(vol)
    expected = [ml_reference(*q) for q in p]
    np.testing.assert_allclose(values_at(vol, idx), expected, atol=1e-6)
    for q in [(0.0, 0.0, 0.0), (0.3, -0.2, 0.7), (-1.0, 1.0, -1.0), (0.123, 0.456, -0.789)]:
        assert marschner_lobb(*q) == pytest.approx(ml_reference(*q), abs=1e-14)
    lo, hi = vol.bounds
    np.testing.assert_allclose(lo, -1.0)
    np.testing.assert_allclose(hi, 1.0)
    # The object is the dense lower half: high values near z = -1, low near z = +1.
    assert vol.metadata["default_iso"] == 0.5 and vol.metadata["inside"] == "high"
    assert vol.data[:, :, 0].min() >= 0.79 and vol.data[:, :, -1].max() <= 0.21


def test_marschner_lobb_gradient_matches_finite_differences() -> None:
    pts = np.vstack([RNG.uniform(-1, 1, size=(50, 3)), [[0.0, 0.0, 0.3], [1e-9, 0.0, -0.5]]])
    h = 1e-6
    grad = marschner_lobb_gradient(pts[:, 0], pts[:, 1], pts[:, 2])
    assert grad.shape == (len(pts), 3)
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        hi, lo = pts + step, pts - step
        fd = (marschner_lobb(*hi.T) - marschner_lobb(*lo.T)) / (2 * h)
        np.testing.assert_allclose(grad[:, axis], fd, rtol=1e-5, atol=1e-6)
    assert np.all(np.isfinite(grad))
    np.testing.assert_allclose(grad[-2, :2], 0.0, atol=1e-12)  # on the z axis


# --------------------------------------------------------------------------- noise
def test_noise_is_deterministic_and_seeded() -> None:
    a = demo("noise", size=24, seed=7)
    b = demo("noise", size=24, seed=7)
    c = demo("noise", size=24, seed=8)
    np.testing.assert_array_equal(a.data, b.data)
    assert not np.array_equal(a.data, c.data)
    assert a.dtype == np.float32
    assert a.metadata["inside"] == "high" and a.metadata["default_iso"] == 0.5
    assert a.name == "demo:noise?size=24&seed=7"
    assert demo("noise", size=24).name == "demo:noise?size=24"


def test_noise_known_values() -> None:
    # Pinned so that a change of algorithm or a platform difference is noticed.
    vol = demo("noise", size=9, seed=0)
    got = vol.data[[0, 4, 8, 2], [0, 4, 8, 7], [0, 4, 8, 1]]
    expected = [0.6276485323905945, 0.4492558240890503, 0.31075039505958557, 0.5017156004905701]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)


def test_noise_features_scale_with_the_domain() -> None:
    coarse = demo("noise", size=33, seed=3)
    fine = demo("noise", size=65, seed=3)
    # Every other sample of the fine grid is a sample of the coarse grid: same field.
    np.testing.assert_allclose(fine.data[::2, ::2, ::2], coarse.data, atol=1e-6)
    np.testing.assert_allclose(fine.bounds[0], 0.0)
    np.testing.assert_allclose(fine.bounds[1], 1.0)
    assert -0.3 < fine.data.min() < 0.3 and 0.7 < fine.data.max() < 1.3
    assert 0.4 < float(fine.data.mean()) < 0.6


# --------------------------------------------------------------------------- entry points
def test_read_demo_uri() -> None:
    vol = read("demo:sphere?size=32")
    assert vol.shape == (32, 32, 32)
    assert vol.metadata["name"] == "demo:sphere?size=32"
    assert vol.spacing == pytest.approx((2 / 31,) * 3)
    assert read("demo:noise?size=16&seed=2").metadata["name"] == "demo:noise?size=16&seed=2"
    assert demo("torus").shape == (64, 64, 64)


def test_unknown_demo_name() -> None:
    valid = "valid: marschner-lobb, sphere, torus, chmutov, noise"
    with pytest.raises(ParameterError, match=valid):
        demo("teapot")
    with pytest.raises(ParameterError, match="teapot"):
        read("demo:teapot?size=8")


@pytest.mark.parametrize("size", [1, 0, -3, 2.5, "big"])
def test_bad_size(size: object) -> None:
    with pytest.raises(ParameterError, match="size"):
        demo("sphere", size=size)


def test_bad_parameters() -> None:
    with pytest.raises(ParameterError, match="size"):
        read("demo:sphere?size=abc")
    with pytest.raises(ParameterError, match="seed"):
        demo("sphere", size=8, seed=1)
    with pytest.raises(ParameterError, match="seed"):
        demo("noise", size=8, seed=0.5)
