"""Command-line arguments shared by the kernel diagnostics (``profile_kernel.py``,
``cycle_breakdown.py``): which comparison scene, mode, model and image size to render."""

from __future__ import annotations

import argparse

#: Modes the diagnostics render, and the name of each one's kernel parameter class (the second
#: half of a band's key in :func:`splinecast.render.driver.pair_band`'s table).
MODE_CLASSES = {"iso": "IsoMode", "mip": "MipMode", "dvr": "DvrMode"}


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--scene``, ``--mode``, ``--model`` and ``--size`` to ``parser``."""
    parser.add_argument("--scene", default="sphere SDF 128^3", help="a comparison scene label")
    parser.add_argument("--mode", choices=tuple(MODE_CLASSES), default="iso")
    parser.add_argument("--model", default="trilinear")
    parser.add_argument("--size", default="1024x768")
