"""Figures that read right: names typeset as Greek letters however a model spells them,
special points labelled clear of their markers and by where a switched branch came from,
line styles that change exactly at the located special point, one legend entry per meaning
with every branch named -- and every figure of the gallery checked the same way.

Two checks serve every figure here and in the gallery:

* :func:`legend_problems`: every line with a label is named in a legend (its own axes', the
  figure's, or another axes' entry drawn exactly like it), no legend names a thing twice, and
  every line drawn with a line style in an axes that has a legend shares its colour with an
  entry of it (a branch drawn but left out of the legend shows so);
* :func:`overlaps`: no text of an axes covers a marker of that axes, measured in display
  space after ``fig.canvas.draw()`` (markers of point clouds drawn rasterized -- a sweep's
  thousands of section points, a background -- are left out).

Every figure is drawn on the Agg canvas; files go to pytest's ``tmp_path`` only.
"""

from __future__ import annotations

import os
import runpy
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.markers import MarkerStyle  # noqa: E402
from matplotlib.transforms import Bbox  # noqa: E402

import pwsdyn  # noqa: E402
import pwsdyn.plot as plot  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


# ======================================================================================
# the checks
# ======================================================================================

def _no_marker(m) -> bool:
    return m is None or (isinstance(m, str) and m in ("None", "none", "", " "))


def _entries(legend) -> list:
    """``(text, handle)`` of each entry of a legend."""
    return [(t.get_text(), h) for t, h in zip(legend.get_texts(), legend.legend_handles)]


def _look(artist):
    """What a line looks like: colour, line style, marker (``None`` where not a line)."""
    if not hasattr(artist, "get_linestyle") or not hasattr(artist, "get_marker"):
        return None
    ls = artist.get_linestyle()
    ls = "None" if ls in ("None", "none", "", " ") else ls
    m = artist.get_marker()
    return (to_rgb(artist.get_color()), ls, "None" if _no_marker(m) else m)


def _colours(handle) -> list:
    """The colours an entry shows."""
    out = []
    for get in ("get_color", "get_facecolor", "get_markerfacecolor", "get_edgecolor"):
        try:
            c = getattr(handle, get)()
        except (AttributeError, TypeError):
            continue
        arr = np.atleast_2d(np.asarray(matplotlib.colors.to_rgba_array(c)))
        out += [tuple(np.round(r[:3], 4)) for r in arr if r[3] > 0]
    return out


def legend_problems(fig) -> list:
    """What the legends of ``fig`` get wrong, in words (an empty list: nothing)."""
    problems = []
    legends = [(ax, ax.get_legend()) for ax in fig.axes if ax.get_legend() is not None]
    legends += [(None, lg) for lg in fig.legends]
    for ax, lg in legends:
        texts = [t for t, _ in _entries(lg)]
        dup = sorted({t for t in texts if texts.count(t) > 1})
        if dup:
            problems.append(f"legend entries named twice: {dup}")
    for ax in fig.axes:
        own = [e for a, lg in legends if a is ax or a is None for e in _entries(lg)]
        shared = [e for a, lg in legends if a is not None and a is not ax for e in _entries(lg)]
        for line in ax.get_lines():
            label = line.get_label()
            if not label or label.startswith("_") or not line.get_visible():
                continue
            if any(t == label for t, _ in own):
                continue
            # a legend of another panel names it if it shows it exactly as it is drawn
            if any(t == label and _look(h) == _look(line) for t, h in shared):
                continue
            problems.append(f"line {label!r} is in no legend")
        mine = [h for a, lg in legends if a is ax or a is None for _, h in _entries(lg)]
        if not mine:
            continue
        shown = {c for h in mine for c in _colours(h)}
        for line in ax.get_lines():
            ls = line.get_linestyle()
            if (not line.get_visible() or ls in ("None", "none", "", " ")
                    or line.get_transform() != ax.transData):   # axhline: a reference
                continue
            xy = np.asarray(line.get_xydata(), dtype=float)
            if np.isfinite(xy).all(axis=1).sum() < 2:
                continue
            if tuple(np.round(to_rgb(line.get_color()), 4)) not in shown:
                problems.append(f"a line of colour {line.get_color()!r} ({line.get_label()!r}) "
                                "has no legend entry of its colour")
    return problems


