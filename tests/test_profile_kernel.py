"""The report of ``benchmarks/tools/profile_kernel.py`` (its perf run is a developer tool; the
report's arithmetic is checked here on a made-up disassembly with known counts)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks" / "tools"))
from profile_kernel import _report  # noqa: E402


def test_the_report_splits_the_code_at_its_returns_and_ranks_the_windows():
    # Two functions: [0x0, 0x120] (ends with ret at 0x120) and [0x121, 0x310].
    rows = [(5, 0x0, "push %rbp"), (40, 0x10, "vdivsd %xmm1,%xmm2,%xmm3"),
            (15, 0x110, "add %rax,%rbx"), (0, 0x120, "ret"),
            (1, 0x121, "mov %rdi,%rax"), (39, 0x300, "vsqrtsd %xmm0,%xmm0,%xmm0"),
            (0, 0x310, "ret")]
    info = {"pair": ["TrilinearGrid", "IsoMode"], "threads": 1, "frame_ms": 12.5,
            "samples": 200}
    args = argparse.Namespace(scene="sphere SDF 128^3", mode="iso", model="trilinear",
                              frames=10, size="64x48")
    text = _report(info, rows, args)
    assert "Samples: 200 in all, 100 (50.0%) in the band's code." in text
    assert "| 0x0-0x120 | 60 | 60.0% |" in text
    assert "| 0x121-0x310 | 40 | 40.0% |" in text
    # Windows of 256 bytes: 0x0 holds 45, 0x100 holds 16, 0x300 holds 39.
    windows = text.split("## Hottest 256-byte windows")[1].split("## Hottest instructions")[0]
    assert windows.index("| 0x0 | 45 |") < windows.index("| 0x300 | 39 |") < windows.index(
        "| 0x100 | 16 |")
    hottest = text.split("## Hottest instructions")[1]
    assert hottest.index("vdivsd") < hottest.index("vsqrtsd") < hottest.index("add %rax")
