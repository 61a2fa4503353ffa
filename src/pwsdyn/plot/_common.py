"""What every figure family shares: parameter and state names typeset, numbers written for
mathtext, the user's axes checked, legends merged, figure files checked and written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import ArgumentError

def _latex_name(name: str) -> str:
    import sympy as sp

    # Greek letters and subscripts as a reader expects them (omega -> \omega, mu_s -> \mu_{s})
    return sp.latex(sp.Symbol(name))


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
    from .._netcdf import _check_output_path

    fmt = _figure_format(path)
    _check_output_path(path, overwrite=overwrite)
    return fmt


def _save_figure(fig: Figure, path, overwrite: bool = False) -> Path:
    from ..io import atomic_write

    fmt = _figure_format(path)
    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120, format=fmt),
                        overwrite=overwrite)


def _tex(name: str) -> str:
    return f"${_latex_name(name)}$"

