"""Front-to-back order of the bricks of a cut, seen from a camera.

The bricks of a cut are the leaves of an octree (several roots: the coarsest level's bricks), so
they have one visibility order valid for every ray of a camera, found by walking the tree as a
BSP tree: along every ray the index of the brick it is in moves away from the eye's brick, axis
by axis. Hence

- the roots (a regular grid of bricks) are visited in order of their L1 distance, in brick
  indices, from the root that holds the eye (the eye's index clamped to the grid): every step
  of a ray into the next root increases that distance by one;
- the up to 2 x 2 x 2 children of a brick in order of the number of axes along which the child
  lies on the far side of the split plane from the eye, for the same reason.

An orthographic camera's eye is at infinity: the near side along an axis is the side the rays
come from (the sign of the viewing direction). Each brick's key is the tuple of these ranks from
its root down to itself; sorting the keys lexicographically gives the order (no brick of a cut
is the ancestor of another, so no key is a prefix of another).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...camera import Camera

__all__ = ["front_to_back", "eye_index"]


def eye_index(camera: Camera, tree: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """The eye in level-0 index space and again (perspective cameras), or the viewing direction
    there and ``None`` (orthographic: the eye is at infinity)."""
    volume = tree.volume
    spacing = np.asarray(volume.spacing, dtype=np.float64)
    if camera.ortho:
        return np.asarray(camera.forward, dtype=np.float64) / spacing, None
    eye = (np.asarray(camera.position, dtype=np.float64) - np.asarray(volume.origin)) / spacing
    return eye, eye


def front_to_back(keys: np.ndarray, camera: Camera, tree: Any) -> np.ndarray:
    """Permutation that puts the bricks ``keys`` (n, 4: level, i, j, k) in front-to-back order.

    Parameters
    ----------
    keys : ndarray (n, 4)
        Bricks of a cut (leaves of the octree: none is the ancestor of another).
    camera : Camera
    tree : BrickOctree
        Supplies ``levels`` (finest first), ``brick`` and ``factors`` (the level-0 voxels per
        brick of each level are ``brick * factors[p]``) and ``volume`` (level-0 geometry).

    Returns
    -------
    ndarray of int
        Indices into ``keys``, nearest brick first.
    """
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 4)
    if len(keys) == 0:
        return np.zeros(0, dtype=np.int64)
    point, eye = eye_index(camera, tree)
    size = tree.brick * np.asarray(tree.factors, dtype=np.float64)  # (n_levels, 3) level-0 voxels
    n_levels = len(tree.levels)
    position = np.array([tree.levels.index(int(level)) for level in keys[:, 0]])
    # Rank columns from the root level down; bricks above their own level get -1 (sorts first,
    # but never compared: no key is a prefix of another).
    ranks = np.full((len(keys), n_levels), -1, dtype=np.int64)
    root = n_levels - 1
    for p in range(root, -1, -1):
        here = position <= p
        if not here.any():
            continue
        # The brick's ancestor (or itself) on level p: its index scaled down by the factor ratio.
        ratio = np.asarray(tree.factors[p]) // np.asarray(tree.factors[position[here]])
        index = keys[here, 1:] // ratio
        if p == root:
            count = np.asarray(tree.counts[p], dtype=np.int64)
            if eye is None:  # orthographic: the nearest root is at the end the rays come from
                near = np.where(point >= 0, 0, count - 1)
            else:
                near = np.clip(np.floor(eye / size[p]).astype(np.int64), 0, count - 1)
            ranks[here, 0] = np.abs(index - near).sum(axis=1)
            continue
        split = np.asarray(tree.factors[p + 1]) // np.asarray(tree.factors[p])  # 1 or 2 per axis
        offset = index % split
        if eye is None:
            near_offset = np.where(point >= 0, 0, split - 1)
            far = offset != near_offset
        else:
            # The child on the eye's side of the parent's split plane comes first.
            first_child = index - offset
            eye_brick = np.floor(eye / size[p]).astype(np.int64)
            near_offset = np.where(eye_brick <= first_child, 0, split - 1)
            far = offset != near_offset
        ranks[here, root - p] = (far & (split > 1)).sum(axis=1)
    return np.lexsort(ranks.T[::-1])
