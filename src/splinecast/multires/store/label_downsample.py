"""The downsampling filter of label pyramids: the most frequent label, never an average.

Averaging labels invents values (the mean of labels 2 and 4 is 3, another organ). A label
pyramid keeps the geometry of splinecast's other pyramids (:mod:`.store.downsample`: coarse voxel
``c`` sits on fine voxel ``2 c``, same NGFF translation on every level, nested bricks), and
takes, instead of the binomial average of the fine voxels ``2c - 1, 2c, 2c + 1`` along every
halved axis, their **weighted mode**: each of those (up to 27) voxels votes for its label with
the binomial weight it has in the average (``[1, 2, 1]`` per axis: the centre 8, a face
neighbour 4, an edge neighbour 2, a corner 1, out of 64), and the label with the most weight
wins; a tie goes to the smallest label value. The grid is mirrored at its ends as for the
average. So every coarse voxel holds a label that occurs among the fine voxels around it, and a
region keeps its place and roughly its extent level after level.
"""

from __future__ import annotations

import numpy as np

from ..._jit import jit
from .downsample import mirror

__all__ = ["mode_halve", "DESCRIPTION"]

#: What the store's ``multiscales[0]["metadata"]["description"]`` says of a label pyramid.
DESCRIPTION = ("coarse voxel c = the most frequent label among the fine voxels 2c-1, 2c, 2c+1 "
               "along every halved axis, each weighted as in [1, 2, 1] / 4 per axis (ties: the "
               "smallest label), mirrored at the ends; voxel centres shared with level 0 "
               "(translation unchanged)")


@jit(nogil=True)
def _weighted_mode(src, i0, i1, i2, w0, w1, w2, out):  # pragma: no cover - compiled
    """``out[a, b, c]``: the label with the largest total weight ``w0[p] w1[q] w2[r]`` among
    ``src[i0[a, p], i1[b, q], i2[c, r]]`` (ties: the smallest)."""
    n0, n1, n2 = out.shape
    t0, t1, t2 = w0.shape[0], w1.shape[0], w2.shape[0]
    labels = np.empty(t0 * t1 * t2, src.dtype)
    votes = np.empty(t0 * t1 * t2, np.float64)
    for a in range(n0):
        for b in range(n1):
            for c in range(n2):
                m = 0
                for p in range(t0):
                    for q in range(t1):
                        for r in range(t2):
                            v = src[i0[a, p], i1[b, q], i2[c, r]]
                            w = w0[p] * w1[q] * w2[r]
                            s = 0
                            while s < m and labels[s] != v:
                                s += 1
                            if s == m:
                                labels[m] = v
                                votes[m] = w
                                m += 1
                            else:
                                votes[s] += w
                best = 0
                for s in range(1, m):
                    if votes[s] > votes[best] or (votes[s] == votes[best]
                                                  and labels[s] < labels[best]):
                        best = s
                out[a, b, c] = labels[best]


_WEIGHTS = np.array([1.0, 2.0, 1.0])


def mode_halve(fine: np.ndarray, fine_lo: np.ndarray, fine_shape: np.ndarray,
               halve: tuple[bool, bool, bool], out_lo: np.ndarray,
               out_shape: np.ndarray) -> np.ndarray:
    """Coarse labels ``out_lo .. out_lo + out_shape`` (x, y, z) from a fine block.

    The same contract as :func:`.store.downsample.binomial_halve` (``fine`` holds the fine level
    from
    index ``fine_lo`` on, every mirrored voxel the output reads; ``halve`` says which axes are
    halved, the others are copied), with the weighted mode of the module's text instead of the
    average. The result has ``fine``'s dtype.
    """
    offset = np.asarray(fine_lo, np.int64)
    indices, weights = [], []
    for axis in range(3):
        o = np.arange(out_lo[axis], out_lo[axis] + out_shape[axis])
        if halve[axis]:
            taps = np.stack([2 * o - 1, 2 * o, 2 * o + 1], axis=1)
            indices.append(mirror(taps, int(fine_shape[axis])) - offset[axis])
            weights.append(_WEIGHTS)
        else:
            indices.append((o - offset[axis])[:, None])
            weights.append(np.ones(1))
    out = np.empty(tuple(int(n) for n in out_shape), dtype=fine.dtype)
    _weighted_mode(fine, *(np.ascontiguousarray(i, dtype=np.int64) for i in indices),
                   *weights, out)
    return out
