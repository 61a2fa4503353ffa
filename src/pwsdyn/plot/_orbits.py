"""Periodic orbits: one period with its events, and its Floquet multipliers."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import ArgumentError
from ._common import _check_figure_path, _number, _save_figure
from ._trajectories import (SURFACE_COLOR, _draw_trajectory, _finish, _panels, _prepare,
                            _title, _trajectory_figure, _trajectory_slots)

if TYPE_CHECKING:
    from ..orbits import PeriodicOrbit

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


