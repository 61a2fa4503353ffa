"""Event-driven simulation against closed forms and an independent integrator.

Every expected number here comes from a closed form or from scipy's `solve_ivp`; none from
pwsdyn itself.
"""

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn import SolveError, Status

from _reference import scipy_impacting

G = 9.81
#: The zoo's ball on a static floor: its [defaults] params vibrate the table (A = 0.224).
FLOOR = {"A": 0.0}


# --------------------------------------------------------------------------------------
# bouncing ball on a static floor: impact times and the chattering accumulation point
# --------------------------------------------------------------------------------------

def ball_closed_form(y0, e, n):
    """Impact times of a ball dropped from rest at height y0 (g = 9.81, restitution e):
    t_1 = sqrt(2 y0 / g), v_1 = g t_1, then flights of 2 e^k v_1 / g; the sequence accumulates
    at t_inf = t_1 + 2 e v_1 / (g (1 - e))."""
    t1 = math.sqrt(2 * y0 / G)
    v1 = G * t1
    times = [t1]
    for k in range(1, n):
        times.append(times[-1] + 2 * e**k * v1 / G)
    t_inf = t1 + 2 * e * v1 / (G * (1 - e))
    return np.array(times), t_inf


@pytest.mark.parametrize("e", [0.8, 0.5])
def test_static_floor_impacts_and_accumulation(e):
    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 6),
                           params={"e": e, **FLOOR})
    assert traj.status is Status.SUCCESS
    impacts = traj.event_times("impact")
    expected, t_inf = ball_closed_form(1.0, e, len(impacts))
    # impact times to 1e-9 relative (issue acceptance); flights are parabolas, which RK5
    # integrates exactly, so the error is round-off in the event location
    np.testing.assert_allclose(impacts, expected, rtol=1e-9, atol=0)
    # the chattering map of Nordmark & Piiroinen (2009) is exact for a constant normal
    # acceleration: the accumulation time matches the closed form (acceptance: 1e-8)
    (chatter,) = traj.events_of("chatter")
    assert chatter.t_after == pytest.approx(t_inf, rel=1e-8)
    (stick,) = traj.events_of("stick")
    assert stick.mode_after == "stick:impact"
    # then the ball rests on the floor
    late = traj(np.linspace(t_inf + 1e-6, 6, 50))
    np.testing.assert_allclose(late, 0.0, atol=1e-12)
    # no budget near exhaustion
    assert traj.stats["events"] < 200 and traj.stats["steps"] < 1000


def test_impacts_land_on_the_surface_and_approach():
    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 6), params=FLOOR)
    for ev in traj.events_of("impact"):
        assert abs(ev.x_before[0]) < 1e-13          # located to round-off on h = y = 0
        assert ev.x_before[1] < 0 < ev.x_after[1]   # approaching before, leaving after
        assert ev.x_after[1] == pytest.approx(-0.8 * ev.x_before[1], rel=1e-15)
    t = traj.event_times("impact")
    assert np.all(np.diff(t) > 0)                   # no re-trigger at a restart


def test_ball_at_rest_on_the_floor_sticks_at_once():
    # a start at rest on the constraint starts sticking (no zero-speed impact and chattering
    # sequence first: see tests/test_restart.py)
    traj = pwsdyn.simulate("bouncing-ball", {"y": 0.0, "v": 0.0}, (0, 1), params=FLOOR)
    assert traj.events == [] or len(traj.events) == 0
    assert set(traj.state) == {"stick:impact"}
    np.testing.assert_allclose(traj.x[-1], 0.0, atol=1e-12)


# --------------------------------------------------------------------------------------
# vibrating table: sticking and release
# --------------------------------------------------------------------------------------

