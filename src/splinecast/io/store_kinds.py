"""Openers of splinecast Zarr stores that are not images, by the ``kind`` their root attribute
``"splinecast"`` names (a spline-wavelet pyramid: ``"wavelet"``).

The layers above :mod:`splinecast.io` register them (``splinecast/__init__.py``), so that
:func:`splinecast.read` opens such a store without this package importing them. Kept apart from
:mod:`.omezarr` so that registering costs nothing at ``import splinecast``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["register_store_kind", "store_opener"]

_STORE_KINDS: dict[str, Callable[..., Any]] = {}


def register_store_kind(kind: str, opener: Callable[..., Any]) -> None:
    """Make :func:`splinecast.io.omezarr.open_zarr` return ``opener(path, root_group,
    attributes)`` for a store whose ``"splinecast"`` root attribute says ``kind``."""
    _STORE_KINDS[kind] = opener


def store_opener(kind: str) -> Callable[..., Any] | None:
    """The opener registered for ``kind``, or ``None``."""
    return _STORE_KINDS.get(kind)
