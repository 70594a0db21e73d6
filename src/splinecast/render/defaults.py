"""What splinecast shows when it is not told: isovalue, MIP window, transfer function, framing.

A newcomer types ``splinecast render head.nii.gz -o head.png`` without knowing the data's values;
VTK, napari and PyVista show something sensible in that case, and so does splinecast. Every
default here is computed from the volume's histogram with a documented rule, and the command line
prints what it chose so that the user learns the numbers to change.

Background (:func:`background_value`)
    The value of the empty space around the object: the zero padding around an MRI head, the
    air outside a CT's field of view, the empty space of a label volume or a mask, the zeros
    outside the brain of a signed statistical map. Of the two candidates, the volume's minimum
    and 0 (when 0 is a value of the volume's range), it is the one more voxels hold, provided
    that is at least :data:`BACKGROUND_SHARE` of them; else the minimum. Background voxels are
    left out of every statistic below, so a large empty region cannot pull a threshold towards
    itself (removing the handful of voxels at the minimum of a volume without such a region
    changes nothing noticeable).

Signed data (:func:`is_signed`)
    A background of 0 with values on both sides of it, each side at least
    :data:`SIGNED_SHARE` of the other voxels: a statistical map (t, z, beta), a difference
    image, a phase map. A CT is not signed: its background (-1024 or -1000) is not 0, and an
    MRI with a few negative voxels of interpolation ringing is not either. Signed data gets the
    diverging colormap :data:`~splinecast.transfer.DIVERGING` and a window symmetric about 0.

Sampling
    Statistics come from at most :data:`SAMPLE_VOXELS` voxels: a volume with more is read with the
    same stride along every axis (a strided view; a memory map reads only those pages). NaN and
    infinite values are ignored.

Isovalue (:func:`auto_iso`)
    ``metadata["default_iso"]`` when the volume has one (the demo volumes do), else Otsu's
    threshold of the non-background values: the split of their histogram that maximises the
    variance between the two classes (Otsu 1979). For integer data the histogram has one bin per
    integer (up to :data:`HISTOGRAM_BINS` bins) and the threshold lies halfway between two
    integers, so no voxel sits exactly on the surface. When the non-background voxels hold a
    single value (a mask), the isovalue is halfway between it and the background. Signed data:
    Otsu's threshold ``T`` of the absolute values, a surface around the strong positive values
    (``iso=[-T, T]`` shows both signs; the command line prints the suggestion).

MIP / minIP window (:func:`auto_window`)
    From the image a projection shows rather than from the voxels: the volume's maximum
    projections (minimum for minIP) along its three axes stand in for the view (a projection
    picks the extreme value along every ray, so its pixels hold the top of the voxel
    distribution: the window of the voxels' percentiles left a brain MIP washed out to white).
    The window is the :data:`WINDOW_PERCENTILES` (5th and 99.9th; for minIP the 0.1st and 95th)
    of those projections' pixels, leaving out the pixels whose ray meets only background: the
    dimmest 5% of the object's pixels (its rim) reach black and structure inside shows, while a
    few outliers such as metal in a CT cannot compress the window. It does not depend on the
    view, so a turntable movie or the viewer keeps one window. Signed data: symmetric,
    ``(-m, m)`` with ``m`` the 99.9th percentile of the absolute values of the maximum and
    minimum projections. When the percentiles (nearly) coincide (a probability map's MIP is 1
    almost everywhere), the window runs from the background to the largest value.
    (napari's default contrast limits are the data's minimum and maximum: simple, but a single
    bright voxel compresses them, and they do not look at what a projection shows.)

MIP / minIP colormap (:func:`auto_colormap`)
    ``gray``; :data:`~splinecast.transfer.DIVERGING` for signed data. Pixels whose projected
    value is the background value (their ray meets only background, or for signed data nothing
    beyond 0 in the projection's direction) show the background colour, so the volume's box is
    not drawn.

Inside (:func:`auto_inside`)
    Which side of an isovalue is the object: ``metadata["inside"]`` when the volume has it,
    else ``"low"`` for an isovalue below the background (a negative isovalue of a signed map:
    the object is the values below it) and ``"high"`` otherwise. Rays start in the background,
    so the surface they meet first is then a front face.

DVR transfer function (:func:`auto_transfer_function`)
    Opacity rises linearly from 0 at the isovalue of :func:`auto_iso` (where the object starts) to
    :data:`DVR_MAX_OPACITY` per voxel at the 99.5th percentile of the non-background values, and
    stays there above it; the ``viridis`` colormap (perceptually uniform) spans the same range.

Framing (:func:`content_box`)
    The world box of the voxels the isovalue or transfer function makes visible, for
    :meth:`splinecast.Camera.orbit`'s ``fit``.
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..transfer import DIVERGING, TransferFunction
from ..volume import Volume

__all__ = [
    "BACKGROUND_SHARE",
    "SIGNED_SHARE",
    "background_value",
    "is_signed",
    "auto_colormap",
    "auto_inside",
    "SAMPLE_VOXELS",
    "HISTOGRAM_BINS",
    "DVR_MAX_OPACITY",
    "WINDOW_PERCENTILES",
    "DVR_TOP_PERCENTILE",
    "sample_values",
    "otsu_threshold",
    "auto_iso",
    "auto_window",
    "auto_transfer_function",
    "content_box",
]

#: Largest number of voxels a statistic reads; bigger volumes are strided evenly.
SAMPLE_VOXELS = 4_000_000
#: Largest number of histogram bins of Otsu's threshold.
HISTOGRAM_BINS = 1024
#: Opacity of a one-voxel slab at the top of the default DVR ramp.
DVR_MAX_OPACITY = 0.1
#: Percentiles of the pixels of the axis-aligned maximum projections (non-background) that bound
#: the default MIP window; minIP takes ``(100 - hi, 100 - lo)`` of the minimum projections.
WINDOW_PERCENTILES = (5.0, 99.9)
#: Smallest share of the voxels that the background value must hold (else: the minimum).
BACKGROUND_SHARE = 0.01
#: Smallest share of the non-background voxels on each side of 0 for data to count as signed.
SIGNED_SHARE = 0.05
#: Percentile of the non-background values where the default DVR opacity ramp reaches its top.
DVR_TOP_PERCENTILE = 99.5

# Statistics already computed for a volume (keyed weakly: they go when the volume goes).
_CACHE: weakref.WeakKeyDictionary[Volume, dict[str, Any]] = weakref.WeakKeyDictionary()


def _stride(shape: tuple[int, ...], max_voxels: int) -> int:
    """The smallest equal per-axis stride that leaves at most ``max_voxels`` voxels."""
    stride = max(1, math.ceil((math.prod(shape) / max_voxels) ** (1.0 / 3.0)))
    while math.prod(-(-n // stride) for n in shape) > max_voxels:
        stride += 1
    return stride


def _cached(volume: Volume, key: str, compute: Any) -> Any:
    entry = _CACHE.setdefault(volume, {})
    if key not in entry:
        entry[key] = compute()
    return entry[key]


def _sample(volume: Volume, max_voxels: int = SAMPLE_VOXELS) -> np.ndarray:
    """The volume read at the stride that leaves at most ``max_voxels`` voxels (float64, 3D)."""
    stride = _stride(volume.shape, max_voxels)
    return np.asarray(volume.data[::stride, ::stride, ::stride], dtype=np.float64)


def background_value(volume: Any) -> float:
    """The value of the volume's empty space (see the module's description).

    The volume's minimum or 0, whichever more voxels hold, if that is at least
    :data:`BACKGROUND_SHARE` of the voxels; else the minimum. ``metadata["background"]`` when
    the volume has it (a header without voxels carries it so).

    Examples
    --------
    >>> import numpy as np, splinecast as sc
    >>> data = np.zeros((20, 20, 20), np.float32)
    >>> data[5:10, 5:15, 5:15], data[10:15, 5:15, 5:15] = -3.0, 2.0   # a signed map
    >>> sc.background_value(sc.Volume(data))
    0.0
    """
    if volume.metadata.get("background") is not None:
        return float(volume.metadata["background"])

    def compute() -> float:
        lo, hi = (float(v) for v in volume.value_range)
        values = _sample(volume)
        counts = {lo: int(np.count_nonzero(values == lo))}
        if lo < 0.0 <= hi:
            counts[0.0] = int(np.count_nonzero(values == 0.0))
        best = max(counts, key=lambda v: counts[v])
        return best if counts[best] >= BACKGROUND_SHARE * values.size else lo

    return _cached(volume, "background", compute)


def sample_values(volume: Volume, max_voxels: int = SAMPLE_VOXELS) -> np.ndarray:
    """The finite, non-background voxel values the defaults are computed from (float64, 1D).

    At most ``max_voxels`` voxels are read (an even stride along every axis). The background is
    :func:`background_value`; when every voxel holds it, the result is empty.
    """
    values = _sample(volume, max_voxels).ravel()
    values = values[np.isfinite(values)]
    return values[values != background_value(volume)]


def is_signed(volume: Any) -> bool:
    """Whether the volume holds signed data: a background of 0 with values on both sides, each
    side at least :data:`SIGNED_SHARE` of the non-background voxels (see the module's
    description). ``metadata["signed"]`` when the volume has it."""
    if volume.metadata.get("signed") is not None:
        return bool(volume.metadata["signed"])

    def compute() -> bool:
        if background_value(volume) != 0.0:
            return False
        values = sample_values(volume)
        if values.size == 0:
            return False
        below = np.count_nonzero(values < 0.0) / values.size
        return bool(min(below, 1.0 - below) >= SIGNED_SHARE)

    return _cached(volume, "signed", compute)


def auto_colormap(volume: Any) -> str:
    """The MIP / minIP colormap used when none is given: ``metadata["default_colormap"]``,
    else :data:`~splinecast.transfer.DIVERGING` for signed data (:func:`is_signed`), else
    ``"gray"``."""
    if volume.metadata.get("default_colormap") is not None:
        return str(volume.metadata["default_colormap"])
    return DIVERGING if is_signed(volume) else "gray"


def auto_inside(volume: Any, iso: Any = None) -> str:
    """Which side of ``iso`` is the object when not told: ``metadata["inside"]``, else
    ``"low"`` when every isovalue lies below :func:`background_value` (the object is the values
    below it, as for a negative isovalue of a signed map), else ``"high"``.

    ``iso`` is a number, a list of numbers or ``None`` (:func:`auto_iso`).
    """
    if volume.metadata.get("inside") is not None:
        return str(volume.metadata["inside"])
    isos = np.atleast_1d(np.asarray(auto_iso(volume) if iso is None else iso, np.float64))
    if isos.size and np.all(isos < background_value(volume)):
        return "low"
    return "high"


def otsu_threshold(values: np.ndarray, integer: bool = False,
                   bins: int = HISTOGRAM_BINS) -> float:
    """Otsu's threshold of ``values``: the histogram split maximising the between-class variance.

    Parameters
    ----------
    values : ndarray
        Finite values (any shape), at least two distinct ones.
    integer : bool
        The values are integers: bins are whole numbers wide and centred on integers, so the
        threshold lies halfway between two integers.
    bins : int
        Largest number of bins.

    Returns
    -------
    float
        A value strictly between the smallest and largest of ``values``: voxels above it form
        one class, voxels below the other.
    """
    values = np.asarray(values, dtype=np.float64).ravel()
    lo, hi = float(values.min()), float(values.max())
    if not hi > lo:
        raise ParameterError("Otsu's threshold needs at least two distinct values")
    if integer:
        width = max(1, math.ceil((hi - lo + 1) / bins))
        n = int((hi - lo) // width) + 1
        edges = lo - 0.5 + width * np.arange(n + 1)
        counts = np.bincount(((values - lo) // width).astype(np.int64), minlength=n)
        centres = lo + width * np.arange(n) + 0.5 * (width - 1)
    else:
        counts, edges = np.histogram(values, bins=bins, range=(lo, hi))
        centres = 0.5 * (edges[:-1] + edges[1:])
    counts = counts.astype(np.float64)
    # Class 0 is bins 0..k, class 1 bins k+1..; the between-class variance is
    # w0 * w1 * (mu0 - mu1)^2 with weights w and means mu of the two classes.
    w0 = np.cumsum(counts)[:-1]
    s0 = np.cumsum(counts * centres)[:-1]
    total, total_sum = counts.sum(), float(np.dot(counts, centres))
    w1 = total - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        between = w0 * w1 * (s0 / w0 - (total_sum - s0) / w1) ** 2
    between[(w0 == 0) | (w1 == 0)] = -1.0
    k = int(np.argmax(between))
    return float(edges[k + 1])


def auto_iso(volume: Volume) -> float:
    """The isovalue shown when none is given (see the module's description).

    Returns ``volume.metadata["default_iso"]`` when present, else Otsu's threshold of the
    non-background values; for a constant volume, its value (the image is then empty).

    Examples
    --------
    >>> import numpy as np, splinecast as sc
    >>> data = np.zeros((20, 20, 20), np.uint8)
    >>> data[5:15, 5:15, 5:15] = 100        # a mask: one value besides the background
    >>> sc.auto_iso(sc.Volume(data))
    50.0
    """
    if volume.metadata.get("default_iso") is not None:
        return float(volume.metadata["default_iso"])

    def compute() -> float:
        lo, hi = volume.value_range
        values = sample_values(volume)
        if values.size == 0:
            return float(lo)  # constant volume: nothing to show
        vmin, vmax = float(values.min()), float(values.max())
        if vmax == vmin:
            return 0.5 * (background_value(volume) + vmin)
        integer = volume.dtype.kind in "iu"
        if is_signed(volume):
            # Otsu's split of the magnitudes: the positive surface of the strong values (the
            # split of the signed values would fall near 0, between the two signs).
            magnitudes = np.abs(values)
            if magnitudes.max() > magnitudes.min():
                return min(otsu_threshold(magnitudes, integer=integer), float(hi))
        # Within the volume's range: the samples' own bounds for a plain volume, but a preview
        # of a multiresolution volume (coarse spline coefficients can overshoot the data)
        # carries the whole volume's range, against which isovalues are checked.
        return min(max(otsu_threshold(values, integer=integer), float(lo)), float(hi))

    return _cached(volume, "iso", compute)


def _projected(volume: Volume, kind: str) -> np.ndarray:
    """The pixels of the volume's maximum (``kind="mip"``) or minimum projections along its
    three axes whose ray meets something besides the background (float64, 1D)."""
    data = _sample(volume)
    background = background_value(volume)
    reduce = np.fmax.reduce if kind == "mip" else np.fmin.reduce  # NaN voxels are ignored
    pixels = np.concatenate([reduce(data, axis=a).ravel() for a in range(3)])
    pixels = pixels[np.isfinite(pixels)]
    return pixels[pixels != background]


def auto_window(volume: Any, mode: str = "mip") -> tuple[float, float]:
    """The MIP / minIP value window shown when none is given: ``(lo, hi)``, ``lo < hi``.

    ``volume.metadata["default_window_<mode>"]``, else ``["default_window"]``, when present;
    else percentiles of the volume's axis-aligned projections (:data:`WINDOW_PERCENTILES`;
    symmetric about 0 for signed data: see the module's description), or the data range
    (widened by one when the volume is constant) when those coincide.

    Parameters
    ----------
    volume : Volume
    mode : {"mip", "minip"}
        The projection the window is for.
    """
    if mode not in ("mip", "minip"):
        raise ParameterError(f"mode must be 'mip' or 'minip', got {mode!r}")
    meta = volume.metadata
    stored = meta.get(f"default_window_{mode}")
    stored = meta.get("default_window") if stored is None else stored
    if stored is not None:
        lo, hi = (float(v) for v in stored)
        return lo, hi

    def compute() -> tuple[float, float]:
        lo_data, hi_data = (float(v) for v in volume.value_range)
        if is_signed(volume):
            pixels = np.concatenate([_projected(volume, "mip"), _projected(volume, "minip")])
            m = float(np.percentile(np.abs(pixels), WINDOW_PERCENTILES[1])) if pixels.size else 0
            m = m if m > 0 else max(-lo_data, hi_data)
            return -m, m
        pixels = _projected(volume, mode)
        q = WINDOW_PERCENTILES if mode == "mip" else (100 - WINDOW_PERCENTILES[1],
                                                      100 - WINDOW_PERCENTILES[0])
        span = hi_data - lo_data
        if pixels.size:
            lo, hi = (float(v) for v in np.percentile(pixels, q))
            if hi - lo > 1e-3 * span:
                return lo, hi
            # A projection that is (nearly) one value: from the background to it.
            background = background_value(volume)
            lo, hi = (background, hi) if mode == "mip" else (lo, background)
            if hi > lo:
                return lo, hi
        return (lo_data, hi_data if hi_data > lo_data else lo_data + 1.0)

    return _cached(volume, f"window-{mode}", compute)


def auto_transfer_function(volume: Volume) -> TransferFunction:
    """The DVR transfer function used when none is given.

    Opacity ramps linearly from 0 at :func:`auto_iso` to :data:`DVR_MAX_OPACITY` at the 99.5th
    percentile of the non-background values (and stays there above it); the ``viridis``
    colormap spans the ramp. ``volume.metadata["default_tf"]`` (a
    :meth:`TransferFunction.to_dict`) replaces it when present.
    """
    if volume.metadata.get("default_tf") is not None:
        return TransferFunction.from_dict(volume.metadata["default_tf"])

    def compute() -> TransferFunction:
        start = auto_iso(volume)
        values = sample_values(volume)
        values = values[values > start]
        end = float(np.percentile(values, DVR_TOP_PERCENTILE)) if values.size else start
        if not end > start:
            # Nothing (or one value) above the isovalue: ramp over the rest of the data range.
            end = max(volume.value_range[1], start + 1.0)
            end = end if end > start else start + 1.0
        return TransferFunction([(start, 0.0), (end, DVR_MAX_OPACITY)], domain=(start, end),
                                colormap="viridis")

    return _cached(volume, "tf", compute)


def content_box(volume: Volume, iso: Any = None, tf: TransferFunction | None = None,
                inside: str | None = None,
                max_voxels: int = SAMPLE_VOXELS) -> tuple[np.ndarray, np.ndarray]:
    """World-space box ``(lo, hi)`` around what an isovalue or a transfer function shows.

    Give it to :meth:`splinecast.Camera.orbit` as ``fit=`` to frame the object rather than the
    whole grid (as VTK's ``ResetCamera(bounds)`` frames the visible actors).

    Parameters
    ----------
    volume : Volume
        The data.
    iso : float or list of float, optional
        Isovalue(s); the box holds every voxel on the object's side of the (lowest, for
        ``inside="high"``) isovalue, grown by one voxel since the surface passes between voxels.
        Default: :func:`auto_iso`.
    tf : TransferFunction, optional
        Instead of ``iso``: the box holds every voxel the transfer function gives a non-zero
        opacity, grown by one voxel (the reconstruction blends it with its neighbours).
    inside : {"high", "low"}, optional
        Which side of the isovalue is the object; default :func:`auto_inside`.
    max_voxels : int
        Volumes with more voxels are examined at an even stride; the box then grows by the stride
        so that voxels between the samples stay inside it.

    Returns
    -------
    lo, hi : ndarray, shape (3,)
        World corners, clipped to the volume's bounds; the volume's bounds when nothing would be
        visible.
    """
    if inside is None and tf is None:
        inside = auto_inside(volume, iso)
    inside = inside or volume.metadata.get("inside", "high")
    if inside not in ("high", "low"):
        raise ParameterError(f"inside must be 'high' or 'low', got {inside!r}")
    stride = _stride(volume.shape, max_voxels)
    data = volume.data[::stride, ::stride, ::stride]
    if tf is not None:
        if not isinstance(tf, TransferFunction):
            raise ParameterError(f"tf must be a TransferFunction, got {type(tf).__name__}")
        mask = np.zeros(data.shape, dtype=bool)
        for a, b in tf.visible_ranges():
            mask |= (data >= a) & (data <= b)
    else:
        isos = auto_iso(volume) if iso is None else iso
        isos = np.atleast_1d(np.asarray(isos, dtype=np.float64))
        if isos.size == 0 or not np.all(np.isfinite(isos)):
            raise ParameterError(f"iso must be finite numbers, got {iso!r}")
        mask = data >= isos.min() if inside == "high" else data <= isos.max()
    lo_world, hi_world = volume.bounds
    hits = [np.flatnonzero(mask.any(axis=other)) for other in ((1, 2), (0, 2), (0, 1))]
    if any(h.size == 0 for h in hits):
        return lo_world, hi_world
    grow = stride  # one voxel of the full grid beyond each sample (the stride covers it)
    first = np.array([h[0] * stride - grow for h in hits], dtype=np.float64)
    last = np.array([h[-1] * stride + grow for h in hits], dtype=np.float64)
    first = np.maximum(first, 0.0)
    last = np.minimum(last, np.asarray(volume.shape, dtype=np.float64) - 1.0)
    return volume.index_to_world(first), volume.index_to_world(last)
