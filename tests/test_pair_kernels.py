"""The per-(model, mode) kernels of the render driver: hooks inlined into copies of the one loop.

* The specialized band renders exactly what the generic loop (every hook a call through its
  overload) renders: same hits, depths, normals, colours and per-ray counters.
* A second process loads the pair's band and the image loop that calls it (one for every pair,
  taking the band as a first-class function) from numba's on-disk cache instead of compiling
  them, and their index files are saved under splinecast's lock (``_LockedIndexFile``).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast.render import driver


def test_pair_kernel_equals_generic_loop(monkeypatch):
    vol = sc.demo("marschner-lobb", size=20)
    cam = sc.Camera.orbit(vol, azimuth=31, elevation=17, size=(37, 29))
    scene = sc.Scene(vol, model="trilinear")
    fast = scene.render(cam, iso=0.5)
    assert (type(scene.model.kernel_grid()), sc.render.iso.IsoMode) in driver._KERNELS
    monkeypatch.setattr(driver, "pair_band", lambda grid_class, mode_class:
                        driver._trace_band)
    slow = scene.render(cam, iso=0.5)
    assert np.isfinite(slow.depth).sum() > 50  # the surface is in view
    np.testing.assert_array_equal(fast.depth, slow.depth)
    np.testing.assert_array_equal(fast.normal, slow.normal)
    np.testing.assert_array_equal(fast.rgba, slow.rgba)
    for a, b in zip((fast.cells_visited, fast.cells_tested, fast.blocks_skipped),
                    (slow.cells_visited, slow.cells_tested, slow.blocks_skipped), strict=True):
        np.testing.assert_array_equal(a, b)


_RENDER = textwrap.dedent("""
    import json
    import splinecast as sc
    from splinecast.render import driver
    vol = sc.demo("marschner-lobb", size=20)
    cam = sc.Camera.orbit(vol, azimuth=31, elevation=17, size=(37, 29))
    sc.Scene(vol, model="trilinear").render(cam, iso=0.5)
    report = {}
    kernel = driver._trace_image
    for (g, m), band in driver._KERNELS.items():
        report[g.__name__ + "/" + m.__name__] = {
            "misses": sum(kernel.stats.cache_misses.values())
                      + sum(band.stats.cache_misses.values()),
            "hits": sum(kernel.stats.cache_hits.values()) + sum(band.stats.cache_hits.values()),
            "index": type(kernel._cache._cache_file).__name__,
            "path": kernel._cache._cache_path,
        }
    print(json.dumps(report))
""")


def test_second_process_loads_pair_kernels_from_cache():
    # splinecast's own cache folder: the first run compiles the pair only if nothing did before
    # (the suite's other tests usually have), the second must load it.
    def run() -> dict:
        proc = subprocess.run([sys.executable, "-c", _RENDER], capture_output=True, text=True,
                              timeout=1200)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return json.loads(proc.stdout.strip().splitlines()[-1])

    first = run()
    assert set(first) == {"TrilinearGrid/IsoMode"}
    second = run()["TrilinearGrid/IsoMode"]
    assert second["misses"] == 0 and second["hits"] >= 1, second  # loaded, not compiled
    assert second["index"] == "_LockedIndexFile"
    names = {p.name for p in Path(second["path"]).glob("*.nbi")}
    assert any(n.startswith("driver._trace_band__TrilinearGrid_IsoMode") for n in names), names
    assert any(n.startswith("driver._trace_image-") for n in names), names
