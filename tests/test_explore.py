"""Global analysis (issue 5): sweeps, basins, Lyapunov spectra, maps, Dask, resumable stores.

Every number is checked against something independent of the code under test: closed forms
of the ball on a vibrating table (derived below), finite differences of the flow map, the
determinant of the saltation matrix in closed form, and the square-root map's cycles solved by
hand. Long checks are marked ``slow``.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
import xarray as xr

import pwsdyn
from pwsdyn.explore import StoreMismatchError, basin_fractions
from pwsdyn.model.iteration import iterate
from pwsdyn.model.maps import MapModel

G = 9.81
OMEGA = 2 * np.pi   # table frequency: period T = 1
E = 0.8             # restitution


def ball_A(gamma):
    """Table amplitude for the normalised peak acceleration Gamma = A omega^2 / g."""
    return np.asarray(gamma) * G / OMEGA ** 2


# ======================================================================================
# Ball on a vibrating table: closed forms
# ======================================================================================
#
# Table s(t) = A sin(w t), ball in free flight y'' = -g, impact y = s: v+ = s' - e (v- - s').
# Period-1 orbit (one impact per table period T = 2 pi / w, flight time exactly T): the ball
# leaves the table at t* with velocity u and lands on it again at t* + T where s(t* + T) = s(t*),
# so u T - g T^2 / 2 = 0, u = g T / 2 and v- = -g T / 2. The impact law gives
# g T / 2 = (1 + e) s'(t*) + e g T / 2, i.e. s'(t*) = g T (1 - e) / (2 (1 + e)) and
#     cos(w t*) = pi (1 - e) / ((1 + e) Gamma),     Gamma = A w^2 / g,
# which exists for Gamma > Gamma_SN = pi (1 - e) / (1 + e) (the formula).
#
# Stability: the impact map (t_k, u_k) -> (t_{k+1}, u_{k+1}) is defined implicitly by
# F(tau; t, u) = u tau - g tau^2 / 2 - (s(t + tau) - s(t)) = 0, t' = t + tau,
# u' = (1 + e) s'(t') - e (u - g tau). At the period-1 orbit tau = T, F_t = 0, F_tau = -w with
# w = g T / 2 + s'(t*) (relative approach speed), so d tau/dt = 0, d tau/du = T / w, and
#     J = [[1, T/w], [(1+e) s''*, (1+e) s''* T/w - e + e g T/w]],  s''* = -A w^2 sin(w t*).
# With g T / w = 1 + e (restitution on the relative velocity): det J = e^2 and
#     tr J = 1 + e^2 + (1 + e)^2 s''* / g = 1 + e^2 - (1 + e)^2 Gamma sin(w t*).
# The multipliers solve m^2 - tr m + e^2 = 0. A multiplier -1 (period doubling) needs
# tr = -(1 + e^2), i.e. Gamma sin(w t*) = 2 (1 + e^2) / (1 + e)^2, hence
#     Gamma_PD = sqrt( (2 (1 + e^2) / (1 + e)^2)^2 + (pi (1 - e) / (1 + e))^2 ),
# (for e = 0.8: Gamma_SN = 0.349066, Gamma_PD = 1.070836); the orbit is stable in between.

GAMMA_SN = np.pi * (1 - E) / (1 + E)
GAMMA_PD = np.hypot(2 * (1 + E * E) / (1 + E) ** 2, GAMMA_SN)


def period_one_orbit(gamma):
    """(state at t = 0 on the period-1 orbit, multipliers) from the closed forms above."""
    T = 2 * np.pi / OMEGA
    A = ball_A(gamma)
    phi = np.arccos(GAMMA_SN / gamma)           # the stable branch: sin(w t*) > 0
    ts, u = phi / OMEGA, G * T / 2
    y_s = A * np.sin(phi)
    x0 = [y_s + u * (T - ts) - G * (T - ts) ** 2 / 2, u - G * (T - ts)]   # flight to t = T
    tr = 1 + E * E - (1 + E) ** 2 * gamma * np.sin(phi)
    return np.array(x0), np.roots([1.0, -tr, E * E])


def test_closed_form_thresholds_are_consistent():
    # the derived values, and the trace formula reproducing multiplier -1 at Gamma_PD
    assert GAMMA_SN == pytest.approx(0.3490658504, abs=1e-9)
    assert GAMMA_PD == pytest.approx(1.0708364682, abs=1e-9)
    _, m = period_one_orbit(GAMMA_PD)
    assert np.min(m.real) == pytest.approx(-1.0, abs=1e-12)


@pytest.mark.parametrize("exact", [False, True])
def test_ball_sweep_finds_period_one_and_its_period_doubling(exact):
    """Sweeping the table amplitude up from Gamma = 0.9 (one chunk, so the period-1 branch is
    continued without restarts) the period-1 orbit (1 impact per period, period 1) holds up
    to Gamma_PD and gives way to period 2 there, to within the sweep resolution; with the
    Runge-Kutta pair and with exact flights (``exact=True``)."""
    gam = np.linspace(0.9, 1.2, 61)                     # step 0.005
    step = gam[1] - gam[0]
    ds = pwsdyn.sweep("bouncing-ball", "A", ball_A(gam), {"y": 1.5, "v": 0.0},
                      params={"omega": OMEGA, "e": E}, transient=400, samples=64,
                      chunk_size=len(gam), workers=1, progress=False, exact=exact)
    per = ds.period.sel(direction="up").values
    ev = ds.events_per_period.sel(direction="up").values
    assert np.all(ds.status.values == 0)
    below = gam < GAMMA_PD - step
    above = gam > GAMMA_PD + step
    assert np.all(per[below] == 1) and np.all(ev[below] == 1)
    assert np.all(per[above] == 2) and np.all(ev[above] == 1)
    first2 = gam[np.argmax(per == 2)]
    assert abs(first2 - GAMMA_PD) <= step, (first2, GAMMA_PD)
    # the period-1 section point is the closed-form orbit's state at t = 0 (phase 0)
    k = int(np.argmin(abs(gam - 1.0)))
    x_exact, _ = period_one_orbit(gam[k])
    np.testing.assert_allclose(ds.section.sel(direction="up").values[k, -1], x_exact,
                               atol=1e-7)


def test_ball_sweep_down_loses_period_one_at_existence_threshold():
    """Sweeping down from Gamma = 0.9 the period-1 bouncing orbit persists down to Gamma_SN;
    below it the ball ends sticking to the table (no impacts, whole period stuck)."""
    gam = np.linspace(0.25, 0.9, 66)                    # step 0.01
    step = gam[1] - gam[0]
    ds = pwsdyn.sweep("bouncing-ball", "A", ball_A(gam), {"y": 1.5, "v": 0.0},
                      params={"omega": OMEGA, "e": E}, transient=400, samples=64,
                      direction="down", chunk_size=len(gam), workers=1, progress=False)
    d = ds.sel(direction="down")
    bouncing = (d.period.values == 1) & (d.events_per_period.values == 1)
    assert np.all(bouncing[gam > GAMMA_SN + step])
    assert not np.any(bouncing[gam < GAMMA_SN - step])
    stuck = gam < GAMMA_SN - step
    np.testing.assert_allclose(d.stick_time.values[stuck], 1.0, atol=1e-9)
    assert np.all(d.events_per_period.values[stuck] == 0)
    # the ball never passes through the table, also where a sticking state is carried into
    # the next value (the table is at s = 0 at the stroboscopic times t = k T)
    assert np.nanmin(d.section.values[..., 0]) > -1e-8


def test_sticking_state_carried_between_values_stays_on_the_table():
    """A ball stuck to the table (Gamma < 1) carried from value to value: each restart
    registers the contact again (chattering map, sticking) instead of falling through the
    table from a position a round-off below it."""
    gam = np.linspace(0.2, 0.3, 12)
    ds = pwsdyn.sweep("bouncing-ball", "A", ball_A(gam), {"y": 0.0, "v": 0.0},
                      params={"omega": OMEGA, "e": E}, transient=3, samples=4,
                      chunk_size=len(gam), direction="both", workers=1, progress=False)
    np.testing.assert_allclose(ds.stick_time.values, 1.0, atol=1e-9)
    np.testing.assert_allclose(ds.section.values[..., 0], 0.0, atol=1e-9)
    # the velocity is the table's, A omega cos(0)
    np.testing.assert_allclose(ds.section.values[..., 1],
                               np.broadcast_to((ball_A(gam) * OMEGA)[None, :, None],
                                               ds.section.shape[:3]), atol=1e-9)


def test_event_section_records_impacts_of_the_closed_form_orbit():
    """Section 'impact' of the Budd & Dux oscillator at omega = 2.5: the period-1 orbit's
    impact velocity and phase (closed form, tests/test_model.py and the zoo file:
    0.645352178..., phase 0.728364114...)."""
    ds = pwsdyn.sweep("impact-oscillator", "omega", [2.5], [-0.5, 0.0], section="impact",
                      transient=150, samples=20, workers=1, progress=False)
    d = ds.sel(direction="up", omega=2.5)
    assert int(d.period) == 1 and float(d.events_per_period) == 1.0
    assert int(d.n_points) == 20
    np.testing.assert_allclose(np.abs(d.section.values[:, 1]), 0.645352178, atol=2e-8)
    np.testing.assert_allclose(d.phase.values, 0.728364114, atol=2e-8)


# ======================================================================================
# Lyapunov spectra
# ======================================================================================

def test_lyapunov_on_period_one_orbit_equals_log_multipliers():
    """Gamma = 1.065 (just below period doubling; real multipliers -0.937, -0.683): the
    spectrum equals log|m_i| / T to 1e-3, with m_i from the closed-form Jacobian above and,
    independently, from central finite differences of the one-period flow map (plain
    simulations, no variational equations)."""
    gamma = 1.065
    x0, m = period_one_orbit(gamma)
    params = {"A": float(ball_A(gamma)), "omega": OMEGA, "e": E}
    T = 2 * np.pi / OMEGA
    expected = np.sort(np.log(np.abs(m)))[::-1] / T
    # finite differences of the flow map P(x) = x(T; x(0) = x)
    h = 1e-6
    J = np.empty((2, 2))
    for c in range(2):
        d = np.zeros(2)
        d[c] = h
        xp = pwsdyn.simulate("bouncing-ball", x0 + d, (0, T), params, dense=False).x_final
        xm = pwsdyn.simulate("bouncing-ball", x0 - d, (0, T), params, dense=False).x_final
        J[:, c] = (xp - xm) / (2 * h)
    fd = np.sort(np.log(np.abs(np.linalg.eigvals(J))))[::-1] / T
    np.testing.assert_allclose(fd, expected, atol=1e-5)
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", x0, params, transient=0, duration=3000)
    assert res.status == 0 and res.events == {"impact": 3000}
    np.testing.assert_allclose(res.exponents, expected, atol=1e-3)


@pytest.mark.parametrize("gamma", [2.5, 4.0])
def test_lyapunov_sum_rule_on_chaotic_attractor(gamma):
    """Chaotic bouncing (a positive exponent): the sum of the exponents equals the mean
    divergence (tr f_x = 0 for free flight) plus the mean log|det S| per unit time. For the
    impact on the moving table, S = g_x + (f+ - g_x f- - g_t) h_x / (h_t + h_x f-) with
    h = y - s(t), g_x = diag(1, -e): det S = e^2 (closed form), so the sum must be
    2 log(e) * (impacts / time)."""
    params = {"A": float(ball_A(gamma)), "omega": OMEGA, "e": E}
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", [1.0, 0.0], params, transient=50,
                                   duration=600)
    assert res.status == 0
    assert set(res.events) == {"impact"}           # no chattering or sticking here
    assert res.exponents[0] > 0.1
    rule = 2 * np.log(E) * res.events["impact"] / res.time
    assert abs(res.sum - rule) < 1e-3, (res.sum, rule)


def test_filippov_stick_slip_sweep_and_spectrum():
    """Stick-slip on a moving belt (Filippov sliding on v = V, autonomous): with the switch as
    event section the cycle alternates sliding start (v = V) and end, which is at
    x = Fs / k = 1 (the spring force reaches static friction; closed form); the spectrum of
    the limit cycle is (0, -inf): 0 along the flow of an autonomous system, -inf because
    sliding entry maps the normal direction to zero (rank-deficient saltation)."""
    if "stick-slip-oscillator" not in pwsdyn.zoo_names():
        pytest.skip("no stick-slip-oscillator in the zoo")
    m = pwsdyn.load_model("stick-slip-oscillator")
    Vs = np.array([0.15, 0.2, 0.3])
    ds = pwsdyn.sweep(m, "V", Vs, [0.0, 0.0], period=2 * np.pi, section="vrel",
                      transient=20, samples=20, workers=1, progress=False)
    d = ds.sel(direction="up")
    assert np.all(d.status.values == 0) and np.all(d.period.values == 2)
    assert np.all(d.slide_time.values > 0)
    for i, V in enumerate(Vs):
        pts = d.section.values[i][: int(d.n_points[i])]
        ends = pts[np.isclose(pts[:, 0], 1.0, atol=1e-6)]
        starts = pts[~np.isclose(pts[:, 0], 1.0, atol=1e-6)]
        assert len(ends) >= 5 and len(starts) >= 5
        np.testing.assert_allclose(ends[:, 0], 1.0, atol=1e-8)      # x = Fs / k
        np.testing.assert_allclose(starts[:, 1], V, atol=1e-8)      # v = V: sticks to belt
    res = pwsdyn.lyapunov_spectrum(m, [0.0, 0.0], segment=2 * np.pi, transient=10,
                                   duration=200)
    assert res.status == 0 and res.events["slide_start"] > 20
    assert abs(res.exponents[0]) < 1e-6 and res.exponents[1] == -np.inf


def _sqrt_cycle2(mu, lam):
    """The period-2 cycle x_R > 0 -> x_L = mu - sqrt(x_R) <= 0 -> mu + lam x_L = x_R:
    with s = sqrt(x_R): s^2 + lam s - mu (1 + lam) = 0."""
    s = (-lam + np.sqrt(lam * lam + 4 * mu * (1 + lam))) / 2
    return s * s, mu - s


def test_sqrt_map_periodic_orbit_exponent_closed_form():
    mu, lam = 0.1, 0.1
    xr_, xl = _sqrt_cycle2(mu, lam)
    assert xl <= 0 < xr_
    # exponent of the 2-cycle: (log lam + log |d/dx (mu - sqrt x)|_{x_R}) / 2
    expected = (np.log(lam) + np.log(1 / (2 * np.sqrt(xr_)))) / 2
    res = pwsdyn.lyapunov_spectrum("sqrt-map", [0.0], {"mu": mu, "lam": lam}, transient=200,
                                   duration=2000)
    assert res.exponents[0] == pytest.approx(expected, abs=1e-9)
    xs, pieces = iterate("sqrt-map", [0.0], 4, params={"mu": mu, "lam": lam}, transient=200)
    np.testing.assert_allclose(np.sort(xs[:2, 0]), [xl, xr_], atol=1e-12)
    assert set(pieces) == {0, 1}


def test_sqrt_map_periodic_for_small_lambda_chaotic_for_large():
    """lam = 0.1: a periodic attractor (negative exponent, period found) at every mu of a
    sweep of (0, 0.05]; lam = 0.8 > 2/3: robust chaos, a positive exponent at every value."""
    mus = np.linspace(0.0005, 0.05, 100)
    common = dict(transient=2000, samples=20000, lyapunov=True, direction="up", workers=1,
                  progress=False)
    small = pwsdyn.sweep("sqrt-map", "mu", mus, [0.0], params={"lam": 0.1}, **common)
    assert np.all(small.lyapunov.values < -0.05)
    assert np.all(small.period.values >= 1)
    large = pwsdyn.sweep("sqrt-map", "mu", mus, [0.0], params={"lam": 0.8}, **common)
    assert np.all(large.lyapunov.values > 0.05), float(large.lyapunov.min())
    assert np.all(large.period.values == 0)


def test_map_model_from_dict_and_errors(tmp_path):
    tent = {"name": "tent", "kind": "map", "states": ["x"], "parameters": {"a": 1.9},
            "pieces": [{"name": "left", "condition": "x <= 0.5", "map": {"x": "a*x"}},
                       {"name": "right", "map": {"x": "a*(1 - x)"}}]}
    m = pwsdyn.load_model(tent)
    assert isinstance(m, MapModel) and m.mode_names == ("left", "right")
    # tent map: exponent log(a) exactly (|F'| = a everywhere)
    res = pwsdyn.lyapunov_spectrum(m, [0.1234], duration=5000)
    assert res.exponents[0] == pytest.approx(np.log(1.9), abs=1e-12)
    with pytest.raises(pwsdyn.ModelError, match="only the last piece"):
        pwsdyn.load_model({**tent, "pieces": [{"name": "a", "map": {"x": "x"}},
                                              {"name": "b", "map": {"x": "x"}}]})
    with pytest.raises(pwsdyn.ModelError, match="exactly one of"):
        pwsdyn.load_model({k: v for k, v in tent.items() if k != "pieces"})
    with pytest.raises(pwsdyn.ModelError, match="unknown"):
        pwsdyn.load_model({**tent, "pieces": [{"name": "a", "map": {"y": "x"}}]})


def test_two_dimensional_map_spectrum_and_basins():
    """A 2-D piecewise-linear map (Lozi): the exponents sum to log|det J| = log b per
    iteration exactly; basins label escaping starts -1."""
    lozi = {"name": "lozi", "kind": "map", "states": ["x", "y"],
            "parameters": {"a": 1.7, "b": 0.5},
            "pieces": [{"name": "pos", "condition": "x >= 0", "map": {"x": "1 - a*x + y",
                                                                      "y": "b*x"}},
                       {"name": "neg", "map": {"x": "1 + a*x + y", "y": "b*x"}}]}
    res = pwsdyn.lyapunov_spectrum(lozi, [0.1, 0.1], transient=100, duration=20000)
    assert res.exponents[0] > 0.3
    assert res.sum == pytest.approx(np.log(0.5), abs=1e-10)
    ds = pwsdyn.basins(lozi, {"x": np.linspace(-3, 3, 7), "y": np.linspace(-3, 3, 5)},
                       transient=50, samples=16, bound=1e6, workers=1, progress=False)
    assert ds.fraction.sum() == pytest.approx(1.0, abs=1e-14)
    assert int(ds.label.sel(x=0.0, y=0.0)) >= 0            # on the chaotic attractor
    assert int(ds.label.sel(x=-3.0, y=-3.0)) == -1          # escapes


# ======================================================================================
# Basins
# ======================================================================================

def test_ball_basins_classify_coexisting_bouncing_and_sticking():
    """Gamma = 0.9: the period-1 bouncing orbit and sticking to the table coexist (zoo file:
    dropped from 1.5 m the ball bounces, from 1 m it sticks)."""
    params = {"A": float(ball_A(0.9)), "omega": OMEGA, "e": E}
    ys, vs = np.linspace(0.25, 2.0, 8), np.linspace(-3.0, 3.0, 7)
    ds = pwsdyn.basins("bouncing-ball", {"y": ys, "v": vs}, params=params, transient=100,
                       samples=16, workers=1, progress=False)
    lab = ds.label
    assert lab.shape == (8, 7)
    fr = ds.fraction.values
    assert np.all((fr >= 0) & (fr <= 1)) and fr.sum() == pytest.approx(1.0, abs=1e-14)
    assert set(basin_fractions(ds)) <= set(ds.basin.values.tolist())
    bounce = int(lab.sel(y=1.5, v=0.0))
    stick = int(lab.sel(y=1.0, v=0.0))
    assert bounce != stick and bounce >= 0 and stick >= 0
    a = ds.sel(attractor=bounce)
    assert int(a.attractor_period) == 1 and float(a.attractor_events_per_period) == 1.0
    x_exact, _ = period_one_orbit(0.9)
    np.testing.assert_allclose(a.attractor_points.values[0], x_exact, atol=1e-6)
    s = ds.sel(attractor=stick)
    assert float(s.attractor_stick_time) == pytest.approx(1.0, abs=1e-9)
    assert float(s.attractor_events_per_period) == 0.0


def test_map_basins_one_dimensional_grid():
    ds = pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.5, 0.5, 21)},
                       params={"mu": 0.1, "lam": 0.1}, workers=1, progress=False)
    assert set(np.unique(ds.label.values)) == {0}
    assert int(ds.attractor_period[0]) == 2
    xr_, xl = _sqrt_cycle2(0.1, 0.1)
    np.testing.assert_allclose(np.sort(ds.attractor_points.values[0, :, 0]), [xl, xr_],
                               atol=1e-9)
    assert basin_fractions(ds) == {0: 1.0}


# ======================================================================================
# Execution: workers, chunks, stores
# ======================================================================================

BALL_SWEEP = dict(params={"omega": OMEGA, "e": E}, transient=100, samples=24, chunk_size=4,
                  direction="both")


@pytest.mark.slow   # ~20-30 s (the sweeps' stitching and scans test the same in the default run)
def test_serial_and_parallel_give_identical_datasets(tmp_path):
    """Same chunking, 1 worker (in-process) vs 2 threads (the default, ``workers=2``) vs a
    LocalCluster of 2 worker processes (``scheduler="processes"``, or the user's, reached by
    ``client=`` or a scheduler address): the datasets are identical, sweeps and basins
    alike."""
    vals = ball_A(np.linspace(0.9, 1.2, 20))
    a = pwsdyn.sweep("bouncing-ball", "A", vals, [1.5, 0.0], workers=1, progress=False,
                     **BALL_SWEEP)
    b = pwsdyn.sweep("bouncing-ball", "A", vals, [1.5, 0.0], workers=2, progress=False,
                     out=tmp_path / "b.nc", **BALL_SWEEP)
    xr.testing.assert_identical(a, b)
    d = pwsdyn.sweep("bouncing-ball", "A", vals, [1.5, 0.0], workers=2, progress=False,
                     scheduler="processes", **BALL_SWEEP)
    xr.testing.assert_identical(a, d)
    with xr.open_dataset(tmp_path / "b.nc", engine="h5netcdf") as f:
        flags = ["chunk_start", "chunk_rerun"]
        xr.testing.assert_equal(a.drop_vars(flags), f.load().drop_vars(flags))
    assert a.attrs["model_hash"] == pwsdyn.load_model("bouncing-ball").hash
    assert json.loads(a.attrs["settings"])["chunk_size"] == 4
    # a cluster the user already has: by scheduler address (basins) and as a client (sweep)
    from dask.distributed import Client, LocalCluster

    grid = {"y": np.linspace(0.2, 2.0, 6), "v": np.linspace(-3, 3, 4)}
    params = {"A": float(ball_A(0.9)), "omega": OMEGA, "e": E}
    kw = dict(params=params, transient=60, samples=16, chunk_size=2, progress=False)
    serial = pwsdyn.basins("bouncing-ball", grid, workers=1, **kw)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster:
        par = pwsdyn.basins("bouncing-ball", grid, scheduler=cluster.scheduler_address, **kw)
        with Client(cluster) as client:
            c = pwsdyn.sweep("bouncing-ball", "A", vals, [1.5, 0.0], client=client,
                             progress=False, **BALL_SWEEP)
            assert len(client.scheduler_info()["workers"]) == 2
            # each worker process built the model (and loaded its compiled code from the
            # disk cache) once, and reused it for all its chunks: one context per model
            counts = client.run(_contexts_on_worker)
            assert sorted(counts.values()) == [1, 1], counts
    xr.testing.assert_identical(serial, par)
    xr.testing.assert_identical(a, c)


def _contexts_on_worker():
    from pwsdyn.integrate import compiled as _context

    return len(_context._CONTEXTS)


_KILL_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import pwsdyn

    def main():
        pwsdyn.sweep("impact-oscillator", "omega", np.linspace(2.3, 3.1, {n}), [-0.5, 0.0],
                     transient={tr}, samples=50, chunk_size=2, warmup=1, direction="up",
                     workers=1, progress=False, store=sys.argv[1])

    if __name__ == "__main__":
        main()
""")


