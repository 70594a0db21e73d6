"""The harness's verdicts: each outcome provoked on purpose by a misbehaving entry point, so that
a clean fuzzing report means something."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest

from .cases import Case
from .harness import Runner


def _segfault(argv: list[str]) -> int:
    os.kill(os.getpid(), signal.SIGSEGV)
    return 0


def _sleep(argv: list[str]) -> int:
    time.sleep(60)
    return 0


def _allocate(argv: list[str]) -> int:
    block = bytearray(8 << 30)  # far above the address-space cap
    return len(block)


def _raise(argv: list[str]) -> int:
    raise ValueError("a traceback")


def _leave_file(argv: list[str]) -> int:
    Path(".out.png.1234.part").write_bytes(b"half")
    print("splinecast: error: something", file=sys.stderr)
    return 2


def _noisy(argv: list[str]) -> int:
    print("WARNING: a library speaks first", file=sys.stderr)
    print("splinecast: error: then us", file=sys.stderr)
    return 2


def _read_outside(argv: list[str]) -> int:
    Path(argv[0]).read_bytes()
    print("splinecast: error: read it", file=sys.stderr)
    return 2


def _clean(argv: list[str]) -> int:
    print("splinecast: error: v.mhd: DimSize must be 3 integers", file=sys.stderr)
    return 2


def _accept(argv: list[str]) -> int:
    Path("out.png").write_bytes(b"png")
    return 0


@pytest.mark.parametrize(("entry", "outcome"), [
    (_segfault, "crash"), (_sleep, "hang"), (_allocate, "memory"), (_raise, "unhandled"),
    (_leave_file, "left-behind"), (_noisy, "noise"), (_read_outside, "outside-read"),
    (_clean, "clean-error"), (_accept, "accepted"),
])
def test_every_verdict(tmp_path, entry, outcome):
    root = tmp_path / "root"
    folder = root / "cases" / "0"
    folder.mkdir(parents=True)
    sentinel = root / "SENTINEL.raw"
    sentinel.write_bytes(b"secret")
    argv = [str(sentinel)] if entry is _read_outside else ["render", "x", "-o", "out.png"]
    case = Case(0, "test", argv, ["provoked"], folder, ["out.png"],
                [str(root.resolve()), "/etc/passwd"])
    runner = Runner(root, workers=1, timeout=2.0, max_bytes=64 << 20, entry=entry)
    (result,) = list(runner.run([case], keep=True))
    assert result.outcome == outcome, result


def test_a_case_may_write_the_image_format_its_last_output_names(tmp_path):
    # argparse keeps the last -o: a case that ends with "-o out.jpg" writes a JPEG, which the
    # verdict must allow (it was called "left-behind").
    from .cases import OUTPUT_SUFFIXES, build_case

    found = []
    for number in range(0, 4000, 2):  # even numbers: the "cli" target when there are no seeds
        case = build_case(number, 1, {}, tmp_path)
        argv = list(case.argv)
        if case.target != "cli" or "-o" not in argv[4:]:
            continue
        last = argv[len(argv) - 1 - argv[::-1].index("-o") + 1]
        if last.lower().endswith(OUTPUT_SUFFIXES):
            found.append(last)
            assert last in case.outputs, (number, argv, case.outputs)
        if any(name.endswith(".jpg") for name in found):
            break
    assert any(name.endswith(".jpg") for name in found), found
