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
autodoc_preserve_defaults = True  # signatures show defaults as written (``MODELS``, not its repr)
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



def _help_text(command: str) -> str:
    """What ``splinecast COMMAND --help`` prints, at a fixed width (the CLI is the source)."""
    import contextlib
    import io
    import os

    from splinecast.cli import main

    out = io.StringIO()
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "96"
    try:
        with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
            main([command, "--help"])
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return out.getvalue()


# Docstrings name objects the way the code sees them: relative to their module (``:mod:`.seams```,
# ``:class:`Frame```), or through a package that re-exports them. Such a reference that Sphinx
# cannot find by name is looked up in Python and linked to the page that documents the object
# (``_resolve_by_object``). What is still missing is an error (``-n``), except the names below:
# private names, which are not documented, and other projects' objects (the build is offline,
# without intersphinx).
nitpick_ignore_regex = [
    (r"py:.*", r"(.*\.)?_[A-Za-z].*"),
    (r"py:.*", r"(os|sys|io|json|pathlib|collections|typing|numpy|np|numba|llvmlite|zarr|dask|"
               r"distributed|aiohttp|PIL|vtk|pyvista|scipy|bisect|heapq|threading|concurrent|"
               r"contextlib|dataclasses|enum|argparse|mmap|ctypes)(\..*)?"),
]

_documented_objects: dict[int, str] = {}


def _import_path(path: str):
    """The object a dotted path names, importing the longest module prefix; None if none."""
    import importlib

    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except Exception:  # noqa: BLE001 (any failure: not a module)
            continue
        try:
            for part in parts[i:]:
                obj = getattr(obj, part)
        except AttributeError:
            return None
        return obj
    return None


def _is_linkable(obj) -> bool:
    import inspect

    return (inspect.ismodule(obj) or inspect.isclass(obj) or inspect.isroutine(obj)
            or isinstance(obj, (property, dict)))


def _resolve_by_object(app, env, node, contnode):
    """Link a Python reference Sphinx did not find to the documented object it names."""
    from sphinx.util.nodes import make_refnode

    if node.get("refdomain") != "py":
        return None
    domain = env.get_domain("py")
    if not _documented_objects:
        for name in sorted(domain.objects, key=len, reverse=True):  # shortest name wins
            obj = _import_path(name)
            if obj is not None and _is_linkable(obj):
                _documented_objects[id(obj)] = name
    target = node["reftarget"].lstrip(".~")
    module = node.get("py:module") or ""
    klass = node.get("py:class") or ""
    candidates = []
    while module:
        if klass:
            candidates.append(f"{module}.{klass}.{target}")
        candidates.append(f"{module}.{target}")
        module = module.rpartition(".")[0]
    # The module of the object whose documentation holds the reference (a class method's, or a
    # top-level function's generated page) is where its docstring's names live.
    owner = _import_path(f"{node.get('py:module') or ''}.{klass}".strip(".")) if klass else None
    if owner is None and node["refdoc"].startswith("generated/"):
        owner = _import_path(node["refdoc"].partition("/")[2])
    home = getattr(owner, "__module__", None) if owner is not None else None
    if home:
        if klass:
            candidates.append(f"{home}.{getattr(owner, '__qualname__', klass)}.{target}")
        candidates.append(f"{home}.{target}")
    candidates += [target, f"splinecast.{target}"]
    for candidate in candidates:
        name = candidate if candidate in domain.objects else None
        if name is None:
            obj = _import_path(candidate)
            if obj is None:
                # An attribute set on instances: link to its documented class.
                parent = candidate.rpartition(".")[0]
                if parent in domain.objects and domain.objects[parent].objtype in (
                        "class", "exception"):
                    name = parent
                else:
                    continue
            name = _documented_objects.get(id(obj)) if _is_linkable(obj) else None
            if name is None:
                # An object without an entry of its own (a constant, a helper left out of the
                # module's __all__): link to the documented module that holds it.
                parent = candidate.rpartition(".")[0]
                while parent and parent not in domain.objects:
                    parent = parent.rpartition(".")[0]
                if not parent:
                    continue
                name = parent
        entry = domain.objects[name]
        return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                            contnode, name)
    # Last, a name that only one documented object ends with (a module's summary line, shown
    # out of its module's context).
    matches = [name for name in domain.objects if name.endswith("." + target)]
    if len(matches) == 1:
        entry = domain.objects[matches[0]]
        return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                            contnode, matches[0])
    return None


def _skip_exported(app, what, name, obj, skip, options):
    """A module page leaves out what the top-level package exports (it has its own page) and
    what it imports from another splinecast module (documented on that module's page)."""
    import splinecast

    if what != "module":
        return None
    if (isinstance(obj, type) or callable(obj)) and any(
            getattr(splinecast, public, None) is obj for public in splinecast.__all__):
        return True
    home = getattr(obj, "__module__", None)
    current = app.env.temp_data.get("autodoc:module")
    if (isinstance(home, str) and home.startswith("splinecast.") and current
            and home != current and (isinstance(obj, type) or callable(obj))):
        return True
    return None


def _numpydoc_with_one_template():
    """numpydoc's ``get_doc_object``, its docstring template compiled once per builder.

    numpydoc compiles the same Jinja template again for every object it formats, which took a
    third of this site's build; the template's text and loader do not change between objects.
    """
    import numpydoc.docscrape_sphinx as scrape
    from jinja2 import FileSystemLoader
    from jinja2.sandbox import SandboxedEnvironment
    from sphinx.jinja2glue import BuiltinTemplateLoader

    templates = {}

    def get_doc_object(obj, what=None, doc=None, config=None, builder=None):
        config = {} if config is None else config
        template = templates.get(id(builder))
        if template is None:
            dirs = [str(Path(scrape.__file__).parent / "templates")]
            if builder is not None:
                loader = BuiltinTemplateLoader()
                loader.init(builder, dirs=dirs)
            else:
                loader = FileSystemLoader(dirs)
            template = SandboxedEnvironment(loader=loader).get_template("numpydoc_docstring.rst")
            templates[id(builder)] = template
        config["template"] = template
        return scrape.get_doc_object_orig(obj, what=what, doc=doc, config=config,
                                          class_doc=scrape.SphinxClassDoc,
                                          func_doc=scrape.SphinxFunctionDoc,
                                          obj_doc=scrape.SphinxObjDoc)

    return get_doc_object


def setup(app):
    """``.. splinecast-help:: render`` includes a subcommand's ``--help`` as a literal block."""
    import numpydoc.docscrape_sphinx
    import numpydoc.numpydoc

    if hasattr(numpydoc.docscrape_sphinx, "get_doc_object_orig"):  # the numpydoc we know
        numpydoc.numpydoc.get_doc_object = _numpydoc_with_one_template()
    from docutils import nodes
    from sphinx.util.docutils import SphinxDirective

    app.connect("missing-reference", _resolve_by_object)
    app.connect("autodoc-skip-member", _skip_exported)

    class SplinecastHelp(SphinxDirective):
        required_arguments = 1

        def run(self):
            command = self.arguments[0]
            title = nodes.rubric(text=f"splinecast {command}")
            block = nodes.literal_block(text=_help_text(command))
            block["language"] = "text"
            return [title, block]

    app.add_directive("splinecast-help", SplinecastHelp)
    return {"parallel_read_safe": True}


html_theme = "pydata_sphinx_theme"
html_title = f"splinecast {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_prev_next": False,
}
html_static_path: list[str] = []