def test_killed_run_resumes_to_identical_dataset(tmp_path):
    """A sweep really killed (SIGKILL) midway and resumed from its store gives the dataset of
    an uninterrupted run; the chunks stored before the kill are not recomputed."""
    n, tr = 48, 400
    script = tmp_path / "run.py"
    script.write_text(_KILL_SCRIPT.format(n=n, tr=tr))
    store = tmp_path / "store"
    proc = subprocess.Popen([sys.executable, str(script), str(store)])
    deadline = time.time() + 120
    try:
        while time.time() < deadline and proc.poll() is None:
            if len(list(store.glob("chunk-*.nc"))) >= 3:
                proc.send_signal(signal.SIGKILL)
                break
            time.sleep(0.005)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    done = sorted(store.glob("chunk-*.nc"))
    assert 3 <= len(done) < n // 2, len(done)           # guesses only (slots 0 .. n/2 - 1)
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    kw = dict(transient=tr, samples=50, chunk_size=2, warmup=1, direction="up", workers=1,
              progress=False)
    values = np.linspace(2.3, 3.1, n)
    resumed = pwsdyn.sweep("impact-oscillator", "omega", values, [-0.5, 0.0], store=store,
                           **kw)
    assert {p.name: p.stat().st_mtime_ns for p in done} == stamps   # not rewritten
    # every guess, and each chunk rerun by the stitching in its own slot
    assert len(list(store.glob("chunk-*.nc"))) == n // 2 + resumed.attrs["stitch_reruns"]
    assert not list(store.glob("*.tmp*"))
    full = pwsdyn.sweep("impact-oscillator", "omega", values, [-0.5, 0.0], **kw)
    xr.testing.assert_identical(resumed, full)


