"""Stopping a read that is under way because its result is no longer wanted.

A brick loader reads batches of bricks, over a network several at once, each read many
requests in flight. When the camera moves and the new view needs none of a read's bricks,
waiting for them to arrive holds the connections (and the loader's place) that the new view's
bricks need. Each read runs inside :func:`cancellable` with its :class:`CancelToken` (the token
is the calling thread's: every loader thread has its own); the rendering thread calls
:meth:`CancelToken.cancel`, and every request the read has in flight is cancelled on its event
loop (the connection is closed, so the server stops sending), after which the read raises
:class:`ReadCancelled` in the loader's thread.

:class:`ReadCancelled` derives from :class:`BaseException`, as :class:`asyncio.CancelledError`
does: the readers turn every :class:`Exception` into a one-line :class:`~splinecast.ReadError`
naming the data, and a cancelled read is not a failure of the data.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

__all__ = ["CancelToken", "ReadCancelled", "cancellable", "current"]


class ReadCancelled(BaseException):  # noqa: N818  (named as asyncio.CancelledError is)
    """A read was stopped by :meth:`CancelToken.cancel`: nothing is wrong with the data."""


class CancelToken:
    """A flag a reading thread's requests watch; :meth:`cancel` stops them from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._cancelled = False
        self._hooks: dict[int, Callable[[], None]] = {}
        self._next = 0

    @property
    def cancelled(self) -> bool:
        return self._cancelled

    def cancel(self) -> None:
        """Stop the read: every hook registered now or later is called (once)."""
        with self._lock:
            if self._cancelled:
                return
            self._cancelled = True
            hooks = list(self._hooks.values())
        for hook in hooks:
            hook()

    def check(self) -> None:
        """Raise :class:`ReadCancelled` if the read was cancelled."""
        if self._cancelled:
            raise ReadCancelled()

    @contextmanager
    def hook(self, stop: Callable[[], None]) -> Iterator[None]:
        """Call ``stop`` (from the cancelling thread) if the token is cancelled while inside;
        at once if it already is. ``stop`` must not block: it schedules the cancellation (for
        example with ``loop.call_soon_threadsafe``)."""
        with self._lock:
            ident = self._next
            self._next += 1
            self._hooks[ident] = stop
            now = self._cancelled
        if now:
            stop()
        try:
            yield
        finally:
            with self._lock:
                self._hooks.pop(ident, None)


_local = threading.local()


def current() -> CancelToken | None:
    """The token of the read the calling thread is doing (None: not cancellable)."""
    return getattr(_local, "token", None)


@contextmanager
def cancellable(token: CancelToken) -> Iterator[CancelToken]:
    """Run the calling thread's reads under ``token`` (nested scopes: the innermost)."""
    before = current()
    _local.token = token
    try:
        yield token
    finally:
        _local.token = before
