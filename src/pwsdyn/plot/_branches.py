"""Continued branches (pwsdyn.continuation): bifurcation diagrams drawn as AUTO and COCO
draw them."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import ArgumentError
from ._common import (_check_figure_path, _free_side, _label_beside, _legend, _legend_entry,
                      _one_axes, _save_figure, _tex)
from ._sweeps import plot_bifurcation

if TYPE_CHECKING:
    import xarray as xr

#: Line styles of a branch: stable solid, unstable dashed, not admissible dotted (AUTO/COCO).
BRANCH_STYLES = {"stable": "-", "unstable": "--", "not admissible": ":"}
#: Markers of special points.
SPECIAL_MARKERS = {"LP": "s", "BP": "D", "PD": "o", "NS": "^", "HB": "*", "EP": "|"}
_SPECIAL_SIZE = 7.0
_SPECIAL_EDGE = 1.5
_SPECIAL_COLOR = "#D55E00"


def _point_styles(branch) -> list:
    """The style of each point: ``"not admissible"``, ``"stable"`` or ``"unstable"``."""
    return ["not admissible" if not a else "stable" if s else "unstable"
            for s, a in zip(branch.stable, branch.admissible)]


def _runs(style: list, special: list, sig: list) -> list:
    """The polylines of a branch, ``(first, last, style)`` with ``last`` included.

    Each segment between two neighbouring points takes a style: where stability or
    admissibility changes at a located special point (a point of its own, whose multiplier
    lies on the unit circle to the tolerance, so its own flag says nothing), the segment on
    either side takes the style of its other end, and the style changes exactly at that
    point. Between two regular points of different styles the segment keeps the first's (the
    change is somewhere inside, and no point says where). No segment joins points of two
    signatures: past a graze the section state is another point of the orbit, and the curve
    restarts there."""
    n = len(style)
    if n == 1:
        return [(0, 0, style[0])]
    seg: list = []
    for k in range(n - 1):
        if sig[k] != sig[k + 1]:
            seg.append(None)
        elif special[k] and not special[k + 1]:
            seg.append(style[k + 1])
        else:
            seg.append(style[k])
    runs: list = []
    for k, st in enumerate(seg):
        if st is None:
            continue
        if runs and runs[-1][1] == k and runs[-1][2] == st:
            runs[-1][1] = k + 1
        else:
            runs.append([k, k + 1, st])
    return [tuple(r) for r in runs]


def _branch_name(branch) -> str:
    """A branch's name in the legend: what its points are."""
    if getattr(branch, "curve", ""):
        return f"{branch.curve} curve"
    if branch.kind != "orbit":
        return "equilibria"
    periods = getattr(getattr(branch.problem, "orbit_problem", None), "periods", 1)
    return f"period-{periods} orbits"


def _marked(ax, kind: str, xy) -> bool:
    """Whether a special point of this kind is already marked at ``xy`` in ``ax``."""
    for line in ax.get_lines():
        if line.get_gid() == f"special {kind}":
            x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            if np.allclose([x[0], y[0]], xy, rtol=1e-9, atol=1e-12):
                return True
    return False


def _branch_y(branch, y):
    """The quantity plotted against the parameter and its axis label."""
    names = list(branch.problem.state_names)
    if (y is None and branch.kind == "orbit" and names
            and getattr(branch, "parameter2", None) is None):
        # the largest value of the first state over the orbit: continuous through a graze,
        # where the section state jumps (the branch would be drawn as two pieces); a
        # two-parameter curve is drawn in its parameter plane instead (below)
        y = f"max:{names[0]}"
    if callable(y):
        if branch.kind != "orbit":
            raise ArgumentError("`y` as a function is a measure of an orbit: the branch is of "
                                f"{branch.kind}s")
        # any measure of the orbit (a PeriodicOrbit: its events, trajectory, multipliers)
        vals = np.array([float(y(branch.problem_of(p).orbit(p.u, p.lam)))
                         for p in branch.points])
        return vals, getattr(y, "__name__", "y").replace("_", " ")
    if isinstance(y, str) and y.split(":")[0] in ("max", "min") and branch.kind == "orbit":
        # a measure of the whole orbit (its largest or smallest value of a state over one
        # period): the same on both sides of a graze, where the section state jumps
        how, _, state = y.partition(":")
        if state not in names:
            raise ArgumentError(f"`y` = {y!r}: {state!r} is not a state {names}")
        k = names.index(state)
        out = []
        for p in branch.points:
            traj = branch.problem_of(p).orbit(p.u, p.lam).trajectory
            _, X = traj.sample(400)
            out.append(X[:, k].max() if how == "max" else X[:, k].min())
        return np.array(out), f"{how} {_tex(state)} over the orbit"
    p2 = getattr(branch, "parameter2", None)
    if p2 is not None and (y is None or y == p2):
        # a two-parameter curve is drawn in its parameter plane by default (the first
        # parameter across, as a period map of pwsdyn.scan is drawn)
        return branch.values_of(p2), _tex(p2)
    if y is None:
        # the state that changes most along the branch (at an impact section the position
        # is the wall's, the same at every point)
        X = branch.states
        y = names[int(np.argmax(np.ptp(X, axis=0)))] if len(X) else names[0]
    if y == "period" and branch.kind == "orbit":
        return np.array([p.data.get("period", np.nan) for p in branch.points]), "period"
    if y == "norm":
        return np.linalg.norm(branch.states, axis=1), "$\\|x\\|$ at the section"
    if isinstance(y, (int, np.integer)):
        if not 0 <= y < len(names):
            raise ArgumentError(f"`y` index {y} out of range for states {names}")
        y = names[y]
    if y not in names:
        raise ArgumentError(f"`y` must be a state {names}, 'norm' or 'period' (orbits), "
                            f"got {y!r}")
    where = "at the section" if branch.kind == "orbit" else "(equilibrium)"
    return branch.states[:, names.index(y)], f"{_tex(y)} {where}"


