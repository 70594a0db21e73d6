"""OME-Zarr (NGFF) image metadata: axes, axis order and per-level coordinate transformations.

The one place where NGFF's axis order meets splinecast's. NGFF stores a 3D image as a Zarr array
whose dimensions are listed in ``multiscales[0]["axes"]``, spatial axes last and, as the
specification recommends, in the order ``z, y, x`` (the last index varies fastest, so ``x`` rows
are contiguous). splinecast indexes ``data[i, j, k]`` with ``i`` along x (see
:mod:`splinecast.volume`). :func:`spatial_order` says which array axis holds x, y and z; every
reader and writer in the package goes through it, and through :func:`to_ngff` /
:func:`from_ngff` for triples (shapes, spacings, origins).

A level's transformations map array indices to physical coordinates: ``p = scale * index +
translation`` (scale first, then translation; NGFF 0.4 and 0.5). That is the voxel-centre
convention of :mod:`splinecast.volume` with ``spacing = scale`` and ``origin = translation``.
Transformations listed for the whole multiscale apply after the level's own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ReadError
from ..errors.limits import printable, shorten

__all__ = [
    "NGFF_VERSION",
    "NGFF_AXES",
    "UNITS",
    "to_ngff",
    "from_ngff",
    "spatial_order",
    "ngff_unit",
    "multiscales_attributes",
    "NgffImage",
    "NgffDataset",
    "parse_image",
    "omero_channels",
]

#: The OME-Zarr version splinecast writes (Zarr v3).
NGFF_VERSION = "0.5"
#: Spatial axis names in the order NGFF recommends and splinecast writes.
NGFF_AXES = ("z", "y", "x")
#: Spellings of length units found in file headers -> the UDUNITS-2 name NGFF asks for.
UNITS = {
    "mm": "millimeter", "millimeter": "millimeter", "millimetre": "millimeter",
    "um": "micrometer", "µm": "micrometer", "micron": "micrometer", "micrometer": "micrometer",
    "nm": "nanometer", "nanometer": "nanometer", "m": "meter", "meter": "meter",
    "cm": "centimeter", "centimeter": "centimeter", "angstrom": "angstrom", "pm": "picometer",
}


def to_ngff(xyz: Sequence[Any]) -> list[Any]:
    """A splinecast triple ``(x, y, z)`` in NGFF order ``[z, y, x]``."""
    return [xyz[2], xyz[1], xyz[0]]


def from_ngff(zyx: Sequence[Any]) -> tuple[Any, Any, Any]:
    """An NGFF triple ``[z, y, x]`` in splinecast order ``(x, y, z)``."""
    return (zyx[2], zyx[1], zyx[0])


def spatial_order(names: Sequence[str]) -> tuple[int, int, int]:
    """For three spatial axis names in array order, the array axis of x, of y and of z.

    Names that are a permutation of x, y, z (any case) are honoured; anything else is read in the
    order NGFF recommends, ``z, y, x`` (so ``(2, 1, 0)``).

    >>> spatial_order(["z", "y", "x"])
    (2, 1, 0)
    >>> spatial_order(["X", "Y", "Z"])
    (0, 1, 2)
    """
    lower = [str(n).lower() for n in names]
    if sorted(lower) == ["x", "y", "z"]:
        return (lower.index("x"), lower.index("y"), lower.index("z"))
    return (2, 1, 0)


def ngff_unit(unit: Any) -> str | None:
    """The NGFF (UDUNITS-2) name of a length unit, ``None`` when unknown."""
    if unit is None:
        return None
    return UNITS.get(str(unit).strip().lower())


def multiscales_attributes(
    name: str,
    datasets: Sequence[tuple[str, Sequence[float], Sequence[float]]],
    unit: str | None = None,
    downsampling: str | None = None,
    downsampling_metadata: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The group attributes of an OME-Zarr 0.5 image with three spatial axes.

    Parameters
    ----------
    name : str
        The image's name.
    datasets : sequence of (path, spacing, origin)
        One entry per level, finest first; ``spacing`` and ``origin`` in splinecast order
        ``(x, y, z)`` and world units (the centre of voxel 0 is at ``origin``).
    unit : str, optional
        A UDUNITS-2 length unit (``"millimeter"``) for all three axes.
    downsampling : str, optional
        The ``type`` field: how the coarser levels were made.
    downsampling_metadata : dict, optional
        The ``metadata`` field describing the downsampling.
    """
    axes = []
    for axis in NGFF_AXES:
        entry: dict[str, Any] = {"name": axis, "type": "space"}
        if unit:
            entry["unit"] = unit
        axes.append(entry)
    entries = [
        {
            "path": path,
            "coordinateTransformations": [
                {"type": "scale", "scale": [float(v) for v in to_ngff(spacing)]},
                {"type": "translation", "translation": [float(v) for v in to_ngff(origin)]},
            ],
        }
        for path, spacing, origin in datasets
    ]
    multiscale: dict[str, Any] = {"name": name, "axes": axes, "datasets": entries}
    if downsampling:
        multiscale["type"] = downsampling
    if downsampling_metadata:
        multiscale["metadata"] = downsampling_metadata
    return {"ome": {"version": NGFF_VERSION, "multiscales": [multiscale]}}