def test_chunk_borders_warmup_and_one_chunk():
    """With one chunk the state is carried through every value; with several chunks each
    starts from x0 after its warm-up. On a single attractor both agree; the chunk starts are
    recorded."""
    vals = np.linspace(0.01, 0.05, 9)
    one = pwsdyn.sweep("sqrt-map", "mu", vals, [0.0], params={"lam": 0.1}, chunk_size=9,
                       workers=1, progress=False, transient=500, samples=40, direction="up")
    many = pwsdyn.sweep("sqrt-map", "mu", vals, [0.0], params={"lam": 0.1}, chunk_size=2,
                        workers=1, progress=False, transient=500, samples=40, direction="up")
    np.testing.assert_allclose(one.section.values, many.section.values, atol=1e-12)
    assert one.chunk_start.values.sum() == 1 and many.chunk_start.values.sum() == 5


def test_coexisting_attractors_do_not_show_at_chunk_borders():
    """The ball at 0.98 <= Gamma <= 1.05 has a period-1 orbit (continued from Gamma = 0.9)
    and a period-3 one (reached from the drop at 1.5 m). One chunk follows period 1 all the
    way. With chunks of 4 values each chunk's guess restarts from x0 after its warm-up and
    may land on period 3; the stitching sees that the first window of such a chunk is not
    on the attractor the previous chunk hands on and reruns it: the sweep follows period 1
    throughout, as the single chunk does, and records the chunks rerun."""
    gam = np.linspace(0.9, 1.05, 16)
    kw = dict(params={"omega": OMEGA, "e": E}, transient=300, samples=32, direction="up",
              workers=1, progress=False)
    one = pwsdyn.sweep("bouncing-ball", "A", ball_A(gam), [1.5, 0.0], chunk_size=16, **kw)
    assert np.all(one.period.values == 1)
    many = pwsdyn.sweep("bouncing-ball", "A", ball_A(gam), [1.5, 0.0], chunk_size=4, **kw)
    np.testing.assert_array_equal(many.period.values, one.period.values)
    np.testing.assert_allclose(many.section.values, one.section.values, atol=1e-6)
    rerun = many.chunk_rerun.values[0]
    starts = many.chunk_start.values[0]
    assert many.attrs["stitch_borders"] == 3
    assert 1 <= many.attrs["stitch_reruns"] == int(np.sum(rerun & starts))
    assert not rerun[0]                         # the first chunk starts at x0: exact


