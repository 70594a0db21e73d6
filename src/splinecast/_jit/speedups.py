"""Faster numba compiles of very large functions: replacements for three slow spots of numba.

splinecast's render kernels are large: every model's and mode's hooks are inlined into one pixel
loop at numba's IR level (:func:`splinecast._jit.overload_jit`), so one kernel reaches thousands of
IR blocks and variables. Several of numba's own passes grow with blocks x variables there, and
together they took about half of a kernel's compile time. This module replaces three of them with
code that computes exactly the same result more cheaply; each is installed at import only if the
numba in use has the shape it was written for, and otherwise numba keeps its own behaviour.

- :class:`_CopyModuleSharingScopes`: the copies numba makes of each inlined function.
- :func:`_compare_flags_cheaply`: the hash and comparison of compiler flags at every overload typed.
- :func:`live_variables`: the liveness analysis numba runs after every rewrite.
"""

from __future__ import annotations

import copy
import functools
from typing import Any

__all__ = ["live_variables"]


class _CopyModuleSharingScopes:
    """Stands in for the ``copy`` module inside ``numba.core.inline_closurecall``.

    Numba copies the IR of every function it inlines block by block, one ``copy.deepcopy`` per
    block, and each of those copies the function's whole variable scope again (a ``Var`` holds
    its scope): the cost is blocks x variables. Our hooks, inlined into one another, reach
    thousands of both, and those copies took about a fifth of a render kernel's compile time
    (s31 iso from an empty cache: 68 s -> 53 s). While one ``inline_ir`` runs, this object gives
    the blocks of one function a shared memo, so the scope is copied once per function copy,
    which is what one ``deepcopy`` of the whole IR would do. Everything else is the real module.
    """

    def __init__(self) -> None:
        self.memos: dict[int, dict] | None = None

    def deepcopy(self, x: Any, memo: dict | None = None) -> Any:
        if memo is None and self.memos is not None and isinstance(x, _ir.Block):
            # One memo per scope: the blocks of one function copy share it, while the second
            # copy numba makes (of the first) gets its own.
            memo = self.memos.setdefault(id(x.scope), {})
        return copy.deepcopy(x, memo)

    def __getattr__(self, name: str) -> Any:
        return getattr(copy, name)


def _copy_each_inlined_function_once() -> None:
    """Install :class:`_CopyModuleSharingScopes` where numba inlines (if numba is as expected)."""
    worker = getattr(_inline, "InlineWorker", None)
    inline_ir = getattr(worker, "inline_ir", None)
    if inline_ir is None or getattr(_inline, "copy", None) is not copy:
        return  # another numba version (or already installed): keep its behaviour
    shim = _CopyModuleSharingScopes()

    @functools.wraps(inline_ir)
    def inline_ir_copying_scopes_once(*args: Any, **kwargs: Any) -> Any:
        shim.memos = {}
        try:
            return inline_ir(*args, **kwargs)
        finally:
            shim.memos = None

    _inline.copy = shim
    worker.inline_ir = inline_ir_copying_scopes_once


def _compare_flags_cheaply() -> None:
    """Let numba hash and compare its compiler flags without reading every option first.

    Numba keys its cache of overload implementations by the current compiler flags and looks
    it up at every overload call it types; the flags' ``__hash__`` and ``__eq__`` each build a
    dictionary of all fifty-odd options, which showed in profiles of the cut renderer's launch
    compile. Numba's hash is of the option names only (the sorted keys of that
    dictionary), fixed per class: here it is computed from the names directly. Two flags of one
    class with equal explicitly set options are equal without building the dictionaries; any
    other pair is compared as numba does. Installed only if this numba's hash is the one
    described.
    """
    config = getattr(_targetconfig, "TargetConfig", None)
    flags_class = getattr(_compiler, "Flags", None)
    if config is None or flags_class is None or "__hash__" not in vars(config):
        return
    original_hash, original_eq = config.__hash__, config.__eq__

    def __hash__(self: Any) -> int:
        return hash(tuple(sorted(self.options)))

    def __eq__(self: Any, other: Any) -> Any:
        if type(self) is type(other) and self._values == other._values:
            return True
        return original_eq(self, other)

    probe = flags_class()
    probe.nrt = True  # a set option: equal hashes whatever the values
    if original_hash(probe) == __hash__(probe) == original_hash(flags_class()):
        config.__hash__ = __hash__
        config.__eq__ = __eq__


