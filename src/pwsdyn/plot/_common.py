"""What every figure family shares: parameter and state names typeset, numbers written for
mathtext, the user's axes checked, legends merged, figure files checked and written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import ArgumentError

#: Short spellings of Greek letters that models use for parameter and state names, and the
#: letter each stands for (the full names, ``omega``, ``sigma``, ``mu``, ... need none).
GREEK_SPELLINGS = {"eps": "epsilon", "lam": "lambda", "lamda": "lambda", "Lam": "Lambda",
                   "Lamda": "Lambda"}
#: The letters typeset in another form than SymPy's: the curly epsilon of the literature
#: (and of Unicode's Greek block), not the lunate one.
_LETTER_FORMS = {r"\epsilon": r"\varepsilon"}


def _latex_name(name: str) -> str:
    """A parameter or state name as mathtext (without the dollar signs): Greek letters as
    letters, however they are spelt (``eps``, ``epsilon`` -> ``\\varepsilon``; ``lam``,
    ``lambda`` -> ``\\lambda``; ``omega`` -> ``\\omega``), the rest of the name as
    subscripts (``mu_s`` -> ``\\mu_{s}``, ``x1`` -> ``x_{1}``).

    Every name a figure shows (titles, axis labels, legends, surface labels) goes through this
    one function, so that a name reads the same everywhere."""
    import sympy as sp
    from sympy.printing.conventions import split_super_sub

    base, sups, subs = split_super_sub(str(name))
    if base in GREEK_SPELLINGS:
        name = (GREEK_SPELLINGS[base] + "".join(f"^{s}" for s in sups)
                + "".join(f"_{s}" for s in subs))
    out = sp.latex(sp.Symbol(name))
    for letter, form in _LETTER_FORMS.items():
        # whole commands only: \epsilon but not a longer command that begins with it
        out = re.sub(re.escape(letter) + r"(?![A-Za-z])", lambda m: form, out)
    return out


def _tex(name: str) -> str:
    """A name as mathtext, dollar signs included (see :func:`_latex_name`)."""
    return f"${_latex_name(name)}$"


def _latex_expr(expr) -> str:
    """A SymPy expression as mathtext (without dollar signs), its symbols named as
    :func:`_latex_name` names them."""
    import sympy as sp

    return sp.latex(expr, symbol_names={s: _latex_name(str(s)) for s in expr.free_symbols})


def _number(v) -> str:
    """A parameter value for mathtext: 4 significant digits, powers of ten as a reader
    writes them (``2 \\times 10^{-5}``)."""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return str(v)
    s = f"{v:.4g}"
    if "e" in s:
        mant, exp = s.split("e")
        power = f"10^{{{int(exp)}}}"
        return power if mant == "1" else f"{mant} \\times {power}"
    return s


def _wrap(items: list, plain: list, width: int, sep: str = ", ") -> list:
    """``items`` joined by ``sep`` into lines whose plain text is at most ``width`` long."""
    lines: list = []
    cur: list = []
    n = 0
    for item, text in zip(items, plain):
        if cur and n + len(sep) + len(text) > width:
            lines.append(sep.join(cur))
            cur, n = [], 0
        n += (len(sep) if cur else 0) + len(text)
        cur.append(item)
    if cur:
        lines.append(sep.join(cur))
    return lines


def _values_text(values: dict, exclude=(), width: int = 90) -> list:
    """Lines of ``name = value`` (mathtext, names typeset) for the entries of ``values``
    not in ``exclude``."""
    keys = [k for k in values if k not in exclude]
    items = [f"${_latex_name(k)} = {_number(values[k])}$" for k in keys]
    plain = [f"{k} = {float(values[k]):.4g}" if isinstance(values[k], (int, float))
             else f"{k} = {values[k]}" for k in keys]
    return _wrap(items, plain, width)


def _root_figure(ax) -> Figure:
    """The figure that holds ``ax`` (the top-level one when ``ax`` lies in a subfigure)."""
    fig = ax.figure
    while getattr(fig, "figure", None) is not None and fig.figure is not fig:
        fig = fig.figure
    return fig


def _one_axes(ax, figsize: tuple, what: str) -> tuple:
    """The axes a one-panel figure draws into: ``ax`` checked (one Axes, ``what`` naming the
    panel in the error), or the axes of a new figure of ``figsize``. Returns ``(ax, fig)``."""
    if ax is None:
        fig = Figure(figsize=figsize, layout="constrained")
        return fig.subplots(), fig
    (ax,), fig = _user_axes(ax, {1: what})
    return ax, fig


def _user_axes(ax, counts: dict, argname: str = "ax", single_ok: bool = False) -> tuple:
    """Check ``ax`` (one Axes or a sequence of them) against the accepted numbers of axes.

    ``counts`` maps each accepted number of axes to what it means (for the error message).
    Returns the list of axes and their common figure."""
    axes: list = []
    if isinstance(ax, Axes):
        axes = [ax]
    elif not isinstance(ax, (str, bytes)):
        try:
            axes = list(np.asarray(ax, dtype=object).ravel())
        except Exception:
            axes = []
    if not axes or not all(isinstance(a, Axes) for a in axes):
        raise ArgumentError(f"`{argname}` must be a matplotlib Axes or a sequence of Axes, "
                            f"got {type(ax).__name__}")
    if len(axes) not in counts:
        accepted = "; ".join(f"{k} axes: {what}" for k, what in counts.items())
        if single_ok:
            accepted = "one Axes (not in a list): the phase plane; " + accepted
        raise ArgumentError(f"`{argname}` holds {len(axes)} axes; this figure takes "
                            f"{accepted}")
    figs = {id(_root_figure(a)) for a in axes}
    if len(figs) != 1:
        raise ArgumentError(f"`{argname}`: all axes must belong to one figure")
    if len({id(a) for a in axes}) != len(axes):
        raise ArgumentError(f"`{argname}`: the same axes is given twice")
    return axes, _root_figure(axes[0])


def figure_formats() -> list:
    """The figure formats (file suffixes) matplotlib can write: ``png``, ``pdf``, ``svg``..."""
    from matplotlib.backend_bases import FigureCanvasBase

    return sorted(FigureCanvasBase.get_supported_filetypes())


def _figure_format(path) -> str:
    """The format of a figure file from its suffix (no suffix: PNG); refuses an unknown one."""
    suffix = Path(path).suffix
    fmt = suffix[1:].lower() or "png"
    if fmt not in figure_formats():
        raise ArgumentError(f"cannot write the figure {str(path)!r}: unknown format "
                            f"{suffix!r}; supported formats: {', '.join(figure_formats())}")
    return fmt


def _check_figure_path(path, overwrite: bool = False) -> str:
    """Check a figure path before drawing: its format, directory and an existing file."""
    from .._netcdf import check_output_path

    fmt = _figure_format(path)
    check_output_path(path, overwrite=overwrite)
    return fmt


def _save_figure(fig: Figure, path, overwrite: bool = False) -> Path:
    from .._netcdf import atomic_write

    fmt = _figure_format(path)
    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120, format=fmt),
                        overwrite=overwrite)


# ======================================================================================
# labels next to markers, legends
# ======================================================================================

def _marker_radius(marker, size: float, edge: float = 0.0) -> float:
    """Half the extent of a marker in points: its path at ``size`` plus half its edge."""
    from matplotlib.markers import MarkerStyle

    style = MarkerStyle(marker)
    ext = style.get_path().transformed(style.get_transform()).get_extents()
    return size * float(np.max(np.abs([ext.x0, ext.x1, ext.y0, ext.y1]))) + 0.5 * edge


def _label_beside(ax, text: str, xy, *, marker, size: float, edge: float = 0.0,
                  gap: float = 2.0, side=(1, 1), **kw):
    """Write ``text`` beside a marker at ``xy``, clear of it: the label's near corner is
    offset (in points, so at any zoom) by the marker's half extent and a gap, diagonally to
    ``side`` (``(1, 1)``: up and to the right), so that the label's box and the marker's
    never overlap."""
    d = _marker_radius(marker, size, edge) + gap
    sx, sy = (1 if side[0] >= 0 else -1), (1 if side[1] >= 0 else -1)
    return ax.annotate(text, xy, textcoords="offset points", xytext=(sx * d, sy * d),
                       ha="left" if sx > 0 else "right", va="bottom" if sy > 0 else "top",
                       **kw)


def _free_side(xy, neighbours) -> tuple:
    """The diagonal side of ``xy`` that none of the curve's ``neighbours`` lies towards
    (up-right first, then up-left, down-right, down-left). The side of a point in data
    coordinates is its side on the page at any zoom, so the choice holds however the axes
    are rescaled later."""
    taken = set()
    for q in neighbours:
        dx, dy = q[0] - xy[0], q[1] - xy[1]
        if np.isfinite(dx) and np.isfinite(dy) and (dx or dy):
            taken.add((1 if dx >= 0 else -1, 1 if dy >= 0 else -1))
    for side in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
        if side not in taken:
            return side
    return (1, 1)


def _legend_entry(ax, label: str, **style) -> None:
    """An entry of the axes' legend, added once per axes: an empty line with ``style`` that
    carries ``label``. Figures drawn one after another into one axes (several branches, a
    branch over a sweep) share their entries so, and ``ax.legend()`` called by the user
    later still finds every one of them."""
    if any(line.get_label() == label for line in ax.get_lines()):
        return
    ax.plot([], [], label=label, **style)


def _legend(ax, **kw):
    """The axes' legend, drawn again with every labelled line of the axes, each label once:
    an entry its legend already has keeps its handle (a sweep's markers drawn large enough
    to read), the others are the lines themselves."""
    entries: dict = {}
    old = ax.get_legend()
    if old is not None:
        for handle, text in zip(old.legend_handles, old.get_texts()):
            entries.setdefault(text.get_text(), handle)
    for handle, label in zip(*ax.get_legend_handles_labels()):
        entries.setdefault(label, handle)
    return ax.legend(list(entries.values()), list(entries), **kw)
