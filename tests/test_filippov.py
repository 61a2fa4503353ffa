"""Filippov systems, sliding and dry friction (issue 3).

Every number is checked against something independent of the kernel's sliding code: a
closed form, scipy at tight tolerance, or the same system written another way. Equations
cited: thesis = F. Svahn, PhD thesis (KTH 2009), slides = P. T. Piiroinen, Numerical Methods
for the Analysis of Piecewise-smooth Systems (NUI Galway 2015).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner
from scipy.integrate import solve_ivp

import pwsdyn
from pwsdyn.cli import main as cli_main
from pwsdyn.errors import ModelError, SolveError, Status
from pwsdyn.model.discontinuities import U_SYMBOL

# ======================================================================================
# models
# ======================================================================================

#: Thesis section 2.2.2 (Papers D and E): f1 = (x2, -1 - x1, omega) above h = x2,
#: f2 = (x2, 1 - x1, omega) below; eq. 2.8 gives alpha = (1 + x1)/2 and the sliding field
#: f12 = (0, 0, omega).
THESIS_EXPLICIT = {
    "name": "thesis-2-2-2", "states": ["x1", "x2", "x3"], "parameters": {"omega": 1.3},
    "modes": {"f1": {"x1": "x2", "x2": "-1 - x1", "x3": "omega"},
              "f2": {"x1": "x2", "x2": "1 - x1", "x3": "omega"}},
    "switches": [{"name": "h", "surface": "x2", "above": "f1", "below": "f2"}],
}
#: The same system as a paper writes it: one field with sign(x2).
THESIS_SIGN = {
    "name": "thesis-2-2-2-sign", "states": ["x1", "x2", "x3"], "parameters": {"omega": 1.3},
    "modes": {"m": {"x1": "x2", "x2": "-x1 - sign(x2)", "x3": "omega"}},
}


def belt(**params):
    """Mass on a belt with Coulomb friction, x'' + k x = -mu sign(x' - V) + A cos(w t)."""
    p = {"k": 1.0, "mu": 1.0, "V": 0.5, "A": 0.0, "w": 1.0}
    p.update(params)
    return {"name": "belt", "states": ["x", "v"], "parameters": p,
            "modes": {"slip": {"x": "v", "v": "-k*x - mu*sign(v - V) + A*cos(w*t)"}}}


def belt_explicit(**params):
    """The belt written as two explicit modes and a switching surface (thesis eq. 2.6)."""
    p = {"k": 1.0, "mu": 1.0, "V": 0.5, "A": 0.0, "w": 1.0}
    p.update(params)
    return {"name": "belt-explicit", "states": ["x", "v"], "parameters": p,
            "modes": {"fast": {"x": "v", "v": "-k*x - mu + A*cos(w*t)"},
                      "slow": {"x": "v", "v": "-k*x + mu + A*cos(w*t)"}},
            "switches": [{"name": "belt", "surface": "v - V", "above": "fast",
                          "below": "slow"}]}


def belt_fs_fd(**params):
    """Mass on a belt with static friction Fs > dynamic Fd (thesis eq. 5.4 on a moving belt):
    explicit slip_pos / slip_neg / stick modes with guarded transitions."""
    p = {"m": 1.0, "k": 1.0, "V": 0.5, "Fs": 1.0, "Fd": 0.6}
    p.update(params)
    return {
        "name": "belt-fs-fd", "states": ["x", "v"], "parameters": p, "initial_mode": "stick",
        "modes": {"slip_pos": {"x": "v", "v": "(-k*x - Fd)/m"},
                  "slip_neg": {"x": "v", "v": "(-k*x + Fd)/m"},
                  "stick": {"x": "V", "v": "0"}},
        "events": [
            {"name": "stick_from_neg", "surface": "v - V", "direction": 1, "modes": "slip_neg",
             "guard": "k*x >= -Fs", "reset": {"v": "V"}, "target": "stick"},
            {"name": "pass_from_neg", "surface": "v - V", "direction": 1, "modes": "slip_neg",
             "guard": "k*x < -Fs", "reset": {"v": "V"}, "target": "slip_pos"},
            {"name": "stick_from_pos", "surface": "v - V", "direction": -1,
             "modes": "slip_pos", "guard": "k*x <= Fs", "reset": {"v": "V"}, "target": "stick"},
            {"name": "pass_from_pos", "surface": "v - V", "direction": -1, "modes": "slip_pos",
             "guard": "k*x > Fs", "reset": {"v": "V"}, "target": "slip_neg"},
            {"name": "break_fwd", "surface": "k*x - Fs", "direction": 1, "modes": "stick",
             "target": "slip_neg"},
            {"name": "break_back", "surface": "k*x + Fs", "direction": -1, "modes": "stick",
             "target": "slip_pos"},
        ]}


# ======================================================================================
# sign / Heaviside / Abs / Max / Min -> modes and switches
# ======================================================================================

def test_sign_splits_modes_into_named_variants_with_filippov_switches():
    m = pwsdyn.load_model(belt())
    assert m.mode_names == ("slip[v-V>0]", "slip[v-V<0]")
    (sw,) = m.switches
    assert (sw.kind, sw.name, sw.above, sw.below) == ("filippov", "v-V", 0, 1)
    assert str(m.surfaces[sw.surface].expr) == str(pwsdyn.load_model(belt_explicit())
                                                   .surfaces[0].expr)
    # the variants are the fields on either side; the family has sign(v - V) -> u
    x, v = m.state_symbols
    k, mu, V, A, w = m.parameter_symbols
    forcing = A * sp.cos(w * m.t)
    assert sp.simplify(m.modes[0].rhs[1] - (-k * x - mu + forcing)) == 0
    assert sp.simplify(m.modes[1].rhs[1] - (-k * x + mu + forcing)) == 0
    assert sp.simplify(sw.family[1] - (-k * x - mu * U_SYMBOL + forcing)) == 0
    # the user's mode name still selects a mode (its first variant)
    assert m.mode_index("slip") == 0


def test_several_sign_terms_give_the_product_of_sides():
    m = pwsdyn.load_model({"name": "two", "states": ["x", "y"],
                           "modes": {"m": {"x": "-sign(x) + 0.5*sign(y)",
                                           "y": "Heaviside(x) - sign(y)"}}})
    assert len(m.modes) == 4 and len(m.switches) == 4
    assert {s.name for s in m.switches} == {"x", "y"}
    # each switch joins two variants that differ in one side only
    for s in m.switches:
        a, b = m.mode_names[s.above], m.mode_names[s.below]
        assert sum(p != q for p, q in zip(a, b)) == 1 and s.kind == "filippov"
    # Heaviside(x) is 1 above x = 0 and 0 below it
    fields = {name: tuple(float(e) for e in mode.rhs)
              for name, mode in zip(m.mode_names, m.modes)}
    assert fields["m[x>0,y>0]"] == (-0.5, 0)
    assert fields["m[x<0,y<0]"] == (0.5, 1)


def test_abs_max_min_give_continuous_switches_and_too_many_surfaces_fail():
    m = pwsdyn.load_model({"name": "kinks", "states": ["x", "v"],
                           "parameters": {"k1": 1.0, "k2": 4.0},
                           "modes": {"m": {"x": "v", "v": "-k1*Max(x, 0) - k2*Min(x, 0)"}}})
    assert [s.kind for s in m.switches] == ["continuous"]
    assert m.mode_names == ("m[x>0]", "m[x<0]")
    terms = " + ".join(f"sign(x - {i})" for i in range(11))
    with pytest.raises(ModelError, match="more than 10 distinct switching surfaces"):
        pwsdyn.load_model({"name": "many", "states": ["x"], "modes": {"m": {"x": terms}}})


# ======================================================================================
# thesis section 2.2.2: sliding with (0, 0, omega), convex and equivalent control
# ======================================================================================

@pytest.mark.parametrize("sliding", ["convex", "utkin"])
@pytest.mark.parametrize("model", [THESIS_EXPLICIT, THESIS_SIGN], ids=["modes", "sign"])
def test_thesis_example_slides_with_zero_field_and_holds_x1(model, sliding):
    """Thesis eq. 2.7-2.8: on h = x2 = 0 with |x1| < 1, alpha = (1 + x1)/2 and
    f12 = (0, 0, omega). Any start there slides; x1 is held to 1e-12 over t = 1000."""
    omega = 1.3
    for x10 in (-0.999, -0.5, 0.0, 0.3, 0.9):
        traj = pwsdyn.simulate(model, [x10, 0.0, 0.0], (0.0, 1000.0), sliding=sliding)
        assert all(s.startswith("slide:") for s in traj.state)
        assert traj.events == []
        assert np.max(np.abs(traj.x[:, 0] - x10)) <= 1e-12
        assert np.max(np.abs(traj.x[:, 1])) <= 1e-12
        np.testing.assert_allclose(traj.x[:, 2], omega * traj.t, rtol=1e-12, atol=1e-12)


def test_thesis_example_arrives_and_then_slides():
    """A start above the surface follows f1 (a circle about (-1, 0)) to x2 = 0 and slides
    there with f12 = (0, 0, omega). From (x1, x2) = (0.5, 0.5): (x1 + 1)^2 + x2^2 = 2.5,
    reached at x1 = sqrt(2.5) - 1 after time atan2(0.5, 1.5) (closed form)."""
    traj = pwsdyn.simulate(THESIS_EXPLICIT, [0.5, 0.5, 0.0], (0.0, 50.0))
    (start,) = traj.events
    assert start.kind == "slide_start"
    assert start.t == pytest.approx(math.atan2(0.5, 1.5), abs=1e-12)
    # the arrival point carries the integration error of the arc (rtol 1e-10) ...
    x1s = math.sqrt(2.5) - 1.0
    assert start.x_after[0] == pytest.approx(x1s, abs=1e-9)
    # ... and is then held exactly: f12 = (0, 0, omega)
    assert traj.x_final[0] == pytest.approx(start.x_after[0], abs=1e-12)
    assert abs(traj.x_final[1]) <= 1e-14


# ======================================================================================
# sliding exit in closed form
# ======================================================================================

def test_sliding_exit_time_matches_closed_form():
    """Belt x'' + k x = -mu sign(x' - V). Stuck on v = V the motion is x = x0 + V t (sliding
    field of eq. 2.7: (V, 0)); the field below turns tangent (alpha = 1) when k x = mu, so the
    block leaves at t = (mu/k - x0)/V. Before: arrival from (x0, v0), v0 < V, on the slip
    ellipse x = c + (x0 - c) cos(w t) + (v0/w) sin(w t), c = mu/k, w = sqrt(k)."""
    k, mu, V = 2.0, 1.0, 0.5
    w, c = math.sqrt(k), mu / k
    # start on the surface
    x0 = -0.3
    for sliding in ("convex", "utkin"):
        traj = pwsdyn.simulate(belt(k=k, mu=mu, V=V), [x0, V], (0.0, 5.0), sliding=sliding)
        end = traj.events_of("slide_end")[0]
        assert end.t == pytest.approx((mu / k - x0) / V, abs=1e-9)
        assert end.mode_after == "slip[v-V<0]"
    # arrive from below, then stick, then leave
    x0, v0 = -0.3, 0.0
    R, phi = math.hypot(v0, (x0 - c) * w), math.atan2((x0 - c) * w, v0)
    # v(t) = -(x0 - c) w sin(w t) + v0 cos(w t) = R cos(w t + phi) = V, with v increasing:
    # w t + phi = -acos(V/R) (mod 2 pi)
    ta = ((-math.acos(V / R) - phi) % (2 * math.pi)) / w
    xa = c + (x0 - c) * math.cos(w * ta) + v0 / w * math.sin(w * ta)
    assert abs(k * xa) < mu
    traj = pwsdyn.simulate(belt(k=k, mu=mu, V=V), [x0, v0], (0.0, 10.0))
    start, end = traj.events_of("slide_start")[0], traj.events_of("slide_end")[0]
    assert start.t == pytest.approx(ta, abs=1e-9)
    assert end.t == pytest.approx(ta + (mu / k - xa) / V, abs=1e-9)


def test_pseudo_equilibrium_is_reached_and_held():
    """y' = -sign(y), x' = -x + sign(y): on y = 0, alpha = 1/2 and f12 = (-x, 0), so x decays
    to the pseudo-equilibrium (0, 0) as x0 exp(-t) and stays, without chattering."""
    m = {"name": "pseudo", "states": ["x", "y"],
         "modes": {"m": {"x": "-x + sign(y)", "y": "-sign(y)"}}}
    traj = pwsdyn.simulate(m, [2.0, 0.0], (0.0, 30.0))
    assert traj.events == [] and traj.state[-1].startswith("slide:")
    tt = np.linspace(0, 30, 61)
    np.testing.assert_allclose(traj(tt)[:, 0], 2.0 * np.exp(-tt), rtol=0, atol=1e-10)
    assert np.max(np.abs(traj.x[:, 1])) == 0.0


def test_stabilising_term_holds_a_curved_sliding_surface():
    """Sliding on the unit circle h = x^2 + y^2 - 1 with f = (-y, x) - sign(h) (x, y): the
    sliding field is the rotation (-y, x), so x = cos t, y = sin t. The surface is curved,
    so the Runge-Kutta steps drift off it; the term -C h grad h / |grad h|^2 (slides) pulls
    the state back (by default each accepted step is projected onto h = 0): |h| stays at
    round-off level and the phase is exact to 1e-8 after 16 turns, also with the continuous
    term of gain C = 1 instead of the projection."""
    m = {"name": "circle", "states": ["x", "y"],
         "modes": {"m": {"x": "-y - x*sign(x**2 + y**2 - 1)",
                         "y": "x - y*sign(x**2 + y**2 - 1)"}}}
    for gain, htol in ((0.0, 1e-14), (1.0, 1e-10)):
        traj = pwsdyn.simulate(m, [1.0, 0.0], (0.0, 100.0), sliding_gain=gain)
        assert traj.events == []
        h = traj.x[:, 0] ** 2 + traj.x[:, 1] ** 2 - 1
        assert np.max(np.abs(h)) <= htol
        np.testing.assert_allclose(traj.x[:, 0], np.cos(traj.t), atol=1e-8)


# ======================================================================================
# sign() and explicit modes; an independent scipy solution
# ======================================================================================

FORCED = dict(mu=0.5, V=0.2, A=0.8, w=0.7)


def test_sign_model_and_explicit_switch_give_the_same_trajectory():
    """The forced friction oscillator written with mu*sign(v - V) and as two modes with a
    switch: same events (6 stick phases, 8 crossings) and the same dense output to 1e-9."""
    a = pwsdyn.simulate(belt(**FORCED), [0.5, 0.0], (0.0, 60.0))
    b = pwsdyn.simulate(belt_explicit(**FORCED), [0.5, 0.0], (0.0, 60.0))
    assert a.event_counts() == b.event_counts() == {"slide_start": 6, "slide_end": 6,
                                                    "crossing": 8}
    assert [e.kind for e in a.events] == [e.kind for e in b.events]
    np.testing.assert_allclose(a.event_times(), b.event_times(), rtol=0, atol=1e-9)
    tt = np.linspace(0.0, 60.0, 1201)
    np.testing.assert_allclose(a(tt), b(tt), rtol=0, atol=1e-9)


def _scipy_filippov_belt(p, x0, t_end):
    """Hand-written Filippov solution of the forced belt with scipy (DOP853, rtol 1e-13):
    slip phases with the friction sign fixed and a terminal event at v = V; there the stick
    condition |F| <= mu on the other forces F = -k x + A cos(w t) decides between sticking
    (x' = V, v' = 0 until F = +-mu) and crossing. Returns the stick intervals."""
    k, mu, V, A, w = p["k"], p["mu"], p["V"], p["A"], p["w"]
    opts = dict(method="DOP853", rtol=1e-13, atol=1e-14)

    def force(t, u):
        return -k * u[0] + A * math.cos(w * t)

    def belt_ev(t, u):
        return u[1] - V

    def release(sign):
        def ev(t, u):
            return force(t, u) - sign * mu
        ev.terminal = True
        return ev

    belt_ev.terminal = True
    t, u, phase, sticks = 0.0, np.array(x0, float), (1 if x0[1] > V else -1), []
    # slip phases end when v reaches V from their side (so a restart on v = V never fires)
    while t < t_end:
        if phase == 0:
            sol = solve_ivp(lambda t, u: [V, 0.0], (t, t_end), u, events=(release(1),
                                                                         release(-1)), **opts)
            if sol.status != 1:
                sticks.append((t, t_end))
                break
            i = 0 if sol.t_events[0].size else 1
            te = sol.t_events[i][0]
            sticks.append((t, te))
            t, u = te, sol.y_events[i][0]
            phase = 1 if i == 0 else -1   # F = +mu pushes forward: v > V
            continue
        belt_ev.direction = -phase
        sol = solve_ivp(lambda t, u: [u[1], force(t, u) - phase * mu], (t, t_end), u,
                        events=belt_ev, **opts)
        if sol.status != 1:
            break
        t, u = sol.t_events[0][0], sol.y_events[0][0].copy()
        u[1] = V
        f = force(t, u)
        phase = 0 if abs(f) <= mu else -phase
    return sticks


def test_stick_phases_of_a_forced_belt_match_scipy():
    """The stick phases (entry and exit located by pwsdyn) agree with a hand-written scipy
    Filippov solution at rtol 1e-13 to 1e-8."""
    p = {"k": 1.0, **FORCED}
    traj = pwsdyn.simulate(belt(**FORCED), [0.5, 0.0], (0.0, 60.0))
    ref = _scipy_filippov_belt(p, [0.5, 0.0], 60.0)
    got = traj.sliding_intervals()
    assert len(got) == len(ref) == 6
    np.testing.assert_allclose(np.array([g[:2] for g in got]), np.array(ref), rtol=0, atol=1e-8)


def test_smoothed_reference_approaches_the_sliding_solution():
    """sign(v - V) -> tanh((v - V)/eps), integrated with scipy Radau at rtol 1e-12: the
    distance to pwsdyn's Filippov solution decreases like eps (measured: 0.31, 0.043,
    0.0048, 5.3e-4 for eps = 1e-1 ... 1e-4)."""
    V, T = 0.2, 15.0
    traj = pwsdyn.simulate(belt(V=V, mu=1.0), [0.0, 0.0], (0.0, T))
    # one sticking phase. The slip after it returns one period later exactly to where
    # sticking ended, (x, v) = (1, V), tangent to the surface: a touch whose time is defined
    # only to ~sqrt(eps), which rounding may log as a sliding episode of zero length (3e-8)
    slides = traj.sliding_intervals()
    assert slides[0][1] - slides[0][0] > 4.0
    assert all(b - a < 1e-6 for a, b, _ in slides[1:]), slides
    tt = np.linspace(0.0, T, 301)
    ref = traj(tt)
    errors = []
    for eps in (1e-1, 1e-2, 1e-3, 1e-4):
        def rhs(t, u, eps=eps):
            return [u[1], -u[0] - math.tanh((u[1] - V) / eps)]

        def jac(t, u, eps=eps):
            s = (u[1] - V) / eps
            sech2 = 0.0 if abs(s) > 350 else 1.0 / math.cosh(s) ** 2
            return [[0.0, 1.0], [-1.0, -sech2 / eps]]

        sol = solve_ivp(rhs, (0.0, T), [0.0, 0.0], method="Radau", rtol=1e-12, atol=1e-12,
                        jac=jac, t_eval=tt)
        errors.append(np.max(np.abs(sol.y.T - ref)))
    assert all(b < 0.2 * a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-3


# ======================================================================================
# Utkin's equivalent control
# ======================================================================================

def test_equivalent_control_differs_where_the_switch_enters_nonlinearly():
    """x' = g(sign(y)), y' = -sign(y) + 0.5 slides on y = 0. Convex method (thesis eq.
    2.7-2.8): alpha = 0.25, x' = 0.75 g(1) + 0.25 g(-1). Equivalent control (slides):
    -u + 0.5 = 0, u = 0.5, x' = g(0.5). For g(u) = u^2 and g(u) = exp(u), in closed form."""
    for g, convex, utkin in (("sign(y)**2", 1.0, 0.25),
                             ("exp(sign(y))", 0.75 * math.e + 0.25 / math.e, math.exp(0.5))):
        m = {"name": "nonlinear-switch", "states": ["x", "y"],
             "modes": {"m": {"x": g, "y": "-sign(y) + 0.5"}}}
        for sliding, rate in (("convex", convex), ("utkin", utkin)):
            traj = pwsdyn.simulate(m, [0.0, 0.0], (0.0, 2.0), sliding=sliding)
            assert traj.x_final[0] == pytest.approx(2.0 * rate, abs=1e-12)


def test_equivalent_control_exit_when_u_reaches_one():
    """y' = -sign(y) + c t, x' = sign(y)**3, sliding on y = 0 from t = 0. Equivalent control:
    u = c t, x' = (c t)^3; convex method: alpha = (1 - c t)/2, x' = 1 - 2 alpha = c t. Both
    leave the surface (upwards) at t = 1/c, where u = 1 and alpha = 0, with
    x = 1/(4c) (Utkin) and 1/(2c) (convex)."""
    c = 0.4
    m = {"name": "exit", "states": ["x", "y"], "parameters": {"c": c},
         "modes": {"m": {"x": "sign(y)**3", "y": "-sign(y) + c*t"}}}
    for sliding, x_exit in (("utkin", 1 / (4 * c)), ("convex", 1 / (2 * c))):
        traj = pwsdyn.simulate(m, [0.0, 0.0], (0.0, 4.0), sliding=sliding)
        end = traj.events_of("slide_end")[0]
        assert end.t == pytest.approx(1 / c, abs=1e-9)
        assert end.mode_after == "m[y>0]"
        assert end.x_before[0] == pytest.approx(x_exit, abs=1e-10)


# ======================================================================================
# several surfaces
# ======================================================================================

TWO_SURFACES = {"name": "two-surfaces", "states": ["x", "y", "z"],
                "modes": {"m": {"x": "1", "y": "-sign(y) + 0.5*sign(x)",
                                "z": "sign(x)*(1 + 0.5*sign(y))"}}}


def test_sliding_on_one_surface_while_crossing_another():
    """Slides on y = 0 from t = 0.2 and crosses x = 0 at t = 1 while sliding. On y = 0 the
    convex parameter is alpha = (1 - 0.5 s)/2 (s = sign(x)), so z' = s (1.5 - alpha):
    -0.75 before the crossing, 1.25 after it; z(3) = -1.5*0.2 - 0.75*0.8 + 1.25*2 = 1.6."""
    traj = pwsdyn.simulate(TWO_SURFACES, [-1.0, 0.3, 0.0], (0.0, 3.0))
    assert [(e.kind, e.name) for e in traj.events] == [("slide_start", "y"), ("crossing", "x")]
    assert traj.events[0].t == pytest.approx(0.2, abs=1e-12)
    assert traj.events[1].t == pytest.approx(1.0, abs=1e-12)
    assert traj.events[1].mode_before == traj.events[1].mode_after == "slide:y"
    assert traj.x_final[2] == pytest.approx(1.6, abs=1e-12)
    assert np.max(np.abs(traj.x[traj.t >= 0.2, 1])) <= 1e-14
    assert traj.sliding_intervals() == [(pytest.approx(0.2), 3.0, "y")]


def test_reaching_a_non_attracting_intersection_while_sliding_is_reported():
    """x' = -sign(x), y' = sign(y) (1/2 - 3/2 sign(x)) + 3/4 from (1, 1/8): slides on y = 0
    from t = 1/2 (y' = -1/4 above, 7/4 below) and reaches x = y = 0 at t = 1, where the
    sliding field points into x = 0; beyond it y = 0 repels (y' = 11/4 above, -5/4 below). The
    bilinear weights solve u_x = 0 and u_y/2 + 3/4 = 0: u_y = -3/2 outside [-1, 1]
    (lambda_y = 5/4), the intersection is not attracting, and the run ends there. (An
    attracting intersection is slid on: tests/test_intersections.py.)"""
    m = {"name": "corner", "states": ["x", "y"],
         "modes": {"m": {"x": "-sign(x)", "y": "sign(y)*(0.5 - 1.5*sign(x)) + 0.75"}}}
    traj = pwsdyn.simulate(m, [1.0, 0.125], (0.0, 3.0), throw=False)
    assert traj.status == Status.SURFACE_INTERSECTION
    assert traj.t_final == pytest.approx(1.0, abs=1e-12)
    assert np.max(np.abs(traj.x_final)) <= 1e-12
    assert "intersection of switching surfaces" in traj.message
    assert "not attracting" in traj.message
    # t = 1 to rounding
    with pytest.raises(SolveError, match=r"intersection.*Stopped at t=(1\b|0\.999999999999)"):
        pwsdyn.simulate(m, [1.0, 0.125], (0.0, 3.0))


def test_kinks_of_max_min_are_located_and_crossed():
    """Bilinear spring x'' = -k1 max(x, 0) - k2 min(x, 0): half periods pi/sqrt(k1) in
    x > 0 and pi/sqrt(k2) in x < 0, amplitudes v0/sqrt(k1) and v0/sqrt(k2)."""
    k1, k2 = 1.0, 4.0
    m = {"name": "bilinear", "states": ["x", "v"], "parameters": {"k1": k1, "k2": k2},
         "modes": {"m": {"x": "v", "v": "-k1*Max(x, 0) - k2*Min(x, 0)"}}}
    traj = pwsdyn.simulate(m, [0.0, 1.0], (0.0, 20.0))
    assert {e.kind for e in traj.events} == {"crossing"}
    h1, h2 = math.pi / math.sqrt(k1), math.pi / math.sqrt(k2)
    expect = np.cumsum([h1, h2] * 10)
    expect = expect[expect < 20.0]
    np.testing.assert_allclose(traj.event_times(), expect, rtol=0, atol=1e-10)
    # each half is harmonic: the kink is crossed with speed |v0| and the amplitudes are
    # v0/sqrt(k) (dense output on a fine grid)
    np.testing.assert_allclose(np.abs([e.x_before[1] for e in traj.events]), 1.0, atol=1e-9)
    xs = traj(np.linspace(0.0, 20.0, 200001))[:, 0]
    assert xs.max() == pytest.approx(1 / math.sqrt(k1), abs=1e-8)
    assert xs.min() == pytest.approx(-1 / math.sqrt(k2), abs=1e-8)


def test_start_in_a_mode_on_the_wrong_side_is_corrected():
    """A switch decides the mode from the side of h: asking for 'f1' (above) at x2 < 0 runs
    'f2'; the slide then starts where the f2 circle about (1, 0) reaches x2 = 0."""
    traj = pwsdyn.simulate(THESIS_EXPLICIT, [0.5, -0.5, 0.0], (0.0, 20.0), mode="f1")
    assert traj.state[0] == "f2"
    start = traj.events_of("slide_start")[0]
    # (x1 - 1)^2 + x2^2 = 0.5: x2 = 0 at x1 = 1 - sqrt(0.5), after atan2(0.5, 0.5) = pi/4
    assert start.t == pytest.approx(math.pi / 4, abs=1e-12)
    assert start.x_after[0] == pytest.approx(1 - math.sqrt(0.5), abs=1e-9)


# ======================================================================================
# stick-slip with static > dynamic friction (thesis eq. 5.4), impacts and friction
# ======================================================================================

def test_stick_slip_with_static_friction_above_dynamic_matches_hand_derivation():
    """Belt with Fs > Fd as guarded modes (thesis eq. 5.4 on a belt). From a stick at x0 the
    block moves with the belt until k x = Fs: t1 = (Fs/k - x0)/V. It slips back on the
    ellipse about c = Fd/k through (Fs/k, V): x - c = A cos(w t) + (V/w) sin(w t),
    A = (Fs - Fd)/k, and meets v = V again at w t = 2 pi - 2 atan(A w/V), at x_r, where
    |k x_r| <= Fs: it sticks again for (Fs/k - x_r)/V."""
    m_, k, V, Fs, Fd = 1.0, 2.0, 0.5, 1.0, 0.6
    w = math.sqrt(k / m_)
    x0 = 0.1
    traj = pwsdyn.simulate(belt_fs_fd(k=k, V=V, Fs=Fs, Fd=Fd), [x0, V], (0.0, 12.0))
    names = [e.name for e in traj.events]
    assert names[:4] == ["break_fwd", "stick_from_neg", "break_fwd", "stick_from_neg"]
    t1 = (Fs / k - x0) / V
    A = (Fs - Fd) / k
    theta = 2 * math.pi - 2 * math.atan(A * w / V)
    xr = Fd / k + A * math.cos(theta) + V / w * math.sin(theta)
    assert abs(k * xr) <= Fs
    t2 = t1 + theta / w
    t3 = t2 + (Fs / k - xr) / V
    np.testing.assert_allclose(traj.event_times()[:3], [t1, t2, t3], rtol=0, atol=1e-9)
    assert traj.events[1].x_before[0] == pytest.approx(xr, abs=1e-9)
    # the stick interval, the number the issue asks for
    assert t3 - t2 == pytest.approx((Fs / k - xr) / V, abs=1e-9)


def test_stick_slip_reverses_instead_of_sticking_outside_the_static_region():
    """With a large start on the slip ellipse the block comes to v = V where k x > Fs: the
    guard sends it on into slip_neg (reverse), not into stick (guards on one surface)."""
    traj = pwsdyn.simulate(belt_fs_fd(), [3.0, 2.0], (0.0, 3.0), mode="slip_pos")
    first = traj.events[0]
    assert first.name == "pass_from_pos" and first.mode_after == "slip_neg"
    assert first.x_before[0] > 1.0


def test_friction_impact_oscillator_stick_interval_ends_at_the_impact_in_closed_form():
    """Zoo model (thesis eq. 3.3-3.5, 5.4): a mass at rest at q_s is hit when the constraint
    -b + a sin(omega t) reaches it: omega t = asin((q_s + b)/a) + 2 pi n, the first such
    time after it came to rest. The constraint never passes through the mass (checked on a
    fine grid of the dense output, not only at the steps)."""
    m = pwsdyn.load_model("friction-impact-oscillator")
    p = m.parameters
    traj = pwsdyn.simulate(m, [0.0, 0.0], (0.0, 200.0))
    ev = traj.events
    n_checked = 0
    for e0, e1 in zip(ev, ev[1:]):
        if e0.mode_after != "stick":
            continue
        assert e1.kind == "impact"
        qs = e0.x_after[0]
        assert abs(p["k"] * qs) <= p["Fs"]
        phi = math.asin((qs + p["b"]) / p["a"])
        n = math.ceil((p["omega"] * e0.t - phi) / (2 * math.pi))
        t_hit = (phi + 2 * math.pi * n) / p["omega"]
        assert e1.t == pytest.approx(t_hit, abs=1e-9)
        n_checked += 1
    assert n_checked >= 20
    tt = np.linspace(0.0, 200.0, 40001)
    q = traj(tt)[:, 0]
    assert np.min(q + p["b"] - p["a"] * np.sin(p["omega"] * tt)) >= -1e-9
    # impact law (thesis eq. 3.5): relative velocity reversed with restitution e
    for e in traj.events_of("impact"):
        vc = p["a"] * p["omega"] * math.cos(p["omega"] * e.t)
        assert e.x_after[1] - vc == pytest.approx(-p["e"] * (e.x_before[1] - vc), abs=1e-12)


def test_impacts_while_sliding_agree_with_the_guarded_modes():
    """The friction-impact oscillator with Fs = Fd written with sign(v) (a Filippov switch:
    the mass rests by sliding on v = 0 and impacts happen while sliding) and the zoo's guarded
    modes with Fs = Fd: the same 26 impacts and trajectory to 1e-9."""
    zoo = pwsdyn.load_model("friction-impact-oscillator")
    p = dict(zoo.parameters)
    sgn = {"name": "fio-sign", "states": ["q", "v"],
           "parameters": {k: p[k] for k in ("m", "k", "Fd", "a", "b", "omega", "e")},
           "modes": {"free": {"q": "v", "v": "(-k*q - Fd*sign(v))/m"}},
           "events": [{"name": "impact", "kind": "impact", "surface": "q + b - a*sin(omega*t)",
                       "reset": {"v": "(1 + e)*a*omega*cos(omega*t) - e*v"}}]}
    a = pwsdyn.simulate(zoo, [0.0, 0.0], (0.0, 200.0), params={"Fs": p["Fd"]})
    b = pwsdyn.simulate(sgn, [0.0, 0.0], (0.0, 200.0))
    assert b.state[0] == "slide:v"
    ia, ib = a.event_times("impact"), b.event_times("impact")
    assert len(ia) == len(ib) >= 20
    np.testing.assert_allclose(ia, ib, rtol=0, atol=1e-9)
    assert all(e.mode_before == "slide:v" for e in b.events_of("impact"))
    tt = np.linspace(0.0, 200.0, 4001)
    np.testing.assert_allclose(a(tt), b(tt), rtol=0, atol=1e-9)


# ======================================================================================
# relay feedback, quarter car, zoo and CLI
# ======================================================================================

def test_relay_feedback_runs_through_many_sliding_segments_per_period():
    """di Bernardo et al. (2001) / Piiroinen & Kuznetsov (2008): the symmetric periodic orbit
    (x(t + T/2) = -x(t)) has 14 sliding segments per period. Steps per period and the
    smallest step are bounded (no step-size collapse at the many entries and exits), and
    Utkin's equivalent control agrees with the convex method (the relay enters affinely)."""
    traj = pwsdyn.simulate("relay-feedback", [0.0, -0.001, -0.02], (0.0, 60.0))
    assert traj.success
    slides = traj.sliding_intervals()
    longs = [a for a, b, _ in slides if b - a > 0.5]
    t0, t_half, t1 = longs[-3], longs[-2], longs[-1]
    T = t1 - t0
    assert T == pytest.approx(5.9618, abs=1e-3)
    assert t_half - t0 == pytest.approx(T / 2, abs=1e-9)
    np.testing.assert_allclose(traj(t_half, side="right"), -traj(t0, side="right"), atol=1e-8)
    n_seg = sum(1 for a, _, _ in slides if t0 <= a < t1)
    assert n_seg == 14
    inside = (traj.t[:-1] >= t0) & (traj.t[1:] <= t1)
    dt = np.diff(traj.t)[inside]
    dt = dt[dt > 0]
    assert len(dt) < 2000          # measured: 1428 steps per period at rtol 1e-10
    assert dt.min() > 1e-4         # measured: 3.9e-4
    utkin = pwsdyn.simulate("relay-feedback", [0.0, -0.001, -0.02], (0.0, 60.0),
                            sliding="utkin")
    np.testing.assert_allclose(utkin.x_final, traj.x_final, atol=1e-9)


def test_quarter_car_bumpstop_damping_kinks_and_wheel_hop():
    """Zoo quarter-car (thesis Paper C): natural frequencies about 1 Hz and 10 Hz; bumpstop
    impacts conserve momentum and reverse the relative velocity with restitution r; the
    damper kink (vr = 0) and the loss of tyre contact (tyre load = 0) are located on their
    surfaces."""
    m = pwsdyn.load_model("quarter-car")
    p = m.parameters
    K = np.array([[p["ks"], -p["ks"]], [-p["ks"], p["ks"] + p["kt"]]])
    M = np.diag([p["ms"], p["mu"]])
    f = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real)) / (2 * np.pi)
    assert f[0] == pytest.approx(1.0, rel=0.1) and f[1] == pytest.approx(10.0, rel=0.1)
    traj = pwsdyn.simulate(m, m.spec["defaults"]["x0"], (0.0, 4.0))
    counts = {}
    for e in traj.events:
        counts[(e.kind, e.name)] = counts.get((e.kind, e.name), 0) + 1
    assert counts[("impact", "bumpstop")] >= 10 and counts[("chatter", "bumpstop")] >= 1
    assert counts[("crossing", "vr")] >= 10 and counts[("crossing", "tyre")] >= 2
    r, ms, mu = p["r"], p["ms"], p["mu"]
    for e in traj.events_of("impact"):
        b, a = e.x_before, e.x_after
        assert a[1] - a[3] == pytest.approx(-r * (b[1] - b[3]), abs=1e-12)
        assert ms * a[1] + mu * a[3] == pytest.approx(ms * b[1] + mu * b[3], abs=1e-10)
        assert b[0] - b[2] + p["delta"] == pytest.approx(0.0, abs=1e-12)
    for e in traj.events_of("crossing"):
        x = e.x_before
        if e.name == "vr":
            assert abs(x[1] - x[3]) <= 1e-12
        else:
            zr = p["A"] * math.sin(p["omega"] * e.t)
            assert abs((ms + mu) * p["g"] + p["kt"] * (zr - x[2])) <= 1e-7


