"""``walk_cells`` (integer-state grid traversal) against an exact rational reference.

The reference (:func:`reference.exact_walk`) computes every plane crossing exactly with
``fractions.Fraction`` on the float inputs and lists the cells whose interior the ray passes
through. Conventions (module docstring of ``splinecast.accel.traversal``): a cell only touched in
an edge or corner is not visited; a ray lying exactly in a cell face belongs to the cell on the
positive side, except on the grid's upper face, which belongs to the last cell.

Random rays use floats drawn at random, so no crossing parameters tie within rounding error (ties
are exercised by the dyadic cases, where the float arithmetic of the traversal is exact).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from reference import exact_walk

from splinecast.accel.traversal import walk_cells


def walk(origin, direction, n_cells, max_cells=100000):
    out = walk_cells(
        np.asarray(origin, dtype=np.float64),
        np.asarray(direction, dtype=np.float64),
        np.asarray(n_cells, dtype=np.int64),
        max_cells,
    )
    return [tuple(int(v) for v in row) for row in out]


def starts_on_plane_moving_down(origin, direction, n_cells):
    """True when the entry point has an integer coordinate strictly inside the grid on an axis
    along which the ray moves to the negative side (the start-cell case of the last test)."""
    o = [Fraction(float(v)) for v in origin]
    d = [Fraction(float(v)) for v in direction]
    t0 = Fraction(0)
    for a in range(3):
        if d[a] != 0:
            t0 = max(t0, min((0 - o[a]) / d[a], (int(n_cells[a]) - o[a]) / d[a]))
    for a in range(3):
        x = o[a] + t0 * d[a]
        if d[a] < 0 and x.denominator == 1 and 0 < x < int(n_cells[a]):
            return True
    return False


def check(origin, direction, n_cells):
    ref = exact_walk(origin, direction, n_cells)
    got = walk(origin, direction, n_cells)
    assert got == ref, (
        f"origin={list(origin)} direction={list(direction)} n_cells={list(n_cells)}\n"
        f"reference ({len(ref)}): {ref[:12]}...\nwalk_cells ({len(got)}): {got[:12]}..."
    )
    return ref


def test_reference_sanity():
    # A few hand-computed walks, to make sure the reference itself means what it should.
    row = [(0, 0, 0), (1, 0, 0), (2, 0, 0)]
    assert exact_walk((0.5, 0.5, 0.5), (1.0, 0.0, 0.0), (3, 2, 2)) == row
    # diagonal through corners: never the side cells
    diagonal = [(0, 0, 0), (1, 1, 1), (2, 2, 2)]
    assert exact_walk((0.5, 0.5, 0.5), (1.0, 1.0, 1.0), (3, 3, 3)) == diagonal
    # lying in the face y = 1: positive side
    assert exact_walk((0.5, 1.0, 0.5), (1.0, 0.0, 0.0), (2, 2, 2)) == [(0, 1, 0), (1, 1, 0)]
    # lying in the upper face y = 2: last cell
    assert exact_walk((0.5, 2.0, 0.5), (1.0, 0.0, 0.0), (2, 2, 2)) == [(0, 1, 0), (1, 1, 0)]
    # starting on the face x = 2, going to -x: cell 2 is never entered
    assert exact_walk((2.0, 0.5, 0.5), (-1.0, 0.0, 0.0), (3, 1, 1)) == [(1, 0, 0), (0, 0, 0)]
    # touches the box in a single point of an edge
    assert exact_walk((-1.0, 1.0, 0.5), (1.0, -1.0, 0.0), (2, 2, 2)) == []


@pytest.mark.parametrize("seed", range(6))
def test_random_rays(seed):
    rng = np.random.default_rng(1000 + seed)
    nonempty = 0
    for _ in range(60):
        n = rng.integers(1, 41, size=3)
        kind = rng.integers(3)
        if kind == 0:  # inside the grid
            origin = rng.uniform(0, 1, 3) * n
        elif kind == 1:  # around the grid
            origin = rng.uniform(-0.5, 1.5, 3) * n
        else:  # far outside, aimed at a random point of the grid
            origin = rng.normal(0, 3, 3) * n
        target = rng.uniform(0, 1, 3) * n
        direction = target - origin if kind == 2 else rng.normal(size=3)
        direction *= rng.choice([1e-3, 1.0, 1e3])
        ref = check(origin, direction, n)
        nonempty += bool(ref)
    assert nonempty >= 20


@pytest.mark.parametrize("seed", range(3))
def test_random_rays_with_zero_components(seed):
    # rays parallel to one or two axes, at random (non-integer) offsets
    rng = np.random.default_rng(2000 + seed)
    for _ in range(60):
        n = rng.integers(1, 41, size=3)
        origin = rng.uniform(-0.3, 1.3, 3) * n
        direction = rng.normal(size=3)
        zero = rng.random(3) < 0.5
        if zero.all():
            zero[rng.integers(3)] = False
        direction[zero] = 0.0
        check(origin, direction, n)


@pytest.mark.parametrize("axis", range(3))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_axis_aligned(axis, sign):
    n = np.array([7, 5, 9])
    direction = np.zeros(3)
    direction[axis] = sign
    origin = np.array([3.25, 2.5, 4.75])
    origin[axis] = -2.0 if sign > 0 else n[axis] + 2.0
    ref = check(origin, direction, n)
    assert len(ref) == n[axis]
    # along a grid line (edge of four cells): the cells on the positive sides
    origin2 = origin.copy()
    others = [a for a in range(3) if a != axis]
    origin2[others] = [2.0, 3.0]
    ref = check(origin2, direction, n)
    assert len(ref) == n[axis]
    assert {(c[others[0]], c[others[1]]) for c in ref} == {(2, 3)}


@pytest.mark.parametrize(
    "direction",
    [
        (1, 1, 1), (1, -1, 1), (-1, 1, 1), (1, 1, -1),
        (-1, -1, -1), (2, 1, 1), (1, 2, -2), (4, -2, 1), (1, 1, 0), (0, -1, 1),
    ],
)
def test_exact_diagonals_through_corners(direction):
    n = np.array([16, 16, 16])
    direction = np.asarray(direction, dtype=np.float64)
    # Start at a corner or cell centre shifted by a dyadic amount: every crossing parameter is a
    # dyadic rational, so ties between axes are exact in floating point too. Starts on a plane
    # moving to its negative side are included (the start-cell case of the last test).
    on_plane_moving_down = 0
    for start in ((0.5, 0.5, 0.5), (8.0, 8.0, 8.0), (8.25, 7.75, 8.5), (0.0, 0.0, 0.0)):
        origin = np.array(start, dtype=np.float64)
        for a in range(3):
            if direction[a] < 0:
                origin[a] = n[a] - origin[a]
        for o in (origin, origin - 40.0 * direction):  # inside, and from outside the grid
            on_plane_moving_down += starts_on_plane_moving_down(o, direction, n)
            assert check(o, direction, n)
    if any(v < 0 for v in direction):
        assert on_plane_moving_down > 0  # the case the start-cell fix is about is exercised

def test_diagonal_through_corners_skips_side_cells():
    ref = check((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0), (5, 5, 5))
    assert ref == [(i, i, i) for i in range(5)]
    ref = check((-1.0, 6.0, -1.0), (1.0, -1.0, 1.0), (5, 5, 5))
    assert ref == [(i, 4 - i, i) for i in range(5)]


def test_rays_through_edges():
    n = (10, 10, 10)
    # crosses the edge x = 3, y = 4 (parallel to z) exactly: never enters (3, 3) or (2, 4)
    check((1.0, 2.0, 0.5), (1.0, 1.0, 0.0), n)
    check((1.0, 2.0, 0.5), (1.0, 1.0, 0.25), n)
    check((5.5, 1.5, 0.25), (-1.0, 1.0, 0.5), n)
    # lies in the plane z = 3 and crosses edges inside it
    check((0.5, 0.25, 3.0), (0.75, 0.75, 0.0), n)
    # along an interior edge line (two zero components, two integer coordinates)
    ref = check((-3.0, 4.0, 7.0), (1.0, 0.0, 0.0), n)
    assert all(c[1:] == (4, 7) for c in ref)


def test_rays_starting_inside():
    n = (12, 9, 7)
    # (decimal directions such as (0.3, -0.7) would make crossings at t = 1.5 / 0.3 and
    # 3.5 / 0.7 differ by less than an ulp: a float traversal cannot order those)
    check((5.5, 4.5, 3.5), (0.3, -0.71, 0.2), n)
    check((0.1, 0.2, 0.3), (-1.0, 0.0, 0.0), n)  # leaves at once
    check((11.9, 8.9, 6.9), (1.0, 1.0, 1.0), n)
    check((3.25, 2.75, 1.5), (-2.0, 1.0, 0.5), n)


def test_rays_that_miss():
    n = (8, 8, 8)
    assert check((-1.0, -1.0, -1.0), (-1.0, 0.3, 0.2), n) == []  # pointing away
    assert check((-1.0, 4.0, 4.0), (0.0, 1.0, 0.0), n) == []  # parallel, outside the slab
    assert check((4.0, 4.0, 9.0), (1.0, 0.5, 0.0), n) == []  # above the grid
    assert check((-1.0, 7.0, 4.0), (1.0, 1.0, 0.0), n) == []  # touches the edge x=0, y=8 only
    assert check((20.0, 20.0, 20.0), (1.0, 1.0, 1.0), n) == []  # grid behind the origin


def test_grazing_bounding_box_faces():
    n = np.array([6, 5, 4])
    # lying in the lower faces: the first cells
    ref = check((-1.0, 0.0, 2.5), (1.0, 0.0, 0.0), n)
    assert [c[1] for c in ref] == [0] * 6
    # lying in the upper faces: the last cells
    ref = check((-1.0, 5.0, 2.5), (1.0, 0.0, 0.0), n)
    assert [c[1] for c in ref] == [4] * 6
    ref = check((6.0, 5.0, -2.0), (0.0, 0.0, 1.0), n)
    assert ref == [(5, 4, k) for k in range(4)]
    # in an upper face, crossing the other axes diagonally
    check((6.0, -1.0, -1.0), (0.0, 1.0, 1.0), n)
    check((6.0, -0.5, -1.0), (0.0, 1.0, 0.75), n)
    # just outside a face: nothing
    assert check((-1.0, -1e-12, 2.5), (1.0, 0.0, 0.0), n) == []
    assert check((-1.0, 5.0 + 1e-12, 2.5), (1.0, 0.0, 0.0), n) == []


def test_long_ray_has_no_drift():
    # ~3000 cells; the last cell and every step must be exact.
    n = np.array([1000, 1000, 1000])
    origin = np.array([-0.37, 0.123456789, 999.71])
    direction = np.array([1.0, 0.987654321, -0.5 * 0.99999])
    ref = check(origin, direction, n)
    assert len(ref) > 2000
    assert ref[-1][0] == 999  # leaves through the x = 1000 face
    # a ray along the main diagonal of a 1000^3 grid through exact corners
    ref = check((-0.5, -0.5, -0.5), (1.0, 1.0, 1.0), n)
    assert ref == [(i, i, i) for i in range(1000)]
    # a nearly axis-aligned ray: one step in y somewhere in the middle
    origin = np.array([-1.0, 500.25, 10.5])
    direction = np.array([1.0, 1.5 / 1001.0, 0.0])
    ref = check(origin, direction, n)
    assert len(ref) == 1001 and ref[0] == (0, 500, 10) and ref[-1] == (999, 501, 10)


def test_max_cells_bound():
    got = walk((0.5, 0.5, 0.5), (1.0, 0.0, 0.0), (50, 1, 1), max_cells=7)
    assert got == [(i, 0, 0) for i in range(7)]


# ------------------------------------------------------------------ start on a plane (fixed bug)
def test_no_zero_length_first_cell_when_starting_on_a_plane():
    """A ray whose entry point lies on an interior grid plane and that moves to the negative side
    never enters the cell on the positive side of that plane.

    ``start_cell`` takes ``floor`` of the entry point regardless of the direction, so such a ray
    first lists the cell on the positive side (touched only in a point, an edge, or a corner) and
    only then the cell it really enters. The docstring of ``walk_cells`` promises that "a cell the
    ray only touches in an edge or corner is not listed". (The face convention "belongs to the
    cell on the positive side" is for rays *lying* in a face, not crossing it.)
    """
    n = (5, 5, 5)
    # enters the grid through the x = 0 face exactly on the grid line y = 3, going to -y:
    # cell (0, 3, 0) is only touched along its edge x = 0, y = 3
    check((-1.0, 3.5, 0.5), (1.0, -0.5, 0.0), n)
    # starts inside on the edge x = 2, y = 2 and goes to -x, +y: (2, 2, 0) is only touched there
    check((2.0, 2.0, 0.5), (-1.0, 1.0, 0.0), n)
    # starts on the face x = 2 going to -x
    check((2.0, 0.5, 0.5), (-1.0, 0.0, 0.0), n)
    # starts on a grid corner going diagonally down in y
    check((2.0, 2.0, 2.0), (1.0, -1.0, 1.0), n)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_subnormal_direction_components_walk_like_the_exact_ray(sign):
    # The walk enters the grid multiplying by 1/d, which overflows for a subnormal d (a NaN
    # entry point where the ray starts on a face). The cells must still be those of the exact
    # ray, which starts on a grid plane here and leaves it to the side its tiny slope points
    # to: out of the grid when that plane is the grid's face on that side.
    for origin in ([-0.5, 2.0, 1.5], [-0.5, 0.0, 1.5], [-0.5, 3.0, 1.5]):
        got = check(origin, [1.0, sign * 5e-310, 0.0], [4, 3, 3])
        leaves = (sign < 0 and origin[1] == 0.0) or (sign > 0 and origin[1] == 3.0)
        assert (len(got) == 0) == leaves
