"""The documentation's sources cover the code: the bibliography has an entry for every work
the code cites, the API reference lists every public name, the gallery builds every script.

Fast and without Sphinx: these read the sources (``src/pwsdyn``, ``docs/``, ``examples/``) as
text. The build itself (``python -m sphinx -W ... docs docs/_build/html``, in ``.ci/run``) runs
the gallery and fails on any warning; the slow test below runs each gallery script on its own,
as a user would.
"""

from __future__ import annotations

import ast
import io
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import pwsdyn

sys.path.insert(0, str(Path(__file__).parent))
from _snippets import bare_values, check_printed, run_script, stated_lines  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "src" / "pwsdyn"
DOCS = ROOT / "docs"
EXAMPLES = ROOT / "examples"

# ---- the bibliography ------------------------------------------------------------------------

#: How the code cites a work (a regular expression) -> its key in docs/references.bib. The
#: thesis is cited as "thesis eq. 2.36", "thesis section 5.2", "thesis Paper B", its appended
#: papers as "Paper A" .. "Paper E" (handled below, with ranges such as "Papers B-E"), the
#: slides as "the slides"; other works by their authors.
CITATIONS = {
    r"\bthesis\b|\bSvahn,? \(?2009\b": "svahn2009thesis",
    r"\bslides\b": "piiroinen2015slides",
    r"\bBudd\b": "budd1994",
    r"\bNordmark & Piiroinen\b": "nordmark2009",
    r"\bNordmark (\(|, )?1991\b|\bNordmark's (discontinuity map|square-root)": "nordmark1991",
    r"thesis's refs?\. \[(16, )?19\]|\bFredriksson\b": "fredriksson1997",
    r"\bDankowicz & Piiroinen\b|\bDankowicz and P\. T\. Piiroinen\b": "dankowicz2002",
    r"\bdi Bernardo\b": "dibernardo2001",
    r"\bPiiroinen & Kuznetsov\b|\bPiiroinen and Yu\. A\. Kuznetsov\b": "piiroinen2008",
    r"\bLeine\b": "leine1998",
    r"\bAdolfsson\b": "adolfsson2001",
    r"\bFilippov\b": "filippov1988",
    r"\bUtkin\b": "utkin1992",
    r"\bDieci\b|\bLopez\b": "dieci2011",
    r"\bKuznetsov, Rinaldi & Gragnani\b": "kuznetsov2003",
    r"\bKuznetsov,? (\*Elements|section)": "kuznetsov2004",
    r"\bKeller's\b": "keller1977",
    r"\bAllgower\b": "allgower2003",
    r"\bDankowicz & Schilder\b": "dankowicz2013",
    r"\bThota & Dankowicz\b": "thota2008",
    r"\bDormand\b": "dormand1980",
    r"\bShampine\b": "shampine1986",
    r"\bHairer\b": "hairer1993",
    r"\bParlett & Reinsch\b": "parlett1969",
    r"\bBenettin\b": "benettin1980",
    r"\bVan Loan\b": "vanloan1978",
    r"\bDeuflhard\b": "deuflhard2004",
    r"\bM(ü|ue)ller\b": "muller1995",
    r"\bKrauskopf (&|and) Osinga\b": "krauskopf1998",
    r"\bHobson\b": "hobson1993",
    r"\bNusse (&|and) Yorke\b": "nusse1992",
    r"\bGrebogi,\s+Ott\s+(&|and)\s+Yorke\b": "grebogi1983",
    r"\bSvahn & Dankowicz\b|\bSvahn and H\. Dankowicz\b": "svahn2008paperD",
    r"\bDankowicz and F\. Svahn\b|\bDankowicz & Svahn\b": "dankowicz2007paperB",
    r"\bSvahn, J\. Jerrelind\b": "svahn2009paperC",
    r"\bBurridge (&|and) (L\. )?Knopoff\b": "burridge1967",
    r"\bCarlson (&|and) (J\. S\. )?Langer\b": "carlson1989",
    r"\bNussbaum (&|and) (A\. )?Ruina\b": "nussbaum1987",
}
#: The thesis's appended papers.
PAPERS = {"A": "wilcox2009paperA", "B": "dankowicz2007paperB", "C": "svahn2009paperC",
          "D": "svahn2008paperD", "E": "svahn2009paperE"}
