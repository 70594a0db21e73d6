"""Label volumes: each label's surface, its colour, compositing, picking, label pyramids.

References are independent of the code under test: analytic ray-sphere intersections of the
spheres the label volume was made from, single renders of each label's indicator over the whole
volume (another code path than the label scene's sub-volumes) composited by the test itself, and
a brute-force weighted mode of the fine voxels for the label pyramid.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import main
from splinecast.io.label_colors import palette_color
from splinecast.render.compose import nearest_hit, on_background, over_by_depth

N = 48
SPACING = 0.5
ORIGIN = np.array([-3.0, 1.0, 2.0])
# (label, world centre, world radius): three spheres, two of them overlapping in the image.
SPHERES = [
    (3, ORIGIN + SPACING * np.array([16.0, 16.0, 20.0]), SPACING * 9.0),
    (5, ORIGIN + SPACING * np.array([31.0, 30.0, 26.0]), SPACING * 11.0),
    (12, ORIGIN + SPACING * np.array([22.0, 36.0, 12.0]), SPACING * 6.5),
]
# Flat colours: ambient 1, no diffuse or specular light, so a hit's colour is its label's.
FLAT = sc.Shading(ambient=1.0, diffuse=0.0, specular=0.0)


def sphere_labels() -> sc.Volume:
    idx = np.indices((N, N, N)).astype(np.float64)
    pos = ORIGIN[:, None, None, None] + SPACING * idx
    data = np.zeros((N, N, N), np.uint8)
    for value, centre, radius in SPHERES:
        inside = ((pos - centre[:, None, None, None]) ** 2).sum(axis=0) <= radius**2
        data[inside] = value
    return sc.Volume(data, spacing=SPACING, origin=tuple(ORIGIN), metadata={"name": "spheres"})


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sphere_labels()


@pytest.fixture(scope="module")
def camera(vol) -> sc.Camera:
    return sc.Camera.orbit(vol, azimuth=60, elevation=-20, size=(96, 72), fit="box")


def ray_sphere(origins, dirs, centre, radius):
    """First positive hit distance of unit rays with a sphere (inf on a miss)."""
    oc = origins - centre
    b = (oc * dirs).sum(-1)
    c = (oc * oc).sum(-1) - radius**2
    disc = b * b - c
    t = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def first_sphere(camera, grow: float) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel: the label of the sphere (radius + grow) hit first, 0 on a miss, and its depth."""
    origins, dirs = camera.rays()
    depth = np.full(dirs.shape[:2], np.inf)
    label = np.zeros(dirs.shape[:2], np.int64)
    for value, centre, radius in SPHERES:
        t = ray_sphere(origins, dirs, centre, radius + grow)
        nearer = t < depth
        depth[nearer], label[nearer] = t[nearer], value
    return label, depth


# A binary indicator's 0.5 isosurface lies within a voxel of the analytic sphere it was sampled
# from (the voxel centres on either side of it are inside and outside the sphere).
DELTA = SPACING * 1.0


def test_label_buffer_names_the_sphere_each_ray_meets_first(vol, camera):
    frame = sc.Scene(vol, labels=True).render(camera, samples=1)
    assert frame.label.shape == (72, 96)
    # Robust pixels: the same answer for the spheres shrunk and grown by the tolerance.
    small, _ = first_sphere(camera, -DELTA)
    large, _ = first_sphere(camera, +DELTA)
    robust = small == large
    assert robust.mean() > 0.8
    assert set(np.unique(small[robust])) == {0, 3, 5, 12}  # every sphere seen, and misses
    np.testing.assert_array_equal(frame.label[robust], small[robust])
    assert set(np.unique(frame.label)) <= {0, 3, 5, 12}