NEW_ZOO = ["friction-impact-oscillator", "stick-slip-oscillator", "relay-feedback",
           "quarter-car"]


@pytest.mark.parametrize("name", NEW_ZOO)
def test_new_zoo_models_run_from_the_cli_with_a_figure(name, tmp_path):
    m = pwsdyn.load_model(name)
    assert m.description and m.reference and m.spec["defaults"]["t_end"] > 0
    out = tmp_path / f"{name}.png"
    res = CliRunner().invoke(cli_main, ["simulate", name, "--plot", str(out)])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 20_000
    assert "SUCCESS" in res.output
    if m.switches:
        assert "switching" in res.output


def test_cli_summary_counts_crossings_sliding_segments_and_time():
    """The stick-slip oscillator from rest: 4 stick phases in 40 time units; the summary's
    total sliding time is the sum of the stick phases of the trajectory."""
    res = CliRunner().invoke(cli_main, ["simulate", "stick-slip-oscillator", "--sliding",
                                        "utkin"])
    assert res.exit_code == 0, res.output
    traj = pwsdyn.simulate("stick-slip-oscillator", [0.0, 0.0], (0.0, 40.0), sliding="utkin")
    total = sum(b - a for a, b, _ in traj.sliding_intervals())
    line = next(ln for ln in res.output.splitlines() if ln.startswith("switching"))
    assert "0 crossings, 4 sliding segments" in line
    assert f"{total:.10g}" in line
    # the first stick phase runs from the arrival to x = Fs/k at the belt speed
    a, b, _ = traj.sliding_intervals()[1]
    x_a = traj(a, side="right")[0]
    assert b - a == pytest.approx((1.0 - x_a) / 0.2, abs=1e-9)


def test_dop853_slides_as_well():
    traj = pwsdyn.simulate(belt(k=2.0), [-0.3, 0.5], (0.0, 5.0), method="DOP853")
    assert traj.events_of("slide_end")[0].t == pytest.approx((0.5 + 0.3) / 0.5, abs=1e-9)
