"""Figures of simulation results (matplotlib).

Figures are built on :class:`matplotlib.figure.Figure` directly, without ``pyplot``: no global
figure state, nothing is shown, no GUI backend is needed, and the user's backend choice is left
alone. A returned figure displays in a notebook and can be saved with ``fig.savefig``.

A figure written through the ``path`` argument of the functions here never replaces an
existing file unless ``overwrite=True`` (:class:`~pwsdyn.OutputExistsError` otherwise); the
path (directory, format, existing file) is checked before the figure is drawn.

This module only reads result objects; the numerical code never imports it.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .errors import ArgumentError

if TYPE_CHECKING:
    import xarray as xr

    from .integrate.trajectory import Trajectory
    from .orbits import PeriodicOrbit

#: Colour of the trajectory itself.
TRAJECTORY_COLOR = "#0072B2"
#: Marker style of each event kind (Okabe-Ito colours, readable by colour-blind readers,
#: and a distinct marker shape per kind so the figure also reads in grey scale).
EVENT_STYLES = {
    "impact": dict(color="#D55E00", marker="o", label="impact"),
    "transition": dict(color="#CC79A7", marker="D", label="transition"),
    "chatter": dict(color="#E69F00", marker="*", label="chattering sequence"),
    "stick": dict(color="#009E73", marker="v", label="stick"),
    "release": dict(color="#56B4E9", marker="^", label="release"),
    "crossing": dict(color="#000000", marker="X", label="crossing"),
    "slide_start": dict(color="#F0E442", marker=">", label="sliding starts"),
    "slide_end": dict(color="#8C564B", marker="<", label="sliding ends"),
}
#: Underlay of the segments where the motion is constrained to a surface.
CONSTRAINED_STYLES = {
    "stick": dict(color="#009E73", label="sticking"),
    "slide": dict(color="#CC79A7", label="sliding"),
}
SURFACE_COLOR = "0.35"
#: Largest number of samples chosen automatically (see ``num`` of :func:`plot_trajectory`).
_MAX_AUTO_SAMPLES = 60_000


# ======================================================================================
# surfaces
# ======================================================================================

@dataclass
class _SurfaceCurve:
    """A surface solved for one state: ``x[state] = position(t)``."""

    name: str
    state: int
    position: object  # callable t -> values
    label: str


@dataclass
class _SurfaceContour:
    """A time-independent surface of at most the two phase-plane states."""

    name: str
    states: tuple  # indices into the model's states, a subset of the phase-plane pair
    function: object  # callable (x_i, x_j) -> values
    label: str


def _latex_name(name: str) -> str:
    import sympy as sp

    # Greek letters and subscripts as a reader expects them (omega -> \omega, mu_s -> \mu_{s})
    return sp.latex(sp.Symbol(name))


def _analyse_surfaces(model, params: dict, phase: tuple | None):
    """Split the model's surfaces into those drawn in the time series and in the phase plane.

    A surface ``h`` linear in exactly one state ``s`` (the only state it involves, with a
    coefficient free of ``s``) is solved for ``s`` as a function of time: the position of a
    wall or a table, drawn under that state's time series. A surface that does not depend on
    time and involves only the phase-plane states is drawn as its zero contour there.
    """
    import sympy as sp

    states = model.state_symbols
    t = model.t
    psyms = model.parameter_symbols
    pvals = {s: float(params.get(str(s), model.parameters[str(s)])) for s in psyms}
    curves, contours = [], []
    for surf in model.surfaces:
        expr = sp.sympify(surf.expr)
        involved = [k for k, s in enumerate(states) if expr.has(s)]
        try:
            if len(involved) == 1:
                k = involved[0]
                s = states[k]
                coeff = sp.diff(expr, s)
                if coeff != 0 and not coeff.has(s):
                    # expr = coeff*s + rest  =>  s = -rest/coeff on the surface
                    position = -expr.subs(s, 0) / coeff
                    f = sp.lambdify((t,) + psyms, position, modules="numpy")
                    vals = [pvals[p] for p in psyms]
                    label = (f"{surf.name} surface: ${sp.latex(s)} = "
                             f"{sp.latex(position)}$")
                    curves.append(_SurfaceCurve(
                        surf.name, k,
                        lambda tt, f=f, vals=vals: np.broadcast_to(
                            np.asarray(f(tt, *vals), dtype=float), np.shape(tt)),
                        label))
            # with the parameter values in, a table at rest (A = 0) is a fixed wall
            sub = expr.subs(pvals)
            if (phase is not None and involved and not sub.has(t)
                    and set(involved) <= set(phase)):
                i, j = phase
                f2 = sp.lambdify((states[i], states[j]), sub, modules="numpy")
                contours.append(_SurfaceContour(
                    surf.name, tuple(involved),
                    lambda a, b, f2=f2: np.broadcast_to(
                        np.asarray(f2(a, b), dtype=float), np.shape(a)),
                    f"{surf.name} surface: ${sp.latex(expr)} = 0$"))
        except Exception as exc:  # a surface we cannot draw must not cost the whole figure
            warnings.warn(f"surface {surf.name!r} is not drawn: {exc}", stacklevel=3)
    return curves, contours


# ======================================================================================
# data preparation
# ======================================================================================

def _state_index(model, s, argname: str) -> int:
    names = list(model.states)
    if isinstance(s, (int, np.integer)) and not isinstance(s, bool):
        if not -len(names) <= s < len(names):
            raise ArgumentError(f"`{argname}`: state index {s} out of range for states {names}")
        return int(s) % len(names)
    if isinstance(s, str):
        if s not in names:
            raise ArgumentError(f"`{argname}`: unknown state {s!r}; states are {names}")
        return names.index(s)
    raise ArgumentError(f"`{argname}` must hold state names or indices, got {s!r}")


def _left_right(T, X):
    """Keep only the first (left) and last (right) sample of each run of equal times.

    ``Trajectory.sample`` may list an event time more than once (for instance as both ``t``
    and ``t_after`` of an impact), which would read as the state jumping back and forth.
    """
    if len(T) < 3:
        return T, X
    new_run = np.r_[True, T[1:] != T[:-1]]
    run_end = np.r_[T[1:] != T[:-1], True]
    keep = new_run | run_end
    return T[keep], X[keep]


def _break_at_jumps(T, Y, tol):
    """Insert NaN where the state jumps, so the line is not drawn across the jump.

    ``T``, ``Y`` come from :meth:`Trajectory.sample` (both sides of every event at one time).
    Returns the broken arrays and the list of jumps as ``(y_before, y_after)`` pairs.
    """
    if len(T) < 2:
        return T, Y, []
    same = T[1:] == T[:-1]
    diff = np.abs(Y[1:] - Y[:-1]) > tol
    jump = same & np.any(diff, axis=1)
    idx = np.nonzero(jump)[0] + 1
    pairs = [(T[k], Y[k - 1], Y[k]) for k in idx]
    Tb = np.insert(T.astype(float), idx, np.nan)
    Yb = np.insert(Y.astype(float), idx, np.nan, axis=0)
    return Tb, Yb, pairs


def _constrained_spans(traj):
    """Time spans ``(a, b, kind, name)`` where the state is ``stick:...`` or ``slide:...``."""
    from .integrate.trajectory import DiscreteState

    t = np.asarray(traj.t)
    spans = []
    cur = None
    for i in range(len(t) - 1):
        if not t[i + 1] > t[i]:
            continue  # a jump: zero length, the discrete state changes across it
        st = traj.state[i]
        kind = DiscreteState.parse(str(st)).kind
        if kind in CONSTRAINED_STYLES:
            if cur is not None and cur[3] == st and cur[1] == t[i]:
                cur[1] = t[i + 1]
            else:
                if cur is not None:
                    spans.append(tuple(cur))
                cur = [t[i], t[i + 1], kind, st]
        elif cur is not None:
            spans.append(tuple(cur))
            cur = None
    if cur is not None:
        spans.append(tuple(cur))
    return spans


def _span_states(traj, a, b, num):
    """Times and states on ``[a, b]``: the right side of a jump at ``a``, the left at ``b``."""
    if traj.dense is None:
        t = np.asarray(traj.t)
        sel = (t >= a) & (t <= b)
        return t[sel], np.asarray(traj.x)[sel]
    ts = np.linspace(a, b, max(num, 2))
    xs = np.empty((len(ts), traj.n_states))
    xs[:-1] = traj(ts[:-1], side="right")
    xs[-1] = traj(ts[-1], side="left")
    return ts, xs


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


def _title(traj) -> str:
    model = traj.model
    lines = _values_text(dict(traj.params), width=90)
    if len(lines) == 1 and len(lines[0]) < 60:
        title = f"{model.name}   ({lines[0]})"
    else:
        title = "\n".join([f"{model.name}"] + lines)
    if traj.status.failed:
        title += f"\nstopped early: {traj.status.name} at $t = {traj.t_final:.10g}$"
    if traj.dense is None:
        title += "\n(no dense output: straight lines between stored nodes)"
    return title


# ======================================================================================
# axes: the figure's own, or the user's (``ax=``)
# ======================================================================================

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


def _trajectory_slots(ax, n_series: int, has_phase: bool, multipliers: bool = False):
    """Split the user's axes into (time-series axes, phase-plane axes, multiplier axes,
    figure): one Axes is the phase plane (a one-state model's time series); a sequence holds
    the time series, then the phase plane, then (an orbit's) multipliers."""
    if isinstance(ax, Axes):
        if has_phase:
            return [], ax, None, _root_figure(ax)
        if n_series == 1:
            return [ax], None, None, _root_figure(ax)
    series = f"the {n_series} time series" if n_series > 1 else "the time series"
    counts = {n_series: series}
    if has_phase:
        counts[n_series + 1] = f"{series}, then the phase plane"
        if multipliers:
            counts[n_series + 2] = f"{series}, the phase plane, then the Floquet multipliers"
    axes, fig = _user_axes(ax, counts, single_ok=has_phase)
    k = len(axes)
    if k == n_series:
        return axes, None, None, fig
    if k == n_series + 1:
        return axes[:-1], axes[-1], None, fig
    return axes[:n_series], axes[n_series], axes[n_series + 1], fig


# ======================================================================================
# the figure
# ======================================================================================

@dataclass
class _Prepared:
    """A trajectory sampled and analysed for drawing."""

    shown: list
    phase_ij: tuple | None
    T: np.ndarray
    X: np.ndarray
    tol: np.ndarray
    curves: list
    contours: list
    spans: list
    events: list
    msize: float
    num_eff: int


def _check_trajectory(traj) -> None:
    for attr in ("t", "x", "events", "model", "sample"):
        if not hasattr(traj, attr):
            raise ArgumentError(f"`traj` must be a Trajectory, got {type(traj).__name__}")


def _panels(model, states, phase) -> tuple:
    """The states shown as time series and the phase-plane pair (checked arguments)."""
    names = list(model.states)
    n = len(names)
    if states is None:
        shown = list(range(n))
    else:
        if isinstance(states, (str, int)):
            states = [states]
        shown = [_state_index(model, s, "states") for s in states]
        if not shown:
            raise ArgumentError("`states` must name at least one state")
    if phase is None:
        phase_ij = (0, 1) if n >= 2 else None
    else:
        if n < 2:
            raise ArgumentError(f"`phase`: model {model.name!r} has one state, no phase plane")
        if len(phase) != 2:
            raise ArgumentError(f"`phase` must be a pair of states, got {phase!r}")
        phase_ij = (_state_index(model, phase[0], "phase"), _state_index(model, phase[1], "phase"))
        if phase_ij[0] == phase_ij[1]:
            raise ArgumentError(f"`phase` must name two different states, got {phase!r}")
    return shown, phase_ij


def _prepare(traj, shown, phase_ij, num) -> _Prepared:
    model = traj.model
    n = len(model.states)
    # at least a few samples per stored step, so long runs with many oscillations stay smooth;
    # capped because every sample is evaluated from the dense output one by one
    num_eff = int(min(max(num, 3 * len(traj.t)), max(num, _MAX_AUTO_SAMPLES)))
    T, X = traj.sample(num_eff)
    T, X = _left_right(np.asarray(T, dtype=float), np.asarray(X, dtype=float))
    # a jump is a change larger than rounding relative to the size of the data
    scale = np.maximum(np.nanmax(np.abs(X), axis=0), 1e-300) if len(X) else np.ones(n)
    tol = 1e-9 * scale
    curves, contours = _analyse_surfaces(model, traj.params, phase_ij)
    duration = max(float(T[-1] - T[0]), 1e-300) if len(T) else 1.0
    spans = [(kind, *_span_states(traj, a, b, max(200, int(num_eff * (b - a) / duration))))
             for a, b, kind, _ in _constrained_spans(traj)]
    events = list(traj.events)
    msize = 30 if len(events) <= 200 else 12
    return _Prepared(shown, phase_ij, T, X, tol, curves, contours, spans, events, msize,
                     num_eff)


def _draw_trajectory(traj, pr: _Prepared, ts_axes: list, ph_ax, own: bool) -> dict:
    """Draw the time series into ``ts_axes`` (one per shown state) and the phase plane into
    ``ph_ax`` (or none); returns the legend handles by key."""
    model = traj.model
    names = list(model.states)
    T, X, tol = pr.T, pr.X, pr.tol
    handles: dict = {}
    label_of = {k: f"${_latex_name(names[k])}$" for k in range(len(names))}

    # --- time series ---------------------------------------------------------------------
    for row, (ax, k) in enumerate(zip(ts_axes, pr.shown)):
        for kind, ss, xs in pr.spans:
            style = CONSTRAINED_STYLES[kind]
            h, = ax.plot(ss, xs[:, k], color=style["color"], lw=6, alpha=0.35,
                         solid_capstyle="butt", zorder=1)
            handles.setdefault(f"{kind}", (h, style["label"]))
        for c in pr.curves:
            if c.state != k:
                continue
            tt = np.linspace(T[0], T[-1], pr.num_eff)
            with np.errstate(all="ignore"):
                h, = ax.plot(tt, c.position(tt), ls="--", lw=1.1, color=SURFACE_COLOR, zorder=2)
            handles.setdefault(f"surface:{c.name}", (h, c.label))
        Tb, Yb, jumps = _break_at_jumps(T, X[:, [k]], tol[[k]])
        h, = ax.plot(Tb, Yb[:, 0], color=TRAJECTORY_COLOR, lw=1.3, zorder=3)
        handles.setdefault("trajectory", (h, "trajectory"))
        if jumps:
            jt = [(tj, tj) for tj, _, _ in jumps]
            jy = [(y0[0], y1[0]) for _, y0, y1 in jumps]
            h, = ax.plot(*_segments(jt, jy), ls=":", lw=0.9, color=TRAJECTORY_COLOR, zorder=3)
            handles.setdefault("jump", (h, "jump (reset)"))
        _mark_events(ax, pr.events, lambda e: (e.t, e.x_before[k]), pr.msize, handles)
        ax.set_ylabel(label_of[k])
        ax.grid(True, alpha=0.3, lw=0.6)
        ax.margins(x=0.01)
        if own and row < len(ts_axes) - 1:
            ax.tick_params(labelbottom=False)
        if not own or row == len(ts_axes) - 1:
            ax.set_xlabel("$t$")

    # --- phase plane -----------------------------------------------------------------------
    if ph_ax is not None and pr.phase_ij is not None:
        i, j = pr.phase_ij
        ax = ph_ax
        for kind, ss, xs in pr.spans:
            style = CONSTRAINED_STYLES[kind]
            h, = ax.plot(xs[:, i], xs[:, j], color=style["color"], lw=6, alpha=0.35,
                         solid_capstyle="round", zorder=1)
            handles.setdefault(f"{kind}", (h, style["label"]))
        Tb, Yb, jumps = _break_at_jumps(T, X[:, [i, j]], tol[[i, j]])
        h, = ax.plot(Yb[:, 0], Yb[:, 1], color=TRAJECTORY_COLOR, lw=1.1, zorder=3)
        handles.setdefault("trajectory", (h, "trajectory"))
        if jumps:
            jx = [(y0[0], y1[0]) for _, y0, y1 in jumps]
            jy = [(y0[1], y1[1]) for _, y0, y1 in jumps]
            h, = ax.plot(*_segments(jx, jy), ls=":", lw=0.9, color=TRAJECTORY_COLOR, zorder=3)
            handles.setdefault("jump", (h, "jump (reset)"))
        _mark_events(ax, pr.events, lambda e: (e.x_before[i], e.x_before[j]), pr.msize,
                     handles)
        h = ax.scatter([X[0, i]], [X[0, j]], s=40, facecolors="white", edgecolors="k",
                       linewidths=1.2, zorder=5)
        handles.setdefault("start", (h, "initial state"))
        ax.set_xlabel(label_of[i])
        ax.set_ylabel(label_of[j])
        ax.grid(True, alpha=0.3, lw=0.6)
        if own:
            ax.set_title("phase plane", fontsize="medium")
        _draw_contours(ax, pr.contours, pr.phase_ij, handles)
    return handles


def _legend_items(model, handles: dict) -> list:
    order = (["trajectory", "jump", "start"] + [f"surface:{s.name}" for s in model.surfaces]
             + list(CONSTRAINED_STYLES) + [f"event:{k}" for k in EVENT_STYLES])
    return [handles[key] for key in order if key in handles]


def _trajectory_figure(n_series: int, has_phase: bool, multipliers: bool = False):
    """The figure of :func:`plot_trajectory` (and :func:`plot_orbit` with ``multipliers``):
    time series on the left, the phase plane to their right, and for an orbit a column with
    the Floquet multipliers (and their values below) on the far right."""
    width_ratios = [1.45] + ([1.0] if has_phase else []) + ([0.7] if multipliers else [])
    width = 11.0 + (2.9 if multipliers else 0.0)
    fig = Figure(figsize=(width, max(4.2, 1.9 * n_series + 1.6)), layout="constrained")
    gs = fig.add_gridspec(n_series, len(width_ratios), width_ratios=width_ratios)
    ts_axes: list = []
    for row in range(n_series):
        ts_axes.append(fig.add_subplot(gs[row, 0], sharex=ts_axes[0] if ts_axes else None))
    ph_ax = fig.add_subplot(gs[:, 1]) if has_phase else None
    mu_ax = text_ax = None
    if multipliers:
        sub = gs[:, -1].subgridspec(2, 1, height_ratios=[1.0, 0.8])
        mu_ax = fig.add_subplot(sub[0])
        text_ax = fig.add_subplot(sub[1])
        text_ax.set_axis_off()
    return fig, ts_axes, ph_ax, mu_ax, text_ax


def _finish(fig, model, handles, title: str, ts_axes: list, ph_ax, own: bool) -> None:
    """Title and legend: the figure's (own figure) or the first and last axes' (``ax=``)."""
    items = _legend_items(model, handles)
    if own:
        fig.suptitle(title, fontsize="large")
        if items:
            fig.legend([h for h, _ in items], [lab for _, lab in items],
                       loc="outside lower center", ncol=min(len(items), 4), frameon=False,
                       fontsize="small")
        return
    axes = ts_axes + ([ph_ax] if ph_ax is not None else [])
    axes[0].set_title(title, fontsize="medium")
    if items:
        axes[-1].legend([h for h, _ in items], [lab for _, lab in items], fontsize="x-small",
                        loc="best")


def plot_trajectory(traj: Trajectory, path: str | Path | None = None,
                    states: Sequence[str | int] | str | int | None = None,
                    phase: tuple[str | int, str | int] | None = None, *, num: int = 4000,
                    title: str | None = None, overwrite: bool = False,
                    ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """A figure of a trajectory: time series, phase plane, events and event surfaces.

    Panels: on the left the time series of each state; on the right the phase plane of two
    states. The flow is drawn with a break at each jump of the state (impacts, resets) and a
    thin dotted line joining the two sides of the jump. Events are marked at the state just
    before them, coloured and shaped by kind. Segments of sticking or sliding on a surface are
    underlaid with a thick band. Event surfaces are drawn dashed: a surface that gives one
    state as a function of time (a wall, a vibrating table ``y = A sin(omega t)``) in that
    state's time series; a time-independent surface of the phase-plane states as its zero
    contour in the phase plane.

    Parameters
    ----------
    traj : Trajectory
        A result of :func:`pwsdyn.simulate`.
    path : str or pathlib.Path, optional
        Also save the figure there (PNG at 120 dpi unless the suffix names another format).
        The file is written atomically (temporary file, then rename). The path is checked
        before the figure is drawn (directory, format, existing file). With ``ax``, the
        figure that holds ``ax`` is saved.
    states : sequence of str or int, optional
        States shown as time series (default: all), by name or index.
    phase : (str or int, str or int), optional
        The two states of the phase plane (default: the first two). A model with one state
        has no phase plane.
    num : int
        Least number of uniform sample times (both sides of every event are added). Long
        runs get up to three per stored step, at most 60000 unless ``num`` is larger.
    title : str, optional
        Replaces the default title (model name and parameter values).
    overwrite : bool
        Replace an existing file at ``path``; by default it is refused with
        :class:`~pwsdyn.OutputExistsError` before anything is drawn.
    ax : matplotlib.axes.Axes or sequence of Axes, optional
        Draw into these axes of your own figure instead of a new one: one Axes receives the
        phase plane (the time series of a one-state model); a sequence receives the time
        series of ``states`` in order, then (if it holds one more axes) the phase plane --
        ``ax=[ax_x]`` with ``states=["x"]`` draws one time series. The title goes to the
        first of these axes and the legend into the last; the figure's layout, title and
        legend are left alone.

    Returns
    -------
    matplotlib.figure.Figure
        The new figure, or with ``ax`` the figure that holds ``ax``.

    Examples
    --------
    >>> import pwsdyn
    >>> from pwsdyn.plot import plot_trajectory
    >>> traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 5))
    >>> fig = plot_trajectory(traj)
    """
    _check_trajectory(traj)
    if path is not None:
        _check_figure_path(path, overwrite)
    model = traj.model
    shown, phase_ij = _panels(model, states, phase)
    if not (isinstance(num, (int, np.integer)) and num >= 2):
        raise ArgumentError(f"`num` must be an integer >= 2, got {num!r}")
    own = ax is None
    if own:
        fig, ts_axes, ph_ax, _, _ = _trajectory_figure(len(shown), phase_ij is not None)
    else:
        ts_axes, ph_ax, _, fig = _trajectory_slots(ax, len(shown), phase_ij is not None)
    pr = _prepare(traj, shown, phase_ij, num)
    handles = _draw_trajectory(traj, pr, ts_axes, ph_ax, own)
    _finish(fig, model, handles, title if title is not None else _title(traj), ts_axes, ph_ax,
            own)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def _draw_multipliers(ax, mult: np.ndarray) -> None:
    """The Floquet multipliers in the complex plane, with the unit circle."""
    th = np.linspace(0.0, 2.0 * np.pi, 200)
    ax.plot(np.cos(th), np.sin(th), color=SURFACE_COLOR, lw=0.8)
    ax.axhline(0.0, color="0.8", lw=0.5, zorder=0)
    ax.axvline(0.0, color="0.8", lw=0.5, zorder=0)
    ax.scatter(mult.real, mult.imag, s=36, marker="x", color="#D55E00", linewidths=1.4,
               zorder=3)
    big = float(np.max(np.abs(mult))) if mult.size else 0.0
    lim = max(1.15, 1.1 * big) if np.isfinite(big) else 1.15
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(r"Re $\mu$", fontsize="small")
    ax.set_ylabel(r"Im $\mu$", fontsize="small", labelpad=1)
    ax.tick_params(labelsize="x-small")
    ax.set_title("Floquet multipliers", fontsize="medium")


def _multiplier_text(mult: np.ndarray, trivial=None, most: int = 6) -> str:
    """The multipliers, largest modulus first: each value, and its modulus below it."""
    order = np.argsort(-np.abs(mult), kind="stable")
    lines = []
    for r, m in enumerate(mult[order][:most]):
        re, im = float(m.real), float(m.imag)
        value = f"{re:.4g}" if im == 0 else f"{re:.4g} {'+' if im > 0 else '-'} {abs(im):.4g}i"
        lines.append(f"$\\mu_{{{r + 1}}}$ = {value}")
        lines.append(f"      $|\\mu_{{{r + 1}}}|$ = {abs(m):.4g}")
    if len(mult) > most:
        lines.append(f"... ({len(mult) - most} more)")
    if not lines:
        lines.append("(no multipliers)")
    if trivial is not None:
        lines.append(f"(trivial multiplier 1 left out:\n |$\\mu$ - 1| = {abs(trivial - 1):.2g})")
    return "\n".join(lines)


def plot_orbit(orbit: PeriodicOrbit, path: str | Path | None = None,
               states: Sequence[str | int] | str | int | None = None,
               phase: tuple[str | int, str | int] | None = None, *, num: int = 4000,
               overwrite: bool = False, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """A figure of a periodic orbit: one period with its events, and its Floquet multipliers.

    The panels of :func:`plot_trajectory` for ``orbit.trajectory`` (time series, phase plane,
    events marked by kind, event surfaces), the period, stability and largest multiplier
    modulus in the title, and a separate panel on the right with the multipliers in the
    complex plane (the unit circle drawn) and their values listed below it -- apart from the
    other panels, so it never covers the orbit or its tick labels.

    Parameters
    ----------
    orbit : PeriodicOrbit
        A result of :func:`pwsdyn.find_periodic_orbit`.
    path : str or pathlib.Path, optional
        Also save the figure there.
    states, phase, num, overwrite
        As for :func:`plot_trajectory`.
    ax : matplotlib.axes.Axes or sequence of Axes, optional
        Draw into your own axes, as for :func:`plot_trajectory`; a sequence may hold one more
        axes after the phase plane for the multipliers (otherwise they are only summarised in
        the title).

    Returns
    -------
    matplotlib.figure.Figure
        The new figure, or with ``ax`` the figure that holds ``ax``.
    """
    for attr in ("trajectory", "multipliers", "period", "events"):
        if not hasattr(orbit, attr):
            raise ArgumentError(f"`orbit` must be a PeriodicOrbit, got {type(orbit).__name__}")
    if orbit.trajectory is None:
        raise ArgumentError("the orbit has no trajectory to plot")
    if path is not None:
        _check_figure_path(path, overwrite)
    traj = orbit.trajectory
    model = traj.model
    shown, phase_ij = _panels(model, states, phase)
    if not (isinstance(num, (int, np.integer)) and num >= 2):
        raise ArgumentError(f"`num` must be an integer >= 2, got {num!r}")
    mult = np.atleast_1d(np.asarray(orbit.multipliers if orbit.multipliers is not None else [],
                                    dtype=complex))
    own = ax is None
    text_ax = None
    if own:
        fig, ts_axes, ph_ax, mu_ax, text_ax = _trajectory_figure(len(shown),
                                                                 phase_ij is not None, True)
    else:
        ts_axes, ph_ax, mu_ax, fig = _trajectory_slots(ax, len(shown), phase_ij is not None,
                                                       multipliers=True)
    stab = "stable" if orbit.stable else "unstable"
    head = _title(traj).split("\n(no dense")[0].split("\nstopped early")[0]
    biggest = (f", max $|\\mu| = {_number(np.max(np.abs(mult)))}$"
               if mult.size and np.all(np.isfinite(mult)) else "")
    n_ev = len(orbit.events)
    title = (f"{head}\nperiodic orbit: $T = {orbit.period:.10g}$, {n_ev} "
             f"event{'' if n_ev == 1 else 's'} per period, {stab}{biggest}"
             + ("" if orbit.converged else " (NOT converged)"))
    pr = _prepare(traj, shown, phase_ij, num)
    handles = _draw_trajectory(traj, pr, ts_axes, ph_ax, own)
    _finish(fig, model, handles, title, ts_axes, ph_ax, own)
    if mu_ax is not None:
        _draw_multipliers(mu_ax, mult)
    if text_ax is not None:
        text_ax.text(0.0, 1.0, _multiplier_text(mult, getattr(orbit, "trivial_multiplier", None)),
                     transform=text_ax.transAxes, va="top", ha="left", fontsize="small",
                     linespacing=1.4)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def _segments(xpairs, ypairs):
    """Many two-point segments as one NaN-separated polyline (one artist, fast to draw)."""
    m = len(xpairs)
    xs = np.full(3 * m, np.nan)
    ys = np.full(3 * m, np.nan)
    xs[0::3], xs[1::3] = np.asarray(xpairs, dtype=float).T
    ys[0::3], ys[1::3] = np.asarray(ypairs, dtype=float).T
    return xs, ys


def _mark_events(ax, events, where, msize, handles):
    by_kind: dict = {}
    for e in events:
        by_kind.setdefault(e.kind, []).append(where(e))
    # chattering last, so its star lies on top of the stick mark that follows it at almost
    # the same place
    rank = {k: r for r, k in enumerate(k for k in EVENT_STYLES if k != "chatter")}
    rank["chatter"] = len(rank)
    for kind in sorted(by_kind, key=lambda k: rank.get(k, len(rank))):
        pts = by_kind[kind]
        style = EVENT_STYLES.get(kind, dict(color="k", marker="o", label=kind))
        pts = np.asarray(pts, dtype=float)
        h = ax.scatter(pts[:, 0], pts[:, 1], s=msize * (1.8 if style["marker"] == "*" else 1),
                       marker=style["marker"], color=style["color"], edgecolors="k",
                       linewidths=0.5, zorder=4 + 0.01 * rank.get(kind, len(rank)))
        handles.setdefault(f"event:{kind}", (h, style["label"]))


def _draw_contours(ax, contours, phase_ij, handles):
    if not contours:
        return
    # the surfaces are drawn over the region the data occupy (plus the default margins)
    ax.autoscale_view()
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    gx = np.linspace(*xlim, 400)
    gy = np.linspace(*ylim, 400)
    GX, GY = np.meshgrid(gx, gy)
    for c in contours:
        try:
            with np.errstate(all="ignore"):
                Z = np.array(c.function(GX, GY), dtype=float)
        except Exception as exc:
            warnings.warn(f"surface {c.name!r} is not drawn in the phase plane: {exc}",
                          stacklevel=3)
            continue
        finite = Z[np.isfinite(Z)]
        if finite.size == 0 or not (finite.min() <= 0 <= finite.max()):
            continue  # the surface does not pass through the plotted region
        ax.contour(GX, GY, Z, levels=[0.0], colors=[SURFACE_COLOR], linestyles="--",
                   linewidths=1.1, zorder=2)
        proxy = Line2D([], [], ls="--", lw=1.1, color=SURFACE_COLOR)
        handles.setdefault(f"surface:{c.name}", (proxy, c.label))
    ax.set_xlim(xlim)
    ax.set_ylim(ylim)


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
    from ._netcdf import _check_output_path

    fmt = _figure_format(path)
    _check_output_path(path, overwrite=overwrite)
    return fmt


def _save_figure(fig: Figure, path, overwrite: bool = False) -> Path:
    from .io import atomic_write

    fmt = _figure_format(path)
    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120, format=fmt),
                        overwrite=overwrite)


# ======================================================================================
# global analysis: bifurcation diagrams, basins, Lyapunov exponents (pwsdyn.explore)
# ======================================================================================

#: Colours of the up and down sweeps (Okabe-Ito blue and vermillion).
SWEEP_COLORS = {"up": "#0072B2", "down": "#D55E00"}
#: Markers of the up and down sweeps: filled dots up, crosses down -- where both sweeps
#: give the same points the dot shows through the cross, where they differ (hysteresis)
#: each reads on its own, also in grey scale.
SWEEP_MARKERS = {"up": "o", "down": "x"}
#: Colours of the basin labels -2 (run failed) and -1 (diverged); attractors use BASIN_COLORS.
BASIN_SPECIAL_COLORS = {-2: "#7F7F7F", -1: "#000000"}
BASIN_COLORS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
                "#8C564B", "#9467BD", "#BCBD22", "#17BECF", "#FF9896")


def _tex(name: str) -> str:
    return f"${_latex_name(name)}$"


def _sweep_param(ds):
    if ds.attrs.get("kind") != "sweep":
        raise ArgumentError("expected the dataset of pwsdyn.sweep (attribute kind = 'sweep')")
    return ds.attrs["parameter"]


def _settings(ds) -> dict:
    """The run settings stored with a sweep or basins dataset (empty if unreadable)."""
    import json

    try:
        s = json.loads(ds.attrs.get("settings", "{}"))
    except (TypeError, ValueError):
        return {}
    return s if isinstance(s, dict) else {}


def _fixed_text(ds, exclude=(), width: int = 80) -> str:
    """The parameter values of the run (not ``exclude``), wrapped into lines."""
    params = _settings(ds).get("params")
    if not isinstance(params, dict):
        return ""
    return "\n".join(_values_text(params, exclude=exclude, width=width))


def _explore_title(ds, what: str, exclude=()) -> str:
    head = f"{ds.attrs.get('model', '')}: {what}"
    fixed = _fixed_text(ds, exclude)
    return f"{head}\n{fixed}" if fixed else head


def _sweep_handle(d: str) -> Line2D:
    """A legend entry of a sweep direction, large enough to read."""
    return Line2D([], [], ls="none", marker=SWEEP_MARKERS[d], color=SWEEP_COLORS[d],
                  ms=6, mew=1.5, label=f"sweep {d}")


def plot_bifurcation(ds: xr.Dataset, state: str | int | None = None,
                     path: str | Path | None = None, *, markersize: float = 1.5, overwrite: bool = False,
                     ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """Bifurcation diagram of a :func:`pwsdyn.sweep` result.

    Top: the section points of ``state`` against the parameter, the up sweep as dots and the
    down sweep as crosses in another colour (down drawn over up, so where the sweeps agree
    both show and hysteresis reads at once). Bottom: events per period (maps: border
    crossings per iteration). The title gives the model and the values of the parameters
    held fixed.

    Parameters
    ----------
    ds : xarray.Dataset
        The result of :func:`pwsdyn.sweep` (or the NetCDF file it wrote, opened by xarray).
    state : str or int, optional
        The state plotted (default: the first state for a stroboscopic section, the last --
        the velocity of the zoo's mechanical models -- for an event section).
    path : str or Path, optional
        Also save the figure there (PNG, PDF, SVG by extension; with ``ax``, the figure that
        holds ``ax``).
    markersize : float
        Size of the section points in points (default 1.5).
    overwrite : bool
        Replace an existing file at ``path`` (default: refused, see :func:`plot_trajectory`).
    ax : matplotlib.axes.Axes or pair of Axes, optional
        Draw into your own axes: one Axes receives the diagram only, a pair the diagram and
        the events per period.

    Returns
    -------
    matplotlib.figure.Figure
        The new figure, or with ``ax`` the figure that holds ``ax``.
    """
    pname = _sweep_param(ds)
    if path is not None:
        _check_figure_path(path, overwrite)
    states = [str(s) for s in ds.state.values]
    if state is None:
        state = states[0] if ds.attrs.get("section") == "stroboscopic" else states[-1]
    if isinstance(state, (int, np.integer)):
        if not 0 <= state < len(states):
            raise ArgumentError(f"`state` index {state} out of range for states {states}")
        state = states[state]
    if state not in states:
        raise ArgumentError(f"unknown state {state!r}; states are {states}")
    if ax is None:
        fig = Figure(figsize=(8.0, 6.0), layout="constrained")
        ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    else:
        axes, fig = _user_axes(ax, {1: "the diagram", 2: "the diagram, then the events per "
                                                          "period"})
        ax1, ax2 = (axes + [None])[:2]
    pv = ds[pname].values
    handles = []
    for d in [str(x) for x in ds.direction.values]:
        sec = ds.section.sel(direction=d, state=state).values  # (param, sample)
        X = np.repeat(pv[:, None], sec.shape[1], axis=1)
        ok = np.isfinite(sec)
        marker = SWEEP_MARKERS.get(d, "o")
        # a dot is all face; the smaller cross drawn on it is all stroke, so where the two
        # sweeps agree the dot's rim shows around the cross
        cross = marker == "x"
        ax1.plot(X[ok], sec[ok], marker=marker, ms=markersize * (1.2 if cross else 2.0),
                 mew=0.45 * markersize if cross else 0, ls="none",
                 color=SWEEP_COLORS.get(d, "k"), alpha=0.9, label=f"sweep {d}",
                 rasterized=True)
        handles.append(_sweep_handle(d))
        if ax2 is not None:
            ax2.plot(pv, ds.events_per_period.sel(direction=d).values, drawstyle="steps-mid",
                     color=SWEEP_COLORS.get(d, "k"), lw=1.0, ls="-" if d == "up" else "--",
                     label=f"sweep {d}")
        bad = ds.status.sel(direction=d).values != 0
        if bad.any():
            h, = ax1.plot(pv[bad], np.full(bad.sum(), np.nanmin(sec) if ok.any() else 0.0), "|",
                          color=SWEEP_COLORS.get(d, "k"), ms=6, mew=1.2,
                          label=f"failed / diverged ({d})")
            handles.append(h)
    section = ds.attrs.get("section", "stroboscopic")
    what = "stroboscopic section" if section == "stroboscopic" else f"before each {section}"
    if ds.attrs.get("model_kind") == "map":
        what = "iterates"
    ax1.set_ylabel(f"{_tex(state)} ({what})")
    ax1.set_title(_explore_title(ds, f"bifurcation diagram in {_tex(pname)}", (pname,)),
                  fontsize="medium")
    ax1.legend(handles=handles, loc="best", fontsize=8)
    if ax2 is not None:
        ax2.set_ylabel("iterate crossings" if ds.attrs.get("model_kind") == "map"
                       else "events / period")
        ax2.set_xlabel(_tex(pname))
        ax2.grid(True, lw=0.3)
        if ax is not None:
            ax2.legend(fontsize=8, loc="best")
    if ax2 is None or ax is not None:
        ax1.set_xlabel(_tex(pname))
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def plot_lyapunov(ds: xr.Dataset, path: str | Path | None = None, *, overwrite: bool = False,
                  ax: Axes | None = None) -> Figure:
    """Lyapunov exponents against the parameter (a :func:`pwsdyn.sweep` run with
    ``lyapunov=True``): every exponent (solid: the largest, dashed: the others), the up sweep
    with dots and the down sweep with crosses in another colour, zero marked; the title gives
    the values of the parameters held fixed. ``path`` and ``overwrite`` as for
    :func:`plot_bifurcation`; ``ax``: draw into this Axes of your own figure (and return that
    figure)."""
    pname = _sweep_param(ds)
    if "lyapunov" not in ds:
        raise ArgumentError("the sweep has no Lyapunov exponents: run it with lyapunov=True")
    if path is not None:
        _check_figure_path(path, overwrite)
    if ax is None:
        fig = Figure(figsize=(8.0, 4.4), layout="constrained")
        ax = fig.subplots()
    else:
        (ax,), fig = _user_axes(ax, {1: "the exponents"})
    pv = ds[pname].values
    ax.axhline(0.0, color="0.5", lw=0.8)
    for d in [str(x) for x in ds.direction.values]:
        ly = ds.lyapunov.sel(direction=d).values
        marker = SWEEP_MARKERS.get(d, "o")
        for i in range(ly.shape[1]):
            ax.plot(pv, ly[:, i], color=SWEEP_COLORS.get(d, "k"), lw=1.0, marker=marker,
                    ms=3 if marker == "o" else 4, mew=0 if marker == "o" else 1.0,
                    ls="-" if i == 0 else "--", alpha=0.85,
                    label=f"$\\lambda_{{{i + 1}}}$ ({d})")
    unit = "per iteration" if ds.attrs.get("model_kind") == "map" else "per unit time"
    ax.set_xlabel(_tex(pname))
    ax.set_ylabel(f"Lyapunov exponents ({unit})")
    window = _settings(ds).get("samples")
    what = "Lyapunov spectrum"
    if isinstance(window, int):
        what += f" ({window} {'iterations' if unit == 'per iteration' else 'periods'} per value)"
    ax.set_title(_explore_title(ds, what, (pname,)), fontsize="medium")
    ax.legend(fontsize=8, ncols=2)
    ax.grid(True, lw=0.3)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def _attractor_points(ds, b: int, dims) -> np.ndarray:
    """The stored section points of attractor ``b`` in the grid's coordinates (rows)."""
    if "attractor_points" not in ds:
        return np.zeros((0, len(dims)))
    pts = ds.attractor_points.isel(attractor=b).transpose("cycle_point", "state")
    cols = [pts.sel(state=s).values for s in dims]
    P = np.column_stack(cols) if cols else np.zeros((0, 0))
    return P[np.all(np.isfinite(P), axis=1)]


def _tag_attractors(ax, tags: list) -> None:
    """Number the attractors next to their markers; attractors that lie at one place (within
    3 % of the axes) share one tag, "0, 2"."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    groups: list = []
    for b, x, y in tags:
        u, v = (x - x0) / (x1 - x0), (y - y0) / (y1 - y0)
        for g in groups:
            if abs(g[1] - u) < 0.03 and abs(g[2] - v) < 0.03:
                g[0].append(b)
                break
        else:
            groups.append([[b], u, v])
    for members, u, v in groups:
        ax.annotate(", ".join(map(str, members)), (u, v), xycoords="axes fraction",
                    xytext=(6, 6), textcoords="offset points", fontsize=9, fontweight="bold",
                    color="k", zorder=5,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.85))


def plot_basins(ds: xr.Dataset, path: str | Path | None = None, *, overwrite: bool = False,
                ax: Axes | None = None) -> Figure:
    """Basins of attraction of a :func:`pwsdyn.basins` result: one categorical colour per
    attractor, black for divergence, grey for failed runs; each attractor marked where it
    lies (its section points, ``attractor_points``: a periodic attractor's cycle as circles,
    the non-periodic class's sample as small diamonds, edged in black and filled with its
    basin's colour, numbered); a legend with each attractor's period, events per period and
    basin fraction; the parameter values in the title. ``path`` and ``overwrite`` as for
    :func:`plot_bifurcation`; ``ax``: draw into this Axes of your own figure (and return that
    figure)."""
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.patches import Patch

    if ds.attrs.get("kind") != "basins":
        raise ArgumentError("expected the dataset of pwsdyn.basins (attribute kind = 'basins')")
    if path is not None:
        _check_figure_path(path, overwrite)
    if ax is None:
        fig = Figure(figsize=(7.8, 6.0), layout="constrained")
        ax = fig.subplots()
    else:
        (ax,), fig = _user_axes(ax, {1: "the basins"})
    lab = ds.label
    dims = lab.dims
    K = ds.sizes["attractor"]
    ids = [-2, -1] + list(range(K))
    colors = [BASIN_SPECIAL_COLORS[-2], BASIN_SPECIAL_COLORS[-1]] + [
        BASIN_COLORS[k % len(BASIN_COLORS)] for k in range(K)]
    cmap = ListedColormap(colors)
    norm = BoundaryNorm(np.arange(-2.5, K, 1.0), cmap.N)
    frac = dict(zip(ds.basin.values.tolist(), ds.fraction.values.tolist()))
    if len(dims) == 2:
        x, y = ds[dims[0]].values, ds[dims[1]].values
        ax.pcolormesh(x, y, lab.values.T, cmap=cmap, norm=norm, shading="nearest",
                      rasterized=True)
        ax.set_xlabel(_tex(dims[0]))
        ax.set_ylabel(_tex(dims[1]))
    else:
        x = ds[dims[0]].values
        ax.pcolormesh(x, [0, 1], np.vstack([lab.values, lab.values]), cmap=cmap, norm=norm,
                      shading="nearest", rasterized=True)
        ax.set_yticks([])
        ax.set_xlabel(_tex(dims[0]))
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    states = [str(s) for s in ds.state.values] if "state" in ds.coords else []
    handles = []
    tags: list = []   # (attractor, x, y) of a point of each attractor inside the grid
    is_map = ds.attrs.get("model_kind") == "map"
    for b, c in zip(ids, colors):
        f = frac.get(b, 0.0)
        marker = None
        if b >= 0:
            k = int(ds.attractor_period.values[b])
            ev = float(ds.attractor_events_per_period.values[b])
            per = "crossing{}/iteration" if is_map else "event{}/period"
            text = (f"{b}: non-periodic" if k == 0 else f"{b}: period {k}") + \
                f", {ev:.3g} " + per.format("" if ev == 1 else "s")
            if float(ds.attractor_stick_time.values[b]) > 0:
                text += ", sticks"
            P = (_attractor_points(ds, b, list(dims)) if all(s in states for s in dims)
                 else np.zeros((0, len(dims))))
            if len(P):
                px = P[:, 0]
                py = P[:, 1] if len(dims) == 2 else np.full(len(P), 0.5)
                inside = ((px >= min(xlim)) & (px <= max(xlim)) & (py >= min(ylim))
                          & (py <= max(ylim)))
                style = dict(marker="o", ms=8) if k else dict(marker="D", ms=4.5)
                marker, = ax.plot(px, py, ls="none", mfc=c, mec="k", mew=1.3, zorder=4,
                                  label=f"attractor {b}", **style)
                if inside.any():
                    tags.append((b, px[inside][0], py[inside][0]))
                else:
                    text += ", outside the grid"
        elif f == 0:
            continue
        else:
            text = "diverged" if b == -1 else "failed (budget)"
        patch = Patch(color=c)
        handles.append(((patch, marker) if marker is not None else patch,
                        f"{text} ({100 * f:.1f}%)"))
    ax.set_xlim(xlim)
    ax.set_ylim(ylim)
    _tag_attractors(ax, tags)
    ax.legend([h for h, _ in handles], [t for _, t in handles],
              handler_map={tuple: HandlerTuple(ndivide=1)}, loc="upper left",
              bbox_to_anchor=(1.01, 1.0), fontsize=8,
              title="attractor (markers: its section points)", title_fontsize=8)
    ax.set_title(_explore_title(ds, "basins of attraction"), fontsize="medium")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


# ======================================================================================
# continuation: branches (pwsdyn.continuation)
# ======================================================================================

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
# ======================================================================================
#: Metrics drawn by :func:`plot_metrics` by default (variables of
#: :func:`pwsdyn.explore.metrics.metrics_sweep`).
DEFAULT_METRICS = ("rms_acceleration", "travel_range", "impact_velocity_max")
#: Colours of the variants of :func:`plot_metrics`, in order (Okabe-Ito).
VARIANT_COLORS = ("#000000", "#D55E00", "#0072B2", "#009E73", "#CC79A7", "#E69F00")


def plot_metrics(ds: xr.Dataset, metrics: Sequence[str] | None = None,
                 path: str | Path | None = None, *, overwrite: bool = False,
                 ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """Response metrics against the swept parameter, one panel per metric, one colour per
    variant, the up sweep solid with dots and the down sweep dashed with crosses (so that
    hysteresis reads as two curves of one colour).

    Parameters
    ----------
    ds : xarray.Dataset
        The result of :func:`pwsdyn.explore.metrics.metrics_sweep`.
    metrics : sequence of str, optional
        Its variables drawn (default :data:`DEFAULT_METRICS`).
    path : str or Path, optional
        Also save the figure there (see :func:`plot_trajectory`).
    overwrite : bool
        Replace an existing file at ``path``.
    ax : matplotlib.axes.Axes or sequence of Axes, optional
        Draw into your own axes, one per metric.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if ds.attrs.get("kind") != "metrics" or "variant" not in ds.dims:
        raise ArgumentError("`ds` must be a result of pwsdyn.explore.metrics.metrics_sweep()")
    metrics = list(DEFAULT_METRICS if metrics is None else metrics)
    if isinstance(metrics, str) or not metrics:
        raise ArgumentError("`metrics` must be a non-empty sequence of variable names")
    known = [k for k in ds.data_vars if k != "status"]
    for k in metrics:
        if k not in known:
            raise ArgumentError(f"unknown metric {k!r}; the dataset has {known}")
    if path is not None:
        _check_figure_path(path, overwrite)
    if ax is None:
        fig = Figure(figsize=(7.0, 2.2 * len(metrics) + 0.6), layout="constrained")
        axes = list(np.atleast_1d(fig.subplots(len(metrics), 1, sharex=True)))
    else:
        axes, fig = _user_axes(ax, {len(metrics): "one per metric"})
    pname = ds.attrs["parameter"]
    pv = ds[pname].values
    variants = [str(v) for v in ds.variant.values]
    for a, k in zip(axes, metrics):
        for vi, v in enumerate(variants):
            color = VARIANT_COLORS[vi % len(VARIANT_COLORS)]
            for d in [str(x) for x in ds.direction.values]:
                y = ds[k].sel(variant=v, direction=d).values
                a.plot(pv, y, color=color, ls="-" if d == "up" else "--",
                       marker="o" if d == "up" else "x", ms=3, lw=1.0,
                       label=f"{v} ({d})" if len(ds.direction) > 1 else v)
        unit = ds[k].attrs.get("units")
        label = k.replace("_", " ")
        a.set_ylabel(f"{label} ({unit})" if unit and unit != "1" else label, fontsize=8)
        a.grid(True, lw=0.3)
    axes[0].legend(fontsize=7, loc="best")
    axes[-1].set_xlabel(_tex(pname))
    axes[0].set_title(f"response metrics of {ds.attrs.get('model', '')} in "
                      f"{_tex(pname)}", fontsize="medium")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig
