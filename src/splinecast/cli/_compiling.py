"""Telling the user, on stderr, that a wait is a one-time kernel compile, and only then.

The first render of a model, a mode and a voxel type compiles its kernels (tens of seconds on a
laptop); every later run loads them from the on-disk cache in a fraction of a second. A command
that compiles says so when the compile begins, with what it is for and roughly how long it
takes, keeps a line of elapsed time going while it lasts longer than two seconds, and says how
long it took. A run that compiles nothing prints none of this.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any, TextIO

from .._jit import reporting_compiles
from ..models import MODELS

__all__ = ["CompileNotice", "typical_compile_s"]

#: Seconds without news after which the elapsed time is shown.
QUIET_S = 2.0


def typical_compile_s(model: str) -> int:
    """A typical compile time of a model's first render, in seconds (order of magnitude).

    Each model states its own (``typical_compile_s``, measured from an empty cache on a 2-core
    machine by ``benchmarks/bench_cold_start.py``); a further mode of the same model takes about
    half. Only the order of magnitude is promised to the user."""
    cls = MODELS.get(model)
    return cls.typical_compile_s if cls is not None else 60


class CompileNotice:
    """A context in which compiles are announced on ``stream``.

    Parameters
    ----------
    what : str
        What the kernels are for, as the user named it ("s31 / dvr, uint8 data").
    model : str
        The model, for the estimate of the time.
    enabled : bool
        False prints nothing (``--quiet``).
    stream : file, optional
        Where to write; stderr by default.
    """

    def __init__(self, what: str, model: str, enabled: bool = True,
                 stream: TextIO | None = None) -> None:
        self.what, self.model, self.enabled = what, model, enabled
        self.stream = stream or sys.stderr
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.compiled_s = 0.0  # total time spent compiling
        self._first: float | None = None
        self._active = False
        self._stop = threading.Event()
        self._lock = threading.Lock()  # the ticker and the compiling thread both write
        self._drawn = False  # an elapsed-time line is on screen, not ended (terminal)
        self._ticker: threading.Thread | None = None
        self._context: Any = None

    def __enter__(self) -> CompileNotice:
        self._context = reporting_compiles(self._started, self._ended)
        self._context.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._context.__exit__(*exc)
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        if self._first is not None and self.enabled:
            self._write(f"compiled in {time.perf_counter() - self._first:.0f} s "
                        "(cached: the next run starts at once)", end=True)

    # ------------------------------------------------------------------ compile events
    def _started(self, name: str) -> None:
        self._active = True
        if self._first is not None:
            return
        self._first = time.perf_counter()
        if not self.enabled:
            return
        self._write(f"compiling kernels for {self.what} (first use; about "
                    f"{typical_compile_s(self.model)} s on 2 cores, once)", end=True)
        self._ticker = threading.Thread(target=self._tick, name="compile-notice", daemon=True)
        self._ticker.start()

    def _ended(self, name: str, seconds: float) -> None:
        self._active = False
        self.compiled_s += seconds
        with self._lock:
            if self._drawn:  # leave the line clean for whatever the command prints next
                self.stream.write("\r\033[K")
                self.stream.flush()
                self._drawn = False

    # ------------------------------------------------------------------------ output
    def _tick(self) -> None:
        """Elapsed time while compiling: redrawn in place on a terminal, a line every ten
        seconds elsewhere."""
        interval = 0.5 if self._tty else 10.0
        while not self._stop.wait(interval):
            elapsed = time.perf_counter() - (self._first or 0.0)
            if elapsed >= QUIET_S and self._active and not self._stop.is_set():
                self._write(f"  compiling... {elapsed:.0f} s", end=not self._tty)

    def _write(self, line: str, end: bool) -> None:
        with self._lock:
            prefix = "\r\033[K" if self._tty else ""
            self.stream.write(prefix + line + ("\n" if end else ""))
            self.stream.flush()
            self._drawn = self._tty and not end
