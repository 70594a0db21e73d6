"""Run cases in forked children of a warmed-up parent and classify what happened.

The parent imports splinecast, every reader library and compiles (or loads) every kernel once
(:func:`warm_up`); each case then runs in a ``fork`` of it, so a case costs milliseconds instead of
an interpreter start and a kernel load. Numba must use its fork-safe ``workqueue`` threading
layer with one thread (set by :mod:`fuzz.run` before numba is imported): the kernels are the same,
only the thread pool differs.

A child runs ``splinecast.cli.main(argv)`` in the case folder with

* ``SPLINECAST_MAX_BYTES`` set (the memory guard must refuse anything larger),
* an address-space cap (``RLIMIT_AS``) a few times that size above the parent's, so an allocation
  that slipped past the guard fails as ``MemoryError`` instead of taking the machine,
* an audit hook (:func:`sys.addaudithook`) that records every file it opens outside the case
  folder in the fuzzing root (the sentinel, other cases) or naming ``/etc/passwd`` and devices,
* stdout and stderr (also at the file-descriptor level) sent to log files outside the folder.

Numba compiles a kernel per voxel type: a case whose volume has a type the warm-up did not
compile would spend its time compiling. With ``compile="skip"`` (the short run of the test
suite) such a case stops at the first compilation and counts as ``skipped-compile``; with
``compile="allow"`` (``make fuzz``) it compiles, the time spent compiling does not count towards
the timeout (up to ``compile_timeout``), and the result lands in numba's disk cache for the next
cases.

Outcomes, worst first: ``outside-read``, ``crash`` (killed by a signal), ``hang`` (killed at the
timeout), ``memory`` (``MemoryError``, or a peak resident size above the allowance),
``unhandled`` (any other exception, or an exit status other than 0 and 2), ``left-behind`` (a
file the run should not have left in the folder), ``noise`` (status 2 with more than the one
``splinecast: error:`` line, or status 0 with stderr lines that are not splinecast warnings), then
the two good ones, ``accepted`` and ``clean-error``.
"""

from __future__ import annotations

import contextlib
import faulthandler
import io
import os
import resource
import shutil
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

from .cases import PYRAMIDS, Case

GOOD = ("accepted", "clean-error", "skipped-compile")
BAD = ("outside-read", "crash", "hang", "memory", "unhandled", "left-behind", "noise",
       "harness-error")
OUTCOMES = GOOD + BAD
_UNHANDLED_STATUS = 70
_MEMORY_STATUS = 71
_COMPILE_STATUS = 72
#: Voxel types whose kernels the warm-up compiles for every render mode, read-only and writable
#: (float32 also for every model): the types the seeds read as.
WARM_DTYPES = ("float32", "uint16", "int16")


@dataclass
class Result:
    """What one case did."""

    number: int
    target: str
    outcome: str
    seconds: float
    peak_mib: float
    summary: str
    detail: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def _vm_bytes(key: str) -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return 0