# ======================================================================================
# bad input
# ======================================================================================

def test_bad_input_gives_clear_errors_and_writes_nothing(tmp_path):
    ball = "bouncing-ball"
    with pytest.raises(ValueError, match="non-empty"):
        pwsdyn.sweep(ball, "A", [], [1.0, 0.0], workers=1, progress=False)
    with pytest.raises(ValueError, match="unknown parameter 'Z'"):
        pwsdyn.sweep(ball, "Z", [0.1, 0.2], [1.0, 0.0], workers=1, progress=False)
    with pytest.raises(ValueError, match="direction"):
        pwsdyn.sweep(ball, "A", [0.1], [1.0, 0.0], direction="sideways", progress=False)
    with pytest.raises(ValueError, match="section"):
        pwsdyn.sweep(ball, "A", [0.1], [1.0, 0.0], section="nosuch", progress=False)
    with pytest.raises(ValueError, match="zero size"):
        pwsdyn.basins(ball, {"y": [], "v": [0.0]}, workers=1, progress=False)
    with pytest.raises(ValueError, match="unknown state"):
        pwsdyn.basins(ball, {"q": [1.0], "v": [0.0]}, workers=1, progress=False)
    # a store of another run: refused, naming why; nothing overwritten
    store = tmp_path / "st"
    kw = dict(params={"omega": OMEGA}, transient=5, samples=8, workers=1, progress=False)
    pwsdyn.sweep(ball, "A", [0.1, 0.2], [1.0, 0.0], store=store, **kw)
    before = {p.name: p.read_bytes() for p in store.iterdir()}
    with pytest.raises(StoreMismatchError, match="setting `samples`: stored 8, requested 9"):
        pwsdyn.sweep(ball, "A", [0.1, 0.2], [1.0, 0.0], store=store, **{**kw, "samples": 9})
    with pytest.raises(StoreMismatchError, match="model: stored"):
        pwsdyn.sweep("impact-oscillator", "omega", [2.5, 2.6], [0.0, 0.0], store=store,
                     transient=5, samples=8, workers=1, progress=False)
    with pytest.raises(StoreMismatchError, match="analysis"):
        pwsdyn.basins(ball, {"y": [1.0], "v": [0.0]}, store=store, **kw)
    assert {p.name: p.read_bytes() for p in store.iterdir()} == before
    # an existing output file is never overwritten
    out = tmp_path / "d.nc"
    out.write_bytes(b"keep")
    with pytest.raises(FileExistsError, match="nothing was overwritten"):
        pwsdyn.sweep(ball, "A", [0.1], [1.0, 0.0], out=out, **kw)
    assert out.read_bytes() == b"keep"
    other = tmp_path / "junk"
    other.mkdir()
    (other / "x.txt").write_text("x")
    with pytest.raises(StoreMismatchError, match="not a pwsdyn store"):
        pwsdyn.sweep(ball, "A", [0.1], [1.0, 0.0], store=other, **kw)


