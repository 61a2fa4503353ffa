"""Lyapunov spectra of flows with sticking (events issue, item 8): a sticking episode is a
reset of the tangent dynamics, not a -inf average (pwsdyn.LyapunovSpectrum, Notes).

Ball on a table s(t) = A sin(w t), y'' = -g, impact y = s: v+ = s' - e (v- - s'). Independent
references:

* the event log of plain ``pwsdyn.simulate`` runs over the same span (stick and release
  times, chattering starts, impact counts), and the closed-form release phase: a sticking ball
  leaves the table when the table's downward acceleration reaches g, s''(t) = -g, i.e.
  ``sin(w t) = g / (A w^2)`` with s'' decreasing: ``w t = asin(g / (A w^2)) mod 2 pi``;
* the determinant of the impact saltation in closed form. With h = y - s(t), h_x = (1, 0),
  h_t = -s', g_x = diag(1, -e), g_t = (0, (1 + e) s''), f- = (v-, -g), f+ = (v+, -g):
  S = g_x + (f+ - g_x f- - g_t) h_x / (h_t + h_x f-) = [[(v+ - s')/(v- - s'), 0], [*, -e]]
  = [[-e, 0], [*, -e]], so det S = e^2 at every impact, whatever the table's phase; free
  flight is area-preserving (tr f_x = 0; its Jacobian [[1, t], [0, 1]]). So the exponents of
  the free motion obey ``sum(exponents) * T_free = 2 log(e) * (impacts in the free motion)``.
"""

from __future__ import annotations

import numpy as np
import pytest

import pwsdyn

G, E = 9.81, 0.8
OMEGA = 2 * np.pi      # table period 1
A_INTERMITTENT = 0.35  # A w^2 / g = 1.41: the ball sticks now and then and is released
# Segments start at phase 1/4, where s'' = -A w^2 < -g: the ball cannot stick there, so no
# sticking episode straddles a segment boundary and plain runs restarted at the same times
# (free flight) are the same motion as the spectrum's segments.
T0 = 0.25
TRANSIENT, DURATION = 100, 1000


def _plain_log(params, x0, t0, transient, duration):
    """Event columns (t, t_after, kind) of plain simulations over the spectrum's window:
    the transient in one run, then one run per forcing period from the previous end state,
    restarted at the same times as the spectrum's segments. One long run would not do: the
    motion is chaotic (largest exponent ~0.8), and a run that is not restarted takes
    different steps and separates from the segmented one after a few dozen impacts."""
    tr = pwsdyn.simulate("bouncing-ball", x0, (t0, t0 + transient), params, dense=False,
                         method="RK45")
    x = tr.x_final
    t, t_after, kind = [], [], []
    for k in range(duration):
        ta = t0 + transient + k
        # exact=False: the spectrum's segments carry the variational equations, which run on
        # the Runge-Kutta pair (its transient, like the one above, has the default exact
        # flight). RK45 in both: with it the variational runs take the plain runs' steps
        # (DOP853's steps there are also limited by the variational part, and the chaotic
        # motions separate)
        tr = pwsdyn.simulate("bouncing-ball", x, (ta, ta + 1.0), params, dense=False,
                             exact=False, method="RK45")
        assert tr.success and tr.final_discrete_state[0] == 0   # premise: free at the restart
        t.append(tr.events.t)
        t_after.append(tr.events.t_after)
        kind.append(np.asarray(tr.events.kind, dtype=str))
        x = tr.x_final
    return np.concatenate(t), np.concatenate(t_after), np.concatenate(kind), x


@pytest.fixture(scope="module")
def intermittent():
    params = {"A": A_INTERMITTENT, "omega": OMEGA}
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", [1.5, 0.0], params, t0=T0,
                                   transient=TRANSIENT, duration=DURATION, method="RK45")
    return res, _plain_log(params, [1.5, 0.0], T0, TRANSIENT, DURATION)


def test_intermittent_sticking_gives_finite_exponents_and_the_contact_time(intermittent):
    """A = 0.35: the spectrum was [-inf, -inf] with one sticking episode; now it is finite
    (chaotic: a positive exponent) and the time in contact is reported apart, equal to the
    plain runs' stick-to-release times. The plain runs repeat the spectrum's arithmetic (same
    restarts, same kernel), so the times agree to round-off; 1e-9 leaves room for a
    different order of summation."""
    res, (t, t_after, kind, x_end) = intermittent
    assert res.status == 0 and not res.ends_stuck
    assert np.all(np.isfinite(res.exponents)) and res.exponents[0] > 0.1
    stick, release, chatter = t[kind == "stick"], t[kind == "release"], t[kind == "chatter"]
    assert len(stick) >= 2 and len(release) == len(stick) == len(chatter)
    assert np.all(chatter <= stick) and np.all(stick < release)
    # every release where the table's downward acceleration reaches g (closed form)
    phase = np.arcsin(G / (A_INTERMITTENT * OMEGA ** 2)) / OMEGA
    np.testing.assert_allclose(release % 1.0, phase, atol=1e-8)
    assert res.events == {k: int(np.sum(kind == k)) for k in set(kind)}
    assert res.contact_episodes == len(stick)
    assert res.span == DURATION
    assert res.contact_time > 0
    assert res.contact_time == pytest.approx(np.sum(release - stick), abs=1e-9)
    assert res.contact_fraction == pytest.approx(np.sum(release - stick) / DURATION, abs=1e-12)
    # the averaging time: the span less each episode from its chattering map to its release
    assert res.time == pytest.approx(DURATION - np.sum(release - chatter), abs=1e-9)
    np.testing.assert_allclose(res.x_final, x_end, rtol=1e-9, atol=1e-9)


