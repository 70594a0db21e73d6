"""``python -m fuzz.run`` (from ``tests/``): a fuzzing run with a report.

    python -m fuzz.run --cases 300                  # what the test suite runs
    python -m fuzz.run --cases 20000 --json r.json  # make fuzz
    python -m fuzz.run --only 1234 --seed 7         # rebuild and rerun one case, keeping it

Exit status 1 when any case ended in a bad outcome (see :mod:`fuzz.harness`).
"""

from __future__ import annotations

import os

# Before numba is imported (by splinecast): the fork-safe thread pool, one thread per child.
os.environ["NUMBA_THREADING_LAYER"] = "workqueue"
os.environ["NUMBA_NUM_THREADS"] = "1"

import argparse  # noqa: E402
import gc  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections import Counter, defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

from .cases import build_case  # noqa: E402
from .harness import BAD, OUTCOMES, Result, Runner, warm_up  # noqa: E402
from .seeds import DATA_BYTES, make_seeds  # noqa: E402


def _cases(args: argparse.Namespace, seeds: dict, root: Path):  # noqa: ANN202 - a generator
    numbers = [args.only] if args.only is not None else range(args.start, args.start + args.cases)
    for number in numbers:
        try:
            with warnings.catch_warnings():  # the mutations' own use of pydicom and friends
                warnings.simplefilter("ignore")
                case = build_case(number, args.seed, seeds, root)
        except Exception as exc:  # a bug of the harness: reported, never hidden
            yield Result(number, "?", "harness-error", 0.0, 0.0, f"#{number}",
                         f"{type(exc).__name__}: {exc}")
        else:
            yield case


def report(results: list[Result], seconds: float, args: argparse.Namespace,
           warm_seconds: float, formats: list[str]) -> dict:
    """Outcome counts per target, rate, and the bad cases."""
    table: dict[str, Counter] = defaultdict(Counter)
    for r in results:
        table[r.target][r.outcome] += 1
    totals = Counter(r.outcome for r in results)
    bad = [r.as_dict() for r in results if r.outcome in BAD]
    return {
        "cases": len(results),
        "seconds": round(seconds, 1),
        "warm_up_seconds": round(warm_seconds, 1),
        "cases_per_second": round(len(results) / seconds, 2) if seconds else None,
        "workers": args.workers,
        "timeout": args.timeout,
        "max_bytes": args.max_bytes,
        "compile": args.compile,
        "seed": args.seed,
        "formats": formats,
        "machine": f"{platform.machine()} {os.cpu_count()} cores, {platform.python_version()}",
        "totals": {k: totals.get(k, 0) for k in OUTCOMES},
        "per_target": {t: {k: c.get(k, 0) for k in OUTCOMES} for t, c in sorted(table.items())},
        "slowest": sorted(((r.seconds, r.summary) for r in results), reverse=True)[:5],
        "bad": bad[:200],
        "skipped": [r.summary for r in results if r.outcome == "skipped-compile"][:50],
    }


