"""The one place that says how splinecast compiles its kernels.

``error_model="numpy"`` makes a float division by zero give inf/NaN as in numpy instead of raising,
which removes a branch from every division in the hot loops; the kernels handle those values
explicitly. ``cache=True`` stores compiled code on disk so only the first run compiles.
``nogil=True`` releases the GIL while compiled code runs, so a server (the browser viewer) can
render in a worker thread while its event loop keeps answering.

Several processes often compile the same kernels at once: the workers of a Dask ``LocalCluster``,
two viewers, the test suite run in parallel. Numba's on-disk index of a function is then not safe:
two processes that save at the same moment can pick the same data-file name, and the index can end
up naming the other process's code for a signature, which would be loaded and called with the
wrong types. Every splinecast function therefore saves through :class:`_LockedIndexFile`, which
holds an exclusive lock on the index while it saves and writes the data file before the index
entry that names it. Loading needs no lock: both files are replaced atomically by numba; a file
damaged some other way (cut short, overwritten) reads as missing and is rewritten. And a
process about to compile a signature another process is compiling waits for it and loads its
result instead of compiling the same code at the same time (:func:`_compile_lock`).

Compiling is slow mostly because of inlining (the render hooks are inlined at Numba's IR level, see
:func:`overload_jit`); :mod:`.speedups` removes the largest avoidable parts of numba's own
work on such large functions.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import hashlib
import os
import pickle
import threading
import time
import types
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import numba
import numpy as np
from numba import njit
from numba._dispatcher import compute_fingerprint
from numba.core import event as _event
from numba.core import sigutils
from numba.core.compiler_lock import global_compiler_lock
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.core.types import WrapperAddressProtocol
from numba.extending import overload

from . import speedups  # noqa: F401 - installs the speed-ups before anything compiles

try:  # POSIX; elsewhere saving keeps numba's own (unlocked) behaviour
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

try:
    from numba.core.caching import IndexDataCacheFile
except ImportError:  # pragma: no cover - a numba without this class: keep its behaviour
    IndexDataCacheFile = None  # type: ignore[assignment,misc]

try:  # prints only under NUMBA_DEBUG_CACHE, like numba's own cache messages
    from numba.core.caching import _cache_log
except ImportError:  # pragma: no cover
    def _cache_log(msg: str, *args: Any) -> None:
        pass

#: Marks an index written by :class:`_LockedIndexFile` (each key pickled on its own).
_INDEX_FORMAT = "splinecast-keys-1"

__all__ = ["jit", "overload_jit", "inlined", "rebound", "first_class", "call_with_first_class",
           "call_with_first_classes", "bind_first_class", "bind_first_classes", "package_stamp",
           "reporting_compiles", "CompileNeeded", "forbidding_compiles",
           "collecting_only_new_objects", "read_only"]


_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}


@contextlib.contextmanager
def _locked(path: str) -> Iterator[None]:
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


if IndexDataCacheFile is not None and fcntl is not None:

    class _LockedIndexFile(IndexDataCacheFile):
        """Numba's index-and-data cache file, saved under a lock, data before index, each key
        of the index decoded on its own; a file that cannot be decoded counts as missing."""

        # Numba unpickles the index and data files as they are: a file cut short (a full disk,
        # a killed process on a file system without atomic replace, a copied-over install) or
        # overwritten raises from the unpickler at every call of the kernel, in every later
        # process, until someone deletes the file by hand. Such a file holds nothing usable,
        # so it is read as an empty index or an absent entry: the kernel compiles as if the
        # cache were empty and the next save writes valid files over the damaged ones. Errors
        # of the file system itself (OSError) still propagate as in numba: they are not about
        # the content, and numba already treats a missing data file as a miss.
        #
        # Numba pickles the whole index as one dictionary whose keys hold the argument types.
        # The generic kernels (the image loop, the cut renderer's launch) take the grid and
        # mode types of every model and mode they were called with, including models that a
        # user registers in a script: a process that cannot import that script cannot unpickle
        # the index at all, read it as empty, and its next save wrote an index holding only its
        # own entry, dropping every other process's kernels (they were compiled again, for
        # minutes, by the next process that needed them). So each key is pickled on its own
        # (:data:`_INDEX_FORMAT`): a key this process cannot decode is kept as bytes, written
        # back unchanged, and its data file is never reused for another key.

        def _load_index(self) -> dict:
            self._undecoded: dict[bytes, str] = {}
            try:
                with open(self._index_path, "rb") as fh:
                    version = pickle.load(fh)
                    payload = fh.read()
            except FileNotFoundError:
                return {}
            except OSError:
                raise
            except Exception as exc:  # anything the unpickler raises on arbitrary bytes
                _cache_log("[cache] unreadable index %r ignored: %r", self._index_path, exc)
                return {}
            if version != (self._version, _INDEX_FORMAT):
                return {}  # numba's own format or another version: stale, rewritten on save
            try:
                stamp, entries = pickle.loads(payload)
                if stamp != self._source_stamp or not isinstance(entries, dict):
                    return {}
                overloads = {}
                undecoded = {}
                for raw, name in entries.items():
                    try:
                        overloads[pickle.loads(raw)] = name
                    except Exception:  # a type from a module this process does not have
                        undecoded[raw] = name
            except Exception as exc:
                _cache_log("[cache] unreadable index %r ignored: %r", self._index_path, exc)
                return {}
            self._undecoded = undecoded
            return overloads

        def _save_index(self, overloads: dict) -> None:
            entries = dict(getattr(self, "_undecoded", {}))
            entries.update((self._dump(key), name) for key, name in overloads.items())
            payload = self._dump((self._source_stamp, entries))
            with self._open_for_write(self._index_path) as fh:
                pickle.dump((self._version, _INDEX_FORMAT), fh, protocol=-1)
                fh.write(payload)

        def _load_data(self, name: str) -> Any:
            try:
                return super()._load_data(name)
            except OSError:
                raise
            except Exception as exc:
                _cache_log("[cache] unreadable data %r ignored: %r", name, exc)
                return None

        def flush(self) -> None:
            self._undecoded = {}
            self._save_index({})

        def save(self, key: Any, data: Any) -> None:
            with _locked(self._index_path + ".lock"):
                overloads = self._load_index()
                name = overloads.get(key)
                if name is None:
                    taken = set(overloads.values()) | set(self._undecoded.values())
                    number = 1
                    while self._data_name(number) in taken:
                        number += 1
                    name = self._data_name(number)
                self._save_data(name, data)
                overloads[key] = name
                self._save_index(overloads)
else:  # pragma: no cover
    _LockedIndexFile = None  # type: ignore[assignment,misc]


#: The folder of the splinecast package, whose sources :func:`package_stamp` covers.
PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def package_stamp(root: str) -> tuple:
    """Name, modification time and size of every ``.py`` file under ``root``, as one tuple.

    Numba stamps a function's cache with its own source file only. A splinecast kernel inlines
    functions of many modules (a render driver inlines every hook of its model and mode), so
    after an edit of ``models/bspline_ray.py`` the driver's cached kernels would still load
    with the old model code inside, silently. Every splinecast cache therefore carries this
    stamp of the whole package too: a change to any module recompiles every kernel once.
    """
    entries = []
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                st = os.stat(path)
                entries.append((os.path.relpath(path, root), st.st_mtime_ns, st.st_size))
    return tuple(entries)


_PACKAGE_STAMP: list[tuple] = []


#: Lock files this process holds (a compile that re-enters itself must not wait for itself).
_HELD: set[str] = set()


def _compile_lock_path(index_path: str, args: tuple) -> str:
    """The lock file of one signature: next to the function's cache index, named by a digest
    of the argument types (whose text is the same in every process)."""
    digest = hashlib.sha1(str(args).encode()).hexdigest()[:16]
    return f"{index_path}.{digest}.compiling"


def _compile_lock(index_path: str, args: tuple, stack: contextlib.ExitStack) -> bool:
    """Take the lock of compiling ``args`` for the function whose cache index is
    ``index_path``, shared by all processes, into ``stack``; False if the cache folder cannot
    be written (then nothing is saved either, and nothing is locked).

    A render kernel takes a minute to compile. Processes that start at once (the test suite's
    workers, a Dask cluster's workers, two viewers) often need the same kernel at about the
    same time and each compiled it: two cores busy for one result. Under the lock, the second
    process waits and then finds the first one's code in the disk cache (numba looks there
    before compiling). The lock is taken inside numba's own compiler lock, so threads of one
    process never wait for each other on it; nested compiles take locks in the order of the
    call graph, which has no cycles, so two processes cannot wait for each other.
    """
    path = _compile_lock_path(index_path, args)
    if path in _HELD:  # an outer compile of this process holds it
        return True
    try:
        stack.enter_context(_locked(path))
    except OSError:
        return False
    stack.callback(_HELD.discard, path)
    _HELD.add(path)
    return True


#: Open scopes of :func:`collecting_only_new_objects`, in any thread (they nest; the
#: outermost one's exit releases what they froze).
_SCOPES = [0]
_SCOPES_LOCK = threading.RLock()
#: CPU seconds of a compile after which its scope collects at once (:func:`_prepared`).
_COLLECT_AFTER = 2.0


@contextlib.contextmanager
def collecting_only_new_objects(collect_after: float | None = None) -> Iterator[None]:
    """Keep Python's cyclic garbage collector to the objects made inside the block.

    A compile makes millions of short-lived objects, and the full collections they trigger each
    walked the whole heap: every object of the process, the code of every kernel compiled
    before included. That was 13-14% of a cold first frame (trilinear iso: 3.9 of 30.5 s of
    CPU; adding s31 iso: 11.5 of 84 s) and more in a process that compiles many kernels; a
    failed command line collects after itself and walked it too. Frozen (:func:`gc.freeze`),
    what existed before the block is left out of those walks (the young garbage of what ran
    before is collected first: it is not to be kept).

    Scopes nest (a compile inside a command): an inner one freezes again, so what the outer
    block made so far joins the frozen objects, and leaves them frozen; the outermost releases
    everything (:func:`gc.unfreeze`) when it ends, and it is collected as before. Objects a
    program froze itself, outside any scope, are left alone: no scope freezes or releases then.

    Parameters
    ----------
    collect_after : float, optional
        CPU seconds after which the end of the block collects at once: the objects made inside
        it (an inner scope), or the garbage that waited among the frozen ones (the outermost),
        so a long block does not leave the peak memory higher.
    """
    with _SCOPES_LOCK:
        ours = _SCOPES[0] > 0 or gc.get_freeze_count() == 0
        if ours:
            gc.collect(1)
            gc.freeze()
            _SCOPES[0] += 1
    start = time.process_time()
    try:
        yield
    finally:
        if ours:
            with _SCOPES_LOCK:
                _SCOPES[0] -= 1
                if _SCOPES[0] == 0:
                    gc.unfreeze()
            if collect_after is not None and time.process_time() - start > collect_after:
                gc.collect()


class CompileNeeded(RuntimeError):
    """Raised under :func:`forbidding_compiles` where a kernel would have to be compiled."""


#: Per thread: how many :func:`forbidding_compiles` blocks are open.
_FORBIDDEN = threading.local()


@contextlib.contextmanager
def forbidding_compiles() -> Iterator[None]:
    """In this thread, load kernels from memory or the on-disk cache only: a kernel that would
    have to be compiled raises :class:`CompileNeeded` instead (before any work on it).

    The viewer renders under it, so a new model or mode never stops the frames: it prepares
    the kernels on another thread while the page goes on showing what is ready. Covers the
    functions made with :func:`jit` (every splinecast kernel); other threads are unaffected.
    """
    _FORBIDDEN.depth = getattr(_FORBIDDEN, "depth", 0) + 1
    try:
        yield
    finally:
        _FORBIDDEN.depth -= 1


def _load_or_refuse(dispatcher: Any, sig: Any, args: tuple) -> Any:
    """The entry point of ``sig`` from memory or the disk cache, as numba's own
    ``Dispatcher.compile`` finds it before it compiles; :class:`CompileNeeded` otherwise."""
    with global_compiler_lock:
        existing = dispatcher.overloads.get(args)
        if existing is not None:
            return existing.entry_point
        cres = dispatcher._cache.load_overload(sig, dispatcher.targetctx)
        if cres is None:
            name = getattr(dispatcher.py_func, "__qualname__", "kernel")
            raise CompileNeeded(f"{name} needs compiling for {args}")
        if not cres.objectmode:
            dispatcher.targetctx.insert_user_function(cres.entry_point, cres.fndesc,
                                                      [cres.library])
        dispatcher.add_overload(cres)
        return cres.entry_point


def _lock_cache(dispatcher: Any) -> str | None:
    """Make ``dispatcher``'s disk cache safe for several processes and stale-proof; returns
    its index path where compiles can be locked across processes (else None)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if _LockedIndexFile is not None and type(cache_file) is IndexDataCacheFile:
        # Same state, safer ``save``: the subclass adds only what each index load sets.
        cache_file.__class__ = _LockedIndexFile
    if cache_file is not None and hasattr(cache_file, "_source_stamp"):
        if not _PACKAGE_STAMP:
            _PACKAGE_STAMP.append(package_stamp(PACKAGE_ROOT))
        cache_file._source_stamp = (cache_file._source_stamp, _PACKAGE_STAMP[0])
    if fcntl is not None and cache_file is not None and hasattr(cache_file, "_index_path"):
        return cache_file._index_path
    return None


