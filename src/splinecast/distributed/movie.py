"""Movie files written frame by frame, all or nothing: MP4, GIF or a folder of numbered PNGs.

Frames go to a temporary file (or folder) beside the target, named ``.NAME.XXXX.part``, and are
moved onto the target only when the last frame is written; an error or Ctrl-C removes the
temporary, so a movie under the final name is always complete. MP4 is H.264 (``yuv420p``,
playable everywhere) through the ffmpeg binary of the imageio-ffmpeg wheel; GIF and PNG through
Pillow.
"""

from __future__ import annotations

import os
import re
import sys
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_folder, atomic_outputs
from ..errors import ParameterError

__all__ = ["MovieWriter", "movie_kind"]

#: Suffix -> kind of movie file; a folder gets numbered PNG frames.
KINDS = {".mp4": "mp4", ".gif": "gif"}
#: Names of the PNG frames in a folder (the number is zero-padded to at least 4 digits).
FRAME_NAME = "frame_{:0{width}d}.png"
_FRAME_RE = re.compile(r"frame_\d+\.png")


def movie_kind(path: str | os.PathLike) -> str:
    """``"mp4"``, ``"gif"`` or ``"png"`` (a folder: the path ends with a slash, is an existing
    folder, or has no suffix).

    Raises
    ------
    ParameterError
        For any other suffix.
    """
    text = os.fspath(path)
    p = Path(text)
    if text.endswith(("/", os.sep)) or p.is_dir() or not p.suffix:
        return "png"
    kind = KINDS.get(p.suffix.lower())
    if kind is None:
        raise ParameterError(f"{text}: a movie must be .mp4, .gif or a folder/ of PNG frames")
    return kind


class MovieWriter:
    """Write same-sized 8-bit RGBA (or RGB) images as the frames of a movie, in order.

    Use it as a context manager; the movie appears under ``path`` when the block ends without
    an exception, and nothing is left behind otherwise.

    Parameters
    ----------
    path : str or os.PathLike
        ``NAME.mp4``, ``NAME.gif`` or a folder (``NAME/``) for ``frame_0000.png``, ...
        An existing file is replaced; an existing folder only when it holds nothing but such
        frames (a previous movie), so a mistyped path cannot wipe out unrelated files.
    size : (int, int)
        Frame ``(width, height)``; MP4 needs both even (H.264 in ``yuv420p``).
    frames : int
        Number of frames that will be written (sets the PNG numbers' width).
    fps : float
        Frames per second of MP4 and GIF.
    quality : float
        MP4 quality from 1 to 10 (imageio-ffmpeg's scale; 8 is visually lossless for renders).

    Examples
    --------
    >>> with MovieWriter("spin.mp4", (512, 512), frames=120) as movie:  # doctest: +SKIP
    ...     for image in scene.render_many(cameras, iso=80, image_only=True):
    ...         movie.write(image)
    """

    def __init__(self, path: str | os.PathLike, size: tuple[int, int], frames: int,
                 fps: float = 24.0, quality: float = 8.0) -> None:
        self.path = Path(path)
        self.kind = movie_kind(path)
        self.width, self.height = (int(v) for v in size)
        self.frames = int(frames)
        self.fps = float(fps)
        self.quality = float(quality)
        self.written = 0
        if not self.fps > 0:
            raise ParameterError(f"fps must be positive, got {fps}")
        if not 1 <= self.quality <= 10:
            raise ParameterError(f"quality must be between 1 and 10, got {quality}")
        if not self.path.parent.is_dir():
            raise ParameterError(f"{path}: the folder {self.path.parent} does not exist")
        if self.kind == "mp4" and (self.width % 2 or self.height % 2):
            raise ParameterError(f"{path}: MP4 (H.264) needs an even width and height, got "
                                 f"{self.width}x{self.height}")
        if self.kind != "png" and self.path.is_dir():
            raise ParameterError(f"{path}: is a folder")
        if self.kind == "png" and self.path.is_dir():
            strangers = [p.name for p in self.path.iterdir() if not _FRAME_RE.fullmatch(p.name)]
            if strangers:
                raise ParameterError(f"{path}: the folder exists and holds other files than "
                                     f"frame_NNNN.png (e.g. {strangers[0]}); choose a new one")
        if self.kind == "mp4":
            _ffmpeg()  # a missing imageio-ffmpeg fails before any rendering
        self._stack: ExitStack | None = None
        self._encoder: Any = None

    def __enter__(self) -> MovieWriter:
        self._stack = ExitStack()
        if self.kind == "png":
            temp = self._stack.enter_context(atomic_folder(self.path))
            self._encoder = _PngFolder(temp, self.frames)
        else:
            (temp,) = self._stack.enter_context(atomic_outputs(self.path))
            encoder = _Mp4 if self.kind == "mp4" else _Gif
            self._encoder = encoder(temp, (self.width, self.height), self.fps, self.quality)
        return self

    def write(self, image: np.ndarray) -> None:
        """Append one frame: ``(height, width, 4)`` or ``(height, width, 3)`` uint8."""
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.shape[:2] != (self.height, self.width) \
                or image.ndim != 3 or image.shape[2] not in (3, 4):
            raise ValueError(f"frame must be ({self.height}, {self.width}, 3 or 4) uint8, got "
                             f"{image.shape} {image.dtype}")
        self._encoder.write(image)
        self.written += 1

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> bool:
        assert self._stack is not None, "use MovieWriter in a with block"
        try:
            self._encoder.close(abort=exc_type is not None)
        except BaseException:
            # Encoding failed at the end (e.g. disk full): discard the temporary as well.
            if not self._stack.__exit__(*sys.exc_info()):
                raise
            return False
        return bool(self._stack.__exit__(exc_type, exc, tb))


