"""The interface every render mode offers the driver: how ray pieces become a pixel.

A mode's parameters are a named tuple whose class identifies the mode (``IsoMode``,
``MultiIsoMode``, ``MipMode``, ``DvrMode``). Its per-ray state is a tuple of numbers carried
along the ray (first hit so far, running maximum, accumulated colour and opacity, crossings so
far); between calls of the driver (one brick after another) it lives in the mode's *state
arrays*. The driver (:mod:`.driver`) calls, per ray:

``state_new(mode)`` or ``state_load(mode, state, row, col)`` -> ``st``
    A fresh state, or the one left by an earlier segment of the same ray.
``ray_begin(mode, grid, scratch, mscratch, blocks, st, ray, ncx, ncy, ncz, t0, t1)`` -> ``st``
    Once per ray and grid, before the walk (MIP takes a lower bound of its answer here, from
    the model's value where the thread's previous ray found its maximum, or from block ranges
    and a few values along the ray). ``mscratch`` is the thread's ``mode_scratch``: it lives
    from ray to ray of one tile, so a mode may keep what one ray learnt for the next.
``tile_begin(mode, mscratch)``
    Before the first ray of each tile of the image (``tile`` columns by ``band_rows`` rows, on
    the image's own grid of tiles; optional, default: nothing). The driver traces a tile's rays
    in a fixed order, so a result that depends on what earlier rays left in ``mscratch`` (MIP
    with a tolerance) depends only on the rays of its own tile, and any window of the image
    whose edges lie on that grid of tiles renders the same pixels as the whole image.
``skip_size(mode, blocks, i, j, k, st)`` -> ``int``
    Edge in cells of the block around cell ``(i, j, k)`` to leap over, 0 to process the cell.
    A 0 is taken for the cell's whole block of the smallest edge the mode answers for
    (``answer_shift``; 4 cells per axis unless it says otherwise): the driver processes the
    ray's next cells in that block without asking again, so a mode whose answer may change
    along the ray (MIP's running maximum) must also refuse cells through ``wants``.
``wants(mode, st, lo, hi)`` -> ``bool``
    Whether a cell or piece whose values lie in ``[lo, hi]`` can change the result.
``on_skip(mode, grid, scratch, st, ray, t0, t1, lo, hi)`` -> ``st``
    A stretch of the ray left out (a leapt block, ``lo`` NaN; or a cell or piece with range
    ``[lo, hi]`` that ``wants`` refused); only the sampled methods take notice.
``consume(mode, mscratch, grid, scratch, piece, ray, st)`` -> ``st``
    A piece, a :class:`RayPiece` (exported here, defined in :mod:`.rays`) read by field name:
    the model's cell context ``ctx``, the cell ``i, j, k`` and the piece's ``tag`` in it, the
    model's polynomial ``poly`` in ``s in [0, 1]``, its value range ``[lo, hi]``, ray
    parameters ``[t0, t1]``, local cell points ``ax, ay, az`` (entry) and ``bx, by, bz``
    (exit). Gradients come from :func:`splinecast.models.pieces.gradient` (resolved for the
    grid's model at compile time).
``done(mode, st)`` -> ``bool``
    Early termination.
``ray_end(mode, grid, scratch, st, ray, t_far)`` -> ``st``
    After the walk of the ray's last segment.
``asks_again(mode)`` -> ``bool``
    Whether the driver asks ``skip_size`` again after each cell the mode tested (its range
    was wanted), instead of taking the 0 for the rest of the block (optional; default:
    no). MIP's running
    maximum may have risen past the block's maximum in that cell, and the rest of the block is
    then leapt over.
``answer_shift(mode)`` -> ``int``
    log2 of the edge, in cells, of the smallest block ``skip_size`` answers for (optional;
    default: the hierarchy's finest level, 4-cell blocks). The exact isosurface also answers
    for 2-cell blocks (:data:`splinecast.accel.minmax.PAIR_SHIFT`).
``watches_skips(mode)`` -> ``bool``
    Whether ``on_skip`` and ``ray_end`` do anything (optional; default: no). The driver calls
    them only then: a call that passes the ray and state tuples costs more than the cheap cells
    it follows, and LLVM does not inline a function with that many arguments.
``entry_left_out(mode, grid, scratch, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz)`` -> ``st``
    The footprint (:mod:`.footprint`) keeps ``[t_lo, t_hi]`` of the ray's interval
    ``[t0, t1]`` in the grid, and ``t0`` lies outside it (optional; default:
    :func:`unchanged_entry`). Called before the walk or the samples. What the footprint leaves
    out crosses no block the mode named for it. MIP named the blocks holding anything above
    the grid's smallest value, so every value left out is that value; when the ray's entry
    into the grid is left out, it takes the value there, which the ray would have met first.
``finish(mode, out, row, col, st, ray)``
    Writes the pixel's outputs (colour, depth, ...). A fresh state (``state_new``: the ray met
    nothing) is finished without reading ``ray``: the driver passes zeros for the pixels it
    does not trace (:mod:`.footprint`), where the ray would cost a square root and a division.
    Its outputs must not depend on the pixel either: over a run of tiles with nothing to
    trace, the driver finishes one pixel and copies it (:func:`.outputs.copy_pixel`).
``state_store(mode, state, row, col, st)``
    Keeps the state for the ray's next segment.

A mode may instead be *sampled*: it registers ``sample_step`` and ``segment`` as well, and the
driver then runs the fixed-step loop of :mod:`.sampler` for it (no cell walk, so no
``ray_begin``, ``on_skip`` or ``consume``; a block ``skip_size`` names must add nothing to the
result whatever its samples, so it depends on the position (DVR: a transparent block) or on a
state that only grows along the ray (sampled MIP: a block whose maximum does not beat the
running one); ``wants`` and ``blocks[3]``, ``blocks[4]``, the value ranges of the 4-cell
blocks, decide whether a stretch between two leapt blocks can be left out):

``sample_step(mode)`` -> ``float``
    Distance between samples, in voxels.
``sample_planes(mode)`` -> ``bool`` (optional, default :func:`never`)
    Whether the samples lie on planes of voxels rather than every ``sample_step`` voxels along
    the ray: where the ray crosses every ``sample_step``-th voxel plane across its dominant
    axis (the index axis along which it moves fastest), as slice-based renderers sample. On a
    plane through voxels the trilinear model reads 4 voxels instead of 8
    (:func:`splinecast.models.pieces.value_on_plane`).
``segment(mode, grid, scratch, st, ray, stretch)`` -> ``st``
    A :class:`Stretch` (exported here, defined in :mod:`.rays`) read by field name: the
    stretch ``[ta, tb]`` of the ray between two samples (or a sample and an end of the grid's
    interval), the model's values ``va`` and ``vb`` there, its ``length`` in voxels, and
    ``(x, y, z)``, the point at ``tb`` in the grid's traversal space (for a gradient).

plus ``mode_scratch(mode)`` (per-thread buffers, made once per band of rays). ``ray`` is a
:class:`Ray` (exported here, defined in :mod:`.rays`), a named tuple of sixteen floats read by
field name: the world origin and unit direction (``world_x`` ... ``world_dz``), the same ray in
the grid's traversal space (``index_x`` ... ``index_dz``: the point ``index + t * index_d``, the
parameter ``t`` staying the world distance), the spacing of the grid's level (``spacing_x``
... ``spacing_z``: index-space gradients are divided by it for world units) and ``anchor``, the
parameter where the ray enters the volume (the sampled methods' and DVR's sample grid starts
there, so every brick samples at the same places).
A mode module registers its functions with :func:`register`; each mode also states how two
partial results of one ray combine (its ``combine`` kernel), which is what brick-parallel and
distributed compositing use. How finished frames of several channels combine is declared on the
mode's user-side class instead (:attr:`splinecast.render.modes.RenderMode.compositing`, a
:class:`splinecast.render.compose.Compositing`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._jit import jit, overload_jit
from ..accel.minmax import BLOCK_SHIFTS, inactive_block_size
from .rays import Ray, RayPiece, Stretch

__all__ = [
    "Ray", "RayPiece", "Stretch", "no_scratch", "unchanged_begin", "unchanged_skip",
    "unchanged_end", "flagged_block_size",
    "register", "state_new", "state_load", "state_store", "mode_scratch", "ray_begin",
    "skip_size", "wants", "on_skip", "consume", "done", "ray_end", "finish", "watches_skips",
    "never", "hooks_of", "sampled_of", "sample_step", "sample_planes", "segment", "asks_again",
    "answer_shift", "finest_blocks", "entry_left_out", "unchanged_entry", "tile_begin",
    "unchanged_tile",
]

_HOOKS: dict[type, dict[str, Any]] = {}
_NAMES = ("state_new", "state_load", "state_store", "mode_scratch", "ray_begin", "skip_size",
          "wants", "on_skip", "consume", "done", "ray_end", "finish")
#: The hooks of a sampled mode, registered together or not at all.
_SAMPLED = ("sample_step", "segment")


def register(mode_class: type, **hooks: Any) -> None:
    """Register a mode's compiled functions for its parameter tuple class (all of
    :data:`_NAMES`; ``watches_skips`` and ``asks_again`` default to :func:`never`,
    ``answer_shift`` to :func:`finest_blocks`, ``sample_planes`` to :func:`never`,
    ``entry_left_out`` to :func:`unchanged_entry`, ``tile_begin`` to :func:`unchanged_tile`)."""
    missing = set(_NAMES) - set(hooks)
    if missing:
        raise TypeError(f"{mode_class.__name__} is missing {', '.join(sorted(missing))}")
    if 0 < len(set(_SAMPLED) & set(hooks)) < len(_SAMPLED):
        raise TypeError(f"{mode_class.__name__}: a sampled mode registers all of "
                        f"{', '.join(_SAMPLED)}")
    _HOOKS[mode_class] = {"watches_skips": never, "asks_again": never,
                          "answer_shift": finest_blocks, "sample_planes": never,
                          "entry_left_out": unchanged_entry, "tile_begin": unchanged_tile,
                          **hooks}


def sampled_of(mode_class: type) -> bool:
    """Whether a mode class is sampled (the driver runs :mod:`.sampler`'s loop for it)."""
    return "segment" in _HOOKS.get(mode_class, {})


def hooks_of(mode_class: type) -> dict[str, Any] | None:
    """The registered functions of a mode class by hook name (None: not registered)."""
    hooks = _HOOKS.get(mode_class)
    return None if hooks is None else dict(hooks)


def _impl(mode: Any, name: str) -> Any:
    cls = getattr(mode, "instance_class", None)
    return _HOOKS[cls].get(name) if cls in _HOOKS else None


# Stubs for Python, overloads for compiled code that compile the mode's registered function in
# their place (its Python source, so no forwarding layer is compiled on top).

def state_new(mode):
    """A fresh per-ray state (compiled code only)."""
    raise NotImplementedError


@overload_jit(state_new, inline="never")
def _state_new(mode):
    f = _impl(mode, "state_new")
    return None if f is None else f.py_func


def state_load(mode, state, row, col):
    """The state a previous segment left for pixel ``(row, col)`` (compiled code only)."""
    raise NotImplementedError


@overload_jit(state_load, inline="never")
def _state_load(mode, state, row, col):
    f = _impl(mode, "state_load")
    return None if f is None else f.py_func


def state_store(mode, state, row, col, st):
    """Keep the state of pixel ``(row, col)`` for the next segment (compiled code only)."""
    raise NotImplementedError


@overload_jit(state_store, inline="never")
def _state_store(mode, state, row, col, st):
    f = _impl(mode, "state_store")
    return None if f is None else f.py_func


def mode_scratch(mode):
    """Per-thread buffers of the mode (compiled code only)."""
    raise NotImplementedError


@overload_jit(mode_scratch, inline="never")
def _mode_scratch(mode):
    f = _impl(mode, "mode_scratch")
    return None if f is None else f.py_func


def ray_begin(mode, grid, scratch, mscratch, blocks, st, ray, ncx, ncy, ncz, t0, t1):
    """Per-ray set-up before the walk through one grid (compiled code only)."""
    raise NotImplementedError


@overload_jit(ray_begin, inline="never")
def _ray_begin(mode, grid, scratch, mscratch, blocks, st, ray, ncx, ncy, ncz, t0, t1):
    f = _impl(mode, "ray_begin")
    return None if f is None else f.py_func


def skip_size(mode, blocks, i, j, k, st):
    """Edge of the block to leap over at cell ``(i, j, k)``, 0: process the cell."""
    raise NotImplementedError


@overload_jit(skip_size, inline="never")
def _skip_size(mode, blocks, i, j, k, st):
    f = _impl(mode, "skip_size")
    return None if f is None else f.py_func


def wants(mode, st, lo, hi):
    """Whether values in ``[lo, hi]`` can change the result (compiled code only)."""
    raise NotImplementedError


@overload_jit(wants, inline="never")
def _wants(mode, st, lo, hi):
    f = _impl(mode, "wants")
    return None if f is None else f.py_func


def on_skip(mode, grid, scratch, st, ray, t0, t1, lo, hi):
    """A stretch of the ray left out by skipping (compiled code only)."""
    raise NotImplementedError


@overload_jit(on_skip, inline="never")
def _on_skip(mode, grid, scratch, st, ray, t0, t1, lo, hi):
    f = _impl(mode, "on_skip")
    return None if f is None else f.py_func


def consume(mode, mscratch, grid, scratch, piece, ray, st):
    """Take one ray piece (a :class:`RayPiece`) into the state (compiled code only)."""
    raise NotImplementedError


@overload_jit(consume, inline="never")
def _consume(mode, mscratch, grid, scratch, piece, ray, st):
    f = _impl(mode, "consume")
    return None if f is None else f.py_func


def done(mode, st):
    """Whether the ray can stop early (compiled code only)."""
    raise NotImplementedError


@overload_jit(done, inline="never")
def _done(mode, st):
    f = _impl(mode, "done")
    return None if f is None else f.py_func


def ray_end(mode, grid, scratch, st, ray, t_far):
    """After the walk of a ray's last segment (compiled code only)."""
    raise NotImplementedError


@overload_jit(ray_end, inline="never")
def _ray_end(mode, grid, scratch, st, ray, t_far):
    f = _impl(mode, "ray_end")
    return None if f is None else f.py_func


def entry_left_out(mode, grid, scratch, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz):
    """Take what the footprint leaves out of a ray, its entry into the grid included, into the
    state (compiled code only)."""
    raise NotImplementedError


@overload_jit(entry_left_out, inline="never")
def _entry_left_out(mode, grid, scratch, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz):
    f = _impl(mode, "entry_left_out")
    return None if f is None else f.py_func


def tile_begin(mode, mscratch):
    """Prepare the thread's mode scratch for the first ray of a tile (compiled code only)."""
    raise NotImplementedError


@overload_jit(tile_begin, inline="never")
def _tile_begin(mode, mscratch):
    f = _impl(mode, "tile_begin")
    return None if f is None else f.py_func


def finish(mode, out, row, col, st, ray):
    """Write pixel ``(row, col)``'s outputs from its final state (compiled code only)."""
    raise NotImplementedError


@overload_jit(finish, inline="never")
def _finish(mode, out, row, col, st, ray):
    f = _impl(mode, "finish")
    return None if f is None else f.py_func


def watches_skips(mode):
    """Whether the mode's ``on_skip`` and ``ray_end`` do anything (compiled code only)."""
    raise NotImplementedError


@overload_jit(watches_skips, inline="never")
def _watches_skips(mode):
    f = _impl(mode, "watches_skips")
    return None if f is None else f.py_func


def asks_again(mode):
    """Whether the driver asks ``skip_size`` again after a processed cell (compiled code only)."""
    raise NotImplementedError


@overload_jit(asks_again, inline="never")
def _asks_again(mode):
    f = _impl(mode, "asks_again")
    return None if f is None else f.py_func


def answer_shift(mode):
    """log2 of the edge of the smallest block ``skip_size`` answers for (compiled code only)."""
    raise NotImplementedError


@overload_jit(answer_shift, inline="never")
def _answer_shift(mode):
    f = _impl(mode, "answer_shift")
    return None if f is None else f.py_func


def sample_step(mode):
    """Distance between the samples of a sampled mode, in voxels (compiled code only)."""
    raise NotImplementedError


@overload_jit(sample_step, inline="never")
def _sample_step(mode):
    f = _impl(mode, "sample_step")
    return None if f is None else f.py_func


def sample_planes(mode):
    """Whether a sampled mode samples on voxel planes across the ray (compiled code only)."""
    raise NotImplementedError


@overload_jit(sample_planes, inline="never")
def _sample_planes(mode):
    f = _impl(mode, "sample_planes")
    return None if f is None else f.py_func


def segment(mode, grid, scratch, st, ray, stretch):
    """Take the stretch of a ray between two samples (a :class:`Stretch`) into the state
    (compiled code only)."""
    raise NotImplementedError


@overload_jit(segment, inline="never")
def _segment(mode, grid, scratch, st, ray, stretch):
    f = _impl(mode, "segment")
    return None if f is None else f.py_func


# Hooks several modes share: nothing to do at that point, or leaping over the blocks the mode's
# flags (``blocks[0..2]``, one per hierarchy level) mark as unable to contribute.

@jit()
def never(mode):
    """``watches_skips`` of a mode whose ``on_skip`` and ``ray_end`` leave the state alone, and
    ``asks_again`` of one whose refusals do not change along the ray."""
    return False


@jit()
def finest_blocks(mode):
    """``answer_shift`` of a mode that answers for the hierarchy's finest blocks."""
    return BLOCK_SHIFTS[0]


@jit()
def no_scratch(mode):
    """``mode_scratch`` of a mode that needs no per-thread buffers."""
    return np.empty(0)


@jit()
def unchanged_begin(mode, grid, scratch, mscratch, blocks, st, ray, ncx, ncy, ncz, t0, t1):
    """``ray_begin`` with nothing to prepare."""
    return st


@jit()
def unchanged_skip(mode, grid, scratch, st, ray, t0, t1, lo, hi):
    """``on_skip`` of a mode that ignores what it leaves out."""
    return st


@jit()
def unchanged_entry(mode, grid, scratch, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz):
    """``entry_left_out`` of a mode for which what the footprint leaves out is empty space
    (the isosurfaces, DVR)."""
    return st


@jit()
def unchanged_tile(mode, mscratch):
    """``tile_begin`` of a mode whose rays learn nothing from one another."""
    return None


@jit()
def unchanged_end(mode, grid, scratch, st, ray, t_far):
    """``ray_end`` with nothing to finish."""
    return st


@jit()
def flagged_block_size(mode, blocks, i, j, k, st):
    """``skip_size`` from the mode's block flags (0: process the cell)."""
    return inactive_block_size(blocks[0], blocks[1], blocks[2], i, j, k)
