"""A priority queue that sorts only what a frame can use (reference 002, section 3.5).

Split-and-collapse performs at most O(M) operations per frame on queues of N nodes, so sorting
all N after every priority change (O(N log N)) would dominate. The paper keeps each queue as two
parts: **A**, at most M nodes in sorted order (the head end), and **B**, the unsorted rest, with
every key in A ranking before every key in B. A re-prioritisation is one partial sort (O(N + M log
M): a selection of the M best, then sorting those); inserting goes into A when the key ranks
before A's last entry (which then moves to B if A is full) and into B otherwise; removing is a
binary search in A or O(1) in B; only when A runs empty is B partially sorted again.

A is a Python list kept sorted with :mod:`bisect` (O(log M) comparisons plus a memmove of at most
M pointers, negligible for M in the hundreds); B is a dict.

Keys are ``(primary, secondary)`` pairs of a float and an int, smallest first.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator

import numpy as np

__all__ = ["PartialQueue"]

Key = tuple[float, int]


class PartialQueue:
    """Nodes ordered by ``(primary, secondary)`` keys, smallest first; only ``capacity`` sorted.

    Parameters
    ----------
    capacity : int
        Size of the sorted part A (the paper's M).
    """

    def __init__(self, capacity: int):
        self.capacity = max(1, int(capacity))
        self._a: list[tuple[Key, int]] = []
        self._a_key: dict[int, Key] = {}
        self._b: dict[int, Key] = {}
        self.partial_sorts = 0

    def __len__(self) -> int:
        return len(self._a) + len(self._b)

    def __contains__(self, node: int) -> bool:
        return node in self._a_key or node in self._b

    def __iter__(self) -> Iterator[int]:
        yield from self._a_key
        yield from self._b

    def key(self, node: int) -> Key:
        """The key a node was inserted with."""
        return self._a_key[node] if node in self._a_key else self._b[node]

    # ------------------------------------------------------------------------- partial sort
    def rebuild(self, nodes: np.ndarray, primary: np.ndarray, secondary: np.ndarray) -> None:
        """Replace the content; sort only the ``capacity`` smallest keys (O(n + M log M))."""
        nodes = np.asarray(nodes, np.int64)
        primary = np.asarray(primary, np.float64)
        secondary = np.asarray(secondary, np.int64)
        n = nodes.shape[0]
        self.partial_sorts += 1
        if n > self.capacity:
            # Everything strictly below the capacity-th primary key is in A; the ties at that key
            # compete on the secondary key.
            kth = np.partition(primary, self.capacity - 1)[self.capacity - 1]
            head = np.flatnonzero(primary <= kth)
        else:
            head = np.arange(n)
        order = head[np.lexsort((secondary[head], primary[head]))]
        a_idx = order[:self.capacity]
        in_a = np.zeros(n, bool)
        in_a[a_idx] = True
        self._a = [((p, s), b) for p, s, b in zip(primary[a_idx].tolist(),
                                                  secondary[a_idx].tolist(),
                                                  nodes[a_idx].tolist(), strict=True)]
        self._a_key = {b: k for k, b in self._a}
        rest = ~in_a
        self._b = dict(zip(nodes[rest].tolist(), zip(primary[rest].tolist(),
                                                     secondary[rest].tolist(), strict=True),
                           strict=True))

    def _refill(self) -> None:
        """A ran empty: partially sort B into a new A."""
        if not self._b:
            return
        nodes = np.fromiter(self._b.keys(), np.int64, len(self._b))
        keys = list(self._b.values())
        primary = np.fromiter((k[0] for k in keys), np.float64, len(keys))
        secondary = np.fromiter((k[1] for k in keys), np.int64, len(keys))
        self.rebuild(nodes, primary, secondary)

    # --------------------------------------------------------------------------- operations
    def push(self, node: int, key: Key) -> None:
        """Insert ``node`` (not already present) with ``key``."""
        if not self._a and self._b:
            self._refill()
        if (not self._b and len(self._a) < self.capacity) or (self._a and key < self._a[-1][0]):
            bisect.insort(self._a, (key, node))
            self._a_key[node] = key
            if len(self._a) > self.capacity:
                last_key, last = self._a.pop()
                del self._a_key[last]
                self._b[last] = last_key
        else:
            self._b[node] = key

    def remove(self, node: int) -> None:
        """Remove ``node`` (which must be present)."""
        key = self._a_key.pop(node, None)
        if key is None:
            del self._b[node]
            return
        i = bisect.bisect_left(self._a, (key, node))
        del self._a[i]

    def discard(self, node: int) -> None:
        """Remove ``node`` if present."""
        if node in self:
            self.remove(node)

    def peek(self) -> tuple[Key, int] | None:
        """``(key, node)`` of the smallest key, or None when empty."""
        if not self._a:
            self._refill()
        return self._a[0] if self._a else None

    def pop(self) -> tuple[Key, int] | None:
        """Remove and return the smallest ``(key, node)``."""
        head = self.peek()
        if head is not None:
            self.remove(head[1])
        return head
