"""Hybrid orbit problems F(u, p) = 0 on a fixed signature (issue "Make room for continuation").

Checked against independent references:

* ``F_u`` and ``F_p`` against central differences of ``F`` (step ``1e-6 max(1, |u_k|)``):
  the difference quotient's own error is its truncation ``O(h^2)`` plus the integration error
  (tolerances 1e-12) divided by ``h``, about ``1e-6`` of the entries at worst, so the bound is
  1e-6 relative to the largest entry of the matrix (and 1e-5 per column, relative to the
  column's largest entry or 1e-3 of the matrix's);
* the multipliers of the problem's monodromy (its own saltation matrices, chattering included)
  against those of the kernel's run (``find_periodic_orbit``);
* ``PeriodicOrbit.sensitivity`` against central differences of ``find_periodic_orbit`` in the
  parameter, and ``dV/dsigma`` of the Budd & Dux one-impact orbit against the derivative of
  its closed form (``tests/_orbit_cases.py``);
* admissibility past the grazing of the impact oscillator's one-impact orbit against the
  closed form (the impact velocity changes sign at ``sigma = R``, the amplitude of the
  non-impacting response) and against the orbit's own trajectory crossing the wall.
"""

import functools
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

import pwsdyn
from pwsdyn import OrbitError, PeriodicOrbit, find_periodic_orbit
from pwsdyn.errors import ArgumentError
from pwsdyn.newton import TrialRejected, newton
from pwsdyn.orbits import OrbitProblem, Signature
from pwsdyn.model.augment import with_parameters_as_states

sys.path.insert(0, str(Path(__file__).parent))
from _orbit_cases import IO, io_closed_form, io_orbit  # noqa: E402

VDP_WALL = {
    "name": "vdp-wall", "states": ["x", "v"],
    "parameters": {"mu": 1.0, "sigma": 1.5, "r": 0.7},
    "modes": {"free": {"x": "v", "v": "mu*(1 - x**2)*v - x"}},
    "events": [{"name": "wall", "kind": "impact", "surface": "sigma - x", "reset": {"v": "-r*v"}}],
}
VDP = {"name": "vdp", "states": ["x", "v"], "parameters": {"mu": 1.0},
       "modes": {"free": {"x": "v", "v": "mu*(1 - x**2)*v - x"}}}


# ======================================================================================
# the orbits of the acceptance cases
# ======================================================================================

@functools.lru_cache(maxsize=None)
def case_orbit(name: str) -> PeriodicOrbit:
    if name == "impact-oscillator":
        return io_orbit("stable")
    if name == "stick-slip-oscillator":
        return PeriodicOrbit.from_trajectory(pwsdyn.simulate(name, [0.0, 0.0], (0, 40)))
    if name == "relay-feedback":
        return PeriodicOrbit.from_trajectory(
            pwsdyn.simulate(name, [0.0, -0.001, -0.02], (0, 60)))
    if name == "one-legged-jumper":
        Tf = 2 * np.pi / 0.8
        return PeriodicOrbit.from_trajectory(
            pwsdyn.simulate(name, [1.5, 0, 10.5, 0], (0, 60 * Tf)))
    raise ValueError(name)


def central_fd(fun, x, h=1e-6):
    x = np.asarray(x, dtype=float)
    cols = []
    for k in range(len(x)):
        step = h * max(1.0, abs(x[k]))
        e = np.zeros(len(x))
        e[k] = step
        cols.append((fun(x + e) - fun(x - e)) / (2 * step))
    return np.column_stack(cols)


def matrix_rel(approx, exact) -> float:
    return float(np.max(np.abs(approx - exact)) / np.max(np.abs(exact)))


def column_rel(approx, exact) -> float:
    big = np.max(np.abs(exact))
    return max(float(np.max(np.abs(approx[:, k] - exact[:, k]))
                     / max(np.max(np.abs(exact[:, k])), 1e-3 * big))
               for k in range(exact.shape[1]))


