"""Mutations of a seed folder: byte-level ones that know nothing, structure-aware ones that know
the format (text header fields, JSON keys, the ``.npy`` header, NIfTI header fields, DICOM tags,
compressed streams, TIFF descriptions, file names and symbolic links).

Every mutation takes the case folder (a copy of a seed), the seed and a ``random.Random`` and
changes the files in place; it returns a short description for the report, so that any case can
be understood (and rebuilt: cases are deterministic in their number and the run's seed).
"""

from __future__ import annotations

import bz2
import gzip
import json
import os
import random
import re
import struct
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

from .seeds import DATA_BYTES, SHAPE, Seed

#: Names a hostile header may give its data file (relative to the case folder, which is
#: ``root/cases/<n>``); :data:`SENTINEL` is filled in with the absolute sentinel path.
SENTINEL = "@SENTINEL@"
PATH_TOKENS = [
    "../../SENTINEL.raw", SENTINEL, "/etc/passwd", "../" * 12 + "etc/passwd", "/dev/zero",
    "/proc/self/mem", "../other/v.raw", "sub/../../../SENTINEL.raw", "./v.raw", "..", ".", "/",
    "", "v.raw\0.png", "a" * 300, "a/" * 2100 + "v.raw", "nonexistent.raw", "LOCAL", "LIST",
    "v%03d.raw 1 3 1", "  v.raw  ", "\u00e9\u00e8.raw", "C:\\Windows\\win.ini", "~/v.raw",
]
NUMBER_TOKENS = [
    "0", "-0", "1", "-1", "2", "1.5", "1e-320", "4.9e-324", "1e-45", "-1e-320", "nan", "NaN",
    "inf", "-inf", "Infinity", "1e30", "1e308", "1e400", "2147483647", "2147483648",
    "4294967296", "65535", "9223372036854775807", "9223372036854775808",
    "-9223372036854775808", "1180591620717411303424", "0x10", "1_000", "", "abc", "\0", " ",
    "1" * 5000, "1e-300", "3.0000000001", "+5", "٣",
]
TUPLE_TOKENS = [
    "6 5 4", "4 5 6", "2000 2000 2000", "1 1 1000000000", "65535 65535 65535", "0 5 4",
    "-6 5 4", "6 5", "6 5 4 1", "6 5 4 2", "1 1 1", "1e30 1 1", "inf 1 1", "nan 5 4",
    "1e-320 1 1", "1 1e-320 1", "6.5 5 4", "2e9 2e9 2e9", "1180591620717411303424 1 1",
    "1e-320 1e-320 1e-320", "1e12 1e12 1e12", "1e15 0 0", "1e300 1e300 1e300",
]
TYPE_TOKENS = [
    "MET_UCHAR", "MET_CHAR", "MET_SHORT", "MET_USHORT", "MET_INT", "MET_UINT", "MET_FLOAT",
    "MET_DOUBLE", "MET_LONG", "MET_ULONG_LONG", "MET_FLOAT_ARRAY", "MET_STRING", "MET_OTHER",
    "uchar", "signed char", "short", "unsigned short", "int", "uint", "float", "double",
    "int64", "uint64", "block", "float16", "complex", "bool", "uint8", "u2", "<f4", ">i2",
    "|O", "object", "S10", "V8", "U3", "(2,)f4", "f4,f4", "[('a','<f4')]", "M8[s]", "c16",
    "float128", "int4", "((((((((", "'", "", "\0",
]
ENCODING_TOKENS = ["raw", "gzip", "gz", "bzip2", "bz2", "text", "txt", "ascii", "hex", "zrl",
                   "lzma", "xz", "zstd", "GZIP", "", "raw gzip"]
INTERESTING_INTS = [0, 1, -1, 2, 3, 0x7F, 0x80, 0xFF, 0x7FFF, 0x8000, 0xFFFF, 0x7FFFFFFF,
                    0x80000000, 0xFFFFFFFF, 2**63 - 1, 2**63, 2**64 - 1, 6, 5, 4, 1000, 65536,
                    2000, 10**9]
INTERESTING_FLOATS = [0.0, -0.0, 1.0, -1.0, float("nan"), float("inf"), float("-inf"),
                      1e-320, 5e-324, 1e-45, 1e-38, 1e38, 3.4e38, 1e308, 1e30, 1e-30, 0.5]


# --------------------------------------------------------------------------- helpers
def _files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.is_file() and not p.is_symlink())


def _main_file(folder: Path, seed: Seed) -> Path:
    main = folder / seed.main
    if main.is_file():
        return main
    files = _files(folder)
    if not files:  # an earlier mutation left no regular file: start one
        main.parent.mkdir(parents=True, exist_ok=True)
        main.write_bytes(b"")
        return main
    return files[0]


def _split_text_header(data: bytes, fmt: str) -> tuple[bytes, bytes]:
    """(header, rest) of a file whose header is text: MetaImage, NRRD, VTK legacy."""
    if fmt in ("mha", "mhd"):
        match = re.search(rb"ElementDataFile[^\n]*\n", data)
        end = match.end() if match else len(data)
        return data[:end], data[end:]
    if fmt.startswith(("nrrd", "nhdr")):
        end = data.find(b"\n\n")
        return (data, b"") if end < 0 else (data[: end + 1], data[end + 1:])
    if fmt == "vtk-legacy":
        match = re.search(rb"LOOKUP_TABLE[^\n]*\n", data)
        end = match.end() if match else len(data)
        return data[:end], data[end:]
    return data, b""


def _token(rng: random.Random, tokens: list[str], root: Path) -> str:
    token = rng.choice(tokens)
    return token.replace(SENTINEL, str(root / "SENTINEL.raw"))


def _value_for(key: str, old: str, rng: random.Random, root: Path) -> str:
    """A hostile value for a header field, chosen by what the field holds."""
    low = key.lower()
    if any(word in low for word in ("file", "datafile")):
        return _token(rng, PATH_TOKENS, root)
    if "type" in low or low == "descr":
        return _token(rng, TYPE_TOKENS, root)
    if "encoding" in low:
        return _token(rng, ENCODING_TOKENS, root)
    numbers = old.replace("(", " ").replace(")", " ").replace(",", " ").split()
    if len(numbers) > 1 and rng.random() < 0.5:  # one component of a tuple at its edge
        numbers[rng.randrange(len(numbers))] = _token(rng, NUMBER_TOKENS, root)
        return " ".join(numbers)
    pool = rng.choice([NUMBER_TOKENS, TUPLE_TOKENS, NUMBER_TOKENS + PATH_TOKENS])
    return _token(rng, pool, root)


