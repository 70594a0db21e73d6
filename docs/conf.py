"""Sphinx configuration of the splinecast documentation (``make docs``).

Builds offline: no intersphinx, no remote images, no analytics. The gallery is ``examples/``;
sphinx-gallery runs each example and shows every :class:`splinecast.Frame` it renders (the
``frame_scraper`` below), so the pictures are always those of the current code.
``-D plot_gallery=0`` builds the pages without running the examples (the quick mode the test
suite uses; ``tests/test_examples.py`` runs the examples themselves).
"""

from __future__ import annotations

from pathlib import Path

import splinecast

project = "splinecast"
author = "the splinecast developers"
copyright = "the splinecast developers"  # noqa: A001 (Sphinx's name)
version = release = splinecast.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]
templates_path = ["_templates"]  # the class page documents its methods
exclude_patterns = ["_build", "gallery/*.ipynb", "gallery/*.py.md5", "gallery/*.zip"]

# The gallery's scraper is a function: Sphinx cannot pickle it, so every build is a full one.
suppress_warnings = ["config.cache"]
autosummary_generate = True
autodoc_typehints = "none"  # numpydoc's parameter lists already give the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

_seen: dict[str, set[int]] = {}


def frame_scraper(block, block_vars, gallery_conf):
    """Save every new splinecast Frame in the example's namespace as one of its images."""
    from sphinx_gallery.scrapers import figure_rst

    seen = _seen.setdefault(block_vars["src_file"], set())
    paths = []
    for value in list(block_vars["example_globals"].values()):
        frames = value if isinstance(value, (list, tuple)) else [value]
        for frame in frames:
            if isinstance(frame, splinecast.Frame) and id(frame) not in seen:
                seen.add(id(frame))
                path = next(block_vars["image_path_iterator"])
                frame.save(path)
                paths.append(path)
    return figure_rst(paths, gallery_conf["src_dir"])


sphinx_gallery_conf = {
    "examples_dirs": str(Path(__file__).parent.parent / "examples"),
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "image_scrapers": (frame_scraper,),
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
}

html_theme = "pydata_sphinx_theme"
html_title = f"splinecast {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_prev_next": False,
}
html_static_path: list[str] = []
