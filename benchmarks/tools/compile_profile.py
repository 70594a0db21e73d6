"""Where the test suite's compile time goes: Numba compiles per test, recorded and summarised.

Most of the suite's time is Numba compiling kernels (one specialisation per model, mode and
argument types). As a pytest plugin this module records every compile through Numba's event API
(``numba:compile``): the test that was running, the function, its argument types, the time and
the nesting depth (a compile inside another one has depth > 0). Each pytest process writes its
own file; run as a script it sums them up by function, by test file and by signature.

    mkdir -p /tmp/cprof
    COMPILE_PROFILE_DIR=/tmp/cprof PYTHONPATH=benchmarks/tools python -m pytest -p compile_profile
    python benchmarks/tools/compile_profile.py /tmp/cprof

It found, for example, a kernel compiled for both (float32, float32) and (float32, float64) grid
lists because one test file used float64 stores where every other used float32: one
specialisation per pair had become two or three.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import time
from pathlib import Path
from typing import Any

_CURRENT = ["<collection>"]
_ROWS: list[dict[str, Any]] = []
_installed = False


def _install() -> None:
    from numba.core import event

    class _Recorder(event.Listener):
        def __init__(self) -> None:
            self.started: list[float] = []

        def on_start(self, ev: Any) -> None:
            self.started.append(time.perf_counter())

        def on_end(self, ev: Any) -> None:
            began = self.started.pop()
            dispatcher = ev.data.get("dispatcher")
            name = getattr(getattr(dispatcher, "py_func", None), "__qualname__", str(dispatcher))
            _ROWS.append({"test": _CURRENT[0], "function": name,
                          "args": str(ev.data.get("args")), "depth": len(self.started),
                          "seconds": time.perf_counter() - began})

    event.register("numba:compile", _Recorder())


def pytest_configure(config: Any) -> None:
    global _installed
    if not _installed:
        _install()
        _installed = True


def pytest_runtest_logstart(nodeid: str, location: Any) -> None:
    _CURRENT[0] = nodeid


def pytest_sessionfinish(session: Any) -> None:
    folder = Path(os.environ.get("COMPILE_PROFILE_DIR", "compile_profile"))
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / f"{os.getpid()}.jsonl", "w") as f:
        for row in _ROWS:
            f.write(json.dumps(row) + "\n")


def summarise(folder: Path, top: int = 30) -> str:
    """Outermost compiles (depth 0) summed by function, by test file and by signature."""
    rows = [json.loads(line) for path in sorted(folder.glob("*.jsonl"))
            for line in path.read_text().splitlines() if line]
    outer = [r for r in rows if r["depth"] == 0]
    lines = [f"{len(outer)} outermost compiles, {sum(r['seconds'] for r in outer):.0f} s"]

    def table(title: str, key: Any) -> None:
        total: dict[str, list[float]] = collections.defaultdict(list)
        for r in outer:
            total[key(r)].append(r["seconds"])
        lines.append(f"\n## {title}\n\n| seconds | compiles | {title} |\n|---|---|---|")
        for name, secs in sorted(total.items(), key=lambda kv: -sum(kv[1]))[:top]:
            lines.append(f"| {sum(secs):.0f} | {len(secs)} | {name} |")

    def signature(r: dict[str, Any]) -> str:
        kinds = collections.Counter(re.findall(r"array\((\w+), 3d", r["args"]))
        grids = sorted(set(re.findall(r"(\w+Grid)\(", r["args"])))
        modes = sorted(set(re.findall(r"(\w+Mode)\(", r["args"])))
        return f"{r['function']} {grids} {modes} 3d arrays {dict(kinds)}"

    table("function", lambda r: r["function"])
    table("test file", lambda r: r["test"].split("::")[0])
    table("signature", signature)
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="COMPILE_PROFILE_DIR of the pytest run")
    parser.add_argument("--top", type=int, default=30)
    args = parser.parse_args()
    print(summarise(args.folder, args.top))


if __name__ == "__main__":
    main()
