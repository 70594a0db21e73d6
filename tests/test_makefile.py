"""The Makefile's recipes name scripts and modules that exist.

``make compare`` once ran ``benchmarks/compare.py`` after the suite had become the package
``benchmarks/compare``; nothing ran that target, so nothing noticed. This finds every
``$(PY) <script>.py`` and ``$(PY) -m <module>`` in the Makefile (``$(PY)``: the virtual
environment's Python) and checks the script path or the module against the tree.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_RUN = re.compile(r"\$\(PY\) (?:-m ([\w.]+)|(\S+\.py)\b)")


def test_every_python_recipe_names_an_existing_script_or_module():
    runs = _RUN.findall((REPO / "Makefile").read_text())
    modules = {m for m, _ in runs if m}
    scripts = {s for _, s in runs if s}
    assert "pytest" in modules and len(runs) >= 5  # the recipes were read
    for script in scripts:
        assert (REPO / script).is_file(), f"the Makefile runs {script}, which does not exist"
    sys.path.insert(0, str(REPO))  # make runs from the repository's root
    try:
        for module in modules:
            assert importlib.util.find_spec(module) is not None, \
                f"the Makefile runs -m {module}, which cannot be imported"
    finally:
        sys.path.remove(str(REPO))