# --------------------------------------------------------------------------- the parent
def warm_up(seed_mains: list[tuple[Path, str]], models: Iterable[str]) -> None:
    """Import the readers and compile every kernel the cases use, once, in the parent."""
    import numpy as np

    import splinecast as sc
    from splinecast.cli import main

    from .seeds import WAVELET_MAIN

    argv_list: list[list[str]] = []
    for folder, main_name in seed_mains:
        argv_list.append(["info", str(folder / main_name)])
    with _quiet_directory() as out:
        tf = out / "tf.json"
        sc.TransferFunction([[0, 0], [1, 0.5]], (0, 1)).save(tf)
        pyramids = [(f, m) for f, m in seed_mains if f.name in PYRAMIDS][:1]
        for folder, main_name in pyramids:
            # A pyramid renders through the cut renderer (bricks of its own voxel type): every
            # mode of the cases, once, coarse and fine.
            render = ["render", str(folder / main_name), "--size", "8x8", "--quiet", "-o",
                      str(out / "p.png")]
            argv_list += [render + ["--iso", "60"], render + ["--mode", "mip"],
                          render + ["--mode", "minip", "--lod", "0.25"],
                          render + ["--mode", "dvr", "--tf", str(tf)],
                          render + ["--iso", "60", "--depth", str(out / "d.npy"), "--lod", "4"]]
        for folder, main_name in seed_mains:
            if main_name != WAVELET_MAIN:
                continue
            # A wavelet store renders through the cut renderer and its reconstruction kernels,
            # which no in-memory volume compiles: every mode of the cases, once.
            render = ["render", str(folder / main_name), "--size", "8x8", "--quiet", "-o",
                      str(out / "w.png")]
            argv_list += [render + ["--iso", "60"], render + ["--mode", "mip"],
                          render + ["--mode", "minip"], render + ["--mode", "dvr", "--tf", str(tf)],
                          render + ["--iso", "60", "--depth", str(out / "d.npy")]]
        # Kernels are compiled per voxel type. A memory-mapped file (.npy) and a decoded one
        # (.npz) share them (grids are handed over as read-only views); both are still read
        # here so the readers' own compiled helpers are loaded in the parent too.
        sources = ["demo:sphere?size=10"]
        for dtype in WARM_DTYPES:
            data = (np.indices((6, 5, 4)).sum(axis=0) % 2).astype(dtype)
            np.save(out / f"{dtype}.npy", data)
            np.savez(out / f"{dtype}.npz", data=data)
            sources += [str(out / f"{dtype}.npy"), str(out / f"{dtype}.npz")]
        for source in sources:
            render = ["render", source, "--size", "8x8", "--quiet", "-o", str(out / "w.png")]
            argv_list += [render + ["--iso", "0.5"], render + ["--mode", "mip"],
                          render + ["--mode", "minip"],
                          render + ["--mode", "dvr", "--tf", str(tf)],
                          render + ["--iso", "0.5", "--depth", str(out / "d.npy")]]
        render = ["render", sources[0], "--size", "8x8", "--quiet", "-o", str(out / "w.png")]
        argv_list += [
            render + ["--mode", "dvr", "--tf", str(tf), "--adaptive"],
            render + ["--mode", "dvr", "--tf", str(tf), "--preintegration", "none"],
            render + ["--mode", "dvr", "--tf", str(tf), "--preintegration", "3d",
                      "--table-layout", "exponential", "--adaptive"],
            render + ["--iso", "0.2,0.5"], render + ["--iso", "0.5", "--method", "sampled"],
            render + ["--mode", "mip", "--method", "sampled"],
            render + ["--mode", "minip", "--method", "sampled"],
            render + ["--iso", "0.5", "--texture", "noise", "--shading", "cel"],
            render + ["--iso", "0.5", "--texture", "checker"],
            render + ["--iso", "0.5", "--smooth", "3"], render + ["--iso", "0.5", "--smooth", "5"],
            render + ["--iso", "0.5", "--ortho"],
        ]
        for model in models:
            argv_list.append(render + ["--iso", "0.5", "--model", model])
            argv_list.append(render + ["--iso", "0.5", "--model", model, "--prefilter"])
            for finder in ("bernstein", "rfbs", "sturm", "newton"):
                argv_list.append(render + ["--iso", "0.5", "--model", model,
                                           "--root-finder", finder])
        saved = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = io.StringIO()
        try:
            for argv in argv_list:
                main(argv)
        finally:
            sys.stdout, sys.stderr = saved
    for module in ("PIL.PngImagePlugin", "pydicom.pixels", "nrrd", "nibabel", "tifffile"):
        with contextlib.suppress(ImportError):
            __import__(module)


@contextlib.contextmanager
def _quiet_directory() -> Iterator[Path]:
    import tempfile

    with tempfile.TemporaryDirectory(prefix="splinecast-warm-") as name:
        yield Path(name)


