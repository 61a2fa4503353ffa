"""Grazing impacts and short release windows are found inside one step, on every path.

A crossing and re-crossing of a surface inside one step (a graze) and a constraint force that
pulls only for a short time while sticking (a release window) hide at an extremum of the
watched function between the samples. The kernel searches such an extremum on the dense
output (the exact flow on an exact step) with a bound on it, instead of one sample at the
extremum of a Hermite fit, so a graze deeper than the position tolerance is found whatever
the step.

References are closed forms, none computed by pwsdyn:

* ``x'' = -x`` against a wall at ``W = 1 - delta``: the impact at the first time
  ``a sin(t + phi) = W`` (mpmath, 40 digits, from the rounded inputs); a wall at ``1 + delta``
  is never reached;
* the built-in impact oscillator (``x'' + x = sin(omega t)``, ``eps = 0``): the closed-form
  free motion, its first maximum and the crossing of a stop ``delta`` below it (brentq);
* the bouncing ball on a table ``s(t) = A sin(omega t)``: a parabola made tangent to the table
  and lowered by ``depth`` (raised, for the near miss); the impact is the first root of
  parabola minus table (brentq on a fine grid);
* release from a table with ``A omega^2 = g (1 + eta)``: at ``sin(omega t) = 1 / (1 + eta)``
  on the rising side, in every forcing period.
"""

import math

import mpmath
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

import pwsdyn
from pwsdyn.integrate.simulate import DEFAULTS

G = 9.81
EPS = np.finfo(float).eps
#: position tolerance of the default run on states of size ~1
TOL_X = DEFAULTS["atol"] + DEFAULTS["rtol"]
# each integration path on its own: the Runge-Kutta pairs with exact=False (the default
# "auto" would propagate these affine models exactly), and the exact flow
PATHS = {"RK45": dict(method="RK45", exact=False), "DOP853": dict(method="DOP853", exact=False),
         "exact": dict(exact=True)}

HARMONIC = {"name": "harmonic-wall", "states": ["x", "v"], "parameters": {"W": 1.0, "e": 0.5},
            "modes": {"free": {"x": "v", "v": "-x"}},
            "events": [{"name": "wall", "kind": "impact", "surface": "W - x", "direction": -1,
                        "reset": {"v": "-e*v"}}]}


@pytest.fixture(scope="module")
def harmonic():
    return pwsdyn.load_model(HARMONIC)


def _impacts(traj):
    ev = traj.events
    return ev.t[np.asarray(ev.kind) == "impact"]


def _harmonic_reference(x0, v0, wall):
    with mpmath.workdps(40):
        a = mpmath.sqrt(mpmath.mpf(x0) ** 2 + mpmath.mpf(v0) ** 2)
        return float(mpmath.asin(mpmath.mpf(wall) / a) - mpmath.atan2(x0, v0))


_DEPTH = st.floats(math.log10(100 * TOL_X), -3.0).map(lambda k: 10.0 ** k)
_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------------------
# a fixed wall: x'' = -x against 1 - delta
# --------------------------------------------------------------------------------------

@_SETTINGS
@given(delta=_DEPTH, phi=st.floats(0.0, 1.0), path=st.sampled_from(sorted(PATHS)))
def test_graze_of_a_fixed_wall_is_found_at_the_closed_form_time(harmonic, delta, phi, path):
    x0, v0 = math.sin(phi), math.cos(phi)
    wall = 1.0 - delta
    traj = pwsdyn.simulate(harmonic, [x0, v0], (0.0, 3.0), params={"W": wall}, dense=False,
                           **PATHS[path])
    t = _impacts(traj)
    assert len(t) >= 1, f"graze of depth {delta:.3g} missed ({path}, phase {phi})"
    t_ref = _harmonic_reference(x0, v0, wall)
    # The impact time is as good as the position at the wall over the approach speed
    # sqrt(2 delta): within the position tolerance on the Runge-Kutta paths (observed up to
    # 0.2 of it with RK45), to rounding on the exact flow (observed ~1.5 eps)
    speed = math.sqrt(2.0 * delta)
    tol = TOL_X / speed if path != "exact" else 1e-4 * TOL_X / speed
    assert abs(t[0] - t_ref) <= tol, (path, delta, phi, t[0] - t_ref)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(delta=_DEPTH, phi=st.floats(0.0, 1.0), path=st.sampled_from(sorted(PATHS)))