def test_vibrating_table_sticks_and_releases_where_table_acceleration_is_minus_g():
    A, w, e = 0.02, 25.0, 0.3
    traj = pwsdyn.simulate("bouncing-ball", {"y": 0.01, "v": 0.0}, (0, 2),
                           params={"A": A, "omega": w, "e": e})
    releases = traj.events_of("release")
    sticks = traj.events_of("stick")
    assert len(releases) >= 5 and len(sticks) >= 5
    # release where the table acceleration -A w^2 sin(w t) first falls below -g after the
    # ball stuck: sin(w t) = g / (A w^2) with sin increasing
    phase = math.asin(G / (A * w * w))
    for rel in releases:
        stuck_since = max(s.t for s in sticks if s.t < rel.t)
        k = math.ceil((w * stuck_since - phase) / (2 * math.pi))
        t_expected = (phase + 2 * math.pi * k) / w
        if t_expected < stuck_since:
            t_expected += 2 * math.pi / w
        assert rel.t == pytest.approx(t_expected, abs=1e-8)
        # at release the ball moves with the table
        s = A * math.sin(w * rel.t)
        sdot = A * w * math.cos(w * rel.t)
        assert rel.x_before[0] == pytest.approx(s, abs=1e-10)
        assert rel.x_before[1] == pytest.approx(sdot, abs=1e-9)
    # while stuck, the ball follows the table
    for st in sticks:
        after = [r.t for r in releases if r.t > st.t]
        if not after:
            continue
        ts = np.linspace(st.t, after[0], 20)[1:-1]
        X = traj(ts)
        np.testing.assert_allclose(X[:, 0], A * np.sin(w * ts), atol=1e-10)
        np.testing.assert_allclose(X[:, 1], A * w * np.cos(w * ts), atol=1e-8)


# --------------------------------------------------------------------------------------
# impact oscillator against scipy
# --------------------------------------------------------------------------------------

IMPACT_OSCILLATOR = {
    "name": "impact-oscillator-test",
    "states": ["x", "v"],
    "parameters": {"eps": 0.1, "omega": 2.2, "sigma": 0.1, "r": 0.8},
    "forcing_period": "2*pi/omega",
    "modes": {"free": {"x": "v", "v": "-eps*v - x + sin(omega*t)"}},
    "events": [{"name": "impact", "kind": "impact", "surface": "sigma - x",
                "reset": {"v": "-r*v"}}],
}


def test_impact_oscillator_agrees_with_scipy_over_50_periods():
    eps, om, sig, r = 0.1, 2.2, 0.1, 0.8
    T = 2 * math.pi / om
    traj = pwsdyn.simulate(IMPACT_OSCILLATOR, [0.0, 0.0], (0, 50 * T), rtol=1e-12, atol=1e-14)

    def rhs(t, y):
        return [y[1], -eps * y[1] - y[0] + math.sin(om * t)]

    te, yb, ya, yend = scipy_impacting(rhs, lambda t, y: sig - y[0],
                                       lambda t, y: np.array([y[0], -r * y[1]]), [0.0, 0.0],
                                       (0, 50 * T), rtol=1e-12, atol=1e-14)
    impacts = traj.events_of("impact")
    assert len(impacts) == len(te) >= 50
    # both integrators run at rtol 1e-12 on a stable periodic orbit, so the differences stay
    # at the level of a few hundred times the tolerance
    np.testing.assert_allclose([e.t for e in impacts], te, rtol=0, atol=1e-9)
    np.testing.assert_allclose([e.x_before for e in impacts], yb, rtol=0, atol=1e-9)
    np.testing.assert_allclose([e.x_after for e in impacts], ya, rtol=0, atol=1e-9)
    np.testing.assert_allclose(traj.x[-1], yend, rtol=0, atol=1e-9)


