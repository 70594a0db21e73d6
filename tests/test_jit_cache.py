"""splinecast's compiled functions save numba's on-disk cache safely from several processes.

Dask workers on one machine, two viewers, or the test suite run with ``pytest -n`` compile the
same functions at the same moment. Several processes here save many cache entries of one
function at once (released together by a start time); afterwards every key of the index must name
a data file that holds that key's own data: an unlocked save can hand two keys the same file.

The cache must also survive real installs: damaged cache files are rebuilt, and a package folder
that cannot be written has its kernels cached (and locked) in the user's cache folder.
"""

from __future__ import annotations

import importlib.util
import json
import os
import pickle
import random
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

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


def _read_index(path: Path) -> dict:
    """The index file's entries, key -> data file name (each key is pickled on its own)."""
    with open(path, "rb") as fh:
        pickle.load(fh)  # numba's version and the index format
        _, entries = pickle.loads(fh.read())
    return {pickle.loads(raw): name for raw, name in entries.items()}


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
    overloads = _read_index(indexes[0])
    expected = {("proc", i, "key", j) for i in range(PROCESSES) for j in range(KEYS)}
    assert set(overloads) == expected  # no entry lost
    assert len(set(overloads.values())) == len(expected)  # one data file per key
    for key, name in overloads.items():
        with open(indexes[0].parent / name, "rb") as fh:
            data = pickle.loads(fh.read())
        assert data["payload"] == key, (key, name)


_CALLER = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import splinecast._jit as J
    if sys.argv[2] == "edited":  # as if a module of the package had been edited since
        stamp = J.package_stamp(J.PACKAGE_ROOT)
        J._PACKAGE_STAMP[:] = [stamp + (("edited.py", 1, 1),)]
    import cached_caller
    assert cached_caller.f(2) == 3
    stats = cached_caller.f.stats
    print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))
""")


def test_a_change_anywhere_in_the_package_recompiles_cached_kernels(tmp_path: Path) -> None:
    """A kernel inlines functions of other modules (a driver: its model's and mode's hooks), so
    its cache must go stale when any module of the package changes, not only its own file.

    The same cached function is compiled, loaded again, then loaded as if another module of the
    package had been edited: the third process must compile anew instead of using the cache."""
    (tmp_path / "cached_caller.py").write_text(
        "from splinecast._jit import jit\n\n@jit\ndef f(x):\n    return x + 1\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run(state: str) -> list[str]:
        out = subprocess.run([sys.executable, "-c", _CALLER, str(tmp_path), state], env=env,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout.split()

    assert run("same") == ["0", "1"]    # first run: compiled (a miss) and saved
    assert run("same") == ["1", "0"]    # unchanged package: loaded from the cache
    assert run("edited") == ["0", "1"]  # another module changed: compiled again


def test_package_stamp_follows_every_module_but_not_caches(tmp_path: Path) -> None:
    from splinecast._jit import package_stamp

    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    before = package_stamp(str(tmp_path))
    assert [e[0] for e in before] == ["a.py", os.path.join("sub", "b.py")]
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / "c.py").write_text("z = 3\n")
    (tmp_path / "notes.txt").write_text("not code\n")
    assert package_stamp(str(tmp_path)) == before
    (tmp_path / "sub" / "b.py").write_text("y = 22\n")
    assert package_stamp(str(tmp_path)) != before


_WAITER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, sys.argv[1])
    from numba import types
    import splinecast._jit as J
    import waited_module
    f = waited_module.f
    path = J._compile_lock_path(f._cache._cache_file._index_path, (types.int64,))
    if sys.argv[2] == "as-holder":  # compiles as the process that holds the lock would
        J._HELD.add(path)
    print(path, flush=True)
    sys.stdin.readline()  # the test holds the lock now
    assert f(2) == 3
    stats = f.stats
    print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()), flush=True)
""")