def _marker_boxes(ax, renderer) -> list:
    """Display-space boxes of the markers of ``ax`` (vector ones, inside the axes)."""
    fig = ax.figure
    px = fig.dpi / 72.0
    view = ax.bbox
    boxes = []

    def add(points, half):
        for x, y in points:
            if (np.isfinite(x) and np.isfinite(y) and view.x0 <= x <= view.x1
                    and view.y0 <= y <= view.y1):
                boxes.append(Bbox([[x - half, y - half], [x + half, y + half]]))

    for line in ax.get_lines():
        m = line.get_marker()
        if not line.get_visible() or line.get_rasterized() or _no_marker(m):
            continue
        style = MarkerStyle(m)
        ext = style.get_path().transformed(style.get_transform()).get_extents()
        half = (line.get_markersize() * max(abs(ext.x0), abs(ext.x1), abs(ext.y0), abs(ext.y1))
                + 0.5 * line.get_markeredgewidth()) * px
        xy = np.asarray(line.get_xydata(), dtype=float)
        add(line.get_transform().transform(xy) if len(xy) else [], half)
    for coll in ax.collections:
        if (not coll.get_visible() or coll.get_rasterized() or not hasattr(coll, "get_sizes")
                or not len(coll.get_sizes()) or not len(coll.get_offsets())):
            continue
        # a scatter's size is the marker's area in points squared
        half = 0.5 * np.sqrt(float(np.max(coll.get_sizes()))) * px
        add(coll.get_offset_transform().transform(coll.get_offsets()), half)
    return boxes


def overlaps(fig) -> list:
    """Texts of an axes that cover a marker of the same axes, after the figure is drawn."""
    if fig.canvas is None or not hasattr(fig.canvas, "get_renderer"):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    found = []
    for ax in fig.axes:
        marks = _marker_boxes(ax, renderer)
        for text in ax.texts:
            if not text.get_visible() or not text.get_text().strip():
                continue
            box = text.get_window_extent(renderer)
            box = Bbox([[box.x0 + 0.5, box.y0 + 0.5], [box.x1 - 0.5, box.y1 - 0.5]])
            hits = [m for m in marks if box.overlaps(m)]
            if hits:
                found.append(f"{text.get_text()!r} covers {len(hits)} marker(s) in "
                             f"{ax.get_title()[:40]!r}")
    return found


# ======================================================================================
# the impact oscillator's period doubling: the branch, the other way, the doubled branch
# ======================================================================================

IO = "impact-oscillator"
IO_PARAMS = {"eps": 0.1, "sigma": -0.5, "r": 0.8}


@pytest.fixture(scope="module")
def io_branches():
    traj = pwsdyn.simulate(IO, {"x": -1.0, "v": 0.0}, (0, 100),
                           params={**IO_PARAMS, "omega": 2.8})
    orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
    # one side, up (the default follows both sides of the start)
    up = pwsdyn.continue_orbit(IO, orbit, "omega", span=(2.0, 4.6), direction="up")
    down = pwsdyn.continue_orbit(IO, orbit, "omega", span=(2.0, 4.6), ds=-0.01)
    pd = up.special("PD")[0]
    doubled = pwsdyn.continue_orbit(IO, pd, "omega", span=(2.0, 4.6))
    return up, down, pd, doubled


def _branch_lines(ax, color, ls):
    return [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 1
            and ln.get_linestyle() == ls and to_rgb(ln.get_color()) == to_rgb(color)]


def _with_stability_at(branch, index, stable: bool):
    """The branch with one point's stability flag set (a copy: the fixture is shared)."""
    import copy

    out = copy.copy(branch)
    out.points = list(branch.points)
    p = copy.copy(out.points[index])
    p.data = {**p.data, "stable": stable}
    out.points[index] = p
    return out


@pytest.mark.parametrize("pd_flag", [None, True, False])
def test_stability_style_changes_exactly_at_the_located_pd(io_branches, pd_flag):
    """The solid (stable) part of the period-one branch ends at the located PD value and the
    dashed part starts there, whatever the PD point's own stability flag says (a multiplier
    on the unit circle to the tolerance); the period-two branch is solid from there on."""
    up, _, pd, doubled = io_branches
    if pd_flag is not None:
        up = _with_stability_at(up, pd.index, pd_flag)
    fig = up.plot(y="v")
    ax = fig.axes[0]
    doubled.plot(y="v", ax=ax, color="C3")
    solid = _branch_lines(ax, "k", "-")
    dashed = _branch_lines(ax, "k", "--")
    assert len(solid) == 1 and len(dashed) == 1
    assert max(solid[0].get_xdata()) == pd.value
    assert min(dashed[0].get_xdata()) == pd.value
    # the curve is unbroken at the PD: both parts hold its point
    y_pd = up.states[pd.index, 1]
    assert solid[0].get_ydata()[-1] == y_pd and dashed[0].get_ydata()[0] == y_pd
    red_solid = _branch_lines(ax, "C3", "-")
    assert len(red_solid) == 1 and min(red_solid[0].get_xdata()) == pd.value
    assert _branch_lines(ax, "C3", "--") == []
    # one past the PD would be the next computed point: not reached by the solid line
    assert up.values[pd.index + 1] > pd.value


