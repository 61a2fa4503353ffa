"""Figures (pwsdyn.plot): drawing into the user's axes (``ax=``), the orbit figure's
multiplier panel clear of the other panels, up and down sweeps told apart, the fixed
parameters in the titles, the attractors marked on basin figures, every name of the package
importable from ``pwsdyn.plot``.

Every figure is drawn on the Agg canvas; files go to pytest's ``tmp_path`` only.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import pwsdyn  # noqa: E402
import pwsdyn.plot as plot  # noqa: E402
from pwsdyn import ArgumentError, PeriodicOrbit  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _orbit_cases import io_orbit  # noqa: E402


# ======================================================================================
# shared results (small and quick)
# ======================================================================================

@pytest.fixture(scope="module")
def ball():
    return pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0.0, 3.0),
                           params={"A": 0.1, "omega": 2 * np.pi})


@pytest.fixture(scope="module")
def ball_orbit():
    """The bouncing ball's period-1 orbit on its vibrating table (the zoo's defaults)."""
    params = {"A": 0.224, "omega": 2 * np.pi}
    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.5, "v": 0.0}, (0.0, 60.0), params=params)
    return PeriodicOrbit.from_trajectory(traj)


@pytest.fixture(scope="module")
def stick_slip_orbit():
    """An autonomous orbit with Filippov sliding (trivial multiplier left out)."""
    traj = pwsdyn.simulate("stick-slip-oscillator", {"x": 0.0, "v": 0.0}, (0.0, 40.0))
    return PeriodicOrbit.from_trajectory(traj, period=12.0)


@pytest.fixture(scope="module")
def sweep_both():
    """A map's sweep in both directions with Lyapunov exponents (lam held fixed)."""
    return pwsdyn.sweep("sqrt-map", "mu", np.linspace(0.005, 0.05, 12), [0.0],
                        params={"lam": 0.1}, lyapunov=True, direction="both", workers=1,
                        progress=False)


@pytest.fixture(scope="module")
def map_basins():
    return pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.5, 0.5, 11)},
                         params={"mu": 0.1, "lam": 0.1}, workers=1, progress=False)


@pytest.fixture(scope="module")
def flow_basins():
    """A 2-D grid of the impact oscillator with its stable period-1 orbit (exact flow)."""
    return pwsdyn.basins("impact-oscillator", {"x": np.linspace(-1.0, -0.2, 5),
                                               "v": np.linspace(-1.0, 1.0, 5)},
                         params={"omega": 2.5}, transient=60, samples=16, workers=1,
                         progress=False, exact=True)


@pytest.fixture
def no_new_figure(monkeypatch):
    """Any figure made by pwsdyn.plot fails the test (with ``ax`` it must draw there)."""
    def forbidden(*args, **kwargs):
        raise AssertionError("pwsdyn.plot created a figure although ax= was given")

    # every module of the package that makes figures
    for module in (plot._common, plot._trajectories, plot._orbits, plot._sweeps,
                   plot._branches):
        monkeypatch.setattr(module, "Figure", forbidden)


