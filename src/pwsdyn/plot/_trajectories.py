"""Trajectories: time series, phase plane, events and event surfaces."""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..errors import ArgumentError
from ._common import (_check_figure_path, _latex_expr, _latex_name, _root_figure, _save_figure,
                      _user_axes, _values_text)

if TYPE_CHECKING:
    from ..integrate.trajectory import Trajectory

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
    "slide_multi": dict(color="#882255", label="sliding on an intersection"),
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
                    label = (f"{surf.name} surface: ${_latex_name(str(s))} = "
                             f"{_latex_expr(position)}$")
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
                    f"{surf.name} surface: ${_latex_expr(expr)} = 0$"))
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
    from ..integrate.trajectory import DiscreteState

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

def _title(traj) -> str:
    model = traj.model
    lines = _values_text(dict(traj.params), width=90)
    # short enough for one line as printed: a mathtext command (\omega) is one letter
    shown = re.sub(r"\\[A-Za-z]+", "x", lines[0]).translate({ord(c): None for c in "${}"}) \
        if lines else ""
    if len(lines) == 1 and len(shown) < 60:
        title = f"{model.name}   ({lines[0]})"
    else:
        title = "\n".join([f"{model.name}"] + lines)
    if traj.status.failed:
        title += f"\nstopped early: {traj.status.name} at $t = {traj.t_final:.10g}$"
    if traj.dense is None:
        title += "\n(no dense output: straight lines between stored nodes)"
    return title


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