# ======================================================================================
# Signature
# ======================================================================================

def test_signature_is_a_value():
    orbit = case_orbit("impact-oscillator")
    sig = orbit.signature
    assert isinstance(sig, Signature)
    # equal to the plain tuples it always was, hashable, printable and parseable
    assert sig == (("impact", "impact", "free", "free"),)
    assert hash(sig) == hash((("impact", "impact", "free", "free"),))
    assert str(sig) == "(free) impact:impact (free)"
    assert Signature.parse(str(sig)) == sig
    assert eval(repr(sig), {"Signature": Signature}) == sig
    assert {sig: 1}[Signature([("impact", "impact", "free", "free")])] == 1
    d = sig.doubled()
    assert len(d) == 2 and d == sig + sig and d.closed
    assert d[0].kind == "impact" and d[0].mode_before == "free"
    jumper = case_orbit("one-legged-jumper").signature
    assert jumper.closed and jumper.count("chatter") == 1 and jumper.count("stick") == 1
    assert Signature.parse(str(jumper)) == jumper
    assert jumper.rotated(3).same_cycle(jumper) and jumper.rotated(3) != jumper
    assert jumper.states[-1] == "stick:impact"
    with pytest.raises(ValueError, match="unknown event kind"):
        Signature([("bounce", "impact", "free", "free")])
    with pytest.raises(ValueError, match="cannot parse"):
        Signature.parse("free impact:impact")
    assert Signature() == () and str(Signature()) == "()" and Signature.parse("()") == ()


# ======================================================================================
# F_u, F_p against central differences of F
# ======================================================================================

CASES = ["impact-oscillator", "stick-slip-oscillator", "relay-feedback", "one-legged-jumper"]


@pytest.mark.parametrize("name", CASES)
def test_jacobians_match_central_differences(name):
    """At the orbit of free-running shooting the residual is at its tolerance and F_u, F_p
    (every parameter of the model) agree with central differences of F. Measured (matrix /
    column relative): impact oscillator 6e-10 / 9e-10 (F_u), 5e-10 / 5e-10 (F_p); stick-slip
    with a sliding segment 1.4e-9 / 2.2e-9, 5e-10 / 1e-8; relay feedback (autonomous, 28
    segments, 14 sliding) 1.4e-11 / 1.4e-8, 1.6e-8 / 2.5e-7; jumper (20 impacts, chattering,
    sticking, release) 6.8e-8 / 5.1e-7, 3.7e-8 / 4.3e-7."""
    orbit = case_orbit(name)
    prob, u = OrbitProblem.from_orbit(orbit)
    assert prob.parameters == tuple(orbit.model.parameters)
    ev = prob.evaluate(u)
    assert prob.norm(ev.F, u) < 1e-9
    assert ev.F_u.shape == (prob.size, prob.size) and ev.F_p.shape == (prob.size, prob.q)
    Ju = central_fd(lambda uu: prob.residual(uu), u)
    Jp = central_fd(lambda pp: prob.residual(u, pp), prob.p0)
    assert matrix_rel(Ju, ev.F_u) < 1e-6
    assert matrix_rel(Jp, ev.F_p) < 1e-6
    assert column_rel(Ju, ev.F_u) < 1e-5
    assert column_rel(Jp, ev.F_p) < 1e-5
    # Newton on the problem stays at the orbit; its multipliers (the problem's own saltation
    # matrices, the chattering map's included) are the kernel's
    res = prob.solve(u)
    assert res.converged and np.max(np.abs(res.x - u)) < 1e-7 * (1 + np.max(np.abs(u)))
    np.testing.assert_allclose(np.sort_complex(prob.multipliers(prob.evaluate(res.x))),
                               np.sort_complex(orbit.multipliers), rtol=0, atol=1e-8)
    assert prob.admissibility(res.x).admissible


