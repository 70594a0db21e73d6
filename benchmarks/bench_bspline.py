"""B-spline isosurface benchmark: Steinberger 2010's tables 3.1, 3.2 and 6.2 on the CPU.

1. Composition (table 3.1): tri-cubic cell polynomial composed with random ray segments in
   scaled Bernstein form, power form and term-by-term ("naive"); time per composition (including
   the per-cell transform) and error against a long-double evaluation of the same cell
   polynomial, relative to the largest coefficient.
2. Root finders (table 3.2): degree-9 profiles from real rays through Marschner–Lobb whose control
   polygon crosses zero; time per polynomial, mean squared and maximum error of the first root
   against mpmath (60 digits), misses and false hits.
3. Frames per second (table 6.2) for degree 1, 2, 3 at 1024x768 on Marschner–Lobb 128^3, the
   MNI152 MRI (if present) and noise 256^3, and our ratio to the thesis' 4.6 / 2.8 / 1.5 fps
   (256^3 CT "Foot", GTX 285, 2009).

Run ``python benchmarks/bench_bspline.py [--quick]``; results go to
``benchmarks/results/bspline[_quick].json`` and ``.md``. Medians after warm-up.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import mpmath
import numpy as np
from numba import njit

import splinecast as sc
from splinecast.models.bspline import POWER_MATRIX, SB_MATRIX, SCALE, BSpline3Model, cell_transform
from splinecast.models.bspline_ray import (
    axis_basis_power,
    axis_basis_sb,
    compose,
    compose_naive,
    segment_polynomial,
)
from splinecast.roots.bernstein import bernstein_to_power
from splinecast.roots.first_root import DEFAULT_ITERATIONS, ROOT_FINDERS, first_root_by_id

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import MRI, describe, median_ms  # noqa: E402

HERE = Path(__file__).resolve().parent
THESIS_FPS = {1: 4.6, 2: 2.8, 3: 1.5}



# ------------------------------------------------------------------------------ composition
@njit(cache=False)
def _compose_all(coeffs, cells, seg, form, out):
    tensor = np.empty((4, 4, 4))
    tmp = np.empty((4, 4, 4))
    bx = np.empty((4, 4))
    by = np.empty((4, 4))
    bz = np.empty((4, 4))
    inner = np.empty(4)
    middle = np.empty(7)
    term = np.empty(10)
    for m in range(cells.shape[0]):
        i, j, k = cells[m, 0], cells[m, 1], cells[m, 2]
        a = seg[m, 0]
        b = seg[m, 1]
        if form == 0:
            cell_transform(coeffs, i, j, k, 3, SB_MATRIX[3], tensor, tmp)
            axis_basis_sb(a[0], b[0], 3, bx)
            axis_basis_sb(a[1], b[1], 3, by)
            axis_basis_sb(a[2], b[2], 3, bz)
            compose(tensor, bx, by, bz, 3, inner, middle, out[m])
        elif form == 1:
            cell_transform(coeffs, i, j, k, 3, POWER_MATRIX[3], tensor, tmp)
            axis_basis_power(a[0], b[0], 3, bx)
            axis_basis_power(a[1], b[1], 3, by)
            axis_basis_power(a[2], b[2], 3, bz)
            compose(tensor, bx, by, bz, 3, inner, middle, out[m])
        else:
            cell_transform(coeffs, i, j, k, 3, POWER_MATRIX[3], tensor, tmp)
            compose_naive(tensor, a[0], a[1], a[2], b[0], b[1], b[2], 3, term, out[m])


def bench_composition(count: int, repeats: int) -> list[dict]:
    rng = np.random.default_rng(0)
    coeffs = rng.uniform(-1, 1, (24, 24, 24))  # random polynomial data, as in table 3.1
    cells = rng.integers(0, 21, (count, 3))
    seg = rng.random((count, 2, 3))
    s = np.linspace(0, 1, 9).astype(np.longdouble)
    # Reference: the cell polynomial in long double, evaluated at u(s) directly (no composition).
    w = np.asarray(POWER_MATRIX[3], np.longdouble) / np.longdouble(6)
    results = []
    base_ms = None
    for form, name in ((2, "naive"), (1, "power"), (0, "scaled Bernstein")):
        out = np.empty((count, 10))
        _compose_all(coeffs, cells[:2], seg[:2], form, out[:2])
        ms = median_ms(lambda form=form, out=out: _compose_all(coeffs, cells, seg, form, out),
                       repeats)
        errors = []
        for m in range(min(count, 400)):
            i, j, k = cells[m]
            ic = coeffs[i:i + 4, j:j + 4, k:k + 4].astype(np.longdouble)
            u = seg[m, 0][None, :] + s[:, None] * (seg[m, 1] - seg[m, 0])[None, :]
            pw = np.stack([np.ones_like(u), u, u * u, u * u * u], axis=-1)  # (9, 3, 4)
            basis = np.einsum("spr,ra->spa", pw, w)  # B-spline weights per axis
            ref = np.einsum("sa,sb,sc,abc->s", basis[:, 0], basis[:, 1], basis[:, 2], ic)
            poly = out[m].astype(np.longdouble) / np.longdouble(SCALE[3] ** 3)
            if form == 0:  # scaled Bernstein coefficients
                val = np.array([sum(poly[q] * x**q * (1 - x) ** (9 - q) for q in range(10))
                                for x in s])
            else:
                val = np.array([sum(poly[q] * x**q for q in range(10)) for x in s])
            errors.append(np.asarray((val - ref) / np.abs(ic).max(), np.float64))
        err = np.concatenate(errors)
        us = ms * 1e3 / count
        base_ms = base_ms or us
        results.append({"form": name, "us_per_composition": us, "time_vs_naive": us / base_ms,
                        "mse": float(np.mean(err**2)), "max_error": float(np.abs(err).max())})
        print(f"composition {name}: {us:.3f} us, mse {results[-1]['mse']:.3g}", flush=True)
    return results


# ------------------------------------------------------------------------------ root finders
@njit(cache=False)
def _solve_all(fid, polys, iterations, tol, out):
    n = polys.shape[1] - 1
    work = np.empty((n + 1, n + 1))
    degrees = np.empty(n + 1, dtype=np.int64)
    for m in range(polys.shape[0]):
        out[m] = first_root_by_id(fid, polys[m], n, iterations, tol, work, degrees)


def ray_profiles(count: int) -> np.ndarray:
    """Degree-9 control points of ML profiles whose control polygon crosses the isovalue 0.5."""
    vol = sc.demo("marschner-lobb", size=32)
    model = BSpline3Model(vol)
    rng = np.random.default_rng(1)
    n_cells = np.array(model.n_cells)
    out = []
    while len(out) < count:
        cell = rng.integers(0, n_cells)
        b = segment_polynomial(model.coefficients, 3, cell, rng.random(3), rng.random(3)) - 0.5
        if b.min() < 0 < b.max():
            out.append(b)
    return np.array(out)


def mp_first_root(power: np.ndarray) -> float:
    mpmath.mp.dps = 60
    roots = mpmath.polyroots([mpmath.mpf(float(c)) for c in power[::-1]], maxsteps=400,
                             extraprec=400)
    real = [float(mpmath.re(r)) for r in roots
            if abs(mpmath.im(r)) < 1e-25 and 0 <= mpmath.re(r) <= 1]
    return min(real) if real else np.nan


def bench_roots(count: int, repeats: int, budgets: dict[str, int]) -> list[dict]:
    bern = ray_profiles(count)
    power = np.empty_like(bern)
    for m in range(count):
        bernstein_to_power(bern[m], 9, power[m])
    # References per input form (the finders receive exactly these floats).
    ref_b = np.array([mp_first_root(p) for p in power])  # conversion error ~1e-15, negligible
    results = []
    for name, fid in ROOT_FINDERS.items():
        polys = power if name in ("sturm", "newton") else bern
        out = np.empty(count)
        for label, iterations in (("default", DEFAULT_ITERATIONS[name]), ("thesis", budgets[name])):
            _solve_all(fid, polys[:2], iterations, 1e-12, out[:2])
            ms = median_ms(lambda polys=polys, out=out, it=iterations, fid=fid:
                           _solve_all(fid, polys, it, 1e-12, out), repeats)
            both = np.isfinite(out) & np.isfinite(ref_b)
            err = np.abs(out[both] - ref_b[both])
            results.append({
                "finder": name, "budget": label, "iterations": iterations,
                "us_per_polynomial": ms * 1e3 / count,
                "mse": float(np.mean(err**2)) if err.size else 0.0,
                "max_error": float(err.max()) if err.size else 0.0,
                "misses": int(np.count_nonzero(np.isnan(out) & np.isfinite(ref_b))),
                "false_hits": int(np.count_nonzero(np.isfinite(out) & np.isnan(ref_b))),
                "polynomials": count, "with_root": int(np.isfinite(ref_b).sum()),
            })
            r = results[-1]
            print(f"{name} ({label}, {iterations}): {r['us_per_polynomial']:.3f} us, "
                  f"max {r['max_error']:.2g}, misses {r['misses']}", flush=True)
    return results


# ------------------------------------------------------------------------------ frames per second
def bench_fps(cases, size: tuple[int, int], repeats: int) -> list[dict]:
    results = []
    for label, make, iso in cases:
        vol = make()
        cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size)
        for degree in (1, 2, 3):
            scene = sc.Scene(vol, model=f"bspline{degree}")
            frame = scene.render(cam, iso=iso)  # warm-up: compilation, first touch
            ms = median_ms(lambda scene=scene, cam=cam, iso=iso: scene.render(cam, iso=iso),
                           repeats)
            fps = 1e3 / ms
            results.append({
                "volume": label, "degree": degree, "width": size[0], "height": size[1],
                "ms_per_frame": ms, "fps": fps, "thesis_fps_foot_256": THESIS_FPS[degree],
                "ratio_to_thesis": fps / THESIS_FPS[degree], "prepare_ms": scene.prepare_ms,
                "hits": frame.stats["hits"],
                "mean_cells_visited": frame.stats["mean_cells_visited"],
                "mean_cells_tested": frame.stats["mean_cells_tested"],
            })
            print(f"{label} degree {degree}: {ms:.0f} ms/frame = {fps:.2f} fps "
                  f"({fps / THESIS_FPS[degree]:.2f}x thesis)", flush=True)
    return results


def markdown(res: dict) -> str:
    m = res["machine"]
    lines = [
        "# B-spline isosurfaces: Steinberger 2010 tables 3.1, 3.2, 6.2 on the CPU", "",
        f"Machine: {m['cpu']}, {m['cores']} cores, numba {m['versions']['numba']} "
        f"({m['numba_threads']} threads). Command: `{res['command']}`. Medians after warm-up; "
        "the machine is shared, so timings are noisy.", "",
        "## Composition, tri-cubic (table 3.1)", "",
        "| form | us / composition (incl. transform) | time vs naive | MSE (rel.) | max error |",
        "|---|---|---|---|---|",
    ]
    for r in res["composition"]:
        lines.append(f"| {r['form']} | {r['us_per_composition']:.3f} | {r['time_vs_naive']:.3f} "
                     f"| {r['mse']:.3g} | {r['max_error']:.3g} |")
    lines += ["", "## Root finders, degree 9, Marschner–Lobb ray profiles (table 3.2)", "",
              "| finder | budget | iterations | us / polynomial | MSE | max error | misses | "
              "false hits |", "|---|---|---|---|---|---|---|---|"]
    for r in res["roots"]:
        lines.append(f"| {r['finder']} | {r['budget']} | {r['iterations']} | "
                     f"{r['us_per_polynomial']:.3f} | {r['mse']:.3g} | {r['max_error']:.3g} | "
                     f"{r['misses']} | {r['false_hits']} |")
    lines += ["", "## Frames per second (table 6.2)", "",
              "| volume | degree | image | ms/frame | fps | thesis fps (Foot 256^3, GTX 285) | "
              "ratio | cells visited/ray | cells tested/ray |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in res["fps"]:
        lines.append(f"| {r['volume']} | {r['degree']} | {r['width']}x{r['height']} | "
                     f"{r['ms_per_frame']:.0f} | {r['fps']:.2f} | {r['thesis_fps_foot_256']} | "
                     f"{r['ratio_to_thesis']:.2f} | {r['mean_cells_visited']:.1f} | "
                     f"{r['mean_cells_tested']:.1f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few repeats")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    quick = args.quick
    repeats = 3 if quick else 5
    # Thesis budgets for volume data (tri-cubic: 7 LR81 iterations) next to our defaults.
    budgets = {"bernstein": 7, "rfbs": 7, "sturm": 7, "newton": 7}
    cases = [("marschner-lobb 128^3", lambda: sc.demo("marschner-lobb", size=128), 0.5)]
    if MRI.exists():
        cases.append(("MNI152 T1 MRI", lambda: sc.read(MRI), 80.0))
    else:
        print(f"skipping the MRI: {MRI} not found", flush=True)
    cases.append(("noise 256^3", lambda: sc.demo("noise", size=256, seed=0), 0.5))
    size = (1024, 768)
    if quick:
        cases = [("marschner-lobb 48^3", lambda: sc.demo("marschner-lobb", size=48), 0.5),
                 ("noise 64^3", lambda: sc.demo("noise", size=64, seed=0), 0.5)]
        size = (256, 192)
    res = {"command": "python benchmarks/bench_bspline.py" + (" --quick" if quick else "")}
    res["composition"] = bench_composition(2000 if quick else 20000, repeats)
    res["roots"] = bench_roots(150 if quick else 1000, repeats, budgets)
    res["fps"] = bench_fps(cases, size, 2 if quick else 3)
    res["machine"] = describe()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "bspline_quick" if quick else "bspline"
    (out / f"{stem}.json").write_text(json.dumps(res, indent=2, default=float))
    (out / f"{stem}.md").write_text(markdown(res))
    print(markdown(res))


if __name__ == "__main__":
    main()
