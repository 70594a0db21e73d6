"""Render the same bricks twice: a multiresolution scene's stream frame recorded and replayed.

The loader thread keeps reading and evicting between two renders of a scene, so two renders of
one view may draw different pieces. Tests that compare two ways of drawing (one launch against
one call per piece, seam shells against whole copies) record the stream's frame of the first
render and hand the very same bricks to the second.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any


class Replay:
    """Records every stream frame of ``scene``; :meth:`hold` makes later renders draw the last."""

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self.real = scene._frame
        self.frames: list[Any] = []

    def _record(self, *args: Any, **kwargs: Any) -> Any:
        self.frames.append(self.real(*args, **kwargs))
        return self.frames[-1]

    def hold(self) -> None:
        drawn = self.frames[-1]
        self.scene._frame = lambda *args, **kwargs: drawn


@contextlib.contextmanager
def replay(scene: Any) -> Iterator[Replay]:
    """Within the block, the scene's stream frames are recorded (see :class:`Replay`)."""
    recorder = Replay(scene)
    scene._frame = recorder._record
    try:
        yield recorder
    finally:
        scene._frame = recorder.real