def _prepared(dispatcher: Any) -> Any:
    """``dispatcher`` with its cache made safe (:func:`_lock_cache`) and its compiles wrapped:
    a signature already compiled goes straight to numba; a new one is compiled under numba's
    compiler lock, :func:`collecting_only_new_objects` (nested compiles are inner scopes of the
    outermost) and, for a cached function, the lock shared by processes
    (:func:`_compile_lock`), or only loaded from the disk cache under
    :func:`forbidding_compiles`."""
    index_path = _lock_cache(dispatcher)
    original = dispatcher.compile

    def compile(sig: Any) -> Any:  # noqa: A001 - the dispatcher's own method name
        args, _ = sigutils.normalize_signature(sig)
        args = tuple(args)
        if args in dispatcher.overloads:
            return original(sig)
        with global_compiler_lock, collecting_only_new_objects(_COLLECT_AFTER):
            if index_path is None:
                return original(sig)
            if getattr(_FORBIDDEN, "depth", 0):
                return _load_or_refuse(dispatcher, sig, args)
            with contextlib.ExitStack() as stack:
                _compile_lock(index_path, args, stack)
                return original(sig)

    dispatcher.compile = compile
    return dispatcher


def read_only(value: Any) -> Any:
    """``value`` as a read-only view (no copy) when it is a writable array, else unchanged.

    Numba compiles a separate specialization for a read-only array (a memory-mapped file, a
    cached or broadcast array) and a writable one of the same type. A compiled function that
    only reads an argument, handed read-only views always, compiles once for both.
    """
    if isinstance(value, np.ndarray) and value.flags.writeable:
        value = value.view()
        value.flags.writeable = False
    return value


def jit(function: Callable | None = None, **options: Any) -> Any:
    """Decorator for every compiled function in splinecast (accepts ``njit`` keyword arguments).

    Used bare (``@jit``) or with options (``@jit(parallel=True)``), like ``numba.njit``.
    """
    settings = {**_OPTIONS, **options}
    if function is None:
        return lambda f: _prepared(njit(**settings)(f))
    return _prepared(njit(**settings)(function))


def overload_jit(stub: Callable, inline: str = "never") -> Any:
    """``numba.extending.overload`` with splinecast's error model.

    An overload's implementation is compiled with its own options, not its caller's: without
    ``error_model="numpy"`` every division in it gets a zero check and an exception path, which
    also keeps LLVM from inlining it. ``inline="always"`` inlines it into the caller at Numba's
    IR level (the render hooks: their arguments are long tuples that a real call would copy).
    """
    return overload(stub, jit_options={"error_model": "numpy", "nogil": True}, inline=inline)


_INLINED: dict[Any, Any] = {}


def inlined(dispatcher: Any) -> Any:
    """The Python function behind ``dispatcher`` as a ``jit(inline="always")`` function.

    Numba inlines such a function into its caller at IR level, before type inference: no call
    remains, so nothing is copied and no reference count changes at the call. One wrapper per
    function is kept so every specialization refers to the same object.
    """
    py_func = dispatcher.py_func
    wrapper = _INLINED.get(py_func)
    if wrapper is None:
        wrapper = _INLINED[py_func] = jit(py_func, inline="always")
    return wrapper