# --------------------------------------------------------------------------- reading
@dataclass(frozen=True)
class NgffDataset:
    """One resolution level as the metadata describes it (full array dimensionality)."""

    path: str
    scale: tuple[float, ...]
    translation: tuple[float, ...]


@dataclass(frozen=True)
class NgffImage:
    """What splinecast needs from an image's ``multiscales`` metadata."""

    version: str
    name: str | None
    axis_names: tuple[str, ...]
    axis_types: tuple[str | None, ...]
    units: tuple[str | None, ...]
    spatial: tuple[int, ...]  # positions of the three spatial axes in the array
    datasets: tuple[NgffDataset, ...]
    downsampling: str | None


def _transform(entries: Any, ndim: int, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Scale and translation from a list of NGFF transformations (scale first, then translation)."""
    scale = np.ones(ndim)
    translation = np.zeros(ndim)
    if entries is None:
        return scale, translation
    if not isinstance(entries, list):
        raise ReadError(f"{where}: coordinateTransformations must be a list")
    for entry in entries:
        kind = entry.get("type") if isinstance(entry, dict) else None
        if kind == "identity":
            continue
        if kind not in ("scale", "translation"):
            raise ReadError(f"{where}: unsupported coordinate transformation {kind!r}")
        if "path" in entry and kind not in entry:
            raise ReadError(f"{where}: {kind} stored in a separate array is not supported")
        try:
            values = np.asarray(entry.get(kind), dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            values = np.full(0, np.nan)
        if values.shape != (ndim,) or not np.all(np.isfinite(values)):
            raise ReadError(f"{where}: {kind} must be {ndim} finite numbers, got {entry.get(kind)}")
        if kind == "scale":
            if np.any(values <= 0):
                raise ReadError(f"{where}: scale must be positive, got {values.tolist()}")
            scale, translation = scale * values, translation * values
        else:
            translation = translation + values
    return scale, translation


def parse_image(attributes: dict[str, Any], label: str) -> NgffImage | None:
    """Read the first multiscale image of a group's attributes (NGFF 0.4 or 0.5).

    Returns ``None`` when the attributes hold no ``multiscales`` entry. Raises
    :class:`~splinecast.errors.ReadError` naming ``label`` when the entry is malformed.
    """
    ome = attributes.get("ome")
    if isinstance(ome, dict) and "multiscales" in ome:  # 0.5: namespaced under "ome"
        version = shorten(ome.get("version", "0.5"), 24).strip("'")
        multiscales = ome["multiscales"]
    elif "multiscales" in attributes:  # 0.4 and older: top level, version inside
        multiscales = attributes["multiscales"]
        first = multiscales[0] if isinstance(multiscales, list) and multiscales else {}
        version = str(first.get("version", "0.4")) if isinstance(first, dict) else "0.4"
    else:
        return None
    if not isinstance(multiscales, list) or not multiscales or not isinstance(multiscales[0], dict):
        raise ReadError(f"{label}: 'multiscales' must be a non-empty list")
    ms = multiscales[0]
    axes = ms.get("axes")
    if axes is None:  # 0.1 / 0.2: always t, c, z, y, x
        axes = [{"name": n} for n in "tczyx"]
    if not isinstance(axes, list) or not 2 <= len(axes) <= 5:
        raise ReadError(f"{label}: 'axes' must list 2 to 5 axes")
    names, types, units = [], [], []
    for n, axis in enumerate(axes):
        if isinstance(axis, str):  # 0.3 lists bare names
            axis = {"name": axis}
        fields = (axis.get("name"), axis.get("type"), axis.get("unit")) \
            if isinstance(axis, dict) else (None, None, None)
        if not isinstance(fields[0], str) or not all(isinstance(v, str | None)
                                                     for v in fields[1:]):
            raise ReadError(f"{label}: axis {n} must have a text 'name' (and text 'type' and "
                            f"'unit'), got {shorten(axis)}")
        names.append(fields[0])
        kind = fields[1]
        if kind is None and names[-1].lower() in ("x", "y", "z"):
            kind = "space"
        types.append(kind)
        units.append(fields[2])
    if len(set(names)) != len(names):
        raise ReadError(f"{label}: axis names must be unique, got {names}")
    spatial = tuple(i for i, t in enumerate(types) if t == "space")
    if len(spatial) != 3:
        raise ReadError(
            f"{label}: splinecast needs 3 spatial axes, the image has {len(spatial)} "
            f"({', '.join(names)})"
        )
    ndim = len(names)
    outer_scale, outer_translation = _transform(
        ms.get("coordinateTransformations"), ndim, f"{label}: multiscales"
    )
    entries = ms.get("datasets")
    if not isinstance(entries, list) or not entries:
        raise ReadError(f"{label}: 'datasets' must be a non-empty list")
    datasets = []
    for n, entry in enumerate(entries):
        if not isinstance(entry, dict) or not isinstance(entry.get("path"), str):
            raise ReadError(f"{label}: dataset {n} has no 'path'")
        where = f"{label}: dataset {entry['path']!r}"
        scale, translation = _transform(entry.get("coordinateTransformations"), ndim, where)
        datasets.append(
            NgffDataset(
                entry["path"],
                tuple(float(v) for v in scale * outer_scale),
                tuple(float(v) for v in translation * outer_scale + outer_translation),
            )
        )
    name = ms.get("name")
    downsampling = ms.get("type")
    return NgffImage(
        version=version,
        name=str(name) if name is not None else None,
        axis_names=tuple(names),
        axis_types=tuple(types),
        units=tuple(units),
        spatial=spatial,
        datasets=tuple(datasets),
        downsampling=downsampling if isinstance(downsampling, str) else None,
    )


# --------------------------------------------------------------------------- omero
def _omero_color(value: Any) -> tuple[float, float, float] | None:
    """An ``omero`` channel colour (``"FF0000"``, 6 hex digits, ``#`` tolerated) as RGB in
    [0, 1]; ``None`` for anything else."""
    if not isinstance(value, str):
        return None
    text = value.strip().lstrip("#")
    if len(text) != 6:
        return None
    try:
        packed = int(text, 16)
    except ValueError:
        return None
    return ((packed >> 16) / 255.0, ((packed >> 8) & 255) / 255.0, (packed & 255) / 255.0)


def _omero_window(value: Any) -> tuple[float, float] | None:
    """``window.start`` and ``window.end`` as ``(lo, hi)`` with ``lo < hi``, else ``None``."""
    if not isinstance(value, dict):
        return None
    try:
        lo, hi = float(value["start"]), float(value["end"])
    except (KeyError, TypeError, ValueError, OverflowError):
        return None
    return (lo, hi) if np.isfinite(lo) and np.isfinite(hi) and lo < hi else None


def omero_channels(attributes: dict[str, Any], count: int) -> list[dict[str, Any]] | None:
    """The display settings of an image's channels from its ``omero`` metadata.

    ``omero`` is transitional NGFF metadata (0.4 at the top of the attributes, 0.5 under
    ``"ome"``) written by ome-zarr-py, OMERO and Fiji: per channel a ``label``, a ``color``
    (``"RRGGBB"``), a ``window`` (``start``/``end`` shown, ``min``/``max`` of the data) and
    ``active``. Display metadata never stops an image from being read: a malformed field is
    left out (``None``), and a list whose length is not ``count`` (the image's channels) is
    ignored.

    Returns
    -------
    list of dict or None
        One ``{"label", "color", "window", "active"}`` per channel (``color`` RGB in [0, 1],
        ``window`` ``(start, end)``, either ``None`` when absent), or ``None`` without usable
        ``omero`` metadata.
    """
    ome = attributes.get("ome")
    omero = attributes.get("omero")
    if omero is None and isinstance(ome, dict):
        omero = ome.get("omero")
    channels = omero.get("channels") if isinstance(omero, dict) else None
    if not isinstance(channels, list) or len(channels) != count:
        return None
    found = []
    for entry in channels:
        entry = entry if isinstance(entry, dict) else {}
        label = entry.get("label")
        active = entry.get("active")
        found.append({
            "label": printable(label)[:80] if isinstance(label, str) else None,
            "color": _omero_color(entry.get("color")),
            "window": _omero_window(entry.get("window")),
            "active": active if isinstance(active, bool) else True,
        })
    return found
