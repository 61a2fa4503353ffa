"""Sphinx configuration of the pwsdyn documentation.

Build (from the repository root; warnings are errors, as in CI)::

    MPLBACKEND=Agg python -m sphinx -W --keep-going -b html docs docs/_build/html

The gallery scripts in ``examples/plot_*.py`` are run during the build (sphinx-gallery); a
script that raises fails the build.

Every reference is checked (``nitpicky``): a reference to a pwsdyn object, module, page or
label that resolves to nothing fails the build. To check only the references, without running
the gallery::

    python -m sphinx -W --keep-going -b html -D sphinx_gallery_conf.plot_gallery=0 \
        docs /tmp/pwsdyn-references
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
# Document the checkout being built, whatever pwsdyn is installed elsewhere.
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(HERE))            # the _ext helpers (model zoo table, gallery scraper)
os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("PWSDYN_QUIET", "1")

import pwsdyn  # noqa: E402

project = "pwsdyn"
author = "the pwsdyn authors"
copyright = "the pwsdyn authors"
release = pwsdyn.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "sphinxcontrib.bibtex",
    "sphinx_click",
    "_ext.zoo_table",
    "_ext.summaries",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py",
                    "auto_examples/*.zip", "auto_examples/*.json", "auto_examples/*.md5",
                    "auto_examples/*.codeobj.json"]
templates_path = ["_templates"]

# -- API reference --------------------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "none"         # the signatures show them; docstrings describe them
autodoc_preserve_defaults = True
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True

# -- Cross-references -----------------------------------------------------------------------
# A reference that resolves to nothing would render as plain text, not a link: with -W it
# fails the build instead. Not checked, each for its reason:
nitpicky = True
nitpick_ignore_regex = [
    # the words of a parameter's type description, which napoleon turns into class references
    # ("array_like, optional", "{'full', 'projected'}", "int or None", "n + 1")
    (r"py:class", r"[a-z_]+|.*[\s'{}\[\]:,].*|[A-Z]|True|False|None"),
    # other libraries' classes (linking them would need intersphinx, and so the network),
    # by their dotted names and the two that type descriptions name without a module
    (r"py:class", r"(collections|dask|enum|matplotlib|numpy|pathlib|sympy|xarray)\..+"),
    (r"py:class", r"Path|Axes"),
]


def _public_bases(app, name, obj, options, bases):
    """A class page's "Bases:" names public classes only: a private base (the equilibrium
    problems' shared ``_PointProblem``) is not documented, so it gives way to its own bases."""
    def public(base):
        if getattr(base, "__module__", "").startswith("pwsdyn") and base.__name__[0] == "_":
            return [b for parent in base.__bases__ for b in public(parent)]
        return [base]

    out = []
    for base in bases:
        out += [b for b in public(base) if b not in out]
    bases[:] = out


def setup(app):
    app.connect("autodoc-process-bases", _public_bases)


# -- Markdown pages (the user guide's continuation and extending pages) ---------------------
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3

# -- Bibliography ---------------------------------------------------------------------------
bibtex_bibfiles = ["references.bib"]
bibtex_default_style = "plain"
bibtex_reference_style = "author_year"

# -- Gallery --------------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": str(HERE / "auto_examples"),
    # every examples/plot_*.py is run: no list to keep in step with the directory
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"__init__\.py",
    "within_subsection_order": "FileNameSortKey",
    # a script that raises stops the build with an error (not a warning or a broken page)
    "abort_on_example_error": False,
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "plot_gallery": "True",
    "remove_config_comments": True,
    "matplotlib_animations": False,
    # pyplot's figures, and the Figure objects pwsdyn's plotting functions return (by name:
    # a function in the configuration could not be cached between builds)
    "image_scrapers": ("matplotlib", "_ext.gallery_scrapers.pwsdyn_figures"),
    # an example that ends a block with its figure shows the figure, not the figure's repr
    "ignore_repr_types": r"matplotlib\.(text|axes|figure)",
    # thumbnails up to 360 px wide on the page (docs/_static/pwsdyn.css; sphinx-gallery's own
    # 160 px are too small to read), rendered larger to stay sharp on high-density screens
    "thumbnail_size": (560, 392),
}

# -- HTML -----------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"pwsdyn {release}"
html_static_path = ["_static"]
# code and output that scroll or wrap inside the page, larger gallery thumbnails
html_css_files = ["pwsdyn.css"]

# -- Each object documented once, at its shortest public path ------------------------------
# The top-level names (``pwsdyn.simulate``) first, then a subpackage's re-exports
# (``pwsdyn.continuation.ContinuationSettings``), then what is left in each public module. A
# module page leaves out what a shorter path documents already: autodoc files a class under
# its defining module, so a second description of it would be a duplicate.
import importlib  # noqa: E402
import inspect  # noqa: E402
import pkgutil  # noqa: E402


def _public_modules() -> list[str]:
    names = []
    for info in pkgutil.walk_packages(pwsdyn.__path__, "pwsdyn."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names, key=lambda n: (n.count("."), n))


def _exclusions() -> tuple[list[str], dict[str, list[str]]]:
    documented = {id(getattr(pwsdyn, n)) for n in pwsdyn.__all__}
    packages, exclude = [], {}
    for name in _public_modules():
        mod = importlib.import_module(name)
        is_package = hasattr(mod, "__path__")
        if is_package:
            packages.append(name)
        own = getattr(mod, "__all__", None)
        members = own if own is not None else [k for k in vars(mod) if not k.startswith("_")]
        skip, shown = [], []
        for k in members:
            obj = getattr(mod, k, None)
            if inspect.ismodule(obj):
                continue
            if id(obj) in documented:
                skip.append(k)
            elif is_package and (inspect.isclass(obj) or inspect.isroutine(obj)):
                # autodoc finds a class's or a function's docstring through the package; a
                # constant's ``#:`` comment it reads only in the module that assigns it, so
                # that module's page keeps it
                shown.append(obj)
        exclude[name] = sorted(skip)
        documented |= {id(o) for o in shown}
    return packages, exclude


_packages, _exclude = _exclusions()
autosummary_context = {"reexporting": _packages, "exclude": _exclude}
