"""View-dependent chunk selection and chunk reconstruction of spline-wavelet pyramids.

Bricks come from the compiled gather kernel, chunk by chunk. They are checked against
``BSplineModel``'s own coefficients (ε = 0) and against the selection's global spline computed by
a different path — whole-array synthesis with the unselected details zeroed
(:func:`reconstruct` with ``active``), evaluated with ``splinecast.models.bspline.evaluate``.
Bricks are evaluated with the model's cell function ``local_value_gradient``.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.models.bspline import (
    BSpline1Model,
    BSpline2Model,
    BSpline3Model,
    evaluate,
    gradient,
    knot_offset,
    local_value_gradient,
)
from splinecast.multires.wavelet.lod import WHOLE_CHUNK, Selection, select
from splinecast.multires.wavelet.reconstruct import ChunkReconstructor
from splinecast.multires.wavelet.transform import decompose, reconstruct

MODELS = {1: BSpline1Model, 2: BSpline2Model, 3: BSpline3Model}
SHAPE = (29, 26, 23)
CHUNK = 4


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(5)
    return rng.standard_normal(SHAPE)


@pytest.fixture(scope="module", params=(1, 2, 3))
def pyramid(request, data):
    return decompose(data, request.param, chunk=CHUNK)


def brick_values(brick, degree, chunk, points):
    """Value and voxel-space gradient of a brick's spline at world-voxel points (m, 3)."""
    s = (points - brick.origin) / brick.scale + knot_offset(degree)
    cells = np.clip(np.floor(s), 0, chunk - 1).astype(np.int64)
    u = s - cells
    out = np.array([local_value_gradient(brick.coeffs, degree, *cells[i], *u[i])
                    for i in range(len(points))])
    return out[:, 0], out[:, 1:] / brick.scale


def model_padded(window, layout):
    """A selection's level-0 window as a BSplineModel-style padded array (voxel v -> v + pad)."""
    if layout.odd:
        return np.pad(window, layout.pad, mode="reflect")
    return window  # window index i is voxel i - 1 = i - pad


def octant_boxes(layout, level, idx, mask):
    """Voxel boxes (3 x [lo, hi]) drawn by a brick, clipped to the volume."""
    boxes = []
    for octant in range(8):
        if mask != WHOLE_CHUNK and not mask >> octant & 1:
            continue
        if mask == WHOLE_CHUNK and octant:
            break
        box = []
        for a, bit in enumerate(((octant >> 2) & 1, (octant >> 1) & 1, octant & 1)):
            if mask == WHOLE_CHUNK:
                lo, hi = layout.region(level, a, idx[a])
            else:
                lo, hi = layout.region(level - 1, a, 2 * idx[a] + bit)
            box.append((float(lo), float(hi)))
        if all(hi > lo for lo, hi in box):
            boxes.append(box)
    return boxes


def test_epsilon_zero_bricks_are_the_model_coefficients(pyramid, data):
    lay = pyramid.layout
    sel = select(lay, pyramid.ranges, eye=(100.0, 50.0, -20.0), epsilon=0.0)
    assert sel.share == 1.0
    rec = ChunkReconstructor(pyramid)
    rec.update(sel)
    model = MODELS[lay.degree](sc.Volume(data)).coefficients
    pad = lay.pad
    drawn = sel.drawn()
    assert {level for level, _, _ in drawn} == {0}
    assert len(drawn) == np.prod(lay.chunks(0))
    compared = 0
    for level, idx, mask in drawn:
        brick = rec.brick(level, idx, mask)
        voxel = [lay.node_origin(0) + lay.brick_first_node(idx[a]) + np.arange(lay.brick_size)
                 for a in range(3)]
        keep = [np.nonzero((v >= -pad) & (v <= SHAPE[a] - 1 + pad))[0]
                for a, v in enumerate(voxel)]
        rows = [(voxel[a][keep[a]] + pad).astype(int) for a in range(3)]
        np.testing.assert_allclose(brick.coeffs[np.ix_(*keep)], model[np.ix_(*rows)],
                                   rtol=0, atol=1e-12)
        compared += np.prod([len(k) for k in keep])
    assert compared >= model.size  # every model coefficient is in some brick


def mixed_selection(pyramid):
    eye = (-3.0, -2.0, -4.0)
    return select(pyramid.layout, pyramid.ranges, eye=eye, epsilon=0.3)


