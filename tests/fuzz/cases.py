"""Cases: a mutated seed with a command to run on it, or command-line options at their edges.

:func:`build_case` is deterministic in ``(run seed, case number)``: the same numbers rebuild the
same folder and command, so any case of a report can be rerun alone (``--only N``). Targets take
turns (every format, ``cli`` for the render options, ``demo`` for synthetic-volume URIs), so any
run spreads its cases evenly.
"""

from __future__ import annotations

import json
import random
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from .mutations import mutate
from .seeds import Seed

#: The image size of every render case whose size is not itself being fuzzed.
SMALL = "16x16"
CLI_TARGETS = ("cli", "demo")


@dataclass
class Case:
    """One run of the command line in its own folder."""

    number: int
    target: str
    argv: list[str]
    description: list[str]
    folder: Path
    outputs: list[str] = field(default_factory=list)  # files a successful run may write
    #: Paths this case may not open (resolved): the sentinel region, and for hostile headers
    #: also devices a header could name.
    forbidden: list[str] = field(default_factory=list)

    def summary(self) -> str:
        return f"#{self.number} [{self.target}] {' '.join(self.argv)[:160]} <- " + \
            "; ".join(self.description)[:200]


def _tf(folder: Path, lo: float, hi: float) -> str:
    if not hi > lo:
        hi = lo + 1.0
    spec = {"domain": [lo, hi], "opacity": [[lo, 0.0], [hi, 0.8]], "colormap": "viridis"}
    (folder / "tf.json").write_text(json.dumps(spec))
    return "tf.json"


#: Seeds read as multiscale pyramids (``--budget``, ``--lod``, ``--allow-missing`` apply).
PYRAMIDS = ("ome-zarr", "zarr-v2", "ome-zarr-py", "ngff-zarr", "ngff-zarr-sharded")


def _multiscale_options(seed: Seed, rng: random.Random) -> list[str]:
    """The options of pyramids and wavelet stores, at times: a brick budget, a level of detail,
    substitution of unreadable bricks allowed."""
    extra: list[str] = []
    if seed.fmt in PYRAMIDS:
        if rng.random() < 0.3:
            extra.append("--allow-missing")
        if rng.random() < 0.2:
            extra += ["--budget", rng.choice(["64KiB", "1MiB", "256MiB"])]
        if rng.random() < 0.2:
            extra += ["--lod", rng.choice(["0.25", "1", "4"])]
    elif seed.fmt == "wavelet" and rng.random() < 0.3:
        extra += ["--lod", rng.choice(["0", "0.01"])]
    return extra


def _file_command(seed: Seed, folder: Path, rng: random.Random) -> tuple[list[str], list[str]]:
    lo, hi = seed.value_range
    render = ["render", seed.main, "-o", "out.png", "--size", SMALL, "--quiet",
              *_multiscale_options(seed, rng)]
    kind = rng.choice(["info", "info", "iso", "iso", "mip", "minip", "dvr", "depth"])
    if kind == "info":
        return ["info", seed.main], []
    if kind in ("iso", "depth"):
        extra = ["--iso", f"{(lo + hi) / 2:g}"]
        if kind == "depth":
            return render + extra + ["--depth", "d.npy"], ["out.png", "d.npy"]
        return render + extra, ["out.png"]
    if kind == "dvr":
        return render + ["--mode", "dvr", "--tf", _tf(folder, lo, hi)], ["out.png"]
    return render + ["--mode", kind], ["out.png"]


# --------------------------------------------------------------------------- option scenarios
def _pick(rng: random.Random, values: list[str]) -> str:
    return rng.choice(values)


STEPS = ["0", "-1", "1e-300", "1e-6", "0.0009", "0.001", "0.01", "1e300", "inf", "nan", "1e-320",
         "4", "100"]