# ======================================================================================
# CLI and figures
# ======================================================================================

def _cli(args):
    from click.testing import CliRunner

    from pwsdyn.cli import main

    return CliRunner().invoke(main, args, catch_exceptions=False)


def _png(path: Path):
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 5000


def test_cli_sweep_and_basins_write_data_and_figures(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _cli(["sweep", "sqrt-map", "--param", "mu", "--from", "0.005", "--to", "0.05",
                "--num", "20", "--set", "lam=0.8", "--lyapunov", "--transient", "500",
                "--samples", "2000", "--workers", "1", "--no-progress",
                "--out", "d.nc", "--plot", "d.png"])
    assert res.exit_code == 0, res.output
    _png(tmp_path / "d.png")
    _png(tmp_path / "d-lyapunov.png")
    assert not (tmp_path / "d.nc.store").exists()          # the default store is removed
    with xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf") as ds:
        assert bool((ds.lyapunov > 0).all())
        assert ds.attrs["model"] == "sqrt-map" and ds.attrs["parameter"] == "mu"
    res = _cli(["sweep", "sqrt-map", "--param", "mu", "--from", "0.005", "--to", "0.05",
                "--num", "20", "--workers", "1", "--out", "d.nc"])
    assert res.exit_code == 1 and "nothing was overwritten" in res.output
    res = _cli(["basins", "bouncing-ball", "--x", "y", "--x-from", "0.2", "--x-to", "2",
                "--x-num", "6", "--y", "v", "--y-from", "-3", "--y-to", "3", "--y-num", "5",
                "--set", f"A={float(ball_A(0.9))}", "--set", f"omega={OMEGA}",
                "--transient", "60", "--samples", "16", "--workers", "1", "--no-progress",
                "--out", "b.nc", "--plot", "b.png"])
    assert res.exit_code == 0, res.output
    assert "period 1" in res.output
    _png(tmp_path / "b.png")


@pytest.mark.parametrize("lyapunov, samples", [(False, 100), (True, 300)])
def test_sweep_window_defaults_are_the_same_in_the_api_and_the_cli(lyapunov, samples, tmp_path,
                                                                   monkeypatch):
    """The recording window defaults to 100 periods, 300 with Lyapunov exponents (over 100
    the finite-time exponents scatter visibly between neighbouring values); one default in
    pwsdyn.sweep, which the CLI does not override."""
    monkeypatch.chdir(tmp_path)
    values = np.linspace(0.005, 0.05, 3)
    ds = pwsdyn.sweep("sqrt-map", "mu", values, [0.0], params={"lam": 0.8},
                      lyapunov=lyapunov, workers=1, progress=False)
    assert json.loads(ds.attrs["settings"])["samples"] == samples
    res = _cli(["sweep", "sqrt-map", "--param", "mu", "--from", "0.005", "--to", "0.05",
                "--num", "3", "--set", "lam=0.8", "--workers", "1", "--no-progress",
                "--out", "d.nc"] + (["--lyapunov"] if lyapunov else []))
    assert res.exit_code == 0, res.output
    with xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf") as cli:
        assert json.loads(cli.attrs["settings"])["samples"] == samples
    assert pwsdyn.explore._sweep.LYAPUNOV_SAMPLES == 300


@pytest.mark.parametrize("args, words", [
    (["--param", "nosuch"], ["--param", "nosuch"]),
    (["--param", "A", "--set", "zz=1"], ["--set", "zz"]),
    (["--param", "A", "--num", "0"], ["--num"]),
])
def test_cli_sweep_bad_arguments(args, words):
    base = ["sweep", "bouncing-ball", "--from", "0.1", "--to", "0.2"]
    if "--num" not in args:
        base += ["--num", "3"]
    res = _cli(base + args)
    assert res.exit_code == 2
    for w in words:
        assert w in res.output


def test_plots_of_sweep_basins_and_lyapunov(tmp_path):
    from pwsdyn.plot import plot_basins, plot_bifurcation, plot_lyapunov

    ds = pwsdyn.sweep("sqrt-map", "mu", np.linspace(0.005, 0.05, 12), [0.0],
                      params={"lam": 0.1}, lyapunov=True, direction="both", workers=1,
                      progress=False)
    fig = plot_bifurcation(ds, path=tmp_path / "bif.png")
    assert len(fig.axes) == 2 and len(fig.axes[0].lines) == 2   # up and down
    _png(tmp_path / "bif.png")
    plot_lyapunov(ds, path=tmp_path / "ly.png")
    _png(tmp_path / "ly.png")
    with pytest.raises(ValueError, match="unknown state"):
        plot_bifurcation(ds, state="q")
    b = pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.5, 0.5, 11)},
                      params={"mu": 0.1, "lam": 0.1}, workers=1, progress=False)
    plot_basins(b, path=tmp_path / "b.png")
    _png(tmp_path / "b.png")


