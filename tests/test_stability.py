"""Variational equations, saltation matrices, transfer matrices, Poincaré maps (issue 4).

Every Jacobian the kernel integrates is checked against something that does not use it:
central finite differences of event-driven scipy flows (``tests/_hybrid_reference.py``,
DOP853 at rtol 1e-12, restarted at each event), closed-form saltation matrices written out by
hand, and the Liouville identity with the divergence integrated by scipy.
"""

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import pwsdyn
from pwsdyn.stability import (SectionNotReachedError, event_saltations, floquet_multipliers,
                              monodromy, poincare_map, saltation_matrix, segments)

sys.path.insert(0, str(Path(__file__).parent))
from _hybrid_reference import (belt_flow, central_fd, impacting_flow, jumper_flow,  # noqa: E402
                               rel_err)

#: Tight integration for the pwsdyn side of every comparison.
TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-12)
#: Relative step of the central differences: truncation ~ h^2 and noise ~ 1e-12 / h both stay
#: well below 1e-6 (measured: 1e-8 .. 3e-9 for h = 1e-5 on the flows below).
FD_STEP = 1e-5
#: Acceptance: Jacobians agree with central differences of the scipy flow to 1e-6 relative.
FD_TOL = 1e-6

IO = dict(eps=0.1, sigma=-0.5, omega=2.8, r=0.8)

# Forced dry-friction oscillator on a belt (Filippov): crossings, sliding entry and exit.
BELT = {
    "name": "belt-forced", "states": ["x", "v"],
    "parameters": {"k": 1.0, "c": 0.05, "mu": 0.5, "vb": 0.3, "A": 1.5, "w": 1.2},
    "forcing_period": "2*pi/w",
    "modes": {"above": {"x": "v", "v": "-k*x - c*v - mu + A*cos(w*t)"},
              "below": {"x": "v", "v": "-k*x - c*v + mu + A*cos(w*t)"}},
    "switches": [{"name": "slip", "surface": "v - vb", "above": "above", "below": "below"}],
}

# Van der Pol oscillator against a wall: an autonomous impacting limit cycle whose divergence
# mu (1 - x^2) is not constant (for the Liouville identity).
VDP_WALL = {
    "name": "vdp-wall", "states": ["x", "v"],
    "parameters": {"mu": 1.0, "sigma": 1.5, "r": 0.7},
    "modes": {"free": {"x": "v", "v": "mu*(1 - x**2)*v - x"}},
    "events": [{"name": "wall", "kind": "impact", "surface": "sigma - x", "reset": {"v": "-r*v"}}],
}


def _io_rhs(t, y, eps=0.1, omega=2.8):
    return [y[1], np.sin(omega * t) - eps * y[1] - y[0]]


# ======================================================================================
# flow Jacobians across events against finite differences of scipy flows
# ======================================================================================

def test_flow_jacobian_across_impacts_matches_scipy_fd():
    """Impact oscillator (3 impacts in the window): kernel Jacobian with full saltation
    matrices vs central differences of the scipy flow restarted at each impact."""
    x0, t0, t1 = np.array([-0.7, 0.1]), 0.3, 6.0
    tr = pwsdyn.simulate("impact-oscillator", x0, (t0, t1), params=IO, variational=True, **TIGHT)
    assert tr.event_counts() == {"impact": 3}

    def flow(x):
        return impacting_flow(_io_rhs, lambda t, y: -0.5 - y[0],
                              lambda t, y: np.array([y[0], -0.8 * y[1]]), x, t0, t1)[0]

    assert rel_err(tr.jacobian, central_fd(flow, x0, FD_STEP)) < FD_TOL


def test_flow_jacobian_across_moving_surface_matches_scipy_fd():
    """Bouncing ball on a vibrating table: time-dependent surface h = y - A sin(w t) and reset
    v+ = s' - e (v - s'); the saltation matrix needs the h_t and g_t terms."""
    p = dict(A=0.224, omega=2 * np.pi)
    g, e, A, w = 9.81, 0.8, p["A"], p["omega"]
    x0, t0, t1 = np.array([1.5, 0.0]), 0.0, 2.5
    tr = pwsdyn.simulate("bouncing-ball", x0, (t0, t1), params=p, variational=True, **TIGHT)
    assert tr.event_counts() == {"impact": 3}

    def reset(t, y):
        sd = A * w * np.cos(w * t)
        return np.array([y[0], sd - e * (y[1] - sd)])

    def flow(x):
        return impacting_flow(lambda t, y: [y[1], -g], lambda t, y: y[0] - A * np.sin(w * t),
                              reset, x, t0, t1)[0]

    assert rel_err(tr.jacobian, central_fd(flow, x0, FD_STEP)) < FD_TOL