def test_problem_layout():
    orbit = case_orbit("stick-slip-oscillator")
    prob, u = OrbitProblem.from_orbit(orbit, parameters=["V"])
    assert not prob.forced and prob.m == 2 and prob.size == 6 and prob.q == 1
    t0, xs, Ts = prob.unpack(u)
    np.testing.assert_array_equal(prob.pack(t0, xs, Ts), u)
    assert sum(Ts) == pytest.approx(orbit.period, rel=1e-12)
    assert prob.state_names == ["block[vrel<0]", "slide:vrel"]
    io, uio = OrbitProblem.from_orbit(case_orbit("impact-oscillator"), parameters=("sigma", "r"))
    assert io.forced and io.size == 1 + 1 * 3 and io.p0.tolist() == [IO["sigma"], IO["r"]]
    with pytest.raises(ArgumentError, match="must have 4 entries"):
        io.residual(np.zeros(3))
    with pytest.raises(ArgumentError, match="parameters"):
        OrbitProblem("impact-oscillator", orbit.signature, parameters=["nope"])
    with pytest.raises(ArgumentError, match="not closed"):
        OrbitProblem("impact-oscillator", [("impact", "impact", "free", "stick:impact")])


# ======================================================================================
# locked signatures: the same orbits as free-running shooting
# ======================================================================================

@pytest.mark.parametrize("name", CASES[:3])
def test_locked_signature_gives_the_free_running_orbit(name, tmp_path):
    """find_periodic_orbit(signature=...) from the orbit's own start: the same orbit (x0,
    period, multipliers and event times to 1e-8, measured <= 3e-10; monodromy to 1e-7
    relative, measured 1.5e-8 for the relay, whose sliding-field Jacobian the kernel takes by
    central differences, ~1e-10 for the others), admissible; the kernel run from its x0
    reproduces the signature and closes to 1e-8 (measured ~5e-11)."""
    orbit = case_orbit(name)
    lk = find_periodic_orbit(orbit.model, orbit.x0, params=orbit.params, t0=orbit.t0,
                             period=orbit.period, mode=orbit.state0,
                             signature=orbit.signature)
    assert lk.converged and lk.locked and lk.admissible and lk.reason is None
    assert lk.signature == orbit.signature
    assert abs(lk.t0 - orbit.t0) < 1e-8
    np.testing.assert_allclose(lk.x0, orbit.x0, rtol=0, atol=1e-8)
    assert abs(lk.period - orbit.period) < 1e-8
    np.testing.assert_allclose(np.sort_complex(lk.multipliers),
                               np.sort_complex(orbit.multipliers), rtol=0, atol=1e-8)
    assert matrix_rel(lk.monodromy, orbit.monodromy) < 1e-7
    assert max(abs(a.t - b.t) for a, b in zip(lk.events, orbit.events)) < 1e-8
    # the trajectory assembled from the segments: transfer matrices, dense output
    prod = lk.transfer_matrices[0]
    for m in lk.transfer_matrices[1:]:
        prod = m @ prod
    np.testing.assert_allclose(prod, lk.monodromy, atol=1e-13)
    np.testing.assert_allclose(lk.trajectory.jacobian, lk.monodromy, atol=0)
    ts = np.linspace(lk.t0, lk.t0 + lk.period, 7)[1:-1]
    np.testing.assert_allclose(lk.trajectory(ts), orbit.trajectory(ts - lk.t0 + orbit.t0),
                               atol=1e-8)
    # the simulator from x0 (independent of the problem) follows the same signature
    tr = pwsdyn.simulate(orbit.model, lk.x0, (lk.t0, lk.t0 + lk.period), params=lk.params,
                         mode=lk.state0, method="DOP853", rtol=1e-12, atol=1e-12)
    assert Signature(tr.events) == lk.signature
    assert np.max(np.abs(tr.x_final - lk.x0)) < 1e-8
    assert "(locked)" in lk.summary()
    path = lk.save(tmp_path / "locked.nc")
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["locked"] == 1 and ds.attrs["admissible"] == 1