@pytest.mark.slow
def test_readme_sweep_command(tmp_path, monkeypatch):
    """The README's main job: a sweep of the built-in impact oscillator (both directions,
    default transient and samples, local cluster with one worker per core)."""
    monkeypatch.chdir(tmp_path)
    res = _cli(["sweep", "impact-oscillator", "--param", "omega", "--from", "2.4", "--to",
                "3.4", "--num", "1000", "--no-progress", "--out", "diagram.nc",
                "--plot", "diagram.png"])
    assert res.exit_code == 0, res.output
    _png(tmp_path / "diagram.png")
    with xr.open_dataset(tmp_path / "diagram.nc", engine="h5netcdf") as ds:
        assert ds.sizes["omega"] == 1000 and list(ds.direction.values) == ["up", "down"]
        assert int((ds.status != 0).sum()) == 0
        # omega = 2.5 lies on the stable period-1 branch (zoo file): period 1, one impact
        d = ds.sel(omega=2.5, method="nearest")
        assert bool((d.period == 1).all()) and bool((d.events_per_period == 1).all())


def test_lyapunov_of_a_ball_stuck_on_its_table_is_superstable():
    # With table acceleration A w^2 < g the ball, once stuck, never releases: any perturbation
    # (a small hop) ends by sticking again in finite time, so both exponents are -inf. A
    # restart of each segment in free flight re-registered the contact with a chattering
    # saltation every segment and reported a spurious positive exponent.
    w = 2 * np.pi
    lyap = pwsdyn.lyapunov_spectrum("bouncing-ball", {"y": 0.5, "v": 0.0},
                                    params={"A": 0.2, "omega": w}, duration=50, transient=20)
    assert 0.2 * w * w < 9.81
    assert np.all(np.isneginf(lyap.exponents))
    assert lyap.events.get("chatter", 0) <= 1   # not one per segment


