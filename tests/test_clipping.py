"""Clip planes and the crop box, applied analytically to the ray interval.

A plane through the sphere ``|p| = 0.6``: rays that pass through the cut disk enter the kept half
space inside the sphere, so their first hit is the sphere's far side (a back face), exactly on the
analytic sphere and on the kept side of the plane; no hit lies on the clipped side.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.render.clipping import make_planes

CUT = 0.1  # keep x <= 0.1: the plane (-1, 0, 0, 0.1)


@pytest.fixture(scope="module")
def sphere_scene():
    vol = sc.demo("sphere", size=41)
    cam = sc.Camera((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), size=(24, 24), ortho=True,
                    ortho_height=1.5)
    return vol, sc.Scene(vol), cam


def test_plane_through_sphere_shows_the_far_side(sphere_scene):
    vol, scene, cam = sphere_scene
    frame = scene.render(cam, iso=0.0, clip=[(-1.0, 0.0, 0.0, CUT)])
    origins, _ = cam.rays()
    y, z = origins[..., 1], origins[..., 2]
    r2 = y * y + z * z
    through_disk = r2 < 0.6**2 - CUT**2 - 0.02   # well inside the cut disk
    assert through_disk.sum() > 50
    pos = frame.position[through_disk]
    # The far side of the sphere: x = -sqrt(0.36 - y^2 - z^2).
    np.testing.assert_allclose(pos[:, 0], -np.sqrt(0.36 - r2[through_disk]), atol=5e-3)
    assert np.all(frame.face[through_disk] == -1)
    hits = frame.hit
    assert np.all(frame.position[hits][:, 0] <= CUT + 1e-9)
    # Rays beside the disk still see the unclipped front of the sphere.
    outside = (r2 > 0.6**2 - CUT**2 + 0.02) & (r2 < 0.6**2 - 0.02)
    assert np.all(frame.face[outside] == 1)
    np.testing.assert_allclose(frame.position[outside][:, 0],
                               np.sqrt(0.36 - r2[outside]), atol=5e-3)


def test_without_clip_the_near_side_is_hit(sphere_scene):
    vol, scene, cam = sphere_scene
    frame = scene.render(cam, iso=0.0)
    assert np.any(frame.position[frame.hit][:, 0] > CUT + 0.1)


def test_crop_box_keeps_hits_inside(sphere_scene):
    vol, scene, cam = sphere_scene
    box = (-0.5, 0.2, -0.3, 0.4, -1.0, 1.0)
    frame = scene.render(cam, iso=0.0, crop=box)
    pos = frame.position[frame.hit]
    assert len(pos) > 20
    for axis in range(3):
        assert np.all(pos[:, axis] >= box[2 * axis] - 1e-9)
        assert np.all(pos[:, axis] <= box[2 * axis + 1] + 1e-9)


def test_mip_and_multi_iso_respect_the_plane(sphere_scene):
    vol, scene, cam = sphere_scene
    mip = scene.render(cam, mode="minip", clip=[(-1.0, 0.0, 0.0, CUT)])
    assert np.all(mip.position[np.isfinite(mip.depth)][:, 0] <= CUT + 1e-9)
    multi = scene.render(cam, iso=[-0.2, 0.0], clip=[(-1.0, 0.0, 0.0, CUT)])
    assert np.all(multi.position[multi.hit][:, 0] <= CUT + 1e-9)


def test_make_planes_validation():
    planes = make_planes([(0, 0, 1, 0.5)], crop=(0, 1, 0, 2, 0, 3))
    assert planes.shape == (7, 4)
    pts = np.array([[0.5, 1.0, 1.5], [1.5, 1.0, 1.5], [0.5, 1.0, -0.6]])
    keep = (pts @ planes[:, :3].T + planes[:, 3] >= 0).all(axis=1)
    assert keep.tolist() == [True, False, False]
    with pytest.raises(sc.ParameterError, match="non-zero normal"):
        make_planes([(0, 0, 0, 1)])
    with pytest.raises(sc.ParameterError, match="crop"):
        make_planes(crop=(1, 0, 0, 1, 0, 1))
