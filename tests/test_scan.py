"""Two-parameter scans (pwsdyn.scan, pwsdyn.plot.plot_scan, ``pwsdyn scan``).

* Every row of a scan is the uninterrupted sequential sweep of its row (pwsdyn.sweep in one
  chunk, which continues the final state from each value to the next): bit for bit, with
  any number of workers and after a resume from the store.
* The borders of the period regions lie where the bifurcations are, against closed forms of
  the impact oscillator derived independently of pwsdyn (tests/_orbit_cases.py): the period
  doubling of the one-impact orbit (``det(M + I) = 0``) and the graze of the non-impacting
  orbit (``sigma = R(omega) = 1 / |1 - omega^2 + i eps omega|``), and the curves continued by
  pwsdyn.continue_bifurcation run between the same grid cells. A border can only be located
  to the grid spacing: the check is that the cells on either side of it bracket the
  bifurcation's value (at a period doubling one cell between them may show no period: the
  transient decays slowly where a multiplier is near -1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from scipy.optimize import brentq

import pwsdyn
from pwsdyn.errors import ArgumentError
from pwsdyn.plot import plot_scan, scan_classes

from _orbit_cases import io_one_impact, io_orbit

IO_MODEL = "impact-oscillator"
IO_PARAMS = {"eps": 0.1, "r": 0.8}
X0 = {"x": -1.0, "v": 0.0}


def _io_scan(grid, x0=X0, **kw):
    kw = {"section": "impact", "transient": 100, "samples": 32, "progress": False,
          "params": IO_PARAMS, **kw}
    return pwsdyn.scan(IO_MODEL, grid, x0, **kw)


# ---- the meaning: rows are sequential sweeps, whatever the schedule ----------------------

GRID = {"omega": np.linspace(3.0, 4.6, 9), "sigma": [-0.5, 0.0, 0.1]}


@pytest.fixture(scope="module")
def serial():
    return _io_scan(GRID, workers=1)


def test_each_row_is_the_uninterrupted_sequential_sweep(serial):
    assert serial.attrs["kind"] == "scan"
    assert (serial.attrs["parameter"], serial.attrs["parameter2"]) == ("omega", "sigma")
    assert dict(serial.sizes) == {"direction": 2, "omega": 9, "sigma": 3, "state": 2}
    for s in GRID["sigma"]:
        sw = pwsdyn.sweep(IO_MODEL, "omega", GRID["omega"], X0,
                          params={**IO_PARAMS, "sigma": s}, section="impact", transient=100,
                          samples=32, chunk_size=len(GRID["omega"]), workers=1,
                          progress=False)
        row = serial.sel(sigma=s)
        for k in ("period", "events_per_period", "stick_time", "slide_time", "n_points",
                  "status", "steps", "x_final"):
            assert np.array_equal(row[k].values, sw[k].values, equal_nan=True), (s, k)


def test_workers_and_resume_do_not_change_the_result(serial, tmp_path):
    """1 worker, 2 threads, a Dask LocalCluster of 2 worker processes (the user's cluster is
    reached the same way, by its address) and a resume: identical datasets."""
    xr.testing.assert_identical(_io_scan(GRID, workers=2), serial)
    xr.testing.assert_identical(_io_scan(GRID, workers=2, scheduler="processes"), serial)
    store = tmp_path / "store"
    first = _io_scan(GRID, workers=2, store=store)
    xr.testing.assert_identical(first, serial)
    rows = sorted(store.glob("chunk-*.nc"))
    assert len(rows) == 2 * len(GRID["sigma"])
    # a run killed after some rows: the others are recomputed, the kept ones read back
    for f in rows[1::2]:
        f.unlink()
        f.with_suffix(".sha256").unlink()
    resumed = _io_scan(GRID, workers=2, store=store)
    xr.testing.assert_identical(resumed, serial)
    with pytest.raises(pwsdyn.explore.StoreMismatchError):
        _io_scan(GRID, workers=1, store=store, transient=101)


def test_the_dataset_round_trips_through_its_file(serial, tmp_path):
    from pwsdyn.io import open_dataset

    out = tmp_path / "scan.nc"
    ds = _io_scan(GRID, workers=2, out=out)
    back = open_dataset(out)
    assert back.equals(ds) and back.attrs["kind"] == "scan"
    with pytest.raises(pwsdyn.OutputExistsError):
        _io_scan(GRID, out=out)


def test_a_map_scan_and_the_largest_lyapunov_exponent():
    """A map scans as a flow does, and ``lyapunov=True`` adds the largest exponent (its
    values are checked against closed forms in tests/test_explore.py; here: one finite
    exponent per point, over the grid)."""
    ds = pwsdyn.scan("sqrt-map", {"mu": [0.01, 0.02], "lam": [0.2, 0.3]}, [0.0],
                     direction="up", lyapunov=True, samples=200, transient=100, workers=1,
                     progress=False)
    assert dict(ds.sizes) == {"direction": 1, "mu": 2, "lam": 2, "state": 1}
    assert np.isfinite(ds.lyapunov.values).all() and (ds.status.values == 0).all()


def test_the_arguments_are_checked_before_any_work(tmp_path):
    with pytest.raises(ArgumentError, match="two parameters"):
        pwsdyn.scan(IO_MODEL, {"omega": [3.0]}, X0)
    with pytest.raises(ArgumentError, match="unknown parameter 'Q'"):
        pwsdyn.scan(IO_MODEL, {"omega": [3.0], "Q": [1.0]}, X0)
    with pytest.raises(ArgumentError, match="distinct"):
        pwsdyn.scan(IO_MODEL, {"omega": [3.0, 3.0], "sigma": [0.0]}, X0)
    with pytest.raises(ArgumentError, match="must not set the scanned parameter 'sigma'"):
        pwsdyn.scan(IO_MODEL, {"omega": [3.0], "sigma": [0.0]}, X0, params={"sigma": 1.0})
    with pytest.raises(ArgumentError, match="forcing period"):
        pwsdyn.scan(IO_MODEL, {"sigma": [0.0], "omega": [0.0, 1.0]}, X0)
    with pytest.raises(ArgumentError, match="direction"):
        pwsdyn.scan(IO_MODEL, {"omega": [3.0], "sigma": [0.0]}, X0, direction="sideways")


# ---- the borders lie on the bifurcation curves -------------------------------------------

def _border(cls_row, before, after, gap: int = 1):
    """``(i, k)``: the last cell ``i`` of class ``before`` and the first cell ``k > i`` of
    class ``after`` in a row (in the order of the row), with at most ``gap`` cells between
    them, each without a period (class 0), or None. At a bifurcation the multiplier that
    crosses the unit circle makes the transient decay slowly (as ``|mu|^n``, ``|mu| -> 1``):
    a cell next to it may not settle to ``period_tol`` within the transient, and shows no
    period; the border is then that band."""
    for i in range(len(cls_row) - 1):
        if cls_row[i] != before:
            continue
        for k in range(i + 1, min(i + 2 + gap, len(cls_row))):
            if cls_row[k] == after:
                return i, k
            if cls_row[k] != 0:
                break
    return None


def test_period_doubling_curve_lies_on_the_border_of_period_one_and_two():
    """Rows up in omega through the period doubling of the one-impact orbit: the last
    period-1 cell and the first period-2 cell bracket omega_PD(sigma), the root of
    det(M + I) = 0 of the closed form, and the PD curve continued in (omega, sigma)."""
    omegas = np.linspace(3.8, 4.8, 21)            # spacing 0.05
    sigmas = [-0.55, -0.5, -0.45]
    ds = _io_scan({"omega": omegas, "sigma": sigmas}, direction="up", transient=200,
                  samples=64, workers=2)
    cls = scan_classes(ds.sel(direction="up"))
    up = pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "omega", span=(2.0, 4.6),
                               ds=0.05)
    curve = pwsdyn.continue_bifurcation(IO_MODEL, up.special("PD")[0], ("omega", "sigma"),
                                        span=(3.6, 5.0), ds=0.05, max_points=40)
    back = pwsdyn.continue_bifurcation(IO_MODEL, up.special("PD")[0], ("omega", "sigma"),
                                       span=(3.6, 5.0), ds=-0.05, max_points=40)
    w_c = np.concatenate([back.values[::-1], curve.values])
    s_c = np.concatenate([back.values_of("sigma")[::-1], curve.values_of("sigma")])
    order = np.argsort(s_c)
    for j, s in enumerate(sigmas):
        found = _border(cls[:, j], 1, 2)
        assert found is not None, (s, cls[:, j])
        lo, hi = omegas[found[0]], omegas[found[1]]
        w_pd = brentq(lambda w: (lambda M: 1 + np.trace(M) + np.linalg.det(M))(
            io_one_impact(w, 1, sigma=s)[2]), lo - 0.2, hi + 0.2, xtol=1e-13)
        assert lo < w_pd < hi, (s, lo, w_pd, hi)
        w_curve = np.interp(s, s_c[order], w_c[order])
        assert lo < w_curve < hi, (s, lo, w_curve, hi)
        # the curve is the closed form's to the interpolation between its points
        assert abs(w_curve - w_pd) < 5e-3


def _grazing_point(omega, eps):
    X, Y = np.linalg.solve(np.array([[1 - omega**2, -eps * omega],
                                     [eps * omega, 1 - omega**2]]), [1.0, 0.0])
    R = math.hypot(X, Y)
    orb = pwsdyn.find_periodic_orbit(IO_MODEL, [Y, omega * X], t0=0.0,
                                     params={**IO_PARAMS, "omega": omega, "sigma": R + 0.3})
    br = pwsdyn.continue_orbit(IO_MODEL, orb, "sigma", span=(R - 0.3, R + 0.3), ds=-0.05,
                               on_dib="stop")
    return br.special("GR")[0]


def test_grazing_curve_lies_on_the_border_of_the_impacting_region():
    """Rows down in sigma at fixed omega, from rest at x = 0: every row settles without
    impacts at sigma = 0.3 (asserted: the forced response has amplitude R(omega) < 0.09
    there), on the non-impacting orbit, and follows it until it grazes the stop at
    sigma = R(omega); the last
    cell without an impact and the first with impacts bracket R(omega) and the GR curve
    continued in (omega, sigma). The map is drawn in (omega, sigma) with the curve on top."""
    sigmas = np.linspace(0.0, 0.3, 16)            # spacing 0.02
    omegas = [3.5, 3.75, 4.0, 4.25]
    ds = _io_scan({"sigma": sigmas, "omega": omegas}, direction="down", workers=2,
                  x0={"x": 0.0, "v": 0.0})
    cls = scan_classes(ds.sel(direction="down"))
    curve = pwsdyn.continue_bifurcation(IO_MODEL, _grazing_point(3.5, IO_PARAMS["eps"]),
                                        ("omega", "sigma"), span=(3.4, 4.4), ds=0.05,
                                        max_points=40)
    for j, w in enumerate(omegas):
        down = cls[::-1, j]                       # in the order the row was swept
        assert down[0] == -2                      # no impact at the start of the row
        found = _border(down, -2, 1, gap=0)
        assert found is not None, (w, down)
        hi, lo = sigmas[::-1][found[0]], sigmas[::-1][found[1]]
        R = 1.0 / math.hypot(1 - w * w, IO_PARAMS["eps"] * w)
        assert lo < R < hi, (w, lo, R, hi)
        s_curve = np.interp(w, curve.values, curve.values_of("sigma"))
        assert lo < s_curve < hi, (w, lo, s_curve, hi)
    fig = plot_scan(ds, transpose=True)
    ax = fig.axes[0]
    n_before = len(ax.get_lines())
    curve.plot(ax=ax)
    assert len(ax.get_lines()) > n_before
    assert ax.get_xlabel() == "$\\omega$" and ax.get_ylabel() == "$\\sigma$"
    # the period map's legend stays beside the curves' own
    texts = [t.get_text() for leg in ax.findobj(lambda a: type(a).__name__ == "Legend")
             for t in leg.get_texts()]
    assert any(t.startswith("no impact") for t in texts)
    assert any(t.startswith("GR") for t in texts)


# ---- the figure and the command line -----------------------------------------------------

def test_plot_scan_classes_and_file(serial, tmp_path):
    cls = scan_classes(serial)
    per = serial.period.values
    assert np.array_equal(cls[(serial.status.values == 0) & (per >= 1) & (per <= 8)],
                          per[(serial.status.values == 0) & (per >= 1) & (per <= 8)])
    assert np.all(cls[(per == 0) & (serial.n_points.values == 0)] == -2)
    png = tmp_path / "map.png"
    fig = plot_scan(serial, png, direction="down")
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert "rows swept down" in fig.axes[0].get_title()
    with pytest.raises(pwsdyn.OutputExistsError):
        plot_scan(serial, png)
    with pytest.raises(ArgumentError, match="pwsdyn.scan"):
        plot_scan(serial.assign_attrs(kind="sweep"))
    with pytest.raises(ArgumentError, match="direction"):
        plot_scan(serial.sel(direction=["up"]), direction="down")


def test_cli_scan_writes_the_dataset_and_the_map(tmp_path):
    from click.testing import CliRunner

    from pwsdyn.cli import main
    from pwsdyn.io import open_dataset

    out, png = tmp_path / "s.nc", tmp_path / "s.png"
    args = ["scan", "sqrt-map", "--param", "mu", "--from", "0.01", "--to", "0.03", "--num",
            "3", "--param2", "lam", "--from2", "0.2", "--to2", "0.4", "--num2", "2",
            "--transient", "50", "--samples", "40", "--workers", "1", "--no-progress",
            "--out", str(out), "--plot", str(png)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert f"wrote       {out}" in res.output and f"wrote       {png}" in res.output
    assert not (tmp_path / "s.nc.store").exists()
    ds = open_dataset(out)
    api = pwsdyn.scan("sqrt-map", {"mu": np.linspace(0.01, 0.03, 3),
                                   "lam": np.linspace(0.2, 0.4, 2)}, None, transient=50,
                      samples=40, workers=1, progress=False)
    assert ds.equals(api)
    assert png.read_bytes()[:4] == b"\x89PNG"
    same = CliRunner().invoke(main, [*args[:-4], "--param2", "mu"])
    assert same.exit_code == 2 and "must differ" in same.output