def _size(rng: random.Random, folder: Path) -> list[str]:
    return ["--size", _pick(rng, [
        "0x4", "4x0", "-3x4", "1x64000000", "8000x8000", "32768x1", "32769x1", "65536x65536",
        "1e3x5", "x", "5x5x5", "9" * 40 + "x1", "9" * 5000 + "x1", "1x1", "2x3", "3000x3000",
        "0x0", "nanxnan", " 16x16", "16X16", "0x10000000000", "-0x-0", "16x16x", "20x20"])]


def _camera(rng: random.Random, folder: Path) -> list[str]:
    option = rng.choice(["--fov", "--zoom", "--distance", "--azimuth", "--elevation"])
    values = {
        "--fov": ["0", "180", "-1", "inf", "nan", "1e-300", "179.9999", "1e308", "0.001", "1e-9"],
        "--zoom": ["0", "-1", "1e-300", "1e300", "inf", "nan", "1e-7", "1e7", "1e6", "1e-6"],
        "--distance": ["0", "-1", "1e-300", "1e300", "inf", "nan", "1e-9", "1e9"],
        "--azimuth": ["1e308", "-1e308", "nan", "inf", "90", "1e20"],
        "--elevation": ["1e308", "nan", "90", "-90", "89.9999999", "1e20", "-inf"],
    }[option]
    args = [option, _pick(rng, values)]
    if rng.random() < 0.3:
        args += ["--ortho"]
    return args


def _sampled(rng: random.Random, folder: Path) -> list[str]:
    mode = rng.choice(["iso", "mip", "minip"])
    args = ["--method", "sampled", "--step", _pick(rng, STEPS)]
    return args + (["--mode", mode] if mode != "iso" else ["--iso", "0.5"])


def _tf_file(rng: random.Random, folder: Path) -> str:
    choice = rng.randrange(16)
    path = folder / "tf.json"
    good = {"domain": [0, 1], "opacity": [[0, 0], [1, 0.5]], "colormap": "viridis"}
    if choice == 0:
        return "/dev/zero"
    if choice == 1:
        path.write_text("[" * 100000 + "]" * 100000)
    elif choice == 2:
        path.write_text('{"domain": [0, ' + "1" * 5000 + '], "opacity": [[0, 0], [1, 1]]}')
    elif choice == 3:
        return "nonexistent.json"
    elif choice == 4:
        return "."
    elif choice == 5:
        path.write_text(json.dumps(good).replace("0.5", "Infinity"))
    elif choice == 6:
        path.write_text(json.dumps({**good, "opacity": [[0, 0], [1, 7]]}))
    elif choice == 7:
        path.write_text(json.dumps({**good, "domain": [1, 0]}))
    elif choice == 8:
        path.write_text(json.dumps({**good, "opacity": [[i / 1e5, 0.5] for i in range(100000)]}))
    elif choice == 9:
        path.write_text(json.dumps({**good, "colormap": [[0, 0, 0, 0]] * 3 + ["x"]}))
    elif choice == 10:
        path.write_bytes(b"")
    elif choice == 11:
        path.write_bytes(bytes(range(256)) * 10)
    elif choice == 12:
        path.write_bytes(b" " * (1 << 20) + b"{}")
    elif choice == 13:
        path.write_text(json.dumps({**good, "domain": [0, 1e308], "opacity": [[0, 0], [1e308, 1]]}))
    elif choice == 14:
        path.write_text(json.dumps({**good, "opacity": [[0, 0], [1, 0.5]] * 40000}))
    else:
        path.write_text(json.dumps({**good, "domain": [0, 1e-320]}))
    return "tf.json"