def _ffmpeg() -> Any:
    """The imageio-ffmpeg module, or one clear error saying how to install it."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise ParameterError("writing MP4 needs imageio-ffmpeg: "
                             "pip install 'splinecast[distributed]'") from None
    return imageio_ffmpeg


class _Mp4:
    """H.264 frames piped to the ffmpeg binary that the imageio-ffmpeg wheel carries."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float, quality: float) -> None:
        # The temporary's name does not end in .mp4, so the container is named explicitly;
        # macro_block_size=1 keeps the frame size exact (the writer checked it is even).
        self._gen = _ffmpeg().write_frames(
            str(path), size, fps=fps, quality=quality, macro_block_size=1,
            output_params=["-f", "mp4"], ffmpeg_log_level="error")
        self._gen.send(None)

    def write(self, image: np.ndarray) -> None:
        self._gen.send(np.ascontiguousarray(image[..., :3]))

    def close(self, abort: bool) -> None:
        self._gen.close()  # ffmpeg finishes the file; on abort the temporary is removed after


class _Gif:
    """Frames quantized to 256 colours as they arrive (1 byte per pixel held), saved at the end
    (Pillow writes a GIF in one call). Identical consecutive frames become one frame shown as
    long as both: the GIF plays the same but may hold fewer frames."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float, quality: float) -> None:
        self._path = path
        self._duration = max(20, round(1000.0 / fps))  # ms; browsers clamp shorter delays
        self._frames: list = []

    def write(self, image: np.ndarray) -> None:
        from PIL import Image

        self._frames.append(Image.fromarray(np.ascontiguousarray(image[..., :3])).quantize(256))

    def close(self, abort: bool) -> None:
        if abort or not self._frames:
            return
        first, *rest = self._frames
        first.save(self._path, format="GIF", save_all=True, append_images=rest,
                   duration=self._duration, loop=0)


class _PngFolder:
    """Numbered RGBA PNG frames (lossless, as ``splinecast render`` writes them)."""

    def __init__(self, folder: Path, frames: int) -> None:
        self._folder = folder
        self._digits = max(4, len(str(max(frames - 1, 0))))
        self._count = 0

    def write(self, image: np.ndarray) -> None:
        from PIL import Image

        name = FRAME_NAME.format(self._count, width=self._digits)
        Image.fromarray(np.ascontiguousarray(image)).save(self._folder / name, format="PNG")
        self._count += 1

    def close(self, abort: bool) -> None:
        pass
