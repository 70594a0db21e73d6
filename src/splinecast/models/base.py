"""What a model tells the layers above it: its interface and its capabilities, in one place.

Scenes, pyramids, wavelet stores and the distributed renderers hold a model and ask it what they
need to know; they never test which model it is (no attribute probes, no tables keyed by model
name). Every model class derives from :class:`ReconstructionModel`, which documents each question
and gives the answer of a plain model (one that reads a brick of its prepared array as it is, with
no isovalue classification of its cells); a model that differs overrides the answer in its own
module. A new model is then a module in this package and an entry in
:data:`splinecast.models.MODELS`, and every layer above renders it without a change.

A capability that needs code of a higher layer is expressed as data (a border rule's name for
``numpy.pad``, a degree) or as a function of plain arrays the model supplies (a brick prefilter),
because this package imports nothing above it.
"""

from __future__ import annotations

import inspect
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np

__all__ = ["ActiveCellClassifier", "BrickRefusal", "ReconstructionModel"]


class BrickRefusal(NamedTuple):
    """Why a model with some options cannot be rendered brick by brick (see
    :meth:`ReconstructionModel.brick_refusal`)."""

    #: The option at fault, as the user wrote it (``"prefilter=True"``).
    option: str
    #: Why bricks cannot honour it, and what to do instead.
    reason: str


class ActiveCellClassifier(Protocol):
    """What :class:`splinecast.accel.active_cells.ActiveCells` reads to classify the cells of a
    model by isovalue (the type-6 splines' cubes and tetrahedra).

    The acceleration layer knows nothing of models; a model that classifies its cells hands an
    object of this shape (usually itself) from
    :meth:`ReconstructionModel.active_cell_classifier`.
    """

    #: Exact per-cube coefficient ranges, arrays of the cube grid's shape.
    cube_lo: np.ndarray
    cube_hi: np.ndarray
    #: Cubes per axis.
    n_cells: tuple[int, ...]
    #: Coefficients per cube.
    n_points: int
    #: Whether the coefficients of the active cubes are stored after an isovalue change.
    precompute: bool
    #: Memory held independently of the isovalue, in bytes.
    static_nbytes: int

    def tet_masks(self, cubes: np.ndarray, iso: float) -> np.ndarray:
        """24-bit masks of the pieces of ``cubes`` (linear indices) that may hold ``iso``."""
        ...

    def coefficient_rows(self, cubes: np.ndarray) -> np.ndarray:
        """All coefficients of ``cubes``, shape ``(len(cubes), n_points)``."""
        ...


