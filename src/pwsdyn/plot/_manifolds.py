"""Global analysis: a crisis located from the geometry, drawn with the attractor, the boundary
saddle's stable manifold and the point where they touch."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from ..errors import ArgumentError
from ._common import _check_figure_path, _legend, _number, _one_axes, _save_figure, _tex

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from ..manifolds import Crisis

#: Colours of the figure's parts (colour-blind safe, as the other families').
CRISIS_COLORS = {"attractor": "0.15", "stable": "#0072B2", "unstable": "#D55E00",
                 "contact": "#009E73"}


def plot_crisis(crisis: Crisis, path: str | Path | None = None, *, attractor=None,
                overwrite: bool = False, ax: Axes | None = None) -> Figure:
    """A crisis of :func:`pwsdyn.locate_crisis` or :func:`pwsdyn.locate_tangency` at its
    located value: the attractor's points ``attractor`` (an ``(m, n)`` array, for example
    ``pwsdyn.model.iterate`` at ``crisis.value``; optional), the stable manifold of the
    boundary saddle and the unstable manifold that touches it (planar maps), the saddles and
    the contact point; a one-state map is drawn along its axis. ``path`` and ``overwrite`` as
    for :func:`plot_bifurcation`; ``ax``: draw into this Axes of your own figure (and return
    that figure)."""
    if not hasattr(crisis, "saddle") or not hasattr(crisis, "value"):
        raise ArgumentError("plot_crisis(): expected a pwsdyn.Crisis")
    if path is not None:
        _check_figure_path(path, overwrite)
    ax, fig = _one_axes(ax, (7.0, 5.4), "the crisis")
    names = list(crisis.model.states)
    planar = len(names) >= 2

    def xy(P):
        P = np.atleast_2d(np.asarray(P, dtype=float))
        return (P[:, 0], P[:, 1]) if planar else (P[:, 0], np.zeros(len(P)))

    if attractor is not None:
        A = np.atleast_2d(np.asarray(attractor, dtype=float))
        A = A[np.all(np.isfinite(A), axis=1)]
        ax.plot(*xy(A), ".", ms=1.5 if planar else 6, color=CRISIS_COLORS["attractor"],
                label="attractor", rasterized=True, zorder=1)
    for m in crisis.manifolds:
        style = {"color": CRISIS_COLORS[m.kind], "lw": 1.2 if m.kind == "stable" else 0.7}
        label = ("stable manifold of the boundary saddle" if m.kind == "stable"
                 else "unstable manifold (the attractor's edge)")
        m.plot(ax=ax, saddle=False, label=label, zorder=2, **style)
    ax.plot(*xy(crisis.saddle.cycle), "s", ms=7, mfc="none", mec=CRISIS_COLORS["stable"],
            mew=1.5, label=f"saddle (period {crisis.saddle.period})", zorder=3)
    if crisis.unstable is not None and crisis.unstable is not crisis.saddle:
        ax.plot(*xy(crisis.unstable.cycle), "D", ms=6, mfc="none",
                mec=CRISIS_COLORS["unstable"], mew=1.5,
                label=f"attractor's saddle (period {crisis.unstable.period})", zorder=3)
    ax.plot(*xy(crisis.point), "o", ms=9, mfc="none", mec=CRISIS_COLORS["contact"], mew=2.0,
            label="contact", zorder=4)
    if planar:
        # the manifolds reach far beyond the attractor: the view is the attractor, the
        # saddles and the contact, with a margin
        view = [np.atleast_2d(crisis.point), crisis.saddle.cycle]
        if crisis.unstable is not None:
            view.append(crisis.unstable.cycle)
        if attractor is not None and len(A):
            view.append(A)
        V_ = np.vstack([v[:, :2] for v in view])
        lo, hi = V_.min(axis=0), V_.max(axis=0)
        pad = 0.15 * np.maximum(hi - lo, 1e-9 * (1 + np.abs(hi)))
        ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
        ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    ax.set_xlabel(_tex(names[0]))
    if planar:
        ax.set_ylabel(_tex(names[1]))
    else:
        ax.set_yticks([])
    ax.set_title(f"{crisis.model.name}: {crisis.kind} at {_tex(crisis.param)} = "
                 f"{_number(crisis.value)}", fontsize="medium")
    _legend(ax, loc="best", fontsize="small")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig
