"""The screen footprint of the active blocks (render/footprint.py).

Two checks against independent references: every pixel ray that meets an active block's box
(a slab test in numpy, on the rays of ``Camera.rays``) meets it inside its tile's interval; and
frames rendered with the footprint are bit-identical to frames rendered without it, for every
exact isosurface model, perspective and orthographic cameras, an eye inside the volume, an
image tile, several translucent isosurfaces and DVR's three samplings.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from reference import box_interval

import splinecast as sc
import splinecast.scene as scene_module
from splinecast.accel.minmax import BLOCK_SHIFTS, PAIR_SHIFT
from splinecast.render import footprint as footprint_module
from splinecast.render import segment
from splinecast.render.footprint import FOOTPRINT_SHIFT, block_footprint
from splinecast.render.iso import Iso
from splinecast.render.mip import Mip
from splinecast.render.rays import GEOM_ORIGIN, GEOM_SIZE, GEOM_SPACING

SHIFT = 2  # blocks of 4 cells


def _cameras(vol):
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    centre = origin + 0.5 * (np.asarray(vol.shape) - 1) * spacing
    return {
        "perspective": sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(72, 56)),
        "orthographic": sc.Camera.orbit(vol, azimuth=-60, elevation=40, size=(72, 56),
                                        ortho=True),
        "eye inside": sc.Camera(centre + 0.1 * spacing * np.asarray(vol.shape),
                                centre + (5.0, 3.0, 1.0), size=(64, 48), fov=70),
        "tile": sc.Camera.orbit(vol, azimuth=200, elevation=-30, size=(96, 80),
                                zoom=1.6).tile(13, 21, 50, 37),
    }


@pytest.mark.parametrize("shift", [SHIFT, PAIR_SHIFT])
@pytest.mark.parametrize("view", ["perspective", "orthographic", "eye inside", "tile"])
def test_every_ray_meeting_an_active_block_meets_it_inside_its_tiles_interval(view, shift):
    vol = sc.Volume(np.zeros((25, 21, 17), np.float32), spacing=(0.7, 1.0, 1.3),
                    origin=(-3.0, 2.0, 0.5))
    cam = _cameras(vol)[view]
    n_cells = (24, 20, 16)
    edge = 1 << shift
    rng = np.random.default_rng(7)
    blocks = tuple(-(-n // edge) for n in n_cells)
    # About as many active boxes at either size (a fifth of the 4-cell blocks).
    active = (rng.random(blocks) < 0.2 * (edge / 4) ** 3).astype(np.uint8)
    geom = np.zeros(GEOM_SIZE)
    geom[GEOM_ORIGIN:GEOM_ORIGIN + 3] = vol.origin
    geom[GEOM_SPACING:GEOM_SPACING + 3] = vol.spacing
    fp = block_footprint(cam.pixel_basis(), geom, n_cells, active, shift, cam.width, cam.height)
    origins, directions = cam.rays()
    col0, row0 = (int(v) for v in cam.pixel_basis()[16:18])  # a tile's place in the image
    rows = ((np.arange(cam.height) + row0) >> FOOTPRINT_SHIFT) - (row0 >> FOOTPRINT_SHIFT)
    cols = ((np.arange(cam.width) + col0) >> FOOTPRINT_SHIFT) - (col0 >> FOOTPRINT_SHIFT)
    tiles = fp[rows[:, None], cols[None, :]]
    met = 0
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    for b in np.argwhere(active):
        lo = origin + b * edge * spacing
        hi = origin + np.minimum((b + 1) * edge, n_cells) * spacing
        t0, t1 = (a.reshape(cam.height, cam.width) for a in
                  box_interval(origins.reshape(-1, 3), directions.reshape(-1, 3), lo, hi))
        hit = t0 <= t1
        met += int(hit.sum())
        assert np.all(tiles[hit, 0] <= t0[hit]), f"block {b} entered before its tile's interval"
        assert np.all(tiles[hit, 1] >= t1[hit]), f"block {b} left after its tile's interval"
    assert met > 50  # the check saw rays meeting blocks
    if view == "tile":  # the same intervals as the full image's tiles: tiles render alike
        full = _cameras(vol)["tile"]
        whole = sc.Camera.orbit(vol, azimuth=200, elevation=-30, size=(96, 80), zoom=1.6)
        fp_whole = block_footprint(whole.pixel_basis(), geom, n_cells, active, shift,
                                   whole.width, whole.height)
        ty0, tx0 = row0 >> FOOTPRINT_SHIFT, col0 >> FOOTPRINT_SHIFT
        assert np.array_equal(fp, fp_whole[ty0:ty0 + fp.shape[0], tx0:tx0 + fp.shape[1]])
        assert full.width == cam.width
    empty = fp[..., 0] > fp[..., 1]
    if view in ("perspective", "orthographic"):  # the whole volume in view
        assert empty.any(), "a few active blocks should leave some tiles empty"


def _without_footprint(monkeypatch):
    monkeypatch.setattr(scene_module, "render_grid",
                        functools.partial(segment.render_grid, footprint=False))


@pytest.mark.parametrize("model", ["trilinear", "s31", "bspline3"])
def test_frames_are_identical_with_and_without_the_footprint(model, monkeypatch):
    vol = sc.demo("torus", size=33)
    iso = vol.metadata["default_iso"]
    scene = sc.Scene(vol, model=model)
    outputs = ("rgba", "depth", "position", "normal", "face")
    with_fp = {v: scene.render(c, iso=iso, outputs=outputs)
               for v, c in _cameras(vol).items()}
    _without_footprint(monkeypatch)
    for view, cam in _cameras(vol).items():
        plain = scene.render(cam, iso=iso, outputs=outputs)
        assert np.isfinite(plain.depth).sum() > 20, view
        for name in outputs:
            a, b = getattr(plain, name), getattr(with_fp[view], name)
            assert np.array_equal(a, b, equal_nan=True), f"{view}: {name} differs"


def test_blocks_behind_the_eye_cover_no_tile():
    """A camera looking away from the volume: every block lies behind the eye's plane, and no
    ray (``t >= 0``) meets one, so no tile gets an interval (such blocks used to cover the
    whole screen, and every ray was traced). Reference: slab tests of the rays against every
    block box find no intersection either."""
    vol = sc.Volume(np.zeros((25, 21, 17), np.float32), spacing=(0.7, 1.0, 1.3),
                    origin=(-3.0, 2.0, 0.5))
    n_cells = (24, 20, 16)
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    centre = origin + 0.5 * np.asarray(n_cells) * spacing
    eye = centre + (0.0, 0.0, -30.0)
    geom = np.zeros(GEOM_SIZE)
    geom[GEOM_ORIGIN:GEOM_ORIGIN + 3] = vol.origin
    geom[GEOM_SPACING:GEOM_SPACING + 3] = vol.spacing
    active = np.ones(tuple(-(-n // 4) for n in n_cells), np.uint8)
    for ortho in (False, True):
        cam = sc.Camera(eye, eye + (0.3, -0.2, -1.0), size=(40, 32), fov=70, ortho=ortho,
                        ortho_height=20.0)
        origins, directions = cam.rays()
        t0, t1 = box_interval(origins.reshape(-1, 3), directions.reshape(-1, 3), origin,
                              origin + np.asarray(n_cells) * spacing)
        assert not np.any(t0 <= t1)  # no ray meets the volume's box
        fp = block_footprint(cam.pixel_basis(), geom, n_cells, active, SHIFT, cam.width,
                             cam.height)
        assert np.all(fp[..., 0] > fp[..., 1]), f"ortho={ortho}: a tile got an interval"
        # The eye turned round towards the volume: the blocks cover tiles again.
        back = sc.Camera(eye, centre, size=(40, 32), fov=70, ortho=ortho, ortho_height=20.0)
        fp = block_footprint(back.pixel_basis(), geom, n_cells, active, SHIFT, back.width,
                             back.height)
        assert np.any(fp[..., 0] <= fp[..., 1])


@pytest.mark.parametrize("kind", ["mip", "minip"])
def test_mip_frames_are_identical_with_and_without_the_footprint(kind, monkeypatch):
    """MIP's footprint is the volume's box (every block, coarsest level): values, depths and
    positions are the ones without it, for every view, and a zoomed-out view leaves tiles
    untraced (the footprint is in use)."""
    vol = sc.demo("marschner-lobb", size=30)
    scene = sc.Scene(vol)
    cams = {**_cameras(vol),
            "far": sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(72, 56), zoom=0.3)}
    outputs = ("value", "depth", "position")
    with_fp = {v: scene.render(c, mode=kind, outputs=outputs) for v, c in cams.items()}
    blocks = Mip(kind=kind).blocks(scene.grid.hierarchy)
    tiles = segment.screen_footprint(scene.grid, Mip(kind=kind), cams["far"], blocks)
    assert tiles.shape[0] > 0 and np.any(tiles[..., 0] > tiles[..., 1])
    _without_footprint(monkeypatch)
    for view, cam in cams.items():
        plain = scene.render(cam, mode=kind, outputs=outputs)
        assert np.isfinite(plain.value).sum() > 20, view
        for name in outputs:
            a, b = getattr(plain, name), getattr(with_fp[view], name)
            assert np.array_equal(a, b, equal_nan=True), f"{view}: {name} differs"


def _blob_in_air(floor: float, sign: float, dtype: str) -> sc.Volume:
    """A lumpy blob in the middle of a box whose outer layers all hold ``floor`` (air, as
    around a head in an MRI): brighter than the air for MIP (``sign`` 1), darker for minIP."""
    n = (44, 38, 36)
    x, y, z = np.meshgrid(*(np.linspace(-1.0, 1.0, m) for m in n), indexing="ij")
    r = np.sqrt((x / 0.55) ** 2 + (y / 0.5) ** 2 + (z / 0.45) ** 2)
    blob = np.clip(1.0 - r, 0.0, None) * (1.0 + 0.4 * np.sin(9.0 * x) * np.cos(7.0 * y + z))
    data = floor + sign * 180.0 * blob / blob.max()
    return sc.Volume(np.round(data).astype(dtype), spacing=(0.9, 1.0, 1.2),
                     origin=(-2.0, 1.0, 0.5))


_AIR_CASES = [(kind, dtype, floor, "trilinear", method)
              for kind, dtype, floor in [("mip", "uint8", 0.0), ("mip", "float32", -1024.0),
                                         ("minip", "uint8", 255.0)]
              for method in ("exact", "sampled", "slices")]
_AIR_CASES += [("mip", "uint8", 0.0, "bspline3", "exact")]


@pytest.mark.parametrize("kind, dtype, floor, model, method", _AIR_CASES)
def test_mip_rays_through_air_start_at_the_blocks_above_it(kind, dtype, floor, model, method,
                                                           monkeypatch):
    """MIP's footprint names the blocks holding a value above the grid's smallest (below its
    largest, minIP): rays start and end there, and rays crossing only air get the air's value
    at their entry. Values, depths and positions are the ones without a footprint, for every
    view (a clip plane through the blob among them); the footprint does cut the rays' fronts
    and leaves tiles to their entry only; and the pixels that see only air are there to
    compare (their value is the floor, not a miss).
    The cubic B-spline's values are sums of the voxels' (zeros in the air); the ranges of the
    s31 model's blocks round 4e-11 below the air, so nothing is left out there."""
    sign = 1.0 if kind == "mip" else -1.0
    vol = _blob_in_air(floor, sign, dtype)
    scene = sc.Scene(vol, model=model)
    cams = {**_cameras(vol),
            "far": sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(72, 56), zoom=0.6)}
    options = {"mode": kind, "method": method, "outputs": ("value", "depth", "position")}
    if method != "exact":
        options["step"] = 1.5
    # A clip plane through the blob: rays enter the volume inside it or in the air.
    centre = np.asarray(vol.origin) + 0.5 * (np.asarray(vol.shape) - 1) * np.asarray(vol.spacing)
    normal = np.array([1.0, 0.4, -0.3])
    clip = {"clip": [(*normal, -float(normal @ centre))]}
    views = {**{v: (c, {}) for v, c in cams.items()}, "clipped": (cams["perspective"], clip)}
    with_fp = {v: scene.render(c, **options, **extra) for v, (c, extra) in views.items()}
    mode = Mip(kind=kind, method=method, step=1.5)
    blocks = mode.blocks(scene.grid.hierarchy)
    cam = cams["perspective"]
    tiles = segment.screen_footprint(scene.grid, mode, cam, blocks)
    box = block_footprint(cam.pixel_basis(), scene.grid.geom, scene.grid.n_cells,
                          np.ones(blocks[2].shape, np.uint8), BLOCK_SHIFTS[-1], cam.width,
                          cam.height)
    seen = box[..., 0] <= box[..., 1]
    assert np.any(tiles[seen, 0] == footprint_module.ENTRY_ONLY), "no tile of air only"
    cut = seen & (tiles[..., 0] != footprint_module.ENTRY_ONLY)
    assert np.any(tiles[cut, 0] > box[cut, 0] + 1.0), "no ray starts past the air"
    _without_footprint(monkeypatch)
    air = 0
    for view, (cam, extra) in views.items():
        plain = scene.render(cam, **options, **extra)
        air += int(np.sum(plain.value == floor))
        assert np.sum(np.isfinite(plain.value) & (plain.value != floor)) > 20, view
        for name in options["outputs"]:
            a, b = getattr(plain, name), getattr(with_fp[view], name)
            assert np.array_equal(a, b, equal_nan=True), f"{view}: {name} differs"
    assert air > 200