def test_mixed_bricks_equal_the_global_spline_and_meet_continuously(pyramid):
    """Each drawn region's brick is the selection's global spline; faces between levels agree."""
    lay = pyramid.layout
    d = lay.degree
    sel = mixed_selection(pyramid)
    rec = ChunkReconstructor(pyramid)
    rec.update(sel)
    drawn = sel.drawn()
    levels = {level for level, _, _ in drawn}
    assert len(levels) >= 2, levels
    global_coeffs = model_padded(reconstruct(pyramid, 0, active=sel.active), lay)
    rng = np.random.default_rng(d)
    regions = []
    for level, idx, mask in drawn:
        brick = rec.brick(level, idx, mask)
        for box in octant_boxes(lay, level, idx, mask):
            regions.append((level, brick, box))
            pts = np.stack([rng.uniform(lo, hi, 25) for lo, hi in box], axis=1)
            value, grad = brick_values(brick, d, lay.chunk, pts)
            np.testing.assert_allclose(value, evaluate(global_coeffs, d, pts), atol=1e-9)
            if d > 1:
                np.testing.assert_allclose(grad, gradient(global_coeffs, d, pts), atol=1e-9)
    # The drawn regions tile the volume's box.
    volume = sum(np.prod([hi - lo for lo, hi in box]) for _, _, box in regions)
    assert volume == pytest.approx(np.prod(np.array(SHAPE) - 1.0))
    # Faces shared by two regions of different levels: both sides agree.
    faces = 0
    for i, (la, ba, box_a) in enumerate(regions):
        for lb, bb, box_b in regions[i + 1:]:
            if la == lb:
                continue
            for axis in range(3):
                if box_a[axis][1] == box_b[axis][0] or box_b[axis][1] == box_a[axis][0]:
                    plane = box_a[axis][1] if box_a[axis][1] == box_b[axis][0] else box_a[axis][0]
                    other = [a for a in range(3) if a != axis]
                    span = [(max(box_a[a][0], box_b[a][0]), min(box_a[a][1], box_b[a][1]))
                            for a in other]
                    if any(hi <= lo for lo, hi in span):
                        continue
                    pts = np.empty((12, 3))
                    pts[:, axis] = plane
                    for a, (lo, hi) in zip(other, span, strict=True):
                        pts[:, a] = rng.uniform(lo, hi, 12)
                    va, ga = brick_values(ba, d, lay.chunk, pts)
                    vb, gb = brick_values(bb, d, lay.chunk, pts)
                    np.testing.assert_allclose(va, vb, atol=1e-9)
                    if d > 1:
                        np.testing.assert_allclose(ga, gb, atol=1e-9)
                    faces += 1
    assert faces > 0


def test_cache_equals_fresh_reconstruction_along_a_path(pyramid):
    lay = pyramid.layout
    path = [((-3.0, -2.0, -4.0), 0.3), ((30.0, 28.0, 25.0), 0.3), ((-3.0, -2.0, -4.0), 0.6),
            ((10.0, 12.0, 11.0), 0.15)]
    cached = ChunkReconstructor(pyramid)
    for eye, eps in path:
        sel = select(lay, pyramid.ranges, eye=eye, epsilon=eps)
        cached.update(sel)
        fresh = ChunkReconstructor(pyramid)
        fresh.update(sel)
        for level, idx, _ in sel.drawn():
            np.testing.assert_array_equal(cached.brick(level, idx).coeffs,
                                          fresh.brick(level, idx).coeffs)
        again = cached.update(sel)
        assert sum(again.computed) == 0
        assert sum(again.reused) == sum(r.sum() for r in sel.reconstructed[:-1])