def test_flow_jacobian_across_crossing_and_sliding_matches_scipy_fd():
    """Forced belt oscillator: a crossing, sliding entry, sliding exit and three more crossings;
    the scipy reference slides by hand (x' = vb on v = vb) until the below field's normal
    velocity vanishes."""
    x0, t0, t1 = np.array([0.5, 0.0]), 0.0, 12.0
    tr = pwsdyn.simulate(BELT, x0, (t0, t1), variational=True, **TIGHT)
    kinds = [e.kind for e in tr.events]
    assert kinds == ["crossing", "slide_start", "slide_end", "crossing", "crossing", "crossing"]
    p = BELT["parameters"]
    assert belt_flow(p, x0, t0, t1)[1] == kinds
    J = central_fd(lambda x: belt_flow(p, x, t0, t1)[0], x0, FD_STEP)
    assert rel_err(tr.jacobian, J) < FD_TOL


def test_flow_jacobian_across_chattering_matches_scipy_fd():
    """One-legged jumper through landing, complete chattering (the map Q, q of the slides at
    the first impact: chatter_ratio = 1), sticking and release. The scipy reference applies the
    same map and integrates the sticking phase with the foot on the ground."""
    m = pwsdyn.load_model("one-legged-jumper")
    Tf = 2 * np.pi / m.parameters["omega"]
    t0 = 50.4 * Tf
    x0 = pwsdyn.simulate(m, [1.5, 0, 10.5, 0], (0, t0), dense=False).x_final  # in flight
    t1 = t0 + 1.3 * Tf
    tr = pwsdyn.simulate(m, x0, (t0, t1), variational=True, chatter_ratio=1.0, **TIGHT)
    kinds = [e.kind for e in tr.events]
    assert kinds == ["chatter", "stick", "release"]
    ref, ref_kinds = jumper_flow(m.parameters, x0, t0, t1)
    assert ref_kinds == kinds
    assert np.max(np.abs(tr.x_final - ref)) < 1e-9          # the same map, two integrators
    J = central_fd(lambda x: jumper_flow(m.parameters, x, t0, t1)[0], x0, FD_STEP)
    assert rel_err(tr.jacobian, J) < FD_TOL
    # sticking constrains two directions (h and hdot): the Jacobian has rank n - 2
    sv = np.linalg.svd(tr.jacobian, compute_uv=False)
    assert sv[-1] < 1e-8 * sv[0] and sv[-2] < 1e-8 * sv[0] and sv[-3] > 1e-3 * sv[0]


# ======================================================================================
# saltation matrices: closed forms and the two forms
# ======================================================================================