def test_mip_footprint_is_the_box_without_air():
    """A smooth field with no 16-cell block of its smallest value: every block is named at the
    coarsest level (a few boxes to project), as before there was air to leave out."""
    vol = sc.demo("marschner-lobb", size=30)
    scene = sc.Scene(vol)
    for method in ("exact", "slices"):
        mode = Mip(method=method, step=2.0)
        flags = mode.footprint_flags(mode.blocks(scene.grid.hierarchy))
        assert flags[0] is None and flags[1] is None and flags[2].all()
    vol = _blob_in_air(0.0, 1.0, "uint8")
    mode = Mip(method="slices", step=2.0)
    flags = mode.footprint_flags(mode.blocks(sc.Scene(vol).grid.hierarchy))
    assert 0 < flags[1].sum() < flags[1].size


def test_translucent_isosurfaces_are_identical_with_and_without_the_footprint(monkeypatch):
    vol = sc.demo("sphere", size=41)
    cams = _cameras(vol)
    options = {"iso": [-0.4, -0.2, 0.0], "opacity": [0.6, 0.4, 0.3]}
    with_fp = {v: scene_module.Scene(vol).render(c, **options) for v, c in cams.items()}
    _without_footprint(monkeypatch)
    for view, cam in cams.items():
        plain = scene_module.Scene(vol).render(cam, **options)
        assert np.array_equal(plain.rgba, with_fp[view].rgba), view
        assert np.array_equal(plain.depth, with_fp[view].depth, equal_nan=True), view


