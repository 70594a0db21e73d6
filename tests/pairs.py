"""Which (model, mode) pairs the renderer implements today: the parametrizations of the tests that
must hold for every pair (normals and faces, clipping and cropping, multi-isosurface crossings).

The kernel rewrite ("every model in every mode") extends these lists; ``test_pairs.py`` fails
as soon as a pair outside them starts to render, as a reminder to add it here so the tests cover
it.
"""

from __future__ import annotations

#: Every reconstruction model, by its ``Scene(model=...)`` name.
ALL_MODELS = ("trilinear", "bspline1", "bspline2", "bspline3", "qss", "s31")

#: Render modes (``"multi-iso"`` is ``mode="iso"`` with a list of isovalues).
ALL_MODES = ("iso", "multi-iso", "mip", "minip", "dvr")

#: mode -> models whose kernels exist for it: every model renders in every mode.
MODELS_FOR_MODE: dict[str, list[str]] = {mode: list(ALL_MODELS) for mode in ALL_MODES}


def pairs(*modes: str) -> list[tuple[str, str]]:
    """``(model, mode)`` for the implemented pairs of ``modes`` (all modes by default)."""
    return [(model, mode) for mode in (modes or ALL_MODES) for model in MODELS_FOR_MODE[mode]]
