"""A compile leaves the objects that existed before it out of Python's cyclic collections.

Compiling makes millions of short-lived objects, and each full collection they trigger walked
every object of the process. splinecast's compiled functions freeze what exists when a compile
starts (:func:`gc.freeze`) and unfreeze it after, unless the program froze objects itself.
"""

from __future__ import annotations

import gc
import weakref

import pytest

from splinecast._jit import jit, overload_jit


class _Cycle:
    """An object in a reference cycle: only the cycle collector frees it."""

    def __init__(self) -> None:
        self.me = self


def _probe(x):
    raise NotImplementedError


#: What the probe saw while it was typed, inside a compile.
_SEEN: list[dict] = []


@overload_jit(_probe)
def _probe_impl(x):
    before = _SEEN[-1]["before"]
    # Made inside the compile: garbage the compile's own collections may free.
    inside = weakref.ref(_Cycle())
    gc.collect()
    _SEEN[-1].update(frozen=gc.get_freeze_count(), before_alive=before() is not None,
                     inside_alive=inside() is not None)

    def impl(x):
        return x + 1

    return impl


def _new_kernel():
    """A new compiled function, so that every call of a test compiles."""
    @jit(cache=False)
    def kernel(x):
        return _probe(x)

    return kernel


@pytest.fixture
def collector_held():
    """No automatic collection during the test: only the ones it asks for run."""
    enabled = gc.isenabled()
    gc.disable()
    yield
    gc.unfreeze()
    if enabled:
        gc.enable()


def test_a_compile_collects_its_own_garbage_and_leaves_older_objects_alone(collector_held):
    assert gc.get_freeze_count() == 0
    before = weakref.ref(_Cycle())  # garbage from before the compile,
    gc.freeze()
    gc.unfreeze()  # moved to the oldest generation (the young ones are collected first)
    _SEEN.append({"before": before})
    assert _new_kernel()(1) == 2
    seen = _SEEN.pop()
    assert seen["frozen"] > 0  # what existed was frozen during the compile
    assert seen["before_alive"]  # so a collection inside it did not walk it
    assert not seen["inside_alive"]  # while the compile's own garbage was freed
    assert gc.get_freeze_count() == 0  # and everything is collectable again after it
    gc.collect()
    assert before() is None


def test_a_program_that_froze_objects_keeps_them_frozen(collector_held):
    gc.freeze()
    frozen = gc.get_freeze_count()
    _SEEN.append({"before": weakref.ref(_Cycle())})
    assert _new_kernel()(2) == 3
    _SEEN.pop()
    # (a frozen object whose last reference goes is still freed: allow for a few)
    assert frozen * 0.99 < gc.get_freeze_count() <= frozen


def test_a_compile_inside_a_scope_freezes_what_the_scope_made(collector_held):
    from splinecast._jit import collecting_only_new_objects

    with collecting_only_new_objects():
        at_start = gc.get_freeze_count()
        assert at_start > 0
        made = [_Cycle() for _ in range(1000)]  # made inside the outer scope
        _SEEN.append({"before": weakref.ref(made[0])})
        assert _new_kernel()(3.5) == 4.5  # a float: typed anew (the int's typing is kept)
        seen = _SEEN.pop()
        # The compile froze what the scope had made, so its collections did not walk it ...
        assert seen["frozen"] >= at_start + len(made)
        assert not seen["inside_alive"]
        # ... and left it frozen for the outer scope to release.
        assert gc.get_freeze_count() >= at_start + len(made)
    assert gc.get_freeze_count() == 0