def mutate_text_lines(text: str, sep: str, rng: random.Random, root: Path) -> tuple[str, str]:
    """Change, delete, duplicate, reorder or add ``key<sep>value`` lines of a text header."""
    lines = text.split("\n")
    sep = sep if sep.strip() else " "  # VTK legacy: "KEYWORD value ..."
    mark = sep.strip() or " "
    fields = [n for n, line in enumerate(lines) if mark in line.strip()]
    op = rng.choice(["value"] * 6 + ["delete", "duplicate", "swap", "insert", "key", "case"])
    if not fields:
        op = "insert"
    n = rng.choice(fields) if fields else 0
    if op == "value":
        key, _, old = lines[n].partition(mark)
        new = _value_for(key, old, rng, root)
        lines[n] = f"{key.rstrip()}{sep}{new}"
        return "\n".join(lines), f"{key.strip()} = {new[:40]!r}"
    if op == "delete":
        gone = lines.pop(n)
        return "\n".join(lines), f"delete {gone[:30]!r}"
    if op == "duplicate":
        key, _, old = lines[n].partition(mark)
        lines.insert(n + 1, f"{key.rstrip()}{sep}{_value_for(key, old, rng, root)}")
        return "\n".join(lines), f"duplicate {key.strip()!r}"
    if op == "swap" and len(fields) > 1:
        a, b = rng.sample(fields, 2)
        lines[a], lines[b] = lines[b], lines[a]
        return "\n".join(lines), "swap two lines"
    if op == "key":
        key, _, old = lines[n].partition(mark)
        lines[n] = f"{key.strip()}{rng.choice(['', 'x', '!', ' ', '='])}{sep}{old.strip()}"
        return "\n".join(lines), f"mangle key {key.strip()!r}"
    if op == "case":
        lines[n] = lines[n].swapcase()
        return "\n".join(lines), "swap case"
    key = rng.choice(["DimSize", "ElementSpacing", "HeaderSize", "ElementDataFile", "Offset",
                      "sizes", "spacings", "data file", "byte skip", "line skip", "encoding",
                      "type", "space directions", "ElementNumberOfChannels", "NDims",
                      "dimension", "CompressedData", "endian"])
    value = _value_for(key, "", rng, root)
    lines.insert(rng.randrange(1, max(2, len(lines))), f"{key}{sep}{value}")
    return "\n".join(lines), f"insert {key!r}"


