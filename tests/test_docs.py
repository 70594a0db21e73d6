"""The documentation site builds offline, in the quick mode (gallery pages without running the
examples, which tests/test_examples.py runs), with every page and API entry in place, no warning
and every cross-reference resolved (``-W -n``, as ``make docs``)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_docs_build(tmp_path):
    pytest.importorskip("sphinx_gallery", reason="the docs extra is not installed "
                        "(pip install -e '.[docs]')")
    # A copy, so the build's generated sources never land in the work tree.
    for name in ("docs", "examples"):
        shutil.copytree(ROOT / name, tmp_path / name,
                        ignore=shutil.ignore_patterns("_build", "generated", "gallery",
                                                      "sg_execution_times.rst"))
    for name in ("CHANGELOG.md", "CONTRIBUTING.md"):  # included by the site's pages
        shutil.copy(ROOT / name, tmp_path)
    out = tmp_path / "html"
    result = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-q", "-W", "-n", "--keep-going",
         "-D", "plot_gallery=0", str(tmp_path / "docs"), str(out)],
        capture_output=True, text=True, cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    for page in ("index", "install", "api", "changelog", "guide/defaults", "guide/formats",
                 "guide/multiresolution", "guide/viewer", "guide/dask", "guide/wavelets",
                 "guide/cut-selection", "guide/input-safety", "accuracy", "performance",
                 "architecture", "references", "contributing", "internals",
                 "gallery/index", "gallery/plot_quickstart",
                 "generated/splinecast.Volume", "generated/splinecast.auto_iso",
                 "generated/splinecast.Camera", "generated/splinecast.render.segment"):
        assert (out / f"{page}.html").is_file(), page
    volume = (out / "generated" / "splinecast.Volume.html").read_text()
    assert "from_vtk" in volume and "x fastest" in volume  # the API reference is the docstrings
    assert "Otsu" in (out / "generated" / "splinecast.auto_iso.html").read_text()
    # The command line's reference is its own --help.
    assert "--tolerance" in (out / "guide" / "cli.html").read_text()