def _blocked_on(path: str, pid: int, timeout: float) -> bool:
    """Whether process ``pid`` comes to wait for a ``flock`` on ``path`` within ``timeout``
    seconds, as the kernel's lock table says (Linux ``/proc/locks``: a waiter's line has
    ``->`` and the file's device and inode)."""
    st = os.stat(path)
    inode = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with open("/proc/locks") as table:
            for line in table:
                fields = line.split()
                if "->" in fields and str(pid) in fields and inode in fields:
                    return True
        time.sleep(0.01)  # the lock table has no change notification: look again shortly
    return False


def test_a_process_waits_for_the_same_compile_in_another_and_loads_its_code(
        tmp_path: Path) -> None:
    """Two processes that need the same signature at once compile it once: the second waits
    for the first's lock and then loads the first's code from the disk cache.

    The test holds the signature's lock (as a process compiling it would); a waiting process
    must not finish while it does, even after a third process (acting as the lock's holder)
    has compiled and saved the code; once the lock is released, the waiting process loads
    that code instead of compiling (a cache hit, no miss)."""
    from splinecast._jit import _locked

    (tmp_path / "waited_module.py").write_text(
        "from splinecast._jit import jit\n\n@jit\ndef f(x):\n    return x + 1\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def start(role: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-c", _WAITER, str(tmp_path), role], env=env,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)

    waiter = start("waiter")
    path = waiter.stdout.readline().strip()
    assert path.endswith(".compiling"), waiter.stderr.read()[-2000:]
    with _locked(path):
        waiter.stdin.write("go\n")
        waiter.stdin.flush()
        holder = start("as-holder")
        assert holder.stdout.readline().strip() == path
        out, err = holder.communicate("go\n", timeout=300)
        assert holder.returncode == 0, err[-2000:]
        assert out.split() == ["0", "1"]  # compiled (a miss) and saved
        # The kernel lists the waiter as blocked on the lock file: it is waiting, not compiling.
        assert _blocked_on(path, waiter.pid, timeout=300), waiter.poll()
        assert waiter.poll() is None
    out, err = waiter.communicate(timeout=300)
    assert waiter.returncode == 0, err[-2000:]
    assert out.split() == ["1", "0"]  # loaded the holder's code, compiled nothing


_KERNEL = "from splinecast._jit import jit\n\n\n@jit\ndef f(x):\n    return x + 1\n"


def _import(path: Path, name: str) -> ModuleType:
    """A new module object (so new dispatchers, nothing compiled in memory) from ``path``."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _garbage(data: bytes) -> bytes:
    return random.Random(0).randbytes(len(data))


#: (file, what is done to it): the damage a cache file can take from a full disk, a killed
#: process, a copied-over or half-synchronised install.
_DAMAGES: dict[str, tuple[str, Callable[[bytes], bytes] | None]] = {
    "index-cut-to-half": ("index", lambda b: b[:len(b) // 2]),
    "index-empty": ("index", lambda b: b""),
    "index-garbage": ("index", _garbage),
    "data-cut-to-half": ("data", lambda b: b[:len(b) // 2]),
    "data-empty": ("data", lambda b: b""),
    "data-garbage": ("data", _garbage),
    "data-missing": ("data", None),  # the index names a data file that is not there
}


@pytest.mark.parametrize("damage", list(_DAMAGES))
def test_a_damaged_cache_file_is_ignored_and_rebuilt(tmp_path: Path, damage: str,
                                                     capfd: pytest.CaptureFixture) -> None:
    """A kernel whose index or data file is damaged still returns the right value: the file
    counts as a cache miss (quietly), the kernel compiles, and the save writes a valid cache
    that the next fresh dispatcher loads without compiling."""
    from splinecast._jit import CompileNeeded, forbidding_compiles

    source = tmp_path / "damaged_kernels.py"
    source.write_text(_KERNEL)
    first = _import(source, "damaged_kernels_first").f
    assert first(2) == 3  # compiled and saved
    index = Path(first._cache._cache_file._index_path)
    data = index.with_name(index.name[:-len(".nbi")] + ".1.nbc")
    assert index.is_file() and data.is_file()

    target, change = _DAMAGES[damage]
    path = index if target == "index" else data
    if change is None:
        path.unlink()
    else:
        path.write_bytes(change(path.read_bytes()))

    damaged = _import(source, "damaged_kernels_second").f
    with forbidding_compiles(), pytest.raises(CompileNeeded):
        damaged(2)  # the damaged cache is a miss, not an error
    assert damaged(2) == 3
    assert (sum(damaged.stats.cache_hits.values()), sum(damaged.stats.cache_misses.values())) \
        == (0, 1)  # compiled anew

    rebuilt = _import(source, "damaged_kernels_third").f
    with forbidding_compiles():  # would raise CompileNeeded if the cache were not valid
        assert rebuilt(2) == 3  # loaded from the rewritten cache
    assert capfd.readouterr() == ("", "")  # nothing printed about the damage


_READ_ONLY = textwrap.dedent("""
    import json, os, sys
    package = os.path.realpath(sys.argv[1])
    refused = []

    def read_only(event, args):
        # Refuses, as a read-only file system would, any change under the package folder.
        if event == "open":
            paths = [args[0]] if args[2] & (os.O_WRONLY | os.O_RDWR | os.O_CREAT) else []
        elif event == "os.rename":
            paths = [args[0], args[1]]
        elif event in ("os.mkdir", "os.remove", "os.rmdir", "os.chmod", "os.utime",
                       "os.truncate", "os.link", "os.symlink"):
            paths = [args[0]]
        else:
            return
        for path in paths:
            if isinstance(path, int):  # a file descriptor, already open
                continue
            path = os.path.realpath(os.fsdecode(path))
            if path == package or path.startswith(package + os.sep):
                refused.append(path)
                raise PermissionError(13, "Read-only file system", path)

    sys.addaudithook(read_only)
    sys.path.insert(0, os.path.dirname(package))
    from readonly_kernels.kernels import f
    assert f(2) == 3
    print(json.dumps({"cache_file": type(f._cache._cache_file).__name__,
                      "cache_path": os.path.realpath(f._cache.cache_path), "refused": refused,
                      "hits": sum(f.stats.cache_hits.values()),
                      "misses": sum(f.stats.cache_misses.values())}))