def markdown(summary: dict) -> str:
    """The report as a markdown table."""
    cols = ["accepted", "clean-error", "skipped-compile", *BAD]
    lines = [
        f"Fuzzing run: {summary['cases']} cases in {summary['seconds']} s "
        f"({summary['cases_per_second']} cases/s, {summary['workers']} workers, "
        f"warm-up {summary['warm_up_seconds']} s) on {summary['machine']}; seed {summary['seed']},"
        f" timeout {summary['timeout']} s, SPLINECAST_MAX_BYTES={summary['max_bytes']}.",
        "",
        "| target | " + " | ".join(cols) + " |",
        "|---|" + "---:|" * len(cols),
    ]
    for target, counts in summary["per_target"].items():
        lines.append(f"| {target} | " + " | ".join(str(counts[c]) for c in cols) + " |")
    totals = summary["totals"]
    lines.append("| **all** | " + " | ".join(f"**{totals[c]}**" for c in cols) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fuzz.run", description=__doc__)
    parser.add_argument("--cases", type=int, default=300)
    parser.add_argument("--start", type=int, default=0, help="number of the first case")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--max-bytes", type=int, default=256 << 20)
    parser.add_argument("--compile", choices=("skip", "allow"), default="skip",
                        help="skip cases that would compile a new kernel (default), or let "
                             "them compile (the time does not count towards --timeout)")
    parser.add_argument("--formats", help="comma-separated formats (default: all available)")
    parser.add_argument("--root", help="working folder (default: a new temporary one)")
    parser.add_argument("--json", help="write the report here")
    parser.add_argument("--markdown", help="write the table here")
    parser.add_argument("--only", type=int, help="rebuild and rerun this case, and keep it")
    parser.add_argument("--keep", action="store_true", help="keep every case folder")
    parser.add_argument("--show", action="store_true", help="print every case's outcome")
    parser.add_argument("--report-every", type=int, default=500,
                        help="rewrite --json/--markdown every N cases (0: only at the end); "
                             "SIGTERM stops the run and writes what ran")
    args = parser.parse_args(argv)

    root = Path(args.root or tempfile.mkdtemp(prefix="splinecast-fuzz-")).resolve()
    root.mkdir(parents=True, exist_ok=True)
    # The sentinel outside every case folder: the size of the seeds' raw data, so a header that
    # were allowed to name it would be read without complaint.
    (root / "SENTINEL.raw").write_bytes(b"\x07" * DATA_BYTES)
    (root / "other").mkdir(exist_ok=True)
    (root / "other" / "v.raw").write_bytes(b"\x07" * DATA_BYTES)

    start = time.monotonic()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seeds = make_seeds(root / "seeds", args.formats.split(",") if args.formats else None)
        import splinecast as sc

        warm_up([(s.folder, s.main) for s in seeds.values()], sc.MODELS)
    # Every case runs in a fork of this process. The CLI collects garbage after a failure, and
    # a collection in a child walks (and copies, page by page) the whole heap of the parent,
    # which compiling the kernels in the warm-up makes large: seconds per case instead of
    # milliseconds. The parent's objects are frozen out of the children's collections.
    gc.collect()
    gc.freeze()
    warm_seconds = time.monotonic() - start
    print(f"fuzz: {len(seeds)} formats ({', '.join(seeds)}), warm-up {warm_seconds:.1f} s, "
          f"root {root}", flush=True)

    runner = Runner(root, workers=args.workers, timeout=args.timeout, max_bytes=args.max_bytes,
                    compile=args.compile)
    results = []
    start = time.monotonic()
    keep = args.keep or args.only is not None
    stopped = []

    def stop(signum: int, frame: object) -> None:  # SIGTERM: report what ran so far
        stopped.append(signum)  # checked after each result (raising here could hit a fork)

    previous = signal.signal(signal.SIGTERM, stop)

    def write(partial: bool) -> dict:
        summary = report(results, time.monotonic() - start, args, warm_seconds, sorted(seeds))
        summary["partial"] = partial
        table = markdown(summary)
        if args.json:
            Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")
        if args.markdown:
            Path(args.markdown).write_text(table)
        return summary

    try:
        for n, result in enumerate(runner.run(_cases(args, seeds, root), keep=keep), 1):
            results.append(result)
            if args.show and result.outcome not in BAD:
                print(f"fuzz: {result.outcome}: {result.summary}\n    {result.detail[-300:]}")
            if result.outcome in BAD or args.only is not None:
                print(f"fuzz: {result.outcome}: {result.summary}\n    {result.detail[-600:]}",
                      flush=True)
            if n % 1000 == 0:
                rate = n / (time.monotonic() - start)
                print(f"fuzz: {n} cases, {rate:.1f}/s", flush=True)
            if args.report_every and n % args.report_every == 0:
                write(partial=True)  # a run stopped early still leaves its numbers
            if stopped:
                print(f"fuzz: stopped after {len(results)} cases", file=sys.stderr, flush=True)
                break
    except KeyboardInterrupt:
        print(f"fuzz: stopped after {len(results)} cases", file=sys.stderr, flush=True)
    finally:
        signal.signal(signal.SIGTERM, previous)
    summary = write(partial=bool(stopped) or len(results) < args.cases)
    print(markdown(summary))
    failed = sum(summary["totals"][k] for k in BAD)
    if not failed and not keep and args.root is None:
        shutil.rmtree(root, ignore_errors=True)
    elif failed:
        print(f"fuzz: {failed} bad cases; folders and logs kept under {root}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
