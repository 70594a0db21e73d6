"""Raw voxels described by a JSON sidecar: ``foo.raw`` + ``foo.json`` (or ``foo.raw.json``).

The sidecar is the simplest way to hand splinecast a block of voxels from any program::

    {"shape": [256, 256, 128], "dtype": "uint16",
     "spacing": [0.5, 0.5, 1.0], "origin": [0, 0, 0],
     "byte_order": "little", "order": "F", "header_bytes": 0}

``shape`` and ``dtype`` (a numpy name) are required. ``order`` is ``"F"`` (x varies fastest, the
default, as in MetaImage and NRRD) or ``"C"`` (z fastest). ``header_bytes`` bytes are skipped at
the start of the data file (``-1``: the voxels are the last bytes of the file). An optional
``data_file`` names the data file relative to the sidecar (in its folder or below, unless external
files are allowed); otherwise it is the sidecar's name without ``.json`` (``foo.raw.json``) or
with ``.raw`` instead (``foo.json``). The sidecar itself is read with the bounds of
:func:`splinecast.errors.limits.load_json`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .._atomic import atomic_outputs
from ..errors import ParameterError, ReadError, limits
from ..volume import Volume
from ._common import check_dtype, finish_volume
from .rawfile import map_raw, write_raw

__all__ = ["find_sidecar", "read_sidecar", "write_sidecar"]


def find_sidecar(data_path: Path) -> Path | None:
    """The JSON sidecar of a data file, if any (``foo.raw.json`` wins over ``foo.json``)."""
    candidates = (data_path.with_name(data_path.name + ".json"), data_path.with_suffix(".json"))
    for candidate in candidates:
        if candidate != data_path and candidate.is_file():
            return candidate
    return None


def _data_file_of(sidecar: Path, fields: dict[str, Any], allow_external: bool | None) -> Path:
    if "data_file" in fields:
        return limits.check_data_file(
            sidecar, fields["data_file"], "'data_file'", allow_external=allow_external
        )
    stem = sidecar.name[: -len(".json")]
    return sidecar.parent / (stem if Path(stem).suffix else stem + ".raw")


def read_sidecar(path: Path, *, allow_external: bool | None = None) -> Volume:
    """Read raw voxels described by a JSON sidecar; ``path`` is either the data or the sidecar.

    The voxels are memory-mapped (copied only when big-endian).
    """
    if path.suffix.lower() == ".json":
        sidecar = path
        data_path = None
    else:
        found = find_sidecar(path)
        if found is None:
            raise ReadError(f"{path}: no JSON sidecar ({path.name}.json or {path.stem}.json) found")
        sidecar, data_path = found, path
    fields = limits.load_json(sidecar, str(sidecar))
    if not isinstance(fields, dict):
        raise ReadError(f"{sidecar}: the sidecar must be a JSON object")
    if data_path is None:
        data_path = _data_file_of(sidecar, fields, allow_external)

    for key in ("shape", "dtype"):
        if key not in fields:
            raise ReadError(f"{sidecar}: required key '{key}' is missing")
    shape = fields["shape"]
    if not isinstance(shape, list) or not all(isinstance(n, int) for n in shape):
        raise ReadError(f"{sidecar}: 'shape' must be three positive integers [nx, ny, nz]")
    shape = limits.check_shape(shape, f"{sidecar}: 'shape'", error=ReadError)
    if not isinstance(fields["dtype"], str):
        raise ReadError(f"{sidecar}: 'dtype' must be a numpy type name such as \"uint16\"")
    dtype = check_dtype(fields["dtype"], f"{sidecar}: 'dtype'")
    byte_order = fields.get("byte_order", "little")
    if byte_order not in ("little", "big"):
        raise ReadError(f"{sidecar}: 'byte_order' must be 'little' or 'big', "
                        f"got {limits.shorten(byte_order)}")
    dtype = dtype.newbyteorder("<" if byte_order == "little" else ">")
    order = fields.get("order", "F")
    if order not in ("F", "C"):
        raise ReadError(f"{sidecar}: 'order' must be 'F' (x fastest) or 'C', "
                        f"got {limits.shorten(order)}")
    offset = limits.check_count(fields.get("header_bytes", 0), f"{sidecar}: 'header_bytes'",
                                lo=-1, error=ReadError)
    spacing = _triple(fields, "spacing", 1.0, sidecar)
    origin = _triple(fields, "origin", 0.0, sidecar)

    data = map_raw(data_path, shape, dtype, offset=offset, order=order, header=sidecar.name)
    return finish_volume(
        data, spacing, origin, path,
        metadata={"format": "raw+json", "data_file": str(data_path), "sidecar": str(sidecar)},
    )


def _triple(fields: dict[str, Any], key: str, default: float, sidecar: Path) -> list[float]:
    value = fields.get(key, default)
    if isinstance(value, int | float) and not isinstance(value, bool):
        try:
            return [float(value)] * 3
        except OverflowError:  # an integer beyond float range
            pass
    if isinstance(value, list) and len(value) == 3:
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
            try:
                return [float(v) for v in value]
            except OverflowError:  # an integer beyond float range
                pass
    raise ReadError(
        f"{sidecar}: '{key}' must be a number or a list of 3 numbers, got {limits.shorten(value)}"
    )


def write_sidecar(volume: Volume, path: Path) -> None:
    """Write ``foo.raw`` (little-endian, x fastest) and its sidecar ``foo.json``."""
    dtype = volume.data.dtype.newbyteorder("=")
    if dtype.kind not in "uif":
        raise ParameterError(f"{path}: raw files cannot hold {volume.data.dtype} voxels")
    sidecar = path.with_suffix(".json")
    fields = {
        "shape": list(volume.shape),
        "dtype": dtype.name,
        "spacing": list(volume.spacing),
        "origin": list(volume.origin),
        "byte_order": "little",
        "order": "F",
        "header_bytes": 0,
    }
    with atomic_outputs(path, sidecar) as (raw_temp, json_temp):
        with open(raw_temp, "wb") as fh:
            write_raw(fh, volume.data)
        with open(json_temp, "w", encoding="utf-8") as fh:
            json.dump(fields, fh, indent=2)
            fh.write("\n")
