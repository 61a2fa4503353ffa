"""Adversarial event harness: events that coincide, runs cut at an event, restarts from any
logged state, on every integration path (RK45, DOP853 and the exact flow).

Event-driven integrators fail where two things happen at one instant or where a run is cut and
taken up again: an event logged twice or never across a restart, a second event lost behind
the first one's reset, a release missed because a step or a run ended on it. Each property
generates such situations and checks invariants against closed forms (none computed by
pwsdyn):

1. an impact and an independent event (a surface ``t - tc`` crossed at the same instant):
   both logged once, at the closed-form time, and the impact sequence unchanged;
2. a release from a vibrating table and an event at the same instant: the release at its
   closed-form time, the flight after it reaching the table where the parabola does;
3. a run that ends exactly at an impact (or within a few ulps of it, on either side; or with
   the first step ending on it), continued from the trajectory or restarted from its final
   state: every impact of the closed form logged exactly once over the two runs, at its time,
   and the constraint never violated;
4. a run of the ball on a vibrating table (impacts, chattering, sticking, releases) restarted
   from any of its logged events, as a continuation or from the state after the event: the
   restart reproduces the uninterrupted run's next events and never goes through the table.

The default run draws ``PROPERTY`` examples per property; the ``slow`` mark runs
``PROPERTY_SLOW`` (300, or ``PWSDYN_HARNESS_EXAMPLES``).
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, currently_in_test_context, given, settings
from hypothesis import strategies as st

import pwsdyn
from pwsdyn import Status
from _closed_forms import G, harmonic_arc, parabola_hits_table, release_time, wall_impacts

# each integration path on its own: the Runge-Kutta pairs with exact=False (the default
# "auto" would propagate these affine models exactly), and the exact flow
PATHS = {"RK45": dict(method="RK45", exact=False), "DOP853": dict(method="DOP853", exact=False),
         "exact": dict(exact=True)}
TOL = dict(rtol=1e-11, atol=1e-13)
# a state may lie on the wrong side of a constraint by the round-off of the event location
# and of the projections (nodes); the dense output between nodes by its interpolation error
H_NODE = 1e-11
H_DENSE = 1e-8
# event times against closed forms: the location error of a crossing at speed >= 0.05 with
# rtol 1e-11 (the tests of single events hold 1e-9; the harness compares whole sequences)
T_EVENT = 1e-8

_HYP = dict(deadline=None, derandomize=True, database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
PROPERTY = settings(max_examples=30, **_HYP)
#: examples per property under the slow mark; PWSDYN_HARNESS_EXAMPLES sets a longer campaign
PROPERTY_SLOW = settings(max_examples=int(os.environ.get("PWSDYN_HARNESS_EXAMPLES", "300")),
                         **_HYP)


def _require(condition):
    """A precondition of a case: drawn cases that miss it are discarded (hypothesis); the
    fixed regression cases must meet it."""
    if currently_in_test_context():
        assume(condition)
    else:
        assert condition


def _dense_grid(traj, n=4001):
    return np.linspace(traj.t[0], traj.t[-1], n)


def _wall_model(clock: bool):
    """``x'' = a - x`` against the wall ``1 - x >= 0`` (impact, ``v -> -e v``); with ``clock``
    also a transition event on ``t - tc`` (no reset, no target: logged, nothing changes)."""
    events = [{"name": "wall", "kind": "impact", "surface": "1 - x", "reset": {"v": "-e*v"}}]
    if clock:
        events.append({"name": "clock", "kind": "transition", "surface": "t - tc",
                       "direction": 1})
    return pwsdyn.load_model({
        "name": "harness-wall" + ("-clock" if clock else ""),
        "states": ["x", "v"],
        "parameters": {"a": 0.5, "e": 0.5, "tc": 0.0},
        "modes": {"free": {"x": "v", "v": "a - x"}},
        "events": events,
    })


WALL = _wall_model(clock=False)
WALL_CLOCK = _wall_model(clock=True)


def _ball_model(clock: bool):
    """The built-in bouncing ball on a vibrating table, with ``clock`` also a transition event
    on ``t - tc``."""
    spec = {
        "name": "harness-ball" + ("-clock" if clock else ""),
        "states": ["y", "v"],
        "parameters": {"g": G, "e": 0.5, "A": 0.1, "omega": 10.0, "tc": 0.0},
        "forcing_period": "2*pi/omega",
        "definitions": {"s": "A*sin(omega*t)", "sdot": "A*omega*cos(omega*t)"},
        "modes": {"flight": {"y": "v", "v": "-g"}},
        "events": [{"name": "impact", "kind": "impact", "surface": "y - s", "direction": -1,
                    "reset": {"v": "sdot - e*(v - sdot)"}}],
    }
    if clock:
        spec["events"].append({"name": "clock", "kind": "transition", "surface": "t - tc",
                               "direction": 1})
    return pwsdyn.load_model(spec)


BALL_CLOCK = _ball_model(clock=True)


def _assert_outside_wall(*trajs):
    for traj in trajs:
        assert traj.x[:, 0].max() <= 1.0 + H_NODE
        assert traj(_dense_grid(traj))[:, 0].max() <= 1.0 + H_DENSE


def _assert_above_table(traj, A, w):
    """Never below the table: at the nodes to round-off, on the dense output to its
    interpolation error. The interval jumped by the chattering map is left out: its dense
    output is the chord from the sequence's entry to its accumulation point, which cuts
    under a curved table by ``A w^2 dt^2 / 8`` (the nodes at both ends are on the table)."""
    gap = traj.x[:, 0] - A * np.sin(w * traj.t)
    assert gap.min() >= -H_NODE * (1 + A), gap.min()
    ts = _dense_grid(traj)
    for x in traj.events:
        if x.kind == "chatter":
            ts = ts[(ts <= x.t) | (ts >= x.t_after)]
    gap = traj(ts)[:, 0] - A * np.sin(w * ts)
    assert gap.min() >= -H_DENSE * (1 + A), gap.min()


# --------------------------------------------------------------------------------------
# 1. an impact and an independent event at the same instant
# --------------------------------------------------------------------------------------

wall_cases = st.fixed_dictionaries({
    "path": st.sampled_from(sorted(PATHS)),
    "t0": st.sampled_from([0.0, 1.25, 40.0, 1000.0]),
    "a": st.one_of(st.floats(0.2, 0.9), st.floats(1.15, 2.5)),
    "u": st.floats(0.05, 1.5),
    "e": st.floats(0.3, 0.9),
    # which impact of the closed form the other event (or the end of the run) falls on
    "k": st.integers(0, 2),
    # the other event within a few ulps of the impact, on either side
    "ulps": st.integers(-3, 3),
    # the first step ends exactly on the first impact
    "first_step_on_it": st.booleans(),
})


def _wall_sequence(c, horizon):
    """The closed form from a start on the wall leaving it with speed ``u`` at ``t0``."""
    t0, a, u, e = c["t0"], c["a"], c["u"], c["e"]
    t1 = t0 + harmonic_arc(u, a)
    times, speeds = wall_impacts(t1, u, a, e, t0 + horizon)
    _require(len(times) > c["k"])
    # the chattering sequence of a > 1 accumulates: keep away from the accumulation point,
    # where impacts are closer than the location error (that case has its own tests)
    _require(speeds[-1] > 1e-3)
    return t1, times, speeds


def _options(c, t1):
    opts = dict(PATHS[c["path"]], **TOL)
    if c["first_step_on_it"]:
        opts["first_step"] = t1 - c["t0"]
    return opts


def _check_impacts(traj_events, times, speeds):
    impacts = [x for x in traj_events if x.kind == "impact"]
    assert len(impacts) == len(times), ([x.t for x in impacts], times)
    np.testing.assert_allclose([x.t for x in impacts], times, rtol=0,
                               atol=T_EVENT * (1 + times[-1]))
    np.testing.assert_allclose([x.x_before[1] for x in impacts], speeds, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("path", sorted(PATHS))
def test_impact_and_clock_event_at_one_instant(path):
    c = dict(path=path, t0=0.0, a=0.5, u=0.4, e=0.5, k=0, ulps=0, first_step_on_it=False)
    _check_coinciding_impact(c)


def _check_coinciding_impact(c):
    t0 = c["t0"]
    horizon = 4.0 * math.pi
    t1, times, speeds = _wall_sequence(c, horizon)
    tc = times[c["k"]] + c["ulps"] * np.spacing(times[c["k"]])
    traj = pwsdyn.simulate(WALL_CLOCK, [1.0, -c["u"]], (t0, t0 + horizon),
                           params=dict(a=c["a"], e=c["e"], tc=tc), **_options(c, t1))
    assert traj.status is Status.SUCCESS, traj.message
    clocks = [x for x in traj.events if x.name == "clock"]
    assert len(clocks) == 1
    assert clocks[0].t == pytest.approx(tc, abs=T_EVENT * (1 + tc))
    # the clock changes nothing: the impacts are the closed form's, each once
    _check_impacts(traj.events, times, speeds)
    _assert_outside_wall(traj)


@PROPERTY
@given(wall_cases)
def test_property_impact_and_other_event_at_one_instant(c):
    _check_coinciding_impact(c)


@pytest.mark.slow
@PROPERTY_SLOW
@given(wall_cases)
def test_property_impact_and_other_event_at_one_instant_many(c):
    _check_coinciding_impact(c)


# --------------------------------------------------------------------------------------
# 2. a release from a vibrating table and another event at the same instant
# --------------------------------------------------------------------------------------

release_cases = st.fixed_dictionaries({
    "path": st.sampled_from(sorted(PATHS)),
    "A": st.floats(0.03, 0.3),
    # table acceleration amplitude over g: the ball leaves the table in every period
    "ratio": st.floats(1.05, 3.0),
    "phase": st.floats(0.0, 2 * math.pi),
    "cycles": st.integers(0, 3),
    "ulps": st.integers(-3, 3),
    "e": st.floats(0.3, 0.9),
})


def _check_release_with_clock(c):
    A = c["A"]
    w = math.sqrt(c["ratio"] * G / A)
    t0 = (c["phase"] + 2 * math.pi * c["cycles"]) / w
    # a start at rest on the table while it pushes (its acceleration above -g)
    _require(-A * w * w * math.sin(w * t0) > -G * (1 - 1e-3))
    t_rel = release_time(A, w, t0)
    _require(t_rel - t0 > 1e-3)
    tc = t_rel + c["ulps"] * np.spacing(t_rel)
    period = 2 * math.pi / w
    t_end = t_rel + period
    x0 = [A * math.sin(w * t0), A * w * math.cos(w * t0)]
    P = dict(A=A, omega=w, e=c["e"], tc=tc)
    traj = pwsdyn.simulate(BALL_CLOCK, x0, (t0, t_end), params=P, **PATHS[c["path"]], **TOL)
    assert traj.status is Status.SUCCESS, traj.message
    assert traj.state[0] == "stick:impact"
    kinds = [x.kind for x in traj.events]
    rel = [x for x in traj.events if x.kind == "release"]
    clocks = [x for x in traj.events if x.name == "clock"]
    assert rel and len(clocks) == 1, kinds
    assert rel[0].t == pytest.approx(t_rel, abs=T_EVENT * (1 + t_rel))
    assert clocks[0].t == pytest.approx(tc, abs=T_EVENT * (1 + tc))
    # the flight after the release: a parabola from the table's state, down to the table
    yr, vr = A * math.sin(w * t_rel), A * w * math.cos(w * t_rel)
    t_hit = parabola_hits_table(t_rel, yr, vr, A, w, t_end)
    impacts = [x for x in traj.events if x.kind in ("impact", "chatter") and x.t > t_rel]
    if t_hit is None:
        assert not impacts, kinds
    else:
        assert impacts, kinds
        # the take-off is tangential (zero relative speed and acceleration): the parabola's
        # error from a release located to T_EVENT grows like its square, hence the looser bound
        assert impacts[0].t == pytest.approx(t_hit, abs=1e-6 * (1 + t_hit))
    _assert_above_table(traj, A, w)


@pytest.mark.parametrize("path", sorted(PATHS))
def test_release_and_clock_event_at_one_instant(path):
    _check_release_with_clock(dict(path=path, A=0.1, ratio=1.5, phase=math.pi, cycles=0,
                                   ulps=0, e=0.5))


@PROPERTY
@given(release_cases)
def test_property_release_and_other_event_at_one_instant(c):
    _check_release_with_clock(c)


@pytest.mark.slow
@PROPERTY_SLOW
@given(release_cases)
def test_property_release_and_other_event_at_one_instant_many(c):
    _check_release_with_clock(c)


# --------------------------------------------------------------------------------------
# 3. a run cut at an impact, then continued or restarted
# --------------------------------------------------------------------------------------

def _check_cut_at_impact(c, restart):
    t0 = c["t0"]
    horizon = 4.0 * math.pi
    t1, times, speeds = _wall_sequence(c, horizon)
    t_cut = times[c["k"]] + c["ulps"] * np.spacing(times[c["k"]])
    t_end = t0 + horizon
    P = dict(a=c["a"], e=c["e"])
    opts = _options(c, t1)
    first = pwsdyn.simulate(WALL, [1.0, -c["u"]], (t0, t_cut), params=P, **opts)
    assert first.status is Status.SUCCESS, first.message
    opts.pop("first_step", None)
    if restart == "continue":
        second = pwsdyn.simulate(WALL, first, t_end, **opts)
    else:
        second = pwsdyn.simulate(WALL, first.x_final, (first.t_final, t_end), params=P, **opts)
    assert second.status is Status.SUCCESS, second.message
    # every impact once over both runs: none lost at the cut, none logged twice
    _check_impacts(list(first.events) + list(second.events), times, speeds)
    _assert_outside_wall(first, second)


@pytest.mark.parametrize("restart", ["continue", "state"])
@pytest.mark.parametrize("path", sorted(PATHS))
def test_run_cut_at_an_impact(path, restart):
    c = dict(path=path, t0=0.0, a=0.5, u=0.4, e=0.5, k=1, ulps=0, first_step_on_it=False)
    _check_cut_at_impact(c, restart)


@PROPERTY
@given(wall_cases, st.sampled_from(["continue", "state"]))
def test_property_run_cut_at_an_impact(c, restart):
    _check_cut_at_impact(c, restart)


@pytest.mark.slow
@PROPERTY_SLOW
@given(wall_cases, st.sampled_from(["continue", "state"]))
def test_property_run_cut_at_an_impact_many(c, restart):
    _check_cut_at_impact(c, restart)


# --------------------------------------------------------------------------------------
# 4. restarts from any logged state of a ball on a vibrating table
# --------------------------------------------------------------------------------------

table_cases = st.fixed_dictionaries({
    "path": st.sampled_from(sorted(PATHS)),
    "A": st.floats(0.02, 0.15),
    # peak table acceleration over g: below 1 the ball can rest for good, above it leaves;
    # not within 5 % of 1, where the release condition is a tangency (the table's peak
    # acceleration just reaches g: releasing or not is decided by round-off)
    "ratio": st.one_of(st.floats(0.6, 0.95), st.floats(1.05, 2.5)),
    "e": st.floats(0.3, 0.85),
    "y0": st.floats(0.05, 0.6),
    "restart": st.sampled_from(["continue", "state"]),
})

# a restart reproduces the uninterrupted run: the next events compared, their times to this
# tolerance (the restart differs from the original by the round-off of the logged state,
# amplified along a few impacts)
T_RESTART = 1e-6
NEXT_EVENTS = 3
# impacts compared one by one: those with a relative speed above this (slower ones belong to
# chattering sequences)
V_MACRO = 1e-2


def _chattering_windows(events, A, w):
    """Time windows of chattering sequences: from the first impact slower than ``V_MACRO``
    (relative to the table) to the sticking that ends the sequence. Inside them one run may
    bounce where the other has jumped over the rest of the sequence with the chattering map
    (whose interval is a chord of the dense output)."""
    windows, start = [], None
    for x in events:
        rel = x.x_before[1] - A * w * math.cos(w * x.t)
        if start is None and (x.kind == "chatter" or (x.kind == "impact" and abs(rel) < V_MACRO)):
            start = x.t
        elif start is not None and x.kind in ("stick", "release"):
            windows.append((start, x.t_after))
            start = None
        elif start is not None and x.kind == "impact" and abs(rel) >= V_MACRO:
            start = None
    if start is not None:
        windows.append((start, math.inf))
    return windows


def _check_restart_from_event(c, pick):
    A, e = c["A"], c["e"]
    w = math.sqrt(c["ratio"] * G / A)
    period = 2 * math.pi / w
    P = dict(A=A, omega=w, e=e, tc=-1.0)
    t_end = 6 * period
    opts = dict(PATHS[c["path"]], **TOL)
    full = pwsdyn.simulate(BALL_CLOCK, [c["y0"] + A * 0.0, 0.0], (0.0, t_end), params=P, **opts)
    assert full.status is Status.SUCCESS, full.message
    _assert_above_table(full, A, w)
    evs = list(full.events)
    _require(evs)
    k = pick(len(evs))
    ev = evs[k]
    # comparisons need an orbit that is not sensitive at round-off level: no near-grazing
    # impact (relative speed below 1e-4) in the compared window
    later = [x for x in evs if x.t > ev.t]
    for x in later[:NEXT_EVENTS]:
        if x.kind == "impact":
            rel = x.x_before[1] - A * w * math.cos(w * x.t)
            _require(abs(rel) > 1e-4)
    if c["restart"] == "continue":
        first = pwsdyn.simulate(BALL_CLOCK, [c["y0"], 0.0], (0.0, ev.t), params=P, **opts)
        assert first.status is Status.SUCCESS, first.message
        _assert_above_table(first, A, w)
        again = pwsdyn.simulate(BALL_CLOCK, first, t_end, **opts)
        t_from = ev.t
    else:
        t_from = ev.t_after
        _require(t_end - t_from > 1e-3)
        again = pwsdyn.simulate(BALL_CLOCK, ev.x_after, (t_from, t_end), params=P, **opts)
    assert again.status is Status.SUCCESS, again.message
    _assert_above_table(again, A, w)
    # Compared after the restart instant (a contact there may be logged again by the start
    # rule, or not): a chattering sequence may be taken over by the chattering map a few
    # impacts earlier or later (the map starts where the impact speed has fallen below a
    # fraction of the sequence's largest, and a restart begins a new sequence), so the
    # comparison is physical. The sticking and release times and the impacts faster than
    # V_MACRO are the same; the states agree on a grid away from event times.
    # (a sticking that ends a chattering sequence at the restart instant may be placed up to
    # ~1e-8 from the other run's: the chattering map's time error, dt^2 |a'| / |a| for a
    # sequence of duration dt, is of the position tolerance over the speed scale |a| dt)
    eps_t = T_RESTART * (1 + t_end)

    def macro(events):
        out = []
        for x in events:
            if x.t <= t_from + eps_t:
                continue
            rel = x.x_before[1] - A * w * math.cos(w * x.t)
            if x.kind in ("stick", "release") or (x.kind == "impact" and abs(rel) > V_MACRO):
                out.append(x)
        return out

    ref = macro(evs)[:NEXT_EVENTS]
    got = macro(again.events)[:len(ref)]
    assert [x.kind for x in got] == [x.kind for x in ref], (
        ev.kind, [(x.kind, x.t) for x in got], [(x.kind, x.t) for x in ref])
    np.testing.assert_allclose([x.t for x in got], [x.t for x in ref], rtol=0,
                               atol=T_RESTART * (1 + t_end))
    # the states on a grid up to the last compared event, away from every event time
    t_last = ref[-1].t if ref else t_end
    ts = np.linspace(t_from, t_last, 401)[1:-1]
    near = np.zeros(ts.shape, bool)
    for events in (evs, list(again.events)):
        for x in events:
            near |= np.abs(ts - x.t) < 1e-5 * (1 + t_end)
            near |= np.abs(ts - x.t_after) < 1e-5 * (1 + t_end)
        for a, b in _chattering_windows(events, A, w):
            near |= (ts >= a - 1e-5) & (ts <= b + 1e-5)
    ts = ts[~near]
    if ts.size:
        np.testing.assert_allclose(again(ts), full(ts), rtol=0, atol=1e-6 * (1 + A * w))


@pytest.mark.parametrize("path", sorted(PATHS))
@pytest.mark.parametrize("restart", ["continue", "state"])
@pytest.mark.parametrize("which", ["chatter", "stick", "release", "impact"])
def test_restart_from_each_kind_of_event(path, restart, which):
    # A omega^2 = 1.3 g: impacts, a chattering sequence, sticking and a release every period
    c = dict(path=path, A=0.05, ratio=1.3, e=0.5, y0=0.2, restart=restart)

    def pick(n, _c=c):
        w = math.sqrt(_c["ratio"] * G / _c["A"])
        full = pwsdyn.simulate(BALL_CLOCK, [_c["y0"], 0.0], (0.0, 6 * 2 * math.pi / w),
                               params=dict(A=_c["A"], omega=w, e=_c["e"], tc=-1.0),
                               **PATHS[_c["path"]], **TOL)
        kinds = [x.kind for x in full.events]
        assert which in kinds, kinds
        return kinds.index(which)

    _check_restart_from_event(c, pick)


@PROPERTY
@given(table_cases, st.data())
def test_property_restart_from_any_logged_state(c, data):
    _check_restart_from_event(c, lambda n: data.draw(st.integers(0, n - 1), label="event"))


@pytest.mark.slow
@PROPERTY_SLOW
@given(table_cases, st.data())
def test_property_restart_from_any_logged_state_many(c, data):
    _check_restart_from_event(c, lambda n: data.draw(st.integers(0, n - 1), label="event"))


# ---- 5. a sliding exit in a short window inside a step ------------------------------------
#
# x' = g(t) above the surface x = 0 and x' = 1 below it, g(t) = eps - (t - t0)^2: the field
# above points into the surface except on |t - t0| < sqrt(eps). A motion sliding on x = 0
# leaves it at ta = t0 - sqrt(eps) (g turns positive), rises with x' = g and comes back to the
# surface where the integral of g from ta vanishes: (s - 2 sqrt(eps)) (s + sqrt(eps))^2 = 0
# for s = tb - t0, so tb = t0 + 2 sqrt(eps), and slides again. In the sliding state the
# field is zero and the steps are long: the window is a small part of one step -- the case of
# a sliding flow touching the boundary of the sliding region near an adding-sliding.
WINDOW = {"name": "sliding-window", "states": ["x"],
          "parameters": {"eps": 1e-4, "t0": 3.0},
          "modes": {"m": {"x": "(1 + eps - (t - t0)**2)/2 - (1 - eps + (t - t0)**2)/2*sign(x)"}}}

window_cases = st.tuples(st.floats(1e-7, 1e-2), st.floats(2.0, 20.0),
                         st.sampled_from(["RK45", "DOP853"]))


def _check_window(case):
    eps, t0, method = case
    r = math.sqrt(eps)
    tr = pwsdyn.simulate(WINDOW, [0.0], (0.0, t0 + 4.0), params={"eps": eps, "t0": t0},
                         **PATHS[method], **TOL)
    kinds = [(e.kind, e.t) for e in tr.events]
    # sliding from the start (a start on the surface is a state, not an event), the exit at
    # ta, the return at tb, sliding to the end
    assert str(tr.state[0]) == "slide:x"
    assert [k for k, _ in kinds] == ["slide_end", "slide_start"], kinds
    assert abs(kinds[0][1] - (t0 - r)) < T_EVENT * (1 + t0)
    # the return: x(t) = eps (t - ta) - ((t - t0)^3 + r^3) / 3 has a simple root at tb with
    # slope g(tb) = -3 eps, so its time is known to the position error over that slope
    assert abs(kinds[1][1] - (t0 + 2 * r)) < T_EVENT * (1 + t0) + 1e-10 / eps
    assert str(tr.state[-1]) == "slide:x"
    slides = tr.sliding_intervals()
    assert len(slides) == 2 and slides[0][0] == 0.0 and slides[1][1] == tr.t_final


@PROPERTY
@given(window_cases)
def test_a_short_sliding_exit_window_is_never_missed(case):
    _check_window(case)


@pytest.mark.slow
@PROPERTY_SLOW
@given(window_cases)
def test_a_short_sliding_exit_window_is_never_missed_campaign(case):
    _check_window(case)