def test_doubled_signature():
    """The one-impact orbit solved on its doubled signature over two forcing periods is the
    same orbit traversed twice: period 2T, multipliers the squares (1e-8)."""
    orbit = case_orbit("impact-oscillator")
    twice = find_periodic_orbit("impact-oscillator", orbit.x0, params=IO, t0=orbit.t0,
                                periods=2, signature=orbit.signature.doubled())
    assert twice.converged and twice.admissible and len(twice.events) == 2
    assert twice.period == pytest.approx(2 * orbit.period, rel=1e-14)
    np.testing.assert_allclose(twice.x0, orbit.x0, atol=1e-8)
    np.testing.assert_allclose(np.sort_complex(twice.multipliers),
                               np.sort_complex(orbit.multipliers ** 2), atol=1e-8)


def test_jumper_orbit_from_its_problem():
    """The jumper's gait as a problem solution (PeriodicOrbit.problem): its orbit has the
    kernel's multipliers (1e-8; the two zeros of sticking among them), period and events.

    find_periodic_orbit(signature=...) needs a guess that the simulator or a segment-by-
    segment integration carries through the signature; the last bounces of this chattering
    sequence rise ~1e-12, below what a segment-by-segment integration resolves, and the
    simulator from the gait's x0 applies the chattering map after 15 impacts instead of 20
    (free-running shooting restarts the kernel at its nodes, and the chattering criterion is
    relative to the largest impact since the restart)."""
    orbit = case_orbit("one-legged-jumper")
    prob, u, p = orbit.problem()
    lk = prob.orbit(u, p, t0=orbit.t0)
    assert lk.admissible and lk.signature == orbit.signature
    np.testing.assert_allclose(np.sort_complex(lk.multipliers),
                               np.sort_complex(orbit.multipliers), atol=1e-8)
    assert abs(lk.period - orbit.period) < 1e-12
    np.testing.assert_allclose(lk.x0, orbit.x0, atol=1e-8)
    kinds = [e.kind for e in lk.events]
    assert kinds.count("chatter") == 1 and kinds.count("stick") == 1
    chatter = lk.events[kinds.index("chatter")]
    assert chatter.t_after > chatter.t   # the jump to the accumulation point


def test_orbits_without_events():
    """An empty signature: forced single shooting (the linear response far from the wall)
    and an autonomous cycle (Van der Pol) with its phase condition; F_u, F_p against central
    differences (1e-6) and the orbits against free-running shooting (1e-8)."""
    p = dict(IO, sigma=5.0)
    free = find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=p)
    lk = find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=p, signature=())
    assert lk.events == [] and lk.locked and lk.admissible
    np.testing.assert_allclose(lk.x0, free.x0, atol=1e-9)
    np.testing.assert_allclose(lk.monodromy, free.monodromy, atol=1e-9)
    tr = pwsdyn.simulate(VDP, [2.0, 0.0], (0, 40))
    free = find_periodic_orbit(VDP, tr.x_final, period=6.6, t0=tr.t_final)
    lk = find_periodic_orbit(VDP, tr.x_final, period=6.6, t0=tr.t_final, signature=Signature())
    assert abs(lk.period - free.period) < 1e-8
    np.testing.assert_allclose(lk.x0, free.x0, atol=1e-8)
    np.testing.assert_allclose(lk.multipliers, free.multipliers, atol=1e-8)
    for orbit in (lk, find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=p,
                                          signature=())):
        prob, u, pp = orbit.problem()
        ev = prob.evaluate(u)
        assert matrix_rel(central_fd(lambda uu: prob.residual(uu), u), ev.F_u) < 1e-6
        assert matrix_rel(central_fd(lambda q: prob.residual(u, q), pp), ev.F_p) < 1e-6


# ======================================================================================
# sensitivities
# ======================================================================================

