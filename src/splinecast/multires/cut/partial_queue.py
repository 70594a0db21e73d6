"""A priority queue that sorts only what a frame can use (Carmona & Froehlich 2011, section 3.5).

Split-and-collapse performs at most O(M) operations per frame on queues of N nodes, so sorting
all N after every priority change (O(N log N)) would dominate. The paper keeps each queue as two
parts: **A**, at most M nodes in sorted order (the head end), and **B**, the unsorted rest, with
every key in A ranking before every key in B. A re-prioritisation is one partial sort (O(N + M log
M): a selection of the M best, then sorting those); inserting goes into A when the key ranks
before A's last entry (which then moves to B if A is full) and into B otherwise; removing is a
binary search in A or O(1) in B; only when A runs empty is B partially sorted again.

A is a Python list kept sorted with :mod:`bisect` (O(log M) comparisons plus a memmove of at most
M pointers, negligible for M in the hundreds). B is three numpy arrays (node, primary key,
secondary key) with a node-to-slot index, so a re-prioritisation never builds N Python objects:
removal swaps the last slot into the hole.

Keys are ``(primary, secondary)`` pairs of a float and an int, smallest first.
"""

from __future__ import annotations

import bisect

import numpy as np

__all__ = ["PartialQueue"]

Key = tuple[float, int]

_IN_A = -2
_ABSENT = -1


class PartialQueue:
    """Nodes ``0..size-1`` ordered by ``(primary, secondary)`` keys, smallest first; only the
    ``capacity`` smallest kept sorted.

    Parameters
    ----------
    capacity : int
        Size of the sorted part A (the paper's M).
    size : int
        Node ids are below this (the tree's K).
    """

    def __init__(self, capacity: int, size: int):
        self.capacity = max(1, int(capacity))
        self._a: list[tuple[Key, int]] = []
        self._a_key: dict[int, Key] = {}
        self._slot = np.full(int(size), _ABSENT, np.int64)   # B slot, _IN_A or _ABSENT
        self._b_node = np.zeros(64, np.int64)
        self._b_primary = np.zeros(64)
        self._b_secondary = np.zeros(64, np.int64)
        self._nb = 0
        self.partial_sorts = 0

    def __len__(self) -> int:
        return len(self._a) + self._nb

    def __contains__(self, node: int) -> bool:
        return self._slot[node] != _ABSENT

    def nodes(self) -> np.ndarray:
        """Every node in the queue (A first, then B; no particular order within B)."""
        a = np.fromiter(self._a_key, np.int64, len(self._a_key))
        return np.concatenate([a, self._b_node[:self._nb]])

    def key(self, node: int) -> Key:
        """The key a node was inserted with."""
        slot = int(self._slot[node])
        if slot == _IN_A:
            return self._a_key[node]
        return (float(self._b_primary[slot]), int(self._b_secondary[slot]))

    # ------------------------------------------------------------------------- partial sort
    def rebuild(self, nodes: np.ndarray, primary: np.ndarray, secondary: np.ndarray) -> None:
        """Replace the content; sort only the ``capacity`` smallest keys (O(n + M log M))."""
        nodes = np.asarray(nodes, np.int64)
        primary = np.asarray(primary, np.float64)
        secondary = np.asarray(secondary, np.int64)
        n = nodes.shape[0]
        self.partial_sorts += 1
        for node in self._a_key:
            self._slot[node] = _ABSENT
        self._slot[self._b_node[:self._nb]] = _ABSENT
        if n > self.capacity:
            # Everything strictly below the capacity-th primary key is in A; the ties at that key
            # compete on the secondary key.
            kth = np.partition(primary, self.capacity - 1)[self.capacity - 1]
            head = np.flatnonzero(primary <= kth)
        else:
            head = np.arange(n)
        order = head[np.lexsort((secondary[head], primary[head]))]
        a_idx = order[:self.capacity]
        self._a = list(zip(zip(primary[a_idx].tolist(), secondary[a_idx].tolist(), strict=True),
                           nodes[a_idx].tolist(), strict=True))
        self._a_key = {b: k for k, b in self._a}
        self._slot[nodes[a_idx]] = _IN_A
        rest = np.ones(n, bool)
        rest[a_idx] = False
        self._set_b(nodes[rest], primary[rest], secondary[rest])

    def _set_b(self, nodes: np.ndarray, primary: np.ndarray, secondary: np.ndarray) -> None:
        nb = nodes.shape[0]
        cap = max(64, 2 * nb)
        self._b_node = np.zeros(cap, np.int64)
        self._b_primary = np.zeros(cap)
        self._b_secondary = np.zeros(cap, np.int64)
        self._b_node[:nb] = nodes
        self._b_primary[:nb] = primary
        self._b_secondary[:nb] = secondary
        self._slot[nodes] = np.arange(nb)
        self._nb = nb

    def _refill(self) -> None:
        """A ran empty: partially sort B into a new A."""
        if self._nb:
            nb = self._nb
            self.rebuild(self._b_node[:nb].copy(), self._b_primary[:nb].copy(),
                         self._b_secondary[:nb].copy())

    def _push_b(self, node: int, key: Key) -> None:
        if self._nb == self._b_node.shape[0]:
            grow = self._b_node.shape[0]
            self._b_node = np.concatenate([self._b_node, np.zeros(grow, np.int64)])
            self._b_primary = np.concatenate([self._b_primary, np.zeros(grow)])
            self._b_secondary = np.concatenate([self._b_secondary, np.zeros(grow, np.int64)])
        slot = self._nb
        self._b_node[slot] = node
        self._b_primary[slot] = key[0]
        self._b_secondary[slot] = key[1]
        self._slot[node] = slot
        self._nb += 1

    def _remove_b(self, node: int) -> None:
        slot = int(self._slot[node])
        last = self._nb - 1
        if slot != last:  # the last slot fills the hole
            moved = int(self._b_node[last])
            self._b_node[slot] = moved
            self._b_primary[slot] = self._b_primary[last]
            self._b_secondary[slot] = self._b_secondary[last]
            self._slot[moved] = slot
        self._slot[node] = _ABSENT
        self._nb = last

    # --------------------------------------------------------------------------- operations
    def push(self, node: int, key: Key) -> None:
        """Insert ``node`` (not already present) with ``key``."""
        if not self._a and self._nb:
            self._refill()
        if (not self._nb and len(self._a) < self.capacity) or (self._a and key < self._a[-1][0]):
            bisect.insort(self._a, (key, node))
            self._a_key[node] = key
            self._slot[node] = _IN_A
            if len(self._a) > self.capacity:
                last_key, last = self._a.pop()
                del self._a_key[last]
                self._push_b(last, last_key)
        else:
            self._push_b(node, key)

    def remove(self, node: int) -> None:
        """Remove ``node`` (which must be present)."""
        if self._slot[node] != _IN_A:
            self._remove_b(node)
            return
        key = self._a_key.pop(node)
        i = bisect.bisect_left(self._a, (key, node))
        del self._a[i]
        self._slot[node] = _ABSENT

    def discard(self, node: int) -> None:
        """Remove ``node`` if present."""
        if self._slot[node] != _ABSENT:
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
