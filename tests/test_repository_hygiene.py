"""The repository reads as a product: a short README that starts with the set-up commands,
user-facing text without work-log references, and benchmarks that are documented.

What is checked here (the documentation's own links are checked by ``tests/test_docs.py``, which
builds the site with ``-W -n``):

* the README is under 200 lines, its first lines after the title are ``make demo`` and
  ``make test`` (``.ci/run`` runs the latter), and its relative links lead to files;
* README, CHANGELOG, CONTRIBUTING, Makefile, pyproject, docs, examples, scripts, src and the
  benchmarks' code carry no issue or session numbers and no paths outside the repository, and
  cite papers by name rather than by a private numbering;
* docstrings and comments in ``src/`` cite no benchmark result files (numbers that go stale
  belong in ``docs/performance.rst``);
* every maintained benchmark and tool is described in ``docs/performance.rst``, and every file in
  ``benchmarks/results/`` is the result of one that is named there;
* CHANGELOG follows Keep a Changelog; LICENSE, CITATION.cff and CONTRIBUTING.md exist.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Issue and session numbers of the development process, which users cannot look up.
WORK_LOG = re.compile(
    r"\b(?:issues?|sessions?)\s*#?\s*\d|\(issues?\b|\bissue\d|\bsession\d", re.IGNORECASE)
#: Paths and documents outside the repository.
OUTSIDE = re.compile(r"\.\./shared|/work/|shared folder|DESIGN\.md|shared/notes", re.IGNORECASE)
#: Papers cited by a private number instead of their authors and year.
PRIVATE_CITATION = re.compile(r"\b(?:references?|ref\.)\s+0\d\d\b", re.IGNORECASE)
#: A benchmark result file named in the package's own text.
RESULT_FILE = re.compile(r"results/[\w.{},*-]+\.(?:md|json|png)|benchmarks/results")

TEXT_SUFFIXES = {".py", ".rst", ".md", ".txt", ".toml", ".cfg", ".sh", ".js", ".html", ".css",
                 ".json", ".cff"}


def _files() -> list[Path]:
    """The files users and contributors read (not test code, not recorded results)."""
    files = [ROOT / name for name in ("README.md", "CHANGELOG.md", "CONTRIBUTING.md", "Makefile",
                                      "pyproject.toml", "CITATION.cff")]
    for folder, skip in (("docs", ("_build", "generated", "gallery")),
                         ("examples", ()), ("scripts", ()), ("src/splinecast", ()),
                         ("benchmarks", ("results",))):
        for path in sorted((ROOT / folder).rglob("*")):
            parts = path.relative_to(ROOT / folder).parts
            if (path.is_file() and path.suffix in TEXT_SUFFIXES and "__pycache__" not in parts
                    and not (parts and parts[0] in skip)
                    and path.name != "sg_execution_times.rst"):
                files.append(path)
    return files


def _hits(pattern: re.Pattern, files: list[Path]) -> list[str]:
    hits = []
    for path in files:
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if pattern.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    return hits


def test_readme_is_short_and_starts_with_the_set_up_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) < 200, f"README.md has {len(lines)} lines; move detail into docs/"
    assert lines[0].startswith("# ")
    body = [line for line in lines[1:] if line.strip()]
    assert body[0].startswith("```"), "the README's first lines after the title are commands"
    assert body[1].split("#")[0].strip() == "make demo"
    assert body[2].split("#")[0].strip() == "make test"
    assert "make test" in (ROOT / ".ci" / "run").read_text()


def test_readme_links_lead_to_files():
    text = (ROOT / "README.md").read_text()
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        assert (ROOT / target.split("#")[0]).exists(), f"README.md links to missing {target}"


@pytest.mark.parametrize(("what", "pattern"), [("issue or session numbers", WORK_LOG),
                                               ("paths outside the repository", OUTSIDE),
                                               ("papers cited by number", PRIVATE_CITATION)])
def test_no_work_log_references(what, pattern):
    hits = _hits(pattern, _files())
    assert not hits, f"{what}:\n" + "\n".join(hits)


def test_package_text_cites_no_benchmark_results():
    files = [path for path in _files() if path.is_relative_to(ROOT / "src")]
    hits = _hits(RESULT_FILE, files)
    assert not hits, ("state the design reason; measurements belong in docs/performance.rst:\n"
                      + "\n".join(hits))


def test_benchmarks_are_documented_and_results_belong_to_them():
    performance = (ROOT / "docs" / "performance.rst").read_text()
    accuracy = (ROOT / "docs" / "accuracy.rst").read_text()
    helpers = {"floor_kernel.py"}  # imported by bench_floor.py and the comparison suite
    for script in sorted((ROOT / "benchmarks").glob("*.py")):
        if not script.name.startswith("_") and script.name not in helpers:
            assert f"benchmarks/{script.name}" in performance, \
                f"benchmarks/{script.name} is not described in docs/performance.rst"
    assert "benchmarks.compare" in performance
    for tool in sorted((ROOT / "benchmarks" / "tools").glob("*.py")):
        if not tool.name.startswith("_"):
            assert tool.name in performance, f"tool {tool.name} missing from docs/performance.rst"
    results = sorted(p for p in (ROOT / "benchmarks" / "results").iterdir() if p.is_file())
    stems = {p.stem for p in results if p.suffix == ".md"}
    for path in results:
        if path.suffix == ".md":
            assert f"results/{path.name}" in performance + accuracy, \
                f"benchmarks/results/{path.name} is not quoted in docs/performance.rst"
        else:
            assert any(path.stem == s or path.stem.startswith(s + "_") for s in stems), \
                f"benchmarks/results/{path.name} belongs to no result in benchmarks/results"


def test_changelog_keeps_a_changelog():
    text = (ROOT / "CHANGELOG.md").read_text()
    assert text.startswith("# Changelog")
    assert "## [Unreleased]" in text
    sections = re.findall(r"^### (.+)$", text, re.MULTILINE)
    assert sections and set(sections) <= {"Added", "Changed", "Deprecated", "Removed", "Fixed",
                                          "Security"}, sections


def test_licence_citation_and_contributing_guide_exist():
    licence = (ROOT / "LICENSE").read_text()
    assert "BSD 3-Clause" in licence and "the splinecast developers" in licence
    assert 'license = "BSD-3-Clause"' in (ROOT / "pyproject.toml").read_text()
    citation = (ROOT / "CITATION.cff").read_text()
    assert "cff-version:" in citation and "license: BSD-3-Clause" in citation
    assert "make test" in (ROOT / "CONTRIBUTING.md").read_text()
