"""The validation layer itself (splinecast.errors.limits): each check against hand-computed
values."""

from __future__ import annotations

import bz2
import gzip
import io
import json
import math
import os
import resource
from pathlib import Path

import numpy as np
import pytest

from splinecast.errors import ParameterError, ReadError, limits


@pytest.mark.parametrize("value", [0, -1, 1.5, float("nan"), float("inf"), True, "3", None,
                                   2**70, limits.MAX_AXIS + 1])
def test_shape_refuses_what_is_not_a_voxel_count(value):
    with pytest.raises(ReadError, match=r"^hdr: DimSize must be 3 integers"):
        limits.check_shape([4, value, 4], "hdr: DimSize", error=ReadError)


def test_shape_accepts_integral_floats_and_numpy_integers():
    assert limits.check_shape([4.0, np.int64(5), np.uint16(6)], "s") == (4, 5, 6)


def test_shape_message_shows_the_values_as_given_never_a_wrapped_product():
    with pytest.raises(ReadError) as info:
        limits.check_shape([2**63, 20, 16], "f: shape", error=ReadError)
    assert "9223372036854775808x20x16" in str(info.value)
    assert "-9223372036854775808" not in str(info.value)


def test_nbytes_is_exact_beyond_64_bits():
    assert limits.nbytes((2**40, 2**40, 2**40), 8) == 2**123


@pytest.mark.parametrize("spacing", [1e-320, 5e-324, 0.0, -1.0, float("nan"), float("inf"),
                                     1e-13, 1e13, [1.0, 1.0], "abc"])
def test_spacing_must_be_normal_and_sane(spacing):
    with pytest.raises(ParameterError, match="spacing"):
        limits.check_spacing(spacing)


def test_spacing_range_ends_are_accepted():
    lo, hi = limits.SPACING_RANGE
    assert limits.check_spacing([lo, 1.0, hi]) == (lo, 1.0, hi)


def test_origin_far_from_zero_in_voxel_units_is_refused():
    spacing = (1e-6, 1.0, 1.0)
    assert limits.check_origin((1e5, 0, 0), spacing) == (1e5, 0.0, 0.0)  # 1e11 voxels: fine
    with pytest.raises(ParameterError, match="2\\^40 voxel spacings"):
        limits.check_origin((1e7, 0, 0), spacing)  # 1e13 voxels > 2^40
    with pytest.raises(ParameterError, match="finite"):
        limits.check_origin((float("nan"), 0, 0), spacing)


def test_step_bounds_follow_the_volume_diagonal():
    shape = (300, 400, 1200)  # diagonal 1300 voxels
    assert limits.check_step(0.01, "step", shape) == 0.01
    with pytest.raises(ParameterError, match=r"step must be a finite number >= 0.001, got 0.0001"):
        limits.check_step(1e-4, "step", shape)
    big = (limits.MAX_AXIS, limits.MAX_AXIS, limits.MAX_AXIS)  # diagonal ~1.8e6 voxels
    with pytest.raises(ParameterError, match="samples per ray"):
        limits.check_step(1.0, "step", big)
    limits.check_step(2.0, "step", big)


@pytest.mark.parametrize(("text", "expected"), [("512MiB", 512 << 20), ("2G", 2 * 10**9),
                                                ("1e9", 10**9), ("4096", 4096), ("1.5kib", 1536)])
def test_parse_bytes(text, expected):
    assert limits.parse_bytes(text) == expected


@pytest.mark.parametrize("text", ["", "-1", "0", "lots", "1 parsec", "nan", "inf"])
def test_parse_bytes_refuses_nonsense(text):
    with pytest.raises(ParameterError, match="SPLINECAST_MAX_BYTES"):
        limits.parse_bytes(text)