@pytest.mark.parametrize("sampling", ["grid", "pieces"])
def test_dvr_frames_are_identical_with_and_without_the_footprint(sampling, monkeypatch):
    vol = sc.demo("sphere", size=33)
    # Visible only near the sphere's surface: most of the volume is transparent.
    tf = sc.TransferFunction([(-0.1, 0.0), (0.0, 0.8), (0.1, 0.0)], vol.value_range, "gray")
    dvr = sc.DVRSettings(step=0.5, sampling=sampling)
    cams = _cameras(vol)
    with_fp = {v: sc.Scene(vol).render(c, mode="dvr", tf=tf, dvr=dvr) for v, c in cams.items()}
    _without_footprint(monkeypatch)
    for view, cam in cams.items():
        plain = sc.Scene(vol).render(cam, mode="dvr", tf=tf, dvr=dvr)
        assert plain.rgba[..., 3].max() > 0.5, view
        assert np.array_equal(plain.rgba, with_fp[view].rgba), view
        assert np.array_equal(plain.depth, with_fp[view].depth, equal_nan=True), view


def _binary_ball(n: int) -> sc.Volume:
    """0 outside a ball, 1 inside: every finest block holds one value or both."""
    x = np.arange(n) - (n - 1) / 2
    r = np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2)
    return sc.Volume((r < 0.3 * n).astype(np.float32))


