"""Restarts on a unilateral constraint (events issue, item 4): a run restarted from a state
on an impact constraint starts sticking, with an impact at the start, or in free motion, and
never passes through the wall. Each check is against a closed form of the bouncing ball
(``y'' = -g``, impact at ``y = s(t) = A sin(omega t)`` with ``v -> sdot - e (v - sdot)``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import pwsdyn
from _closed_forms import release_time
from pwsdyn.errors import ArgumentError
from pwsdyn.integrate._start import BAND_ULPS, round_off_band

G = 9.81
EPS = np.finfo(float).eps
BALL = "bouncing-ball"
_HYP = dict(deadline=None, database=None, derandomize=True,
            suppress_health_check=[HealthCheck.too_slow])


def still(e=0.8):
    return {"A": 0.0, "e": e}


def assert_at_rest(traj, tol=1e-12):
    """The closed form of a ball resting on a still table: y = 0, v = 0 throughout."""
    assert traj.success
    assert np.all(traj.x[:, 0] >= -tol), traj.x[:, 0].min()
    np.testing.assert_allclose(traj.x[:, 0], 0.0, atol=tol)
    np.testing.assert_allclose(traj.x[:, 1], 0.0, atol=tol)
    assert set(traj.state) == {"stick:impact"}
    assert not [e for e in traj.events if e.kind in ("impact", "release")]


def accumulation_time(y0, e):
    """Closed form: first impact at t1 = sqrt(2 y0 / g) with speed v1 = sqrt(2 g y0), then
    flights of 2 e^k v1 / g summing to t_inf = t1 + 2 e v1 / (g (1 - e))."""
    t1 = math.sqrt(2.0 * y0 / G)
    v1 = math.sqrt(2.0 * G * y0)
    return t1 + 2.0 * e * v1 / (G * (1.0 - e))


# --------------------------------------------------------------------------------------
# (1) a run that ends sticking, restarted from its final state
# --------------------------------------------------------------------------------------

def test_restart_from_sticking_final_state_stays_at_rest():
    first = pwsdyn.simulate(BALL, {"y": 1.0, "v": 0.0}, (0, 10), params=still())
    assert first.state[-1] == "stick:impact"
    assert first.final_discrete_state[0] == 1
    t = first.t_final
    traj = pwsdyn.simulate(BALL, first.x_final, (t, t + 3), params=still())
    assert_at_rest(traj)
    # the documented continuation: the trajectory itself, in its final discrete state
    cont = pwsdyn.simulate(BALL, first, t + 3)
    assert cont.t[0] == t and cont.params == first.params
    assert_at_rest(cont)


@pytest.mark.parametrize("x0", [(4e-18, 1e-17), (-4e-18, 1e-17), (4e-18, -1e-17),
                                (-4e-18, -1e-17), (-1e-16, 0.0), (0.0, -1e-16)])
def test_round_off_of_the_issue_rests(x0):
    # the state of the report (a round-off outside the stop) and its sign variants
    traj = pwsdyn.simulate(BALL, x0, (10.0, 13.0), params=still())
    assert_at_rest(traj)


def test_long_sticking_run_that_drifted_behind_the_wall_restarts_at_rest():
    # The kernel's sticking motion is not held on the constraint: with this e the sticking
    # field has a round-off acceleration and after 50 time units the ball is ~1e-12 behind
    # the table (a kernel matter; see the start rule's ADMIT_BEHIND). The restart puts it on
    # the table and it rests.
    e = 0.13830205532047404
    first = pwsdyn.simulate(BALL, [0.5, 0.0], (0, 50), params=still(e), dense=False)
    assert first.final_discrete_state[0] == 1
    t = first.t_final
    traj = pwsdyn.simulate(BALL, first.x_final, (t, t + 3), params=still(e))
    assert traj.x[0, 0] == 0.0 and traj.x[0, 1] == 0.0
    assert np.all(traj.x[:, 0] >= -1e-12)
    assert set(traj.state) == {"stick:impact"}


# --------------------------------------------------------------------------------------
# (2) starts exactly on the ground
# --------------------------------------------------------------------------------------

def test_start_on_ground_at_rest_sticks():
    traj = pwsdyn.simulate(BALL, [0.0, 0.0], (0, 2), params=still())
    assert_at_rest(traj, tol=0.0 + 1e-15)


def test_start_on_ground_moving_in_impacts_at_start():
    # closed form: impact at t0 (v -> e 0.1), then a flight of 2 e 0.1 / g to the next one
    e, v0 = 0.8, 0.1
    for t0 in (0.0, 7.25):
        traj = pwsdyn.simulate(BALL, [0.0, -v0], (t0, t0 + 0.1), params=still(e))
        imp = traj.events_of("impact")
        assert imp[0].t == pytest.approx(t0, abs=4 * EPS * max(1.0, t0))
        assert imp[0].x_after[1] == pytest.approx(e * v0, rel=1e-14)
        assert imp[1].t - imp[0].t == pytest.approx(2 * e * v0 / G, rel=1e-9)
        assert np.all(traj.x[:, 0] >= -1e-15)
        assert traj.state[0] == "flight"


def test_start_on_ground_moving_away_is_free_flight():
    # closed form: y = 0.1 t - g t^2 / 2, first impact at 2 * 0.1 / g
    e, v0 = 0.8, 0.1
    traj = pwsdyn.simulate(BALL, [0.0, v0], (0, 0.1), params=still(e))
    assert traj.state[0] == "flight"
    imp = traj.events_of("impact")
    assert imp[0].t == pytest.approx(2 * v0 / G, rel=1e-12)
    assert imp[0].x_before[1] == pytest.approx(-v0, rel=1e-12)
    tm = v0 / G
    assert traj(tm)[0] == pytest.approx(v0 * tm - G * tm * tm / 2, rel=1e-10)


def test_start_inside_the_wall_is_refused():
    with pytest.raises(ArgumentError, match=r"impact.*-1e-06"):
        pwsdyn.simulate(BALL, [-1e-6, 0.0], (0, 1), params=still())
    with pytest.raises(ArgumentError, match="inside the constraint"):
        pwsdyn.simulate(BALL, [-0.01, 0.3], (0, 1), params={"A": 0.05, "omega": 3.0})


def test_round_off_band_is_the_kernels():
    # 64 ulps of the state scale times the gradient scale (_kernel.fields._surface_offset)
    assert BAND_ULPS == 64.0
    assert round_off_band(1.0, np.array([0.5, 0.0])) == 64 * EPS
    assert round_off_band(3.0, np.array([2.0, -4.0])) == 64 * EPS * 3.0 * 4.0


# --------------------------------------------------------------------------------------
# (3) random restitution and drop heights; round-off perturbations of a resting state
# --------------------------------------------------------------------------------------

@settings(max_examples=12, **_HYP)
@given(e=st.floats(0.01, 0.9), y0=st.floats(0.01, 2.0),
       offsets=st.lists(st.floats(0.0, 2.0), min_size=1, max_size=3))
def test_restart_after_accumulation_point_stays_on_ground(e, y0, offsets):
    t_inf = accumulation_time(y0, e)
    first = pwsdyn.simulate(BALL, [y0, 0.0], (0, t_inf + 0.5), params=still(e), dense=False)
    # the chattering map ends the sequence at the accumulation point (first order in the
    # last impact speed, which is below the chattering floor ~ sqrt(2 g atol))
    stick = [ev for ev in first.events if ev.kind == "stick"]
    assert stick and stick[0].t == pytest.approx(t_inf, abs=1e-5)
    assert first.final_discrete_state[0] == 1
    t = first.t_final
    x = first.x_final
    for off in sorted(offsets):
        tr = pwsdyn.simulate(BALL, x, (t, t + off + 0.1), params=still(e))
        assert np.all(tr.x[:, 0] >= -1e-12)
        np.testing.assert_allclose(tr.x, 0.0, atol=1e-12)
        assert set(tr.state) == {"stick:impact"}
        t, x = tr.t_final, tr.x_final


@settings(max_examples=25, **_HYP)
@given(ky=st.integers(-8, 8), kv=st.integers(-8, 8), t0=st.floats(0.0, 100.0),
       e=st.floats(0.01, 0.9))
def test_round_off_perturbed_rest_still_rests(ky, kv, t0, e):
    x0 = [ky * EPS, kv * EPS]                  # a few ulps of the state scale, either sign
    traj = pwsdyn.simulate(BALL, x0, (t0, t0 + 1.0), params=still(e))
    assert_at_rest(traj)


# --------------------------------------------------------------------------------------
# (4) shooting from a state that sticks
# --------------------------------------------------------------------------------------

def test_shooting_from_a_sticking_guess_finds_the_resting_orbit():
    # A omega^2 < g: a ball on the table stays on it; the periodic orbit is the table's own
    # motion, y = A sin(omega t), v = A omega cos(omega t). The guess lies 3e-17 inside it.
    A, w = 0.05, 10.0
    t0 = 0.3
    x0 = [A * math.sin(w * t0) - 3e-17, A * w * math.cos(w * t0)]
    orb = pwsdyn.find_periodic_orbit(BALL, x0, params={"A": A, "omega": w, "e": 0.5}, t0=t0)
    assert orb.converged
    assert orb.state0 == "stick:impact"
    assert len(orb.events) == 0
    ts = np.linspace(orb.t0, orb.t0 + orb.period, 41)
    xs = np.array([orb.trajectory(t) for t in ts])
    np.testing.assert_allclose(xs[:, 0], A * np.sin(w * ts), atol=1e-12)
    np.testing.assert_allclose(xs[:, 1], A * w * np.cos(w * ts), atol=1e-12)


# --------------------------------------------------------------------------------------
# (5) vibrating table: a sticking restart stays stuck until the release
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("A, w, phase", [(0.1, 12.0, 3.5), (0.05, 20.0, 5.0),
                                         (0.2, 8.0, 3.0)])
def test_vibrating_table_sticking_restart_releases_at_closed_form(A, w, phase):
    assert A * w * w > G
    P = {"A": A, "omega": w, "e": 0.5}
    t0 = phase / w
    assert math.sin(phase) < G / (A * w * w)        # the table pushes: sticking
    t_rel = release_time(A, w, t0)
    on_table = [A * math.sin(w * t0), A * w * math.cos(w * t0)]
    # a start on the table sticks at once; stop it while sticking, then restart from its
    # final state (plain restart and continuation)
    t_mid = 0.5 * (t0 + t_rel)
    first = pwsdyn.simulate(BALL, on_table, (t0, t_mid), params=P)
    assert set(first.state) == {"stick:impact"}
    for x0 in (first.x_final, first):
        span = (t_mid, t_rel + 0.05) if x0 is not first else t_rel + 0.05
        traj = pwsdyn.simulate(BALL, x0, span, params=P)
        assert traj.state[0] == "stick:impact"
        kinds = [e.kind for e in traj.events]
        assert kinds[0] == "release", kinds
        assert traj.events[0].t == pytest.approx(t_rel, abs=1e-8)
        before = traj.t <= t_rel
        ts = traj.t[before]
        np.testing.assert_allclose(traj.x[before, 0], A * np.sin(w * ts), atol=1e-10)
        np.testing.assert_allclose(traj.x[before, 1], A * w * np.cos(w * ts), atol=1e-9)


# --------------------------------------------------------------------------------------
# Filippov sliding: a start within round-off of the surface (handled by the kernel)
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("dv", [0.0, 3 * EPS * 0.2, -3 * EPS * 0.2, 40 * EPS * 0.2])
def test_start_within_round_off_of_sliding_surface_slides(dv):
    # stick-slip oscillator on a belt of speed V = 0.2 with |k x| < Fs at x = 0: the block
    # sticks to the belt, closed form x = V t, v = V, until k x = Fs
    traj = pwsdyn.simulate("stick-slip-oscillator", [0.0, 0.2 + dv], (0, 2))
    assert set(traj.state) == {"slide:vrel"}
    np.testing.assert_allclose(traj.x[:, 0], 0.2 * traj.t, atol=1e-12)
    np.testing.assert_allclose(traj.x[:, 1], 0.2, atol=1e-14)