@pytest.fixture
def machine(tmp_path, monkeypatch):
    """The memory probes pointed at files the test writes: a fake ``/proc/meminfo`` and cgroup
    v2 folder (the ``ulimit -v`` probe is off: ``test_address_space_limit_counts`` has it).
    ``machine(available=..., cgroup_max=..., cgroup_current=...)`` writes them (``None``: the
    file is absent) and forgets the last reading."""
    meminfo, cgroup = tmp_path / "meminfo", tmp_path / "cgroup"
    cgroup.mkdir()
    monkeypatch.setattr(limits, "MEMINFO_PATH", str(meminfo))
    monkeypatch.setattr(limits, "CGROUP_ROOT", str(cgroup))
    monkeypatch.setattr(limits, "_address_space_left", lambda: None)
    monkeypatch.delenv(limits.ENV_MAX_BYTES, raising=False)

    def write(available=8 << 30, cgroup_max=None, cgroup_current=None):
        lines = ["MemTotal:       16318836 kB", "MemFree:          512000 kB"]
        if available is not None:
            lines.append(f"MemAvailable:   {available // 1024:>9} kB")
        meminfo.write_text("\n".join([*lines, "Buffers:           1024 kB", ""]))
        for name, value in (("memory.max", cgroup_max), ("memory.current", cgroup_current)):
            path = cgroup / name
            if value is None:
                path.unlink(missing_ok=True)
            else:
                path.write_text(f"{value}\n")
        monkeypatch.setattr(limits, "_machine_reading", [-math.inf, None, []])

    write()
    return write


def test_memory_cap_from_the_environment(machine, monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "1MiB")
    assert limits.memory_limit()[0] == 1 << 20
    limits.check_memory(1 << 20, "x", "opt")
    wanted = r"^--size: a 2x2 image needs 1.0 MiB, more than the cap SPLINECAST_MAX_BYTES=1MiB$"
    with pytest.raises(ParameterError, match=wanted):
        limits.check_memory((1 << 20) + 1, "a 2x2 image", "--size")
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "bogus")
    with pytest.raises(ParameterError, match="SPLINECAST_MAX_BYTES"):
        limits.memory_limit()


def test_memory_limit_is_the_available_memory(machine):
    machine(available=3 << 30)
    assert limits.memory_limit() == (3 << 30, "the 3.0 GiB of available memory")
    with pytest.raises(ParameterError, match=r"^f: a volume needs 3.0 GiB, more than the 3.0 GiB "
                                             r"of available memory$"):
        limits.check_memory((3 << 30) + 1, "a volume", "f")


def test_cgroup_memory_probe(machine):
    # The cgroup's limit less what the group uses, when that is below the available memory.
    machine(available=8 << 30, cgroup_max=3 << 30, cgroup_current=1 << 30)
    assert limits.memory_limit() == (2 << 30, "the 2.0 GiB of memory left under the cgroup limit")
    # Nothing used yet (no memory.current): the whole limit.
    machine(available=8 << 30, cgroup_max=3 << 30)
    assert limits.memory_limit()[0] == 3 << 30
    # A group above its limit leaves nothing.
    machine(available=8 << 30, cgroup_max=1 << 30, cgroup_current=(1 << 30) + 4096)
    assert limits.memory_limit()[0] == 0
    # "max" (no limit) or no cgroup file at all: the available memory decides.
    machine(available=5 << 30, cgroup_max="max", cgroup_current=1 << 30)
    assert limits.memory_limit() == (5 << 30, "the 5.0 GiB of available memory")
    machine(available=5 << 30)
    assert limits.memory_limit()[0] == 5 << 30
    # A cgroup limit above the available memory does not raise the limit.
    machine(available=1 << 30, cgroup_max=4 << 30, cgroup_current=0)
    assert limits.memory_limit()[0] == 1 << 30


def test_the_default_probes_read_the_kernels_files():
    assert limits.MEMINFO_PATH == "/proc/meminfo"
    assert limits.CGROUP_ROOT == "/sys/fs/cgroup"


