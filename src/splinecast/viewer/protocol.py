"""The viewer's WebSocket message protocol (version :data:`PROTOCOL_VERSION`).

Documented for other clients in ``docs/viewer-protocol.md``. In short:

* client -> server: JSON text messages ``{"type": "render", "id": N, "state": {...},
  "interactive": bool}``, ``{"type": "screenshot", "id": N, "state": {...}}`` and (label
  volumes) ``{"type": "pick", "id": N, "state": {...}, "x": X, "y": Y}``;
* server -> client: a JSON ``hello`` on connection (protocol version, volume, histogram, models,
  modes, colormaps, default state), JSON ``error``, ``status`` and ``pick`` messages, and
  frames as binary messages: a 4-byte big-endian header length, the UTF-8 JSON header, then
  the image (JPEG or PNG).

This module turns bytes into checked messages and back; it knows nothing of sockets.
"""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..models import MODELS
from ..render.modes import MODE_NAMES as MODES
from ..render.modes import MODES as MODE_CLASSES
from ..render.modes import modes_reading
from ..transfer import MENU, colormap_table
from ..volume import Volume

__all__ = [
    "PROTOCOL_VERSION",
    "PROTOCOL_MINOR",
    "MAX_MESSAGE_BYTES",
    "decode_request",
    "hello_message",
    "histogram",
    "pack_frame",
    "unpack_frame",
    "json_safe_stats",
]

#: Version of the message protocol; a client should refuse a ``hello`` with another major number.
PROTOCOL_VERSION = 1
#: Minor version (``hello.v_minor``): additions a version-1 client may ignore. 1: the frame
#: header's ``bricks`` and ``hello.multires`` (multiresolution data), ``hello.v_minor``. 2: the
#: state's ``dvr.sampling``, and the default ``dvr`` state is the library's default DVR. 3: the
#: automatic window, ``preparing`` frames. 4: time series (``hello.timepoints``, the state's
#: ``timepoint``, the frame header's ``timepoint``). 5: several channels (``hello.channels``,
#: the state's ``channels``). 6: ``hello.mode_keywords`` (which controls each mode reads),
#: ``hello.auto_window`` for every mode with a window. 7: label volumes (``hello.labels``, the
#: state's ``labels``, ``pick`` requests answered by ``pick`` messages). 8:
#: ``hello.mode_compositing`` (what each mode shows of several channels).
PROTOCOL_MINOR = 8
#: Largest text message accepted from a client (bytes); larger ones close the connection.
MAX_MESSAGE_BYTES = 64 * 1024
#: Request types a client may send.
REQUEST_TYPES = ("render", "screenshot", "pick")
#: Largest request id (ids are echoed in frame headers; JavaScript integers stay exact below).
MAX_ID = 2**53 - 1

_HEADER_LENGTH = struct.Struct(">I")
_HISTOGRAM_BINS = 256
_HISTOGRAM_SAMPLE = 16_000_000  # voxels; above this the histogram comes from a strided subsample
_COLORMAP_SAMPLES = 64


def _refuse_constant(name: str) -> Any:
    raise ParameterError(f"message: {name} is not a number JSON allows")


def decode_request(text: Any) -> dict[str, Any]:
    """Parse and check a client's text message.

    Returns ``{"type", "id", "state", "interactive"}``; the state itself is checked later by
    :func:`splinecast.viewer.state.parse_state`.

    Raises
    ------
    ParameterError
        Not JSON, not an object, an unknown type or field, a bad id.
    """
    if not isinstance(text, str):
        raise ParameterError("message: only JSON text messages are accepted")
    if len(text) > MAX_MESSAGE_BYTES:
        raise ParameterError(f"message: longer than {MAX_MESSAGE_BYTES} bytes")
    try:
        message = json.loads(text, parse_constant=_refuse_constant)
    except (json.JSONDecodeError, RecursionError) as exc:
        reason = exc.msg if isinstance(exc, json.JSONDecodeError) else "nested too deeply"
        raise ParameterError(f"message: not valid JSON ({reason})") from None
    if not isinstance(message, dict):
        raise ParameterError("message: must be a JSON object")
    kind = message.get("type")
    if kind not in REQUEST_TYPES:
        raise ParameterError(f"message: type must be one of {', '.join(REQUEST_TYPES)}, "
                             f"got {kind!r}")
    fields = ("type", "id", "state", "interactive", "v", "x", "y")
    unknown = sorted(str(k) for k in message if k not in fields)
    if unknown:
        raise ParameterError(f"message: no field {unknown[0]!r} (valid: {', '.join(fields)})")
    version = message.get("v", PROTOCOL_VERSION)
    if version != PROTOCOL_VERSION or isinstance(version, bool):
        raise ParameterError(f"message: protocol version {version!r} is not supported "
                             f"(this server speaks {PROTOCOL_VERSION})")
    ident = message.get("id", 0)
    if isinstance(ident, bool) or not isinstance(ident, int) or not 0 <= ident <= MAX_ID:
        raise ParameterError(f"message: id must be an integer in [0, 2^53), got {ident!r}")
    interactive = message.get("interactive", False)
    if not isinstance(interactive, bool):
        raise ParameterError(f"message: interactive must be true or false, got {interactive!r}")
    state = message.get("state", {})
    if not isinstance(state, dict):
        raise ParameterError("message: state must be an object")
    out = {"type": kind, "id": ident, "state": state, "interactive": interactive}
    if kind == "pick":
        for axis in ("x", "y"):
            value = message.get(axis)
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not math.isfinite(value):
                raise ParameterError(f"pick: {axis} must be a pixel coordinate (a number), "
                                     f"got {value!r}")
            out[axis] = float(value)
    elif "x" in message or "y" in message:
        raise ParameterError(f"message: x and y belong to pick requests, not {kind}")
    return out