@pytest.mark.parametrize("model, smooth, median, p95", [
    ("trilinear", None, 12.0, 25.0),
    ("bspline3", None, 12.0, 25.0),
    # The indicator smoothed first: the voxels' staircase melts into the sphere.
    ("bspline3", 5, 4.0, 10.0),
])
def test_label_depths_and_normals_match_the_analytic_spheres(vol, camera, model, smooth,
                                                              median, p95):
    frame = sc.Scene(vol, model=model, labels=True, smooth=smooth).render(camera, samples=1)
    origins, dirs = camera.rays()
    delta = DELTA * (1.5 if smooth else 1.0)
    small, near_small = first_sphere(camera, -delta)
    large, near_large = first_sphere(camera, +delta)
    exact, _ = first_sphere(camera, 0.0)
    robust = (small == large) & (small > 0)
    assert robust.sum() > 300
    # The hit lies between the grown and the shrunk sphere, along the ray.
    d = frame.depth[robust]
    assert np.all(d >= near_large[robust] - 1e-9)
    assert np.all(d <= near_small[robust] + 1e-9)
    # Normals against the sphere's at the hit.
    hit = origins + frame.depth[..., None] * dirs
    angles = []
    for value, centre, _radius in SPHERES:
        mask = robust & (frame.label == value)
        n_true = hit[mask] - centre
        n_true /= np.linalg.norm(n_true, axis=-1, keepdims=True)
        cos = (frame.normal[mask] * n_true).sum(-1)
        angles.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    angles = np.concatenate(angles)
    assert np.median(angles) < median
    assert np.percentile(angles, 95) < p95
    assert (frame.label[exact > 0] > 0).mean() > 0.9


def single_renders(vol, camera, values, opacity=1.0):
    """Each label's indicator over the whole volume, rendered on its own (transparent
    background, flat colour): the reference the label scene's sub-volumes must reproduce."""
    frames = []
    for value in values:
        indicator = (vol.data == value).astype(np.float32)
        whole = sc.Volume(indicator, spacing=vol.spacing, origin=vol.origin,
                          metadata={"inside": "high"})
        colour = palette_color(value)[:3]
        look = sc.Shading(front_color=colour, back_color=tuple(0.6 * c for c in colour),
                          background=(0, 0, 0, 0), ambient=1.0, diffuse=0.0, specular=0.0)
        frames.append(sc.Scene(whole).render(camera, iso=0.5, inside="high", shading=look,
                                             samples=1, outputs=("rgba", "depth")))
    return frames


def test_opaque_labels_equal_the_nearest_of_single_renders(vol, camera):
    scene = sc.Scene(vol, labels=True)
    frame = scene.render(camera, shading=FLAT, samples=1)
    singles = single_renders(vol, camera, [3, 5, 12])
    depth = np.min([f.depth for f in singles], axis=0)
    which = np.argmin([f.depth for f in singles], axis=0)
    hit = np.isfinite(depth)
    np.testing.assert_allclose(frame.depth[hit], depth[hit], rtol=1e-9, atol=1e-9)
    assert np.all(np.isinf(frame.depth[~hit]))
    np.testing.assert_array_equal(frame.label[hit], np.array([3, 5, 12])[which[hit]])
    colour = np.stack([f.rgba for f in singles])[which, np.arange(72)[:, None],
                                                 np.arange(96)[None, :]]
    np.testing.assert_allclose(frame.rgba[hit], colour[hit], atol=1e-6)
    background = np.broadcast_to(np.float32(FLAT.background), frame.rgba[~hit].shape)
    np.testing.assert_allclose(frame.rgba[~hit], background, atol=1e-6)


def test_translucent_labels_composite_front_to_back(vol, camera):
    alpha = 0.4
    frame = sc.Scene(vol, labels=True, opacity=alpha).render(camera, shading=FLAT, samples=1)
    singles = single_renders(vol, camera, [3, 5, 12])
    bg = np.array(FLAT.background[:3])
    expected = np.empty((72, 96, 3))
    for row in range(72):  # the "over" operator, pixel by pixel, written out
        for col in range(96):
            hits = sorted((f.depth[row, col], i) for i, f in enumerate(singles)
                          if np.isfinite(f.depth[row, col]))
            colour, transmit = np.zeros(3), 1.0
            for _, i in hits:
                colour += transmit * alpha * singles[i].rgba[row, col, :3]
                transmit *= 1.0 - alpha
            expected[row, col] = colour + transmit * bg
    np.testing.assert_allclose(frame.rgba[..., :3], expected, atol=2e-6)
    overlap = sum(np.isfinite(f.depth) for f in singles) >= 2
    assert overlap.sum() > 50  # the spheres do overlap in the image


def test_a_small_budget_prepares_labels_again_with_the_same_picture(vol, camera):
    whole = sc.Scene(vol, labels=True).render(camera, samples=1)
    tight = sc.Scene(vol, labels=True, budget=4 * 20**3)  # about one label's indicator
    for _ in range(2):
        frame = tight.render(camera, samples=1)
        np.testing.assert_array_equal(frame.depth, whole.depth)
        np.testing.assert_array_equal(frame.rgba, whole.rgba)
    assert len(tight._scenes) == 1


