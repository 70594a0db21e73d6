"""The interface every model offers the render modes: a ray walked cell by cell, in pieces.

A model prepares its data once into a *kernel grid*: a named tuple of arrays and numbers whose
class identifies the model (``TrilinearGrid``, ``BSplineGrid``, ``S31Grid``, ``QSSGrid``). The
grid covers a box of cells, the whole volume or one brick with its ghost layers; cell ``c`` of
the grid depends on ``array[c .. c + support]`` per axis. The render layer walks a ray through
the grid's cells (``splinecast.accel.traversal``) and calls the functions below on every cell it
does not leap over. The driver's loop is copied per (model, mode) pair with the registered
functions inlined into it (:func:`splinecast.render.driver.trace`); elsewhere (the modes' own
compiled code) Numba resolves each stub below from the grid's class at compile time, so one
source serves every model without a function-typed argument (which its cache cannot store).

Per cell, in the order a driver uses them:

``cell_load(grid, scratch, i, j, k) -> ctx``
    Whatever the model reads once per cell, as a tuple whose first two entries are a
    conservative range ``(lo, hi)`` of the reconstruction on the cell (``lo > hi``: the cell
    cannot contribute).
``cell_pieces(grid, scratch, ctx, cell, a, e, cuts, tags) -> n``
    The segment ``a + s e`` (``s in [0, 1]``, local cell coordinates in ``[0, 1]^3``; ``a`` and
    ``e`` are ``(x, y, z)`` tuples) through ``cell``, the tuple ``(i, j, k)``, cut into ``n``
    pieces at ``cuts[0] = 0 < ... < cuts[n] = 1`` with a model tag per piece (the tetrahedron
    for the type-6 splines; trilinear and B-splines have one piece).
``piece_range(grid, scratch, ctx, i, j, k, tag) -> (lo, hi)``
    A conservative range of the piece's polynomial, before it is built.
``piece_poly(grid, scratch, ctx, cell, tag, a, b) -> poly``
    The reconstruction along piece ``tag`` of ``cell`` (``(i, j, k)``) from local point ``a``
    to ``b`` (``(x, y, z)`` tuples), a univariate polynomial of :mod:`splinecast.roots.pieces`
    in the model's natural form.
``gradient(grid, scratch, ctx, i, j, k, tag, x, y, z) -> (gx, gy, gz)``
    Gradient at local point ``(x, y, z)`` of the cell, per unit of the grid's index space.
``value_gradient_at(grid, scratch, x, y, z) -> (v, gx, gy, gz)``
    Value and gradient at any point of the grid's traversal space (clamped into the grid; the
    sampled methods' bisection uses it).
``value_at(grid, scratch, x, y, z) -> v`` (optional)
    The value alone, for the fixed-step loop (:mod:`splinecast.render.sampler`), which takes
    one per sample; a model that does not register it gets ``value_gradient_at``'s value.
``value_on_plane(grid, scratch, axis, p, a, b) -> v`` (optional)
    The value on plane ``p`` (a whole number) of the grid's voxels across ``axis`` (0, 1, 2),
    at ``(a, b)`` on the two other axes in order, where a model can read fewer voxels
    (trilinear: the bilinear of one slice, 4 reads instead of 8); the fixed-step loop's plane
    samples use it. The default is ``value_at`` at that point.
``separate_shading(grid) -> bool`` (optional)
    Whether the model shades with a field of its own rather than its reconstruction's
    gradient: the models whose reconstruction is only continuous (trilinear, the linear
    B-spline) shade with the cubic B-spline of their voxels (:mod:`.shading_field`), whose
    gradient is smooth. Default False (the reconstruction is C1 and shades itself).
``shading_gradient_at(grid, scratch, x, y, z) -> (gx, gy, gz)`` (optional)
    The shading field's gradient at a point of the grid's traversal space, per unit of the
    grid's index space; used where ``separate_shading`` says so. Default:
    ``value_gradient_at``'s gradient.
``look_ahead(grid) -> bool`` (optional, a constant)
    Whether the fixed-step loop takes each sample's value one sample early, before the table
    reads of the segment in front of it, so the two memory-bound reads overlap. Worth it for a
    model whose ``value_at`` is a few loads and little arithmetic (trilinear);
    one whose value is costly loses the early value a ray that stops never uses. Default False.
    Called once in Python with ``grid=None`` when a pair's kernel is made, so the code of the
    other case is left out of it.
``prefetch_at(grid, scratch, x, y, z) -> None`` (optional)
    Ask the processor for the memory ``value_at`` at that point will read, without waiting for
    it (a software prefetch): the fixed-step loop of a model that looks ahead calls it a few
    samples before it takes the value, so a read that misses the caches overlaps the samples
    in between. Default: nothing.

And once per grid: ``cell_count(grid) -> (nx, ny, nz)`` and ``new_scratch(grid)`` (per-thread
buffers, allocated once per band of rows). A model module defines these for its grid class and
registers them with :func:`register`.
"""