def test_impact_saltation_closed_form():
    """Impact oscillator at x = sigma with velocity v: f_in = (v, F - sigma - eps v),
    f_out = (-r v, F - sigma + eps r v), h_x = (-1, 0), g_x = diag(1, -r) give (by hand)
    S = [[-r, 0], [(1 + r)(F - sigma)/v, -r]], det S = r^2, with F = sin(omega t)."""
    x0, t0, t1 = np.array([-0.7, 0.1]), 0.3, 3.0
    tr = pwsdyn.simulate("impact-oscillator", x0, (t0, t1), params=IO, variational=True, **TIGHT)
    (ev,) = tr.events
    v, F, r = ev.x_before[1], np.sin(IO["omega"] * ev.t), IO["r"]
    S_hand = np.array([[-r, 0.0], [(1 + r) * (F - IO["sigma"]) / v, -r]])
    S_kernel = tr.transfer_matrices[1]
    np.testing.assert_allclose(S_kernel, S_hand, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(saltation_matrix("impact-oscillator", "impact", ev.t, ev.x_before,
                                                params=IO), S_hand, rtol=1e-13, atol=1e-13)
    assert abs(np.linalg.det(S_kernel) - r**2) < 1e-13


def test_sliding_entry_saltation_closed_form():
    """Sliding entry on v = vb: S = I + (f_s - f_in) h_x / (h_x f_in) with the sliding field
    f_s = (vb, 0) and h_x = (0, 1): the normal direction is lost, h_x S = 0."""
    tr = pwsdyn.simulate(BELT, [0.5, 0.0], (0, 12), variational=True, **TIGHT)
    k = [e.kind for e in tr.events].index("slide_start")
    ev = tr.events[k]
    p = BELT["parameters"]
    x, t = ev.x_before, ev.t
    f_in = np.array([x[1], -p["k"] * x[0] - p["c"] * x[1] - p["mu"] + p["A"] * np.cos(p["w"] * t)])
    f_s = np.array([p["vb"], 0.0])
    hx = np.array([0.0, 1.0])
    S_hand = np.eye(2) + np.outer(f_s - f_in, hx) / (hx @ f_in)
    S = tr.transfer_matrices[2 * k + 1]
    np.testing.assert_allclose(S, S_hand, rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(hx @ S)) < 1e-12
    # the same matrix from the model's derivatives (Python), named by the switch; both fields
    # point into the surface, so the side it arrives from is given
    np.testing.assert_allclose(saltation_matrix(BELT, "slip", t, x, mode=ev.mode_before), S_hand,
                               rtol=1e-12, atol=1e-12)
    # leaving the sliding surface does not change the field: S = I
    kend = [e.kind for e in tr.events].index("slide_end")
    np.testing.assert_array_equal(tr.transfer_matrices[2 * kend + 1], np.eye(2))


def test_crossing_saltation_closed_form():
    """Crossing v = vb from one mode into the other: f_out - f_in = (0, -+2 mu) and h_x =
    (0, 1) give S = I + (f_out - f_in) h_x / (h_x f_in) = diag(1, f_out_v / f_in_v). The
    kernel's matrix and the one saltation_matrix computes for the switch by name both match."""
    p = dict(BELT["parameters"], A=3.0)
    spec = dict(BELT, parameters=p)
    tr = pwsdyn.simulate(spec, [0.5, 0.0], (0, 12), variational=True, **TIGHT)
    crossings = [k for k, e in enumerate(tr.events) if e.kind == "crossing"]
    assert len(crossings) >= 2
    for k in crossings:
        ev = tr.events[k]
        x, t = ev.x_before, ev.t
        common = -p["k"] * x[0] - p["c"] * x[1] + p["A"] * np.cos(p["w"] * t)
        above, below = common - p["mu"], common + p["mu"]
        # arriving from above the flow goes down (v' < 0), and the other way round
        f_in, f_out = (above, below) if below < 0 else (below, above)
        S_hand = np.diag([1.0, f_out / f_in])
        np.testing.assert_allclose(tr.transfer_matrices[2 * k + 1], S_hand, rtol=1e-12,
                                   atol=1e-12)
        np.testing.assert_allclose(saltation_matrix(spec, "slip", t, x), S_hand, rtol=1e-12,
                                   atol=1e-12)


def test_saltation_forms_full_and_projected():
    """Vibrating table (h_t, g_t terms): the full form from the model's derivatives (Python)
    equals the kernel's; the projected form of thesis eq. 2.36 equals S - f_out h_x / (h_t +
    h_x f_in) and maps the incoming field to 0, while S f_in = f_out."""
    p = dict(A=0.224, omega=2 * np.pi)
    g, e, A, w = 9.81, 0.8, p["A"], p["omega"]
    tr = pwsdyn.simulate("bouncing-ball", [1.5, 0.0], (0, 2.5), params=p, variational=True,
                         **TIGHT)
    full_k = event_saltations(tr, "full")
    proj = event_saltations(tr, "projected")
    for ev, S, Sp in zip(tr.events, full_k, proj):
        S_py = saltation_matrix("bouncing-ball", "impact", ev.t, ev.x_before, params=p)
        np.testing.assert_allclose(S, S_py, rtol=1e-12, atol=1e-12)
        f_in = np.array([ev.x_before[1], -g])
        f_out = np.array([ev.x_after[1], -g])
        hx = np.array([1.0, 0.0])
        ht = -A * w * np.cos(w * ev.t)
        den = ht + hx @ f_in
        np.testing.assert_allclose(Sp, S - np.outer(f_out, hx) / den, rtol=1e-12, atol=1e-12)
        gx = np.diag([1.0, -e])
        gt = np.array([0.0, -(1 + e) * A * w * w * np.sin(w * ev.t)])
        u = f_out - gx @ f_in - gt
        # in phase-extended state (t, x) the full saltation matrix maps the flow (1, f_in) to
        # (1, f_out) and the projected one maps it to 0; their time columns are
        # g_t + u h_t / den and g_t - (g_x f_in + g_t) h_t / den
        np.testing.assert_allclose(S @ f_in + gt + u * ht / den, f_out, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Sp @ f_in + gt - (gx @ f_in + gt) * ht / den, 0.0,
                                   atol=1e-12)
        # Newton restitution: det S = e^2 (relative velocities; see test_liouville)
        assert abs(np.linalg.det(S) - e**2) < 1e-12


# A transition with a nonlinear, time-dependent reset on a moving surface: every term of the
# saltation matrix (g_x, g_t, h_t) is nonzero.
KICK = {
    "name": "kicked", "states": ["x", "v"],
    "modes": {"m": {"x": "v", "v": "-x + 0.3*sin(t)"}},
    "events": [{"name": "kick", "kind": "transition", "surface": "x - 0.5*sin(t) - 0.2",
                "direction": 1, "reset": {"x": "x + 0.1*v**2", "v": "0.5*v + 0.2*cos(t)"}}],
}


def test_general_reset_saltation_fd_and_determinant():
    """Flow Jacobian across two kicks vs central differences of the scipy flow; and at each
    kick det S = det(g_x) (h_t + h_x g_x^{-1} (f_out - g_t)) / (h_t + h_x f_in) (matrix
    determinant lemma, see test_liouville), evaluated by hand from the model's formulas."""
    x0, t0, t1 = np.array([-0.3, 0.9]), 0.0, 9.0
    tr = pwsdyn.simulate(KICK, x0, (t0, t1), variational=True, **TIGHT)
    assert [e.kind for e in tr.events] == ["transition", "transition"]

    def rhs(t, y):
        return [y[1], -y[0] + 0.3 * np.sin(t)]

    def surf(t, y):
        return -(y[0] - 0.5 * np.sin(t) - 0.2)        # impacting_flow fires on decrease

    def reset(t, y):
        return np.array([y[0] + 0.1 * y[1] ** 2, 0.5 * y[1] + 0.2 * np.cos(t)])

    J = central_fd(lambda x: impacting_flow(rhs, surf, reset, x, t0, t1)[0], x0, FD_STEP)
    assert rel_err(tr.jacobian, J) < FD_TOL
    for ev, S in zip(tr.events, event_saltations(tr)):
        t, (x, v), (xo, vo) = ev.t, ev.x_before, ev.x_after
        gx = np.array([[1.0, 0.2 * v], [0.0, 0.5]])
        gt = np.array([0.0, -0.2 * np.sin(t)])
        hx, ht = np.array([1.0, 0.0]), -0.5 * np.cos(t)
        f_in = np.array(rhs(t, [x, v]))
        f_out = np.array(rhs(t, [xo, vo]))
        det = np.linalg.det(gx) * (ht + hx @ np.linalg.solve(gx, f_out - gt)) / (ht + hx @ f_in)
        assert abs(np.linalg.det(S) - det) < 1e-12 * abs(det)
        S_hand = gx + np.outer(f_out - gx @ f_in - gt, hx) / (ht + hx @ f_in)
        np.testing.assert_allclose(S, S_hand, rtol=1e-12, atol=1e-12)


def test_projected_saltation_kills_the_flow_autonomous():
    """Autonomous impact (VdP against a wall): eq. 2.36, g_x (I - f_in h_x / (h_x f_in)),
    annihilates f_in; the full form maps f_in to f_out."""
    tr = pwsdyn.simulate(VDP_WALL, [0.1, 0.0], (0, 12), variational=True, **TIGHT)
    assert tr.events
    for ev, S, Sp in zip(tr.events, event_saltations(tr), event_saltations(tr, "projected")):
        x, y = ev.x_before, ev.x_after
        f_in = np.array([x[1], (1 - x[0]**2) * x[1] - x[0]])
        f_out = np.array([y[1], (1 - y[0]**2) * y[1] - y[0]])
        gx = np.diag([1.0, -0.7])
        hx = np.array([-1.0, 0.0])
        np.testing.assert_allclose(Sp, gx @ (np.eye(2) - np.outer(f_in, hx) / (hx @ f_in)),
                                   rtol=1e-12, atol=1e-12)
        assert np.max(np.abs(Sp @ f_in)) < 1e-12
        np.testing.assert_allclose(S @ f_in, f_out, rtol=1e-10, atol=1e-10)


def test_saltation_matrix_arguments():
    with pytest.raises(ValueError, match="form"):
        saltation_matrix("impact-oscillator", "impact", 0.0, [0.0, 1.0], form="half")
    with pytest.raises(ValueError, match="grazing"):
        saltation_matrix("impact-oscillator", "impact", 0.0, [0.0, 0.0])
    with pytest.raises(ValueError, match="unknown switch"):
        saltation_matrix("impact-oscillator", "nothing", 0.0, [0.0, 1.0])


# ======================================================================================
# transfer matrices
# ======================================================================================

def test_transfer_matrices_compose_to_the_jacobian():
    """[Phi_0, S_1, Phi_1, ...]: their ordered product is the Jacobian; each Phi_k is the
    Jacobian of its smooth segment (checked against the closed-form flow of the linear
    oscillator, expm(A dt) with A = [[0, 1], [-1, -eps]])."""
    from scipy.linalg import expm

    tr = pwsdyn.simulate("impact-oscillator", [-0.7, 0.1], (0.3, 6.0), params=IO,
                         variational=True, **TIGHT)
    segs = segments(tr)
    assert len(segs) == len(tr.events) + 1 == len(tr.transfer_matrices) // 2 + 1
    np.testing.assert_allclose(monodromy(tr), tr.jacobian, rtol=1e-14, atol=1e-14)
    A = np.array([[0.0, 1.0], [-1.0, -IO["eps"]]])
    for s in segs:
        np.testing.assert_allclose(s.flow, expm(A * (s.t_end - s.t_start)), rtol=0,
                                   atol=1e-10)
    # the global Phi stored at the nodes and in the dense output is the product so far
    np.testing.assert_allclose(tr(tr.t_final, variational=True)[2:].reshape(2, 2),
                               tr.jacobian, atol=1e-14)
    tm = segs[1].t_start + 0.3 * (segs[1].t_end - segs[1].t_start)
    phi_mid = tr(tm, variational=True)[2:].reshape(2, 2)
    np.testing.assert_allclose(phi_mid, expm(A * (tm - segs[1].t_start)) @ segs[0].transfer,
                               atol=1e-9)


# ======================================================================================
# Liouville: det(monodromy) = prod det(S_i) * exp(integral of div f)
# ======================================================================================
#
# For a saltation matrix S = g_x + u h_x / den, u = f_out - g_x f_in - g_t,
# den = h_t + h_x f_in, the matrix determinant lemma gives
#     det S = det(g_x) (1 + h_x g_x^{-1} u / den)
#           = det(g_x) (h_t + h_x g_x^{-1} (f_out - g_t)) / (h_t + h_x f_in),
# the reset determinant times a ratio of normal velocities. For Newton restitution on
# mechanical coordinates (g_x = diag(1, -r), h_x = (-1, 0) or (1, 0)): det g_x = -r and the
# ratio is (velocity after / velocity before relative to the surface) = -r, so det S = r^2.
# For a Filippov crossing (g = identity) det S = (h_t + h_x f_out) / (h_t + h_x f_in).

def _liouville_io():
    from _orbit_cases import io_orbit
    orbit = io_orbit("stable")
    # div f = -eps; one impact per period with det S = r^2
    return orbit, IO["r"] ** 2 * np.exp(-IO["eps"] * orbit.period)


def _liouville_base():
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator-base", [-0.6726, 0.8576],
                                       t0=194.288013357109)
    m = pwsdyn.load_model("impact-oscillator-base").parameters
    n_imp = sum(e.kind == "impact" for e in orbit.events)
    return orbit, (m["e"] ** 2) ** n_imp * np.exp(-m["d"] / m["m"] * orbit.period)