def test_sum_rule_of_the_free_motion_with_sticking(intermittent):
    """sum(exponents) * T_free = sum of log|det S| over the impacts of the free motion =
    2 log(e) * N (det S = e^2, flight area-preserving; module docstring), with T_free and N
    from the plain runs' log: the span less the contact episodes (chattering map to release),
    and every logged impact (none is logged inside an episode). Each factor's determinant is
    exact to round-off and the frame is re-orthonormalised at every event of a segment with
    contact, so the identity holds to ~1e-11 here (the QR of a whole segment's product across
    the approach to sticking, cond ~1e11..1e15, was off by 2e-4); tolerance 1e-6 relative."""
    res, (t, t_after, kind, _) = intermittent
    t_free = DURATION - np.sum(t[kind == "release"] - t[kind == "chatter"])
    n_impacts = int(np.sum(kind == "impact"))
    rule = 2 * np.log(E) * n_impacts
    assert res.sum * t_free == pytest.approx(rule, rel=1e-6)


def _benettin(params, x0, transient, duration):
    """The plain Benettin QR average, per forcing period, with the Jacobians (saltations
    included) of plain variational runs: what lyapunov_spectrum computed before sticking
    episodes were treated as resets."""
    tr = pwsdyn.simulate("bouncing-ball", x0, (0.0, float(transient)), params, dense=False)
    x, Q, sums = tr.x_final, np.eye(2), np.zeros(2)
    for k in range(duration):
        ta = float(transient + k)
        tr = pwsdyn.simulate("bouncing-ball", x, (ta, ta + 1.0), params, dense=False,
                             variational=True)
        assert not any(e.kind in ("chatter", "stick") for e in tr.events)
        Q, R = np.linalg.qr(tr.jacobian @ Q)
        sums += np.log(np.abs(np.diag(R)))
        x = tr.x_final
    return np.sort(sums / (duration * 1.0))[::-1]


def test_spectrum_without_sticking_is_unchanged():
    """Chaotic bouncing without chattering or sticking (Gamma = A w^2 / g = 2.5): the same
    exponents, bit for bit, as the plain per-period Benettin average (the algorithm before
    this change), and no contact reported."""
    params = {"A": 2.5 * G / OMEGA ** 2, "omega": OMEGA, "e": E}
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", [1.0, 0.0], params, transient=50,
                                   duration=300)
    assert set(res.events) == {"impact"}
    np.testing.assert_array_equal(res.exponents, _benettin(params, [1.0, 0.0], 50, 300))
    assert res.time == res.span == 300.0
    assert res.contact_time == 0.0 and res.contact_episodes == 0 and not res.ends_stuck


def test_a_ball_that_ends_stuck_for_good_has_collapsed():
    """A w^2 < g: once stuck the ball is never released (the table's acceleration never
    reaches -g). Dropped from 1 m it bounces, chatters and sticks within the window: the run
    ends stuck for good (no release in a plain run twice as long), so the state has collapsed
    onto the sticking manifold and the exponents are -inf -- unlike intermittent sticking.
    The contact time runs from the stick to the end of the window (plain run's stick time;
    the segmented run and the plain one reach the chattering map after different numbers of
    impacts, so the accumulation point agrees to ~1e-8, not to round-off)."""
    params = {"A": 0.2, "omega": OMEGA}
    assert 0.2 * OMEGA ** 2 < G
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", [1.0, 0.0], params, transient=0,
                                   duration=30)
    plain = pwsdyn.simulate("bouncing-ball", [1.0, 0.0], (0.0, 60.0), params, dense=False)
    kinds = [e.kind for e in plain.events]
    assert "release" not in kinds and kinds.count("stick") == 1
    t_stick = plain.events_of("stick")[0].t
    assert res.ends_stuck and np.all(np.isneginf(res.exponents))
    assert res.contact_episodes == 1
    assert res.contact_time == pytest.approx(30.0 - t_stick, abs=1e-6)
    assert 0 < res.time < 30.0 - res.contact_time + 1e-6


def test_sweep_lyapunov_column_is_the_spectrum_of_the_free_motion():
    """The sweep's Lyapunov column uses the same segments: at A = 0.35 it equals
    lyapunov_spectrum over the same window (bit for bit), finite, and the sweep's stick_time
    per period is the contact time per period."""
    n_tr, n_s = 100, 300
    ds = pwsdyn.sweep("bouncing-ball", "A", [A_INTERMITTENT], [1.5, 0.0],
                      params={"omega": OMEGA}, phase=T0, transient=n_tr, samples=n_s,
                      lyapunov=True, workers=1, progress=False)
    d = ds.sel(direction="up", A=A_INTERMITTENT)
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", [1.5, 0.0],
                                   {"A": A_INTERMITTENT, "omega": OMEGA}, t0=T0,
                                   transient=n_tr, duration=n_s)
    assert int(d.status) == 0 and res.contact_episodes >= 1
    np.testing.assert_array_equal(d.lyapunov.values, res.exponents)
    assert np.all(np.isfinite(res.exponents))
    assert float(d.stick_time) * n_s == pytest.approx(res.contact_time, abs=1e-9)
