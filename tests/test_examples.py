"""Every gallery example in examples/ runs and renders a picture, so none can rot.

The examples are small already; they run here as they run when the documentation is built
(sphinx-gallery executes the same files), in a scratch folder.
"""

from __future__ import annotations

import runpy
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("plot_*.py"))
NEEDS = {"plot_vtk.py": "vtkmodules"}


def test_there_are_examples():
    assert len(EXAMPLES) >= 5


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_runs_and_renders(path, tmp_path, monkeypatch):
    if path.name in NEEDS:
        pytest.importorskip(NEEDS[path.name], reason=f"{path.name} needs {NEEDS[path.name]}")
    monkeypatch.chdir(tmp_path)
    namespace = runpy.run_path(str(path), run_name="__main__")
    frames = []
    for value in namespace.values():
        for item in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(item, sc.Frame):
                frames.append(item)
    assert frames, f"{path.name} renders no Frame for the gallery"
    for frame in frames:
        image = frame.to_uint8()
        assert np.any(image != image[0, 0]), f"{path.name}: an empty picture"
    assert list(tmp_path.iterdir()) == []  # examples leave no files behind