def _liouville_ball():
    p = dict(A=0.224, omega=2 * np.pi)
    tr = pwsdyn.simulate("bouncing-ball", [1.5, 0.0], (0, 30), params=p)
    orbit = pwsdyn.PeriodicOrbit.from_trajectory(tr)
    n_imp = sum(e.kind == "impact" for e in orbit.events)
    return orbit, (0.8**2) ** n_imp        # div f = 0


def _liouville_vdp():
    tr = pwsdyn.simulate(VDP_WALL, [0.1, 0.0], (0, 60))
    orbit = pwsdyn.PeriodicOrbit.from_trajectory(tr)
    # the divergence mu (1 - x^2) integrated over one period by scipy (restarted at impacts)
    mu, sigma, r = 1.0, 1.5, 0.7

    def rhs(t, y):
        return [y[1], mu * (1 - y[0] ** 2) * y[1] - y[0], mu * (1 - y[0] ** 2)]
    y_end, times = impacting_flow(rhs, lambda t, y: sigma - y[0],
                                  lambda t, y: np.array([y[0], -r * y[1], y[2]]),
                                  np.append(orbit.x0, 0.0), 0.0, orbit.period)
    assert len(times) == 1
    return orbit, r**2 * np.exp(y_end[2])


def _liouville_belt():
    tr = pwsdyn.simulate(BELT, [0.5, 0.0], (0, 300), params={"A": 2.5})
    orbit = pwsdyn.PeriodicOrbit.from_trajectory(tr)
    assert [e.kind for e in orbit.events] == ["crossing", "crossing"]
    p = dict(BELT["parameters"], A=2.5)
    ratio = 1.0
    for e in orbit.events:
        x = e.x_before[0]
        F = p["A"] * np.cos(p["w"] * e.t)
        f_above = -p["k"] * x - p["c"] * p["vb"] - p["mu"] + F    # h_x f with h = v - vb
        f_below = -p["k"] * x - p["c"] * p["vb"] + p["mu"] + F
        ratio *= (f_below / f_above) if e.mode_before == "above" else (f_above / f_below)
    return orbit, ratio * np.exp(-p["c"] * orbit.period)


@pytest.mark.parametrize("case", [_liouville_io, _liouville_base, _liouville_ball,
                                  _liouville_vdp, _liouville_belt],
                         ids=["impact-oscillator", "base-excited", "bouncing-ball",
                              "vdp-wall-autonomous", "belt-crossings"])
def test_liouville(case):
    """det(monodromy) = prod det S_i * exp(int div f dt) to 1e-8 (relative)."""
    orbit, expected = case()
    assert orbit.converged
    det = np.linalg.det(orbit.monodromy)
    assert abs(det - expected) <= 1e-8 * abs(expected)


# ======================================================================================
# Poincaré maps
# ======================================================================================

def test_poincare_event_section_matches_scipy_fd():
    """Autonomous VdP against the wall, section = the wall: the Jacobian of eq. 2.25 (with the
    reset, side 'after') and the return-time gradient vs central differences of the scipy
    Poincaré map."""
    mu, sigma, r = 1.0, 1.5, 0.7
    x0 = np.array([0.3, 1.2])
    res = poincare_map(VDP_WALL, x0, "wall", **TIGHT)
    res_b = poincare_map(VDP_WALL, x0, "wall", side="before", **TIGHT)

    def hit(x, after=True):
        def rhs(t, y):
            return [y[1], mu * (1 - y[0] ** 2) * y[1] - y[0]]

        def ev(t, y):
            return sigma - y[0]
        ev.terminal, ev.direction = True, -1
        sol = solve_ivp(rhs, (0, 50), x, method="DOP853", rtol=1e-12, atol=1e-13, events=[ev])
        y = sol.y_events[0][0]
        return np.array([y[0], -r * y[1]] if after else y), sol.t_events[0][0]

    assert abs(res.t - hit(x0)[1]) < 1e-10
    J = central_fd(lambda x: hit(x)[0], x0, FD_STEP)
    Jb = central_fd(lambda x: hit(x, False)[0], x0, FD_STEP)
    dt = central_fd(lambda x: [hit(x)[1]], x0, FD_STEP)[0]
    # x on the section is sigma whatever x0: the first row vanishes (atol for that row)
    assert np.max(np.abs(res.jacobian - J)) < FD_TOL * np.max(np.abs(J))
    assert np.max(np.abs(res_b.jacobian - Jb)) < FD_TOL * np.max(np.abs(Jb))
    assert np.max(np.abs(res.time_gradient - dt)) < FD_TOL * np.max(np.abs(dt))
    assert np.max(np.abs(res.jacobian[0])) < 1e-12


