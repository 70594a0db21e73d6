"""The bytes of array memory an object graph keeps alive, found by walking its references.

A budget test must not trust the counters of the code it checks: :func:`held_bytes` walks the
references from given roots (containers, and the attributes of splinecast's own objects), collects
every numpy array reached and charges each the buffer that owns its memory (a view keeps its whole
base alive, so a view of a large read block costs the block). Buffers are counted once.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from typing import Any

import numpy as np

__all__ = ["held_bytes", "held_buffers"]

_CONTAINERS = (list, tuple, set, frozenset, deque)


def _owner(array: np.ndarray) -> tuple[int, int]:
    """``(id, bytes)`` of the buffer that owns ``array``'s memory."""
    base: Any = array
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    if isinstance(base, np.ndarray):
        return id(base), int(base.nbytes)
    try:
        return id(base), int(memoryview(base).nbytes)
    except TypeError:  # an exporter without the buffer protocol: the array's own bytes
        return id(array), int(array.nbytes)


def held_buffers(*roots: Any, skip: tuple = ()) -> dict[int, int]:
    """The owning buffers (``id -> bytes``) of every array reachable from ``roots``.

    Walks lists, tuples, sets, dicts (keys and values) and the instance attributes (``__dict__``
    and ``__slots__``) of objects whose class is defined in splinecast; stops at the objects in
    ``skip`` (compared by identity), at modules, classes and functions.
    """
    skipped = {id(obj) for obj in skip}
    seen: set[int] = set()
    buffers: dict[int, int] = {}
    stack = list(roots)
    while stack:
        obj = stack.pop()
        if id(obj) in seen or id(obj) in skipped or obj is None:
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            key, size = _owner(obj)
            buffers[key] = size
        elif isinstance(obj, dict | OrderedDict):
            stack.extend(obj.keys())
            stack.extend(obj.values())
        elif isinstance(obj, _CONTAINERS):
            stack.extend(obj)
        elif type(obj).__module__.startswith("splinecast"):
            stack.extend(vars(obj).values() if hasattr(obj, "__dict__") else ())
            for name in getattr(type(obj), "__slots__", ()):
                stack.append(getattr(obj, name, None))
    return buffers


def held_bytes(*roots: Any, skip: tuple = ()) -> int:
    """Total bytes of :func:`held_buffers`."""
    return sum(held_buffers(*roots, skip=skip).values())
