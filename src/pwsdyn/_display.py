"""Short summaries of results for people: the numbers of a ``repr`` and the HTML table a
notebook shows (``_repr_html_``).

A summary must never fail: it is what a user sees of a failed or empty result, when they most
need it. The helpers here format a value as ``"?"`` where it cannot be formatted, and every
text that goes into HTML is escaped (model, mode and event names are the user's text).
"""

from __future__ import annotations

import html

import numpy as np


def num(value, digits: int = 6) -> str:
    """A real number to ``digits`` significant digits (``"?"`` for ``None`` or no number)."""
    try:
        return f"{float(value):.{digits}g}"
    except (TypeError, ValueError):
        return "?"


def moduli(values, digits: int = 4) -> str:
    """``[|z0|, |z1|, ...]`` of a sequence of (complex) numbers, e.g. Floquet multipliers."""
    try:
        mods = np.abs(np.atleast_1d(np.asarray(values, dtype=complex)))
    except (TypeError, ValueError):
        return "?"
    return "[" + ", ".join(num(m, digits) for m in mods) + "]"


def counts_text(counts: dict) -> str:
    """``"impact 12, chatter 1"`` of ``{kind: count}`` (``"none"`` when empty)."""
    return ", ".join(f"{k} {v}" for k, v in counts.items()) or "none"


def state_text(names, values, digits: int = 6) -> str:
    """``"x=0.1, v=-0.2"`` of state names and values."""
    try:
        return ", ".join(f"{n}={num(v, digits)}" for n, v in zip(names, values)) or "?"
    except TypeError:
        return "?"


def html_table(title: str, rows) -> str:
    """A two-column HTML table: ``title`` as its caption, one row per ``(label, value)``; every
    text escaped."""
    esc = html.escape
    body = "".join(f"<tr><th style=\"text-align:left\">{esc(str(k))}</th>"
                   f"<td style=\"text-align:left\">{esc(str(v))}</td></tr>" for k, v in rows)
    return (f"<table><caption style=\"text-align:left\"><b>{esc(str(title))}</b></caption>"
            f"{body}</table>")