@pytest.mark.parametrize("name", ["sigma", "omega", "eps", "r"])
def test_sensitivity_of_a_forced_orbit(name):
    """d x0/d p (at the fixed t0), d period/d p, d multipliers/d p and the impact's time and
    state against central differences of find_periodic_orbit (step 1e-5 max(1, |p|)), to 1e-6
    relative; measured x0 <= 5.5e-10, multipliers <= 2.5e-10, impact state <= 1e-9."""
    orbit = case_orbit("impact-oscillator")
    s = orbit.sensitivity(name)
    h = 1e-5 * max(1.0, abs(IO[name]))
    op, om = (find_periodic_orbit("impact-oscillator", orbit.x0, t0=orbit.t0,
                                  params=dict(IO, **{name: IO[name] + d})) for d in (h, -h))
    assert matrix_rel(s.x0[None], ((op.x0 - om.x0) / (2 * h))[None]) < 1e-6
    assert matrix_rel(s.multipliers[None],
                      ((op.multipliers - om.multipliers) / (2 * h))[None]) < 1e-6
    assert s.period == pytest.approx((op.period - om.period) / (2 * h), rel=1e-6, abs=1e-12)
    if name == "omega":
        assert s.period == pytest.approx(-2 * np.pi / IO["omega"] ** 2, rel=1e-12)
    fd_v = (op.events[0].x_before - om.events[0].x_before) / (2 * h)
    assert matrix_rel(s.x_before[0][None], fd_v[None]) < 1e-6
    assert s.event_times[0] == pytest.approx((op.events[0].t - om.events[0].t) / (2 * h),
                                             rel=1e-6)


def _one_impact_velocities(sigma, eps=IO["eps"], omega=IO["omega"], r=IO["r"]):
    """Both roots v of the closed form of tests/_orbit_cases.py, (sigma + v b1)^2 +
    (v b2 / omega)^2 = R^2, with dv/dsigma by implicit differentiation, and R."""
    T = 2 * np.pi / omega
    A = np.array([[0.0, 1.0], [-1.0, -eps]])
    E = expm(A * T)
    X, Y = np.linalg.solve(np.array([[1 - omega**2, -eps * omega],
                                     [eps * omega, 1 - omega**2]]), [1.0, 0.0])
    R2 = X * X + Y * Y
    b = np.linalg.solve(np.eye(2) - E, (np.eye(2) + r * E) @ np.array([0.0, 1.0]))
    qa, qb, qc = b[0] ** 2 + (b[1] / omega) ** 2, 2 * sigma * b[0], sigma**2 - R2
    disc = qb * qb - 4 * qa * qc
    out = []
    for v in ((-qb - np.sqrt(disc)) / (2 * qa), (-qb + np.sqrt(disc)) / (2 * qa)):
        # q(v, sigma) = qa v^2 + 2 sigma b1 v + sigma^2 - R^2 = 0
        dv = -(2 * b[0] * v + 2 * sigma) / (2 * qa * v + qb)
        out.append((float(v), float(dv)))
    return out, float(np.sqrt(R2))


def test_dV_dsigma_matches_the_closed_form():
    """Budd & Dux one-impact orbit: V (impact velocity) and dV/dsigma from the orbit's
    sensitivity against the closed form and its derivative (implicit differentiation of the
    quadratic for V): 1e-8 (measured 2.2e-13 and 1.4e-14 relative); the derivative of the
    closed form itself checked by its central difference."""
    orbit = case_orbit("impact-oscillator")
    roots, _ = _one_impact_velocities(IO["sigma"])
    V = orbit.events[0].x_before[1]
    v_cf, dv_cf = min(roots, key=lambda vd: abs(vd[0] - V))
    assert abs(V - v_cf) < 1e-8
    assert v_cf == pytest.approx(io_closed_form()["stable"]["v"], rel=1e-12)
    h = 1e-6
    fd = (min(_one_impact_velocities(IO["sigma"] + h)[0], key=lambda r: abs(r[0] - V))[0]
          - min(_one_impact_velocities(IO["sigma"] - h)[0], key=lambda r: abs(r[0] - V))[0]) \
        / (2 * h)
    assert dv_cf == pytest.approx(fd, rel=1e-8)
    s = orbit.sensitivity("sigma")
    assert s.x_before[0][1] == pytest.approx(dv_cf, rel=1e-8)
    # the velocity after the impact: -r V
    assert s.x_after[0][1] == pytest.approx(-IO["r"] * dv_cf, rel=1e-8)


