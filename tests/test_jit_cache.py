"""splinecast's compiled functions save numba's on-disk cache safely from several processes.

Dask workers on one machine, two viewers, or the test suite run with ``pytest -n`` compile the
same functions at the same moment. Several processes here save many cache entries of one
function at once (released together by a start time); afterwards every key of the index must name
a data file that holds that key's own data: an unlocked save can hand two keys the same file.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap
import time
from pathlib import Path

PROCESSES = 4
KEYS = 40

_SAVER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, sys.argv[1])
    import cached_module
    cache_file = cached_module.f._cache._cache_file
    start = float(sys.argv[3])
    while time.time() < start:
        pass
    for j in range({keys}):
        key = ("proc", int(sys.argv[2]), "key", j)
        cache_file.save(key, {{"payload": key, "pad": bytes(20000)}})
    print(type(cache_file).__name__)
""").format(keys=KEYS)


def test_concurrent_saves_keep_index_and_data_consistent(tmp_path: Path) -> None:
    (tmp_path / "cached_module.py").write_text(
        "from splinecast._jit import jit\n\n@jit\ndef f(x):\n    return x + 1\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    start = time.time() + 3.0  # after every process has imported numba
    procs = [subprocess.Popen([sys.executable, "-c", _SAVER, str(tmp_path), str(i), str(start)],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(PROCESSES)]
    outputs = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, outputs, strict=True):
        assert p.returncode == 0, err[-2000:]
        assert out.strip() == "_LockedIndexFile", out

    indexes = list((tmp_path / "cache").rglob("*.nbi"))
    assert len(indexes) == 1, indexes
    with open(indexes[0], "rb") as fh:
        pickle.load(fh)  # numba's version stamp
        _, overloads = pickle.loads(fh.read())
    expected = {("proc", i, "key", j) for i in range(PROCESSES) for j in range(KEYS)}
    assert set(overloads) == expected  # no entry lost
    assert len(set(overloads.values())) == len(expected)  # one data file per key
    for key, name in overloads.items():
        with open(indexes[0].parent / name, "rb") as fh:
            data = pickle.loads(fh.read())
        assert data["payload"] == key, (key, name)