def test_near_miss_of_a_fixed_wall_logs_nothing(harmonic, delta, phi, path):
    traj = pwsdyn.simulate(harmonic, [math.sin(phi), math.cos(phi)], (0.0, 7.0),
                           params={"W": 1.0 + delta}, dense=False, **PATHS[path])
    assert len(traj.events) == 0


@pytest.mark.parametrize("path", sorted(PATHS))
def test_graze_of_the_impact_oscillator(path):
    """The built-in impact oscillator (eps = 0, omega = 2.5) from (-0.5, 0): a stop delta
    below the first maximum of the free motion, impact speed 1.9e-3 (delta = 1e-6) down to
    1.9e-4 (delta = 1e-8); the exact path used to miss delta <= 1e-6."""
    w = 2.5
    c = 1.0 / (1.0 - w * w)
    x0, v0 = -0.5, 0.0
    b = v0 - w * c

    def x(t):
        return x0 * math.cos(t) + b * math.sin(t) + c * math.sin(w * t)

    def v(t):
        return -x0 * math.sin(t) + b * math.cos(t) + c * w * math.cos(w * t)

    grid = np.linspace(0.0, 5.0, 5001)
    k = next(i for i in range(1, len(grid)) if v(grid[i - 1]) > 0.0 >= v(grid[i]))
    t_max = brentq(v, grid[k - 1], grid[k], xtol=1e-15)
    for delta in (1e-6, 1e-7, 1e-8):
        sigma = x(t_max) - delta
        t_ref = brentq(lambda t: x(t) - sigma, t_max - 0.5, t_max, xtol=1e-15)
        traj = pwsdyn.simulate("impact-oscillator", [x0, v0], (0.0, t_max + 1.0),
                               params={"omega": w, "sigma": sigma}, **PATHS[path])
        t = _impacts(traj)
        assert len(t) == 1, (path, delta)
        tol = TOL_X / v(t_ref) if path != "exact" else 1e-4 * TOL_X / v(t_ref)
        assert abs(t[0] - t_ref) <= tol, (path, delta, t[0] - t_ref)


# --------------------------------------------------------------------------------------
# a moving surface: the bouncing ball on a vibrating table
# --------------------------------------------------------------------------------------

def _ball_graze(depth, phase, miss, omega=2 * math.pi):
    """Ball tangent to the table s = A sin(omega t) at omega t* = pi/2 + phase, lowered by
    ``depth`` (raised, for ``miss``); A omega^2 = 2 g, so parabola minus table is convex
    near t* (its second derivative g (2 sin(omega t*) - 1) >= 0.75 g). Returns x0, t_span,
    params, the first root of parabola minus table (None: none) and the speed there."""
    A = 2.0 * G / omega ** 2
    ts = (math.pi / 2 + phase) / omega
    s = A * math.sin(omega * ts)
    sd = A * omega * math.cos(omega * ts)
    ys = s + (depth if miss else -depth)
    t0 = ts - 0.15 * 2 * math.pi / omega
    t1 = ts + 0.1 * 2 * math.pi / omega
    y0 = ys - sd * (ts - t0) - 0.5 * G * (ts - t0) ** 2
    v0 = sd + G * (ts - t0)

    def gap(t):
        return y0 + v0 * (t - t0) - 0.5 * G * (t - t0) ** 2 - A * math.sin(omega * t)

    def gap_rate(t):
        return v0 - G * (t - t0) - A * omega * math.cos(omega * t)

    grid = np.linspace(t0, t1, 4001)
    vals = np.array([gap(t) for t in grid])
    assert vals[0] > 0.0
    below = np.nonzero(vals <= 0.0)[0]
    if len(below) == 0 and gap(ts) <= 0.0:
        below = [np.searchsorted(grid, ts)]
        grid = np.insert(grid, below[0], ts)
    t_ref = None
    if len(below):
        k = below[0]
        t_ref = brentq(gap, grid[k - 1], grid[k], xtol=1e-16, rtol=4 * EPS)
    return ([y0, v0], (t0, t1), {"A": A, "omega": omega, "e": 0.5}, t_ref,
            abs(gap_rate(t_ref)) if t_ref is not None else None)