def _richardson(f, h):
    """Fourth-order central difference of ``f`` at 0."""
    return (8 * (f(h) - f(-h)) - (f(2 * h) - f(-2 * h))) / (12 * h)


@pytest.mark.parametrize("name", ["mu", "sigma", "r"])
def test_sensitivity_of_an_autonomous_orbit(name):
    """Van der Pol against a wall (autonomous, impacting): d x0/d p in the fixed phase
    section, d period/d p and d multiplier/d p against fourth-order central differences of
    find_periodic_orbit with that section (step 1e-4), to 1e-6 relative; measured x0 <= 6e-10,
    period <= 3e-10, multiplier (|mu| ~ 0.008) <= 7.4e-8 (second-order differences of step
    1e-5 are themselves off by up to 6.5e-7 there)."""
    tr = pwsdyn.simulate(VDP_WALL, [0.1, 0.0], (0, 60))
    orbit = PeriodicOrbit.from_trajectory(tr)
    P = VDP_WALL["parameters"]
    s = orbit.sensitivity(name)

    def solve(d):
        return find_periodic_orbit(VDP_WALL, orbit.x0, params={**P, name: P[name] + d},
                                   period=orbit.period, t0=orbit.t0, phase=orbit.phase_normal,
                                   tol=1e-12)

    cache: dict = {}

    def at(d):
        if d not in cache:
            cache[d] = solve(d)
        return cache[d]

    dx0 = _richardson(lambda d: at(d).x0, 1e-4)
    dT = _richardson(lambda d: at(d).period, 1e-4)
    dmu = _richardson(lambda d: at(d).multipliers, 1e-4)
    assert matrix_rel(s.x0[None], dx0[None]) < 1e-6
    assert s.period == pytest.approx(dT, rel=1e-6)
    assert matrix_rel(s.multipliers[None], dmu[None]) < 1e-6


def test_sensitivity_of_a_sliding_orbit():
    """Stick-slip (a sliding segment): period and x0 against central differences (1e-6
    relative; measured <= 2.3e-9); its multiplier is 0 for every parameter (sliding loses the
    normal direction), so its derivative is 0 (measured ~1e-13)."""
    orbit = case_orbit("stick-slip-oscillator")
    for name in ("delta", "V"):
        s = orbit.sensitivity(name)
        h = 1e-5 * max(1.0, abs(orbit.params[name]))
        kw = dict(period=orbit.period, t0=orbit.t0, phase=orbit.phase_normal, mode=orbit.state0)
        op, om = (find_periodic_orbit("stick-slip-oscillator", orbit.x0,
                                      params={**orbit.params, name: orbit.params[name] + d},
                                      **kw) for d in (h, -h))
        assert matrix_rel(s.x0[None], ((op.x0 - om.x0) / (2 * h))[None]) < 1e-6
        assert s.period == pytest.approx((op.period - om.period) / (2 * h), rel=1e-6)
        assert abs(s.multipliers[0]) < 1e-9


def test_sensitivity_arguments():
    orbit = case_orbit("impact-oscillator")
    with pytest.raises(ArgumentError, match="parameter"):
        orbit.sensitivity("nope")


# ======================================================================================
# past the graze
# ======================================================================================

