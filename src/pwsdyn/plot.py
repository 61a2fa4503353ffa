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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .errors import ArgumentError

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
    t = np.asarray(traj.t)
    spans = []
    cur = None
    for i in range(len(t) - 1):
        if not t[i + 1] > t[i]:
            continue  # a jump: zero length, the discrete state changes across it
        st = traj.state[i]
        kind = st.split(":", 1)[0] if ":" in st else None
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
    if traj._dense is None:
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
    params = ", ".join(f"${_latex_name(k)} = {v:.4g}$" for k, v in traj.params.items())
    title = f"{model.name}"
    if params:
        title += f"   ({params})"
    if traj.status.failed:
        title += f"\nstopped early: {traj.status.name} at $t = {traj.t_final:.10g}$"
    if traj._dense is None:
        title += "\n(no dense output: straight lines between stored nodes)"
    return title


# ======================================================================================
# the figure
# ======================================================================================

def plot_trajectory(traj, path=None, states=None, phase=None, *, num: int = 4000,
                    title: str | None = None, overwrite: bool = False) -> Figure:
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
        before the figure is drawn (directory, format, existing file).
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

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import pwsdyn
    >>> from pwsdyn.plot import plot_trajectory
    >>> traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 5))
    >>> fig = plot_trajectory(traj)
    """
    for attr in ("t", "x", "events", "model", "sample"):
        if not hasattr(traj, attr):
            raise ArgumentError(f"`traj` must be a Trajectory, got {type(traj).__name__}")
    if path is not None:
        _check_figure_path(path, overwrite)
    model = traj.model
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
    if not (isinstance(num, (int, np.integer)) and num >= 2):
        raise ArgumentError(f"`num` must be an integer >= 2, got {num!r}")

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

    nrows = len(shown)
    fig = Figure(figsize=(11.0, max(4.2, 1.9 * nrows + 1.6)), layout="constrained")
    if phase_ij is not None:
        gs = fig.add_gridspec(nrows, 2, width_ratios=[1.45, 1.0])
    else:
        gs = fig.add_gridspec(nrows, 1)
    handles: dict = {}
    label_of = {k: f"${_latex_name(names[k])}$" for k in range(n)}

    # --- time series ---------------------------------------------------------------------
    ts_axes = []
    for row, k in enumerate(shown):
        ax = fig.add_subplot(gs[row, 0], sharex=ts_axes[0] if ts_axes else None)
        ts_axes.append(ax)
        for kind, ss, xs in spans:
            style = CONSTRAINED_STYLES[kind]
            h, = ax.plot(ss, xs[:, k], color=style["color"], lw=6, alpha=0.35,
                         solid_capstyle="butt", zorder=1)
            handles.setdefault(f"{kind}", (h, style["label"]))
        for c in curves:
            if c.state != k:
                continue
            tt = np.linspace(T[0], T[-1], num_eff)
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
        _mark_events(ax, events, lambda e: (e.t, e.x_before[k]), msize, handles)
        ax.set_ylabel(label_of[k])
        ax.grid(True, alpha=0.3, lw=0.6)
        ax.margins(x=0.01)
        if row < nrows - 1:
            ax.tick_params(labelbottom=False)
    ts_axes[-1].set_xlabel("$t$")

    # --- phase plane -----------------------------------------------------------------------
    if phase_ij is not None:
        i, j = phase_ij
        ax = fig.add_subplot(gs[:, 1])
        for kind, ss, xs in spans:
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
        _mark_events(ax, events, lambda e: (e.x_before[i], e.x_before[j]), msize, handles)
        h = ax.scatter([X[0, i]], [X[0, j]], s=40, facecolors="white", edgecolors="k",
                       linewidths=1.2, zorder=5)
        handles.setdefault("start", (h, "initial state"))
        ax.set_xlabel(label_of[i])
        ax.set_ylabel(label_of[j])
        ax.grid(True, alpha=0.3, lw=0.6)
        ax.set_title("phase plane", fontsize="medium")
        _draw_contours(ax, contours, phase_ij, handles)

    fig.suptitle(title if title is not None else _title(traj), fontsize="large")
    order = (["trajectory", "jump", "start"] + [f"surface:{s.name}" for s in model.surfaces]
             + list(CONSTRAINED_STYLES) + [f"event:{k}" for k in EVENT_STYLES])
    items = [handles[key] for key in order if key in handles]
    if items:
        fig.legend([h for h, _ in items], [lab for _, lab in items], loc="outside lower center",
                   ncol=min(len(items), 4), frameon=False, fontsize="small")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def plot_orbit(orbit, path=None, states=None, phase=None, *, num: int = 4000,
               overwrite: bool = False) -> Figure:
    """A figure of a periodic orbit: one period with its events, and its Floquet multipliers.

    The panels of :func:`plot_trajectory` for ``orbit.trajectory`` (time series, phase plane,
    events marked by kind, event surfaces), the period and stability in the title, and an inset
    in the phase plane (or the first time series) with the multipliers and the unit circle.

    Parameters
    ----------
    orbit : PeriodicOrbit
        A result of :func:`pwsdyn.find_periodic_orbit`.
    path : str or pathlib.Path, optional
        Also save the figure there.
    states, phase, num, overwrite
        As for :func:`plot_trajectory`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    for attr in ("trajectory", "multipliers", "period", "events"):
        if not hasattr(orbit, attr):
            raise ArgumentError(f"`orbit` must be a PeriodicOrbit, got {type(orbit).__name__}")
    if orbit.trajectory is None:
        raise ArgumentError("the orbit has no trajectory to plot")
    if path is not None:
        _check_figure_path(path, overwrite)
    mult = np.atleast_1d(np.asarray(orbit.multipliers if orbit.multipliers is not None else [],
                                    dtype=complex))
    stab = "stable" if orbit.stable else "unstable"
    head = _title(orbit.trajectory).split("\n")[0]
    title = (f"{head}\nperiodic orbit: $T = {orbit.period:.10g}$, {len(orbit.events)} events "
             f"per period, {stab}"
             + ("" if orbit.converged else " (NOT converged)"))
    fig = plot_trajectory(orbit.trajectory, states=states, phase=phase, num=num, title=title)
    axes = [ax for ax in fig.axes if ax.get_title() == "phase plane"] or fig.axes[:1]
    ins = axes[0].inset_axes(_emptiest_corner(axes[0], 0.28))
    th = np.linspace(0.0, 2.0 * np.pi, 200)
    ins.plot(np.cos(th), np.sin(th), color=SURFACE_COLOR, lw=0.8)
    ins.scatter(mult.real, mult.imag, s=18, marker="x", color="#D55E00", zorder=3)
    lim = max(1.15, 1.1 * float(np.max(np.abs(mult)))) if mult.size else 1.15
    ins.set_xlim(-lim, lim)
    ins.set_ylim(-lim, lim)
    ins.set_aspect("equal")
    ins.axhline(0.0, color="0.8", lw=0.5, zorder=0)
    ins.axvline(0.0, color="0.8", lw=0.5, zorder=0)
    ins.tick_params(labelsize="x-small")
    ins.set_title("Floquet multipliers", fontsize="x-small")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def _emptiest_corner(ax, size: float) -> list:
    """Axes-fraction bounds of the corner square of ``ax`` holding the fewest data points."""
    pts = [np.asarray(line.get_xydata(), dtype=float) for line in ax.get_lines()]
    pts = np.concatenate(pts) if pts else np.zeros((0, 2))
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    u = (pts[:, 0] - x0) / (x1 - x0) if len(pts) else np.zeros(0)
    v = (pts[:, 1] - y0) / (y1 - y0) if len(pts) else np.zeros(0)
    m = 0.02
    corners = [[1 - size - m, 1 - size - m], [m, 1 - size - m], [1 - size - m, m], [m, m]]
    counts = [np.count_nonzero((u >= a) & (u <= a + size) & (v >= b) & (v <= b + size))
              for a, b in corners]
    a, b = corners[int(np.argmin(counts))]
    return [a, b, size, size]


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
    from .io import _check_output_path

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