@_SETTINGS
@given(depth=_DEPTH, phase=st.floats(-0.5, 0.5), path=st.sampled_from(sorted(PATHS)))
def test_graze_of_a_vibrating_table_is_found_at_the_closed_form_time(depth, phase, path):
    x0, span, params, t_ref, speed = _ball_graze(depth, phase, miss=False)
    assert t_ref is not None
    traj = pwsdyn.simulate("bouncing-ball", x0, span, params=params, dense=False,
                           **PATHS[path])
    t = _impacts(traj)
    assert len(t) >= 1, f"graze of depth {depth:.3g} missed ({path}, phase {phase})"
    # flights are parabolas, which both Runge-Kutta pairs integrate exactly: the error is
    # rounding in the location (observed < 3 eps over the approach speed)
    assert abs(t[0] - t_ref) <= 1e-3 * TOL_X / speed, (path, depth, phase, t[0] - t_ref)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(depth=_DEPTH, phase=st.floats(-0.5, 0.5), path=st.sampled_from(sorted(PATHS)))
def test_near_miss_of_a_vibrating_table_logs_nothing(depth, phase, path):
    x0, span, params, t_ref, _ = _ball_graze(depth, phase, miss=True)
    assert t_ref is None
    traj = pwsdyn.simulate("bouncing-ball", x0, span, params=params, dense=False,
                           **PATHS[path])
    assert len(traj.events) == 0


# --------------------------------------------------------------------------------------
# short release windows while sticking on the table
# --------------------------------------------------------------------------------------

@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(eta=st.floats(-6.0, -1.0).map(lambda k: 10.0 ** k),
       omega=st.floats(math.log(2.0), math.log(100.0)).map(math.exp),
       path=st.sampled_from(["RK45", "DOP853"]))
def test_release_in_every_short_window(eta, omega, path):
    """A ball dropped from 1e-6 above a table with A omega^2 = g (1 + eta) sticks to it at
    once (chattering), then is released in every forcing period where the table's
    acceleration -A omega^2 sin(omega t) falls below -g: at sin(omega t_r) = 1 / (1 + eta),
    sin rising. The window lasts ~2 sqrt(2 eta) / omega: down to 1e-5 of a period."""
    A = G * (1.0 + eta) / omega ** 2
    T = 2 * math.pi / omega
    n_periods = 8
    traj = pwsdyn.simulate("bouncing-ball", [1e-6, A * omega], (0.0, n_periods * T),
                           params={"A": A, "omega": omega, "e": 0.3}, dense=False,
                           **PATHS[path])
    releases = traj.events_of("release")
    sticks = traj.events_of("stick")
    assert len(sticks) >= 1 and sticks[0].t < 0.2 * T
    phase = math.asin(1.0 / (1.0 + eta))
    expected = [(phase + 2 * math.pi * k) / omega for k in range(n_periods)]
    assert len(releases) == n_periods, (eta, omega, [r.t for r in releases])
    for rel, t_r in zip(releases, expected):
        # the free normal acceleration depends on t only here: located to rounding
        assert rel.t == pytest.approx(t_r, abs=1e-9 * T)
        # released from sticking, moving with the table
        assert rel.mode_before == "stick:impact"
        assert rel.x_before[1] == pytest.approx(A * omega * math.cos(omega * rel.t), abs=1e-8)


@pytest.mark.parametrize("eta", [1e-8, 1e-4])
def test_no_release_while_the_table_never_pulls(eta):
    """A omega^2 = g (1 - eta): the contact force never changes sign, the ball stays."""
    omega = 25.0
    A = G * (1.0 - eta) / omega ** 2
    traj = pwsdyn.simulate("bouncing-ball", [1e-6, A * omega], (0.0, 8 * 2 * math.pi / omega),
                           params={"A": A, "omega": omega, "e": 0.3}, dense=False)
    assert [e.kind for e in traj.events][-1] == "stick"
    assert len(traj.events_of("release")) == 0
