"""Colours and names of the labels of a label volume (segmentation).

Where a label's colour comes from, first match wins:

1. a colour table given by the user (:func:`read_color_table`): a JSON or CSV file, or the same
   content as a Python mapping or list;
2. the OME-Zarr ``image-label`` metadata of the store (``colors``: ``{"label-value": k,
   "rgba": [r, g, b, a]}`` with 0..255 integers; ``properties``: ``{"label-value": k, "name":
   ...}`` gives names), which :func:`splinecast.read` keeps as ``metadata["image_label"]``;
3. the default palette (:func:`palette_color`): a hue walk by the golden ratio, so neighbouring
   label values get far-apart hues, and a label keeps its colour whatever else is shown.

Label 0 is the background: it has no colour and is never drawn.

File formats
------------
JSON, either a mapping from label value to an entry, or a list of entries with a
``"label-value"`` (as in ``image-label.colors``)::

    {"3": {"rgba": [255, 0, 0, 255], "name": "liver"}, "5": [0, 128, 255]}
    [{"label-value": 3, "rgba": [255, 0, 0, 255], "name": "liver"}]

An entry is an RGB or RGBA list, or a mapping with ``rgba`` (or ``rgb``, ``color``) and an
optional ``name``. CSV: one label per row, ``value,r,g,b[,a][,name]``; a first row that does not
start with a number is a header. Colour components are 0..255 integers, or numbers in [0, 1] when
any component of the row is written with a decimal point.
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ParameterError, ReadError

__all__ = ["LabelStyle", "palette_color", "read_color_table", "parse_color_table",
           "image_label_table", "MAX_TABLE_BYTES"]

#: Colour tables larger than this are refused (a table names each label once: 64 MiB is far
#: more than any segmentation has labels).
MAX_TABLE_BYTES = 64 << 20
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class LabelStyle:
    """How one label is drawn.

    Attributes
    ----------
    rgba : tuple of 4 floats in [0, 1]
        Colour and opacity.
    name : str or None
        What the label is (``"liver"``), shown by pickers and legends.
    """

    rgba: tuple[float, float, float, float]
    name: str | None = None


def palette_color(value: int) -> tuple[float, float, float, float]:
    """The default colour of label ``value``: hue ``value * 0.618...`` (mod 1), saturation and
    brightness alternating between two levels so that labels of similar hue differ in tone.

    A function of the value alone, so a label keeps its colour whatever else is shown, hidden
    or present (napari colours labels the same way, by value).
    """
    hue = (int(value) * _GOLDEN) % 1.0
    saturation = 0.65 if value % 2 else 0.85
    brightness = 0.95 if (value // 2) % 2 else 0.78
    return (*_hsv_to_rgb(hue, saturation, brightness), 1.0)


def _hsv_to_rgb(h: float, s: float, v: float) -> tuple[float, float, float]:
    i = int(h * 6.0) % 6
    f = h * 6.0 - int(h * 6.0)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    return [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]


def _label_value(key: Any, where: str) -> int:
    try:
        number = float(key)
    except (TypeError, ValueError):
        raise ParameterError(f"{where}: label {key!r} is not an integer") from None
    if not math.isfinite(number) or number != int(number):
        raise ParameterError(f"{where}: label {key!r} is not an integer")
    return int(number)


def _rgba(components: Any, where: str, decimal: bool | None = None) -> tuple[float, ...]:
    """0..255 integers, or [0, 1] numbers (any float among them, or ``decimal``) -> [0, 1]."""
    if not isinstance(components, (list, tuple)) or len(components) not in (3, 4):
        raise ParameterError(f"{where}: a colour must be 3 or 4 numbers (RGB or RGBA), got "
                             f"{components!r}")
    values = []
    for c in components:
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c):
            raise ParameterError(f"{where}: colour components must be numbers, got "
                                 f"{components!r}")
        values.append(c)
    unit = decimal if decimal is not None else any(isinstance(c, float) for c in values)
    top = 1.0 if unit else 255.0
    if any(not 0 <= c <= top for c in values):
        scale = "[0, 1]" if unit else "0..255"
        raise ParameterError(f"{where}: colour components must lie in {scale}, got "
                             f"{components!r}")
    if len(values) == 3:
        values.append(top)
    return tuple(float(c) / top for c in values)


def _entry(value: int, entry: Any, where: str) -> LabelStyle:
    if isinstance(entry, Mapping):
        colour = next((entry[k] for k in ("rgba", "rgb", "color", "colour") if k in entry), None)
        name = entry.get("name")
        if colour is None:
            raise ParameterError(f"{where}: label {value} has no 'rgba'")
        if name is not None and not isinstance(name, str):
            raise ParameterError(f"{where}: the name of label {value} is not text")
        return LabelStyle(_rgba(colour, f"{where}: label {value}"), name)  # type: ignore
    return LabelStyle(_rgba(entry, f"{where}: label {value}"))  # type: ignore[arg-type]


def parse_color_table(table: Any, where: str) -> dict[int, LabelStyle]:
    """A colour table given as a mapping ``{value: entry}`` or a list of entries with
    ``"label-value"`` (see the module's formats), checked.

    Parameters
    ----------
    table : mapping or list
        The table's content.
    where : str
        Names the table in messages (the file and the option it came from).

    Raises
    ------
    ParameterError
        An entry that is not a colour, a label that is not an integer, a label given twice.
    """
    styles: dict[int, LabelStyle] = {}

    def add(value: int, style: LabelStyle) -> None:
        if value in styles:
            raise ParameterError(f"{where}: label {value} is given twice")
        styles[value] = style

    if isinstance(table, Mapping):
        for key, entry in table.items():
            value = _label_value(key, where)
            add(value, _entry(value, entry, where))
    elif isinstance(table, list):
        for entry in table:
            if not isinstance(entry, Mapping) or "label-value" not in entry:
                raise ParameterError(f"{where}: each entry of a list needs a 'label-value'")
            value = _label_value(entry["label-value"], where)
            add(value, _entry(value, entry, where))
    else:
        raise ParameterError(f"{where}: a colour table is a mapping from label to colour or a "
                             f"list of entries, got {type(table).__name__}")
    return styles


def _csv_table(text: str, where: str) -> dict[int, LabelStyle]:
    styles: dict[int, LabelStyle] = {}
    rows = [r for r in csv.reader(text.splitlines()) if r and any(c.strip() for c in r)]
    for number, row in enumerate(rows, 1):
        cells = [c.strip() for c in row]
        if number == 1 and not _is_number(cells[0]):
            continue  # a header
        at = f"{where}, row {number}"
        if len(cells) < 4:
            raise ParameterError(f"{at}: expected value,r,g,b[,a][,name], got {','.join(row)}")
        value = _label_value(cells[0], at)
        numeric = [c for c in cells[1:5] if _is_number(c)]
        count = 4 if len(numeric) == 4 else 3
        parts = cells[1:1 + count]
        if not all(_is_number(c) for c in parts):
            raise ParameterError(f"{at}: colour components must be numbers, got "
                                 f"{','.join(parts)}")
        decimal = any("." in c or "e" in c.lower() for c in parts)
        rgba = _rgba([float(c) for c in parts], at, decimal)
        name = ",".join(cells[1 + count:]) or None
        if value in styles:
            raise ParameterError(f"{at}: label {value} is given twice")
        styles[value] = LabelStyle(rgba, name)  # type: ignore[arg-type]
    return styles


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_color_table(path: str | os.PathLike[str], option: str = "colors",
                     ) -> dict[int, LabelStyle]:
    """Read a colour table file: ``.json`` or ``.csv`` (see the module's formats).

    Parameters
    ----------
    path : path
        The file.
    option : str
        The option or argument that named it, for messages (``"--label-colors"``).

    Returns
    -------
    dict
        Label value -> :class:`LabelStyle`.

    Raises
    ------
    ReadError
        The file is missing, unreadable or too large.
    ParameterError
        Its content is not a colour table (the message names the file and ``option``).
    """
    path = Path(os.fspath(path))
    where = f"{path} ({option})"
    suffix = path.suffix.lower()
    if suffix not in (".json", ".csv"):
        raise ParameterError(f"{where}: a colour table must be a .json or .csv file")
    try:
        size = path.stat().st_size
        if size > MAX_TABLE_BYTES:
            raise ReadError(f"{where}: {size} bytes is too large for a colour table")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ReadError(f"{where}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ReadError(f"{where}: cannot be read ({exc.__class__.__name__})") from None
    if suffix == ".csv":
        return _csv_table(text, where)
    try:
        content = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParameterError(f"{where}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    return parse_color_table(content, where)


def image_label_table(image_label: Any, where: str) -> dict[int, LabelStyle]:
    """The colours and names of OME-Zarr ``image-label`` metadata (``colors`` and
    ``properties``); labels with a name but no colour get the palette's."""
    if not isinstance(image_label, Mapping):
        return {}
    colours = image_label.get("colors") or []
    styles = parse_color_table(list(colours), f"{where}: image-label colors") if isinstance(
        colours, list) else {}
    names: dict[int, str] = {}
    for entry in image_label.get("properties") or []:
        if isinstance(entry, Mapping) and "label-value" in entry:
            name = entry.get("name", entry.get("label-name"))
            if isinstance(name, str):
                names[_label_value(entry["label-value"], where)] = name
    for value, name in names.items():
        style = styles.get(value)
        rgba = style.rgba if style is not None else palette_color(value)
        styles[value] = LabelStyle(rgba, (style.name if style and style.name else name))
    return styles


def describe(values: Iterable[int], limit: int = 12) -> str:
    """``1, 2, 5, ...`` for messages (at most ``limit`` values)."""
    values = list(values)
    text = ", ".join(str(v) for v in values[:limit])
    return text + (f", ... ({len(values)} in all)" if len(values) > limit else "")
