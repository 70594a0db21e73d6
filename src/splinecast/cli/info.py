"""``splinecast info FILE``: shape, dtype, spacing, origin, value range and percentiles, the number
of time points and channels; the levels of a multiscale (Zarr) volume."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

import splinecast as sc

from ._common import add_input_options, add_selection_options, read_options

__all__ = ["add_parser", "run"]

_PERCENTILES = (0.5, 1, 5, 25, 50, 75, 95, 99, 99.5)
_EXACT_STATS_LIMIT = 64_000_000  # voxels; above this, percentiles come from a strided subsample


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    info = sub.add_parser("info", help="describe a volume file: shape, dtype, spacing, values")
    info.add_argument("file", help="volume file, DICOM folder, Zarr folder or demo:NAME?size=N")
    info.add_argument("--array", help="data array of a VTK file holding several")
    add_selection_options(info)
    add_input_options(info)


def run(args: argparse.Namespace) -> int:
    """Print the description of ``args.file``."""
    vol = sc.read(args.file, array=args.array, **read_options(args))
    if not isinstance(vol, sc.Volume):
        if isinstance(vol, sc.WaveletVolume):
            return _wavelet(vol)
        return _multiscale(vol)
    data = vol.data
    sample = data
    note = ""
    if data.size > _EXACT_STATS_LIMIT:
        stride = int(np.ceil((data.size / _EXACT_STATS_LIMIT) ** (1 / 3)))
        sample = data[::stride, ::stride, ::stride]
        note = f" (percentiles from every {stride}th voxel per axis)"
    lo, hi = vol.value_range
    finite = sample[np.isfinite(sample)] if sample.dtype.kind == "f" else sample.reshape(-1)
    pct = np.percentile(finite, _PERCENTILES)
    print(f"file:      {vol.metadata.get('source', vol.name)}")
    print(f"shape:     {' x '.join(str(n) for n in vol.shape)} (x, y, z)")
    print(f"dtype:     {vol.dtype}")
    print(f"spacing:   {', '.join(f'{s:g}' for s in vol.spacing)}")
    print(f"origin:    {', '.join(f'{s:g}' for s in vol.origin)}")
    print(f"extent:    {', '.join(f'{s:g}' for s in vol.extent)}")
    print(f"range:     {lo:g} .. {hi:g}")
    _series(vol.metadata)
    nan, pos, neg = vol.nonfinite_counts()
    print(f"NaN:       {nan}")
    if pos or neg:
        print(f"infinite:  {pos} +inf, {neg} -inf")
    print("percentiles" + note + ":")
    for p, v in zip(_PERCENTILES, pct, strict=True):
        print(f"  {p:>5g}%  {v:g}")
    if "default_iso" in vol.metadata:
        print(f"default iso: {vol.metadata['default_iso']:g}")
    return 0


def _series(metadata: dict[str, Any]) -> None:
    """The time points and channels the file holds, and the ones described (the values above
    are those of one time point and channel)."""
    for what, count, index in (("timepoints", "timepoints", "timepoint"),
                               ("channels", "channels", "channel")):
        n = int(metadata.get(count, 1))
        several = "; render several with --channel 0,2 or all" if index == "channel" else ""
        shown = (f" (this is {metadata.get(index, 0)}; choose with --{index} N{several})"
                 if n > 1 else "")
        print(f"{what + ':':<12}{n}{shown}")
    _omero(metadata.get("omero"))


def _omero(channels: Any) -> None:
    """Each channel's display settings from OME-Zarr ``omero`` metadata (label, colour,
    window, active): what a multichannel render uses by default."""
    if not channels:
        return
    for index, entry in enumerate(channels):
        colour = ("#" + "".join(f"{round(255 * c):02x}" for c in entry["color"])
                  if entry.get("color") else "no colour")
        window = (f", window {entry['window'][0]:g}..{entry['window'][1]:g}"
                  if entry.get("window") else "")
        active = "" if entry.get("active", True) else " (inactive)"
        label = entry.get("label") or f"channel {index}"
        print(f"  channel {index}: {label!r} {colour}{window}{active}")


def _multiscale(mv) -> int:
    """Describe a lazy multiscale volume from its metadata and stored tables (no voxel read,
    except the coarsest level when the store has no value range)."""
    from splinecast.multires.store.budget import format_bytes

    lo, hi = mv.value_range
    exact = "" if mv.metadata.get("value_range_exact") else " (estimated from the coarsest level)"
    print(f"file:      {mv.metadata.get('source', mv.name)}")
    print(f"format:    {mv.metadata.get('format')}")
    print(f"shape:     {' x '.join(str(n) for n in mv.shape)} (x, y, z)")
    print(f"dtype:     {mv.dtype}")
    unit = f" {mv.metadata['units']}" if mv.metadata.get("units") else ""
    print(f"spacing:   {', '.join(f'{s:g}' for s in mv.spacing)}{unit}")
    print(f"origin:    {', '.join(f'{s:g}' for s in mv.origin)}")
    print(f"extent:    {', '.join(f'{s:g}' for s in mv.extent)}")
    print(f"range:     {lo:g} .. {hi:g}{exact}")
    _series(mv.metadata)
    image_label = mv.metadata.get("image_label")
    if isinstance(image_label, dict):
        colours = image_label.get("colors")
        told = f", {len(colours)} colours given" if isinstance(colours, list) else ""
        how = mv.metadata.get("downsampling")
        down = f", levels by {how}" if how else ""
        print(f"labels:    an OME-Zarr label image{told}{down}; rendered as labels "
              "(--no-labels for the raw values)")
    if mv.brick:
        print(f"bricks:    {mv.brick}^3 cells, tables: {', '.join(mv.tables()) or 'none'}")
    from splinecast.multires.store.hist_store import histogram_info

    hist = histogram_info(mv)
    if hist is not None:
        raw, source = int(hist.get("nbytes", 0)), int(hist.get("source_nbytes", 0)) or 1
        print(f"histograms: {format_bytes(raw)} ({100 * raw / source:.1f}% of the "
              f"{format_bytes(source)} source; {format_bytes(hist['disk_bytes'])} on disk), "
              f"{hist.get('bins')} bins")
    print(f"levels:    {len(mv.levels)}")
    print(f"  {'level':>5}  {'shape (x, y, z)':<20} {'spacing':<24} {'chunks':<12} size")
    for lv in mv.levels:
        shape = "x".join(str(n) for n in lv.shape)
        spacing = ", ".join(f"{s:g}" for s in lv.spacing)
        chunks = "x".join(str(n) for n in lv.chunks)
        print(f"  {lv.index:>5}  {shape:<20} {spacing:<24} {chunks:<12} {format_bytes(lv.nbytes)}")
    return 0


def _wavelet(wv: Any) -> int:
    """Describe a spline-wavelet store (metadata only)."""
    lay = wv.layout
    lo, hi = wv.value_range
    print(f"format:    {wv.metadata.get('format')}")
    print(f"shape:     {' x '.join(str(n) for n in wv.shape)} (x, y, z)")
    print(f"spacing:   {', '.join(f'{s:g}' for s in wv.spacing)}")
    print(f"origin:    {', '.join(f'{s:g}' for s in wv.origin)}")
    print(f"range:     {lo:g} .. {hi:g}")
    print(f"wavelet:   degree {lay.degree} (model bspline{lay.degree}), {lay.levels} levels, "
          f"chunks of {lay.chunk}^3 nodes ({lay.chunk_total()} in all), {wv.dtype} coefficients")
    return 0