def histogram(volume: Volume, bins: int = _HISTOGRAM_BINS,
              value_range: tuple[float, float] | None = None) -> dict[str, Any]:
    """Value histogram of ``volume`` over ``value_range`` (default: its data range):
    ``{"lo", "hi", "counts"}``.

    Volumes above 16 million voxels are subsampled with a stride per axis (the page draws the
    histogram behind the sliders, where its shape is what matters).
    """
    data = volume.data
    if data.size > _HISTOGRAM_SAMPLE:
        stride = int(math.ceil((data.size / _HISTOGRAM_SAMPLE) ** (1 / 3)))
        data = data[::stride, ::stride, ::stride]
    lo, hi = volume.value_range if value_range is None else value_range
    top = hi if hi > lo else lo + 1.0
    values = np.asarray(data).reshape(-1)
    if values.dtype.kind == "f":
        values = values[np.isfinite(values)]
    counts, _ = np.histogram(values, bins=bins, range=(lo, top))
    return {"lo": lo, "hi": top, "counts": counts.tolist()}


def hello_message(volume: Volume, defaults: dict[str, Any], limits: dict[str, Any], *,
                  geometry: Any = None, models: Any = MODELS, modes: Any = MODES,
                  multires: dict[str, Any] | None = None, timepoints: int = 1,
                  channels: list[dict[str, Any]] | None = None,
                  labels: list[dict[str, Any]] | None = None) -> dict:
    """The first message of every connection: what the page needs to build its controls.

    ``volume`` gives the histogram (a multiresolution volume's coarsest level: cheap, and never
    the finest level); ``geometry`` (default ``volume``) the description of the data shown;
    ``models`` and ``modes`` the choices offered; ``multires`` describes a pyramid or wavelet
    store; ``timepoints`` is the number of time points of a time series (1 otherwise);
    ``channels`` lists the channels shown together (their labels and starting settings;
    ``None`` for one volume); ``labels`` the labels of a label volume (``value``, ``name``,
    ``color``; ``None`` for other data).
    """
    geometry = volume if geometry is None else geometry
    lo, hi = geometry.bounds
    return {
        "type": "hello",
        "v": PROTOCOL_VERSION,
        "v_minor": PROTOCOL_MINOR,
        "volume": {
            "name": geometry.name,
            "shape": [int(n) for n in geometry.shape],
            "dtype": str(geometry.dtype),
            "spacing": [float(v) for v in geometry.spacing],
            "origin": [float(v) for v in geometry.origin],
            "bounds": [np.asarray(lo).tolist(), np.asarray(hi).tolist()],
            "value_range": [float(v) for v in geometry.value_range],
        },
        "histogram": histogram(volume, value_range=geometry.value_range),
        "multires": multires,
        # Time points the state's ``timepoint`` may choose (the page shows a slider when > 1).
        "timepoints": int(timepoints),
        # Channels shown together (the page lists them; the state's ``channels`` sets them).
        "channels": channels,
        # A label volume's labels (the page lists them; the state's ``labels`` sets them).
        "labels": labels,
        "models": list(models),
        "modes": list(modes),
        # The menu's colormaps, and those of the default state when they are not in it.
        "colormaps": {name: np.round(colormap_table(name, _COLORMAP_SAMPLES), 4).tolist()
                      for name in dict.fromkeys([*MENU, defaults["colormap"],
                                                 defaults["tf"].get("colormap", "viridis")])
                      if isinstance(name, str)},
        "defaults": defaults,
        # What a null window stands for in each projection (the page shows it on the slider).
        "auto_window": {mode: [float(v) for v in MODE_CLASSES[mode].default_window(volume)]
                        for mode in modes_reading("window")},
        # The render keywords each mode reads: the page shows the controls of those.
        "mode_keywords": {mode: list(MODE_CLASSES[mode].keywords) for mode in modes},
        # What each mode shows of several channels (the page's note on the channels).
        "mode_compositing": {mode: MODE_CLASSES[mode].compositing.summary for mode in modes},
        "limits": limits,
    }


def json_safe_stats(stats: dict[str, Any]) -> dict[str, Any]:
    """The scalar entries of a frame's ``stats`` that JSON can carry (finite numbers, strings,
    booleans, null, and lists of numbers)."""
    out: dict[str, Any] = {}
    for key, value in stats.items():
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, bool | str) or value is None:
            out[key] = value
        elif isinstance(value, int | float):
            out[key] = value if math.isfinite(value) else None
        elif isinstance(value, list | tuple) and all(
                isinstance(v, int | float) and math.isfinite(v) for v in value):
            out[key] = list(value)
    return out


def pack_frame(header: dict[str, Any], image: bytes) -> bytes:
    """A binary frame message: header length (4 bytes, big-endian), JSON header, image."""
    head = json.dumps(header, separators=(",", ":")).encode()
    return _HEADER_LENGTH.pack(len(head)) + head + image


def unpack_frame(data: bytes) -> tuple[dict[str, Any], bytes]:
    """Split a binary frame message into its header and image bytes (the inverse of
    :func:`pack_frame`)."""
    (length,) = _HEADER_LENGTH.unpack_from(data)
    start = _HEADER_LENGTH.size
    return json.loads(data[start:start + length]), data[start + length:]