def _dvr(rng: random.Random, folder: Path) -> list[str]:
    args = ["--mode", "dvr", "--tf", _tf_file(rng, folder) if rng.random() < 0.5
            else _tf(folder, 0.0, 1.0)]
    extra = rng.choice(["step", "termination", "adaptive", "preintegration", "layout"])
    if extra == "step":
        args += ["--step", _pick(rng, STEPS)]
    elif extra == "termination":
        args += ["--termination", _pick(rng, ["0", "1", "2", "nan", "-1", "1e-300", "0.99"])]
    elif extra == "adaptive":
        args += ["--adaptive", "--step", _pick(rng, ["0.001", "0.01", "0.25", "1e-300", "8"])]
    elif extra == "preintegration":
        args += ["--preintegration", _pick(rng, ["none", "2d", "3d", "4d"])]
    else:
        args += ["--table-layout", _pick(rng, ["uniform", "exponential", "log"]),
                 "--preintegration", "3d", "--adaptive"]
    return args


def _iso(rng: random.Random, folder: Path) -> list[str]:
    values = ["nan", "inf", "1e308", "-1e308", "", ",", "0.2,0.5,0.8", "0.5," + "0.5," * 300 + "1",
              "abc", "0.5", "-0", "1e-320"]
    args = ["--iso", _pick(rng, values)]
    if rng.random() < 0.4:
        args = ["--iso", "0.2,0.5", "--opacity",
                _pick(rng, ["2,0", "nan,1", "-1,1", "0.5", "0.5,0.5,0.5", "1e308,0", "0,0"])]
    return args


def _geometry(rng: random.Random, folder: Path) -> list[str]:
    option = rng.choice(["--clip", "--crop", "--window"])
    if option == "--clip":
        value = _pick(rng, ["nan,0,0,0", "0,0,0,0", "1,2,3", "1e308,1e308,1e308,1e308",
                            "inf,0,0,0", "1,0,0,-1e300", "1e-320,0,0,0", "1,0,0,0"])
        return [option, value] * rng.choice([1, 2, 50])
    if option == "--crop":
        return [option, _pick(rng, ["0,0,0,0,0,0", "1,0,1,0,1,0", "nan,1,0,1,0,1",
                                    "-1e308,1e308,-1e308,1e308,-1e308,1e308", "1,2,3",
                                    "-1,1,-1,1,-1,1"])]
    return ["--mode", "mip", option, _pick(rng, ["1,0", "0,0", "nan,1", "-inf,inf",
                                                 "1e308,-1e308", "1", "-1e308,1e308"])]


def _model(rng: random.Random, folder: Path) -> list[str]:
    import splinecast as sc

    model = rng.choice([*sc.MODELS, "bogus", ""])
    args = ["--model", model, "--iso", "0.5"]
    extra = rng.choice(["", "iterations", "root", "prefilter"])
    if extra == "iterations":
        args += ["--iterations", _pick(rng, ["0", "-1", "1", "1000", "1001", "1000000000",
                                             "99999999999999999999", "abc"])]
    elif extra == "root":
        args += ["--root-finder", _pick(rng, ["bernstein", "rfbs", "sturm", "newton", "x"])]
    elif extra == "prefilter":
        args += ["--prefilter"]
    return args


def _effects(rng: random.Random, folder: Path) -> list[str]:
    return ["--iso", "0.5", "--texture", rng.choice(["checker", "noise"]), "--texture-scale",
            _pick(rng, ["0", "-1", "1e-300", "1e300", "nan", "0.1", "1e-9"]),
            *(["--shading", "cel"] if rng.random() < 0.5 else [])]


#: Files a render may write: the CLI's image formats and ``--depth``'s array.
OUTPUT_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".npy")


def _outputs(rng: random.Random, folder: Path) -> list[str]:
    option = rng.choice(["-o", "--depth"])
    value = _pick(rng, ["out.jpg", "no/such/dir/out.png", "x" * 300 + ".png",
                        "a/" * 2100 + "o.png", ".png", "out.png/", ".", "", "out.PNG",
                        "d.npy" if option == "--depth" else "o.png"])
    if option == "--depth" and not value.endswith(".npy") and rng.random() < 0.5:
        value = value.replace(".png", ".npy")
    return [option, value, "--iso", "0.5"]


def _smooth(rng: random.Random, folder: Path) -> list[str]:
    return ["--smooth", _pick(rng, ["3", "5", "4", "-3", "0"]), "--iso", "0.5"]