def test_hidden_labels_are_not_drawn(vol, camera):
    scene = sc.Scene(vol, labels=True)
    frame = scene.render(camera, show=[5], samples=1)
    (single,) = single_renders(vol, camera, [5])
    np.testing.assert_array_equal(frame.label, np.where(np.isfinite(single.depth), 5, 0))
    assert scene.render(camera, show=[], samples=1).stats["hits"] == 0


def test_colours_from_image_label_metadata_and_tables(vol, camera, tmp_path):
    meta = dict(vol.metadata, image_label={
        "colors": [{"label-value": 3, "rgba": [255, 0, 0, 255]}],
        "properties": [{"label-value": 5, "name": "liver"}]})
    labelled = sc.Volume(vol.data, spacing=vol.spacing, origin=vol.origin, metadata=meta)
    table = tmp_path / "colours.csv"
    table.write_text("value,r,g,b,a,name\n12,0,0,255,255,kidney\n")
    scene = sc.Scene(labelled, labels=True, colors=table)
    assert scene.style(5).name == "liver" and scene.style(12).name == "kidney"
    frame = scene.render(camera, shading=FLAT, samples=1)
    front = frame.label > 0
    for value, rgb in ((3, (1, 0, 0)), (12, (0, 0, 1)),
                       (5, palette_color(5)[:3])):
        mask = front & (frame.label == value)
        assert mask.sum() > 10
        # Front faces have the label's colour (back faces, where the box cuts, are darker).
        np.testing.assert_allclose(np.median(frame.rgba[mask, :3], axis=0), rgb, atol=1e-6)


def test_colour_table_file_formats(tmp_path):
    from splinecast.io.label_colors import read_color_table

    path = tmp_path / "t.json"
    path.write_text(json.dumps({"3": {"rgba": [255, 0, 0, 128], "name": "liver"},
                                "5": [0.0, 0.5, 1.0]}))
    table = read_color_table(path)
    assert table[3].rgba == (1.0, 0.0, 0.0, 128 / 255) and table[3].name == "liver"
    assert table[5].rgba == (0.0, 0.5, 1.0, 1.0)
    path.write_text(json.dumps([{"label-value": 7, "rgba": [0, 255, 0, 255]}]))
    assert read_color_table(path)[7].rgba == (0.0, 1.0, 0.0, 1.0)
    for bad in ('{"x": [1, 2, 3]}', '{"3": [300, 0, 0]}', '{"3": "red"}', "[1, 2]", "{"):
        path.write_text(bad)
        with pytest.raises(sc.ParameterError, match=str(path)):
            read_color_table(path)


@pytest.fixture(scope="module")
def label_file(vol, tmp_path_factory):
    path = tmp_path_factory.mktemp("labels") / "spheres.npy"
    np.save(path, vol.data)
    return path


@pytest.mark.parametrize("table, needle", [
    ('{"7": [255, 0, 0]}', "label 7 does not occur"),
    ('{"3": [255, 0]}', "3 or 4 numbers"),
])
def test_a_bad_colour_table_is_one_line_naming_file_and_option(label_file, tmp_path, capsys,
                                                                table, needle):
    path = tmp_path / "table.json"
    path.write_text(table)
    code = main(["render", str(label_file), "--labels", "--label-colors", str(path), "--quiet",
                 "-o", str(tmp_path / "x.png")])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(path) in err and "--label-colors" in err and needle in err
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("args, needle", [
    (["--labels", "--show", "3,9"], "--show: label 9 does not occur"),
    (["--labels", "--show", "3,x"], "--show must be label values"),
    (["--labels", "--iso", "0.5"], "--iso does not apply to --labels"),
    (["--labels", "--mode", "mip"], "--mode mip does not apply to --labels"),
    (["--show", "3"], "--show applies to --labels only"),
    (["--labels", "--label-opacity", "2"], "--label-opacity"),
    (["--labels", "--budget", "1GiB"], "--budget applies to multiscale"),
    (["--labels", "--shading", "cel"], "--shading does not apply to --labels"),
    (["--labels", "--inside", "low"], "--inside does not apply to --labels"),
])
def test_bad_label_options_are_one_line(label_file, tmp_path, capsys, args, needle):
    code = main(["render", str(label_file), "--quiet", "-o", str(tmp_path / "x.png"), *args])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err