""")


def test_kernels_of_a_read_only_package_are_cached_in_the_user_cache_folder(
        tmp_path: Path) -> None:
    """An installed package whose folder cannot be written (a system-wide install used by
    another user, a read-only container image) has its kernels cached in numba's user-wide
    folder (``$XDG_CACHE_HOME/numba`` here); splinecast's saving lock and compile lock are
    taken there too, and a second process loads the kernel from there without compiling.

    How the read-only folder is simulated: the tests may run as root, for whom ``chmod 0o555``
    does not stop writes, and a read-only mount needs privileges a test does not have. Each
    process therefore installs an audit hook (``sys.addaudithook``) that refuses, with the
    ``PermissionError`` a read-only file system gives, every opening for writing, creation,
    renaming or removal under the package folder. Every file operation of numba's cache and of
    splinecast's locks goes through Python's ``open``/``os`` functions, which raise those
    audit events, so none can slip past it. The folder is also made ``0o555`` (effective for
    a user who is not root)."""
    package = tmp_path / "readonly_kernels"
    (package / "__pycache__").mkdir(parents=True)  # byte-compiled when installed, read-only
    (package / "__init__.py").write_text("")
    (package / "kernels.py").write_text(_KERNEL)
    user_cache = tmp_path / "user-cache"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(user_cache), PYTHONDONTWRITEBYTECODE="1")

    def run() -> dict:
        out = subprocess.run([sys.executable, "-c", _READ_ONLY, str(package)], env=env,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        return json.loads(out.stdout)

    folders = [package / "__pycache__", package]
    for folder in folders:
        folder.chmod(0o555)
    try:
        first = run()
        second = run()
    finally:
        for folder in folders:
            folder.chmod(0o755)

    numba_folder = os.path.realpath(user_cache / "numba")
    assert first["cache_path"].startswith(numba_folder + os.sep), first
    assert first["refused"]  # numba tried the package's __pycache__ first and was refused
    assert not [p for p in first["refused"] + second["refused"]
                if p.endswith((".nbi", ".nbc", ".lock", ".compiling"))]
    assert first["cache_file"] == "_LockedIndexFile"
    assert (first["hits"], first["misses"]) == (0, 1)   # compiled and saved
    assert (second["hits"], second["misses"]) == (1, 0)  # loaded, nothing compiled
    cached = Path(first["cache_path"])
    for pattern in ("*.nbi", "*.nbc", "*.nbi.lock", "*.compiling"):  # saved and locked there
        assert list(cached.glob(pattern)), pattern
    assert not [p for p in package.rglob("*") if p.suffix in (".nbi", ".nbc", ".lock",
                                                               ".compiling")]


def test_compiler_flags_hash_and_compare_as_numba_defines_them() -> None:
    """splinecast replaces numba's flag hashing and comparison with cheaper code
    (``_compare_flags_cheaply``); both must give what numba's definition gives: the hash of
    the sorted option names, equality of every option's value (defaults included)."""
    import itertools

    from numba.core.compiler import Flags

    import splinecast._jit  # noqa: F401 - installs the replacement

    assert "_compare_flags_cheaply" in Flags.__eq__.__qualname__  # the replacement is in use

    def make(**options: object) -> Flags:
        flags = Flags()
        for name, value in options.items():
            setattr(flags, name, value)
        return flags

    variants = [make(), make(nrt=True), make(nrt=False), make(boundscheck=False),
                make(nrt=True, boundscheck=True), make(nrt=True, error_model="numpy"),
                make(error_model="python"), make(fastmath=True), make(nrt=True)]
    for a, b in itertools.product(variants, repeat=2):
        assert hash(a) == hash(tuple(sorted(a.values())))
        assert (a == b) == (a.values() == b.values()), (a, b)


