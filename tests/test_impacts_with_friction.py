"""Impacts with friction (issue 27): a block on a belt with a rigid stop, next to a second
block whose friction contact sticks while the first one hits the stop.

Two blocks on a belt of speed ``V``, each with undamped Coulomb friction and no coupling,
``x_i'' = -k_i x_i - F_i sign(v_i - V)`` (m = 1), and a rigid stop for block 1 at ``x1 = c``
with Newton's restitution law ``v1+ = -r v1-``. The references are written here and do not
use pwsdyn: scipy's ``solve_ivp`` (DOP853, rtol 1e-12) on each smooth piece with its events
(the impact, the arrival at the belt speed, the release where ``k x = F``), the stick phases
``x' = V`` handled explicitly, and closed forms for the event times:

* stuck, ``x = x0 + V t`` until ``k x = F`` (release at ``(F/k - x0) / V``), or until the
  stop ahead at ``x = c`` (impact at ``(c - x0) / V``);
* slipping below the belt the block oscillates harmonically about ``F / k`` with frequency
  ``w = sqrt(k)``; after a release at ``F / k`` with ``v = V`` it reaches a stop behind it at
  ``c = F/k - V/(2 w)`` where ``w (t - t_r) = 7 pi / 6``, with ``v = V cos(7 pi / 6)``;
* pushed into a stop ahead of it (``d = F/k - c > 0``: the centre lies beyond the stop) the
  block leaves it backwards with speed ``u`` and returns after ``(pi - 2 atan2(d w, u)) /
  w`` (the arc ``x = F/k - R sin(w s + phi)`` with ``R sin(phi) = d``, ``R w cos(phi) =
  u``, from ``phi`` to ``pi - phi``), with ``u -> r u`` at each impact: a sequence that
  accumulates (the flight times fall like ``u``) at the stop, where the block rests while
  ``k c < F`` (the friction of the belt holds it against the stop).

What the integrator does not do: hold a contact that sticks to the stop (``stick:stop``,
an impact constraint) and a contact that sticks to the belt (sliding on a switching surface)
at once -- it has no discrete state with both constraints. Where a run would need one it
ends with ``SURFACE_INTERSECTION`` at that event, in the state before it, and says so.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import pwsdyn
from pwsdyn.errors import SolveError, Status
from test_contacts import coulomb_oscillator

#: the block parameters: (k, F); belt speed, stop, restitution
K1, F1, K2, F2 = 1.0, 1.0, 0.5, 0.4
V, R = 0.2, 0.5
TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-12)
#: the references' tolerances; steps below the shortest flight they resolve (``min_speed``
#: below), so that no first step after an impact spans the whole next flight
REF = dict(method="DOP853", rtol=1e-12, atol=1e-14, max_step=0.02)


def belt_with_stop(behind: bool):
    """The two blocks, block 1 with a rigid stop at ``x1 = c``: behind it (``x1 >= c``) or
    ahead of it (``x1 <= c``)."""
    return {"name": "belt-with-stop", "states": ["x1", "v1", "x2", "v2"],
            "parameters": {"k1": K1, "F1": F1, "k2": K2, "F2": F2, "V": V, "c": 0.9, "r": R},
            "modes": {"blocks": {"x1": "v1", "v1": "-k1*x1 - F1*sign(v1 - V)",
                                 "x2": "v2", "v2": "-k2*x2 - F2*sign(v2 - V)"}},
            "events": [{"name": "stop", "kind": "impact",
                        "surface": "x1 - c" if behind else "c - x1", "direction": -1,
                        "reset": {"v1": "-r*v1"}}]}


# ======================================================================================
# references: scipy on the smooth pieces, the stick phases explicit
# ======================================================================================

def _ev(fun, direction):
    fun.terminal = True
    fun.direction = direction
    return fun


def block_reference(k, F, x0, v0, t_end, stop=None, behind=True, r=R, min_speed=1e-2):
    """One block on the belt (and its stop at ``stop``): a list of pieces ``(t0, t1, sol)``
    with ``sol(t) -> (x, v)``, and the impact times. Slip phases by ``solve_ivp`` with the
    events of the arrival at the belt speed, the stop (reset ``v -> -r v``) and, stuck, the
    release ``k x = F`` or the stop ahead. Impacts slower than ``min_speed`` end the
    reference: from the accumulation point of the sequence (the geometric sum of the
    remaining flight times, in closed form) the block rests at the stop."""
    pieces, impacts = [], []
    t, x, v = 0.0, float(x0), float(v0)
    w = math.sqrt(k)
    released = False
    while t < t_end:
        if v == V and abs(k * x) < F and not released:
            # stuck: x = x + V (s - t) until the release or the stop ahead
            t_rel = t + (F / k - x) / V
            t_hit = t + (stop - x) / V if stop is not None and not behind else math.inf
            t1 = min(t_rel, t_hit, t_end)
            pieces.append((t, t1, lambda s, t=t, x=x: (x + V * (s - t), V + 0 * s)))
            x, t = x + V * (t1 - t), t1
            if t1 == t_hit:
                impacts.append(t)
                v = -r * V
            elif t1 == t_rel:
                x, released = F / k, True    # released: slips below the belt (side -1)
            continue
        side = 1.0 if v > V else -1.0
        released = False

        def rhs(_, y, side=side):
            return [y[1], -k * y[0] - F * side]
        events = [_ev(lambda _, y: y[1] - V, -side)]
        if stop is not None:
            events.append(_ev((lambda _, y: y[0] - stop) if behind
                              else (lambda _, y: stop - y[0]), -1))
        sol = solve_ivp(rhs, (t, t_end), [x, v], events=events, dense_output=True, **REF)
        t1 = sol.t[-1]
        pieces.append((t, t1, lambda s, sol=sol: tuple(sol.sol(s))))
        x, v, t = sol.y[0, -1], sol.y[1, -1], t1
        if sol.status != 1:
            break
        if len(sol.t_events[0]):
            v = V                                   # arrival at the belt speed
            assert abs(k * x) < F, "the references stick only inside the static bound"
        else:
            impacts.append(t)
            x, v = stop, -r * v
            if abs(v) < min_speed:
                # the rest of the sequence: flights of (pi - 2 atan2(d w, u)) / w, u -> r u
                d = F / k - stop
                u, dt = abs(v), 0.0
                while u > 1e-300:
                    dt += (math.pi - 2 * math.atan2(abs(d) * w, u)) / w
                    u *= r
                pieces.append((t, t + dt, None))
                pieces.append((t + dt, t_end, lambda s: (stop + 0 * s, 0 * s)))
                break
    return pieces, impacts


def reference_at(pieces, ts):
    """The reference at the times ``ts`` (NaN inside an unresolved chattering gap)."""
    out = np.full((len(ts), 2), np.nan)
    for t0, t1, f in pieces:
        sel = (ts >= t0) & (ts <= t1)
        if f is not None and sel.any():
            out[sel] = np.array(f(ts[sel])).T
    return out


# ======================================================================================
# an impact while the other contact sticks
# ======================================================================================

def test_impact_behind_while_the_other_block_sticks():
    """Block 1 starts stuck at 0.95, releases at t = 0.25 at x = F1/k1 = 1, slips below the
    belt (x = 1 + 0.2 sin(t - 0.25)) and hits the stop at c = 0.9 = 1 - V/2 where
    t - 0.25 = 7 pi / 6, with v = 0.2 cos(7 pi / 6) = -0.1732; block 2 sticks from 0.788 to
    4.372 (its own closed form, tests/test_contacts.py): the impact happens while it sticks,
    it goes on sticking through it and releases at its own time. Against the references at
    1e-8 (integrations at 1e-12 over a few periods), event times to 1e-9."""
    T = 12.0
    x0 = [0.95, V, -0.2, 0.5]
    traj = pwsdyn.simulate(belt_with_stop(True), x0, T, **TIGHT)
    assert traj.status == Status.SUCCESS, traj.message
    p1, hits = block_reference(K1, F1, x0[0], x0[1], T, stop=0.9, behind=True)
    p2, _ = block_reference(K2, F2, x0[2], x0[3], T)
    t_hit = 0.25 + 7 * math.pi / 6
    assert hits[0] == pytest.approx(t_hit, abs=1e-9)
    impacts = [e for e in traj.events if e.kind == "impact"]
    np.testing.assert_allclose([e.t for e in impacts], hits, rtol=0, atol=1e-9)
    first = impacts[0]
    # block 2 sticks before and after the impact, which resets v1 only
    assert first.mode_before == first.mode_after == "slide:v2-V"
    np.testing.assert_allclose(first.x_before[1], V * math.cos(7 * math.pi / 6), atol=1e-10)
    np.testing.assert_allclose(first.x_after, first.x_before * [1, -R, 1, 1], rtol=0,
                               atol=1e-15)
    # block 2 releases at k2 x2 = F2 after the impact
    (release,) = [e for e in traj.events if e.kind == "slide_end" and e.name == "v2-V"]
    ta, tr, _, _ = coulomb_oscillator(x0[2], x0[3], K2, F2, V)
    assert ta < first.t < tr
    assert release.t == pytest.approx(tr, abs=1e-9)
    ts = np.linspace(0.0, T, 601)
    got = traj(ts)
    np.testing.assert_allclose(got[:, :2], reference_at(p1, ts), rtol=0, atol=1e-8)
    np.testing.assert_allclose(got[:, 2:], reference_at(p2, ts), rtol=0, atol=1e-8)


def test_impacts_ahead_while_both_stick_then_chattering_to_rest():
    """Block 1 stuck at 0.5 is carried into the stop ahead at c = 0.9: the impact at
    t = (c - x0) / V = 2 comes while both blocks stick (on the intersection of their
    surfaces); after it block 1 slips backwards (v1 = -r V) and block 2 goes on sticking. The
    belt's friction (F1 > k1 c) pushes block 1 back: the next impact at 2 + pi/2 (d = 0.1,
    u = 0.1: pi - 2 atan2(0.1, 0.1)), the sequence accumulates (a complete chattering
    sequence) after block 2's release at 4.372, and block 1 rests against the stop
    (``stick:stop``) while block 2 slips. Against the references at 1e-8 outside the
    chattering gap (where the kernel draws the chord of the unresolved bounces), the first
    impacts to 1e-9."""
    T = 12.0
    x0 = [0.5, V, -0.2, 0.5]
    traj = pwsdyn.simulate(belt_with_stop(False), x0, T, **TIGHT)
    assert traj.status == Status.SUCCESS, traj.message
    p1, hits = block_reference(K1, F1, x0[0], x0[1], T, stop=0.9, behind=False)
    p2, _ = block_reference(K2, F2, x0[2], x0[3], T)
    assert hits[:2] == pytest.approx([2.0, 2.0 + math.pi / 2], abs=1e-9)
    impacts = [e for e in traj.events if e.kind == "impact"]
    np.testing.assert_allclose([e.t for e in impacts[:4]], hits[:4], rtol=0, atol=1e-9)
    assert (impacts[0].mode_before, impacts[0].mode_after) == ("slide_multi:v1-V&v2-V",
                                                               "slide:v2-V")
    assert impacts[1].mode_before == impacts[1].mode_after == "slide:v2-V"
    np.testing.assert_allclose(impacts[0].x_after[1], -R * V, rtol=0, atol=1e-15)
    (chatter,) = [e for e in traj.events if e.kind == "chatter"]
    ta, tr, _, _ = coulomb_oscillator(x0[2], x0[3], K2, F2, V)
    assert tr < chatter.t and traj.state[-1] == "stick:stop"
    ts = np.linspace(0.0, T, 1201)
    ref1 = reference_at(p1, ts)
    gap = (ts >= chatter.t - 1e-9) & (ts <= chatter.t_after + 1e-6) | np.isnan(ref1[:, 0])
    got = traj(ts)
    np.testing.assert_allclose(got[~gap, :2], ref1[~gap], rtol=0, atol=1e-8)
    np.testing.assert_allclose(got[:, 2:], reference_at(p2, ts), rtol=0, atol=1e-8)
    assert gap.sum() < 0.1 * len(ts)


def test_chattering_to_rest_while_the_other_block_sticks_is_a_clear_error():
    """As above with block 2 stuck at -0.6 (release at 7): the impacts accumulate at the stop
    while block 2 sticks, and block 1 would then rest against the stop while block 2 sticks
    to the belt -- a contact that sticks (an impact constraint) and a switching surface slid
    on at once, which no discrete state of the integrator holds. The run ends at the event
    that would start it, with ``SURFACE_INTERSECTION``, the state before it and a message
    that names the time, the state, the discrete state, the impact surface and why."""
    x0 = [0.5, V, -0.6, V]
    tr_ = pwsdyn.simulate(belt_with_stop(False), x0, 12.0, throw=False, **TIGHT)
    assert tr_.status == Status.SURFACE_INTERSECTION
    p1, hits = block_reference(K1, F1, x0[0], x0[1], 12.0, stop=0.9, behind=False)
    impacts = [e.t for e in tr_.events if e.kind == "impact"]
    np.testing.assert_allclose(impacts[:len(hits)], hits, rtol=0, atol=1e-9)
    t_acc = p1[-1][0]       # the reference's accumulation point
    assert hits[-1] < tr_.t_final < t_acc < 7.0
    assert tr_.x_final[0] == pytest.approx(0.9, abs=1e-12)           # at the stop
    assert tr_.x_final[3] == pytest.approx(V, abs=1e-12)             # block 2 stuck
    msg = tr_.message
    assert f"Stopped at t={tr_.t_final:.17g} in mode 'slide:v2-V'" in msg
    assert "impact event 'stop'" in msg and "would leave the state in contact" in msg
    assert "no discrete state" in msg
    with pytest.raises(SolveError, match="impact event 'stop'"):
        pwsdyn.simulate(belt_with_stop(False), x0, 12.0, **TIGHT)


def test_sticking_at_the_stop_when_the_other_block_arrives_is_a_clear_error():
    """Block 1 as in the test before last (at rest against the stop from ~5.49); block 2, a
    slow one (k2 = 0.0225, F2 = 0.018), starts at rest at -0.6, slipping below the belt, and
    reaches the belt speed inside its static bound at the time scipy finds (~8.4): there it
    would stick while block 1 sticks to the stop -- the run ends with
    ``SURFACE_INTERSECTION`` at that time, in ``stick:stop``, and the message names the
    switching surface reached."""
    k2, f2 = 0.0225, 0.018
    x0 = [0.5, V, -0.6, 0.0]

    def arrive(_, y):
        return y[1] - V
    sol = solve_ivp(lambda _, y: [y[1], -k2 * y[0] + f2], (0, 20), x0[2:],
                    events=_ev(arrive, 1), **REF)
    t_arr = sol.t_events[0][0]
    assert abs(k2 * sol.y_events[0][0][0]) < f2 and 6.0 < t_arr < 12.0
    tr_ = pwsdyn.simulate(belt_with_stop(False), x0, 12.0, params={"k2": k2, "F2": f2},
                          throw=False, **TIGHT)
    assert tr_.status == Status.SURFACE_INTERSECTION
    # block 2 reaches the belt speed slowly (v2' ~ 0.01 there): a velocity error of 1e-10
    # of the runs at 1e-12 over 8 time units moves that time by 1e-8
    assert tr_.t_final == pytest.approx(t_arr, abs=1e-7)
    assert str(tr_.state[-1]) == "stick:stop"
    msg = tr_.message
    assert "Sticking on the contact of impact event 'stop'" in msg
    assert "it reached switching surface 'v2-V', where it would slide" in msg