_PAPERS = re.compile(r"\bPapers? ([A-E](?:(?:, |,? and | to |-)[A-E])*)\b")

#: What looks like an author-year citation: "Name & Name", "Name et al.", "Name (1991)",
#: "Name 1991". Each one found must be matched by a pattern of CITATIONS (a work cited in a
#: new way needs an entry in the bibliography and a line above).
_AUTHOR = r"[A-Z][a-zà-ÿ'-]+(?: [A-Z][a-zà-ÿ'-]+)?"
_CITATION_LIKE = re.compile(
    rf"\b{_AUTHOR}(?: & {_AUTHOR}|,? et al\.?|,? \(?(?:1[89]|20)\d\d\)?)")
#: Capitalised words before a year or an ampersand that are not authors (publishers, places,
#: journals, software).
NOT_AUTHORS = {"Stockholm", "Springer", "SIAM", "KTH", "Galway", "NUI Galway", "Math",
               "Softw", "Dyn", "Vib", "Control", "Chaos", "Appl", "Syst", "Comput",
               "Systems", "Dynamics", "Mathematics", "The", "In", "ACM"}


def _code_texts() -> list[tuple[Path, str]]:
    files = sorted(SRC.rglob("*.py")) + sorted((SRC / "model" / "zoo").glob("*.toml"))
    return [(p, p.read_text(encoding="utf-8")) for p in files if "__pycache__" not in p.parts]


def _bib_keys() -> set[str]:
    text = (DOCS / "references.bib").read_text(encoding="utf-8")
    return set(re.findall(r"^@\w+\{([^,\s]+),", text, re.M))


def _paper_letters(spec: str) -> set[str]:
    """``"B-E"`` -> B, C, D, E; ``"D and E"`` -> D, E; ``"B, C and E"`` -> B, C, E."""
    out = set()
    for a, b in re.findall(r"([A-E])(?:(?:-| to )([A-E]))?", spec):
        out |= {chr(c) for c in range(ord(a), ord(b or a) + 1)}
    return out


def cited_keys() -> dict[str, set[str]]:
    """The bibliography keys the code cites, each with the files that cite it."""
    found: dict[str, set[str]] = {}
    for path, text in _code_texts():
        rel = str(path.relative_to(ROOT))
        for pattern, key in CITATIONS.items():
            if re.search(pattern, text):
                found.setdefault(key, set()).add(rel)
        for m in _PAPERS.finditer(text):
            for letter in _paper_letters(m.group(1)):
                found.setdefault(PAPERS[letter], set()).add(rel)
    return found


def test_every_work_the_code_cites_has_a_bibliography_entry():
    found = cited_keys()
    # the scan sees the code's citations: the thesis, its papers and the slides are cited in
    # dozens of places, so an empty result would mean the scan is broken, not the code clean
    assert {"svahn2009thesis", "piiroinen2015slides", "wilcox2009paperA",
            "nordmark1991"} <= set(found)
    missing = {k: sorted(v)[:3] for k, v in found.items() if k not in _bib_keys()}
    assert not missing, f"cited in the code but not in docs/references.bib: {missing}"


def test_every_author_year_citation_in_the_code_is_known():
    """A citation in a form CITATIONS does not know (a new work) must be added there and to
    docs/references.bib."""
    unknown = {}
    for path, text in _code_texts():
        for m in _CITATION_LIKE.finditer(text):
            cite = m.group(0)
            first = re.match(_AUTHOR, cite).group(0)
            if first in NOT_AUTHORS or first.split()[0] in NOT_AUTHORS:
                continue
            # the pattern may need the text around the match ("Kuznetsov, section")
            window = text[max(0, m.start() - 20): m.end() + 40]
            if not any(re.search(p, window) for p in CITATIONS):
                unknown.setdefault(cite, str(path.relative_to(ROOT)))
    assert not unknown, f"citations without a bibliography entry: {unknown}"


def test_every_bibliography_entry_is_complete():
    text = (DOCS / "references.bib").read_text(encoding="utf-8")
    entries = re.split(r"^@", text, flags=re.M)[1:]
    assert len(entries) == len(_bib_keys())                # no duplicate or unparsed keys
    for entry in entries:
        key = entry.split("{", 1)[1].split(",", 1)[0]
        for field in ("author", "title", "year"):
            assert re.search(rf"^\s*{field}\s*=", entry, re.M), f"{key} has no {field}"


def test_the_closed_forms_of_the_paper_ranges():
    # the ranges the code writes ("Papers D and E", "Papers B-E", "Papers B, C and E")
    assert _paper_letters("D and E") == {"D", "E"}
    assert _paper_letters("B-E") == {"B", "C", "D", "E"}
    assert _paper_letters("B, C and E") == {"B", "C", "E"}
    assert _PAPERS.search("thesis's Papers B-E as a model").group(1) == "B-E"


# ---- the API reference -----------------------------------------------------------------------

def test_the_api_reference_lists_every_public_name():
    api = (DOCS / "api.rst").read_text(encoding="utf-8")
    listed = set(re.findall(r"^   ([A-Za-z_][\w.]*)\s*$", api, re.M))
    missing = sorted(n for n in pwsdyn.__all__ if n not in listed)
    assert not missing, f"public names missing from docs/api.rst: {missing}"
    # and every public module (no part of its dotted name private), relative to pwsdyn
    modules = set()
    for path in SRC.rglob("*.py"):
        parts = path.relative_to(SRC).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if parts and not any(p.startswith("_") for p in parts):
            modules.add(".".join(parts))
    assert "integrate.simulate" in modules and "io" in modules   # the walk sees them
    assert modules <= listed, f"public modules missing from docs/api.rst: {sorted(modules - listed)}"


def _api_names() -> list[str]:
    """The names the API reference's autosummary tables list, relative to ``pwsdyn``."""
    api = (DOCS / "api.rst").read_text(encoding="utf-8")
    return re.findall(r"^   ([A-Za-z_][\w.]*)\s*$", api, re.M)


def _summaries_checker():
    """docs/_ext/summaries.py, the build's check of the API tables' summaries."""
    sys.path.insert(0, str(DOCS))
    try:
        from _ext.summaries import summary_problem
    finally:
        sys.path.remove(str(DOCS))
    return summary_problem


def test_the_summary_check_sees_a_cut_sentence():
    pytest.importorskip("sphinx")
    problem = _summaries_checker()
    # what autosummary showed for poincare_map before its first sentence was made whole
    assert "(" in problem("Evaluate a Poincaré map and its Jacobian (thesis eq.")
    assert problem("A stray ) bracket.") and problem("Ends [inside a bracket.")
    assert problem("") is None                  # an attribute without a docstring of its own
    assert problem("Evaluate a Poincaré map and its Jacobian (thesis eq. 2.25).") is None
    assert problem("The map ``x -> f(x)`` of a piece [a, b].") is None


def test_a_cut_summary_fails_the_build(tmp_path):
    """The extension in a build: a module whose function's first sentence is cut at "eq."
    gets a warning from the autosummary table, which -W turns into a failed build."""
    pytest.importorskip("sphinx")
    from sphinx.application import Sphinx

    (tmp_path / "cutmod.py").write_text(
        'def f():\n    """Evaluate a map (thesis eq. 2.25).\n\n    More.\n    """\n',
        encoding="utf-8")
    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text(
        "import sys\n"
        f"sys.path[:0] = [{str(tmp_path)!r}, {str(DOCS)!r}]\n"
        "extensions = ['sphinx.ext.autosummary', '_ext.summaries']\n", encoding="utf-8")
    (src / "index.rst").write_text(
        "Index\n=====\n\n.. currentmodule:: cutmod\n\n.. autosummary::\n\n   f\n",
        encoding="utf-8")
    warnings = io.StringIO()
    path = list(sys.path)
    try:
        Sphinx(str(src), str(src), str(tmp_path / "out"), str(tmp_path / "doctrees"), "html",
               status=None, warning=warnings, freshenv=True).build()
    finally:
        sys.path[:] = path                      # the project's conf.py prepends to it
        sys.modules.pop("cutmod", None)
    assert "autosummary of f" in warnings.getvalue()
    assert "(thesis eq." in warnings.getvalue()


