"""``walk_step_cached`` (the driver's walk) against ``walk_step``, step by step.

The cached step keeps each axis's last plane and its crossing parameter and divides only for an
axis whose plane changed. The parameters are the same divisions of the same numbers, so every
step must return exactly what :func:`walk_step` returns: the segment's end, whether the ray goes
on, the next cell and where it is entered. The walks mix cell steps with leaps over blocks of
2 to 16 cells (the renderer's empty-space skipping), in an order drawn at random, on random
rays and on rays whose crossings tie (through edges and corners, along axes, in faces).
"""

from __future__ import annotations

import numpy as np
import pytest

from splinecast._jit import jit
from splinecast.accel.traversal import walk_begin, walk_step, walk_step_cached

_SIZES = np.array([1, 1, 1, 2, 4, 8, 16], np.int64)


@jit()
def _walks(o, d, n, size_draws):
    """Both walks of one ray, each step's ``(t_end, more, i, j, k, t_next)`` as rows."""
    ox, oy, oz, dx, dy, dz = o[0], o[1], o[2], d[0], d[1], d[2]
    nx, ny, nz = n[0], n[1], n[2]
    m = size_draws.shape[0]
    plain = np.full((m, 6), np.nan)
    cached = np.full((m, 6), np.nan)
    for which in range(2):
        out = plain if which == 0 else cached
        inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz)
        planes = (-2, 0.0, -2, 0.0, -2, 0.0)
        step = 0
        while inside and step < m:
            size = size_draws[step]
            if which == 0:
                t_end, inside, ni, nj, nk, t_next = walk_step(
                    (ox, oy, oz), (dx, dy, dz), (nx, ny, nz), ci, cj, ck, t, t_far, size)
            else:
                t_end, inside, ni, nj, nk, t_next, planes = walk_step_cached(
                    (ox, oy, oz), (dx, dy, dz), (nx, ny, nz), ci, cj, ck, t, t_far, size,
                    planes)
            out[step, 0] = t_end
            out[step, 1] = 1.0 if inside else 0.0
            out[step, 2], out[step, 3], out[step, 4] = ni, nj, nk
            out[step, 5] = t_next
            ci, cj, ck, t = ni, nj, nk, t_next
            step += 1
    return plain, cached


def _check(origin, direction, n_cells, rng, leaps=True):
    draws = rng.choice(_SIZES if leaps else _SIZES[:1], size=4000)
    plain, cached = _walks(np.asarray(origin, np.float64), np.asarray(direction, np.float64),
                           np.asarray(n_cells, np.int64), draws)
    steps = int(np.count_nonzero(~np.isnan(plain[:, 0])))
    assert steps > 0
    np.testing.assert_array_equal(cached, plain)
    return steps


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("leaps", [False, True])
def test_random_rays_walk_identically(seed, leaps):
    rng = np.random.default_rng(seed)
    n_cells = rng.integers(5, 70, size=3)
    total = 0
    for _ in range(150):
        # Origins outside and inside the grid, directions of every sign.
        origin = rng.uniform(-30.0, 100.0, size=3)
        target = rng.uniform(0.0, 1.0, size=3) * n_cells
        direction = target - origin
        if not np.any(direction):
            continue
        total += _check(origin, direction, n_cells, rng, leaps)
    assert total > 300  # the rays do cross the grid


@pytest.mark.parametrize("direction", [
    (1.0, 1.0, 1.0), (-1.0, 1.0, 1.0), (1.0, -1.0, 0.5), (0.5, 0.25, -1.0),  # corners, edges
    (1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0),  # along axes
    (1.0, 1.0, 0.0), (0.0, -0.5, 1.0),  # in faces
])
@pytest.mark.parametrize("start", [(0.0, 0.0, 0.0), (3.0, 2.0, 5.0), (2.5, 4.0, 1.25)])
def test_tied_crossings_walk_identically(direction, start):
    """Dyadic rays: crossings on two or three axes at once, exactly (the ties of the walk)."""
    rng = np.random.default_rng(7)
    n_cells = (32, 32, 32)
    d = np.asarray(direction)
    origin = np.asarray(start) + 16.0 - 40.0 * d  # enters the grid through a face or edge
    for leaps in (False, True):
        _check(origin, d, n_cells, rng, leaps)

