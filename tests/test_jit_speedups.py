"""The bit-set liveness that replaces numba's computes exactly what numba's own does.

Compared block by block on the IR of real functions (splinecast's render hooks, numba's
inlined kernels, and generated functions with loops, branches and redefinitions), after the
passes that change the IR most: SSA reconstruction and inlining.
"""

from __future__ import annotations

import random

import numba
import pytest
from numba.core import analysis, ir_utils
from numba.core.compiler import run_frontend
from numba.parfors import parfor

import splinecast._jit.speedups as speedups


def test_numba_uses_the_replacement_everywhere() -> None:
    assert speedups.numba_live_map is not None
    for module in (analysis, ir_utils, parfor):
        assert module.compute_live_map is speedups.live_variables


def _generated(seed: int):
    """A random function with nested loops, branches, early returns and reused names."""
    rng = random.Random(seed)
    names = [f"v{i}" for i in range(6)]
    lines = ["def f(a, b, n):", "    v0 = a", "    v1 = b"]

    def block(depth: int, indent: str) -> None:
        for _ in range(rng.randint(1, 4)):
            kind = rng.random()
            x, y, z = rng.choice(names), rng.choice(names[:2]), rng.choice(names[:2])
            if kind < 0.4 or depth > 2:
                lines.append(f"{indent}{x} = {y} * 2 + {z}")
            elif kind < 0.6:
                lines.append(f"{indent}for i{depth} in range(n):")
                block(depth + 1, indent + "    ")
            elif kind < 0.8:
                lines.append(f"{indent}if {y} > {z}:")
                block(depth + 1, indent + "    ")
                lines.append(f"{indent}else:")
                block(depth + 1, indent + "    ")
            elif kind < 0.9:
                lines.append(f"{indent}while {y} < n:")
                lines.append(f"{indent}    {y} = {y} + 1")
                block(depth + 1, indent + "    ")
            else:
                lines.append(f"{indent}if {y} < 0:")
                lines.append(f"{indent}    return {z}")
    for n in names[2:]:
        lines.append(f"    {n} = a + b")
    block(0, "    ")
    lines.append("    return " + " + ".join(names))
    namespace: dict = {}
    exec("\n".join(lines), namespace)  # noqa: S102 - test input built above
    return namespace["f"]


def _both(func_ir) -> tuple[dict, dict]:
    cfg = analysis.compute_cfg_from_blocks(func_ir.blocks)
    usedefs = analysis.compute_use_defs(func_ir.blocks)
    ours = speedups.live_variables(cfg, func_ir.blocks, usedefs.usemap, usedefs.defmap)
    theirs = speedups.numba_live_map(cfg, func_ir.blocks, usedefs.usemap, usedefs.defmap)
    return ours, theirs


@pytest.mark.parametrize("seed", range(40))
def test_liveness_of_generated_functions_equals_numbas(seed: int) -> None:
    func_ir = run_frontend(_generated(seed))
    ours, theirs = _both(func_ir)
    assert ours == theirs
    assert set(ours) == set(func_ir.blocks)


def test_liveness_inside_a_whole_render_compile_equals_numbas(monkeypatch) -> None:
    """Every liveness numba asks for while compiling an inlined kernel: both answers equal."""
    calls = []

    def checked(cfg, blocks, var_use_map, var_def_map):
        ours = speedups.live_variables(cfg, blocks, var_use_map, var_def_map)
        theirs = speedups.numba_live_map(cfg, blocks, var_use_map, var_def_map)
        calls.append(ours == theirs)
        return theirs

    for module in (analysis, ir_utils, parfor):
        monkeypatch.setattr(module, "compute_live_map", checked)

    @numba.njit(inline="always")
    def hook(x, k):
        s = 0.0
        for i in range(k):
            if x[i] > 0.5:
                s += x[i]
            else:
                s -= 1.0
        return s

    @numba.njit(parallel=True)
    def kernel(x, out):
        for j in numba.prange(out.shape[0]):
            t = hook(x, j % x.shape[0])
            while t > 1.0:
                t *= 0.5
            out[j] = t

    import numpy as np

    out = np.zeros(16)
    kernel(np.linspace(0, 1, 8), out)
    assert calls and all(calls), f"{calls.count(False)} of {len(calls)} liveness answers differ"