# --------------------------------------------------------------------------- byte level
def byte_level(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """Format-blind changes to one file: bit flips, interesting numbers, cuts, insertions."""
    files = _files(folder)
    target = _main_file(folder, seed) if rng.random() < 0.6 else rng.choice(files)
    data = bytearray(target.read_bytes())
    op = rng.choice(["flip", "flip", "byte", "int", "int", "float", "truncate", "extend",
                     "delete", "insert", "duplicate", "zero"])
    where = rng.randrange(max(1, len(data)))
    if op == "flip" and data:
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
    elif op == "byte" and data:
        data[where] = rng.choice([0, 0xFF, 0x7F, 0x80, 0x20, 0x0A, 0x30, 0x39])
    elif op == "int":
        width, fmt = rng.choice([(2, "h"), (2, "H"), (4, "i"), (4, "I"), (8, "q"), (8, "Q")])
        value = rng.choice(INTERESTING_INTS)
        limit = 2 ** (8 * width)
        value = value % limit
        if fmt.islower() and value >= limit // 2:
            value -= limit
        packed = struct.pack(rng.choice("<>") + fmt, value)
        data[where:where + width] = packed
    elif op == "float":
        width, fmt = rng.choice([(4, "f"), (8, "d")])
        value = rng.choice(INTERESTING_FLOATS)
        try:
            packed = struct.pack(rng.choice("<>") + fmt, value)
        except OverflowError:
            packed = struct.pack("<" + fmt, float("inf"))
        data[where:where + width] = packed
    elif op == "truncate":
        del data[where:]
    elif op == "extend":
        data += rng.choice([b"\0", b"\xff", b"A", b"\n"]) * rng.choice([1, 7, 512, 70000])
    elif op == "delete":
        del data[where:where + rng.randint(1, 64)]
    elif op == "insert":
        data[where:where] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
    elif op == "duplicate":
        data[where:where] = data[where:where + rng.randint(1, 256)]
    else:
        data[where:where + rng.randint(1, 512)] = b"\0" * rng.randint(1, 512)
    target.write_bytes(bytes(data))
    return f"bytes {op} @{where} of {target.name}"


# --------------------------------------------------------------------------- structure aware
def text_header(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """MetaImage / NRRD / VTK header fields."""
    header_file = _main_file(folder, seed)
    data = header_file.read_bytes()
    head, rest = _split_text_header(data, seed.fmt)
    sep = " = " if seed.fmt in ("mha", "mhd") else (": " if seed.fmt != "vtk-legacy" else " ")
    text, what = mutate_text_lines(head.decode("latin-1"), sep, rng, root)
    header_file.write_bytes(text.encode("latin-1", "replace") + rest)
    return what


def json_fields(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """The JSON sidecar: hostile values for its keys, nesting, huge numbers."""
    sidecar = folder / seed.main
    try:
        fields = json.loads(sidecar.read_text())
        if not isinstance(fields, dict):
            raise ValueError("not an object")
    except (ValueError, OSError, RecursionError):  # an earlier mutation broke it already
        return byte_level(folder, seed, rng, root)
    key = rng.choice([*fields, "data_file", "shape", "dtype", "extra"])
    choice = rng.randrange(12)
    if choice == 0:
        deep = "[" * 5000 + "]" * 5000
        text = sidecar.read_text().replace(json.dumps(fields.get(key, 0)), deep, 1)
        sidecar.write_text(text)
        return f"{key}: nested 5000 deep"
    if choice == 1:
        text = json.dumps(fields).replace("0.5", "1" * 5000, 1)
        sidecar.write_text(text)
        return "a 5000-digit number"
    if choice == 2:
        sidecar.write_text(json.dumps(fields)[: rng.randrange(1, 40)])
        return "truncated JSON"
    if choice == 3:
        sidecar.write_text(json.dumps(fields) + rng.choice(["NaN", "]", "{}", "\0"]))
        return "trailing junk"
    values = [0, -1, 1, 2**70, -(2**63), 1e30, 1e-320, float("nan"), float("inf"), None, True,
              "uint16", "abc", "\0", [], [6, 5], [6, 5, 4, 1], [6, 5, 4.0], [6.5, 5, 4],
              [2000, 2000, 2000], [0, 5, 4], [1e-320, 1, 1], [[1, 2, 3]], {"a": 1},
              [2**70, 1, 1], ["6", "5", "4"], "../../SENTINEL.raw", str(root / "SENTINEL.raw"),
              "/etc/passwd", "/dev/zero", "big", "C", "x" * 10000, [float("inf"), 1, 1],
              "|O", "<c16", "(2,)<u2", "f4,f4", "S1000000000", "V16"]
    value = rng.choice(values)
    fields[key] = value
    sidecar.write_text(json.dumps(fields))  # NaN/Infinity come out as bare tokens: allowed too
    return f"{key} = {json.dumps(value)[:40]}"


def npy_header(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """The dict text of an ``.npy`` header (in an .npy file or an .npz member)."""
    shapes = ["(6, 5, 4)", "(-6, 5, 4)", "(1180591620717411303424, 1, 1)", "(2000, 2000, 2000)",
              "(0, 5, 4)", "(6, 5)", "(6, 5, 4, 1)", "(120,)", "()", "(6, 5, 4", "[6, 5, 4]",
              "(6.0, 5, 4)", "('6', 5, 4)", "(2**70, 1, 1)", "(9223372036854775807, 2, 1)",
              "((((((((((((((((((((((((((((((((", "None"]
    descrs = ["'<u2'", "'>u2'", "'|O'", "'<c16'", "'<i8'", "'<f2'", "'S10'", "'<U3'",
              "[('a', '<f4')]", "'(2,)<f4'", "'|b1'", "'<M8[s]'", "'bogus'", "3", "'<f8'"]
    orders = ["False", "True", "0", "1", "'yes'", "None"]
    parts = {"descr": "'<u2'", "fortran_order": "True", "shape": "(6, 5, 4)"}
    key = rng.choice(list(parts))
    parts[key] = rng.choice({"descr": descrs, "fortran_order": orders, "shape": shapes}[key])
    change = (key, parts[key])
    header = "{" + ", ".join(f"'{k}': {v}" for k, v in parts.items()) + ", }"
    if rng.random() < 0.2:
        header = header[: rng.randrange(len(header))]  # unbalanced
    body = header.encode("latin-1", "replace")
    pad = (-(10 + len(body) + 1)) % 64
    npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(body) + pad + 1) + body + b" " * pad + b"\n"
    npy += bytes(DATA_BYTES)
    what = f"npy header {change[0]} = {change[1][:30]}"
    target = folder / seed.main
    if seed.fmt == "npy":
        target.write_bytes(npy)
        return what
    return _replace_npz_member(target, "data.npy", npy, rng) + f"; {what}"


def _replace_npz_member(path: Path, name: str, payload: bytes, rng: random.Random) -> str:
    with zipfile.ZipFile(path) as old:
        members = {info.filename: old.read(info) for info in old.infolist()}
    members[name] = payload
    method = rng.choice([zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED])
    with zipfile.ZipFile(path, "w", compression=method) as new:
        for member, content in members.items():
            new.writestr(member, content)
    return f"npz member {name}"


def npz_structure(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """Zip-level changes: members removed, added, renamed, not .npy, bombs."""
    path = folder / seed.main
    with zipfile.ZipFile(path) as old:
        members = {info.filename: old.read(info) for info in old.infolist()}
    op = rng.choice(["drop", "rename", "extra", "notnpy", "geometry", "bomb", "empty"])
    if op == "drop" and members:
        members.pop(rng.choice(list(members)))
    elif op == "rename" and "data.npy" in members:
        members[rng.choice(["x.npy", "data", "data.npy/", "../data.npy", "volume.npy"])] = \
            members.pop("data.npy")
    elif op == "extra":
        members[rng.choice(["other.npy", "volume.npy", "data.npy"])] = members.get(
            "data.npy", b"")
    elif op == "notnpy":
        members["data.npy"] = rng.choice([b"", b"hello", b"PK\x03\x04", b"\x93NUMPY"])
    elif op == "geometry":
        import numpy as np

        value = rng.choice([np.array([1e-320, 1, 1]), np.array([np.nan] * 3), np.zeros(7),
                            np.array(["a", "b", "c"]), np.array([[1.0, 2.0, 3.0]] * 3),
                            np.array(2**70, dtype=object)])
        from io import BytesIO

        buf = BytesIO()
        np.save(buf, value, allow_pickle=True)
        members[rng.choice(["spacing.npy", "origin.npy"])] = buf.getvalue()
    elif op == "bomb":
        header = b"{'descr': '<u2', 'fortran_order': True, 'shape': (6, 5, 4), }"
        pad = (-(10 + len(header) + 1)) % 64
        npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header) + pad + 1) + header \
            + b" " * pad + b"\n" + bytes(DATA_BYTES) + bytes(rng.choice([1, 10**6, 5 * 10**7]))
        members["data.npy"] = npy
    else:
        members = {}
    method = rng.choice([zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED])
    with zipfile.ZipFile(path, "w", compression=method) as new:
        for member, content in members.items():
            new.writestr(member, content)
    return f"npz {op}"


def compressed_stream(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """Bombs, truncation, corruption and the wrong compressor in compressed data."""
    if seed.fmt == "nhdr-bzip2":
        path, head, body = folder / "v.raw.bz2", b"", (folder / "v.raw.bz2").read_bytes()
        codec = "bz2"
    elif seed.fmt == "nifti-gz":
        path, head, body = folder / seed.main, b"", (folder / seed.main).read_bytes()
        codec = "gzip"
    else:  # attached gzip NRRD
        path = folder / seed.main
        head, body = _split_text_header(path.read_bytes(), seed.fmt)
        codec = "gzip"
    compress = (lambda b: gzip.compress(b, mtime=0)) if codec == "gzip" else bz2.compress
    op = rng.choice(["bomb", "bomb", "truncate", "corrupt", "wrong", "concat", "empty", "raw",
                     "short"])
    if op == "bomb":
        size = rng.choice([10**6, 10**7, 6 * 10**7])
        plain = gzip.decompress(body) if codec == "gzip" and seed.fmt == "nifti-gz" else b""
        body = compress(plain + bytes(size))
    elif op == "truncate":
        body = body[: rng.randrange(max(1, len(body)))]
    elif op == "corrupt" and body:
        data = bytearray(body)
        for _ in range(rng.randint(1, 6)):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
        body = bytes(data)
    elif op == "wrong":
        plain = bytes(DATA_BYTES)
        body = bz2.compress(plain) if codec == "gzip" else gzip.compress(plain)
    elif op == "concat":
        body = body + body
    elif op == "empty":
        body = b""
    elif op == "raw":
        body = zlib.compress(bytes(DATA_BYTES))  # a zlib stream without the gzip wrapper
    else:
        body = compress(bytes(DATA_BYTES - 2))
    path.write_bytes(head + body)
    return f"{codec} stream {op}"


#: (offset, struct format) of NIfTI-1 header fields worth breaking.
NIFTI_FIELDS = {
    "sizeof_hdr": (0, "i"), "dim0": (40, "h"), "dim1": (42, "h"), "dim2": (44, "h"),
    "dim3": (46, "h"), "dim4": (48, "h"), "dim5": (50, "h"), "intent_code": (68, "h"),
    "datatype": (70, "h"), "bitpix": (72, "h"), "pixdim0": (76, "f"), "pixdim1": (80, "f"),
    "pixdim2": (84, "f"), "pixdim3": (88, "f"), "vox_offset": (108, "f"),
    "scl_slope": (112, "f"), "scl_inter": (116, "f"), "xyzt_units": (123, "B"),
    "qform_code": (252, "h"), "sform_code": (254, "h"), "quatern_b": (256, "f"),
    "quatern_c": (260, "f"), "quatern_d": (264, "f"), "qoffset_x": (268, "f"),
    "srow_x0": (280, "f"), "srow_x3": (292, "f"), "srow_y1": (300, "f"), "srow_z2": (320, "f"),
    "magic": (344, "4s"),
}


def nifti_fields(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """A NIfTI-1 header field set to an edge value (inside the gzip stream for .nii.gz)."""
    path = folder / seed.main
    raw = path.read_bytes()
    packed = seed.fmt == "nifti-gz"
    data = bytearray(gzip.decompress(raw) if packed else raw)
    name = rng.choice(list(NIFTI_FIELDS))
    offset, fmt = NIFTI_FIELDS[name]
    if fmt == "4s":
        value = rng.choice([b"n+1\0", b"ni1\0", b"n+2\0", b"\0\0\0\0", b"abcd"])
    elif fmt == "f":
        value = rng.choice(INTERESTING_FLOATS + [1e10, 2.0, 352.0, 351.0, 1e9])
    elif fmt == "B":
        value = rng.choice([0, 1, 2, 3, 8, 16, 24, 7, 255, 0x0A, 0x3F])
    else:
        bound = 2 ** (8 * struct.calcsize(fmt) - 1)
        value = rng.choice([v for v in INTERESTING_INTS + [-1, -32768, 16, 64, 128, 255, 1536,
                                                           2304, 512, 1024, 7, 8, 4, 32767]
                            if -bound <= v < bound])
    data[offset:offset + struct.calcsize(fmt)] = struct.pack("<" + fmt, value)
    path.write_bytes(gzip.compress(bytes(data), mtime=0) if packed else bytes(data))
    return f"nifti {name} = {value!r}"


DICOM_CHANGES: list[tuple[str, str, list[object]]] = [
    ("Rows", "US", [0, 1, 65535, None]),
    ("Columns", "US", [0, 1, 65535, None]),
    ("PixelSpacing", "DS", ["abc", "1", "0\\0", "1e-320\\1", "nan\\1", "inf\\inf", "-1\\1",
                            "1\\1\\1", None, "1e400\\1"]),
    ("ImagePositionPatient", "DS", ["0\\0", "abc\\0\\0", "nan\\0\\0", "inf\\0\\0", None,
                                    "1e300\\0\\0", "0\\0\\0\\0"]),
    ("ImageOrientationPatient", "DS", ["0\\0\\0\\0\\0\\0", "1\\0\\0\\1\\0\\0", "1\\0\\0",
                                       "nan\\0\\0\\0\\1\\0", None, "a\\b\\c\\d\\e\\f"]),
    ("SliceThickness", "DS", ["abc", "0", "-1", "1e-320", "nan", "inf", None, "1\\2"]),
    ("SpacingBetweenSlices", "DS", ["abc", "0", "nan", "1e-320", "1\\2"]),
    ("RescaleSlope", "DS", ["abc", "0", "inf", "nan", "1e38", "-1e38", "1\\2", None, "1e-320"]),
    ("RescaleIntercept", "DS", ["abc", "inf", "nan", "1e300", "0.5", "-1e10", "1\\2", None]),
    ("NumberOfFrames", "IS", ["2", "0", "abc", "-1", "99999999"]),
    ("SamplesPerPixel", "US", [3, 0, 2]),
    ("BitsAllocated", "US", [0, 1, 7, 8, 12, 32, 64, 65535]),
    ("BitsStored", "US", [0, 1, 17, 64]),
    ("HighBit", "US", [0, 63, 15, 65535]),
    ("PixelRepresentation", "US", [1, 2, 65535]),
    ("PhotometricInterpretation", "CS", ["RGB", "PALETTE COLOR", "YBR_FULL", "", "MONOCHROME1"]),
    ("SeriesInstanceUID", "UI", ["1.2.3", "", None]),
    ("PixelData", "OW", [b"", b"\0\0", b"\0" * 10**6]),
    ("Modality", "CS", ["\0" * 5000]),
]


def dicom_tags(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """One slice's tag set to a hostile value (or deleted), or its VR bytes replaced."""
    import pydicom
    from pydicom import config

    files = [p for p in _files(folder) if p.name.startswith("IM")]
    target = rng.choice(files)
    if rng.random() < 0.2:  # an unknown or wrong VR, patched in the bytes
        data = bytearray(target.read_bytes())
        tags = [m.start() for m in re.finditer(rb"(DS|US|IS|CS|UI)", bytes(data[132:]))]
        if tags:
            where = 132 + rng.choice(tags)
            vr = rng.choice([b"ZZ", b"SQ", b"OB", b"UN", b"\0\0", b"US", b"FD", b"AT"])
            data[where:where + 2] = vr
            target.write_bytes(bytes(data))
            return f"dicom VR -> {vr!r} in {target.name}"
    keyword, vr, values = rng.choice(DICOM_CHANGES)
    value = rng.choice(values)
    saved = (config.settings.reading_validation_mode, config.settings.writing_validation_mode)
    config.settings.reading_validation_mode = config.IGNORE
    config.settings.writing_validation_mode = config.IGNORE
    try:
        ds = pydicom.dcmread(target)
        if value is None:
            if keyword in ds:
                del ds[keyword]
        else:
            tag = pydicom.tag.Tag(pydicom.datadict.tag_for_keyword(keyword))
            if isinstance(value, int):
                ds.add_new(tag, vr, value)
            else:  # written as raw bytes, so values pydicom would refuse to build go in as-is
                raw = value if isinstance(value, bytes) else value.encode("latin-1")
                if len(raw) % 2:
                    raw += b" "
                ds._dict[tag] = pydicom.dataelem.RawDataElement(tag, vr, len(raw), raw, 0,
                                                                False, True)
        ds.save_as(target)
    finally:
        config.settings.reading_validation_mode, config.settings.writing_validation_mode = saved
    return f"dicom {keyword} = {value!r:.30} in {target.name}"


def tiff_description(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """A rewritten TIFF with a hostile ImageJ description (spacing, unit, images, axes)."""
    import numpy as np
    import tifffile

    from .seeds import SPACING, ramp

    stack = np.ascontiguousarray(ramp().transpose(2, 1, 0))
    key = rng.choice(["spacing", "unit", "images", "slices", "channels", "frames", "hyperstack",
                      "loop", "min", "max", "finterval"])
    value = rng.choice(["abc", "nan", "inf", "-1", "0", "1e-320", "1e400", "", "1" * 5000,
                        "2", "1000000", "\\u0000", "true", "[1,2]"])
    lines = ["ImageJ=1.11a", "images=4", "slices=4", "unit=um", f"spacing={SPACING[2]}",
             "axes=ZYX"]
    lines = [line for line in lines if not line.startswith(key + "=")] + [f"{key}={value}"]
    if rng.random() < 0.3:
        rng.shuffle(lines)
    description = "\n".join(lines) + "\n"
    resolution = rng.choice([(2.0, 1 / SPACING[1]), (0.0, 1.0), (1e-320, 1.0),
                             ((1, 0), (1, 0)), ((2**32 - 1, 1), (1, 2**32 - 1))])
    tifffile.imwrite(folder / seed.main, stack, description=description, metadata=None,
                     resolution=resolution, photometric="minisblack")
    return f"ImageJ {key}={value[:20]} resolution={resolution}"


def tiff_ome(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """An OME-TIFF whose OME-XML puts planes in another file (a hostile name)."""
    import numpy as np
    import tifffile

    from .seeds import ramp

    other = _token(rng, PATH_TOKENS, root).replace('"', "").replace("<", "").replace("&", "")
    size_z = rng.choice([8, 4, 1000000, 0])
    xml = (
        '<?xml version="1.0" encoding="UTF-8"?>'
        '<OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06" UUID="urn:uuid:1">'
        '<Image ID="Image:0"><Pixels ID="Pixels:0" DimensionOrder="XYZCT" Type="uint16" '
        f'SizeX="6" SizeY="5" SizeZ="{size_z}" SizeC="1" SizeT="1">'
        '<Channel ID="Channel:0:0" SamplesPerPixel="1"/>'
        f'<TiffData FirstZ="0" IFD="0" PlaneCount="4"><UUID FileName="{seed.main}">urn:uuid:1'
        '</UUID></TiffData>'
        f'<TiffData FirstZ="4" IFD="0" PlaneCount="4"><UUID FileName="{other}">urn:uuid:2'
        '</UUID></TiffData></Pixels></Image></OME>'
    )
    stack = np.ascontiguousarray(ramp().transpose(2, 1, 0))
    tifffile.imwrite(folder / seed.main, stack, description=xml, metadata=None,
                     photometric="minisblack")
    return f"OME FileName {other[:40]!r} SizeZ={size_z}"


def file_layout(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """Data files removed, emptied, swapped for folders or symbolic links out of the folder."""
    # Never the main file: the user names it, so following it anywhere is their choice.
    files = [p for p in _files(folder) if p != folder / seed.main]
    if not files:
        return byte_level(folder, seed, rng, root)
    target = rng.choice(files)
    op = rng.choice(["symlink", "symlink", "remove", "empty", "folder", "fifo"])
    target.unlink()
    if op == "symlink":
        dest = rng.choice([root / "SENTINEL.raw", Path("/etc/passwd"), Path("/dev/zero"),
                           Path("../../SENTINEL.raw")])
        target.symlink_to(dest)
        return f"{target.name} -> symlink to {dest}"
    if op == "empty":
        target.write_bytes(b"")
    elif op == "folder":
        target.mkdir()
    elif op == "fifo":  # opening it for reading would block: a reader must refuse it first
        os.mkfifo(target)
    return f"{target.name}: {op}"


# --------------------------------------------------------------------------- Zarr stores
#: Hostile JSON values for any field of a Zarr or OME-Zarr metadata file.
JSON_VALUES: list[object] = [
    0, -1, 1, 2**70, -(2**63), 2**64, 1e30, 1e-320, None, True, "abc", "\0", [], {}, [6, 5],
    [6, 5, 4, 1], [6.5, 5, 4], [2000, 2000, 2000], [0, 5, 4], [-6, 5, 4], [2**70, 1, 1],
    [1e-320, 1, 1], [1e300, 1, 1], [1, 1, 1], [100000, 100000, 100000], [1048577, 1, 1],
    ["6", "5", "4"], [[1, 2, 3]], {"a": 1}, "../../SENTINEL.raw", "/etc/passwd", "/dev/zero",
    "x" * 10000, "|O", "<c16", "float128", "bogus", "uint16", "<u2", "int64", "bool",
    "complex64", "string", "S10", "V8", "r16", ".", "/", "..", "../other", "0", "1",
]
#: Field names worth aiming at (Zarr v2 and v3 array and group metadata, NGFF, splinecast's).
JSON_KEYS = [
    "shape", "chunks", "chunk_shape", "data_type", "dtype", "fill_value", "order", "filters",
    "compressor", "codecs", "name", "configuration", "zarr_format", "node_type", "separator",
    "dimension_separator", "dimension_names", "chunk_key_encoding", "chunk_grid", "level",
    "typesize", "cname", "clevel", "blocksize", "endian", "index_codecs", "index_location",
    "multiscales", "datasets", "path", "axes", "type", "unit", "scale", "translation",
    "coordinateTransformations", "version", "ome", "splinecast", "brick", "ghost", "value_range",
    "tables", "complete_chunks", "source_metadata", "attributes", "id", "checksum",
    "kind", "degree", "levels", "chunk", "window", "spacing", "origin", "model", "wavelet",
]


def _json_paths(value: object, prefix: tuple = ()) -> list[tuple]:
    """Every path (keys and indices) into parsed JSON, parents before children."""
    paths = [prefix]
    if isinstance(value, dict):
        for key, child in value.items():
            paths += _json_paths(child, (*prefix, key))
    elif isinstance(value, list):
        for index, child in enumerate(value[:8]):
            paths += _json_paths(child, (*prefix, index))
    return paths


def _metadata_files(folder: Path) -> list[Path]:
    names = ("zarr.json", ".zarray", ".zattrs", ".zgroup")
    return [p for p in _files(folder) if p.name in names]


def zarr_metadata(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """A Zarr metadata file (``zarr.json``, ``.zarray``, ``.zattrs``, ``.zgroup``): a field set
    to a hostile value or deleted, or the JSON itself broken (truncated, junk, NaN, deep,
    5000-digit numbers, not UTF-8)."""
    files = _metadata_files(folder)
    if not files:
        return byte_level(folder, seed, rng, root)
    # The root and level-0 metadata matter most: they are read on every open.
    target = rng.choice(files[:3] + files) if rng.random() < 0.5 else rng.choice(files)
    text = target.read_text(errors="replace")
    name = target.relative_to(folder)
    try:
        doc = json.loads(text)
    except ValueError:
        return byte_level(folder, seed, rng, root)
    op = rng.choice(["field"] * 8 + ["delete", "delete", "aimed", "aimed", "aimed", "syntax",
                                      "deep", "digits", "nan"])
    if op == "syntax":
        cut = rng.choice([text[: rng.randrange(1, max(2, len(text)))], text + "}",
                          text.replace("{", "[", 1), "\xff\xfe" + text, "", "null", "[]", "7"])
        target.write_bytes(cut.encode("utf-8", "surrogateescape") if not cut.startswith("\xff")
                           else b"\xff\xfe" + text.encode())
        return f"{name}: broken JSON"
    if op == "deep":
        target.write_text(text.replace("[", "[" * 3000, 1).replace("]", "]" * 3000, 1))
        return f"{name}: nested 3000 deep"
    if op == "digits":
        target.write_text(re.sub(r"\b\d+\b", "9" * 5000, text, count=1))
        return f"{name}: a 5000-digit number"
    if op == "nan":
        target.write_text(re.sub(r"-?\b\d+(\.\d+)?\b", rng.choice(["NaN", "Infinity", "1e999"]),
                                 text, count=1))
        return f"{name}: a non-finite number"
    paths = [p for p in _json_paths(doc) if p]
    if op == "aimed":
        aimed = [p for p in paths if isinstance(p[-1], str) and p[-1] in JSON_KEYS]
        paths = aimed or paths
    if not paths:
        return byte_level(folder, seed, rng, root)
    path = rng.choice(paths)
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    if op == "delete":
        del parent[path[-1]]
        what = f"delete {'/'.join(map(str, path))[:60]}"
    else:
        value = rng.choice(JSON_VALUES)
        if isinstance(value, str):
            value = value.replace("@SENTINEL@", str(root / "SENTINEL.raw"))
        parent[path[-1]] = value
        what = f"{'/'.join(map(str, path))[:60]} = {json.dumps(value)[:40]}"
    target.write_text(json.dumps(doc))
    return f"{name}: {what}"


def zarr_chunks(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """A chunk (or shard) file: truncated, emptied, replaced by another chunk, by a compression
    bomb (a zstd frame declaring huge content), by zeros, or a shard index pointing anywhere."""
    chunks = [p for p in _files(folder) if p not in _metadata_files(folder)]
    if not chunks:
        return byte_level(folder, seed, rng, root)
    target = rng.choice(chunks)
    data = target.read_bytes()
    op = rng.choice(["truncate", "empty", "swap", "zstd-bomb", "zstd-bomb", "zeros", "index",
                     "index", "junk", "huge"])
    if op == "truncate":
        data = data[: rng.randrange(max(1, len(data)))]
    elif op == "empty":
        data = b""
    elif op == "swap":
        data = rng.choice(chunks).read_bytes()
    elif op == "zstd-bomb":  # frame header: magic, single segment, 8-byte content size
        size = rng.choice([2**40, 2**62, 10**9, 6 * 10**7, 2**31])
        frame = b"\x28\xb5\x2f\xfd\xe0" + struct.pack("<Q", size) + b"\x01\x00\x00"
        data = frame if rng.random() < 0.5 else frame + data[len(frame):]
    elif op == "zeros":
        data = bytes(len(data))
    elif op == "index":  # the last 16 * n + 4 bytes of a shard are its index (+ crc32c)
        if len(data) >= 20:
            at = len(data) - 4 - 16 * rng.randint(1, max(1, (len(data) - 4) // 16 // 4))
            value = rng.choice(INTERESTING_INTS)
            data = data[:at] + struct.pack("<Q", value % 2**64) + data[at + 8:]
    elif op == "junk":
        data = bytes(rng.randrange(256) for _ in range(rng.choice([1, 16, 4096])))
    else:
        data = data + bytes(rng.choice([10**6, 5 * 10**7]))
    target.write_bytes(data)
    return f"chunk {target.relative_to(folder)}: {op}"


#: Sizes a hostile chunk claims or inflates to (a gibibyte from a few kilobytes of RLE blocks).
BOMB_SIZES = [2**30, 2**26, 2**20 + 1, 129, 127, 0]
#: Values for the 8-byte fields of a shard index and a zstd frame's content size.
SIZE_VALUES = [0, 1, 127, 128, 129, 2**31, 2**32, 2**40, 2**63, 2**64 - 1, 2**64 - 2]


def _chunk_files(folder: Path) -> list[Path]:
    meta = set(_metadata_files(folder))
    return [p for p in _files(folder) if p not in meta]


def _zstd_mutation(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """A zstd frame's content-size flag and field, reserved bits, window, trailing frames, or
    an RLE bomb in its place."""
    from .codecs import (
        zstd_frame_info,
        zstd_rle,
        zstd_with_size,
        zstd_without_size,
    )

    op = rng.choice(["no-size", "size", "size", "bomb", "bomb", "reserved", "window", "append",
                     "skippable"])
    if op == "no-size":
        out = zstd_without_size(data)
        return (out, op) if out is not None else (zstd_rle(2**30, declare=False), "bomb")
    if op == "size":
        value = rng.choice(SIZE_VALUES + [len(data), 2 * len(data)])
        out = zstd_with_size(data, value)
        return (out, f"size {value}") if out is not None else (data, "size (not zstd)")
    if op == "bomb":
        size = rng.choice(BOMB_SIZES[:-1])
        declare = rng.choice([True, False, rng.choice(SIZE_VALUES)])
        return zstd_rle(size, declare=declare), f"rle bomb {size} declaring {declare}"
    info = zstd_frame_info(data)
    if info is None:
        return zstd_rle(2**30, declare=False), "bomb (not zstd)"
    out = bytearray(data)
    if op == "reserved":
        out[4] |= 0x08
    elif op == "window" and not info["single"]:
        out[5] = rng.choice([0xFF, 0xF8, 0x00, 0x88])
    elif op == "append":
        out += rng.choice([data, zstd_rle(2**30, declare=False), b"\x28\xb5\x2f\xfd", b"\0" * 7])
    else:  # a skippable frame claiming more bytes than follow
        out = bytearray(struct.pack("<II", 0x184D2A50, rng.choice([0, 8, 2**32 - 1]))) + out
    return bytes(out), op


def _blosc_mutation(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """A blosc header field set to an edge value, or a memcpyed chunk whose header lies."""
    from .codecs import BLOSC_FIELDS, blosc_memcpy, blosc_set

    if rng.random() < 0.25:
        claim = rng.choice([2**31 - 1, 2**30, len(data) * 4, 0])
        return blosc_memcpy(data[16:] or b"\0", nbytes=claim), f"memcpyed claiming {claim}"
    field = rng.choice(list(BLOSC_FIELDS))
    value = rng.choice([0, 1, 2, 3, 0x7F, 0xFF, 0x10, 2**31 - 1, 2**31, 2**32 - 1,
                        len(data), len(data) + 1, len(data) - 1, 2**20, 128, 129])
    return blosc_set(data, **{field: value}), f"blosc {field} = {value}"


def zarr_codecs(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """A chunk changed with knowledge of its codec: a zstd frame's content size (declared,
    left out, lying), reserved bits and trailing frames, RLE bombs of up to a gibibyte;
    blosc header fields; deflate bombs; in a shard, its index entries (crc32c recomputed),
    checksum, and any of the former inside one of its inner chunks."""
    from .codecs import array_meta, deflate_bomb, is_blosc, join_shard, shard_layout, split_shard

    chunks = _chunk_files(folder)
    if not chunks:
        return byte_level(folder, seed, rng, root)
    target = rng.choice(chunks)
    data = target.read_bytes()
    name = target.relative_to(folder)
    meta = array_meta(target) or {}
    layout = shard_layout(meta) if meta.get("zarr_format") == 3 else None

    def inner(chunk: bytes) -> tuple[bytes, str]:
        if chunk.startswith(b"\x28\xb5\x2f\xfd") or rng.random() < 0.2:
            return _zstd_mutation(chunk, rng)
        if is_blosc(chunk):
            return _blosc_mutation(chunk, rng)
        if chunk[:1] == b"\x78" or chunk[:2] == b"\x1f\x8b":
            size = rng.choice([2**24, 2**20, 129])
            return deflate_bomb(size, gzip=chunk[:2] == b"\x1f\x8b"), f"deflate bomb {size}"
        return _zstd_mutation(chunk, rng)

    if layout is None:
        data, what = inner(data)
        target.write_bytes(data)
        return f"chunk {name}: {what}"
    try:
        parts = split_shard(data, layout["count"], layout["at_end"], layout["checksum"])
    except (struct.error, ValueError):
        return f"chunk {name}: not a shard ({byte_level(folder, seed, rng, root)})"
    full = [n for n, c in enumerate(parts) if c is not None] or list(range(len(parts)))
    n = rng.choice(full)
    op = rng.choice(["inner", "inner", "inner", "entry", "entry", "crc", "swap", "empty"])
    entries: dict[int, tuple[int, int]] = {}
    if op == "inner":
        parts[n], what = inner(parts[n] or b"")
        op = f"inner chunk {n}: {what}"
    elif op == "entry":
        offset = rng.choice(SIZE_VALUES + [len(data), len(data) - 1, 0])
        length = rng.choice(SIZE_VALUES + [len(parts[n] or b"") + 1])
        entries[n] = (offset, length) if rng.random() < 0.7 else (2**64 - 1, length)
        op = f"index entry {n} = {entries[n]}"
    elif op == "swap" and len(full) > 1:
        a, b = rng.sample(full, 2)
        parts[a], parts[b] = parts[b], parts[a]
        op = f"inner chunks {a} and {b} swapped"
    elif op == "empty":
        parts[n] = None
        op = f"inner chunk {n} emptied"
    shard = join_shard(parts, layout["at_end"], layout["checksum"], entries)
    if op == "crc" and layout["checksum"]:
        shard = bytearray(shard)
        shard[-1 if layout["at_end"] else 16 * layout["count"]] ^= 0x5A
        shard = bytes(shard)
    target.write_bytes(shard)
    return f"shard {name}: {op}"


# --------------------------------------------------------------------------- VTK XML
VTI_ATTRIBUTES: dict[str, list[str]] = {
    "WholeExtent": ["0 5 0 4 0 3", "0 -1 0 4 0 3", "0 1999 0 1999 0 1999", "0 1e30 0 4 0 3",
                    "0 9223372036854775807 0 0 0 0", "5 0 0 4 0 3", "0 5 0 4", "a b c d e f",
                    "0 5 0 4 0 3 0", "-2147483648 2147483647 0 0 0 0", "0 65535 0 65535 0 65535",
                    "0 0 0 0 0 0", "1 6 1 5 1 4"],
    "Extent": ["0 5 0 4 0 3", "0 6 0 4 0 3", "0 -1 0 4 0 3", "0 1999 0 1999 0 1999", "1 6 1 5 1 4",
               "0 5 0 4", "0 5 0 4 0 300"],
    "Spacing": TUPLE_TOKENS, "Origin": TUPLE_TOKENS,
    "Direction": ["1 0 0 0 1 0 0 0 1", "0 0 0 0 0 0 0 0 0", "nan 0 0 0 1 0 0 0 1", "1 0 0",
                  "0 1 0 1 0 0 0 0 1", "1e308 0 0 0 1 0 0 0 1"],
    "type": ["Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Float32",
             "Float64", "String", "Bit", "IdType", "bogus", "", "ImageData", "PolyData",
             "StructuredGrid", "UnstructuredGrid"],
    "NumberOfComponents": ["0", "1", "2", "3", "4", "9", "-1", "65536", "2147483647",
                           "4294967296", "abc", "1e30"],
    "NumberOfTuples": ["0", "1", "120", "-1", "4294967296", "1e30"],
    "format": ["ascii", "binary", "appended", "bogus", ""],
    "encoding": ["raw", "base64", "bogus", ""],
    "header_type": ["UInt32", "UInt64", "UInt8", "Int64", "", "Float32"],
    "compressor": ["vtkZLibDataCompressor", "vtkLZ4DataCompressor", "vtkLZMADataCompressor",
                   "vtkBogusCompressor", ""],
    "byte_order": ["LittleEndian", "BigEndian", "Middle", ""],
    "offset": ["0", "1", "-1", "100000", "9223372036854775807", "18446744073709551616", "abc"],
    "version": ["0.1", "1.0", "2.2", "99.0", "abc"],
    "Name": ["values", "", "x" * 5000, "\x1b[31m"],
    "Scalars": ["values", "bogus", ""],
    "RangeMin": ["nan", "-1e308", "abc"], "RangeMax": ["inf", "1e308", "abc"],
}


def vti_attributes(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """An XML attribute of a ``.vti`` (VTKFile, ImageData, Piece, DataArray, AppendedData) set to
    a hostile value, removed, or an element duplicated or removed."""
    path = folder / seed.main
    data = path.read_bytes()
    appended = data.find(b"<AppendedData")
    head_end = appended if appended >= 0 else len(data)
    head = data[:head_end]
    found = [(m.start(1), m.end(1), m.group(0).split(b"=")[0].decode())
             for m in re.finditer(rb'\b(?:\w+)="([^"]*)"', head)]
    if appended >= 0:
        tag_end = data.find(b">", appended)
        found += [(m.start(1) + appended, m.end(1) + appended,
                   m.group(0).split(b"=")[0].decode())
                  for m in re.finditer(rb'\b(?:\w+)="([^"]*)"', data[appended:tag_end])]
    op = rng.choice(["value"] * 8 + ["remove", "element"])
    if op == "element":
        elements = [m for m in re.finditer(rb"<(PointData|CellData|DataArray|Piece)[^>]*>", head)]
        if elements:
            m = rng.choice(elements)
            if rng.random() < 0.5:
                data = data[:m.start()] + m.group(0) + data[m.start():]  # duplicated opening tag
                path.write_bytes(data)
                return f"duplicate <{m.group(1).decode()}>"
            data = data[:m.start()] + data[m.end():]
            path.write_bytes(data)
            return f"remove <{m.group(1).decode()}>"
    aimed = [f for f in found if f[2] in VTI_ATTRIBUTES]
    if not aimed:
        return byte_level(folder, seed, rng, root)
    start, end, name = rng.choice(aimed)
    if op == "remove":
        # Remove ' name="value"' entirely.
        at = data.rfind(b" ", 0, start)
        data = data[:at] + data[end + 1:]
        path.write_bytes(data)
        return f"remove {name}"
    value = rng.choice(VTI_ATTRIBUTES[name])
    if name in ("Spacing", "Origin"):
        value = value if " " in value else f"{value} 1 1"
    data = data[:start] + value.encode("latin-1", "replace") + data[end:]
    path.write_bytes(data)
    return f"{name}={value[:40]!r}"


def vti_sizes(folder: Path, seed: Seed, rng: random.Random, root: Path) -> str:
    """The binary size header of a ``.vti`` array (appended raw, or base64 inline): the byte
    count, or a compressed array's block count, block size, last block size, block sizes."""
    import base64

    path = folder / seed.main
    data = path.read_bytes()
    head = data[: data.find(b">", max(0, data.find(b"<VTKFile")))]
    width = 8 if b'header_type="UInt64"' in head else 4
    fmt = "<Q" if width == 8 else "<I"
    words = rng.choice([1, 1, 2, 3, 4])
    value = rng.choice(INTERESTING_INTS + [119, 120, 121, 239, 240, 241, 32768, 2**31, 2**32 - 240])
    packed = struct.pack(fmt, value % 2 ** (8 * width))
    raw_at = data.find(b"_", data.find(b"<AppendedData"))
    if data.find(b"<AppendedData") >= 0 and b'encoding="raw"' in data and raw_at >= 0:
        at = raw_at + 1 + width * (words - 1)
        data = data[:at] + packed + data[at + width:]
        path.write_bytes(data)
        return f"appended raw header word {words} = {value}"
    match = re.search(rb'format="binary"[^>]*>\s*([A-Za-z0-9+/=]+)', data) or re.search(
        rb'<AppendedData[^>]*>\s*_([A-Za-z0-9+/=]+)', data)
    if not match:
        return byte_level(folder, seed, rng, root)
    text = match.group(1)
    chunk = (width * 4 + 2) // 3 * 4
    try:
        header = bytearray(base64.b64decode(text[:chunk] + b"=" * (-len(text[:chunk]) % 4)))
    except ValueError:
        return byte_level(folder, seed, rng, root)
    at = width * (words - 1)
    header[at:at + width] = packed
    new = base64.b64encode(bytes(header))[:chunk]
    data = data[:match.start(1)] + new + text[len(new):] + data[match.end(1):]
    path.write_bytes(data)
    return f"base64 header word {words} = {value}"


Mutation = Callable[[Path, Seed, random.Random, Path], str]

#: Structure-aware mutations per format (byte-level and file-layout ones apply to every format).
STRUCTURED: dict[str, list[Mutation]] = {
    "npy": [npy_header],
    "npz": [npy_header, npz_structure],
    "npz-deflate": [npy_header, npz_structure],
    "mhd": [text_header, text_header],
    "mha": [text_header, text_header],
    "nhdr": [text_header, text_header],
    "nhdr-bzip2": [text_header, compressed_stream],
    "nrrd-raw": [text_header, text_header],
    "nrrd-gzip": [text_header, compressed_stream],
    "nrrd-text": [text_header, text_header],
    "nifti": [nifti_fields, nifti_fields],
    "nifti-gz": [nifti_fields, compressed_stream],
    "nifti-pair": [nifti_fields],
    "dicom": [dicom_tags, dicom_tags, dicom_tags],
    "tiff": [tiff_description, tiff_ome],
    "sidecar": [json_fields, json_fields],
    "vti": [vti_attributes, vti_attributes, vti_sizes],
    "vti-base64": [vti_attributes, vti_attributes, vti_sizes],
    "vti-raw": [vti_attributes, vti_sizes, vti_sizes],
    "vtk-legacy": [text_header, text_header],
    "ome-zarr": [zarr_metadata, zarr_metadata, zarr_metadata, zarr_chunks, zarr_codecs,
                 zarr_codecs],
    "zarr-v2": [zarr_metadata, zarr_metadata, zarr_chunks, zarr_codecs, zarr_codecs],
    "wavelet": [zarr_metadata, zarr_metadata, zarr_metadata, zarr_chunks, zarr_codecs,
                zarr_codecs],
    "ome-zarr-py": [zarr_metadata, zarr_metadata, zarr_chunks, zarr_codecs, zarr_codecs],
    "ngff-zarr": [zarr_metadata, zarr_metadata, zarr_chunks, zarr_codecs, zarr_codecs],
    "ngff-zarr-sharded": [zarr_metadata, zarr_metadata, zarr_chunks, zarr_codecs,
                          zarr_codecs, zarr_codecs],
}


def mutate(folder: Path, seed: Seed, rng: random.Random, root: Path) -> list[str]:
    """Apply one to three mutations; structure-aware ones more often than blind ones."""
    done = []
    chosen = []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        structured = STRUCTURED.get(seed.fmt, [])
        roll = rng.random()
        if structured and roll < 0.6:
            chosen.append(rng.choice(structured))
        elif roll < 0.9:
            chosen.append(byte_level)
        elif file_layout not in chosen:
            chosen.append(file_layout)
    # The layout change goes last: the others read files, and a FIFO it may leave would block
    # them (the harness itself must never open one).
    chosen.sort(key=lambda m: m is file_layout)
    for mutation in chosen:
        try:
            done.append(mutation(folder, seed, rng, root))
        except Exception as exc:  # an earlier mutation broke the structure this one parses
            done.append(f"({mutation.__name__} impossible: {type(exc).__name__}) "
                        + byte_level(folder, seed, rng, root))
    return done


__all__ = ["mutate", "STRUCTURED", "PATH_TOKENS", "SHAPE"]