@pytest.mark.parametrize("step", [1.0, 2.5, 4.0])
@pytest.mark.parametrize("volume", ["shell", "edge"])
def test_fixed_step_dvr_frames_are_identical_with_and_without_the_footprint(volume, step,
                                                                            monkeypatch):
    """DVR's default fixed-step sampling, whose segments reach from a visible block into its
    neighbours: a transfer function visible near the sphere's surface, and a ball of ones in
    zeros with a transfer function visible only around 0.5 (the visible blocks are a thin
    shell, and most of the colour comes from segments between a sample inside and one
    outside)."""
    if volume == "shell":
        vol = sc.demo("sphere", size=33)
        tf = sc.TransferFunction([(-0.1, 0.0), (0.0, 0.8), (0.1, 0.0)], vol.value_range,
                                 "gray")
    else:
        vol = _binary_ball(36)
        tf = sc.TransferFunction([(0.4, 0.0), (0.5, 0.9), (0.6, 0.0)], (0.0, 1.0), "gray")
    dvr = sc.DVRSettings(step=step, sampling="ray")
    shading = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))
    cams = _cameras(vol)
    with_fp = {v: sc.Scene(vol).render(c, mode="dvr", tf=tf, dvr=dvr, shading=shading)
               for v, c in cams.items()}
    _without_footprint(monkeypatch)
    for view, cam in cams.items():
        plain = sc.Scene(vol).render(cam, mode="dvr", tf=tf, dvr=dvr, shading=shading)
        assert (plain.rgba[..., :3].max(axis=-1) > 0.05).sum() > 50, view  # colour to compare
        assert np.array_equal(plain.rgba, with_fp[view].rgba), view
        assert np.array_equal(plain.depth, with_fp[view].depth, equal_nan=True), view


