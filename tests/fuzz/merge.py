"""``python -m fuzz.merge A.json B.json ... --json OUT.json --markdown OUT.md``: one report from
runs of disjoint case ranges (``--start``) that ran side by side on the same code.

Counts are summed per target; the wall time is the longest run's (they ran concurrently), so
``cases_per_second`` is the combined rate. ``--note`` adds a line about the machine.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

from .harness import OUTCOMES
from .run import markdown


def merge(reports: list[dict], note: str | None = None) -> dict:
    """The combined report of ``reports`` (same seed and options, disjoint cases)."""
    first = reports[0]
    for key in ("seed", "timeout", "max_bytes", "compile", "formats"):
        values = {json.dumps(r[key]) for r in reports}
        if len(values) != 1:
            raise ValueError(f"the runs differ in {key}: {sorted(values)}")
    per_target: dict[str, Counter] = {}
    for r in reports:
        for target, counts in r["per_target"].items():
            per_target.setdefault(target, Counter()).update(counts)
    totals = Counter()
    for r in reports:
        totals.update(r["totals"])
    cases = sum(r["cases"] for r in reports)
    seconds = max(r["seconds"] for r in reports)
    return {
        **first,
        "cases": cases,
        "seconds": seconds,
        "warm_up_seconds": max(r["warm_up_seconds"] for r in reports),
        "cases_per_second": round(cases / seconds, 2) if seconds else None,
        "workers": sum(r["workers"] for r in reports),
        "runs": [{k: r[k] for k in ("cases", "seconds", "cases_per_second", "workers",
                                    "warm_up_seconds")} for r in reports],
        "note": note,
        "totals": {k: totals.get(k, 0) for k in OUTCOMES},
        "per_target": {t: {k: c.get(k, 0) for k in OUTCOMES}
                       for t, c in sorted(per_target.items())},
        "slowest": sorted((s for r in reports for s in r["slowest"]), reverse=True)[:5],
        "bad": [b for r in reports for b in r["bad"]][:200],
        "skipped": [s for r in reports for s in r["skipped"]][:50],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fuzz.merge", description=__doc__)
    parser.add_argument("reports", nargs="+")
    parser.add_argument("--json")
    parser.add_argument("--markdown")
    parser.add_argument("--note", help="a line about the machine and how the runs were split")
    args = parser.parse_args(argv)
    summary = merge([json.loads(Path(p).read_text()) for p in args.reports], args.note)
    table = markdown(summary)
    if args.note:
        table += f"\n{args.note}\n"
    print(table)
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")
    if args.markdown:
        Path(args.markdown).write_text(table)
    return 1 if any(summary["totals"][k] for k in OUTCOMES if k not in
                    ("accepted", "clean-error", "skipped-compile")) else 0


if __name__ == "__main__":
    sys.exit(main())