def test_style_runs_between_regular_points_and_across_signatures():
    """Where the style changes between two regular points the first's style reaches the
    second (nothing says where in between); a located point between them moves the change
    to it; no segment joins two signatures."""
    from pwsdyn.plot._branches import _runs

    st = ["stable", "stable", "unstable", "unstable"]
    assert _runs(st, [False] * 4, [0] * 4) == [(0, 2, "stable"), (2, 3, "unstable")]
    assert _runs(st, [False, True, False, False], [0] * 4) == [(0, 1, "stable"),
                                                               (1, 3, "unstable")]
    assert _runs(st, [False, False, True, False], [0] * 4) == [(0, 2, "stable"),
                                                               (2, 3, "unstable")]
    assert _runs(["stable"] * 4, [False] * 4, [0, 0, 1, 1]) == [(0, 1, "stable"),
                                                                (2, 3, "stable")]
    assert _runs(["unstable"], [False], [0]) == [(0, 0, "unstable")]


def test_switched_branch_is_labelled_by_its_origin(io_branches, tmp_path):
    """The period-doubled branch starts at a branch point of the doubled problem (its
    special point stays ``BP``) but records that it was born at the PD, and its first point
    is labelled so -- also after a save and a load; drawn with its parent, the PD is marked
    and labelled once."""
    up, _, pd, doubled = io_branches
    assert doubled.origin == "PD" and up.origin == ""
    assert doubled.points[0].special == "BP"
    ax = doubled.plot(y="v").axes[0]
    texts = [t.get_text() for t in ax.texts]
    assert "PD" in texts and "BP" not in texts
    (mark,) = [ln for ln in ax.get_lines() if ln.get_gid() == "special PD"]
    assert mark.get_xdata()[0] == pd.value
    doubled.save(tmp_path / "doubled.nc")
    loaded = pwsdyn.load_branch(tmp_path / "doubled.nc")
    assert loaded.origin == "PD"
    assert "PD" in [t.get_text() for t in loaded.plot(y="v").axes[0].texts]
    both = up.plot(y="v").axes[0]
    doubled.plot(y="v", ax=both, color="C3")
    assert [t.get_text() for t in both.texts].count("PD") == 1
    assert len([ln for ln in both.get_lines() if ln.get_gid() == "special PD"]) == 1


def test_branches_on_one_axes_share_one_legend_and_are_all_named(io_branches):
    up, down, _, doubled = io_branches
    fig = up.plot(y="v")
    ax = fig.axes[0]
    down.plot(y="v", ax=ax)
    doubled.plot(y="v", ax=ax, color="C3")
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert sorted(texts) == sorted(["stable", "unstable", "period-1 orbits", "period-2 orbits"])
    assert legend_problems(fig) == []
    # the branch's entry has its colour; a name of one's own replaces the default
    entries = dict(_entries(ax.get_legend()))
    assert to_rgb(entries["period-2 orbits"].get_color()) == to_rgb("C3")
    fig2 = up.plot(y="v", label="one impact per period")
    assert "one impact per period" in [t.get_text() for t in fig2.axes[0].get_legend().get_texts()]
    # and over a sweep: the sweep's entries stay, drawn large enough to read
    sweep = pwsdyn.sweep(IO, "omega", np.linspace(3.0, 4.6, 6), {"x": -1.0, "v": 0.0},
                         params=IO_PARAMS, section="impact", transient=20, samples=4,
                         direction="up", progress=False, workers=1)
    ax3 = up.plot(y="v", sweep=sweep).axes[0]
    doubled.plot(y="v", ax=ax3, color="C3")
    entries = dict(_entries(ax3.get_legend()))
    assert {"sweep up", "stable", "unstable", "period-1 orbits", "period-2 orbits"} <= set(entries)
    assert entries["sweep up"].get_markersize() >= 5
    assert legend_problems(ax3.figure) == []


def test_the_checks_see_a_branch_left_out_and_a_duplicate():
    """The legend check itself: a coloured line with no entry, a label in no legend and a
    label named twice are each reported."""
    fig = Figure()
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], color="k", label="stable")
    ax.plot([0, 1], [1, 0], color="C3")                       # drawn, not named
    ax.plot([0, 1], [0.5, 0.5], color="k", label="period-2")  # labelled, not in the legend
    ax.legend(ax.get_lines()[:1] * 2, ["stable", "stable"])
    found = " | ".join(legend_problems(fig))
    assert "named twice" in found and "'period-2' is in no legend" in found
    assert "has no legend entry of its colour" in found


