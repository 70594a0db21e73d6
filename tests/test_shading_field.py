"""The shading field of the C0 models: the cubic B-spline of the voxels, continued linearly.

References: scipy's ``map_coordinates`` (``order=3``, no prefilter: the voxels are the
coefficients) on the voxels padded by their odd reflection (``2 v[0] - v[1]``), differentiated
by central differences; and what the field must reproduce exactly: a linear function's gradient
everywhere (the continuation is linear), a quadratic's in the interior (the cubic B-spline of a
quadratic's samples is that quadratic plus a constant). A brick's halo (:func:`brick_grid`) and
a pyramid brick's ghost layers give the same gradient as the whole volume.
"""

from __future__ import annotations

import numpy as np

from splinecast.models.shading_field import halo_box, shading_gradients

H = 1e-5


def _scipy_gradient(data, points):
    from scipy import ndimage

    padded = np.pad(np.asarray(data, np.float64), 1, mode="reflect", reflect_type="odd")

    def field(p):
        return ndimage.map_coordinates(padded, (p + 1.0).T, order=3, prefilter=False,
                                       mode="nearest")

    return np.stack([(field(points + H * e) - field(points - H * e)) / (2 * H)
                     for e in np.eye(3)], axis=-1)


def test_gradient_matches_scipy_everywhere_in_the_box():
    rng = np.random.default_rng(5)
    data = rng.random((9, 7, 8)).astype(np.float32)
    top = np.asarray(data.shape) - 1.0
    points = rng.uniform(0.0, 1.0, (400, 3)) * top
    points[:40, 0] = 0.0  # on the faces, where the continuation matters
    points[40:80, 1] = top[1]
    got = shading_gradients(data, points)
    np.testing.assert_allclose(got, _scipy_gradient(data, points), rtol=0, atol=2e-8)


def test_linear_functions_everywhere_and_quadratics_inside_are_exact():
    i, j, k = np.indices((8, 9, 10), dtype=np.float64)
    rng = np.random.default_rng(1)
    points = rng.uniform(0.0, 1.0, (300, 3)) * (np.array([7.0, 8.0, 9.0]))
    linear = 0.3 * i - 1.1 * j + 0.7 * k + 2.0
    np.testing.assert_allclose(shading_gradients(linear, points),
                               np.broadcast_to([0.3, -1.1, 0.7], points.shape), atol=1e-12)
    quad = i * i - 0.5 * j * k + 0.25 * k * k
    inside = points[np.all((points >= 1.0) & (points <= np.array([6.0, 7.0, 8.0])), axis=1)]
    x, y, z = inside.T
    expected = np.stack([2 * x, -0.5 * z, -0.5 * y + 0.5 * z], axis=-1)
    np.testing.assert_allclose(shading_gradients(quad, inside), expected, atol=1e-11)


def test_halo_box_of_a_brick_gives_the_whole_volume_gradient():
    """The gradient read through a brick's halo (a block of the voxels with one more on each
    side where there is one) equals the whole volume's, also at the brick's and the volume's
    faces."""
    from splinecast.models.shading_field import _gradients

    rng = np.random.default_rng(2)
    data = rng.random((12, 10, 11))
    lo, hi = np.array([0, 4, 3]), np.array([6, 9, 8])  # cells [lo, hi) of the brick (9 cells in y)
    a = np.maximum(lo - 1, 0)
    b = np.minimum(hi + 2, data.shape)
    halo = np.ascontiguousarray(data[a[0]:b[0], a[1]:b[1], a[2]:b[2]])
    box = halo_box(lo - a, (0, 0, 0), b - a - 1)
    points = rng.uniform(0.0, 1.0, (200, 3)) * (hi - lo) + lo
    points[:20, 0] = lo[0]
    points[20:40, 1] = hi[1]
    out = np.empty((len(points), 3))
    _gradients(halo, box, points - lo, out)  # grid coordinates of the brick
    np.testing.assert_allclose(out, shading_gradients(data, points), rtol=0, atol=1e-12)