def rebound(dispatcher: Any, bindings: dict[str, Any], suffix: str, **options: Any) -> Any:
    """A compiled copy of ``dispatcher``'s function whose global names ``bindings`` override.

    The copy has the same code and options (``options`` override them) and the qualified name
    ``<name>__<suffix>``: numba's on-disk cache names its index file after the qualified name,
    so each copy is cached on its own (keys of one index are signatures, which copies with
    different bindings may share).
    """
    f = dispatcher.py_func
    namespace = {**f.__globals__, **bindings}
    copy = types.FunctionType(f.__code__, namespace, f.__name__, f.__defaults__, f.__closure__)
    copy.__qualname__ = f"{f.__qualname__}__{suffix}"
    copy.__module__ = f.__module__
    copy.__doc__ = f.__doc__
    copy.__kwdefaults__ = f.__kwdefaults__
    settings = {k: v for k, v in dispatcher.targetoptions.items() if k != "nopython"}
    return jit(copy, **{**settings, **options})


class _FirstClass(WrapperAddressProtocol):
    """One compiled signature of a splinecast function as a Numba first-class function value:
    numba types it by its signature and calls it through the address of its C wrapper."""

    def __init__(self, address: int, signature: Any) -> None:
        self._address = address
        self._signature = signature

    def __wrapper_address__(self) -> int:
        return self._address

    def signature(self) -> Any:
        return self._signature