def test_special_point_labels_are_clear_of_every_marker(io_branches):
    """After drawing, no label's box overlaps a marker's: the label sits off the marker by
    its half extent (the diamond of a BP reaches further than a circle) and a gap."""
    up, down, _, doubled = io_branches
    fig = up.plot(y="v")
    ax = fig.axes[0]
    down.plot(y="v", ax=ax)
    doubled.plot(y="v", ax=ax, color="C3")
    kinds = {t.get_text() for t in ax.texts}
    assert {"PD", "LP"} <= kinds
    assert overlaps(fig) == []
    # every marker kind, at a zoom that puts the label right beside it
    fig2 = Figure(figsize=(4, 3), dpi=150)
    ax2 = fig2.subplots()
    from pwsdyn.plot._common import _label_beside
    for k, (kind, mk) in enumerate(plot.SPECIAL_MARKERS.items()):
        ax2.plot(k, 0, marker=mk, ms=7, mew=1.5, ls="none", mfc="white")
        _label_beside(ax2, kind, (k, 0), marker=mk, size=7, edge=1.5, fontsize=8)
    assert overlaps(fig2) == []
    # the check sees a label written over its marker
    ax2.annotate("XX", (0, 0), fontsize=8, ha="center", va="center")
    assert overlaps(fig2)


# ======================================================================================
# names typeset as Greek letters, one way everywhere
# ======================================================================================

@pytest.mark.parametrize("name, tex", [
    ("eps", r"\varepsilon"), ("epsilon", r"\varepsilon"), ("eps_1", r"\varepsilon_{1}"),
    ("sigma", r"\sigma"), ("omega", r"\omega"), ("mu", r"\mu"), ("mu_s", r"\mu_{s}"),
    ("lam", r"\lambda"), ("lambda", r"\lambda"), ("gamma", r"\gamma"), ("Lam", r"\Lambda"),
    ("x1", "x_{1}"), ("A", "A"), ("v", "v")])
def test_names_are_typeset_as_a_reader_writes_them(name, tex):
    assert plot._latex_name(name) == tex
    assert plot._tex(name) == f"${tex}$"


def test_titles_and_labels_typeset_every_parameter_alike(tmp_path):
    """The impact oscillator's eps, sigma, omega are Greek in the trajectory's title and in
    its surface's label; no name is left in Latin letters inside the mathematics."""
    traj = pwsdyn.simulate(IO, {"x": -1.0, "v": 0.0}, (0, 10), params={**IO_PARAMS,
                                                                        "omega": 2.8})
    fig = plot.plot_trajectory(traj)
    title = fig._suptitle.get_text()
    for want in (r"$\varepsilon = 0.1$", r"$\omega = 2.8$", r"$\sigma = -0.5$", "$r = 0.8$"):
        assert want in title
    # four values fit beside the name: a line is measured as printed, not as mathtext source
    assert title.startswith("impact-oscillator   (") and "\n" not in title
    legend = " ".join(t.get_text() for t in fig.legends[0].get_texts())
    assert r"x = \sigma" in legend
    texts = [t.get_text() for t in fig.findobj(matplotlib.text.Text)]
    assert not [t for t in texts if "$eps" in t or "$sigma" in t or "$omega" in t]
    sweep = pwsdyn.sweep("sqrt-map", "lam", np.linspace(0.1, 0.2, 3), [0.0],
                         params={"mu": 0.05}, direction="up", workers=1, progress=False)
    ax = plot.plot_bifurcation(sweep).axes[0]
    assert r"$\lambda$" in ax.get_title() and r"$\mu = 0.05$" in ax.get_title()
    assert plot.plot_bifurcation(sweep).axes[-1].get_xlabel() == r"$\lambda$"


# ======================================================================================
# the gallery: every figure of every script
# ======================================================================================

def _figures(namespace: dict) -> list:
    """The figures a script made: those it holds in variables and pyplot's."""
    import matplotlib.pyplot as plt

    figs = {id(v): v for v in namespace.values() if isinstance(v, Figure)}
    for n in plt.get_fignums():
        f = plt.figure(n)
        figs.setdefault(id(f), f)
    return list(figs.values())


@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(EXAMPLES.glob("plot_*.py")), ids=lambda p: p.name)
def test_gallery_figures_name_every_line_and_keep_labels_clear(script, tmp_path, monkeypatch):
    """Each gallery script run as the documentation build runs it (Agg, in this process):
    every figure it makes has legends that name each labelled line once, and no text over a
    marker of its axes."""
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PWSDYN_QUIET", "1")
    plt.close("all")
    try:
        namespace = runpy.run_path(os.fspath(script), run_name="__main__")
        figs = _figures(namespace)
        assert figs, f"{script.name} made no figure"
        problems = []
        for k, fig in enumerate(figs):
            problems += [f"figure {k}: {p}" for p in legend_problems(fig) + overlaps(fig)]
        assert not problems, "\n".join(problems)
    finally:
        plt.close("all")