def _user_figure(*args, **kwargs) -> Figure:
    fig = Figure(*args, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def _artists(ax) -> int:
    return len(ax.lines) + len(ax.collections) + len(ax.patches) + len(ax.images)


# ======================================================================================
# ax=: drawing into the user's axes
# ======================================================================================

def test_trajectory_into_one_axes_draws_the_phase_plane(ball, no_new_figure):
    fig = _user_figure()
    ax = fig.add_subplot()
    assert plot.plot_trajectory(ball, ax=ax) is fig
    assert fig.axes == [ax] and not fig.legends and fig._suptitle is None
    assert ax.get_xlabel() == "$y$" and ax.get_ylabel() == "$v$"
    assert _artists(ax) >= 3                      # flow, impacts, start (and the surface)
    assert "bouncing-ball" in ax.get_title() and ax.get_legend() is not None


def test_trajectory_into_a_sequence_of_axes(ball, no_new_figure, tmp_path):
    fig = _user_figure(figsize=(8, 6))
    axes = fig.subplots(2, 2).ravel()
    before = [_artists(a) for a in axes]
    out = plot.plot_trajectory(ball, path=tmp_path / "mine.png", ax=axes[:3])
    assert out is fig and len(fig.axes) == 4
    ax_y, ax_v, ax_phase, spare = axes
    assert ax_y.get_ylabel() == "$y$" and ax_v.get_ylabel() == "$v$"
    assert ax_phase.get_xlabel() == "$y$" and ax_phase.get_ylabel() == "$v$"
    assert all(_artists(a) > b for a, b in zip(axes[:3], before[:3]))
    assert _artists(spare) == 0                    # left alone
    assert (tmp_path / "mine.png").read_bytes()[:4] == b"\x89PNG"
    # the time series only: one axes per state shown
    fig2 = _user_figure()
    ax = fig2.add_subplot()
    assert plot.plot_trajectory(ball, states=["v"], ax=[ax]) is fig2
    assert ax.get_ylabel() == "$v$" and ax.get_xlabel() == "$t$"


def test_trajectory_ax_in_a_subfigure_returns_the_whole_figure(ball, no_new_figure):
    fig = _user_figure(figsize=(8, 4))
    left, right = fig.subfigures(1, 2)
    ax = right.add_subplot()
    assert plot.plot_trajectory(ball, ax=ax) is fig


def test_trajectory_ax_of_the_wrong_size_is_refused_before_drawing(ball, tmp_path):
    fig = _user_figure()
    axes = fig.subplots(1, 5)
    with pytest.raises(ArgumentError, match="holds 5 axes.*2 axes: the 2 time series"):
        plot.plot_trajectory(ball, ax=axes, path=tmp_path / "x.png")
    with pytest.raises(ArgumentError, match="Axes"):
        plot.plot_trajectory(ball, ax="not axes")
    other = _user_figure().add_subplot()
    with pytest.raises(ArgumentError, match="one figure"):
        plot.plot_trajectory(ball, ax=[axes[0], axes[1], other])
    assert all(_artists(a) == 0 for a in axes) and not (tmp_path / "x.png").exists()


def test_orbit_into_axes_with_a_multiplier_axes(ball_orbit, no_new_figure):
    fig = _user_figure(figsize=(10, 4))
    axes = list(fig.subplots(1, 4))
    assert plot.plot_orbit(ball_orbit, ax=axes) is fig
    mu_ax = axes[3]
    assert mu_ax.get_title() == "Floquet multipliers"
    pts = np.concatenate([c.get_offsets() for c in mu_ax.collections])
    np.testing.assert_allclose(np.sort_complex(pts[:, 0] + 1j * pts[:, 1]),
                               np.sort_complex(ball_orbit.multipliers), atol=1e-12)
    # one axes: the phase plane; the largest multiplier modulus is in the title
    fig1 = _user_figure()
    ax = fig1.add_subplot()
    plot.plot_orbit(ball_orbit, ax=ax)
    assert fig1.axes == [ax] and "periodic orbit" in ax.get_title()
    assert "max $|\\mu| = 0.8" in ax.get_title()


def test_explore_plots_into_given_axes(sweep_both, map_basins, no_new_figure):
    fig = _user_figure(figsize=(8, 8))
    a1, a2, a3, a4 = fig.subplots(4, 1)
    assert plot.plot_bifurcation(sweep_both, ax=[a1, a2]) is fig
    assert {ln.get_label() for ln in a1.lines} >= {"sweep up", "sweep down"}
    assert len(a2.lines) == 2                      # events per iterate, up and down
    assert plot.plot_lyapunov(sweep_both, ax=a3) is fig
    assert len(a3.lines) >= 2
    assert plot.plot_basins(map_basins, ax=a4) is fig
    assert len(a4.collections) == 1                # the basin colours
    assert len(fig.axes) == 4
    # the diagram alone in one axes
    fig2 = _user_figure()
    ax = fig2.add_subplot()
    plot.plot_bifurcation(sweep_both, ax=ax)
    assert fig2.axes == [ax] and ax.get_xlabel() == "$\\mu$"
    with pytest.raises(ArgumentError, match="holds 3 axes"):
        plot.plot_bifurcation(sweep_both, ax=_user_figure().subplots(1, 3))


# ======================================================================================
# the orbit figure: the multiplier panel covers nothing
# ======================================================================================

def _orbit_cases():
    return ["io-stable", "io-unstable", "ball", "stick-slip"]


@pytest.mark.parametrize("case", _orbit_cases())
def test_multiplier_panel_is_clear_of_the_orbit_and_tick_labels(case, request, tmp_path):
    orbit = {"io-stable": lambda: io_orbit("stable"),
             "io-unstable": lambda: io_orbit("unstable"),
             "ball": lambda: request.getfixturevalue("ball_orbit"),
             "stick-slip": lambda: request.getfixturevalue("stick_slip_orbit")}[case]()
    fig = plot.plot_orbit(orbit, path=tmp_path / f"{case}.png")
    FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    mu_ax = [a for a in fig.axes if a.get_title() == "Floquet multipliers"]
    assert len(mu_ax) == 1
    mu_ax = mu_ax[0]
    # its markers are the multipliers, all inside its limits
    pts = np.concatenate([c.get_offsets() for c in mu_ax.collections])
    assert len(pts) == len(orbit.multipliers)
    lim = mu_ax.get_xlim()
    assert np.all(np.abs(pts) <= max(abs(lim[0]), abs(lim[1])))
    # the panel with its tick labels, axis labels and title overlaps no other axes with its
    # tick labels, and the orbit's axes hold nothing of it
    box = mu_ax.get_tightbbox(renderer)
    for other in fig.axes:
        if other is mu_ax or not other.axison:
            continue
        assert not box.overlaps(other.get_tightbbox(renderer)), other.get_ylabel()
        for label in other.get_xticklabels() + other.get_yticklabels():
            if label.get_visible() and label.get_text():
                assert not box.overlaps(label.get_window_extent(renderer))
    # every axes with its labels, every text (the list of multipliers included) and the
    # legend lie inside the figure
    page = fig.bbox
    boxes = [(a.get_tightbbox(renderer), a.get_title()) for a in fig.axes]
    boxes += [(t.get_window_extent(renderer), t.get_text()) for a in fig.axes for t in a.texts]
    boxes += [(lg.get_window_extent(renderer), "legend") for lg in fig.legends]
    boxes += [(fig._suptitle.get_window_extent(renderer), "title")]
    for ext, what in boxes:
        assert (ext.x0 >= page.x0 - 1 and ext.x1 <= page.x1 + 1
                and ext.y0 >= page.y0 - 1 and ext.y1 <= page.y1 + 1), what


def test_orbit_figure_lists_the_multipliers(ball_orbit):
    fig = plot.plot_orbit(ball_orbit)
    texts = " ".join(t.get_text() for t in fig.findobj(matplotlib.text.Text))
    mu = ball_orbit.multipliers[0]
    assert f"{abs(mu):.4g}" in texts and f"{mu.real:.4g}" in texts
    assert "1 event per period" in fig._suptitle.get_text()


# ======================================================================================
# sweeps: up and down told apart; fixed parameters in the titles
# ======================================================================================

def test_up_and_down_sweeps_differ_in_marker_and_colour(sweep_both):
    fig = plot.plot_bifurcation(sweep_both)
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.lines}
    up, down = lines["sweep up"], lines["sweep down"]
    assert up.get_marker() != down.get_marker()
    assert matplotlib.colors.to_hex(up.get_color()) != matplotlib.colors.to_hex(
        down.get_color())
    # both visible at the default size: neither marker smaller than a point and a half
    assert up.get_markersize() >= 1.5 and down.get_markersize() >= 1.5
    # a cross is only its stroke: it must have one
    assert down.get_markeredgewidth() > 0
    # the legend shows the two markers large enough to read
    legend = ax.get_legend()
    entries = dict(zip([t.get_text() for t in legend.get_texts()], legend.legend_handles))
    assert entries["sweep up"].get_marker() == up.get_marker()
    assert entries["sweep down"].get_marker() == down.get_marker()
    assert min(entries["sweep up"].get_markersize(),
               entries["sweep down"].get_markersize()) >= 5
    # and the Lyapunov figure uses the same pair
    ly = plot.plot_lyapunov(sweep_both).axes[0]
    markers = {ln.get_label().split("(")[-1].rstrip(")"): ln.get_marker() for ln in ly.lines
               if "(" in ln.get_label()}
    assert markers["up"] == up.get_marker() and markers["down"] == down.get_marker()


