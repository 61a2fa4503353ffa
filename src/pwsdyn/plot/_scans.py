"""Period maps of two-parameter scans (pwsdyn.scan), with continued bifurcation curves drawn
on top by :meth:`pwsdyn.Branch.plot` into the same axes (first parameter across, second up,
as a two-parameter curve is drawn)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import ArgumentError
from ._common import _check_figure_path, _one_axes, _save_figure, _tex
from ._sweeps import _explore_title

if TYPE_CHECKING:
    import xarray as xr

#: Colours of periods 1, 2, 3 ... of a period map (Okabe-Ito, then more qualitative ones).
PERIOD_COLORS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
                 "#8C564B", "#9467BD", "#BCBD22", "#17BECF", "#FF9896")
#: Colours of the classes that are not a period: a longer period than those drawn, no period
#: found (non-periodic: chaos or a transient longer than the run), no section point in the
#: window (e.g. no impact at an impact section), divergence, a failed run.
SCAN_SPECIAL_COLORS = {"longer": "#4D4D4D", "nonperiodic": "#D9D9D9", "none": "#FFFFFF",
                       "diverged": "#000000", "failed": "#E41A1C"}

# class codes of the map: 1..k periods, then these
_LONGER, _NONPERIODIC, _NONE, _DIVERGED, _FAILED = -1, 0, -2, -3, -4
_DIVERGED_STATUS = -1          # pwsdyn.Status.DIVERGED


def scan_classes(ds: xr.Dataset, max_period: int = 8) -> np.ndarray:
    """The class of every point of a :func:`pwsdyn.scan` result (an array of the shape of
    its ``period``):
    ``1 .. max_period`` the period, -1 a longer period, 0 no period found, -2 no section
    point, -3 diverged, -4 another failure (the status of a failed run)."""
    per = ds.period.values
    st = ds.status.values
    npts = ds.n_points.values
    c = np.where(per > max_period, _LONGER, per)
    c = np.where((per == 0) & (npts == 0), _NONE, c)
    c = np.where(st == _DIVERGED_STATUS, _DIVERGED, c)
    c = np.where((st != 0) & (st != _DIVERGED_STATUS), _FAILED, c)
    return c.astype(int)


def plot_scan(ds: xr.Dataset, path: str | Path | None = None, *, ax: Axes | None = None,
              direction: str | None = None, transpose: bool = False, max_period: int = 8,
              legend: bool = True, overwrite: bool = False) -> Figure:
    """Period map of a :func:`pwsdyn.scan` result: one discrete colour per period 1 ..
    ``max_period``, dark grey for longer periods, light grey where no period was found
    (chaos, or not settled within the transient), white where the window had no section
    point (an event section that was not crossed), black for divergence and red for a
    failed run; a legend with the share of the grid of each class present. The first parameter runs
    across, the second up (``transpose=True``: the other way round): a two-parameter curve
    of :func:`pwsdyn.continue_bifurcation` continued in the two parameters in the order of
    the axes goes on top with ``branch.plot(ax=fig.axes[0])`` (its first parameter across).

    Parameters
    ----------
    ds : xarray.Dataset
        The result of :func:`pwsdyn.scan` (or the NetCDF file it wrote, opened by xarray).
    path : str or Path, optional
        Also save the figure there (PNG, PDF, SVG by extension).
    ax : matplotlib.axes.Axes, optional
        Draw into this Axes of your own figure (and return that figure).
    direction : {'up', 'down'}, optional
        The map of the rows swept up or down in the first parameter (default: up where the
        scan has it). They differ where attractors coexist.
    transpose : bool
        Draw the second parameter across and the first up (a scan whose rows cross a curve
        transversally, drawn in the plane of the curve).
    max_period : int
        Periods drawn each in its own colour (default 8; at most 12).
    legend : bool
        Draw the legend (outside the axes, on the right).
    overwrite : bool
        Replace an existing file at ``path`` (default: refused).

    Returns
    -------
    matplotlib.figure.Figure
        The new figure, or with ``ax`` the figure that holds ``ax``.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    if ds.attrs.get("kind") != "scan":
        raise ArgumentError("expected the dataset of pwsdyn.scan (attribute kind = 'scan')")
    if (isinstance(max_period, bool) or not isinstance(max_period, (int, np.integer))
            or not 1 <= max_period <= len(PERIOD_COLORS)):
        raise ArgumentError(f"`max_period` must be an integer from 1 to {len(PERIOD_COLORS)}, "
                            f"got {max_period!r}")
    if path is not None:
        _check_figure_path(path, overwrite)
    p1, p2 = ds.attrs["parameter"], ds.attrs["parameter2"]
    swept = p1
    dirs = [str(d) for d in ds.direction.values]
    if direction is None:
        direction = "up" if "up" in dirs else dirs[0]
    if direction not in dirs:
        raise ArgumentError(f"`direction` must be one of the scan's directions {dirs}, got "
                            f"{direction!r}")
    ds = ds.sel(direction=direction)
    ax, fig = _one_axes(ax, (7.8, 5.6), "the period map")
    cls = scan_classes(ds, max_period)
    codes = [_FAILED, _DIVERGED, _NONE, _LONGER, _NONPERIODIC] + list(range(1, max_period + 1))
    colors = [SCAN_SPECIAL_COLORS[k] for k in ("failed", "diverged", "none", "longer",
                                               "nonperiodic")] + list(PERIOD_COLORS[:max_period])
    # codes -4 .. max_period in increasing order, one colour each
    order = np.argsort(codes)
    cmap = ListedColormap([colors[i] for i in order])
    norm = BoundaryNorm(np.arange(min(codes) - 0.5, max_period + 1), cmap.N)
    cls = cls.T                                   # rows of the image: p2
    if transpose:
        p1, p2, cls = p2, p1, cls.T
    x, y = ds[p1].values, ds[p2].values
    ax.pcolormesh(x, y, cls, cmap=cmap, norm=norm, shading="nearest", rasterized=True,
                  zorder=0)
    ax.set_xlabel(_tex(p1))
    ax.set_ylabel(_tex(p2))
    if legend:
        section = ds.attrs.get("section", "stroboscopic")
        unit = ("forcing periods" if section == "stroboscopic" else f"{section} events")
        if ds.attrs.get("model_kind") == "map":
            unit = "iterations"
        texts = {_FAILED: "run failed", _DIVERGED: "diverged",
                 _NONE: "no section point" if section == "stroboscopic" else f"no {section}",
                 _LONGER: f"period > {max_period}", _NONPERIODIC: "no period found (chaos)"}
        total = cls.size
        handles = []
        for code, c in zip(codes, colors):
            count = int(np.sum(cls == code))
            if count == 0:
                continue
            text = texts.get(code, f"period {code}")
            handles.append(Patch(facecolor=c, edgecolor="0.5", lw=0.5,
                                 label=f"{text} ({100 * count / total:.1f}%)"))
        handles.sort(key=lambda h: _legend_rank(h.get_label()))
        leg = ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                        fontsize=8, title=f"attractor (periods in {unit})", title_fontsize=8)
        # kept as an artist of its own: curves drawn on top later (Branch.plot) make the
        # axes' legend of their own, which would otherwise replace this one
        ax.legend_ = None
        ax.add_artist(leg)
        leg.set_clip_on(False)      # add_artist clips to the axes; the legend is outside
    what = f"period map, rows swept {direction} in {_tex(swept)}"
    ax.set_title(_explore_title(ds, what, exclude=(p1, p2)), fontsize="medium")
    if path is not None:
        _save_figure(fig, path, overwrite)
    return fig


def _legend_rank(label: str) -> tuple:
    """Periods first, in order, then the other classes."""
    if label.startswith("period ") and label.split()[1].isdigit():
        return (0, int(label.split()[1]))
    return (1, label)
