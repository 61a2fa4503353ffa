"""Global analysis over a parameter or a grid (pwsdyn.explore): bifurcation diagrams of
sweeps, Lyapunov exponents, basins of attraction, response metrics."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..errors import ArgumentError
from ._common import (_check_figure_path, _label_beside, _one_axes, _save_figure, _tex,
                      _user_axes, _values_text)

if TYPE_CHECKING:
    import xarray as xr

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
                     path: str | Path | None = None, *, markersize: float = 1.5,
                     overwrite: bool = False,
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
        # its lines are steps, not the markers of the diagram: a legend of their own
        ax2.legend(fontsize=7 if ax is None else 8, loc="best")
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
    ax, fig = _one_axes(ax, (8.0, 4.4), "the exponents")
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
        # clear of the largest attractor marker, and of it by the white box's pad too
        _label_beside(ax, ", ".join(map(str, members)), (u, v), marker="o", size=8.0,
                      edge=1.3, gap=2.0 + 0.15 * 9, xycoords="axes fraction", fontsize=9,
                      fontweight="bold", color="k", zorder=5,
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
    ax, fig = _one_axes(ax, (7.8, 6.0), "the basins")
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
                                  gid=f"attractor {b}", **style)
                if inside.any():
                    tags.append((b, px[inside][0], py[inside][0]))
                else:
                    text += ", outside the grid"
        elif f == 0:
            continue
        else:
            text = "diverged" if b == -1 else "failed (budget)"
        patch = Patch(color=c)
        text = f"{text} ({100 * f:.1f}%)"
        if marker is not None:
            marker.set_label(text)      # the markers are named by their legend entry
        handles.append(((patch, marker) if marker is not None else patch, text))
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
# ======================================================================================
#: Metrics drawn by :func:`plot_metrics` by default (variables of
#: :func:`pwsdyn.explore.metrics_sweep`).
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
        The result of :func:`pwsdyn.explore.metrics_sweep`.
    metrics : sequence of str, optional
        Its variables drawn (default ``DEFAULT_METRICS``).
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