def test_poincare_maps_at_a_periodic_point():
    """At the stable one-impact orbit of the forced impact oscillator (closed form, see
    test_orbits): the phase-extended Jacobian of the impact-section map has eigenvalues
    {0, mu_1, mu_2} (0: the projection of eq. 2.25 in place of the trivial 1), the
    stroboscopic one {1, mu_1, mu_2}; two returns give the squares."""
    from _orbit_cases import io_closed_form

    cf = io_closed_form()["stable"]
    x_imp = np.array([IO["sigma"], -IO["r"] * cf["v"]])
    res = poincare_map("impact-oscillator", x_imp, "impact", params=IO, t0=cf["t0"], **TIGHT)
    T = 2 * np.pi / IO["omega"]
    assert abs(res.t - cf["t0"] - T) < 1e-10
    assert np.max(np.abs(res.x - x_imp)) < 1e-10
    mu = np.sort_complex(cf["mu"])
    ev = np.linalg.eigvals(res.extended_jacobian)
    ev = ev[np.argsort(np.abs(ev))]
    assert abs(ev[0]) < 1e-10
    np.testing.assert_allclose(np.sort_complex(ev[1:]), mu, atol=1e-8)
    t_on = cf["t0"] + 0.3 * T                   # a point of the orbit between impacts
    strob = poincare_map("impact-oscillator", res.trajectory(t_on), "stroboscopic", params=IO,
                         t0=t_on, **TIGHT)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(strob.jacobian)), mu, atol=1e-8)
    ev = np.sort_complex(np.linalg.eigvals(strob.extended_jacobian))
    assert np.min(np.abs(ev - 1.0)) < 1e-8
    two = poincare_map("impact-oscillator", x_imp, "impact", params=IO, t0=cf["t0"], returns=2,
                       **TIGHT)
    assert abs(two.t - cf["t0"] - 2 * T) < 1e-9
    ev2 = np.linalg.eigvals(two.extended_jacobian)
    ev2 = ev2[np.argsort(np.abs(ev2))]
    np.testing.assert_allclose(np.sort_complex(ev2[1:]), np.sort_complex(mu**2), atol=1e-8)