#: The render options by family; each returns extra arguments (and may write files).
SCENARIOS: list[Callable[[random.Random, Path], list[str]]] = [
    _size, _camera, _sampled, _dvr, _iso, _geometry, _model, _effects, _outputs, _smooth,
]

DEMO_URIS = [
    "demo:sphere?size=2000", "demo:sphere?size=1e400", "demo:noise?seed=-1",
    "demo:noise?seed=1e30", "demo:noise?seed=" + "9" * 30, "demo:sphere?size=1",
    "demo:sphere?size=nan", "demo:sphere?size=" + "9" * 5000, "demo:bogus", "demo:",
    "demo:sphere?x=1", "demo:sphere?size=16&size=17", "demo:sphere?size=1000",
    "demo:marschner-lobb?size=600", "demo:torus?size=12", "demo:chmutov?size=-5",
    "demo:noise?size=12&seed=3", "demo:sphere?size=0x10", "demo:sphere?size=12.5",
    "demo:" + "x" * 10000, "demo:sphere?size=16&" + "a=1&" * 2000,
]


def _joined(args: list[str]) -> list[str]:
    """``["--fov", "-1"]`` -> ``["--fov=-1"]`` for option values that start with a dash."""
    out: list[str] = []
    for arg in args:
        if out and out[-1].startswith("--") and "=" not in out[-1] and arg.startswith("-") \
                and not arg.startswith("--"):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def build_case(number: int, run_seed: int, seeds: dict[str, Seed], root: Path) -> Case:
    """Build case ``number``: its folder under ``root/cases`` and its command."""
    rng = random.Random(f"{run_seed}:{number}")
    targets = [*sorted(seeds), *CLI_TARGETS]
    target = targets[number % len(targets)]
    folder = root / "cases" / str(number)
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    sentinel_region = [str(root.resolve()), "/etc/passwd"]
    if target == "demo":
        uri = rng.choice(DEMO_URIS)
        command = rng.choice([["info", uri], ["render", uri, "-o", "out.png", "--size", SMALL,
                                             "--quiet"]])
        return Case(number, target, command, [uri[:60]], folder, ["out.png"], sentinel_region)
    if target == "cli":
        source = "v.npy"  # float32 in [0, 1]: the type every model is warmed up for
        import numpy as np

        np.save(folder / source, (np.indices((6, 5, 4)).sum(axis=0) / 12).astype(np.float32))
        base = ["render", source, "-o", "out.png", "--size", SMALL, "--quiet", "--iso", "0.5"]
        scenario = rng.choice(SCENARIOS)
        # "--opt=value", so that a value starting with "-" reaches the option, not argparse.
        extra = _joined(scenario(rng, folder))
        # A later option wins in argparse, so the fuzzed value overrides the base's default.
        argv = base + extra
        if scenario is _iso or scenario is _geometry or scenario is _sampled:
            argv = ["render", "demo:sphere?size=10", "-o", "out.png", "--size", SMALL,
                    "--quiet"] + extra
        # What a successful run may write: the image (argparse keeps the last -o, in any of
        # the CLI's image formats) and a depth array.
        outputs = ["out.png", *[a.split("=", 1)[-1] for a in extra
                                if a.lower().endswith(OUTPUT_SUFFIXES)]]
        return Case(number, target, argv, [scenario.__name__.strip("_")], folder, outputs,
                    sentinel_region)
    seed = seeds[target]
    for path in seed.folder.iterdir():
        if path.is_dir():
            shutil.copytree(path, folder / path.name, symlinks=True)
        else:
            shutil.copy(path, folder / path.name, follow_symlinks=False)
    description = mutate(folder, seed, rng, root)
    argv, outputs = _file_command(seed, folder, rng)
    forbidden = [*sentinel_region, "/dev/zero", "/proc/self/mem"]
    return Case(number, target, argv, description, folder, outputs, forbidden)