def test_lyapunov_sweep_of_a_ball_stuck_after_the_transient():
    # A w^2 < g: the transient ends with the ball stuck on its table, so every value's window
    # starts sticking (a contact episode from its start). That start used to raise
    # AttributeError; both exponents are -inf as for lyapunov_spectrum above.
    w = 2 * np.pi
    ds = pwsdyn.sweep("bouncing-ball", "A", [0.05, 0.06], {"y": 0.5, "v": 0.0},
                      params={"omega": w}, lyapunov=True, transient=20, samples=5, workers=1,
                      progress=False)
    assert 0.06 * w * w < 9.81
    assert int((ds.status != 0).sum()) == 0
    assert np.all(np.isneginf(ds.lyapunov.values))


def test_state_times_from_event_columns():
    """Sticking and sliding time in a window from the log's columns, by hand: stuck from 1
    to 2 (a chatter record followed by stick), sliding from 3 to 4.5, then stuck to the end;
    window [1.5, 6]."""
    from pwsdyn.explore._common import state_times

    t = np.array([0.5, 1.0, 1.0, 2.0, 3.0, 4.5, 5.0])
    after = np.array([0, 0, 1, 0, 2, 0, 1])
    chatter = np.array([False, True, False, False, False, False, False])
    stick, slide = state_times(t, after, chatter, 1.5, 6.0, initial=0)
    assert stick == pytest.approx(0.5 + 1.0) and slide == pytest.approx(1.5)
    assert state_times(t[:0], after[:0], chatter[:0], 0.0, 2.0, initial=1) == (2.0, 0.0)