class ReconstructionModel:
    """Base of every model: the interface the layers above use, with a plain model's answers.

    A model instance is prepared from a :class:`~splinecast.Volume` and offers (each subclass
    defines these): ``volume``; ``prepared``, the array its kernels read, cell ``c`` depending
    on ``prepared[c .. c + support]``; ``coefficients``, the values that bound it cell by cell;
    ``domain()``, the rendered box in voxel index space; ``kernel_grid(array)``, the compiled
    kernels' grid over a block of ``prepared`` (:mod:`splinecast.models.pieces`); ``shift``,
    where the traversal puts cell ``c``; ``nbytes``, the memory it holds. The attributes and
    methods below are the capabilities the render, multiresolution and distributed layers ask
    about.
    """

    #: The name users pass as ``Scene(volume, model=...)``.
    name: ClassVar[str] = ""
    #: Cell ``c`` depends on ``prepared[c .. c + support]`` per axis; a brick carries that many
    #: ghost layers beyond its cells.
    support: ClassVar[int] = 1
    #: How the model extends its data beyond the volume's ends, as a ``numpy.pad`` mode: a
    #: brick of a pyramid level fills its ghost layers beyond the level's ends the same way, so
    #: bricks reproduce the whole level (``"edge"`` repeats the outer voxel, ``"reflect"``
    #: mirrors about it).
    border_rule: ClassVar[str] = "edge"
    #: The spline degree for which the reconstruction of a coarser pyramid level is exactly
    #: one of the finer level (the coarse spline refined by subdivision), so that restricting
    #: the finer bricks at a level boundary closes the seam by itself; None when the coarse
    #: reconstruction is not a fine one (then the seam needs the isosurface's closure).
    nested_degree: ClassVar[int | None] = None
    #: Whether the block hierarchy is built from the model's exact per-cell bounds
    #: (``cube_bounds_of(array)``) rather than from the min/max of the prepared values.
    cube_bounded: ClassVar[bool] = False
    #: Values a separate shading field reads beyond a cell's support on each side
    #: (:mod:`splinecast.models.shading_field`); a brick's grid then carries them as its halo.
    #: 0: none.
    shading_halo: ClassVar[int] = 0
    #: Pixel rows handed out to a thread at once, and the side of the square tiles they are
    #: traced in (0: whole rows): models whose cells cost loads rather than arithmetic keep
    #: neighbouring rays together while their values are in the cache.
    band_rows: ClassVar[int] = 1
    tile: ClassVar[int] = 0
    #: Rows of a thread's work item when larger than ``band_rows`` (0: ``band_rows``): the
    #: item's tiles are traced a column at a time, so rays that share voxels are traced close
    #: in time (the tiles and their pixels stay the same).
    work_rows: ClassVar[int] = 0
    #: Seconds a first render's kernels typically take to compile from an empty cache on a
    #: 2-core machine (an order of magnitude, shown to users while they wait).
    typical_compile_s: ClassVar[int] = 60
    #: The model options the class takes (``Scene(volume, model, **options)``): what the
    #: command line's ``--root-finder``, ``--iterations`` and ``--prefilter`` may set. Unless a
    #: class declares them, the keywords of its constructor after the volume.
    option_names: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "option_names" not in cls.__dict__:
            # Written once, in the signature users read (help(MODELS[name])).
            parameters = list(inspect.signature(cls.__init__).parameters.values())[2:]
            cls.option_names = tuple(p.name for p in parameters if p.kind in (
                p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))

    @classmethod
    def brick_refusal(cls, options: dict[str, Any]) -> BrickRefusal | None:
        """Why the model, with these options, cannot be rendered brick by brick from a pyramid
        level (None: it can).

        Parameters
        ----------
        options : dict
            The model options the user passed (as for :class:`~splinecast.Scene`).

        Returns
        -------
        BrickRefusal or None
            The option at fault and why, or None.
        """
        return None

    @property
    def value_overshoot(self) -> float:
        """How far the reconstruction may reach beyond the range of the values it is built
        from, as a fraction of that range (0: it stays inside, a convex combination); a filter
        of bricks by their value range widens the range by this much."""
        return 0.0

    @property
    def grid_copy_dtype(self) -> np.dtype | None:
        """The dtype ``kernel_grid`` converts a block of values into (None: the block is read
        as it is, without a copy); a brick cache shares its memory budget with those copies."""
        return None

    def prefilter_brick(self, data: np.ndarray, first: np.ndarray,
                        level_shape: Any) -> tuple[np.ndarray, np.ndarray]:
        """The values the kernels read for a brick of a pyramid level, from its voxels.

        Parameters
        ----------
        data : ndarray
            The brick's voxels with their ghost layers.
        first : ndarray of 3 ints
            The level index of ``data[0, 0, 0]``.
        level_shape : 3 ints
            The level's shape, for the border rule at its ends.

        Returns
        -------
        (ndarray, ndarray)
            The prepared values and the level index of their first element: ``(data, first)``
            unchanged for a model that renders its voxels as they are.
        """
        return data, first

    def active_cell_classifier(self) -> ActiveCellClassifier | None:
        """What classifies the model's cells per isovalue (the scene then keeps work lists of
        the active cells and hands them to ``kernel_grid(active=...)``); None: the model's
        cells are leapt by value ranges alone."""
        return None