def test_fixed_step_dvr_flags_hold_the_neighbours_of_visible_blocks_and_visible_pairs():
    """The finest flags on hand-made ranges: a visible block and its 26 neighbours; two
    neighbours whose ranges, each invisible, together span the visible values; nothing else.
    The coarser levels hold any flagged finer block; a step longer than a finest block's edge
    gets no footprint."""
    from splinecast.render.dvr import Dvr, _segment_blocks

    tf = sc.TransferFunction([(0.4, 0.0), (0.5, 0.9), (0.6, 0.0)], (0.0, 1.0), "gray")
    mode = Dvr(tf, sc.DVRSettings(step=2.0, sampling="ray"))
    shape = (9, 8, 7)
    lows, highs = np.zeros(shape), np.full(shape, 0.1)
    visible = np.zeros(shape, np.uint8)
    visible[2, 2, 2] = 1
    lows[6, 5, 4], highs[6, 5, 4] = 0.8, 1.0  # with its neighbour (6, 5, 5): 0..1
    got = _segment_blocks(mode.params, visible, lows, highs)
    want = np.zeros(shape, bool)
    want[1:4, 1:4, 1:4] = True
    want[5:8, 4:7, 3:6] = True  # every neighbour of (6, 5, 4) pairs with it
    np.testing.assert_array_equal(got.astype(bool), want)

    vol = _binary_ball(36)
    scene = sc.Scene(vol)
    blocks = mode.blocks(scene.grid.hierarchy)
    flags = mode.footprint_flags(blocks)
    for level in (1, 2):
        factor = 4 ** level
        expect = np.zeros(blocks[level].shape, bool)
        for i, j, k in zip(*np.nonzero(flags[0]), strict=True):
            expect[i // factor, j // factor, k // factor] = True
        np.testing.assert_array_equal(flags[level].astype(bool), expect)
    long_step = Dvr(tf, sc.DVRSettings(step=4.5, sampling="ray"))
    cam = sc.Camera.orbit(vol, size=(64, 48))
    assert segment.screen_footprint(scene.grid, long_step, cam, blocks).shape[0] == 0


@pytest.mark.parametrize("pairs", [True, False])
def test_the_exact_isosurface_projects_its_2_cell_blocks_while_they_are_few(pairs,
                                                                          monkeypatch):
    """The pairs' footprint is the one of their own flags at their size (and hugs the surface
    closer than the 4-cell blocks'); above :data:`MAX_PROJECTED_PAIRS` the 4-cell blocks are
    projected. Frames are identical with and without the footprint either way."""
    vol = sc.demo("torus", size=41)
    iso = vol.metadata["default_iso"]
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=30, size=(96, 72))
    mode = Iso(iso)
    blocks = mode.blocks(scene.grid.hierarchy)
    pair_flags = blocks[4]  # one byte per 2-cell block (blocks[3] packs them for the walk)
    n_pairs, n_blocks = np.count_nonzero(pair_flags), np.count_nonzero(blocks[0])
    assert 0 < n_blocks < n_pairs <= footprint_module.MAX_PROJECTED_PAIRS
    if not pairs:
        monkeypatch.setattr(footprint_module, "MAX_PROJECTED_PAIRS", n_pairs - 1)
        monkeypatch.setattr(segment, "MAX_PROJECTED_PAIRS", n_pairs - 1)
    fp = segment.screen_footprint(scene.grid, mode, cam, blocks)
    basis, n_cells = cam.pixel_basis(), scene.grid.n_cells
    of_pairs = block_footprint(basis, scene.grid.geom, n_cells, pair_flags, PAIR_SHIFT,
                               cam.width, cam.height)
    of_blocks = block_footprint(basis, scene.grid.geom, n_cells, blocks[0], BLOCK_SHIFTS[0],
                                cam.width, cam.height)
    assert np.array_equal(fp, of_pairs if pairs else of_blocks)
    traced_pairs = np.count_nonzero(of_pairs[..., 0] <= of_pairs[..., 1])
    traced_blocks = np.count_nonzero(of_blocks[..., 0] <= of_blocks[..., 1])
    assert traced_pairs < traced_blocks
    outputs = ("rgba", "depth", "normal")
    with_fp = scene.render(cam, iso=iso, outputs=outputs)
    _without_footprint(monkeypatch)
    plain = scene.render(cam, iso=iso, outputs=outputs)
    assert np.isfinite(plain.depth).sum() > 500
    for name in outputs:
        assert np.array_equal(getattr(plain, name), getattr(with_fp, name), equal_nan=True), name