def test_section_never_reached():
    """A wall the motion never reaches (sigma = 3, response amplitude ~0.2): a clear error
    after t_max, not a hang; the partial run is attached."""
    with pytest.raises(SectionNotReachedError, match="0 of 1") as info:
        poincare_map("impact-oscillator", [0.0, 0.0], "impact", params=dict(sigma=3.0))
    assert info.value.crossings == 0
    assert info.value.result.t_final > 100 * 2 * np.pi / 2.5 - 1e-6
    with pytest.raises(ValueError, match="unknown section"):
        poincare_map("impact-oscillator", [0.0, 0.0], "wall")
    with pytest.raises(ValueError, match="forcing_period"):
        poincare_map(VDP_WALL, [0.0, 1.0], "stroboscopic")


# ======================================================================================
# Floquet multipliers
# ======================================================================================

def test_floquet_multipliers_sorting_and_projection():
    M = np.diag([0.5, -2.0, 0.1])
    np.testing.assert_array_equal(floquet_multipliers(M), [-2.0, 0.5, 0.1])
    # an autonomous monodromy: eigenvalue 1 along f, the others 0.3 and -0.6
    V = np.array([[1.0, 0.2, 0.1], [0.3, 1.0, -0.4], [0.0, 0.5, 1.0]])
    M = V @ np.diag([1.0, 0.3, -0.6]) @ np.linalg.inv(V)
    f = V[:, 0]
    np.testing.assert_allclose(floquet_multipliers(M, flow_direction=f), [-0.6, 0.3],
                               atol=1e-13)
    np.testing.assert_allclose(floquet_multipliers(M, flow_direction=f,
                                                   section_normal=[1.0, 1.0, 1.0]),
                               [-0.6, 0.3], atol=1e-13)
    with pytest.raises(ValueError, match="tangent"):
        floquet_multipliers(M, flow_direction=f, section_normal=[0.3, -1.0, 0.0])


def test_poincare_switch_section_matches_fd_of_the_map():
    """A Filippov switch as section (forced belt, first crossing of v = vb): the Jacobian of
    eq. 2.25 and the return-time gradient against central differences of the section map
    itself (section points computed by the kernel's event location, no variational code)."""
    x0 = np.array([0.5, 0.0])
    res = poincare_map(BELT, x0, "slip", t0=0.0, **TIGHT)
    assert res.event.kind in ("crossing", "slide_start")

    def hit(x):
        r = poincare_map(BELT, x, "slip", t0=0.0, **TIGHT)
        return np.append(r.x, r.t)

    J = central_fd(hit, x0, FD_STEP)
    assert np.max(np.abs(res.jacobian - J[:2])) < FD_TOL * np.max(np.abs(J[:2]))
    assert np.max(np.abs(res.time_gradient - J[2])) < FD_TOL * np.max(np.abs(J[2]))
    # v on the section is vb whatever x0
    assert np.max(np.abs(res.jacobian[1])) < 1e-12