def test_one_impact_orbit_followed_past_the_graze():
    """The one-impact orbit locked to its signature, followed in sigma by natural-parameter
    steps (the previous solution as the guess). The closed form's impact velocity V reaches 0
    at sigma = R = 0.1461 (the amplitude of the non-impacting response): a grazing impact.
    The problem's V agrees with the closed form on both sides (1e-8); the orbit is admissible
    below the graze and not beyond it, where its impact has the wrong sign of normal velocity
    and its free flight passes through the wall (the reasons say so)."""
    orbit = case_orbit("impact-oscillator")
    prob, u = OrbitProblem.from_orbit(orbit, parameters=["sigma"])
    _, R = _one_impact_velocities(0.0)
    seen = {True: 0, False: 0}
    for sigma in np.arange(-0.5, 0.2501, 0.025):
        res = prob.solve(u, [sigma])
        assert res.converged, (sigma, res.message)
        u = res.x
        ev = prob.evaluate(u, [sigma], jacobian=False)
        V = ev.segs[0].y[1]
        roots, _ = _one_impact_velocities(sigma)
        assert min(abs(V - v) for v, _ in roots) < 1e-8
        adm = prob.admissibility(u, [sigma], ev)
        if sigma < R - 0.01:
            assert adm.admissible, (sigma, adm.reason)
            assert V > 0
        elif sigma > R + 0.01:
            assert not adm.admissible and adm.reason
            assert V < 0
            text = " ".join(adm.violations)
            assert "wrong sign of the normal velocity" in text
            assert "passes through the constraint" in text
        seen[adm.admissible] += 1
    assert seen[True] >= 20 and seen[False] >= 3
    # the same through find_periodic_orbit, from the last admissible orbit's state
    below = prob.orbit(prob.solve(u, [0.1]).x, [0.1], t0=orbit.t0)
    assert below.admissible
    past = find_periodic_orbit("impact-oscillator", below.x0, params=dict(IO, sigma=0.2),
                               t0=below.t0, signature=orbit.signature)
    assert past.converged and not past.admissible
    assert "NOT ADMISSIBLE" in past.summary() and "NOT admissible" in repr(past)
    # independent of the checks: the reported trajectory goes beyond the wall x = sigma
    assert np.max(past.trajectory.x[:, 0]) > 0.2 + 1e-3
    assert past.events[0].x_before[1] < 0


def test_guess_that_does_not_follow_the_signature():
    """A wall out of reach: the one-impact signature cannot be followed from the guess."""
    sig = case_orbit("impact-oscillator").signature
    with pytest.raises(OrbitError) as info:
        find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=dict(IO, sigma=5.0),
                            signature=sig)
    assert info.value.reason == "signature"
    with pytest.raises(ArgumentError, match="mode"):
        find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=IO, signature=sig,
                            mode="stick:impact")
    with pytest.raises(ArgumentError, match="signature"):
        find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=IO, signature="free")


# ======================================================================================
# the Newton solver
# ======================================================================================

def test_newton_solver_interface():
    """Quadratic convergence to sqrt(2); each reason of failure; the hooks."""
    res = newton(lambda x: x**2 - 2, [1.0], jac=lambda x: np.diag(2 * x), tol=1e-15)
    assert res.converged and res.reason == "converged"
    assert abs(res.x[0] - np.sqrt(2)) < 1e-15
    h = res.history
    assert all(h[k + 1] < h[k] ** 1.8 for k in range(1, len(h) - 1) if h[k + 1] > 1e-15)
    res = newton(lambda x: x**2, [0.0], jac=lambda x: np.diag(2 * x), tol=-1.0)
    assert res.reason == "singular" and not res.converged
    res = newton(lambda x: x**2 - 2, [1.0], jac=lambda x: np.diag(2 * x), max_iter=1,
                 tol=1e-15)
    assert res.reason == "budget" and len(res.history) == 2

    def refuse(x):
        raise TrialRejected("cannot evaluate", "simulation")
    res = newton(refuse, [1.0], jac=lambda x: np.eye(1))
    assert res.reason == "simulation" and res.history == []

    def picky(x):
        if x[0] != 1.0:
            raise TrialRejected("moved", "signature", data=x[0])
        return np.array([1.0])
    res = newton(picky, [1.0], jac=lambda x: np.eye(1))
    assert res.reason == "no_progress" and len(res.rejections) == 8
    assert res.rejections[0].reason == "signature" and res.step[0] == -1.0
    res = newton(lambda x: np.array([np.exp(x[0]) - 1e9]), [0.0],
                 jac=lambda x: np.array([[1e-12]]), singular_rtol=0.0)
    assert res.reason == "diverged"
    seen = []
    history = [5.0]
    res = newton(lambda x: x - 3, [0.0], jac=lambda x: np.eye(1),
                 on_accept=lambda x, r, n: seen.append(x.copy()), history=history)
    assert res.converged and history[0] == 5.0 and len(seen) == len(history) - 1