def test_lowering_costs_nothing_and_refining_starts_from_present_levels(pyramid):
    """Dropping the finest level computes nothing; adding level-0 detail computes level 0 only."""
    lay = pyramid.layout
    full = mixed_selection(pyramid)
    assert full.active[0].any() and full.active[1].any()
    rec = ChunkReconstructor(pyramid)
    rec.update(full)
    coarser = Selection.from_active(lay, [np.zeros_like(full.active[0])] + full.active[1:])
    stats = rec.update(coarser)
    assert sum(stats.computed) == 0
    assert 0 not in {level for level, _, _ in coarser.drawn()}
    # Refine one more level-0 chunk whose parent is active: only level 0 is computed.
    candidates = np.argwhere(~full.active[0] & np.repeat(np.repeat(np.repeat(
        full.active[1], 2, 0), 2, 1), 2, 2)[:lay.chunks(0)[0], :lay.chunks(0)[1],
                                            :lay.chunks(0)[2]])
    finer_active = [a.copy() for a in full.active]
    finer_active[0][tuple(candidates[0])] = True
    finer = Selection.from_active(lay, finer_active)
    stats = rec.update(finer)
    assert stats.computed[0] > 0
    assert sum(stats.computed[1:]) == 0
    fresh = ChunkReconstructor(pyramid)
    fresh.update(finer)
    for level, idx, _ in finer.drawn():
        np.testing.assert_array_equal(rec.brick(level, idx).coeffs,
                                      fresh.brick(level, idx).coeffs)


def test_epsilon_lowers_the_share_monotonically(pyramid):
    lay = pyramid.layout
    shares = [select(lay, pyramid.ranges, eye=(60.0, 40.0, 30.0), epsilon=e).share
              for e in (0.0, 0.05, 0.1, 0.2, 0.4, 1.0, 10.0)]
    assert shares[0] == 1.0
    assert all(a >= b for a, b in zip(shares, shares[1:], strict=False))
    assert shares[-1] == pytest.approx(1 / lay.chunk_total())


@pytest.mark.parametrize("degree", (1, 3))
def test_detail_outside_the_iso_range_is_never_reconstructed(degree):
    vol = sc.demo("sphere", size=33)
    iso = 0.0
    pyramid = decompose(vol.data, degree, chunk=CHUNK)
    lay = pyramid.layout
    lo, hi = pyramid.ranges
    rec = ChunkReconstructor(pyramid)
    used = [np.zeros(lay.chunks(j), dtype=bool) for j in range(lay.levels)]
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    for eye_voxel, eps in (((-5, 16, 16), 0.0), ((16, 40, 3), 0.05), ((16, 16, 16), 0.2)):
        sel = select(lay, pyramid.ranges, eye=origin + np.asarray(eye_voxel) * spacing,
                     epsilon=eps, iso=iso, spacing=spacing, origin=origin)
        stats = rec.update(sel)
        for j in range(lay.levels):
            used[j] |= stats.detail_owners[j]
    outside = [(lo[j] > iso) | (hi[j] < iso) for j in range(lay.levels)]
    assert sum(o.sum() for o in outside) > 0  # the test can fail
    assert sum(u.sum() for u in used) > 0
    for j in range(lay.levels):
        assert not np.any(used[j] & outside[j]), f"level {j}"
    # Skipping is not vacuous: chunks outside the range own non-zero details ...
    level = 0
    owned = np.zeros(lay.chunks(level), dtype=bool)
    for band in pyramid.details[1].values():
        band = np.abs(np.asarray(band))
        for idx in np.argwhere(outside[level]):
            sl = tuple(slice(CHUNK // 2 * i, CHUNK // 2 * (i + 1)) for i in idx)
            if band[sl].size and band[sl].max() > 1e-9:
                owned[tuple(idx)] = True
    assert owned.any()
    # ... and the full-resolution spline has no surface on their regions (the range is
    # conservative), sampled densely with the model's own evaluation.
    model = MODELS[degree](vol)
    rng = np.random.default_rng(0)
    for idx in np.argwhere(outside[level])[::7]:
        box = [lay.region(level, a, idx[a]) for a in range(3)]
        pts = np.stack([rng.uniform(float(b[0]), float(b[1]), 400) for b in box], axis=1)
        values = model.evaluate(pts)
        assert np.all(values > iso) or np.all(values < iso)


def test_user_mistakes_raise_parameter_errors():
    pyramid = decompose(np.zeros((9, 9, 9)), 3, chunk=4)
    lay = pyramid.layout
    with pytest.raises(sc.ParameterError, match="epsilon"):
        select(lay, pyramid.ranges, (0, 0, 0), -1.0)
    orphan = [np.zeros(lay.chunks(j), dtype=bool) for j in range(lay.levels)]
    orphan[0][0, 0, 0] = True  # its parent on level 1 is inactive
    if lay.levels > 1:
        with pytest.raises(sc.ParameterError, match="inactive parent"):
            Selection.from_active(lay, orphan)
    with pytest.raises(sc.ParameterError, match="degree"):
        decompose(np.zeros((9, 9, 9)), 4)
