"""A progress bar on stderr: redrawn in place on a terminal, a few plain lines otherwise."""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """Count finished items of a known total and show rate and time left.

    On a terminal the bar is redrawn in place (at most ten times a second); in a log file or
    a pipe a line is printed for the first item, then at most every ``interval`` seconds, and
    for the last.

    Parameters
    ----------
    total : int
        Number of items.
    label : str
        What is counted ("frames").
    enabled : bool
        False prints nothing (``--quiet``).
    stream : file, optional
        Where to draw; stderr by default.
    """

    def __init__(self, total: int, label: str, enabled: bool = True,
                 stream: TextIO | None = None, interval: float = 2.0) -> None:
        self.total, self.label, self.enabled = int(total), label, enabled
        self.stream = stream or sys.stderr
        self.interval = interval
        self.done = 0
        self.start = time.perf_counter()
        self._shown = -1.0
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def update(self, count: int = 1) -> None:
        """``count`` more items are finished."""
        self.done += count
        if not self.enabled:
            return
        now = time.perf_counter()
        last = self.done >= self.total
        wait = 0.1 if self._tty else self.interval
        if not last and self._shown >= 0 and now - self._shown < wait:
            return
        self._shown = now
        self.stream.write(("\r" if self._tty else "") + self.line(now - self.start)
                          + ("\n" if last or not self._tty else ""))
        self.stream.flush()

    def line(self, elapsed: float) -> str:
        """``frames [#######.............]  12/120  3.4/s  eta 0:32``."""
        width = 24
        filled = width * self.done // max(self.total, 1)
        rate = self.done / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else 0.0
        eta = f"eta {int(left) // 60}:{int(left) % 60:02d}" if self.done < self.total \
            else f"in {elapsed:.1f} s"
        return (f"{self.label} [{'#' * filled}{'.' * (width - filled)}] "
                f"{self.done}/{self.total}  {rate:.2f}/s  {eta}")
