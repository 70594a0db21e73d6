"""The benchmarks' result writer (``benchmarks/_machine.write_results``) keeps what it is given:
the rows and machine in the JSON, one markdown table line per row under the description."""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from _machine import write_results  # noqa: E402


def test_results_are_written_as_json_and_one_table_line_per_row(tmp_path):
    rows = [{"scene": "a", "ms": 1.25}, {"scene": "b", "ms": 20.0}]
    machine = {"cpu": "test cpu", "cores": 2}
    write_results(tmp_path / "study", "A study", "Command: `python study.py`.",
                  ["scene", "ms"], rows, lambda r: [r["scene"], f"{r['ms']:.1f}"],
                  machine=machine, before_table=["![plot](study.png)"])
    assert json.loads((tmp_path / "study.json").read_text()) == {"machine": machine,
                                                                  "rows": rows}
    # Written out by hand: the layout the committed results/*.md files have.
    assert (tmp_path / "study.md").read_text() == (
        "# A study\n"
        "\n"
        "Machine: {'cpu': 'test cpu', 'cores': 2}. Command: `python study.py`.\n"
        "\n"
        "![plot](study.png)\n"
        "\n"
        "| scene | ms |\n"
        "|---|---|\n"
        "| a | 1.2 |\n"
        "| b | 20.0 |\n")