def test_dop853_agrees_with_rk45_and_closed_form_flight():
    # harmonic oscillator x'' = -x: exact solution cos t
    model = {"name": "harmonic", "states": ["x", "v"], "modes": {"m": {"x": "v", "v": "-x"}}}
    ts = np.linspace(0, 20, 401)
    for method, tol in (("RK45", 1e-10), ("DOP853", 1e-12)):
        traj = pwsdyn.simulate(model, [1.0, 0.0], (0, 20), method=method, rtol=tol, atol=tol,
                               exact=False)
        # global error of an adaptive method over ~3 periods stays within ~100 tolerances;
        # the dense output is checked between the steps as well
        np.testing.assert_allclose(traj(ts)[:, 0], np.cos(ts), atol=300 * tol)
        np.testing.assert_allclose(traj(traj.t), traj.x, atol=1e-14)
    fewer = pwsdyn.simulate(model, [1.0, 0.0], (0, 20), method="DOP853", rtol=1e-10, atol=1e-10,
                            exact=False)
    more = pwsdyn.simulate(model, [1.0, 0.0], (0, 20), method="RK45", rtol=1e-10, atol=1e-10,
                           exact=False)
    assert fewer.stats["steps"] < more.stats["steps"] / 2   # the 8th-order pair pays off


# --------------------------------------------------------------------------------------
# grazing: a dip into h < 0 and out again inside one step
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("method", ["RK45", "DOP853"])
def test_dip_within_one_step_is_detected(method):
    # a ball thrown up at v0 = 10 reaches y_max = v0^2 / (2 g); the surface h = (y_max - d) - y
    # is crossed (downwards, direction -1) during a short time 2 sqrt(2 d / g) around the apex.
    # The flight is a parabola that RK integrates exactly, so the step size grows to the whole
    # span: the crossing and re-crossing lie inside one step.
    v0, d = 10.0, 1e-6
    ymax = v0 * v0 / (2 * G)
    model = {"name": "apex", "states": ["y", "v"], "parameters": {"g": G, "level": ymax - d},
             "modes": {"flight": {"y": "v", "v": "-g"}},
             "events": [{"name": "over", "surface": "level - y", "direction": -1},
                        {"name": "back", "surface": "level - y", "direction": 1}]}
    traj = pwsdyn.simulate(model, [0.0, v0], (0, 2.0), method=method, first_step=2.0)
    # y = ymax - g/2 (t - v0/g)^2, so the level ymax - d is crossed at v0/g -+ sqrt(2 d / g)
    t_over = v0 / G - math.sqrt(2 * d / G)
    t_back = v0 / G + math.sqrt(2 * d / G)
    assert [e.name for e in traj.events] == ["over", "back"]
    # near a graze the time resolution is the round-off of h (~1e-15 * |y|) divided by the
    # slow crossing speed sqrt(2 g d) = 4.4e-3: a few 1e-12
    assert traj.events[0].t == pytest.approx(t_over, abs=2e-11)
    assert traj.events[1].t == pytest.approx(t_back, abs=2e-11)
    assert t_back - t_over < 1e-3
    # the steps really were long: the whole flight took a handful of steps
    assert traj.stats["steps"] <= 6


# --------------------------------------------------------------------------------------
# bad input and budgets
# --------------------------------------------------------------------------------------

def test_wrong_length_x0_and_unknown_state():
    with pytest.raises(ValueError, match="must have 2 entries"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0, 3.0], (0, 1))
    with pytest.raises(ValueError, match="unknown state"):
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "w": 0.0}, (0, 1))
    with pytest.raises(ValueError, match="finite"):
        pwsdyn.simulate("bouncing-ball", [float("nan"), 0.0], (0, 1))


def test_nan_parameter_and_bad_options():
    with pytest.raises(ValueError, match="finite"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (0, 1), params={"g": float("nan")})
    with pytest.raises(ValueError, match="unknown parameter"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (0, 1), params={"gravity": 1.0})
    with pytest.raises(TypeError, match="unexpected keyword"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (0, 1), rtoll=1e-6)
    with pytest.raises(ValueError, match="t_end > t0"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (1, 1))
    with pytest.raises(ValueError, match="`rtol`"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (0, 1), rtol=-1)
    with pytest.raises(ValueError, match="`method`"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (0, 1), method="Euler")