from __future__ import annotations

from typing import Any

from .._jit import jit, overload_jit

__all__ = [
    "register", "hooks_of", "called_of", "cell_count", "new_scratch", "cell_load", "cell_pieces",
    "piece_range", "piece_poly", "gradient", "value_gradient_at", "value_at", "whole_cell",
    "cell_range", "look_ahead", "value_on_plane", "separate_shading", "shading_gradient_at",
    "prefetch_at",
]

#: Kernel grid class -> {hook name: compiled function}.
_HOOKS: dict[type, dict[str, Any]] = {}
#: Kernel grid class -> names of the hooks the driver keeps as calls (not inlined).
_CALLED: dict[type, frozenset[str]] = {}
_NAMES = ("cell_count", "new_scratch", "cell_load", "cell_pieces", "piece_range", "piece_poly",
          "gradient", "value_gradient_at")
#: Hooks a model may leave out (the stub then derives them from the others).
_OPTIONAL = ("value_at", "look_ahead", "value_on_plane", "separate_shading",
             "shading_gradient_at", "prefetch_at")


def register(grid_class: type, called: tuple[str, ...] = (), **hooks: Any) -> None:
    """Register a model's compiled functions for its kernel grid class (all of :data:`_NAMES`).

    The render driver inlines every hook into its per-(model, mode) loop except those named in
    ``called``, which stay calls (hooks whose work per call dwarfs the cost of a call and whose
    inlined body only makes the loop larger and slower to compile).
    """
    missing = set(_NAMES) - set(hooks)
    if missing:
        raise TypeError(f"{grid_class.__name__} is missing {', '.join(sorted(missing))}")
    unknown = set(called) - set(_NAMES) - set(_OPTIONAL)
    if unknown:
        raise TypeError(f"called names unknown hooks: {', '.join(sorted(unknown))}")
    _HOOKS[grid_class] = dict(hooks)
    _CALLED[grid_class] = frozenset(called)


def hooks_of(grid_class: type) -> dict[str, Any] | None:
    """The registered functions of a grid class by hook name (None: not registered)."""
    hooks = _HOOKS.get(grid_class)
    return None if hooks is None else dict(hooks)


def called_of(grid_class: type) -> frozenset[str]:
    """Names of the hooks of a grid class that the driver calls rather than inlines."""
    return _CALLED.get(grid_class, frozenset())


def _impl(grid: Any, name: str) -> Any:
    cls = getattr(grid, "instance_class", None)
    return _HOOKS[cls].get(name) if cls in _HOOKS else None


# Each hook below is a stub for Python and an overload for compiled code that compiles the
# registered implementation of the grid's class in its place (its Python source, so no
# forwarding layer is compiled on top).

def cell_count(grid):
    """Cells per axis of the grid (compiled code only)."""
    raise NotImplementedError


@overload_jit(cell_count, inline="never")
def _cell_count(grid):
    f = _impl(grid, "cell_count")
    return None if f is None else f.py_func


def new_scratch(grid):
    """Per-thread scratch buffers of the model (compiled code only)."""
    raise NotImplementedError


@overload_jit(new_scratch, inline="never")
def _new_scratch(grid):
    f = _impl(grid, "new_scratch")
    return None if f is None else f.py_func


def cell_load(grid, scratch, i, j, k):
    """Per-cell context, ``ctx[0], ctx[1]`` a conservative value range (compiled code only)."""
    raise NotImplementedError


@overload_jit(cell_load, inline="never")
def _cell_load(grid, scratch, i, j, k):
    f = _impl(grid, "cell_load")
    return None if f is None else f.py_func


def cell_pieces(grid, scratch, ctx, cell, a, e, cuts, tags):
    """Cut a cell's segment into pieces; returns their number (compiled code only)."""
    raise NotImplementedError


@overload_jit(cell_pieces, inline="never")
def _cell_pieces(grid, scratch, ctx, cell, a, e, cuts, tags):
    f = _impl(grid, "cell_pieces")
    return None if f is None else f.py_func


def piece_range(grid, scratch, ctx, i, j, k, tag):
    """Conservative value range of a piece (compiled code only)."""
    raise NotImplementedError


@overload_jit(piece_range, inline="never")
def _piece_range(grid, scratch, ctx, i, j, k, tag):
    f = _impl(grid, "piece_range")
    return None if f is None else f.py_func


def piece_poly(grid, scratch, ctx, cell, tag, a, b):
    """The piece's polynomial from local point ``a`` to ``b`` (compiled code only)."""
    raise NotImplementedError


