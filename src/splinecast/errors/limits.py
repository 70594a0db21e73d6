"""The one validation layer for everything that comes from outside: file headers, command lines and
API arguments.

A header field, an option or a keyword argument is checked here, against the limits below, before
anything is allocated, decompressed, memory-mapped or looped over. Every check raises one
exception of :mod:`splinecast.errors` whose message is one line naming the file or parameter and
saying what is wrong; the caller chooses the class (``ReadError`` for a file, ``ParameterError``
for an option) and the name.

What is checked
---------------
Counts and sizes
    Positive integers (no bool, NaN, infinity or fraction), at most :data:`MAX_AXIS` per volume
    axis and :data:`MAX_IMAGE_SIDE` per image side. Byte counts are computed with Python integers,
    so no product can wrap around.
Spacings and origins
    Finite normal floats: a spacing lies in :data:`SPACING_RANGE` (which excludes subnormal
    numbers, whose reciprocals overflow), an origin lies within :data:`MAX_ORIGIN_VOXELS` voxel
    spacings of 0 (so that voxel positions keep 12 fractional bits in float64).
Memory
    :func:`check_memory` compares the bytes an allocation derived from input would take with the
    memory available now (``MemAvailable`` of ``/proc/meminfo``, the cgroup's limit, the address
    space left under ``ulimit -v``) and with the cap ``SPLINECAST_MAX_BYTES`` (for example
    ``512MiB``), whichever is smallest.
Work
    Sampling steps are at least :data:`MIN_STEP` voxels and give at most
    :data:`MAX_SAMPLES_PER_RAY` samples along the volume's diagonal; the command line's
    ``--iterations`` of a root finder is at most :data:`MAX_ROOT_ITERATIONS`; images have at
    most :data:`MAX_IMAGE_SIDE` pixels per side.
Paths
    A path has no NUL byte and at most :data:`MAX_PATH_BYTES` bytes; a data file named by a
    header must lie, with symbolic links resolved, in the header's folder or below, unless the
    caller allows external files (``allow_external=True``, the CLI's ``--allow-external-data``
    or ``SPLINECAST_ALLOW_EXTERNAL_DATA=1``).
Compressed data and small files
    Decompression stops at the byte count the header promises (:func:`read_exact`); JSON files
    (sidecars, transfer functions) are read up to :data:`MAX_JSON_BYTES` and
    :data:`MAX_JSON_DEPTH` levels of nesting (:func:`load_json`), and so is every Zarr metadata
    file; a small file is opened without blocking and refused unless it is a regular file
    (:func:`open_regular`), so a FIFO, device or folder in its place cannot hang a reader.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from . import ParameterError, ReadError, SplinecastError

__all__ = [
    "ENV_ALLOW_EXTERNAL",
    "ENV_MAX_BYTES",
    "FRAME_BYTES_PER_PIXEL",
    "MAX_AXIS",
    "MAX_CHUNKS_PER_READ",
    "MAX_IMAGE_SIDE",
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_JSON_INT_DIGITS",
    "MAX_ORIGIN_VOXELS",
    "MAX_PATH_BYTES",
    "MAX_ROOT_ITERATIONS",
    "MAX_SAMPLES_PER_RAY",
    "MIN_STEP",
    "SPACING_RANGE",
    "allow_external_default",
    "check_count",
    "check_data_file",
    "check_inside",
    "check_memory",
    "check_origin",
    "check_path_text",
    "check_regular_file",
    "check_image",
    "check_render",
    "check_shape",
    "check_spacing",
    "check_step",
    "check_finite_number",
    "fmt_bytes",
    "load_json",
    "memory_limit",
    "nbytes",
    "open_regular",
    "parse_json",
    "parse_bytes",
    "printable",
    "read_exact",
    "read_limited",
    "shorten",
]

#: Environment variable capping the bytes of any one allocation derived from input.
ENV_MAX_BYTES = "SPLINECAST_MAX_BYTES"
#: Environment variable that, set to 1, lets headers name data files outside their folder.
ENV_ALLOW_EXTERNAL = "SPLINECAST_ALLOW_EXTERNAL_DATA"

#: Largest number of voxels along one axis of a volume.
MAX_AXIS = 1 << 20
#: Largest image width or height in pixels.
MAX_IMAGE_SIDE = 1 << 15
#: Smallest and largest voxel spacing (world units); excludes subnormal and absurd values.
SPACING_RANGE = (1e-12, 1e12)
#: Largest distance of an origin from 0, in voxel spacings along the same axis (2**40).
MAX_ORIGIN_VOXELS = float(1 << 40)
#: Smallest sampling step, in voxels (sampled isosurfaces and MIP, DVR).
MIN_STEP = 1e-3
#: Largest number of samples along the volume's diagonal at the chosen step.
MAX_SAMPLES_PER_RAY = 1 << 20
#: Largest iteration budget of a root finder (the defaults are 40 to 96).
MAX_ROOT_ITERATIONS = 1000
#: Longest path (bytes, as encoded for the file system) and longest path component.
MAX_PATH_BYTES = 4096
MAX_NAME_BYTES = 255
#: Bytes per pixel a rendered frame takes (colour, depth, position, normal, face, counters), with
#: room for the PNG conversion: the image-size memory check uses it.
FRAME_BYTES_PER_PIXEL = 96
#: Largest JSON file read (sidecars, transfer functions) and its deepest nesting.
MAX_JSON_BYTES = 1 << 20
MAX_JSON_DEPTH = 32
#: Most chunk files one read of a Zarr level may touch (a store of tiny chunks would take hours).
MAX_CHUNKS_PER_READ = 1 << 18
#: Longest integer (in digits) a JSON file may hold (2**64 has 20).
MAX_JSON_INT_DIGITS = 40

_UNITS = {"": 1, "b": 1, "k": 10**3, "kb": 10**3, "m": 10**6, "mb": 10**6, "g": 10**9,
          "gb": 10**9, "t": 10**12, "tb": 10**12, "kib": 1 << 10, "mib": 1 << 20,
          "gib": 1 << 30, "tib": 1 << 40}
_CHUNK = 1 << 20


# --------------------------------------------------------------------------- messages
def shorten(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters, so a hostile value cannot flood a message."""
    try:
        text = repr(value)
    except Exception:  # a third-party object whose repr fails is still worth naming
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def printable(text: str) -> str:
    """``text`` with every unprintable character escaped (``\\x1b``, ``\\n``, ``\\u2028``).

    Names taken from a hostile header may hold line breaks or terminal escape sequences; a message
    printed with this stays one harmless line.
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def fmt_bytes(n: int | float) -> str:
    """``3221225472`` -> ``"3.0 GiB"``."""
    value = float(n)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if abs(value) < 1024 or unit == "EiB":
            return f"{int(value)} bytes" if unit == "bytes" else f"{value:.1f} {unit}"
        value /= 1024
    raise AssertionError("unreachable")


# --------------------------------------------------------------------------- numbers
def _as_integer(value: Any) -> int | None:
    """``value`` as a Python int if it is an integral real number (not a bool), else None."""
    if isinstance(value, bool | np.bool_):
        return None
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating) and math.isfinite(value) and value == int(value):
        return int(value)
    return None


def check_count(
    value: Any,
    name: str,
    *,
    lo: int | None = 1,
    hi: int | None = None,
    error: type[SplinecastError] = ParameterError,
) -> int:
    """An integer in ``[lo, hi]`` (``None``: unbounded; a float is accepted only when integral).

    Examples
    --------
    >>> check_count(3.0, "size")
    3
    """
    number = _as_integer(value)
    bounds = [f">= {lo}" if lo is not None else "", f"at most {hi}" if hi is not None else ""]
    wanted = "an integer" + "".join(f" {b}" if i == 0 else f" and {b}"
                                    for i, b in enumerate(b for b in bounds if b))
    if number is None:
        raise error(f"{name} must be {wanted}, got {shorten(value)}")
    if (lo is not None and number < lo) or (hi is not None and number > hi):
        raise error(f"{name} must be {wanted}, got {number}")
    return number


def check_shape(
    values: Any,
    name: str,
    *,
    ndim: int = 3,
    error: type[SplinecastError] = ParameterError,
) -> tuple[int, ...]:
    """``ndim`` voxel counts, each an integer in ``[1, MAX_AXIS]``.

    Raises
    ------
    SplinecastError (the ``error`` class)
        With the offending values as given (never a wrapped-around product).
    """
    try:
        items = list(values)
    except TypeError:
        raise error(f"{name} must be {ndim} voxel counts, got {shorten(values)}") from None
    if len(items) != ndim:
        raise error(f"{name} must be {ndim} voxel counts, got {shorten(values)}")
    counts = [_as_integer(v) for v in items]
    if any(c is None or not 1 <= c <= MAX_AXIS for c in counts):
        shown = "x".join(shorten(v, 24) for v in items)
        raise error(
            f"{name} must be {ndim} integers between 1 and {MAX_AXIS}, got {shown}"
        )
    return tuple(int(c) for c in counts)  # type: ignore[arg-type]


def nbytes(shape: Sequence[int], itemsize: int) -> int:
    """Bytes of an array of ``shape`` (exact Python integer arithmetic, never wraps)."""
    total = int(itemsize)
    for n in shape:
        total *= int(n)
    return total


def check_finite_number(
    value: Any,
    name: str,
    *,
    lo: float = -math.inf,
    hi: float = math.inf,
    lo_open: bool = False,
    error: type[SplinecastError] = ParameterError,
) -> float:
    """A finite real number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``)."""
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise error(f"{name} must be a number, got {shorten(value)}") from None
    if isinstance(value, bool | np.bool_):
        raise error(f"{name} must be a number, got {shorten(value)}")
    below = number <= lo if lo_open else number < lo
    if not math.isfinite(number) or below or number > hi:
        low = f"{'>' if lo_open else '>='} {lo:g}"
        if math.isinf(hi):
            wanted = f"a finite number {low}" if math.isfinite(lo) else "a finite number"
        elif math.isinf(lo):
            wanted = f"a finite number <= {hi:g}"
        else:
            wanted = f"a finite number {low} and <= {hi:g}"
        raise error(f"{name} must be {wanted}, got {number:g}")
    return number


def _triple(values: Any, name: str, what: str, error: type[SplinecastError]) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=np.float64)
        arr = np.broadcast_to(arr, (3,)) if arr.size in (1, 3) else None
    except (TypeError, ValueError, OverflowError):
        arr = None
    if arr is None:
        raise error(f"{name} must be {what}, got {shorten(values)}")
    return arr.reshape(3)


def check_spacing(
    values: Any, name: str = "spacing", error: type[SplinecastError] = ParameterError
) -> tuple[float, float, float]:
    """Three spacings (or one for all axes), each finite and within :data:`SPACING_RANGE`."""
    lo, hi = SPACING_RANGE
    what = f"three numbers between {lo:g} and {hi:g}"
    arr = _triple(values, name, what, error)
    if not (np.all(np.isfinite(arr)) and np.all(arr >= lo) and np.all(arr <= hi)):
        raise error(f"{name} must be {what}, got {tuple(float(v) for v in arr)}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def check_origin(
    values: Any,
    spacing: Sequence[float],
    name: str = "origin",
    error: type[SplinecastError] = ParameterError,
) -> tuple[float, float, float]:
    """Three finite coordinates within :data:`MAX_ORIGIN_VOXELS` spacings of 0."""
    arr = _triple(values, name, "three finite numbers", error)
    if not np.all(np.isfinite(arr)):
        raise error(f"{name} must be three finite numbers, got {tuple(float(v) for v in arr)}")
    far = np.abs(arr) > MAX_ORIGIN_VOXELS * np.asarray(spacing, dtype=np.float64)
    if np.any(far):
        raise error(
            f"{name} {tuple(float(v) for v in arr)} lies more than 2^40 voxel spacings from 0; "
            "voxel positions could not be told apart"
        )
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def check_step(
    step: Any, name: str, shape: Sequence[int], error: type[SplinecastError] = ParameterError
) -> float:
    """A sampling step in voxels: at least :data:`MIN_STEP` and, along the diagonal of a volume
    of ``shape``, at most :data:`MAX_SAMPLES_PER_RAY` samples."""
    value = check_finite_number(step, name, lo=MIN_STEP, error=error)
    diagonal = math.sqrt(sum(float(n) ** 2 for n in shape))
    if diagonal / value > MAX_SAMPLES_PER_RAY:
        smallest = diagonal / MAX_SAMPLES_PER_RAY
        raise error(
            f"{name}={value:g} voxels gives more than {MAX_SAMPLES_PER_RAY} samples per ray "
            f"through this volume; use at least {smallest:.3g}"
        )
    return value


def check_image(width: int, height: int, name: str) -> None:
    """An image of ``width x height`` pixels: each side at most :data:`MAX_IMAGE_SIDE`, and its
    frame buffers (:data:`FRAME_BYTES_PER_PIXEL` per pixel) within :func:`memory_limit`."""
    for side, value in (("width", width), ("height", height)):
        check_count(value, f"{name}: image {side}", hi=MAX_IMAGE_SIDE)
    check_memory(nbytes((width, height), FRAME_BYTES_PER_PIXEL), f"a {width}x{height} image",
                 name)


def check_render(volume: Any, camera: Any) -> None:
    """What :meth:`splinecast.Scene.render` checks of every frame before any compiled code runs.

    An in-memory volume's data holds no NaN or infinity (the policy of :mod:`splinecast.volume`;
    a lazy multiscale volume, which has no ``require_finite``, is not scanned here) and the image
    fits in memory. A mode's own limits (a sampling step within the bounds of
    :func:`check_step` for this volume) are checked by the mode object
    (``splinecast.render.modes.RenderMode.check_limits``), which calls :func:`check_step`.
    """
    require_finite = getattr(volume, "require_finite", None)
    if require_finite is not None:
        require_finite()
    check_image(camera.width, camera.height, "camera size")


# --------------------------------------------------------------------------- memory
def parse_bytes(value: Any, name: str = ENV_MAX_BYTES) -> int:
    """A positive byte count from an int or a string such as ``"512MiB"``, ``"1.5GB"``, ``"1e9"``.

    Binary prefixes (KiB, MiB, ...) are powers of 1024; SI ones (kB, MB, ...) and bare letters
    powers of 1000, as in ``dask.utils.parse_bytes``. The one parser of sizes: the memory cap
    ``SPLINECAST_MAX_BYTES`` and the brick budgets of :mod:`splinecast.multires` use it.

    Examples
    --------
    >>> parse_bytes("2GiB"), parse_bytes("1.5 MB"), parse_bytes(4096)
    (2147483648, 1500000, 4096)
    """
    if isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    ):
        number, unit = float(value), ""
    else:
        match = re.fullmatch(r"\s*([0-9.eE+]+)\s*([a-zA-Z]*)\s*", str(value))
        unit = match.group(2).lower() if match else ""
        try:
            number = float(match.group(1)) if match else math.nan
        except ValueError:
            number = math.nan
    size = number * _UNITS[unit] if unit in _UNITS else math.nan
    if not (math.isfinite(size) and size >= 1):
        raise ParameterError(
            f"{name} must be a size such as 2GiB, 512MiB or 1.5GB, got {shorten(value)}"
        )
    return int(size)


#: Where the machine's memory is read (module attributes, so that tests can point them at fake
#: files): the kernel's memory summary and the cgroup v2 folder of this process.
MEMINFO_PATH = "/proc/meminfo"
CGROUP_ROOT = "/sys/fs/cgroup"


def _meminfo_available() -> int | None:
    try:
        with open(MEMINFO_PATH, "rb") as fh:
            for line in fh:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _read_int(path: str) -> int | None:
    try:
        with open(path, "rb") as fh:
            return int(fh.read(64).strip())
    except (OSError, ValueError):
        return None  # absent, or "max" (no limit)


def _cgroup_available() -> int | None:
    """Bytes left under the cgroup v2 memory limit of this process, if it has one."""
    limit = _read_int(os.path.join(CGROUP_ROOT, "memory.max"))
    if limit is None:
        return None
    used = _read_int(os.path.join(CGROUP_ROOT, "memory.current")) or 0
    return max(0, limit - used)


def _address_space_left() -> int | None:
    """Bytes of address space left under ``ulimit -v`` (RLIMIT_AS), if one is set."""
    try:
        import resource
    except ImportError:  # not on Unix
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/status", "rb") as fh:
            for line in fh:
                if line.startswith(b"VmSize:"):
                    return max(0, soft - int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    return soft


#: How long (seconds) a reading of the machine's memory serves :func:`memory_limit`: a brick
#: loader checks every chunk it reads (thousands per second), and reading /proc and the cgroup
#: files each time took a tenth of a 2048^3 pyramid's loading.
_MACHINE_READING_S = 0.5
_machine_reading: list = [-math.inf, None, []]


def _reading_key() -> tuple:
    """What invalidates a reading at once: another process (a fork) or another ``ulimit -v``."""
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    except ImportError:  # not on Unix
        soft = None
    return os.getpid(), soft


def _machine_limits() -> list[tuple[int, str]]:
    """The available memory, the cgroup's remaining memory and the address space left under
    ``ulimit -v`` (those known), read at most every :data:`_MACHINE_READING_S` seconds."""
    now = time.monotonic()
    key = _reading_key()
    if now - _machine_reading[0] > _MACHINE_READING_S or key != _machine_reading[1]:
        found = []
        for value, what in (
            (_meminfo_available(), "available memory"),
            (_cgroup_available(), "memory left under the cgroup limit"),
            (_address_space_left(), "address space left under ulimit -v"),
        ):
            if value is not None:
                found.append((value, f"the {fmt_bytes(value)} of {what}"))
        _machine_reading[:] = [now, key, found]
    return list(_machine_reading[2])


def memory_limit() -> tuple[int, str]:
    """The largest allocation allowed now, and what sets it (for messages).

    The smallest of ``SPLINECAST_MAX_BYTES`` (when set, read at every call), the available
    memory, the cgroup's remaining memory and the address space left under ``ulimit -v`` (read
    at most twice a second).
    """
    candidates: list[tuple[int, str]] = []
    cap = os.environ.get(ENV_MAX_BYTES)
    if cap:
        candidates.append((parse_bytes(cap), f"the cap {ENV_MAX_BYTES}={cap}"))
    candidates.extend(_machine_limits())
    if not candidates:
        return (1 << 62, "no known limit")
    return min(candidates, key=lambda c: c[0])


def check_memory(
    size: int, what: str, name: str, error: type[SplinecastError] = ParameterError
) -> int:
    """Refuse an allocation of ``size`` bytes above :func:`memory_limit`.

    Parameters
    ----------
    size : int
        Bytes the allocation would take (a Python int: may be astronomically large).
    what : str
        What would be allocated, e.g. ``"a 2000x2000x2000 float32 volume"``.
    name : str
        The file or option it comes from, first in the message.
    error : type
        ``ReadError`` for a file, ``ParameterError`` for an option.

    Returns
    -------
    int
        ``size``, for chaining.
    """
    limit, source = memory_limit()
    if size > limit:
        raise error(f"{name}: {what} needs {fmt_bytes(size)}, more than {source}")
    return size


# --------------------------------------------------------------------------- paths
def allow_external_default() -> bool:
    """Whether ``SPLINECAST_ALLOW_EXTERNAL_DATA`` allows data files outside a header's folder."""
    return os.environ.get(ENV_ALLOW_EXTERNAL, "").strip().lower() in ("1", "true", "yes")