def _reference_settings() -> dict:
    """``nitpicky`` and ``nitpick_ignore_regex`` as docs/conf.py sets them (literals)."""
    out = {}
    for node in ast.parse((DOCS / "conf.py").read_text(encoding="utf-8")).body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and getattr(node.targets[0], "id", None) in ("nitpicky", "nitpick_ignore_regex")):
            out[node.targets[0].id] = ast.literal_eval(node.value)
    return out


def _build_with_the_reference_check(tmp_path, see_also: str):
    """A tiny project with docs/conf.py's reference settings documenting a module whose
    function's docstring has a numpydoc type description and ``see_also``, built as the
    documentation is (``python -m sphinx -W --keep-going``, its own process: a second build
    in one process warns about Sphinx's own nodes). Returns (exit status, warnings)."""
    settings = _reference_settings()
    tmp_path.mkdir()
    (tmp_path / "refmod.py").write_text(
        'def f(x, how="a"):\n'
        '    """Do a thing.\n\n'
        '    Parameters\n    ----------\n'
        '    x : array_like, optional\n        The values.\n'
        '    how : {\'a\', \'b\'} or None\n        How; see ' + see_also + '.\n'
        '    """\n\n\n'
        'def g():\n    """Another."""\n', encoding="utf-8")
    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text(
        "import sys\n"
        f"sys.path[:0] = [{str(tmp_path)!r}]\n"
        "extensions = ['sphinx.ext.autodoc', 'sphinx.ext.napoleon']\n"
        "napoleon_google_docstring = False\n"
        f"nitpicky = {settings['nitpicky']!r}\n"
        f"nitpick_ignore_regex = {settings['nitpick_ignore_regex']!r}\n", encoding="utf-8")
    (src / "index.rst").write_text("Index\n=====\n\n.. automodule:: refmod\n   :members:\n",
                                   encoding="utf-8")
    res = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                          "html", str(src), str(tmp_path / "out")],
                         capture_output=True, text=True, env={**os.environ, "NO_COLOR": "1"})
    return res.returncode, res.stderr


def test_the_build_checks_every_reference():
    pytest.importorskip("sphinx")
    assert _reference_settings().get("nitpicky") is True, (
        "docs/conf.py must set nitpicky = True: without it a broken reference renders as "
        "plain text and the build passes")


def test_a_broken_reference_fails_the_build(tmp_path):
    """A reference to nothing (``:func:`nowhere```) fails a build with docs/conf.py's
    settings, as -W makes it; the same docstring with a reference that resolves builds
    cleanly, its type description (``array_like, optional``, ``{'a', 'b'} or None``) not
    taken for references to check."""
    pytest.importorskip("sphinx")
    status, warnings = _build_with_the_reference_check(tmp_path / "broken", ":func:`nowhere`")
    assert status != 0, warnings
    assert "reference target not found: nowhere" in warnings
    status, warnings = _build_with_the_reference_check(tmp_path / "good", ":func:`g`")
    assert status == 0 and "WARNING" not in warnings, warnings


def _summarised_objects():
    """Every object whose summary the API reference shows: the names of its tables and the
    public methods of the classes among them (the class pages' tables)."""
    import importlib
    import inspect

    out = []
    for name in _api_names():
        if hasattr(pwsdyn, name) and "." not in name:
            obj = getattr(pwsdyn, name)
        else:
            obj = importlib.import_module(f"pwsdyn.{name}")
        out.append((name, obj))
        if inspect.isclass(obj):
            for key, member in vars(obj).items():
                if not key.startswith("_") and inspect.isfunction(member):
                    out.append((f"{name}.{key}", member))
    return out


def test_every_api_summary_is_a_whole_sentence():
    """autosummary shows a docstring's first sentence, split at the first period followed by a
    space: "(thesis eq. 2.25)" in it leaves "(thesis eq." in the table. The build warns about
    such a summary (docs/_ext/summaries.py); this finds it without a build."""
    pytest.importorskip("sphinx")
    import inspect

    from docutils.frontend import get_default_settings
    from docutils.parsers.rst import Parser
    from sphinx.ext.autosummary import extract_summary

    problem = _summaries_checker()
    settings = get_default_settings(Parser)
    settings.report_level = 5                   # a summary's parse errors are not ours to show
    objects = _summarised_objects()
    assert len(objects) > 60                    # the tables' names and the classes' methods
    cut = {}
    for name, obj in objects:
        doc = inspect.getdoc(obj)
        if doc is None:
            continue                            # an undocumented method has no table row
        summary = extract_summary(doc.splitlines(), settings)
        why = problem(summary)
        if why:
            cut[name] = f"{summary!r}: {why}"
    assert not cut, f"summaries cut in the API tables: {cut}"


# ---- the pages' code ------------------------------------------------------------------------

_CODE_BLOCK = re.compile(r"^\.\. code-block:: python\n\n((?:(?:    .*)?\n)+)", re.M)


def page_code(page: Path) -> str:
    """The ``.. code-block:: python`` blocks of an RST page, in order, as one script (a page's
    later blocks use the names of its earlier ones)."""
    text = page.read_text(encoding="utf-8")
    blocks = [re.sub(r"^    ", "", m.group(1), flags=re.M) for m in _CODE_BLOCK.finditer(text)]
    return "\n".join(blocks)


def _pages_with_code() -> list[Path]:
    return [p for p in sorted(DOCS.glob("*.rst")) + sorted(DOCS.glob("guide/*.rst"))
            if page_code(p).strip()]


def test_the_pages_code_blocks_are_found():
    names = {p.name for p in _pages_with_code()}
    assert {"getting_started.rst", "model_format.rst", "simulation.rst"} <= names
    assert "continue_orbit" in page_code(DOCS / "getting_started.rst")


def test_the_guides_state_what_their_code_prints():
    """Getting started and every guide with code show their values as printed lines with the
    value in a ``# ->`` comment (the convention of tests/_snippets.py), not as bare expressions
    a script never shows."""
    pages = [p for p in _pages_with_code()
             if p.name == "getting_started.rst" or p.parent.name == "guide"]
    assert len(pages) >= 6
    for page in pages:
        code = page_code(page)
        bare = bare_values(code)
        assert not bare, f"{page.name}: a value shown only in a comment: {bare}"
        assert stated_lines(code), f"{page.name} prints no value for its comments"


@pytest.mark.slow
@pytest.mark.parametrize("page", _pages_with_code(), ids=lambda p: p.name)
def test_the_pages_python_runs(page, tmp_path):
    """Each page's Python, run as a script in a fresh process in a temporary directory
    (files it writes land there), like the README's blocks (tests/test_readme.py), prints what
    its ``# ->`` comments state (tests/_snippets.py)."""
    code = page_code(page)
    res = run_script(code, tmp_path)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    problems = check_printed(code, res.stdout)
    assert not problems, (f"{page.name} printed other values than its comments state:\n"
                          + "\n".join(problems))


# ---- the gallery -----------------------------------------------------------------------------

def _gallery_conf() -> dict:
    """The literal entries of ``sphinx_gallery_conf`` in docs/conf.py."""
    tree = ast.parse((DOCS / "conf.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and getattr(node.targets[0], "id", None) == "sphinx_gallery_conf"):
            out = {}
            for k, v in zip(node.value.keys, node.value.values):
                try:
                    out[ast.literal_eval(k)] = ast.literal_eval(v)
                except ValueError:
                    pass                          # computed entries (the directories)
            return out
    raise AssertionError("docs/conf.py defines no sphinx_gallery_conf")


def gallery_scripts() -> list[Path]:
    return sorted(EXAMPLES.glob("*.py"))


def test_every_gallery_script_is_built():
    """sphinx-gallery runs the scripts whose path matches ``filename_pattern`` (searched in
    the path, as sphinx-gallery does) and lists the others without running them: a script
    the pattern misses would show no figure and never be checked."""
    conf = _gallery_conf()
    pattern = re.compile(conf["filename_pattern"])
    ignore = re.compile(conf["ignore_pattern"])
    scripts = [p for p in gallery_scripts() if not ignore.search(p.name)]
    assert scripts, "no gallery scripts in examples/"
    not_run = [p.name for p in scripts if not pattern.search(os.sep + p.name)]
    assert not not_run, f"gallery scripts that would not be run: {not_run} (name them plot_*.py)"
    assert not conf.get("only_warn_on_example_error", False)   # a failing script fails the build
    assert (EXAMPLES / "README.rst").exists()                  # the gallery's header


@pytest.mark.parametrize("script", gallery_scripts(), ids=lambda p: p.name)
def test_gallery_script_begins_with_a_title_and_a_paragraph(script):
    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8")), clean=False)
    assert doc, f"{script.name} has no docstring"
    lines = doc.strip("\n").splitlines()
    assert len(lines) >= 4, f"{script.name}: a title, its underline and a paragraph"
    title, underline = lines[0].rstrip(), lines[1].rstrip()
    # an RST section title: one punctuation character repeated, at least as long as the title
    assert title and re.fullmatch(r"([=\-~^\"'`#*+:.])\1*", underline) \
        and len(underline) >= len(title), (
        f"{script.name}: the docstring must begin with an RST title and its underline")
    assert lines[2].strip() == "" and lines[3].strip(), f"{script.name}: a paragraph after it"


def _module_constants(script: Path) -> dict:
    """The literal module-level assignments of a script (``NAME = <literal>``)."""
    out = {}
    for node in ast.parse(script.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign):
            try:
                value = ast.literal_eval(node.value)
            except ValueError:
                continue
            for target in node.targets:
                names = target.elts if isinstance(target, ast.Tuple) else [target]
                values = value if isinstance(target, ast.Tuple) else [value]
                for name, v in zip(names, values):
                    if isinstance(name, ast.Name):
                        out[name.id] = v
    return out


def test_the_basins_example_shows_coexisting_attractors():
    """The basins example is about coexisting attractors: at its parameters, on a coarser grid
    over the same window, at least two attractors each draw a substantial share of the starts
    (a single basin would be a plain square)."""
    import numpy as np

    c = _module_constants(EXAMPLES / "plot_basins.py")
    grid = {"x": np.linspace(*c["X_RANGE"], 12), "v": np.linspace(*c["V_RANGE"], 12)}
    ds = pwsdyn.basins(c["MODEL"], grid, params=c["PARAMS"], transient=200, samples=32,
                       progress=False)
    shares = {int(k): float(ds.fraction.sel(basin=k)) for k in ds["attractor"].values}
    assert sum(s >= 0.15 for s in shares.values()) >= 2, f"basin fractions: {shares}"
    labels = ds["label"].values
    assert len({int(v) for v in np.unique(labels) if v >= 0}) >= 2


@pytest.mark.parametrize("script", gallery_scripts(), ids=lambda p: p.name)
def test_gallery_thumbnail_title_is_the_page_title(script):
    """sphinx-gallery writes a thumbnail's title from the RST source with a few regular
    expressions, which take a pair of asterisks for emphasis markers: a title with "a**" in
    it lost the "**" on its thumbnail while the page showed it. The thumbnail must read as
    the page's title does (docutils' rendering of it)."""
    pytest.importorskip("sphinx_gallery")
    from docutils.core import publish_doctree
    from sphinx_gallery.gen_rst import _sanitize_rst

    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8")), clean=False)
    title = doc.strip("\n").splitlines()[0].strip()
    rendered = publish_doctree(title, settings_overrides={"report_level": 5}).astext()
    assert " ".join(_sanitize_rst(title).split()) == " ".join(rendered.split()), (
        f"{script.name}: the thumbnail would read {_sanitize_rst(title)!r}, "
        f"the page {rendered!r}")


@pytest.mark.slow
@pytest.mark.parametrize("script", gallery_scripts(), ids=lambda p: p.name)
def test_gallery_script_runs_on_its_own_and_writes_nothing(script, tmp_path):
    """As a user runs it: ``MPLBACKEND=Agg python examples/plot_x.py``, from another
    directory; it must neither fail nor leave files in examples/ or the working directory."""
    before = sorted(p.name for p in EXAMPLES.iterdir())
    env = {**os.environ, "MPLBACKEND": "Agg", "PWSDYN_QUIET": "1"}
    res = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert sorted(p.name for p in EXAMPLES.iterdir()) == before
    assert not list(tmp_path.iterdir())