def test_zeno_sequence_without_chattering_map_ends_with_clear_error():
    with pytest.raises(SolveError) as info:
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 6), FLOOR, chatter=False)
    err = info.value
    assert err.status in (Status.ZENO, Status.MAX_EVENTS)
    t_inf = ball_closed_form(1.0, 0.8, 1)[1]
    assert err.t == pytest.approx(t_inf, abs=1e-6)      # it stopped at the accumulation point
    msg = str(err)
    assert "t=" in msg and "mode 'flight'" in msg and "y=" in msg and "v=" in msg
    # the same with a small event budget: MAX_EVENTS, the partial trajectory is kept
    with pytest.raises(SolveError) as info:
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 6), FLOOR, chatter=False,
                        max_events=20)
    assert info.value.status is Status.MAX_EVENTS
    assert len(info.value.result.events) == 20


def test_step_budget_and_throw_false():
    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 6), FLOOR, max_steps=5,
                           throw=False)
    assert traj.status is Status.MAX_STEPS and not traj.success
    assert "max_steps" in traj.message
    with pytest.raises(SolveError, match="maximum number of steps"):
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 6), FLOOR, max_steps=5)


def test_blow_up_is_reported_not_hung():
    model = {"name": "blowup", "states": ["x"], "modes": {"m": {"x": "x**2"}}}
    with pytest.raises(SolveError) as info:
        pwsdyn.simulate(model, [1.0], (0, 2))      # x = 1 / (1 - t) blows up at t = 1
    assert info.value.status in (Status.STEP_TOO_SMALL, Status.NONFINITE, Status.MAX_STEPS)
    assert info.value.t == pytest.approx(1.0, abs=1e-3)


def test_dense_output_both_sides_of_a_jump():
    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 2), params=FLOOR)
    ev = traj.events_of("impact")[0]
    np.testing.assert_allclose(traj(ev.t, side="left"), ev.x_before, atol=1e-15)
    np.testing.assert_allclose(traj(ev.t, side="right"), ev.x_after, atol=1e-15)
    # between impacts the dense output is the exact parabola
    t = np.linspace(ev.t, traj.events_of("impact")[1].t, 50)[1:-1]
    v = ev.x_after[1]
    np.testing.assert_allclose(traj(t)[:, 0], v * (t - ev.t) - G / 2 * (t - ev.t) ** 2,
                               atol=1e-12)


@pytest.mark.parametrize("name, x0, params, t_end", [
    ("bouncing-ball", {"y": 0.1, "v": 0.0}, dict(A=0.02, omega=25.0, e=0.3), 1.0),
    ("stick-slip-oscillator", (0.0, 0.0), None, 30.0),
])
def test_event_log_columns_match_its_records(name, x0, params, t_end):
    """The log's arrays and its records say the same (impact/chatter/stick/release on an
    event; slide_start/slide_end on a switch, named after the switch)."""
    traj = pwsdyn.simulate(name, x0, (0, t_end), params=params)
    log = traj.events
    recs = list(log)
    assert len(recs) == len(log) > 3 and log == recs and log[-1] is recs[-1]
    assert log.kind.tolist() == [e.kind for e in recs]
    assert log.name.tolist() == [e.name for e in recs]
    np.testing.assert_array_equal(log.t, [e.t for e in recs])
    np.testing.assert_array_equal(log.x_before, np.array([e.x_before for e in recs]))
    kinds = {"stick": 1, "slide": 2}
    assert log.state_after[:, 0].tolist() == [kinds.get(e.mode_after.split(":")[0], 0)
                                              for e in recs]
    assert {e.kind for e in recs} >= ({"impact", "chatter", "stick", "release"}
                                      if name == "bouncing-ball"
                                      else {"slide_start", "slide_end"})


def test_event_records_and_logs_compare_by_value():
    """Records hold arrays: they compare field by field (the generated dataclass equality
    raised on the truth value of an array)."""
    import copy

    a = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 2))
    b = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 2))
    assert a.events[0] == copy.deepcopy(a.events[0]) and a.events[0] != a.events[1]
    assert list(a.events) == list(b.events) and a.events == b.events