def live_variables(cfg: Any, blocks: dict, var_use_map: dict, var_def_map: dict) -> dict:
    """The variables live at the entry of each block: numba's ``compute_live_map``, on bit sets.

    Same contract and the same fixed points as numba's: first the variables defined or used in
    any block from which a block can be reached, then liveness pushed backwards from each use to
    the predecessors where the variable can exist and is not (re)defined. Numba iterates both
    with Python sets, blocks x variables set unions per sweep, and runs it after every IR rewrite;
    on a render kernel that came to a sixth of the compile. Here each set of variable names is a
    Python ``int`` with one bit per variable, so a union is one machine-word loop in C.

    Parameters
    ----------
    cfg : numba.core.controlflow.CFGraph
        The control-flow graph of ``blocks``.
    blocks : dict
        Block offset -> ``numba.core.ir.Block``.
    var_use_map, var_def_map : dict
        Block offset -> set of variable names used (before any definition) / defined in it.

    Returns
    -------
    dict
        Block offset -> set of variable names live at the block's entry, for every offset of
        ``blocks``.
    """
    order = cfg.topo_order()
    index: dict[str, int] = {}
    names: list[str] = []

    def bits(variables: Any) -> int:
        mask = 0
        for name in variables:
            i = index.get(name)
            if i is None:
                i = index[name] = len(names)
                names.append(name)
            mask |= 1 << i
        return mask

    defined = {b: bits(var_def_map[b]) for b in order}
    touched = {b: defined[b] | bits(var_use_map[b]) for b in order}
    successors = {b: [s for s, _ in cfg.successors(b)] for b in order}
    predecessors = {b: [p for p, _ in cfg.predecessors(b)] for b in order}

    reaching: dict[int, int] = {}  # defined or used in a block that reaches this one (or in it)
    changed = True
    while changed:
        changed = False
        for b in order:
            here = reaching.get(b, 0) | touched[b]
            reaching[b] = here
            for s in successors[b]:
                before = reaching.get(s, 0)
                if before | here != before:
                    reaching[s] = before | here
                    changed = True

    live = {b: bits(var_use_map[b]) for b in blocks}
    changed = True
    while changed:
        changed = False
        for b in reversed(order):
            here = live[b]
            for p in predecessors[b]:
                before = live[p]
                after = before | (here & reaching.get(p, 0) & ~defined.get(p, 0))
                if after != before:
                    live[p] = after
                    changed = True

    def decode(mask: int) -> set[str]:
        out = set()
        while mask:
            low = mask & -mask
            out.add(names[low.bit_length() - 1])
            mask ^= low
        return out

    return {b: decode(mask) for b, mask in live.items()}


def _install_live_variables() -> None:
    """Use :func:`live_variables` wherever numba computes liveness (if numba is as expected)."""
    original = getattr(_analysis, "compute_live_map", None)
    if original is None or original.__code__.co_varnames[:4] != (
            "cfg", "blocks", "var_use_map", "var_def_map"):
        return
    global numba_live_map
    numba_live_map = original  # kept for the tests that compare the two
    for module in (_analysis, _ir_utils, _parfor):
        if getattr(module, "compute_live_map", None) is original:
            module.compute_live_map = live_variables


#: numba's own ``compute_live_map`` once :func:`live_variables` replaces it (else ``None``).
numba_live_map: Any = None


try:
    from numba.core import inline_closurecall as _inline
    from numba.core import ir as _ir
except ImportError:  # pragma: no cover - a numba without these modules
    pass
else:
    _copy_each_inlined_function_once()

try:
    from numba.core import compiler as _compiler
    from numba.core import targetconfig as _targetconfig
except ImportError:  # pragma: no cover - a numba without these modules
    pass
else:
    _compare_flags_cheaply()

try:
    from numba.core import analysis as _analysis
    from numba.core import ir_utils as _ir_utils
    from numba.parfors import parfor as _parfor
except ImportError:  # pragma: no cover - a numba without these modules
    pass
else:
    _install_live_variables()