@overload_jit(piece_poly, inline="never")
def _piece_poly(grid, scratch, ctx, cell, tag, a, b):
    f = _impl(grid, "piece_poly")
    return None if f is None else f.py_func


def gradient(grid, scratch, ctx, i, j, k, tag, x, y, z):
    """Index-space gradient at a local point of a cell's piece (compiled code only)."""
    raise NotImplementedError


@overload_jit(gradient, inline="never")
def _gradient(grid, scratch, ctx, i, j, k, tag, x, y, z):
    f = _impl(grid, "gradient")
    return None if f is None else f.py_func


def value_gradient_at(grid, scratch, x, y, z):
    """Value and gradient at a point of the grid's traversal space (compiled code only)."""
    raise NotImplementedError


@overload_jit(value_gradient_at, inline="never")
def _value_gradient_at(grid, scratch, x, y, z):
    f = _impl(grid, "value_gradient_at")
    return None if f is None else f.py_func


def value_at(grid, scratch, x, y, z):
    """Value at a point of the grid's traversal space, clamped into it (compiled code only)."""
    raise NotImplementedError


def _value_of_value_gradient(grid, scratch, x, y, z):
    return value_gradient_at(grid, scratch, x, y, z)[0]


@overload_jit(value_at, inline="never")
def _value_at(grid, scratch, x, y, z):
    if getattr(grid, "instance_class", None) not in _HOOKS:
        return None
    f = _impl(grid, "value_at")
    return _value_of_value_gradient if f is None else f.py_func


def value_on_plane(grid, scratch, axis, p, a, b):
    """Value on a plane of voxels across ``axis`` (compiled code only)."""
    raise NotImplementedError


def _value_anywhere(grid, scratch, axis, p, a, b):
    if axis == 0:
        return value_at(grid, scratch, p, a, b)
    if axis == 1:
        return value_at(grid, scratch, a, p, b)
    return value_at(grid, scratch, a, b, p)


@overload_jit(value_on_plane, inline="never")
def _value_on_plane(grid, scratch, axis, p, a, b):
    if getattr(grid, "instance_class", None) not in _HOOKS:
        return None
    f = _impl(grid, "value_on_plane")
    return _value_anywhere if f is None else f.py_func


def look_ahead(grid):
    """Whether the fixed-step loop takes values one sample early (compiled code only)."""
    raise NotImplementedError


def _no_look_ahead(grid):
    return False


@overload_jit(look_ahead, inline="never")
def _look_ahead(grid):
    if getattr(grid, "instance_class", None) not in _HOOKS:
        return None
    f = _impl(grid, "look_ahead")
    return _no_look_ahead if f is None else f.py_func


def prefetch_at(grid, scratch, x, y, z):
    """Prefetch what ``value_at`` reads at a point (compiled code only)."""
    raise NotImplementedError


def _no_prefetch(grid, scratch, x, y, z):
    return None


@overload_jit(prefetch_at, inline="never")
def _prefetch_at(grid, scratch, x, y, z):
    if getattr(grid, "instance_class", None) not in _HOOKS:
        return None
    f = _impl(grid, "prefetch_at")
    return _no_prefetch if f is None else f.py_func


def separate_shading(grid):
    """Whether the model shades with a smooth field of its own (compiled code only)."""
    raise NotImplementedError


def _no_separate_shading(grid):
    return False


@overload_jit(separate_shading, inline="never")
def _separate_shading(grid):
    if getattr(grid, "instance_class", None) not in _HOOKS:
        return None
    f = _impl(grid, "separate_shading")
    return _no_separate_shading if f is None else f.py_func


def shading_gradient_at(grid, scratch, x, y, z):
    """The shading field's gradient at a point of the traversal space (compiled code only)."""
    raise NotImplementedError


def _gradient_of_value_gradient(grid, scratch, x, y, z):
    _, gx, gy, gz = value_gradient_at(grid, scratch, x, y, z)
    return gx, gy, gz


@overload_jit(shading_gradient_at, inline="never")
def _shading_gradient_at(grid, scratch, x, y, z):
    if getattr(grid, "instance_class", None) not in _HOOKS:
        return None
    f = _impl(grid, "shading_gradient_at")
    return _gradient_of_value_gradient if f is None else f.py_func


# Hooks shared by the models whose cell is a single piece (trilinear, B-splines).

@jit()
def whole_cell(grid, scratch, ctx, cell, a, e, cuts, tags):
    """``cell_pieces`` of a model whose whole cell is one polynomial piece."""
    cuts[0] = 0.0
    cuts[1] = 1.0
    tags[0] = 0
    return 1


@jit()
def cell_range(grid, scratch, ctx, i, j, k, tag):
    """``piece_range`` of a one-piece cell: the cell's own range from ``cell_load``."""
    return ctx[0], ctx[1]