def test_titles_give_the_fixed_parameters(sweep_both, map_basins, ball):
    bif = plot.plot_bifurcation(sweep_both).axes[0].get_title()
    assert "$\\lambda = 0.1$" in bif and "\\mu =" not in bif      # mu is swept
    ly = plot.plot_lyapunov(sweep_both).axes[0].get_title()
    assert "$\\lambda = 0.1$" in ly and "\\mu =" not in ly
    bas = plot.plot_basins(map_basins).axes[0].get_title()
    assert "$\\mu = 0.1$" in bas and "$\\lambda = 0.1$" in bas
    traj = plot.plot_trajectory(ball)._suptitle.get_text()
    for name, value in [("g", "9.81"), ("e", "0.8"), ("A", "0.1"), ("\\omega", "6.283")]:
        assert f"${name} = {value}$" in traj


def test_parameter_titles_wrap_and_write_powers_of_ten():
    lines = plot._values_text({f"p{k}": 10.0 ** -k for k in range(12)}, width=60)
    assert len(lines) > 1 and all(len(ln) < 200 for ln in lines)
    assert "10^{-5}" in "".join(lines) and "e-05" not in "".join(lines)


# ======================================================================================
# basins: the attractors marked
# ======================================================================================

def _attractor_markers(ax) -> dict:
    return {ln.get_gid(): ln for ln in ax.lines if (ln.get_gid() or "").startswith("attractor")}