def _period_by_loop(points, max_period, tol):
    """The period rule of ``period_estimate`` written as its definition, point by point: the
    record up to its first non-finite row; the smallest shift k with at least k pairs
    (j, j + k) in the second half, all within the tolerance in every component."""
    rows = []
    for row in np.asarray(points, dtype=float):
        if not all(math.isfinite(v) for v in row):
            break
        rows.append(row)
    if len(rows) < 2:
        return 0
    scale = tol * (1.0 + max(abs(v) for row in rows for v in row))
    half = len(rows) // 2
    for k in range(1, max_period + 1):
        pairs = [(rows[j], rows[j + k]) for j in range(half, len(rows) - k)]
        if len(pairs) < k:
            break
        if all(abs(a - b) <= scale for ra, rb in pairs for a, b in zip(ra, rb)):
            return k
    return 0


@settings(max_examples=300, deadline=None, derandomize=True)
@given(period=st.integers(1, 9), m=st.integers(0, 60), d=st.integers(1, 3),
       noise=st.sampled_from([0.0, 1e-9, 5e-7, 2e-6, 1e-3]), nan_tail=st.integers(0, 5),
       max_period=st.integers(1, 30), seed=st.integers(0, 2**31 - 1))
def test_period_estimate_is_the_shift_rule(period, m, d, noise, nan_tail, max_period, seed):
    """``period_estimate`` (all shifts compared in one array) against the rule written as a
    loop over the shifts, on cycles of period 1-9 with noise below, near and above the
    tolerance (1e-6 of the record's scale), records of any length with NaN rows at the end."""
    from pwsdyn.explore._common import period_estimate

    rng = np.random.default_rng(seed)
    cycle = rng.uniform(-2.0, 2.0, size=(period, d))
    pts = cycle[np.arange(m) % period] + noise * rng.standard_normal((m, d))
    pts = np.vstack([pts, np.full((nan_tail, d), np.nan)])
    assert period_estimate(pts, max_period, 1e-6) == _period_by_loop(pts, max_period, 1e-6)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(kinds=st.lists(st.integers(-1, 2), max_size=12), initial=st.integers(0, 2),
       seed=st.integers(0, 2**31 - 1))
def test_state_times_without_sticking_or_sliding_are_zero_and_otherwise_unchanged(
        kinds, initial, seed):
    """``state_times`` (with its shortcut for runs that never stick nor slide) against the
    rule written out interval by interval: each interval between events is in the state
    after the last non-chatter record before it, ``initial`` before the first."""
    from pwsdyn.explore._common import state_times

    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 10.0, len(kinds)))
    after = np.array(kinds, dtype=int)
    chatter = rng.uniform(size=len(kinds)) < 0.2
    lo, hi = 2.0, 8.0
    want = [0.0, 0.0]
    state = initial
    edges = [lo] + list(np.clip(t, lo, hi)) + [hi]
    for i in range(len(edges) - 1):
        if i > 0 and not chatter[i - 1]:
            state = after[i - 1]
        if state in (1, 2):
            want[state - 1] += edges[i + 1] - edges[i]
    got = state_times(t, after, chatter, lo, hi, initial)
    assert got == pytest.approx(tuple(want), abs=1e-12)
    if initial == 0 and not np.any(after > 0):
        assert got == (0.0, 0.0)


@pytest.mark.parametrize("x, bound, ok", [
    ([0.0, 1.0], 1.0, True), ([0.0, -1.0 - 1e-12], 1.0, False), ([np.nan, 0.0], 1e8, False),
    ([np.inf, 0.0], np.inf, False), ([-np.inf], 1e8, False), ([1e300, -1e300], np.inf, True),
    ([], 1.0, True)])
def test_check_bound(x, bound, ok):
    """A state is within the bound while every component is finite and at most ``bound`` in
    magnitude (an infinite bound still refuses an infinite component)."""
    from pwsdyn.explore._common import check_bound

    assert check_bound(np.array(x, dtype=float), bound) is ok
