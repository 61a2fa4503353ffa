"""Continued branches (pwsdyn.continuation): bifurcation diagrams drawn as AUTO and COCO
draw them."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import ArgumentError
from ._common import _check_figure_path, _save_figure, _tex, _user_axes
from ._sweeps import plot_bifurcation

if TYPE_CHECKING:
    import xarray as xr

#: Line styles of a branch: stable solid, unstable dashed, not admissible dotted (AUTO/COCO).
BRANCH_STYLES = {"stable": "-", "unstable": "--", "not admissible": ":"}
#: Markers of special points.
SPECIAL_MARKERS = {"LP": "s", "BP": "D", "PD": "o", "NS": "^", "HB": "*", "EP": "|"}


def _branch_y(branch, y):
    """The quantity plotted against the parameter and its axis label."""
    names = list(branch.problem.state_names)
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
                overwrite: bool = False) -> Figure:
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
        the axis). Default: the state that varies most along the branch.
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
    overwrite : bool
        Replace an existing file at ``path``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if path is not None:
        _check_figure_path(path, overwrite)
    if ax is None:
        fig = Figure(figsize=(7.5, 4.8), layout="constrained")
        ax = fig.subplots()
    else:
        axes, fig = _user_axes(ax, {1: "the diagram"})
        ax = axes[0]
    if sweep is not None:
        plot_bifurcation(sweep, ax=ax, markersize=1.0)
    lam = branch.values
    yv, ylabel = _branch_y(branch, y)
    stab = branch.stable
    adm = branch.admissible
    style = np.where(~adm, "not admissible", np.where(stab, "stable", "unstable"))
    sig = np.array([getattr(p, "signature_index", 0) for p in branch.points])
    seen = set()
    start = 0
    for i in range(1, len(lam) + 1):
        if i == len(lam) or style[i] != style[start] or sig[i] != sig[start]:
            # each run of one style, joined to the next point so that the curve is unbroken;
            # not across a change of signature (past a graze the section state is another
            # point of the orbit: the curve restarts there)
            j = min(i + 1, len(lam)) if i < len(lam) and sig[i] == sig[start] else i
            st = str(style[start])
            ax.plot(lam[start:j], yv[start:j], ls=BRANCH_STYLES[st], color=color, lw=1.4,
                    label=st if st not in seen else None)
            seen.add(st)
            start = i
    for sp in branch.special_points:
        mk = SPECIAL_MARKERS.get(sp.kind, "o")
        ax.plot([sp.value], [yv[sp.index]], marker=mk, ls="none", ms=7, mfc="white",
                mec="#D55E00", mew=1.5, zorder=5)
        if labels and sp.kind != "EP":
            ax.annotate(sp.kind, (sp.value, yv[sp.index]), textcoords="offset points",
                        xytext=(5, 5), fontsize=8, color="#D55E00")
    ax.set_xlabel(_tex(branch.parameter))
    ax.set_ylabel(ylabel)
    ax.set_title(f"{branch.model.name}: {branch.kind} branch in {_tex(branch.parameter)}",
                 fontsize="medium")
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, lw=0.3)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


# ======================================================================================
# response metrics over a parameter