# ======================================================================================
# parameters as states
# ======================================================================================

def test_parameters_as_states():
    """with_parameters_as_states: the extended model's states follow the model's run (1e-10;
    measured 1e-12) and its Jacobian's parameter columns are dx/dp through impacts (against
    central differences of simulate, 1e-6; measured 4e-9). The kernel's projections move the
    parameter-states, as documented: round-off on a sliding surface that depends on V (stick-
    slip), the size of the chattering map's projection when the surface depends on L, A
    (jumper: measured 3.5e-7 and 9e-8 over 20 forcing periods)."""
    m = pwsdyn.load_model("impact-oscillator")
    a = with_parameters_as_states(m, ["sigma", "r"])
    assert a.states == ("x", "v", "sigma", "r") and list(a.parameters) == ["eps", "omega"]
    assert a.forcing_period == m.forcing_period
    p = dict(eps=0.1, omega=2.8)
    T = 2 * np.pi / 2.8
    opts = dict(method="DOP853", rtol=1e-12, atol=1e-12, max_step=T / 4, dense=False)
    tr = pwsdyn.simulate(a, [-0.7, 0.0, -0.5, 0.8], (0, 3 * T), params=p, variational=True,
                         **opts)
    assert tr.event_counts()["impact"] == 4

    def run(s, r):
        return pwsdyn.simulate(m, [-0.7, 0.0], (0, 3 * T), params=dict(p, sigma=s, r=r),
                               **opts).x_final
    np.testing.assert_allclose(tr.x_final[:2], run(-0.5, 0.8), atol=1e-10)
    assert tr.x_final[2:].tolist() == [-0.5, 0.8]
    h = 1e-6
    fd = np.column_stack([(run(-0.5 + h, 0.8) - run(-0.5 - h, 0.8)) / (2 * h),
                          (run(-0.5, 0.8 + h) - run(-0.5, 0.8 - h)) / (2 * h)])
    assert matrix_rel(tr.jacobian[:2, 2:], fd) < 1e-6
    np.testing.assert_array_equal(tr.jacobian[2:, 2:], np.eye(2))
    # omega in the forcing period: the period is dropped
    assert with_parameters_as_states(m, ["omega"]).forcing_period is None
    s = with_parameters_as_states("stick-slip-oscillator", ["V"])
    tr = pwsdyn.simulate(s, [0, 0, 0.2], (0, 40))
    assert tr.event_counts()["slide_start"] == 4 and abs(tr.x_final[2] - 0.2) < 1e-14
    j = with_parameters_as_states("one-legged-jumper", ["L", "A"])
    Tf = 2 * np.pi / 0.8
    tr = pwsdyn.simulate(j, [1.5, 0, 10.5, 0, 0.0, 1.0], (0, 20 * Tf), max_step=Tf / 4)
    assert tr.event_counts()["chatter"] >= 10
    drift = np.abs(tr.x_final[4:] - [0.0, 1.0])
    assert 1e-12 < np.max(drift) < 1e-5
    with pytest.raises(ArgumentError, match="unknown"):
        with_parameters_as_states(m, ["x"])
    with pytest.raises(ArgumentError, match="duplicates"):
        with_parameters_as_states(m, ["r", "r"])