def test_the_sampled_isosurface_method_has_no_footprint():
    vol = sc.demo("sphere", size=17)
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, size=(40, 30))
    exact, sampled = Iso(0.0), Iso(0.0, method="sampled")
    blocks = exact.blocks(scene.grid.hierarchy)
    assert segment.screen_footprint(scene.grid, exact, cam, blocks).shape == (4, 5, 2)
    assert segment.screen_footprint(scene.grid, sampled, cam, blocks).shape[0] == 0


#: Every output buffer of the modes with a footprint.
_EVERY_OUTPUT = {"iso": ("rgba", "depth", "position", "normal", "face"),
                 "multi-iso": ("rgba", "depth", "position", "normal", "face"),
                 "dvr": ("rgba", "depth", "position")}


@pytest.mark.parametrize("mode", ["iso", "multi-iso", "dvr"])
@pytest.mark.parametrize("whole", [True, False])
def test_pixels_of_empty_tiles_are_finished_as_the_traced_ones_would_be(mode, whole,
                                                                        monkeypatch):
    """The band finishes one pixel of a run of tiles the footprint leaves empty and copies it
    over the run (every buffer: float32 colour and normals, float64 depth and positions, the
    int8 face); an image tile whose pixel rows and columns start off the footprint's 8-pixel
    grid makes the band's tiles straddle empty and non-empty footprint tiles."""
    vol = sc.demo("sphere", size=25)
    cam = sc.Camera.orbit(vol, azimuth=20, elevation=10, size=(120, 96), zoom=0.7)
    if not whole:
        cam = cam.tile(5, 3, 101, 83)
    iso = vol.metadata["default_iso"]
    options = {"iso": iso} if mode == "iso" else (
        {"iso": [iso - 0.1, iso], "opacity": [0.5, 0.7]} if mode == "multi-iso"
        else {"mode": "dvr"})
    outputs = _EVERY_OUTPUT[mode]
    scene = sc.Scene(vol)
    with_fp = scene.render(cam, **options, outputs=outputs)
    _without_footprint(monkeypatch)
    plain = scene.render(cam, **options, outputs=outputs)
    # The sphere in the middle, rows and columns of pixels that see nothing around it.
    hit = np.isfinite(plain.depth)
    assert hit.any() and not hit[:8].any() and not hit[:, :8].any() and not hit[-8:].any()
    for name in outputs:
        assert np.array_equal(getattr(plain, name), getattr(with_fp, name), equal_nan=True), name