def _snapshot(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@dataclass
class _Running:
    case: Case
    start: float
    before: set[str]
    killed: bool = False


class Runner:
    """Forks one child per case, at most ``workers`` at a time, and classifies them.

    Parameters
    ----------
    root : Path
        The fuzzing root (seeds, cases, logs, the sentinel).
    workers : int
        Children running at once.
    timeout : float
        Seconds after which a child is killed and the case called a hang.
    max_bytes : int
        ``SPLINECAST_MAX_BYTES`` of the children.
    compile : {"skip", "allow"}
        What a child does when numba starts compiling (see the module notes).
    compile_timeout : float
        Seconds a compilation may take with ``compile="allow"``.
    entry : callable, optional
        What a child runs with the case's arguments (default ``splinecast.cli.main``; the
        harness's own tests pass misbehaving functions to check every verdict).
    """

    def __init__(self, root: Path, workers: int = 2, timeout: float = 60.0,
                 max_bytes: int = 256 << 20, compile: str = "skip",
                 compile_timeout: float = 900.0,
                 entry: Callable[[list[str]], int] | None = None) -> None:
        if compile not in ("skip", "allow"):
            raise ValueError(f"compile must be 'skip' or 'allow', got {compile!r}")
        self.compile = compile
        self.compile_timeout = compile_timeout
        self.entry = entry
        self.root = root
        self.workers = max(1, workers)
        self.timeout = timeout
        self.max_bytes = max_bytes
        self.logs = root / "logs"
        self.logs.mkdir(parents=True, exist_ok=True)
        # Children start as a copy of this process: allow the cap several times over (a reader
        # may hold the file's bytes and the volume at once) plus room for thread stacks.
        self.address_space = _vm_bytes("VmSize") + 4 * max_bytes + (768 << 20)
        self.peak_allowance = _vm_bytes("VmRSS") + 4 * max_bytes

    def run(self, cases: Iterable[Case | Result], keep: bool = False) -> Iterator[Result]:
        """Run every case; yields results as children finish."""
        queue = iter(cases)
        running: dict[int, _Running] = {}
        exhausted = False
        last_check = 0.0
        while running or not exhausted:
            while not exhausted and len(running) < self.workers:
                item = next(queue, None)
                if item is None:
                    exhausted = True
                    break
                if isinstance(item, Result):  # the case could not even be built
                    yield item
                    continue
                before = _snapshot(item.folder)
                pid = os.fork()
                if pid == 0:  # pragma: no cover - the child never returns
                    self._child(item)
                running[pid] = _Running(item, time.monotonic(), before)
            pid, status, usage = os.wait4(-1, os.WNOHANG) if running else (0, 0, None)
            if pid == 0:
                now = time.monotonic()
                if now - last_check > 0.2:
                    last_check = now
                    for child, state in running.items():
                        if not state.killed and now > self._deadline(state):
                            os.kill(child, signal.SIGKILL)
                            state.killed = True
                time.sleep(0.002)
                continue
            state = running.pop(pid)
            result = self._classify(state, status, usage)
            if result.outcome in GOOD and not keep:
                shutil.rmtree(state.case.folder, ignore_errors=True)
                for suffix in (".out", ".err", ".audit", ".compile"):
                    (self.logs / f"{state.case.number}{suffix}").unlink(missing_ok=True)
            yield result

    def _deadline(self, state: _Running) -> float:
        """When the child is called hung: time spent compiling does not count."""
        deadline = state.start + self.timeout
        marks = self.logs / f"{state.case.number}.compile"
        try:
            lines = marks.read_text().split()
            since = marks.stat().st_mtime - time.time() + time.monotonic()
        except OSError:
            return deadline
        compiling = lines.count("start") > lines.count("end")
        return max(deadline, since + (self.compile_timeout if compiling else self.timeout))

    # ----------------------------------------------------------------------- the child
    def _child(self, case: Case) -> None:  # pragma: no cover - runs in the fork
        code = _UNHANDLED_STATUS
        opened: list[str] = []
        try:
            os.chdir(case.folder)
            out = os.open(self.logs / f"{case.number}.out", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            err = os.open(self.logs / f"{case.number}.err", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(out, 1)
            os.dup2(err, 2)
            sys.stdout = open(1, "w", closefd=False, buffering=1)  # noqa: SIM115
            sys.stderr = open(2, "w", closefd=False, buffering=1)  # noqa: SIM115
            faulthandler.enable(file=sys.stderr)  # a crash's Python stack goes to the case log
            os.environ["SPLINECAST_MAX_BYTES"] = str(self.max_bytes)
            os.environ.pop("SPLINECAST_ALLOW_EXTERNAL_DATA", None)
            resource.setrlimit(resource.RLIMIT_AS, (self.address_space, self.address_space))
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
            _watch_compilation(self.logs / f"{case.number}.compile", self.compile)
            sys.addaudithook(_audit(case, opened, self.logs))
            if self.entry is None:
                from splinecast.cli import main
            else:
                main = self.entry

            try:
                code = main(list(case.argv))
            except SystemExit as exc:  # argparse: one line and status 2
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
            except MemoryError:
                traceback.print_exc()
                code = _MEMORY_STATUS
            except BaseException:
                traceback.print_exc()
                code = _UNHANDLED_STATUS
        finally:
            try:
                sys.stdout.flush()
                sys.stderr.flush()
                if opened:
                    (self.logs / f"{case.number}.audit").write_text("\n".join(opened))
            finally:
                os._exit(code if isinstance(code, int) else _UNHANDLED_STATUS)

    # ----------------------------------------------------------------------- the verdict
    def _classify(self, state: _Running, status: int, usage: resource.struct_rusage) -> Result:
        case = state.case
        seconds = time.monotonic() - state.start
        peak = usage.ru_maxrss * 1024 if usage is not None else 0
        err_path, out_path = (self.logs / f"{case.number}{s}" for s in (".err", ".out"))
        err = err_path.read_text(errors="replace") if err_path.exists() else ""
        out = out_path.read_text(errors="replace") if out_path.exists() else ""
        audit = self.logs / f"{case.number}.audit"

        def result(outcome: str, detail: str = "") -> Result:
            return Result(case.number, case.target, outcome, round(seconds, 3),
                          round(peak / 2**20, 1), case.summary(), detail[-2000:])

        if audit.exists():
            return result("outside-read", audit.read_text()[:1000])
        if os.WIFSIGNALED(status):
            if state.killed:
                return result("hang", f"killed after {self.timeout:g} s")
            return result("crash", f"signal {os.WTERMSIG(status)}\n{err}")
        code = os.WEXITSTATUS(status)
        if code == _COMPILE_STATUS:
            for path in case.folder.rglob(".*.part"):  # stopped mid-run: not the code's fault
                path.unlink()
            return result("skipped-compile")
        if code == _MEMORY_STATUS or peak > self.peak_allowance:
            return result("memory", f"peak {peak / 2**20:.0f} MiB\n{err}")
        if code not in (0, 2):
            return result("unhandled", err)
        after = _snapshot(case.folder)
        allowed = set(case.outputs) if code == 0 else set()
        extra = sorted(after - state.before - allowed)
        if extra:
            return result("left-behind", ", ".join(extra)[:500])
        lines = [line for line in err.splitlines() if line.strip()]
        if code == 2:
            if len(lines) != 1 or not lines[0].startswith("splinecast: error: ") or out:
                return result("noise", err)
            return result("clean-error", lines[0])
        if any(not line.startswith("splinecast: warning: ") for line in lines):
            return result("noise", err)
        if case.argv[0] == "render":
            # argparse keeps the last -o given.
            output = case.argv[len(case.argv) - 1 - case.argv[::-1].index("-o") + 1]
            if not (case.folder / output).is_file():
                return result("unhandled", f"status 0 without the output file {output}")
        return result("accepted")


def _watch_compilation(marks: Path, mode: str) -> None:  # pragma: no cover - in the fork
    """Stop the child at its first compilation ("skip"), or log compilations for the parent's
    deadline ("allow")."""
    from numba.core import event

    class Watch(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            if mode == "skip":
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(_COMPILE_STATUS)
            with open(marks, "a") as fh:
                fh.write("start\n")

        def on_end(self, ev: event.Event) -> None:
            with open(marks, "a") as fh:
                fh.write("end\n")

    event.register("numba:compile", Watch())


def _audit(case: Case, opened: list[str], logs: Path):  # noqa: ANN202 - an audit hook
    """An audit hook recording opens of forbidden paths (resolved, symlinks followed) other than
    the case folder and the harness's own log folder."""
    folder = os.path.realpath(case.folder)
    own = os.path.realpath(logs) + os.sep
    roots = [p for p in case.forbidden if os.path.isdir(p)]
    files = {os.path.realpath(p) for p in case.forbidden if not os.path.isdir(p)}
    busy = [False]

    def hook(event: str, args: tuple) -> None:
        if event != "open" or busy[0]:
            return
        path = args[0]
        if not isinstance(path, str | bytes | os.PathLike):
            return  # a file descriptor
        busy[0] = True
        try:
            real = os.path.realpath(os.fsdecode(path))
            inside = real == folder or real.startswith((folder + os.sep, own))
            forbidden = real in files or any(
                real == root or real.startswith(root.rstrip(os.sep) + os.sep) for root in roots)
            if forbidden and not inside:
                opened.append(f"{os.fsdecode(path)} -> {real}")
        except Exception:  # never let the hook itself change the outcome
            pass
        finally:
            busy[0] = False

    return hook
