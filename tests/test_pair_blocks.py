"""The 2-cell blocks below the hierarchy's finest level (``accel.minmax``'s pair level).

Their flags for an isovalue come from 8-bit ranges quantized within their 4-cell block's range.
They are checked against a brute-force reference (the min and max of each 2-cell block's
coefficient window, in numpy), where they must flag every block that can hold the isovalue,
ties included, and few others. The isosurface renders with and without the pair level are
compared bit for bit: leaping a 2-cell block changes where a ray walks, never what it finds.
"""

from __future__ import annotations

import numpy as np
import pytest
from reference import marschner_lobb, smooth_noise, sphere_distance

import splinecast as sc
from splinecast.accel.minmax import MinMaxHierarchy, inactive_pair_size


def reference_pair_flags(coeffs: np.ndarray, support: int, n_cells: tuple, iso: float
                         ) -> np.ndarray:
    """1 where a 2-cell block's coefficient window (cells 2p, 2p + 1 read coefficients
    ``2p .. 2p + 1 + support`` per axis) holds values on both sides of ``iso``, or equal."""
    shape = tuple((n + 1) // 2 for n in n_cells)
    out = np.zeros(shape, np.uint8)
    c = coeffs.astype(np.float64)
    for p in np.ndindex(shape):
        w = c[tuple(slice(2 * q, 2 * q + 2 + support) for q in p)]
        out[p] = w.min() <= iso <= w.max()
    return out


def reference_block_ranges(coeffs: np.ndarray, support: int, n_cells: tuple
                           ) -> tuple[np.ndarray, np.ndarray]:
    shape = tuple((n + 3) // 4 for n in n_cells)
    lo, hi = np.empty(shape), np.empty(shape)
    c = coeffs.astype(np.float64)
    for b in np.ndindex(shape):
        w = c[tuple(slice(4 * q, 4 * q + 4 + support) for q in b)]
        lo[b], hi[b] = w.min(), w.max()
    return lo, hi


def volumes(rng: np.random.Generator) -> list[tuple[str, np.ndarray]]:
    noise = rng.random((13, 10, 11))
    steps = np.round(rng.random((17, 9, 14)) * 4) / 4  # ties between many values and the iso
    flat = np.full((9, 9, 9), 0.25)
    flat[6:, 6:, 6:] = 0.75  # blocks of one value, and a block with two
    huge = rng.uniform(-1.0, 1.0, (11, 7, 12)) * 1.7e308  # a width beyond float64: overflows
    return [("noise", noise), ("noise f32", noise.astype(np.float32)), ("steps", steps),
            ("uint8", (rng.random((10, 13, 9)) * 255).astype(np.uint8)), ("flat", flat),
            ("huge", huge), ("tiny", rng.random((3, 4, 5)))]


@pytest.mark.parametrize("support", [1, 2, 3])
def test_pair_flags_hold_every_block_that_can_hold_the_isovalue(support):
    rng = np.random.default_rng(support)
    extra = total = 0
    for name, coeffs in volumes(rng):
        n_cells = tuple(s - support for s in coeffs.shape)
        if min(n_cells) < 1:
            continue
        h = MinMaxHierarchy(coeffs, n_cells, support)
        lo, hi = reference_block_ranges(coeffs, support, n_cells)
        np.testing.assert_array_equal(h.lows[0], lo, err_msg=name)
        np.testing.assert_array_equal(h.highs[0], hi, err_msg=name)
        values = coeffs.astype(np.float64).ravel()
        u = rng.random(4)  # between the extremes, without their difference (it may overflow)
        isos = [*rng.choice(values, 12), *(values.min() * (1 - u) + values.max() * u)]
        for iso in isos:
            flags = h.classify(float(iso))
            assert len(flags) == 4
            got = flags[3]
            want = reference_pair_flags(coeffs, support, n_cells, float(iso))
            # only inside the active 4-cell blocks (the walk asks nothing finer elsewhere)
            inside = np.kron(flags[0], np.ones((2, 2, 2), np.uint8))[
                tuple(slice(0, s) for s in want.shape)].astype(bool)
            assert got.shape == want.shape, name
            missed = want.astype(bool) & inside & ~got.astype(bool)
            assert not missed.any(), (name, float(iso), np.argwhere(missed)[:3])
            assert not (got.astype(bool) & ~inside).any(), name
            extra += int((got.astype(bool) & ~want.astype(bool)).sum())
            total += int(inside.sum())
    # The 8-bit levels flag a few blocks more than the exact ranges would (the level of a
    # value rounds outwards), and no more than a few.
    assert extra <= 0.05 * total, (extra, total)


def _packed_in_numpy(pairs: np.ndarray, shape: tuple) -> np.ndarray:
    """One byte per 4-cell block, bit 4 * (pi % 2) + 2 * (pj % 2) + pk % 2 for pair (pi, pj, pk)."""
    out = np.zeros(shape, np.uint8)
    for pi, pj, pk in np.argwhere(pairs != 0):
        out[pi // 2, pj // 2, pk // 2] |= 1 << (4 * (pi % 2) + 2 * (pj % 2) + pk % 2)
    return out


def test_packed_pair_flags_hold_the_pairs_bit_by_bit():
    """The walk reads the pair flags packed per 4-cell block: those made with the flags, and
    those packed later (flags from elsewhere), equal a packing in numpy; and the walk's block
    question (``inactive_pair_size``) answers 2 exactly for the cells of unflagged pairs in
    active blocks."""
    rng = np.random.default_rng(11)
    for name, coeffs in volumes(rng):
        n_cells = tuple(s - 1 for s in coeffs.shape)
        if min(n_cells) < 1:
            continue
        h = MinMaxHierarchy(coeffs, n_cells, 1)
        iso = float(np.median(coeffs))
        flags = h.classify(iso)
        want = _packed_in_numpy(flags[3], flags[0].shape)
        assert np.array_equal(h.packed_pairs(flags[3], flags[0]), want), name
        other = (rng.random(flags[3].shape) < 0.4).astype(np.uint8)
        assert np.array_equal(h.packed_pairs(other, flags[0]),
                              _packed_in_numpy(other, flags[0].shape)), name
        packed = h.packed_pairs(flags[3], flags[0])
        for i, j, k in rng.integers(0, n_cells, size=(200, 3)):
            size = inactive_pair_size(*flags[:3], packed, int(i), int(j), int(k))
            if size in (0, 2):
                assert size == (0 if flags[3][i // 2, j // 2, k // 2] else 2), name
            else:  # a leap: no pair of the cell's 4-cell block is flagged
                a, b, c = 2 * (i // 4), 2 * (j // 4), 2 * (k // 4)
                assert not flags[3][a:a + 2, b:b + 2, c:c + 2].any(), name


def test_pair_flags_are_kept_for_the_same_isovalue():
    coeffs = np.random.default_rng(0).random((12, 12, 12))
    h = MinMaxHierarchy(coeffs, (11, 11, 11), 1)
    first = h.classify(0.5)[3]
    assert h.classify(0.5)[3] is first
    assert h.classify(0.25)[3] is not first


def without_pairs(scene, cam, iso, **kw):
    """The frame rendered with the hierarchy's pair level taken away (4-cell blocks only)."""
    scene.render(cam, iso=iso, **kw)  # classifies the blocks for iso
    saved = scene.hierarchy.active
    assert saved[3].size > 0
    scene.hierarchy.active = saved[:3]
    try:
        return scene.render(cam, iso=iso, **kw)  # same iso: these flags are used
    finally:
        scene.hierarchy.active = saved


def pair_volumes() -> dict[str, tuple[sc.Volume, float]]:
    data, spacing, origin = marschner_lobb(41)
    blob = sphere_distance((41, 37, 45), (20.3, 17.7, 22.9), 9.0).astype(np.float32)
    # quantized: many voxels exactly at the isovalue, so 2-cell blocks touch it in a corner
    steps = np.round(smooth_noise((33, 33, 33), seed=4) * 8) / 8
    return {"ml": (sc.Volume(data, spacing=spacing, origin=origin), 0.5),
            "blob": (sc.Volume(blob, metadata={"inside": "low"}), 0.0),
            "steps": (sc.Volume(steps), 0.5)}


@pytest.mark.parametrize("model", ["trilinear", "bspline2", "bspline3"])
@pytest.mark.parametrize("name", ["ml", "blob", "steps"])
def test_leaping_2_cell_blocks_changes_no_hit(name, model):
    vol, iso = pair_volumes()[name]
    scene = sc.Scene(vol, model=model)
    cam = sc.Camera.orbit(vol, azimuth=31, elevation=22, size=(48, 40), zoom=1.2)
    fast = scene.render(cam, iso=iso)
    slow = without_pairs(scene, cam, iso)
    assert fast.hit.sum() > 100
    for out in ("depth", "position", "normal", "face", "rgba", "cells_tested"):
        np.testing.assert_array_equal(getattr(fast, out), getattr(slow, out), err_msg=out)
    # the pair level took effect: fewer cells visited (a tenth fewer or more where the
    # surface is sparse; Marschner-Lobb's fills most 4-cell blocks it meets), more leaps
    share = 0.98 if name == "ml" else 0.9
    assert fast.cells_visited.sum() < share * slow.cells_visited.sum()
    assert fast.blocks_skipped.sum() > slow.blocks_skipped.sum()


def test_sampled_method_and_type6_models_have_no_pair_level():
    vol, iso = pair_volumes()["ml"]
    cam = sc.Camera.orbit(vol, azimuth=31, elevation=22, size=(24, 20))
    scene = sc.Scene(vol)
    exact = scene.render(cam, iso=iso)
    sampled = scene.render(cam, iso=iso, method="sampled")
    slow = without_pairs(scene, cam, iso, method="sampled")
    np.testing.assert_array_equal(sampled.depth, slow.depth)
    np.testing.assert_array_equal(sampled.cells_visited, slow.cells_visited)
    assert exact.cells_visited.sum() < sampled.cells_visited.sum()
    assert sc.Scene(vol, model="s31").hierarchy.classify(iso)[3].size == 0


@pytest.mark.parametrize("model", ["s31", "qss"])
@pytest.mark.parametrize("name", ["ml", "blob", "steps"])
def test_type6_active_pairs_change_no_hit(name, model):
    """The type-6 models' own classification (active cubes) flags the 2-cell blocks too: the
    frame is the one leaping 4-cell blocks only, bit for bit, with fewer cubes visited."""
    vol, iso = pair_volumes()[name]
    scene = sc.Scene(vol, model=model)
    cam = sc.Camera.orbit(vol, azimuth=31, elevation=22, size=(48, 40), zoom=1.2)
    fast = scene.render(cam, iso=iso)
    flags = scene._iso_flags()
    assert len(flags) == 5 and flags[3].any()
    scene._iso_flags = lambda: flags[:3]  # the 4-cell blocks only
    slow = scene.render(cam, iso=iso)
    assert fast.hit.sum() > 100
    for out in ("depth", "position", "normal", "face", "rgba", "cells_tested"):
        np.testing.assert_array_equal(getattr(fast, out), getattr(slow, out), err_msg=out)
    assert fast.cells_visited.sum() < 0.9 * slow.cells_visited.sum()
    assert fast.blocks_skipped.sum() > slow.blocks_skipped.sum()