_FIRST_CLASS: dict[tuple[Any, tuple], _FirstClass] = {}


def first_class(dispatcher: Any, argtypes: tuple) -> Any:
    """``dispatcher`` compiled for ``argtypes``, as a value a compiled function takes and calls.

    Why: a compiled function that calls another links the callee's code into its own, and numba
    optimizes and translates the linked whole again at every level; a parallel function does so
    twice (its loop body is a library of its own). Passed as a first-class function instead, the
    callee is called through its address: its caller compiles without it, and one generic caller
    serves every callee of the same signature (the parallel image loop of :mod:`.render.driver`
    takes each (model, mode) pair's band so). The call is an indirect call per invocation, so
    it suits callees that do much work per call.

    ``argtypes`` are Numba types (``numba.typeof`` of the arguments); the callee is compiled
    (or loaded from the disk cache) for them if it is not yet.
    """
    key = (dispatcher, argtypes)
    value = _FIRST_CLASS.get(key)
    if value is None:
        _compile_taking_first_class(dispatcher, argtypes)  # it may take some itself
        result = dispatcher.overloads[argtypes]
        address = result.library.get_pointer_to_function(result.fndesc.llvm_cfunc_wrapper_name)
        value = _FIRST_CLASS[key] = _FirstClass(address, result.signature)
    return value


def _compile_taking_first_class(dispatcher: Any, argtypes: tuple) -> None:
    """Compile (or load) ``dispatcher`` for ``argtypes``, some of them first-class functions,
    without numba's warning that first-class function types are experimental: splinecast
    uses them knowingly (:func:`first_class`) and a user cannot act on the warning."""
    if argtypes in dispatcher.overloads:
        return
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=NumbaExperimentalFeatureWarning)
        dispatcher.compile(argtypes)


def _fingerprint(value: Any) -> Any:
    """Numba's own key of a value's type (what its dispatcher looks compiled code up by); values
    it has none for (typed containers, strings) give their Numba type."""
    try:
        return compute_fingerprint(value)
    except NotImplementedError:
        numba_type = getattr(value, "_numba_type_", None)
        return numba_type if numba_type is not None else numba.typeof(value)


#: (kernel, callee, argument fingerprints) -> (the callee's first-class value, the kernel's
#: compiled entry point for those types).
_CALLS: dict[tuple, tuple[Any, Any]] = {}


def call_with_first_class(kernel: Any, callee: Any, callee_types: Callable[[tuple], tuple],
                          args: tuple) -> Any:
    """``kernel(callee, *args)`` with ``callee`` passed as a first-class function
    (:func:`first_class`) compiled for ``callee_types(kinds)``, ``kinds`` being the Numba types
    of ``args``.

    The types are worked out once per callee and argument types, found again by numba's own
    fingerprint of the arguments, and the kernel's compiled code is called directly: numba's
    dispatcher cannot fingerprint a first-class value and would type every argument in Python
    at each call (0.7 ms per render of a small image, against 0.1 ms for all the rest).
    """
    return bind_first_class(kernel, callee, callee_types, args)()


