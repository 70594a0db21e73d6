"""Where a frame's time goes inside the compiled pixel loop: an instruction-level profile.

Numba's machine code has no symbols a profiler can see, so this tool finds them itself. A worker
process renders a comparison scene (``benchmarks/compare/scenes.py``) once, looks up the
compiled band of the scene's (model, mode) pair (:func:`splinecast.render.driver.pair_band`),
copies its machine code out of the process's memory, and then renders ``--frames`` frames under
``perf record`` (the ``cpu-clock`` event, which works in virtual machines without hardware
counters). The parent counts the sampled instruction addresses that fall in that code,
disassembles it with ``objdump`` and writes:

* ``<out>.md``: the share of all samples spent in the band's code, the code split at its
  ``ret`` instructions (the band and the functions LLVM kept out of line, such as the cubic's
  root refinement), the hottest 256-byte windows and the hottest instructions;
* ``<out>.asm.txt``: the whole disassembly with a sample count per instruction (a few hundred
  kB, machine-specific: git ignores it).

Reading the hot windows against the source is manual (the code has no line table), but the
shares answer the questions a missed speed target raises: how much is the walk, the root
refinement, the background writes. Needs ``perf`` and ``objdump`` (``scripts/install_profiling.sh``)
and a kernel that lets perf sample (``perf_event_paranoid`` at most 2 for one's own process).

The frame time it reports is inflated by perf's sampling (about 1.5x at 20 kHz here); the
shares are what to read. Example (one thread, so the samples are the frame's own work)::

    python benchmarks/tools/profile_kernel.py --scene "sphere SDF 128^3" --mode iso --frames 200
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "benchmarks" / "tools"))
from _kernel_args import MODE_CLASSES, add_scene_arguments  # noqa: E402

#: Largest stretch of code copied from the process, from the band's entry point (the band
#: and the functions compiled with it; the copy stops earlier at the end of the mapping).
CODE_BYTES = 1 << 18


def _worker(args: argparse.Namespace) -> None:

    import splinecast as sc
    from benchmarks.compare.runner import _camera
    from benchmarks.compare.scenes import by_label
    from splinecast.render import driver

    spec = by_label(args.scene)
    vol = spec.make()
    scene = sc.Scene(vol, model=args.model)
    kwargs = {"iso": spec.isos[0]} if args.mode == "iso" else {"mode": args.mode}
    size = tuple(int(v) for v in args.size.split("x"))
    cams = [_camera(vol, size, a) for a in (40.0, 50.0, 60.0, 70.0)]
    for cam in cams:
        scene.render(cam, **kwargs, outputs=("rgba",))
    wanted = MODE_CLASSES[args.mode]
    # DVR's default sampling ("ray") runs the fixed-step loop under a class of its own.
    found = [(key, disp) for key, disp in driver._KERNELS.items()
             if key[1].__name__ in (wanted, wanted.replace("Mode", "RayMode"))]
    if not found:
        raise SystemExit(f"profile_kernel: no compiled band for mode {args.mode!r}")
    key, disp = found[0]
    cres = next(iter(disp.overloads.values()))
    address = cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)
    end = address + CODE_BYTES
    with open("/proc/self/maps") as maps:
        for line in maps:
            lo, hi = (int(v, 16) for v in line.split()[0].split("-"))
            if lo <= address < hi:
                end = min(end, hi)
    Path(args.work, "code.bin").write_bytes(ctypes.string_at(address, end - address))
    start = time.perf_counter()
    for i in range(args.frames):
        scene.render(cams[i % len(cams)], **kwargs, outputs=("rgba",))
    frame_ms = (time.perf_counter() - start) * 1e3 / args.frames
    info = {"address": address, "length": end - address, "pair": [k.__name__ for k in key],
            "frame_ms": frame_ms, "threads": _threads()}
    Path(args.work, "info.json").write_text(json.dumps(info))


def _threads() -> int:
    import numba

    return numba.get_num_threads()


def _annotate(work: Path) -> tuple[dict, list[tuple[int, int, str]]]:
    """Sample counts per instruction of the copied code: (info, [(count, offset, text)])."""
    info = json.loads((work / "info.json").read_text())
    address = info["address"]
    script = subprocess.run(["perf", "script", "-i", str(work / "perf.data"), "-F", "ip"],
                            capture_output=True, text=True, check=True).stdout
    ips = collections.Counter(int(v, 16) for v in script.split())
    info["samples"] = sum(ips.values())
    dump = subprocess.run(["objdump", "-D", "-b", "binary", "-m", "i386:x86-64",
                           "--no-show-raw-insn", f"--adjust-vma={address:#x}",
                           str(work / "code.bin")], capture_output=True, text=True,
                          check=True).stdout
    rows = []
    for line in dump.splitlines():
        match = re.match(r"\s+([0-9a-f]+):\s+(.*)", line)
        if match:
            at = int(match.group(1), 16)
            rows.append((ips.get(at, 0), at - address, match.group(2).strip()))
    return info, rows


def _report(info: dict, rows: list[tuple[int, int, str]], args: argparse.Namespace) -> str:
    in_code = sum(c for c, _, _ in rows)
    share = (lambda n: f"{100.0 * n / in_code:.1f}%") if in_code else (lambda n: "-")
    lines = [f"# Instruction-level profile: {args.scene}, {args.mode}, {args.model}", "",
             f"Command: `python benchmarks/tools/profile_kernel.py --scene \"{args.scene}\" --mode "
             f"{args.mode} --model {args.model} --frames {args.frames} --size {args.size}`; "
             f"band of {' x '.join(info['pair'])}, {info['threads']} Numba thread(s), "
             f"{info['frame_ms']:.1f} ms per frame under perf.", "",
             f"Samples: {info['samples']} in all, {in_code} "
             f"({100.0 * in_code / max(info['samples'], 1):.1f}%) in the band's code.", "",
             "## The code split at its `ret` instructions (at least 0.3% of its samples)", "",
             "| offsets | samples | share |", "|---|---|---|"]
    start, count = 0, 0
    for c, offset, text in rows:
        count += c
        if text.startswith("ret"):
            if count >= 0.003 * in_code:
                lines.append(f"| {start:#x}-{offset:#x} | {count} | {share(count)} |")
            start, count = offset + 1, 0
    windows: collections.Counter = collections.Counter()
    for c, offset, _ in rows:
        windows[offset // 256] += c
    lines += ["", "## Hottest 256-byte windows", "", "| window | samples | share |",
              "|---|---|---|"]
    lines += [f"| {w * 256:#x} | {c} | {share(c)} |" for w, c in windows.most_common(15)]
    lines += ["", "## Hottest instructions (a sample lands on the instruction after a slow one)",
              "", "| offset | samples | instruction |", "|---|---|---|"]
    for c, offset, text in sorted(rows, key=lambda r: -r[0])[:25]:
        lines.append(f"| {offset:#x} | {c} | `{text}` |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_arguments(parser)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--out", default=None,
                        help="output stem (default: benchmarks/results/profile_<mode>_<scene>)")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        args.work = args.worker
        _worker(args)
        return
    missing = [tool for tool in ("perf", "objdump") if shutil.which(tool) is None]
    if missing:
        raise SystemExit(f"profile_kernel: {', '.join(missing)} not found; "
                         "run scripts/install_profiling.sh")
    slug = re.sub(r"[^a-z0-9]+", "_", args.scene.lower()).strip("_")
    out = Path(args.out or REPO / "benchmarks" / "results" / f"profile_{args.mode}_{slug}")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(REPO / "src"), str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])}
    with tempfile.TemporaryDirectory() as work:
        command = [sys.executable, __file__, "--worker", work, "--scene", args.scene,
                   "--mode", args.mode, "--model", args.model, "--size", args.size]
        # A first run fills Numba's cache, so the profiled one samples frames, not compilation.
        subprocess.run([*command, "--frames", "1"], env=env, check=True)
        run = subprocess.run(["perf", "record", "-q", "-e", "cpu-clock", "-F", "20000", "-o",
                              str(Path(work, "perf.data")), "--", *command, "--frames",
                              str(args.frames)], env=env)
        if run.returncode != 0 or not Path(work, "info.json").exists():
            raise SystemExit(f"profile_kernel: the profiled run failed (exit {run.returncode})")
        info, rows = _annotate(Path(work))
    out.parent.mkdir(parents=True, exist_ok=True)
    Path(f"{out}.md").write_text(_report(info, rows, args))
    Path(f"{out}.asm.txt").write_text(
        "".join(f"{c:7d} {offset:#8x}: {text}\n" for c, offset, text in rows))
    print(f"wrote {out}.md and {out}.asm.txt")


if __name__ == "__main__":
    main()