@pytest.mark.parametrize("smooth", [None, 5])
def test_cli_render_equals_the_api(label_file, tmp_path, capsys, smooth):
    from PIL import Image

    out = tmp_path / "labels.png"
    depth = tmp_path / "depth.npy"
    more = ["--smooth", str(smooth)] if smooth else []
    code = main(["render", str(label_file), "--labels", "--show", "3,12", "--size", "64x48",
                 "--fit", "box", "--samples", "1", "--quiet", "-o", str(out), "--depth",
                 str(depth), *more])
    assert code == 0
    read = sc.read(label_file)  # a .npy file: unit spacing, origin 0
    scene = sc.Scene(read, labels=True, show=[3, 12], smooth=smooth)
    cam = sc.Camera.orbit(read, azimuth=30, elevation=20, size=(64, 48), fit="box")
    frame = scene.render(cam, samples=1)
    np.testing.assert_array_equal(np.load(depth), frame.depth)
    np.testing.assert_array_equal(np.asarray(Image.open(out)), frame.to_uint8())


# --------------------------------------------------------------------------- label pyramids
def blocky_labels(shape=(37, 30, 26), seed=7) -> np.ndarray:
    """Labels 0..6 in random boxes (and a thin sheet), so blocks hold ties and mixtures."""
    rng = np.random.default_rng(seed)
    data = np.zeros(shape, np.uint8)
    for value in rng.integers(1, 7, 40):
        lo = rng.integers(0, np.array(shape) - 2)
        size = rng.integers(1, 9, 3)
        data[lo[0]:lo[0] + size[0], lo[1]:lo[1] + size[1], lo[2]:lo[2] + size[2]] = value
    data[:, 11, :] = 200  # a one-voxel sheet of a high label
    return data


def mirror(index, n):
    period = 2 * (n - 1)
    index = np.abs(index) % period
    return np.where(index > n - 1, period - index, index)


def weighted_mode_reference(fine: np.ndarray, coarse_shape, halve) -> np.ndarray:
    """The weighted mode of each coarse voxel's fine neighbours, by brute force over labels."""
    axes = []
    for a in range(3):
        c = np.arange(coarse_shape[a])
        if halve[a]:
            axes.append([(mirror(2 * c + d, fine.shape[a]), w) for d, w in
                         ((-1, 1.0), (0, 2.0), (1, 1.0))])
        else:
            axes.append([(c, 1.0)])
    values = np.unique(fine)
    votes = np.zeros((len(values), *coarse_shape))
    for ix, wx in axes[0]:
        for iy, wy in axes[1]:
            for iz, wz in axes[2]:
                sample = fine[np.ix_(ix, iy, iz)]
                for n, v in enumerate(values):
                    votes[n] += wx * wy * wz * (sample == v)
    # argmax returns the first maximum: the smallest label of a tie (values are sorted).
    return values[np.argmax(votes, axis=0)]


def children_hold(fine, coarse, halve) -> bool:
    found = np.zeros(coarse.shape, bool)
    axes = []
    for a in range(3):
        c = np.arange(coarse.shape[a])
        axes.append([mirror(2 * c + d, fine.shape[a]) for d in (-1, 0, 1)] if halve[a] else [c])
    for ix in axes[0]:
        for iy in axes[1]:
            for iz in axes[2]:
                found |= fine[np.ix_(ix, iy, iz)] == coarse
    return bool(found.all())


@pytest.fixture(scope="module")
def label_store(tmp_path_factory):
    data = blocky_labels()
    vol = sc.Volume(data, spacing=(1.0, 1.0, 2.0), origin=(0.5, -1.0, 3.0))
    path = tmp_path_factory.mktemp("pyramid") / "labels.zarr"
    sc.build_pyramid(vol, path, brick=8, labels=True, progress=False)
    return data, path


def test_label_pyramid_takes_the_weighted_mode_and_invents_no_label(label_store):
    data, path = label_store
    mv = sc.read(path)
    assert len(mv.levels) >= 3
    assert mv.metadata["downsampling"] == "mode-vertex-centred"
    assert isinstance(mv.metadata["image_label"], dict)
    fine = data
    for level in mv.levels[1:]:
        coarse = level.read((0, 0, 0), level.shape)
        halve = tuple(c != f for c, f in zip(coarse.shape, fine.shape, strict=True))
        assert children_hold(fine, coarse, halve)
        np.testing.assert_array_equal(coarse, weighted_mode_reference(fine, coarse.shape, halve))
        assert set(np.unique(coarse)) <= set(np.unique(data))
        fine = coarse