def test_map_basins_mark_the_period_two_cycle(map_basins):
    ax = plot.plot_basins(map_basins).axes[0]
    marks = _attractor_markers(ax)
    assert set(marks) == {"attractor 0"}
    xs = np.sort(marks["attractor 0"].get_xdata())
    cycle = np.sort(map_basins.attractor_points.values[0, :, 0])
    np.testing.assert_allclose(xs, cycle[np.isfinite(cycle)])
    assert len(xs) == 2
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert len(texts) == 1 and texts[0].startswith("0: period 2, ") and "(100.0%)" in texts[0]


def test_flow_basins_mark_the_attractor_where_it_lies(flow_basins):
    fig = plot.plot_basins(flow_basins)
    ax = fig.axes[0]
    marks = _attractor_markers(ax)
    periodic = [int(a) for a in flow_basins.attractor.values
                if int(flow_basins.attractor_period[a]) > 0]
    assert periodic and {f"attractor {a}" for a in periodic} <= set(marks)
    for a in periodic:
        pts = flow_basins.attractor_points.sel(attractor=a)
        x = pts.sel(state="x").values
        v = pts.sel(state="v").values
        ok = np.isfinite(x)
        np.testing.assert_allclose(marks[f"attractor {a}"].get_xdata(), x[ok])
        np.testing.assert_allclose(marks[f"attractor {a}"].get_ydata(), v[ok])
    # the grid's extent is kept (markers do not rescale the axes)
    assert ax.get_xlim()[0] <= -1.0 and ax.get_xlim()[1] >= -0.2
    # numbered next to the marker
    tags = [t.get_text() for t in ax.texts]
    assert any(str(periodic[0]) in t for t in tags)


def test_basins_of_a_non_periodic_attractor_store_and_mark_its_points():
    ds = pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.2, 0.2, 5)},
                       params={"mu": 0.02, "lam": 0.8}, workers=1, progress=False)
    nonper = [int(a) for a in ds.attractor.values if int(ds.attractor_period[a]) == 0]
    assert nonper, "expected the chaotic attractor of the square-root map"
    pts = ds.attractor_points.sel(attractor=nonper[0]).values
    assert np.isfinite(pts).all(axis=1).sum() >= 2
    ax = plot.plot_basins(ds).axes[0]
    assert f"attractor {nonper[0]}" in _attractor_markers(ax)


# ======================================================================================
# the package: every name importable where it was
# ======================================================================================

#: The names ``pwsdyn.plot`` has offered since it was one module (private ones that tests and
#: other modules import included): a contract, whatever module of the package defines them.
PUBLIC_NAMES = ["BASIN_COLORS", "BASIN_SPECIAL_COLORS", "BRANCH_STYLES", "CONSTRAINED_STYLES",
                "DEFAULT_METRICS", "EVENT_STYLES", "SPECIAL_MARKERS", "SURFACE_COLOR",
                "SWEEP_COLORS", "SWEEP_MARKERS", "TRAJECTORY_COLOR", "VARIANT_COLORS",
                "figure_formats", "plot_basins", "plot_bifurcation", "plot_branch",
                "plot_lyapunov", "plot_metrics", "plot_orbit", "plot_trajectory"]


@pytest.mark.parametrize("name", PUBLIC_NAMES + ["_branch_y", "_values_text", "Figure"])
def test_every_name_of_the_module_is_importable_from_the_package(name):
    import importlib

    # what ``from pwsdyn.plot import name`` does, in a fresh import of the package
    module = importlib.reload(importlib.import_module("pwsdyn.plot"))
    assert hasattr(module, name)


def test_the_package_exports_each_public_name_of_its_modules_once():
    """``__all__`` lists the public names each module of the package defines (functions,
    constants) and nothing else, and each is defined in one module only."""
    import ast

    defined: list = []
    for path in sorted(Path(plot.__file__).parent.glob("_*.py")):
        if path.name == "__init__.py":
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                defined.append(node.name)
            elif isinstance(node, ast.Assign):
                defined += [t.id for t in node.targets if isinstance(t, ast.Name)]
    public = [k for k in defined if not k.startswith("_")]
    assert len(public) == len(set(public))
    assert sorted(public) == sorted(plot.__all__)
    assert set(PUBLIC_NAMES) <= set(plot.__all__)
