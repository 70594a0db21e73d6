"""Byte sizes as people write them: ``"2GiB"``, ``"512MiB"``, ``"1.5GB"``, ``1073741824``."""

from __future__ import annotations

import re
from typing import Any

from ..errors import ParameterError

__all__ = ["parse_bytes", "format_bytes"]

# Binary prefixes (KiB, MiB, ...) are powers of 1024; SI ones (kB, MB, ...) and bare letters powers
# of 1000, as in dask.utils.parse_bytes, so "2GB" means the same here as in a dask config.
_UNITS = {
    "": 1, "b": 1,
    "k": 10**3, "kb": 10**3, "m": 10**6, "mb": 10**6, "g": 10**9, "gb": 10**9,
    "t": 10**12, "tb": 10**12,
    "kib": 2**10, "mib": 2**20, "gib": 2**30, "tib": 2**40,
}
_PATTERN = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:e[+-]?[0-9]+)?)\s*([a-z]*)\s*$")


def parse_bytes(value: Any, name: str = "budget") -> int:
    """A positive byte count from an int or a string such as ``"2GiB"``.

    Raises
    ------
    ParameterError
        Naming ``name`` when the value is not a positive size.

    Examples
    --------
    >>> parse_bytes("2GiB"), parse_bytes("1.5 MB"), parse_bytes(4096)
    (2147483648, 1500000, 4096)
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        number, unit = float(value), 1
    else:
        match = _PATTERN.match(str(value).lower())
        if match is None or match.group(2) not in _UNITS:
            raise ParameterError(
                f"{name} must be a size such as 2GiB, 512MiB or 1.5GB, got {value!r}"
            )
        number, unit = float(match.group(1)), _UNITS[match.group(2)]
    size = int(number * unit)
    if size <= 0:
        raise ParameterError(f"{name} must be positive, got {value!r}")
    return size


def format_bytes(size: float) -> str:
    """``1536 * 2**20`` -> ``"1.5 GiB"`` (binary prefixes, 3 significant digits)."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if abs(size) >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{int(size)} B"