def plot_branch(branch, y=None, path: str | Path | None = None, *, ax: Axes | None = None,
                labels: bool = True, sweep: xr.Dataset | None = None, color: str = "k",
                overwrite: bool = False, label: str | None = None) -> Figure:
    """Bifurcation diagram of a continued branch (:func:`pwsdyn.continue_orbit`,
    :func:`pwsdyn.continue_equilibrium`), drawn as AUTO and COCO draw them: stable parts
    solid, unstable dashed, parts that are not orbits of the hybrid model (past a grazing)
    dotted; special points marked (fold square, period doubling circle, Neimark-Sacker
    triangle, branch point diamond, Hopf star) and labelled with their kind.

    Parameters
    ----------
    branch : Branch
    y : str, int or callable, optional
        A state (at the section: the start of the orbit's first segment), ``"norm"`` or, for
        orbits, ``"period"``, ``"max:<state>"`` / ``"min:<state>"`` (over the whole orbit:
        continuous across a graze, where the section state jumps) or a function of the
        :class:`~pwsdyn.PeriodicOrbit` at each point (its name, underscores as spaces, labels
        the axis). Default: for orbits ``"max:<first state>"`` (continuous through grazes and
        sliding bifurcations), for equilibria the state that varies most along the branch; for
        a two-parameter curve (:func:`pwsdyn.continue_bifurcation`) its second parameter, so
        that the curve is drawn in the parameter plane (also ``y`` = that parameter's name).
    path : str or Path, optional
        Also save the figure there.
    ax : matplotlib.axes.Axes, optional
        Draw into this Axes (several branches on one diagram, or over a sweep).
    labels : bool
        Write the kind of each special point next to it.
    sweep : xarray.Dataset, optional
        A :func:`pwsdyn.sweep` result drawn first, in light colours, on the same axes (its
        section is its own: a stroboscopic or an event section).
    color : str
        Colour of the branch.
    label : str, optional
        The branch's name in the legend (default: ``"period-k orbits"``, ``"equilibria"``
        or the bifurcation curve's kind). Branches drawn into one axes share one legend:
        each line style once (stable, unstable, not admissible) and each branch's name
        with its colour.
    overwrite : bool
        Replace an existing file at ``path``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if path is not None:
        _check_figure_path(path, overwrite)
    ax, fig = _one_axes(ax, (7.5, 4.8), "the diagram")
    if sweep is not None:
        plot_bifurcation(sweep, ax=ax, markersize=1.0)
    lam = branch.values
    yv, ylabel = _branch_y(branch, y)
    style = _point_styles(branch)
    special = [p.special not in ("", "EP") for p in branch.points]
    sig = [getattr(p, "signature_index", 0) for p in branch.points]
    runs = _runs(style, special, sig)
    for a, b, st in runs:
        ax.plot(lam[a:b + 1], yv[a:b + 1], ls=BRANCH_STYLES[st], color=color, lw=1.4)
    origin = getattr(branch, "origin", "")
    for sp in branch.special_points:
        # a switched branch's first point is the special point of the branch it left (a
        # period-doubled branch starts at a branch point of the doubled problem, born at the
        # PD): it is labelled by that, and drawn once when both branches share the axes
        kind = origin if sp.index == 0 and origin else sp.kind
        xy = (float(sp.value), float(yv[sp.index]))
        if _marked(ax, kind, xy):
            continue
        mk = SPECIAL_MARKERS.get(kind, "o")
        ax.plot(*xy, marker=mk, ls="none", ms=_SPECIAL_SIZE, mfc="white", mec=_SPECIAL_COLOR,
                mew=_SPECIAL_EDGE, zorder=5, gid=f"special {kind}")
        if labels and kind != "EP":
            # on the side the branch does not run to, on a white ground, so that another
            # branch passing by does not strike it out
            k = sp.index
            near = [(lam[j], yv[j]) for j in (k - 1, k + 1) if 0 <= j < len(lam)]
            _label_beside(ax, kind, xy, marker=mk, size=_SPECIAL_SIZE, edge=_SPECIAL_EDGE,
                          gap=3.0, side=_free_side(xy, near), fontsize=8,
                          color=_SPECIAL_COLOR, zorder=6,
                          bbox=dict(boxstyle="square,pad=0.1", fc="white", ec="none",
                                    alpha=0.8))
    # the legend: each style once, and each branch by name (its colour), across every branch
    # drawn into these axes
    drawn = {st for _, _, st in runs}
    for st in BRANCH_STYLES:
        if st in drawn:
            _legend_entry(ax, st, ls=BRANCH_STYLES[st], color="k", lw=1.4)
    _legend_entry(ax, label if label is not None else _branch_name(branch), ls="none",
                  marker="s", ms=7, color=color)
    _legend(ax, fontsize=8, loc="best")
    ax.set_xlabel(_tex(branch.parameter))
    ax.set_ylabel(ylabel)
    ax.set_title(f"{branch.model.name}: {branch.kind} branch in {_tex(branch.parameter)}",
                 fontsize="medium")
    ax.grid(True, lw=0.3)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


# ======================================================================================
# response metrics over a parameter
