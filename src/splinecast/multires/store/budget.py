"""Byte sizes as people write them: ``"2GiB"``, ``"512MiB"``, ``"1.5GB"``, ``1073741824``."""

from __future__ import annotations

from typing import Any

from ...errors import limits

__all__ = ["parse_bytes", "format_bytes"]


def parse_bytes(value: Any, name: str = "budget") -> int:
    """A positive byte count from an int or a string such as ``"2GiB"``
    (:func:`splinecast.errors.limits.parse_bytes`, the one parser of sizes).

    Raises
    ------
    ParameterError
        Naming ``name`` when the value is not a positive size.

    Examples
    --------
    >>> parse_bytes("2GiB"), parse_bytes("1.5 MB"), parse_bytes(4096)
    (2147483648, 1500000, 4096)
    """
    return limits.parse_bytes(value, name)


def format_bytes(size: float) -> str:
    """``1536 * 2**20`` -> ``"1.5 GiB"`` (binary prefixes, 3 significant digits)."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if abs(size) >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{int(size)} B"
