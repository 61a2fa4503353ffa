"""Nordmark's discontinuity map at a graze and the persistence test (thesis eq. 2.30-2.35),
against the closed form of the impact oscillator's grazing orbit and against brute-force
sweeps up and down through the graze.

The impact oscillator x'' + eps x' + x = sin(omega t), x <= sigma, v -> -r v: its
non-impacting orbit is the forced response x_p = X sin + Y cos of amplitude R; it grazes the
stop at sigma = R, at the maximum of x_p, where (h = sigma - x)

    a* = h'' = -x_p'' = omega^2 R,

and, in the coordinates (x, v, t) of the forced system (g = (x, -r v, t), h_turning = -v),
eq. 2.34 reduces to beta = (0, 0, -(1 + r) sqrt(2 / a*)): to first order a low-velocity
impact only shifts the phase of the orbit (the rebound reaches zero velocity
(1 + r) sqrt(2 d / a*) earlier than the virtual orbit that passed through the stop, d its
depth).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn.errors import ArgumentError

R_COEF = 0.8


def _grazing_point(omega, eps):
    X, Y = np.linalg.solve(np.array([[1 - omega**2, -eps * omega],
                                     [eps * omega, 1 - omega**2]]), [1.0, 0.0])
    R = math.hypot(X, Y)
    params = {"omega": omega, "eps": eps, "r": R_COEF, "sigma": R + 0.3}
    orb = pwsdyn.find_periodic_orbit("impact-oscillator", [Y, omega * X], t0=0.0,
                                     params=params)
    br = pwsdyn.continue_orbit("impact-oscillator", orb, "sigma", span=(R - 0.3, R + 0.3),
                               ds=-0.05, on_dib="stop")
    return br.special("GR")[0], R, (X, Y)


@pytest.mark.parametrize("omega, eps", [(2.8, 0.1), (0.5, 3.0), (1.2, 1.5)])
def test_a_star_and_beta_match_the_closed_form(omega, eps):
    gr, R, _ = _grazing_point(omega, eps)
    dm = pwsdyn.discontinuity_map(gr)
    a_star = omega**2 * R
    assert abs(dm.a_star - a_star) < 1e-9 * a_star
    beta = np.array([0.0, 0.0, -(1 + R_COEF) * math.sqrt(2 / a_star)])
    # the x component is the tangency time's error times the slope: ~1e-8
    assert np.max(np.abs(dm.beta - beta)) < 1e-6 * abs(beta[2])
    assert dm.names == ("x", "v", "t")
    assert abs(dm.x_star[0] - R) < 1e-10 and abs(dm.x_star[1]) < 1e-7
    # the map: the identity on the admissible side, the square-root phase shift beyond
    x_ok = dm.x_star + np.array([-1e-3, 0.0, 0.0])
    assert np.array_equal(dm(x_ok), x_ok)
    d = 1e-4
    x_in = dm.x_star + np.array([d, 0.0, 0.0])
    assert np.allclose(dm(x_in) - x_in, dm.beta * math.sqrt(d), rtol=1e-12, atol=1e-15)
    # the smooth Poincare map carries the orbit's multipliers (and 0 across the section)
    eig = np.sort_complex(np.linalg.eigvals(dm.P))
    mu = np.sort_complex(np.append(gr.multipliers, 0.0))
    assert np.allclose(eig, mu, atol=1e-8)


def _hysteresis(omega, eps, R, XY):
    """Up and down sweeps of sigma through the graze: coexisting impacting and non-impacting
    attractors at some sigma (the events per period differ)."""
    X, Y = XY
    vals = np.linspace(0.95 * R, 1.05 * R, 21)
    ds = pwsdyn.sweep("impact-oscillator", "sigma", vals, {"x": Y, "v": omega * X},
                      params={"omega": omega, "eps": eps, "r": R_COEF}, transient=100,
                      samples=10, direction="both", workers=1, progress=False)
    epp = ds.events_per_period
    up, down = epp.sel(direction="up").values, epp.sel(direction="down").values
    return bool(np.any((up == 0) != (down == 0)))


@pytest.mark.parametrize("omega, eps, scenario", [(2.8, 0.1, "loss"),
                                                  (0.5, 3.0, "persistence")])
def test_persistence_test_predicts_the_hysteresis_of_sweeps(omega, eps, scenario):
    gr, R, XY = _grazing_point(omega, eps)
    dm = pwsdyn.discontinuity_map(gr)
    seq = dm.persistence(20)
    assert dm.scenario == scenario
    if scenario == "persistence":
        assert np.all(seq[np.abs(seq) > 1e-12 * np.abs(seq).max()] > 0)
    else:
        assert np.any(seq < 0)
    assert _hysteresis(omega, eps, R, XY) == (scenario == "loss")


def test_discontinuity_map_needs_an_interior_graze():
    from _orbit_cases import io_orbit

    br = pwsdyn.continue_orbit("impact-oscillator", io_orbit("stable"), "sigma",
                               span=(-0.6, 0.4), ds=0.05, on_dib="stop")
    with pytest.raises(ArgumentError, match="GR special point"):
        pwsdyn.discontinuity_map(br.special("GR")[0])      # the impact velocity's zero
    with pytest.raises(ArgumentError, match="GR special point"):
        pwsdyn.discontinuity_map(br.points[0])


def test_cli_grazing_prints_the_map_and_the_scenario():
    from click.testing import CliRunner

    from pwsdyn.cli import main

    args = ["grazing", "impact-oscillator", "--param", "sigma", "--from", "0.45", "--to", "0.0",
            "-p", "omega=2.8", "-p", "eps=0.1", "--x0", "x=-0.006,v=-0.41", "--t0", "0"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    R = 1.0 / math.hypot(1 - 2.8**2, 0.1 * 2.8)
    assert f"sigma = {R:.10g}"[:17] in res.output
    assert "a*          1.14523967" in res.output and "scenario    loss" in res.output
    cont = CliRunner().invoke(main, ["continue", *args[1:], "--no-progress"])
    assert cont.exit_code == 0, cont.output
    assert "GR" in cont.output and "grazing on 'impact'" in cont.output
    assert "signatures  ()  ->  (free) impact:impact (free)" in cont.output


def test_grazing_curve_in_two_parameters():
    """The graze followed in (omega, sigma): sigma = R(omega) = 1/|1 - omega^2 + i eps omega|
    at every point of the curve."""
    gr, R, _ = _grazing_point(2.8, 0.1)
    cur = pwsdyn.continue_bifurcation("impact-oscillator", gr, ("omega", "sigma"),
                                      span=(2.2, 3.5), ds=0.05, max_points=12)
    assert cur.curve == "GR" and len(cur) >= 6 and cur.values.max() == pytest.approx(3.5)
    for w, s in zip(cur.values, cur.values_of("sigma")):
        assert abs(s - 1.0 / math.hypot(1 - w * w, 0.1 * w)) < 1e-8


# ---- grazing-sliding ---------------------------------------------------------------------

FRICTION = {"name": "forced-friction", "states": ["x", "v"],
            "parameters": {"m": 1.0, "k": 1.0, "c": 0.1, "F": 0.2, "omega": 1.5, "V": 0.5,
                           "mu": 0.3},
            "forcing_period": "2*pi/omega", "definitions": {"vrel": "v - V"},
            "modes": {"block": {"x": "v",
                                "v": "(F*cos(omega*t) - c*v - k*x - mu*sign(vrel))/m"}}}


def test_grazing_sliding_of_a_forced_friction_oscillator():
    """m x'' + c x' + k x = F cos(omega t) - mu sign(v - V) (a block on a belt moving at V).
    While the block is slower than the belt the friction is the constant +mu and the orbit is
    the forced response x = mu/k + (F/D) cos(omega t - phi), D = |k - m omega^2 + i c omega|:
    its peak velocity F omega / D reaches V at F_GS = V D / omega, where the orbit touches the
    switching surface with the field beyond it pointing back -- grazing-sliding. Past it the
    orbit sticks to the belt for a time T growing like sqrt(F - F_GS): to leading order
    T = sqrt(2 dw / ((1 + q) a)), dw = omega (F - F_GS) / D the velocity excess of the free
    motion, a = V omega^2 its curvature at the peak, and 1 / (1 + q) the amplification of that
    excess by the orbit's own response to the velocity it loses by sliding (q the (v, v) entry
    of E (I - E)^-1, E the free flow over one period)."""
    from scipy.linalg import expm

    m_, k, c, w, V, mu = 1.0, 1.0, 0.1, 1.5, 0.5, 0.3
    D = math.hypot(k - m_ * w * w, c * w)
    F_gs = V * D / w
    model = pwsdyn.load_model(FRICTION)
    F0 = 0.5 * F_gs
    X, Y = np.linalg.solve(np.array([[k - m_ * w * w, c * w], [-c * w, k - m_ * w * w]]),
                           [F0, 0.0])
    orb = pwsdyn.find_periodic_orbit(model, [mu / k + X, w * Y], t0=0.0, params={"F": F0})
    assert len(orb.signature) == 0
    br = pwsdyn.continue_orbit(model, orb, "F", span=(0.0, 0.47), ds=0.05)
    gs = br.special("GS")
    assert len(gs) == 1 and abs(gs[0].value - F_gs) < 1e-10
    assert [str(s) for s in br.signatures][1] == \
        "(block[vrel<0]) slide_start:vrel (slide:vrel) slide_end:vrel (block[vrel<0])"
    A = np.array([[0.0, 1.0], [-k / m_, -c / m_]])
    E = expm(A * 2 * math.pi / w)
    q = (E @ np.linalg.inv(np.eye(2) - E))[1, 1]
    const = math.sqrt(2 * w / (D * (1 + q) * V * w * w))
    ratios = []
    for p in br.points:
        if p.signature_index == 1 and p.lam - F_gs < 1e-3:
            _, _, Ts = br.problem_of(p).orbit_problem.unpack(p.u)
            ratios.append((p.lam - F_gs, Ts[1] / math.sqrt(p.lam - F_gs)))
    assert len(ratios) >= 2 and ratios[0][0] < 2e-4
    assert abs(ratios[0][1] / const - 1) < 0.01            # the square-root law, within 1%
    assert abs(ratios[0][1] / const - 1) < abs(ratios[-1][1] / const - 1)   # converging
    assert br.admissible.all()


def test_grazing_sliding_curve_in_two_parameters():
    """The grazing-sliding followed in (omega, F): F_GS(omega) = V D(omega) / omega."""
    m_, k, c, w, V, mu = 1.0, 1.0, 0.1, 1.5, 0.5, 0.3
    model = pwsdyn.load_model(FRICTION)
    D = math.hypot(k - m_ * w * w, c * w)
    F0 = 0.5 * V * D / w
    X, Y = np.linalg.solve(np.array([[k - m_ * w * w, c * w], [-c * w, k - m_ * w * w]]),
                           [F0, 0.0])
    orb = pwsdyn.find_periodic_orbit(model, [mu / k + X, w * Y], t0=0.0, params={"F": F0})
    br = pwsdyn.continue_orbit(model, orb, "F", span=(0.0, 1.0), ds=0.05, on_dib="stop")
    cur = pwsdyn.continue_bifurcation(model, br.special("GS")[0], ("omega", "F"),
                                      span=(1.3, 2.0), ds=0.05, max_points=10)
    assert cur.curve == "GS" and len(cur) >= 5 and np.ptp(cur.values) > 0.2
    for om, F in zip(cur.values, cur.values_of("F")):
        assert abs(F - V * math.hypot(k - m_ * om * om, c * om) / om) < 1e-8


def test_square_root_law_of_near_grazing_impact_velocities():
    """With the stop moved a depth d0 into the grazing orbit, the first impact has velocity
    v0 = sqrt(2 a* d0); the map (eq. 2.33) kicks the state by beta sqrt(d0) and the smooth map
    carries it round, so the next impact comes at depth d1 = d0 - s1 sqrt(d0), s1 = h_x P beta
    (the first term of the persistence sequence), with velocity sqrt(2 a* d1) -- growing like
    the square root of the previous one, v1 ~ sqrt(-s1) (2 a*)^(1/4) sqrt(v0), when s1 < 0
    (thesis Paper A). Simulation agrees with the map's prediction within 1% for
    v0 = 1e-2 .. 1e-5 (the map's own error is of higher order: 0.6% at 1e-2, 8e-6 at 1e-5)."""
    omega, eps = 1.2, 1.5
    gr, R, (X, Y) = _grazing_point(omega, eps)
    dm = pwsdyn.discontinuity_map(gr)
    s1 = dm.persistence(1)[0]
    assert s1 < 0
    a, tstar, P = dm.a_star, dm.x_star[2], 2 * math.pi / omega
    C = math.sqrt(-s1) * (2 * a) ** 0.25
    errors = []
    for v0 in (1e-2, 1e-3, 1e-4, 1e-5):
        d0 = v0**2 / (2 * a)
        t0 = tstar - P / 2
        x0 = [X * math.sin(omega * t0) + Y * math.cos(omega * t0),
              omega * (X * math.cos(omega * t0) - Y * math.sin(omega * t0))]
        tr = pwsdyn.simulate("impact-oscillator", x0, (t0, t0 + 1.9 * P),
                             params={"omega": omega, "eps": eps, "r": R_COEF, "sigma": R - d0},
                             rtol=1e-13, atol=1e-15)
        vs = [e.x_before[1] for e in tr.events if e.kind == "impact"]
        assert len(vs) == 2 and abs(vs[0] / v0 - 1) < 1e-3
        predicted = math.sqrt(2 * a * (d0 - s1 * math.sqrt(d0)))
        errors.append(abs(vs[1] / predicted - 1))
        assert errors[-1] < 0.01
    assert errors[-1] < 1e-4                          # the error vanishes as v0 -> 0
    assert abs(vs[1] / math.sqrt(vs[0]) / C - 1) < 2e-3   # v1 ~ C sqrt(v0)


def _friction_branch(ds, span=(0.0, 0.6), omega=1.5, **kw):
    m_, k, c, w, V, mu = 1.0, 1.0, 0.1, omega, 0.5, 0.3
    model = pwsdyn.load_model(FRICTION)
    F0 = 0.5 * V * math.hypot(k - m_ * w * w, c * w) / w
    X, Y = np.linalg.solve(np.array([[k - m_ * w * w, c * w], [-c * w, k - m_ * w * w]]),
                           [F0, 0.0])
    orb = pwsdyn.find_periodic_orbit(model, [mu / k + X, w * Y], t0=0.0,
                                     params={"F": F0, "omega": w})
    return model, pwsdyn.continue_orbit(model, orb, "F", span=span, ds=ds, **kw)


@pytest.mark.parametrize("ds", [0.01, 0.1])
def test_switching_sliding_and_the_orbits_on_both_sides(ds):
    """Further up in F the point where the orbit reaches the belt's velocity leaves the
    sliding region through its other boundary (the field above stops pointing back):
    switching-sliding. Past it the block overtakes the belt for a short arc before sticking.
    Each DIB is located once whatever the step; the event sequences on both sides are those
    a direct simulation settles on, and the orbits past them are the simulated ones."""
    model, br = _friction_branch(ds, ds_max=10 * ds, max_points=400)
    assert [s.kind for s in br.special_points if s.kind != "EP"] == ["GS", "SS"]
    sigs = [str(s) for s in br.signatures]
    assert sigs == ["()",
                    "(block[vrel<0]) slide_start:vrel (slide:vrel) slide_end:vrel "
                    "(block[vrel<0])",
                    "(block[vrel<0]) crossing:vrel (block[vrel>0]) slide_start:vrel "
                    "(slide:vrel) slide_end:vrel (block[vrel<0])"]
    assert br.admissible.all() and br.values.max() == pytest.approx(0.6)
    ss = br.special("SS")[0]
    assert abs(ss.monitor.value) < 1e-9
    P = 2 * math.pi / 1.5
    o = ss.orbit
    for dF, n_events in ((-2e-3, 2), (2e-3, 3)):
        tr = pwsdyn.simulate(model, o.x0, (o.t0, o.t0 + 60 * P), params={"F": ss.value + dF},
                             rtol=1e-12, atol=1e-12)
        last = [e for e in tr.events if e.t > o.t0 + 59 * P + 1e-9]
        assert len(last) == n_events
    # a point past the switching-sliding: the orbit the simulation settles on
    p = next(q for q in br.points if q.signature_index == 2 and q.lam > ss.value + 0.02)
    orb = br.problem_of(p).orbit(p.u, p.lam)
    tr = pwsdyn.simulate(model, orb.x0, (orb.t0, orb.t0 + 80 * P), params={"F": p.lam},
                         rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(tr(orb.t0 + 80 * P) - orb.x0)) < 1e-8


def test_switching_sliding_curve_in_two_parameters():
    """The switching-sliding followed in (F, mu): along the curve the monitor (the normal
    velocity of the field above at the sliding entry) stays zero and the orbit keeps its
    signature; checked by solving the orbit problem afresh at points of the curve."""
    model, br = _friction_branch(0.05, on_dib="stop", span=(0.0, 0.6))
    br = pwsdyn.continue_orbit(model, br.special("GS")[0], "F", span=(0.0, 0.6), ds=0.05,
                               on_dib="stop")
    ss = br.special("SS")[0]
    cur = pwsdyn.continue_bifurcation(model, ss, ("mu", "F"), span=(0.25, 0.35), ds=0.01,
                                      max_points=8)
    assert cur.curve == "SS" and len(cur) >= 4 and np.ptp(cur.values) > 0.02
    for p in cur.points[1:]:
        op = cur.problem.orbit_problem
        u, P = p.u[:-1], np.array([p.lam, p.u[-1]])
        mon = op.dib_monitors(u, P)[ss.key]
        assert abs(mon.value) < 1e-9 and np.max(np.abs(op.residual(u, P))) < 1e-9


# ---- corner collision ----------------------------------------------------------------------

CORNER = {"name": "io-corner", "states": ["x", "v"], "forcing_period": "2*pi/omega",
          "parameters": {"eps": 0.1, "omega": 2.8, "sigma": -0.5, "r": 0.8, "k": 0.0,
                         "c": 1.0},
          "modes": {"free": {"x": "v", "v": "sin(omega*t) - eps*v - x + k*abs(v - c)"}},
          "events": [{"name": "impact", "kind": "impact", "surface": "sigma - x",
                      "direction": -1, "reset": {"v": "-r*v"}}]}


@pytest.mark.parametrize("ds", [0.01, 0.1])
def test_corner_collision_of_an_impact_with_a_switching_surface(ds):
    """The impact oscillator with a switching surface v = c that does not change its motion
    (a kink term k |v - c| with k = 0): the one-impact orbit crosses v = c before each impact
    while c is below the impact velocity v_imp (closed form), and impacts above it. At
    c = v_imp the impact point lies on both surfaces -- a corner collision, located once to
    1e-10 -- and beyond it the orbit crosses back below c before it impacts (its velocity
    peaks before the impact), as direct simulation shows on either side; the branch goes on
    with that sequence. Further up, c reaches the orbit's peak velocity v_max (closed form,
    maximized along the closed-form orbit): the arc above c shrinks to nothing between its
    two crossings -- a graze of v = c from below, located to 1e-10 -- and past it the orbit
    only impacts."""
    from scipy.optimize import minimize_scalar

    from _orbit_cases import IO, closed_form_state, io_closed_form, io_one_impact, io_orbit

    m = pwsdyn.load_model(CORNER)
    v_imp = io_one_impact(2.8, 1)[0]
    o = io_orbit("stable")
    orb = pwsdyn.find_periodic_orbit(m, o.x0, t0=o.t0, params={"c": 1.0})
    assert [e.kind for e in orb.events] == ["crossing", "impact"]
    br = pwsdyn.continue_orbit(m, orb, "c", span=(0.5, 2.0), ds=ds, ds_max=10 * ds)
    cc = br.special("CC")
    assert len(cc) == 1 and abs(cc[0].value - v_imp) < 1e-10
    assert [str(s) for s in br.signatures] == [
        "(free[v-c<0]) crossing:v-c (free[v-c>0]) impact:impact (free[v-c<0])",
        "(free[v-c<0]) crossing:v-c (free[v-c>0]) crossing:v-c (free[v-c<0]) impact:impact "
        "(free[v-c<0])",
        "(free[v-c<0]) impact:impact (free[v-c<0])"]
    assert br.admissible.all() and br.values.max() == pytest.approx(2.0)
    T = 2 * math.pi / 2.8
    for dc, kinds in ((-0.01, ["crossing", "impact"]),
                      (0.01, ["crossing", "crossing", "impact"])):
        tr = pwsdyn.simulate(m, o.x0, (o.t0, o.t0 + 40 * T), params={"c": v_imp + dc},
                             rtol=1e-12, atol=1e-12)
        last = [e.kind for e in tr.events if e.t > o.t0 + 39 * T]
        assert last == kinds, (dc, last)
    # the graze of v = c: the closed-form orbit's peak velocity
    cf = io_closed_form()["stable"]

    def v(t):
        return closed_form_state(cf, IO["sigma"], IO["r"], t)[1]
    ts = np.linspace(cf["t0"], cf["t0"] + cf["T"], 2001)[:-1]
    k = int(np.argmax([v(t) for t in ts]))
    peak = minimize_scalar(lambda t: -v(t), bounds=(ts[k - 1], ts[k + 1]), method="bounded",
                           options={"xatol": 1e-12})
    v_max = -peak.fun
    gr = [sp for sp in br.special("GR") if sp.key.endswith("/arc")]
    assert len(gr) == 1 and abs(gr[0].value - v_max) < 1e-10
    assert not br.special("LP") and not br.special("BP")


# ---- crossing-sliding and adding-sliding ---------------------------------------------------

def _simulated_events(model, orbit, params, periods=80):
    """Kinds of the events of the last forcing period of a long run from ``orbit``'s start."""
    P = 2 * math.pi / params.get("omega", 1.5)
    tr = pwsdyn.simulate(model, orbit.x0, (orbit.t0, orbit.t0 + periods * P), params=params,
                         rtol=1e-12, atol=1e-12)
    return [e.kind for e in tr.events if e.t > orbit.t0 + (periods - 1) * P + 1e-9]


@pytest.mark.parametrize("ds", [0.01, 0.1])
def test_crossing_sliding_followed_both_ways(ds):
    """Further up in F than the switching-sliding the sliding entry of the block (coming down
    from above the belt's speed) meets its exit on the boundary of the sliding region, where
    the field below is tangent: crossing-sliding. Past it the block crosses the belt's speed
    twice per period without sticking. Followed up from the non-sliding orbit and back down
    from the crossing one, every DIB is found once, at the same parameter both ways, and
    the grazing-sliding where the branch ends at its closed form F_GS = V D / omega: seen
    from the sliding side, the sliding segment shrinks to nothing there (its duration is zero
    at the graze, the locked signature folds back; no fold is reported beside the graze)."""
    model, up = _friction_branch(ds, span=(0.0, 1.0), ds_max=10 * ds, max_points=400)
    assert [s.kind for s in up.special_points if s.kind != "EP"] == ["GS", "SS", "CS"]
    sliding = ("(block[vrel<0]) crossing:vrel (block[vrel>0]) slide_start:vrel (slide:vrel) "
               "slide_end:vrel (block[vrel<0])")
    crossing = ("(block[vrel<0]) crossing:vrel (block[vrel>0]) crossing:vrel "
                "(block[vrel<0])")
    assert [str(s) for s in up.signatures][2:] == [sliding, crossing]
    cs = up.special("CS")[0]
    assert abs(cs.monitor.value) < 1e-9 and up.admissible.all()
    for dF, kinds in ((-0.01, ["crossing", "slide_start", "slide_end"]),
                      (0.01, ["crossing", "crossing"])):
        assert _simulated_events(model, cs.orbit, {"F": cs.value + dF}) == kinds
    end = up.points[-1]
    orb = up.problem_of(end).orbit(end.u, end.lam)
    down = pwsdyn.continue_orbit(model, orb, "F", span=(0.0, 1.0), ds=-ds, ds_max=10 * ds,
                                 max_points=400, params={"F": end.lam})
    assert [s.kind for s in down.special_points if s.kind != "EP"] == ["CS", "SS", "GS"]
    assert [str(s) for s in down.signatures] == [crossing, sliding, str(up.signatures[1]), "()"]
    assert down.admissible.all() and down.values.min() == pytest.approx(0.0, abs=1e-12)
    # the crossing-sliding from either side: the same point (its monitor is linear in F on
    # both sides); the switching-sliding seen from the crossing side ends a short arc of
    # vanishing duration whose end condition has a double root there, so Newton's tolerance
    # on the residual (1e-10) leaves ~1e-9 in the parameter
    assert abs(down.special("CS")[0].value - cs.value) < 1e-10
    assert abs(down.special("SS")[0].value - up.special("SS")[0].value) < 5e-9
    m_, k, c, w, V = 1.0, 1.0, 0.1, 1.5, 0.5
    assert abs(down.special("GS")[0].value - V * math.hypot(k - m_ * w * w, c * w) / w) < 1e-10


@pytest.mark.parametrize("ds", [0.01, 0.1])
def test_adding_sliding_splits_a_sliding_segment_and_joins_it_back(ds):
    """At omega = 0.5, past the switching-sliding, the sliding flow on the belt comes ever
    closer to the boundary of the sliding region, where the field above (the block faster
    than the belt) is tangent, and touches it (h_x f = 0 and (h_x f)_x f = 0 at a point
    inside the sliding segment: the slides' adding-sliding). Past it the block leaves the belt
    there, overtakes it for an arc and sticks again: the sliding segment is split in two. The
    events on either side are those a direct simulation settles on (which needs the kernel
    to find a sliding exit in a short window inside a step). Followed back down from the
    split side, the adding-sliding is found at the same F and the two sliding segments join."""
    w = 0.5
    model, up = _friction_branch(ds, span=(0.0, 1.3), ds_max=10 * ds, max_points=400,
                                 params={"omega": w}, omega=w)
    assert [s.kind for s in up.special_points if s.kind != "EP"] == ["GS", "SS", "AS"]
    split = ("(block[vrel<0]) crossing:vrel (block[vrel>0]) slide_start:vrel (slide:vrel) "
             "slide_end:vrel (block[vrel>0]) slide_start:vrel (slide:vrel) slide_end:vrel "
             "(block[vrel<0])")
    assert str(up.signatures[-1]) == split and up.admissible.all()
    a = up.special("AS")[0]
    assert a.key == "AS/vrel:above/2" and abs(a.monitor.value) < 1e-9
    params = {"omega": w}
    for dF, n_events in ((-0.01, 3), (0.02, 5)):      # SS lies 0.014 below
        assert len(_simulated_events(model, a.orbit, {**params, "F": a.value + dF})) == n_events
    end = up.points[-1]
    orb = up.problem_of(end).orbit(end.u, end.lam)
    down = pwsdyn.continue_orbit(model, orb, "F", span=(1.0, 1.3), ds=-ds, ds_max=10 * ds,
                                 max_points=400, params={**params, "F": end.lam})
    kinds = [s.kind for s in down.special_points if s.kind != "EP"]
    assert kinds == ["AS", "SS"]
    # from the split side the branch of the locked signature folds at the adding-sliding
    # itself, where the arc between the two sliding segments vanishes: there its solution is
    # not isolated (the Jacobian is singular at the fold), and the located point, exact in F,
    # has the arc's duration within ~1e-5 of zero, of either sign. It is the one point that
    # may fail the admissibility check
    as2 = down.special("AS")[0]
    assert abs(as2.value - a.value) < 1e-10
    assert all(ok for i, ok in enumerate(down.admissible) if i != as2.index)
    _, _, Ts = down.problem_of(down.points[as2.index]).orbit_problem.unpack(
        down.points[as2.index].u)
    assert np.min(Ts) > -1e-4
    assert str(down.signatures[1]) == str(up.signatures[2])