# ======================================================================================
# one saltation formula on the Python side
# ======================================================================================

def test_event_map_saltation_is_the_derivative_of_an_event_map():
    """For an event map that moves time as well as state, ``(t, x) -> (t + q x, G x + g_t t)``,
    applied where ``c = x_0 + 0.2 t - 1`` vanishes, between constant fields ``a`` before and
    ``b`` after, every flow Jacobian is the identity: the saltation matrix is the derivative of
    the state at a later common time with respect to the state at time 0. Everything is affine
    along the way, so central differences are exact but for rounding (measured 1e-12)."""
    from pwsdyn.stability._saltation import event_map_saltation

    a, b = np.array([1.0, 0.5]), np.array([-0.3, 2.0])
    q, G, gt = np.array([0.1, -0.2]), np.array([[1.0, 0.3], [0.0, -0.8]]), np.array([0.05, 0.4])
    cx, ct, T = np.array([1.0, 0.0]), 0.2, 10.0

    def later(x0):
        s = (1.0 - x0[0]) / (a[0] + ct)             # c(s, x0 + a s) = 0
        xs = x0 + a * s
        tau, X = s + q @ xs, G @ xs + gt * s
        return X + b * (T - tau)

    x0 = np.array([0.2, 0.7])
    S = event_map_saltation(G, gt, a, b, cx, ct + cx @ a, tau_x=q, tau_t=1.0)
    np.testing.assert_allclose(S, central_fd(later, x0, 1e-3), rtol=0, atol=1e-10)
    # a reset (tau = t): the slides' full form; for a time-independent surface and reset it
    # takes f_in to f_out, and with no field after it (eq. 2.36's projected form) to 0
    den = ct + cx @ a
    np.testing.assert_allclose(event_map_saltation(G, gt, a, b, cx, den),
                               G + np.outer(b - G @ a - gt, cx) / den, rtol=0, atol=1e-15)
    zero = np.zeros(2)
    np.testing.assert_allclose(event_map_saltation(G, zero, a, b, cx, cx @ a) @ a, b,
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(event_map_saltation(G, zero, a, zero, cx, cx @ a) @ a, zero,
                               rtol=0, atol=1e-15)


def test_the_orbit_problem_uses_the_one_saltation_formula(monkeypatch):
    """``saltation_matrix`` (both forms) and the orbit problem's monodromy go through
    ``event_map_saltation``: a stand-in for it is what they answer with, so no second copy
    of the formula is left. Its home is the compiled-model layer (``ModelContext.saltation``
    calls it there); ``stability._saltation`` keeps it importable."""
    from pwsdyn.integrate import compiled
    from pwsdyn.orbits import problem as orbit_problem
    from pwsdyn.orbits.problem import OrbitProblem
    from pwsdyn.stability import _saltation

    from _orbit_cases import io_orbit

    formula = compiled.event_map_saltation
    assert _saltation.event_map_saltation is formula
    assert orbit_problem.event_map_saltation is formula
    orbit = io_orbit("stable")
    prob, u = OrbitProblem.from_orbit(orbit)
    ev = prob.evaluate(u)
    M = prob.monodromy(ev)
    # at another base point than the orbit's, so its eigenvalues are compared
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(M)),
                               np.sort_complex(np.linalg.eigvals(orbit.monodromy)), atol=1e-9)
    e = orbit.trajectory.events[0]
    p = orbit.params
    S = {form: saltation_matrix("impact-oscillator", "impact", e.t, e.x_before, params=p,
                                form=form) for form in ("full", "projected")}

    def doubled(*args, **kwargs):
        return 2.0 * formula(*args, **kwargs)

    monkeypatch.setattr(orbit_problem, "event_map_saltation", doubled)
    monkeypatch.setattr(compiled, "event_map_saltation", doubled)
    n_events = len(prob.bounds)
    assert n_events >= 1
    np.testing.assert_allclose(prob.monodromy(ev), 2.0 ** n_events * M, rtol=1e-14)
    for form, S0 in S.items():
        np.testing.assert_array_equal(
            saltation_matrix("impact-oscillator", "impact", e.t, e.x_before, params=p,
                             form=form), 2.0 * S0)