def test_address_space_limit_counts(monkeypatch):
    """Under ``ulimit -v`` the guard refuses what could not be mapped (run in a child)."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            with open("/proc/self/status") as fh:
                vm = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize"))
            resource.setrlimit(resource.RLIMIT_AS, (vm + (64 << 20), vm + (64 << 20)))
            left, source = limits.memory_limit()
            os.write(write, json.dumps([left, source]).encode())
        finally:
            os._exit(0)
    os.close(write)
    os.waitpid(pid, 0)
    left, source = json.loads(os.read(read, 4096))
    assert left <= 64 << 20 and "ulimit" in source


def test_path_text_checks():
    assert limits.check_path_text("a/b.raw", "f") == Path("a/b.raw")
    for bad, what in [("a\0b", "NUL"), ("x" * 5000, "too long"), ("a/" + "y" * 300, "too long"),
                      ("", "empty")]:
        with pytest.raises(ParameterError, match=what):
            limits.check_path_text(bad, "f")


def test_data_file_must_stay_in_the_header_folder(tmp_path):
    (tmp_path / "data").mkdir()
    header = tmp_path / "data" / "v.mhd"
    (tmp_path / "data" / "sub").mkdir()
    (tmp_path / "secret.raw").write_bytes(b"x")
    assert limits.check_data_file(header, "sub/v.raw", "F") == tmp_path / "data" / "sub/v.raw"
    assert limits.check_data_file(header, "sub/../v.raw", "F").name == "v.raw"
    for outside in ["../secret.raw", str(tmp_path / "secret.raw"), "/etc/passwd", "..",
                    "sub/../../secret.raw"]:
        with pytest.raises(ReadError, match="outside the header's folder"):
            limits.check_data_file(header, outside, "F")
    # A symbolic link is judged by where it leads, both ways.
    (tmp_path / "data" / "link.raw").symlink_to(tmp_path / "secret.raw")
    with pytest.raises(ReadError, match="outside"):
        limits.check_data_file(header, "link.raw", "F")
    (tmp_path / "data" / "inner.raw").symlink_to(tmp_path / "data" / "sub")
    limits.check_data_file(header, "inner.raw", "F")
    # Explicitly allowed: any path, by argument or by environment.
    limits.check_data_file(header, "../secret.raw", "F", allow_external=True)


def test_data_file_allowed_by_environment(tmp_path, monkeypatch):
    header = tmp_path / "v.mhd"
    monkeypatch.setenv(limits.ENV_ALLOW_EXTERNAL, "1")
    assert limits.check_data_file(header, "/etc/passwd", "F") == Path("/etc/passwd")


def test_regular_file_refuses_devices_and_folders(tmp_path):
    with pytest.raises(ReadError, match="not a regular file"):
        limits.check_regular_file(Path("/dev/zero"), "z")
    with pytest.raises(ReadError, match="not a regular file"):
        limits.check_regular_file(tmp_path, "d")
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(ReadError, match="not a regular file"):
        limits.check_regular_file(tmp_path / "fifo", "p")


def test_read_limited_stops_at_the_bound(tmp_path):
    (tmp_path / "f").write_bytes(b"x" * 1024)
    assert limits.read_limited(tmp_path / "f", 1024, "f") == b"x" * 1024
    with pytest.raises(ReadError, match="longer than 1023 bytes"):
        limits.read_limited(tmp_path / "f", 1023, "f")
    with pytest.raises(ReadError, match="longer than 1.0 KiB"):
        limits.read_limited(Path("/dev/zero"), 1024, "/dev/zero")


@pytest.mark.parametrize(("text", "what"), [
    ("[" * 10000 + "]" * 10000, "nested"),
    ('{"a": ' + "1" * 5000 + "}", "not valid JSON"),
    ('{"a": NaN}', "not valid JSON"),
    ('{"a": 1e999}', "not valid JSON"),
    ('{"a": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]}', "nested"),
    ("\xff\xfe", "UTF-8"),
    ('{"a": 1', "not valid JSON"),
])
def test_load_json_bounds(tmp_path, text, what):
    path = tmp_path / "x.json"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(ReadError, match=what):
        limits.load_json(path, str(path))


def test_load_json_accepts_ordinary_files(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"shape": [1, 2, 3], "spacing": 0.5}')
    assert limits.load_json(path, "x") == {"shape": [1, 2, 3], "spacing": 0.5}


@pytest.mark.parametrize("compress", [lambda b: gzip.compress(b, mtime=0), bz2.compress])
def test_read_exact_bounds_decompression(compress):
    def stream(data: bytes):
        raw = io.BytesIO(compress(data))
        return gzip.GzipFile(fileobj=raw) if compress is not bz2.compress else bz2.BZ2File(raw)

    assert limits.read_exact(stream(b"abcd"), 4, "f").tobytes() == b"abcd"
    with pytest.raises(ReadError, match="more than the 4 bytes"):
        limits.read_exact(stream(bytes(50_000_000)), 4, "f")  # a 50 MB bomb, read 5 bytes of
    with pytest.raises(ReadError, match="ends after 3 of the 4 bytes"):
        limits.read_exact(stream(b"abc"), 4, "f")
    broken = bytearray(compress(b"abcdefgh" * 100))
    broken[len(broken) // 2] ^= 0xFF
    raw = io.BytesIO(bytes(broken))
    bad = gzip.GzipFile(fileobj=raw) if compress is not bz2.compress else bz2.BZ2File(raw)
    with pytest.raises(ReadError, match="corrupt"):
        limits.read_exact(bad, 800, "f")
