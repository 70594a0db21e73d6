"""The short fuzzing run of the test suite: a few hundred hostile cases over every readable format,
the demo URIs and the render options, none of which may crash, hang, exhaust memory, end in a
traceback or noise, leave a file behind or read outside its folder (``make fuzz`` runs 20,000+).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from .harness import BAD
from .seeds import MAKERS, available

TESTS = Path(__file__).resolve().parents[1]
CASES = 300


def test_short_fuzz_run(tmp_path: Path) -> None:
    report = tmp_path / "report.json"
    proc = subprocess.run(
        [sys.executable, "-m", "fuzz.run", "--cases", str(CASES), "--seed", "17",
         "--json", str(report), "--root", str(tmp_path / "root")],
        cwd=TESTS, capture_output=True, text=True, timeout=3600,
    )
    assert report.exists(), proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads(report.read_text())
    bad = {k: v for k, v in summary["totals"].items() if k in BAD and v}
    details = "\n".join(f"{r['outcome']}: {r['summary']}\n    {r['detail'][-400:]}"
                        for r in summary["bad"][:20])
    assert not bad, f"{bad}\n{details}"
    assert proc.returncode == 0, proc.stderr[-2000:]
    # The run covered what it claims: every available format and both option targets, each
    # with cases that ran to a verdict, and both good outcomes occurred.
    # (A format whose reader exists but whose seed could not be written is missing from
    # "formats": the core ones must all be there.)
    core = {f for f, (_, module) in MAKERS.items()
            if available(f) and (module is None or not module.startswith("splinecast."))}
    assert core <= set(summary["formats"]), set(summary["formats"])
    assert set(summary["formats"]) | {"cli", "demo"} <= set(summary["per_target"])
    assert summary["cases"] == CASES
    assert summary["totals"]["accepted"] > 0 and summary["totals"]["clean-error"] > 0
    skipped = summary["totals"]["skipped-compile"]
    assert skipped < CASES // 4, f"{skipped} cases needed kernels the warm-up did not compile"
    print(f"\nfuzz: {summary['totals']} in {summary['seconds']} s "
          f"({summary['cases_per_second']} cases/s)")
