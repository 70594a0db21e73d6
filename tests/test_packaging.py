"""The wheel: built with ``python -m build``, installed into a fresh virtual environment, run.

This is what a user gets from ``pip install splinecast``: nothing of the source tree or of the
development environment is visible to the installed copy. pip's cache keeps the install quick.
"""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
from PIL import Image

import splinecast as sc

ROOT = Path(__file__).resolve().parents[1]


def run(cmd: list[str], cwd: Path, **kw) -> subprocess.CompletedProcess:
    # Outside the project (cwd) and without PYTHONPATH, so only the installed copy can be found.
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    result = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, **kw)
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout}\n{result.stderr}"
    return result


def test_wheel_installs_into_a_fresh_environment_and_renders(tmp_path):
    dist = tmp_path / "dist"
    run([sys.executable, "-m", "build", "--wheel", "--outdir", str(dist), str(ROOT)], cwd=tmp_path)
    wheels = list(dist.glob("splinecast-*.whl"))
    assert len(wheels) == 1
    assert wheels[0].name.startswith(f"splinecast-{sc.__version__}-")
    names = zipfile.ZipFile(wheels[0]).namelist()
    assert "splinecast/py.typed" in names  # PEP 561: type checkers use our hints
    assert "splinecast/io/vtkimage.py" in names and not any(n.startswith("tests/") for n in names)

    env = tmp_path / "env"
    run([sys.executable, "-m", "venv", str(env)], cwd=tmp_path)
    python, cli = env / "bin" / "python", env / "bin" / "splinecast"
    run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
         str(wheels[0])], cwd=tmp_path)
    version = run([str(cli), "--version"], cwd=tmp_path).stdout.strip()
    assert version == f"splinecast {sc.__version__}"
    where = run([str(python), "-c", "import splinecast; print(splinecast.__file__)"],
                cwd=tmp_path).stdout.strip()
    assert Path(where).is_relative_to(env)  # the installed copy, not the source tree

    png = tmp_path / "sphere.png"
    out = run([str(cli), "render", "demo:sphere?size=16", "--size", "24x20", "-o", str(png)],
              cwd=tmp_path)
    assert out.stdout.strip() == str(png.resolve())
    image = np.asarray(Image.open(png))
    assert image.shape == (20, 24, 4)
    assert np.any(image != image[0, 0])  # the sphere is drawn