_FOREIGN_CALLER = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, sys.argv[1])
    if sys.argv[2] == "with-points":  # the script that defines its own argument type
        sys.path.insert(0, sys.argv[3])
        from points import Point
        arg = Point(2.0, 5.0)
    else:
        arg = (2.0, 5.0)  # a plain tuple: a type every process can decode
    from splinecast._jit import forbidding_compiles
    import generic_kernels
    if sys.argv[4] == "forbid":
        with forbidding_compiles():  # raises CompileNeeded instead of compiling
            value = generic_kernels.first(arg)
    else:
        value = generic_kernels.first(arg)
    f = generic_kernels.first
    print(json.dumps([value, sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values())]))
""")


def test_a_type_another_process_cannot_import_keeps_every_cached_kernel(tmp_path: Path) -> None:
    """A generic kernel (the image loop, the cut launch) is cached for the types of every model
    it was called with, also a model a user defines in a script. A process that cannot import
    that script must neither fail to read the other entries nor drop them when it saves its
    own: each process then loads what the others compiled instead of compiling it again."""
    kernels, script = tmp_path / "kernels", tmp_path / "script"
    kernels.mkdir()
    script.mkdir()
    (kernels / "generic_kernels.py").write_text(
        "from splinecast._jit import jit\n\n@jit\ndef first(p):\n    return p[0] + 1.0\n")
    (script / "points.py").write_text(
        "from collections import namedtuple\nPoint = namedtuple('Point', 'x y')\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run(kind: str, compiles: str) -> list:
        proc = subprocess.run([sys.executable, "-c", _FOREIGN_CALLER, str(kernels), kind,
                               str(script), compiles], env=env, capture_output=True, text=True,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return json.loads(proc.stdout.strip().splitlines()[-1])

    assert run("with-points", "allow") == [3.0, 0, 1]  # compiled for the script's Point
    assert run("plain", "allow") == [3.0, 0, 1]  # compiled for a tuple, beside it
    # Both entries are still there: each loads without compiling (``forbidding_compiles``
    # raises, and the process fails, where a kernel would need compiling), in a process that
    # can decode only its own type.
    assert run("with-points", "forbid")[0] == 3.0
    assert run("plain", "forbid")[0] == 3.0
    index = next((tmp_path / "cache").rglob("*.nbi"))
    with open(index, "rb") as fh:
        pickle.load(fh)
        _, entries = pickle.loads(fh.read())
    assert len(entries) == 2 and len(set(entries.values())) == 2  # two keys, two data files