def bind_first_class(kernel: Any, callee: Any, callee_types: Callable[[tuple], tuple],
                     args: tuple) -> Callable[[], Any]:
    """:func:`call_with_first_class` made ready but not called: a function of no arguments
    that runs ``kernel(callee, *args)``, to run it on several threads at once
    (:func:`splinecast._jit.work_queue.run_on_threads`)."""
    key = (kernel, callee, tuple(_fingerprint(a) for a in args))
    entry = _CALLS.get(key)
    if entry is None:
        kinds = tuple(numba.typeof(a) for a in args)
        value = first_class(callee, callee_types(kinds))
        argtypes = (numba.typeof(value), *kinds)
        _compile_taking_first_class(kernel, argtypes)
        entry = _CALLS[key] = (value, kernel.overloads[argtypes].entry_point)
    value, compiled = entry
    return functools.partial(compiled, value, *args)


def call_with_first_classes(kernel: Any, make_values: Callable[[tuple], tuple],
                            args: tuple) -> Any:
    """``kernel(*values, *args)`` with ``values = make_values(kinds)``, first-class functions
    (:func:`first_class`) made from the Numba types ``kinds`` of ``args``.

    As :func:`call_with_first_class`, for a kernel that takes several functions whose types
    depend on one another (a tile function taking the bands it calls); ``make_values`` must be
    one function for every call (a module-level one), as it is part of the key the values and
    the kernel's compiled entry point are found again by.
    """
    return bind_first_classes(kernel, make_values, args)()


def bind_first_classes(kernel: Any, make_values: Callable[[tuple], tuple],
                       args: tuple) -> Callable[[], Any]:
    """:func:`call_with_first_classes` made ready but not called (as
    :func:`bind_first_class`)."""
    key = (kernel, make_values, tuple(_fingerprint(a) for a in args))
    entry = _CALLS.get(key)
    if entry is None:
        kinds = tuple(numba.typeof(a) for a in args)
        values = tuple(make_values(kinds))
        argtypes = (*(numba.typeof(v) for v in values), *kinds)
        _compile_taking_first_class(kernel, argtypes)
        entry = _CALLS[key] = (values, kernel.overloads[argtypes].entry_point)
    values, compiled = entry
    return functools.partial(compiled, *values, *args)


class _CompileReporter(_event.Listener):
    """Numba's compile events of one thread, reduced to the outermost compiles."""

    def __init__(self, thread: int, on_start: Callable[[str], None],
                 on_end: Callable[[str, float], None]) -> None:
        self.thread = thread
        self._report_start, self._report_end = on_start, on_end
        self.depth = 0
        self.began = 0.0

    @staticmethod
    def _name(ev: Any) -> str:
        dispatcher = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
        py_func = getattr(dispatcher, "py_func", None)
        return getattr(py_func, "__qualname__", "kernel")

    def on_start(self, ev: Any) -> None:  # type: ignore[override]
        if threading.get_ident() != self.thread:
            return
        if self.depth == 0:
            self.began = time.perf_counter()
            self._report_start(self._name(ev))
        self.depth += 1

    def on_end(self, ev: Any) -> None:  # type: ignore[override]
        if threading.get_ident() != self.thread:
            return
        self.depth -= 1
        if self.depth == 0:
            self._report_end(self._name(ev), time.perf_counter() - self.began)


@contextlib.contextmanager
def reporting_compiles(on_start: Callable[[str], None],
                       on_end: Callable[[str, float], None]) -> Iterator[None]:
    """Report the kernels this thread compiles while the block runs.

    ``on_start(name)`` is called when an outermost compile begins (a kernel not in memory and
    not in the on-disk cache; loading from the cache reports nothing) and ``on_end(name,
    seconds)`` when it ends; compiles nested in it are part of it. Front ends use it to say
    that a wait is a one-time compile, and only then.
    """
    reporter = _CompileReporter(threading.get_ident(), on_start, on_end)
    _event.register("numba:compile", reporter)
    try:
        yield
    finally:
        _event.unregister("numba:compile", reporter)