def check_path_text(
    path: Any, name: str, error: type[SplinecastError] = ParameterError
) -> Path:
    """A path given as text: no NUL byte, at most :data:`MAX_PATH_BYTES` bytes and
    :data:`MAX_NAME_BYTES` per component (what the operating system would refuse obscurely)."""
    try:
        text = os.fspath(path)
    except TypeError:
        raise error(f"{name} must be a path, got {shorten(path)}") from None
    if isinstance(text, bytes):
        raw = text
    else:
        try:
            raw = os.fsencode(text)
        except (UnicodeError, ValueError):
            raise error(f"{name}: the path {shorten(text)} cannot be encoded") from None
    if not raw:
        raise error(f"{name}: the path is empty")
    if b"\0" in raw:
        raise error(f"{name}: the path {shorten(text)} contains a NUL byte")
    if len(raw) > MAX_PATH_BYTES or any(len(p) > MAX_NAME_BYTES for p in raw.split(b"/")):
        raise error(f"{name}: the path is too long ({len(raw)} bytes): {shorten(text)}")
    return Path(os.fsdecode(raw))


def check_regular_file(path: Path, name: str) -> os.stat_result:
    """The file's status; a folder, device, pipe or socket is refused with a :class:`ReadError`."""
    try:
        info = path.stat()
    except FileNotFoundError:
        raise ReadError(f"{name}: no such file") from None
    except OSError as exc:
        raise ReadError(f"{name}: cannot read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise ReadError(f"{name}: not a regular file")
    return info


def check_data_file(
    header: Path,
    value: Any,
    field: str,
    *,
    allow_external: bool | None = None,
    root_name: str = "the header's folder",
) -> Path:
    """The data file a header names, checked to lie in the header's folder or below.

    Parameters
    ----------
    header : Path
        The header file (its folder is the root data files must stay under).
    value : str
        The file name as written in the header, relative to the header's folder.
    field : str
        The header field, for messages (``"ElementDataFile"``).
    allow_external : bool, optional
        Allow any file; default from ``SPLINECAST_ALLOW_EXTERNAL_DATA``.
    root_name : str
        How messages call the folder (``"the series folder"`` for a DICOM slice).

    Raises
    ------
    ReadError
        A NUL byte, an over-long or empty name, or a file outside the header's folder (symbolic
        links resolved), naming the header and the field.
    """
    label = f"{header}: {field}"
    if not isinstance(value, str):
        raise ReadError(f"{label} must be a file name, got {shorten(value)}")
    name = check_path_text(value.strip(), label, ReadError)
    candidate = header.parent / name
    if allow_external is None:
        allow_external = allow_external_default()
    if allow_external:
        return candidate
    try:
        root = header.parent.resolve()
        target = candidate.resolve()
    except (OSError, RuntimeError) as exc:  # symlink loop
        raise ReadError(f"{label} {shorten(value)} cannot be resolved ({exc})") from None
    if target != root and root not in target.parents:
        raise ReadError(
            f"{label} {shorten(value)} lies outside {root_name}; "
            f"pass --allow-external-data (or set {ENV_ALLOW_EXTERNAL}=1) if that is intended"
        )
    return candidate


# --------------------------------------------------------------------------- bounded reading
def open_regular(path: Path, name: str, *, streams: bool = False) -> int:
    """A file descriptor of ``path`` opened for reading, refusing anything but a regular file.

    The file is opened without blocking, so a FIFO (which would wait for a writer forever), a
    device or a folder is refused before a byte is read; the descriptor is the caller's to close.
    With ``streams``, a pipe or character device is accepted (``--tf <(...)``): opened without
    blocking it cannot hang (a pipe without a writer reads as empty), and the caller bounds the
    read.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ReadError(f"{name}: no such file") from None
    except IsADirectoryError:
        raise ReadError(f"{name}: is a folder, not a file") from None
    except OSError as exc:
        raise ReadError(f"{name}: cannot read: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
    except OSError as exc:
        os.close(fd)
        raise ReadError(f"{name}: cannot read: {exc.strerror or exc}") from None
    if not (stat.S_ISREG(mode) or (streams and (stat.S_ISFIFO(mode) or stat.S_ISCHR(mode)))):
        os.close(fd)
        kind = "a folder" if stat.S_ISDIR(mode) else "a pipe" if stat.S_ISFIFO(mode) else \
            "a device or socket"
        raise ReadError(f"{name}: is {kind}, not a regular file")
    os.set_blocking(fd, True)
    return fd


def read_limited(path: Path, max_bytes: int, name: str) -> bytes:
    """The whole content of a small regular file, refusing one longer than ``max_bytes``.

    Reads at most ``max_bytes + 1`` bytes, so a huge file or ``/dev/zero`` costs nothing; a
    folder or socket is refused, and a pipe is opened without blocking (:func:`open_regular`).
    """
    fd = open_regular(path, name, streams=True)
    try:
        with os.fdopen(fd, "rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise ReadError(f"{name}: cannot read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise ReadError(f"{name}: longer than {fmt_bytes(max_bytes)}; not a file of this kind")
    return data


def _depth(value: Any) -> int:
    """Nesting depth of parsed JSON (iterative, so a deep value cannot exhaust the stack)."""
    deepest = 0
    stack = [(value, 1)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, level)
            if level > MAX_JSON_DEPTH:
                return level
            children = item.values() if isinstance(item, dict) else item
            stack.extend((child, level + 1) for child in children)
    return deepest


def parse_json(raw: bytes, name: str) -> Any:
    """Parse JSON bytes with bounded nesting; any failure is a :class:`ReadError` naming ``name``.

    Non-finite numbers (``NaN``, ``Infinity``, ``1e999``) and integers of more than
    :data:`MAX_JSON_INT_DIGITS` digits are refused as well: no field of a file splinecast reads
    can use them.
    """
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ReadError(f"{name}: not UTF-8 text") from None

    def no_constant(token: str) -> Any:
        raise ValueError(f"{token} is not allowed")

    def finite_float(token: str) -> float:
        number = float(token)
        if not math.isfinite(number):
            raise ValueError(f"number {shorten(token, 24)} is out of range")
        return number

    def bounded_int(token: str) -> int:
        if len(token.lstrip("-")) > MAX_JSON_INT_DIGITS:
            raise ValueError(f"integer {shorten(token, 24)} is out of range")
        return int(token)

    try:
        value = json.loads(text, parse_constant=no_constant, parse_float=finite_float,
                           parse_int=bounded_int)
    except RecursionError:
        raise ReadError(f"{name}: JSON nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, over-long integers, NaN/Infinity
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ReadError(f"{name}: not valid JSON ({shorten(first, 120)})") from None
    if _depth(value) > MAX_JSON_DEPTH:
        raise ReadError(f"{name}: JSON nested more than {MAX_JSON_DEPTH} levels deep")
    return value


def load_json(path: Path, name: str, max_bytes: int = MAX_JSON_BYTES) -> Any:
    """Parse a small JSON file with bounded size and nesting (:func:`parse_json`); any failure
    is a ReadError."""
    return parse_json(read_limited(path, max_bytes, name), name)


def check_inside(path: Path, root: Path, label: str, *, allow_external: bool | None = None,
                 root_name: str = "the store's folder") -> Path:
    """``path`` with symbolic links resolved, refused unless it lies in ``root`` or below (or
    the caller allows external files, see :func:`check_data_file`)."""
    if allow_external is None:
        allow_external = allow_external_default()
    try:
        target = path.resolve()
        base = root.resolve()
    except (OSError, RuntimeError) as exc:  # symlink loop
        raise ReadError(f"{label} cannot be resolved ({exc})") from None
    if not allow_external and target != base and base not in target.parents:
        raise ReadError(
            f"{label} lies outside {root_name} (it leads to {shorten(str(target), 80)}); pass "
            f"--allow-external-data (or set {ENV_ALLOW_EXTERNAL}=1) if that is intended"
        )
    return target


def read_exact(stream: IO[bytes], size: int, name: str, what: str = "data") -> np.ndarray:
    """Read exactly ``size`` bytes from a (decompressing) stream and make sure nothing follows.

    Decompression is bounded by ``size``: a stream that would inflate beyond it (a compression
    bomb, ``/dev/zero``) is stopped after one more byte. Any error of the stream (zlib, bz2, lzma,
    zip CRC, truncation) becomes a :class:`ReadError` naming the file. Check ``size`` with
    :func:`check_memory` first: the bytes are returned in one new ``uint8`` array.
    """
    out = np.empty(size, dtype=np.uint8)
    got = 0
    try:
        while got < size:
            chunk = stream.read(min(_CHUNK, size - got))
            if not chunk:
                break
            out[got : got + len(chunk)] = np.frombuffer(chunk, dtype=np.uint8)
            got += len(chunk)
        extra = stream.read(1) if got == size else b""
    except Exception as exc:  # decompressors raise OSError, EOFError, zlib.error, BadZipFile...
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ReadError(f"{name}: corrupt {what} ({shorten(detail, 120)})") from None
    if got < size:
        raise ReadError(f"{name}: {what} ends after {got} of the {size} bytes the header gives")
    if extra:
        raise ReadError(f"{name}: {what} holds more than the {size} bytes the header gives")
    return out