def test_label_store_renders_as_labels(label_store, tmp_path, capsys):
    data, path = label_store
    mv = sc.read(path)
    cam = sc.Camera.orbit(mv, size=(48, 40), fit="box")
    from_store = sc.Scene(mv, labels=True).render(cam, samples=1)
    in_memory = sc.Scene(sc.Volume(data, spacing=(1.0, 1.0, 2.0), origin=(0.5, -1.0, 3.0)),
                         labels=True).render(cam, samples=1)
    np.testing.assert_array_equal(from_store.label, in_memory.label)
    np.testing.assert_array_equal(from_store.depth, in_memory.depth)
    # A budget too small for level 0 renders a coarser level: still only labels of the data.
    coarse = sc.Scene(mv, labels=True, budget=data.nbytes // 4)
    assert coarse.volume.metadata["level"] >= 1
    assert set(np.unique(coarse.render(cam, samples=1).label)) <= set(np.unique(data))
    # The CLI renders an image-label store as labels without being told, and says so.
    code = main(["render", str(path), "--size", "32x24", "-o", str(tmp_path / "a.png")])
    err = capsys.readouterr().err
    assert code == 0 and "label image" in err and "--no-labels" in err
    # --no-labels: the raw values' isosurface, as the plain scene of the store draws it.
    code = main(["render", str(path), "--no-labels", "--size", "32x24", "--iso", "3.5",
                 "--samples", "1", "--fit", "box", "--depth", str(tmp_path / "d.npy"),
                 "-o", str(tmp_path / "b.png")])
    err = capsys.readouterr().err
    assert code == 0 and "label image" not in err
    raw_cam = sc.Camera.orbit(mv, azimuth=30, elevation=20, size=(32, 24), fit="box")
    with sc.Scene(mv) as plain:
        raw = plain.render(raw_cam, iso=3.5, samples=1, complete=True)
    np.testing.assert_array_equal(np.load(tmp_path / "d.npy"), raw.depth)
    main(["info", str(path)])
    assert "labels:" in capsys.readouterr().out


def test_pyramid_refuses_float_labels(tmp_path):
    vol = sc.Volume(np.zeros((8, 8, 8), np.float32))
    with pytest.raises(sc.ParameterError, match="labels must be integers"):
        sc.build_pyramid(vol, tmp_path / "x.zarr", brick=8, labels=True, progress=False)


# --------------------------------------------------------------------------- compositing
def fake_frame(rgba, depth) -> sc.Frame:
    return sc.Frame(rgba=np.asarray(rgba, np.float32), depth=np.asarray(depth, np.float64),
                    position=None, normal=None, face=None, cells_visited=None,
                    cells_tested=None, blocks_skipped=None)


def test_nearest_hit_and_over_by_depth_on_random_frames():
    rng = np.random.default_rng(3)
    frames = []
    for _ in range(4):
        alpha = rng.choice([0.0, 0.3, 1.0], size=(5, 6))
        rgb = rng.random((5, 6, 3)) * alpha[..., None]  # premultiplied
        depth = np.where(alpha > 0, rng.choice([1.0, 2.0, 3.0], size=(5, 6)), np.inf)
        frames.append(fake_frame(np.dstack([rgb, alpha]), depth))
    depth, source = nearest_hit(frames)
    out = over_by_depth(frames)
    for r in range(5):
        for c in range(6):
            d = [f.depth[r, c] for f in frames]
            best = min(range(4), key=lambda i: (d[i], i))
            assert depth[r, c] == d[best]
            assert source[r, c] == (best if np.isfinite(d[best]) else -1)
            colour, transmit = np.zeros(4), 1.0
            for i in sorted(range(4), key=lambda i: (d[i], i)):
                colour += transmit * frames[i].rgba[r, c]
                transmit *= 1.0 - frames[i].rgba[r, c, 3]
            np.testing.assert_allclose(out[r, c], colour, atol=1e-6)
    composed = on_background(out, (0.2, 0.4, 0.6, 1.0))
    np.testing.assert_allclose(composed[..., 3], 1.0)
    expected = out[..., :3] + (1 - out[..., 3:]) * np.array([0.2, 0.4, 0.6])
    np.testing.assert_allclose(composed[..., :3], expected, atol=1e-6)


def test_antialiased_label_windows_equal_the_whole_image_render(vol, camera):
    """Labels are traced in windows of the image; antialiasing looks past a window's border,
    so the picture equals the whole image's render of the label."""
    frame = sc.Scene(vol, labels=True).render(camera, show=[5], shading=FLAT)
    assert frame.stats["traced_pixels"] < camera.width * camera.height
    colour = palette_color(5)[:3]
    look = sc.Shading(front_color=colour, back_color=tuple(0.6 * c for c in colour),
                      background=(0, 0, 0, 0), ambient=1.0, diffuse=0.0, specular=0.0)
    indicator = sc.Volume((vol.data == 5).astype(np.float32), spacing=vol.spacing,
                          origin=vol.origin)
    single = sc.Scene(indicator).render(camera, iso=0.5, inside="high", shading=look)
    assert single.stats["antialiased"] > 0
    np.testing.assert_allclose(frame.rgba, on_background(single.rgba, FLAT.background),
                               atol=1e-6)


@pytest.mark.parametrize("ortho", [False, True])
def test_box_window_holds_every_ray_that_meets_the_box(ortho):
    lo, hi = np.array([1.0, -2.0, 0.5]), np.array([3.0, 1.0, 2.0])
    vol = sc.Volume(np.zeros((10, 10, 10), np.float32), origin=(-3, -4, -2))
    for azimuth in (0, 40, 130, 250):
        cam = sc.Camera.orbit(vol, azimuth=azimuth, elevation=30, size=(80, 60), ortho=ortho)
        for camera in (cam, cam.tile(10, 5, 50, 40)):
            origins, dirs = camera.rays()
            with np.errstate(divide="ignore", invalid="ignore"):  # the slab test, brute force
                t0, t1 = (lo - origins) / dirs, (hi - origins) / dirs
            near = np.nanmax(np.minimum(t0, t1), axis=-1)
            far = np.nanmin(np.maximum(t0, t1), axis=-1)
            meets = (near <= far) & (far >= 0)
            window = camera.box_window(lo, hi, pad=0)
            assert window is not None and meets.any()
            c0, r0, w, h = window
            inside = np.zeros_like(meets)
            inside[r0:r0 + h, c0:c0 + w] = True
            assert not np.any(meets & ~inside)
            assert w * h < 0.9 * camera.width * camera.height or camera is cam


def test_distributed_labels_equal_the_local_render(vol, camera, label_file, tmp_path):
    """Sort-first on a Dask cluster: tiles rendered by the workers' label scenes assemble
    into the local label render (label buffer, depth and colours)."""
    distributed = pytest.importorskip("distributed")
    table = {"3": {"rgba": [255, 0, 0, 255], "name": "liver"}}
    read = sc.read(label_file)
    cam = sc.Camera.orbit(read, azimuth=60, elevation=-20, size=(64, 48), fit="box")
    local = sc.Scene(read, labels=True, colors=table, show=[3, 5],
                     opacity={5: 0.5}).render(cam)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        from splinecast.distributed import DistributedScene

        scene = DistributedScene(label_file, client, labels=True, colors=table, show=[3, 5],
                                 opacity={5: 0.5})
        frame = scene.render(cam, tile_size=16)
        # The workers' label scenes render surfaces only: the client refuses another mode.
        assert scene.modes == ("iso",)
        with pytest.raises(sc.ParameterError, match=r"\(mode 'iso'\), not mode 'mip'"):
            scene.render(cam, "mip", tile_size=16)
    assert frame.stats["tiles"] > 4
    np.testing.assert_array_equal(frame.label, local.label)
    np.testing.assert_array_equal(frame.depth, local.depth)
    np.testing.assert_allclose(frame.rgba, local.rgba, atol=1e-6)
    assert set(np.unique(frame.label)) == {0, 3, 5}


def test_a_label_image_source_makes_a_label_pyramid_keeping_its_colours(tmp_path):
    data = blocky_labels((20, 18, 16))
    colours = [{"label-value": 200, "rgba": [0, 255, 0, 255]}]
    vol = sc.Volume(data, metadata={"image_label": {"colors": colours}})
    mv = sc.build_pyramid(vol, tmp_path / "a.zarr", brick=8, progress=False)  # labels: auto
    assert mv.attributes["labels"] is True
    assert mv.metadata["image_label"]["colors"] == colours
    assert sc.Scene(mv, labels=True).style(200).rgba == (0.0, 1.0, 0.0, 1.0)
    plain = sc.build_pyramid(sc.Volume(data), tmp_path / "b.zarr", brick=8, progress=False)
    assert "image_label" not in plain.metadata  # never guessed from integer voxels
    assert plain.metadata["downsampling"] == "binomial-vertex-centred"