def plot_bifurcation(ds, state=None, path=None, *, markersize: float = 1.0,
                     overwrite: bool = False) -> Figure:
    """Bifurcation diagram of a :func:`pwsdyn.sweep` result.

    Top: the section points of ``state`` against the parameter, the up and down sweeps in
    two colours (down drawn over up with smaller markers, so hysteresis shows both). Bottom:
    events per period (maps: border crossings per iteration).

    Parameters
    ----------
    ds : xarray.Dataset
        The result of :func:`pwsdyn.sweep` (or the NetCDF file it wrote, opened by xarray).
    state : str or int, optional
        The state plotted (default: the first state for a stroboscopic section, the last --
        the velocity of the zoo's mechanical models -- for an event section).
    path : str or Path, optional
        Also save the figure there (PNG, PDF, SVG by extension).
    overwrite : bool
        Replace an existing file at ``path`` (default: refused, see :func:`plot_trajectory`).

    Returns
    -------
    matplotlib.figure.Figure
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
    fig = Figure(figsize=(8.0, 6.0), layout="constrained")
    ax, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    pv = ds[pname].values
    for d in [str(x) for x in ds.direction.values]:
        sec = ds.section.sel(direction=d, state=state).values  # (param, sample)
        X = np.repeat(pv[:, None], sec.shape[1], axis=1)
        ok = np.isfinite(sec)
        ms = markersize if d == "up" else markersize * 0.6
        ax.plot(X[ok], sec[ok], marker="o", ms=ms, mew=0, ls="none", color=SWEEP_COLORS[d],
                alpha=0.7, label=f"sweep {d}", rasterized=True)
        ax2.plot(pv, ds.events_per_period.sel(direction=d).values, drawstyle="steps-mid",
                 color=SWEEP_COLORS[d], lw=1.0, label=f"sweep {d}")
        bad = ds.status.sel(direction=d).values != 0
        if bad.any():
            ax.plot(pv[bad], np.full(bad.sum(), np.nanmin(sec) if ok.any() else 0.0), "x",
                    color=SWEEP_COLORS[d], ms=4, label=f"failed / diverged ({d})")
    section = ds.attrs.get("section", "stroboscopic")
    what = "stroboscopic section" if section == "stroboscopic" else f"before each {section}"
    if ds.attrs.get("model_kind") == "map":
        what = "iterates"
    ax.set_ylabel(f"{_tex(state)} ({what})")
    ax2.set_ylabel("iterate crossings" if ds.attrs.get("model_kind") == "map"
                   else "events / period")
    ax2.set_xlabel(_tex(pname))
    ax.set_title(f"{ds.attrs.get('model', '')}: bifurcation diagram in {pname}")
    ax.legend(loc="best", fontsize=8, markerscale=6)
    ax2.grid(True, lw=0.3)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def plot_lyapunov(ds, path=None, *, overwrite: bool = False) -> Figure:
    """Lyapunov exponents against the parameter (a :func:`pwsdyn.sweep` run with
    ``lyapunov=True``): every exponent, up and down sweeps in two colours, zero marked.
    ``path`` and ``overwrite`` as for :func:`plot_bifurcation`."""
    pname = _sweep_param(ds)
    if "lyapunov" not in ds:
        raise ArgumentError("the sweep has no Lyapunov exponents: run it with lyapunov=True")
    if path is not None:
        _check_figure_path(path, overwrite)
    fig = Figure(figsize=(8.0, 4.0), layout="constrained")
    ax = fig.subplots()
    pv = ds[pname].values
    ax.axhline(0.0, color="0.5", lw=0.8)
    for d in [str(x) for x in ds.direction.values]:
        ly = ds.lyapunov.sel(direction=d).values
        for i in range(ly.shape[1]):
            ax.plot(pv, ly[:, i], color=SWEEP_COLORS[d], lw=1.0, marker=".", ms=3,
                    ls="-" if i == 0 else "--",
                    label=f"$\\lambda_{{{i + 1}}}$ ({d})")
    unit = "per iteration" if ds.attrs.get("model_kind") == "map" else "per unit time"
    ax.set_xlabel(_tex(pname))
    ax.set_ylabel(f"Lyapunov exponents ({unit})")
    ax.set_title(f"{ds.attrs.get('model', '')}: Lyapunov spectrum")
    ax.legend(fontsize=8, ncols=2)
    ax.grid(True, lw=0.3)
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def plot_basins(ds, path=None, *, overwrite: bool = False) -> Figure:
    """Basins of attraction of a :func:`pwsdyn.basins` result: one categorical colour per
    attractor, black for divergence, grey for failed runs, and a legend with each attractor's
    period, events per period and basin fraction. ``path`` and ``overwrite`` as for
    :func:`plot_bifurcation`."""
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    if ds.attrs.get("kind") != "basins":
        raise ArgumentError("expected the dataset of pwsdyn.basins (attribute kind = 'basins')")
    if path is not None:
        _check_figure_path(path, overwrite)
    lab = ds.label
    dims = lab.dims
    K = ds.sizes["attractor"]
    ids = [-2, -1] + list(range(K))
    colors = [BASIN_SPECIAL_COLORS[-2], BASIN_SPECIAL_COLORS[-1]] + [
        BASIN_COLORS[k % len(BASIN_COLORS)] for k in range(K)]
    cmap = ListedColormap(colors)
    norm = BoundaryNorm(np.arange(-2.5, K, 1.0), cmap.N)
    fig = Figure(figsize=(7.5, 6.0), layout="constrained")
    ax = fig.subplots()
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
    handles = []
    for b, c in zip(ids, colors):
        f = frac.get(b, 0.0)
        if b >= 0:
            k = int(ds.attractor_period.values[b])
            ev = float(ds.attractor_events_per_period.values[b])
            text = (f"{b}: non-periodic" if k == 0 else f"{b}: period {k}") + \
                f", {ev:.3g} events/period"
            if float(ds.attractor_stick_time.values[b]) > 0:
                text += ", sticks"
        elif f == 0:
            continue
        else:
            text = "diverged" if b == -1 else "failed (budget)"
        handles.append(Patch(color=c, label=f"{text} ({100 * f:.1f}%)"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              title="attractor")
    ax.set_title(f"{ds.attrs.get('model', '')}: basins of attraction")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig
