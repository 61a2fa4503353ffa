"""A build check: every summary in the API reference's tables is a whole sentence.

autosummary shows the first sentence of a docstring, found by splitting at a period followed by
a space, so a first sentence with an abbreviation in it ("(thesis eq. 2.25)") is shown cut
after the abbreviation, with its parenthesis left open. :func:`summary_problem` says what is
wrong with one summary; the extension warns, from the generated tables, about every summary it
finds wrong, and the build (``-W``) fails on the warning.
"""

from __future__ import annotations

from docutils import nodes
from sphinx.util import logging

logger = logging.getLogger(__name__)

_PAIRS = {"(": ")", "[": "]", "{": "}"}


def summary_problem(summary: str) -> str | None:
    """Why an autosummary summary is not a whole sentence, or None if it is.

    A bracket left open (or closed without being opened) means the sentence was cut. An
    empty summary (an attribute without a docstring of its own) is not a cut one.
    """
    text = summary.strip()
    stack = []
    for ch in text:
        if ch in _PAIRS:
            stack.append(_PAIRS[ch])
        elif ch in _PAIRS.values():
            if not stack or stack.pop() != ch:
                return f"a {ch!r} closes nothing"
    if stack:
        return f"it ends inside {'(' if stack[-1] == ')' else stack[-1]!r}... (cut at a period?)"
    return None


def _check_tables(app, doctree) -> None:
    from sphinx.ext.autosummary import autosummary_table

    for table in doctree.findall(autosummary_table):
        for row in table.findall(nodes.row):
            entries = [c for c in row.children if isinstance(c, nodes.entry)]
            if len(entries) < 2:
                continue
            name, summary = entries[0].astext().strip(), entries[-1].astext()
            problem = summary_problem(summary)
            if problem:
                logger.warning("autosummary of %s: %r: %s", name, summary.strip(), problem,
                               location=table, type="pwsdyn", subtype="summary")


def setup(app):
    app.connect("doctree-read", _check_tables)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
