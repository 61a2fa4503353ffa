"""Orbit problems whose signature slides on the intersection of two switching surfaces
(issue 27): the two-block belt's orbit on which both blocks stick for a while, found on its
signature and continued in the coupling stiffness.

Every number is checked against something independent of the orbit problem's closed-form
sliding field: plain shooting and simulations (the kernel's Newton iteration for the
weights), the weights' closed form derived below, and central differences of the return map
of simulations.

Closed form of the weights (two blocks both stuck, ``w_i = v_i - V = 0``): the field is
affine in each contact's sign ``u_i``, and on the intersection the friction force is
``u_i Fs_i`` (``|w_i| = 0``), so ``v_i' = 0`` gives ``u_i = -S_i / Fs_i`` with the spring
force ``S_i = k_i x_i + kc (x_i - x_j)``; the multilinear weight is
``lambda_i = (1 - u_i) / 2 = (1 + S_i / Fs_i) / 2``, which reaches 1 (the block leaves
below, slower than the belt) where ``S_i = Fs_i``.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

import pwsdyn
from pwsdyn.integrate.compiled import KernelState, ModelContext
from pwsdyn._codes import SLIDE, SLIDE_MULTI
from pwsdyn.orbits import OrbitProblem, Signature

BELT = "two-block-belt"
#: the orbit of tests/test_contacts.py: block 1 sticks, block 2 joins it, block 1 releases,
#: then block 2
KC = {"kc": 2.0}
GUESS = ([0.9596, -0.4364, 0.9704, -0.4544], 8.735)


@pytest.fixture(scope="module")
def plain():
    """The orbit by plain shooting (the kernel's events; its multiplier -1.761883 is checked
    against central differences in tests/test_contacts.py)."""
    x, T = GUESS
    return pwsdyn.find_periodic_orbit(BELT, x, period=T, params=KC)


@pytest.fixture(scope="module")
def on_signature(plain):
    return pwsdyn.find_periodic_orbit(BELT, plain.x0, period=plain.period, params=KC,
                                      signature=plain.signature)


def test_signature_holds_an_intersection(plain):
    assert [str(e.mode_after) for e in plain.signature] == [
        "slide:w1", "slide_multi:w1&w2", "slide:w2", "blocks[w1<0,w2<0]"]


def test_orbit_on_its_signature_reproduces_plain_shooting(plain, on_signature):
    """The orbit problem (closed-form multilinear field, its weight reaching 1 as the end
    condition of the intersection) converges to the plain-shooting orbit: period and events
    to 1e-9, multipliers to 1e-8 (both solve to a residual near 1e-12; the monodromies are
    products of variational runs at rtol 1e-12 over four segments)."""
    o = on_signature
    assert str(o.signature) == str(plain.signature)
    assert o.period == pytest.approx(plain.period, abs=1e-9)
    for a, b in zip(o.events, plain.events):
        assert (a.kind, a.name) == (b.kind, b.name)
        assert a.t - o.t0 == pytest.approx(b.t - plain.t0, abs=1e-9)
    mu = sorted(np.asarray(o.multipliers), key=abs)
    ref = sorted(np.asarray(plain.multipliers), key=abs)
    assert abs(mu[-1] - ref[-1]) < 1e-8
    assert mu[-1].real == pytest.approx(-1.761883, abs=1e-6)
    # sliding on two surfaces removes two dimensions: the other multipliers vanish
    assert max(abs(v) for v in mu[:-1]) < 1e-8


def test_weights_and_field_against_closed_form_and_kernel(plain, on_signature):
    """Along the intersection interval of the plain-shooting orbit (the kernel's run) the
    problem's weights equal ``(1 + S_i / Fs_i) / 2`` (module docstring) to 1e-12 (round-off
    of the closed forms), lie in [0, 1], and the segment's field equals the kernel's (its
    Newton iteration for the weights) to 1e-12; the interval ends where block 1's weight
    reaches 1, i.e. ``S_1 = Fs1``."""
    prob, _ = OrbitProblem.from_orbit(on_signature)
    i = [f.kind for f in prob.fields].index("slide_multi")
    m = pwsdyn.load_model(BELT)
    p = {**m.parameters, **KC}
    k = [str(e.mode_after) for e in plain.signature].index("slide_multi:w1&w2")
    ta, tb = float(plain.events[k].t), float(plain.events[k + 1].t)
    ts = np.linspace(ta, tb, 7)
    X = np.array([plain.trajectory(t) for t in ts])
    lam = prob.multi_weights(i, ts, X)
    S1 = p["k1"] * X[:, 0] + p["kc"] * (X[:, 0] - X[:, 2])
    S2 = p["k2"] * X[:, 2] + p["kc"] * (X[:, 2] - X[:, 0])
    np.testing.assert_allclose(lam[:, 0], (1 + S1 / p["Fs1"]) / 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lam[:, 1], (1 + S2 / p["Fs2"]) / 2, rtol=0, atol=1e-12)
    assert lam.min() > -1e-12 and lam.max() < 1 + 1e-12
    assert lam[-1, 0] == pytest.approx(1.0, abs=1e-9)
    ctx = ModelContext(m, p)
    st = KernelState(SLIDE_MULTI, prob.fields[i].index, prob.fields[i].mode)
    for t, x in zip(ts, X):
        ours = prob.sys.field(prob._fidx[i], t, np.concatenate([x, prob.p0]), prob._pv)[:4]
        np.testing.assert_allclose(ours, ctx.field(t, x, st), rtol=0, atol=1e-12)


def test_admissible_monitors_and_entry_saltation(on_signature):
    """The orbit is admissible (weights in [0, 1] along the intersection, the entry into it
    with weights in [0, 1]); its monitors are positive; the saltation matrix of the entry into
    the intersection (the sliding-entry formula ``I + (f_out - f_in) h_x / (h_x f_in)`` with
    the closed-form field after) equals the kernel's at the same point to 1e-10 (the two
    fields agree to round-off; the entry's normal velocity is O(0.1))."""
    prob, u = OrbitProblem.from_orbit(on_signature)
    ev = prob.evaluate(u)
    assert prob.admissibility(u, evaluation=ev).admissible
    mons = prob.dib_monitors(u, evaluation=ev)
    assert mons and all(v.value > 0 for v in mons.values())
    i = [f.kind for f in prob.fields].index("slide_multi") - 1
    s = ev.segs[i]
    ctx = ModelContext(BELT, {**pwsdyn.load_model(BELT).parameters, **KC})
    before = KernelState(SLIDE, prob.fields[i].index, int(ctx.stab[prob.fields[i].index]["above"]))
    after = KernelState(SLIDE_MULTI, prob.fields[i + 1].index, prob.fields[i + 1].mode)
    full, _ = ctx.saltation("slide_start", "w2", s.te, s.y[:4], s.X[:4], before, after)
    S = prob.boundary_saltation(i, s)
    assert np.abs(S - np.eye(4)).max() > 1e-2          # a true jump of the field
    np.testing.assert_allclose(S, full, rtol=0, atol=1e-10)


def _return_map_multipliers(orbit, params, h=1e-6):
    """The nontrivial multiplier of ``orbit`` from central differences of the return map of
    simulations (rtol 1e-13) to the hyperplane through a point of the orbit where both
    blocks slip, normal to the field there."""
    t1 = orbit.t0 + 1.0
    x0 = np.asarray(orbit.trajectory(t1), dtype=float)
    V = params.get("V", pwsdyn.load_model(BELT).parameters["V"])
    assert abs(x0[1] - V) > 0.05 and abs(x0[3] - V) > 0.05
    T = orbit.period
    ctx = ModelContext(BELT, {**pwsdyn.load_model(BELT).parameters, **params})
    normal = ctx.mode_field(3, t1, x0)        # blocks[w1<0,w2<0]: both slower than the belt

    def ret(x):
        run = pwsdyn.simulate(BELT, x, (t1, t1 + 1.2 * T), params=params, rtol=1e-13,
                              atol=1e-13)
        t = brentq(lambda s: normal @ (run(s) - x0), t1 + 0.9 * T, t1 + 1.1 * T, xtol=1e-14)
        return run(t)

    assert np.abs(ret(x0) - x0).max() < 1e-9
    J = np.column_stack([(ret(x0 + h * e) - ret(x0 - h * e)) / (2 * h) for e in np.eye(4)])
    return sorted(np.linalg.eigvals(J), key=abs)


def test_continuation_through_the_intersection_segment(on_signature):
    """``continue_orbit`` in ``kc`` keeps the signature with its intersection segment;
    the multiplier at a point away from the start against central differences of the
    simulated return map, to 1e-6 (h = 1e-6: truncation ~h^2, the runs' error over h
    ~1e-7)."""
    br = pwsdyn.continue_orbit(BELT, on_signature, "kc", span=(1.9, 2.1), ds=0.02,
                               max_points=4, direction="up", params=KC)
    assert len(br) >= 3 and br.values.max() > 2.03
    assert len(br.signatures) == 1 and "slide_multi:w1&w2" in str(br.signatures[0])
    assert br.admissible.all()
    p = br.points[len(br) - 1]
    orbit = br.problem.orbit(p.u, p.lam)
    fd = _return_map_multipliers(orbit, {"kc": float(p.lam)})
    mu = sorted(np.asarray(p.data["multipliers"]), key=abs)
    assert abs(mu[-1] - fd[-1]) < 1e-6 * abs(fd[-1])
    assert max(abs(v) for v in fd[:-1]) < 1e-6
    # the multiplier moves along the branch
    assert abs(mu[-1] - on_signature.multipliers[0]) > 1e-3


#: Two relays whose second condition couples the signs: y' = sign(x) sign(y) - 2 sign(y) + 1/2
#: is bilinear in the signs, so its tangency condition on the intersection has a
#: lambda_x lambda_y term.
NONLINEAR = {"name": "coupled-relays", "states": ["x", "y"],
             "modes": {"m": {"x": "0.5 - sign(x)", "y": "0.5 + sign(x)*sign(y) - 2*sign(y)"}}}


def test_nonlinear_weights_are_refused_clearly():
    m = pwsdyn.load_model(NONLINEAR)
    below = [nm for nm in m.mode_names if "x<0" in nm and "y<0" in nm][0]
    sig = Signature.parse(f"({below}) slide_start:x (slide:x) slide_start:y "
                          f"(slide_multi:x&y) slide_end:x (slide:y) slide_end:y ({below})")
    with pytest.raises(pwsdyn.OrbitError, match="not linear in the weights.*plain shooting"):
        OrbitProblem(m, sig)


def test_switch_variants_follow_the_signature(on_signature):
    """The belt's mode is split at both surfaces, so two switches are named ``w1`` (one with
    ``w2 > 0``, one with ``w2 < 0``): sliding on ``w1`` with block 2 slower than the belt, and
    on ``w2`` after block 1 released below, take the variants between the modes with
    ``w2 < 0`` and ``w1 < 0``; the intersection keeps the corner above both."""
    prob, _ = OrbitProblem.from_orbit(on_signature)
    m = prob.model
    names = list(m.mode_names)
    kinds = [(f.kind, f.index) for f in prob.fields]
    assert kinds[0] == ("mode", names.index("blocks[w1<0,w2<0]"))
    sw1, sw2 = m.switches[kinds[1][1]], m.switches[kinds[3][1]]
    assert (sw1.name, names[sw1.above], names[sw1.below]) == (
        "w1", "blocks[w1>0,w2<0]", "blocks[w1<0,w2<0]")
    assert (sw2.name, names[sw2.above], names[sw2.below]) == (
        "w2", "blocks[w1<0,w2>0]", "blocks[w1<0,w2<0]")
    assert kinds[2] == ("slide_multi", 0b11) and names[prob.fields[2].mode] == \
        "blocks[w1>0,w2>0]"
    # block 1 leaves the intersection below (its weight rises to 1)
    assert prob.bounds[2].cond[-1] == 1 and prob.bounds[2].direction == 1


#: Two relays and a state driven by the product of their signs (tests/test_intersections.py):
#: the field is bilinear in the signs but the tangency conditions on x = y = 0 are linear.
BILINEAR = {"name": "two-relays", "states": ["x", "y", "z"],
            "modes": {"m": {"x": "0.5 - sign(x)", "y": "sign(x) - 2*sign(y)",
                            "z": "1 + sign(x)*sign(y)"}}}


def test_closed_form_field_of_a_bilinear_field_is_the_kernels():
    """On x = y = 0 the weights solve ``0.5 - (1 - 2 a) = 0`` and
    ``(1 - 2 a) - 2 (1 - 2 b) = 0``: ``a = 1/4``, ``b = 3/8``, so ``z' = 1 + (1/2)(1/4)
    = 9/8`` (the multilinear extension of ``sign(x) sign(y)`` is the product of the mean
    signs). The generated field matches it and the kernel's Newton iteration to 1e-14."""
    import sympy as sp

    from pwsdyn.orbits._segments import FieldKey, _Symbolic

    m = pwsdyn.load_model(BILINEAR)
    ctx = ModelContext(m, {})
    st = ctx.state("slide_multi:x&y")
    sym = _Symbolic(m, "convex")
    field, lam = sym.multi(st.index, st.mode)
    fn = sp.lambdify(m.state_symbols, list(field))
    assert [float(v) for v in lam] == pytest.approx([0.25, 0.375], abs=1e-15)
    assert list(sym.field(FieldKey("slide_multi", st.index, st.mode))) == list(field)
    for z in (-1.0, 0.3, 2.0):
        x = np.array([0.0, 0.0, z])
        np.testing.assert_allclose(fn(*x), [0.0, 0.0, 9 / 8], rtol=0, atol=1e-14)
        np.testing.assert_allclose(ctx.field(0.0, x, st), [0.0, 0.0, 9 / 8], rtol=0,
                                   atol=1e-14)


def test_admissibility_sees_a_weight_past_one(on_signature):
    """The intersection segment run 0.3 past its end (block 1's spring force beyond its
    static friction, ``lambda_1 = (1 + S_1 / Fs1) / 2 > 1``): not admissible, with the
    weight named as the reason."""
    prob, u = OrbitProblem.from_orbit(on_signature)
    i = [f.kind for f in prob.fields].index("slide_multi")
    bad = u.copy()
    bad[prob._Tcol(i)] += 0.3
    adm = prob.admissibility(bad)
    assert not adm.admissible
    assert any("'w1' on the intersection (its weight must stay <= 1)" in v
               for v in adm.violations)


def test_switching_past_a_weight_touch_inside_the_intersection_gives_the_reason(on_signature):
    """``on_dib='switch'`` at an adding-sliding monitor of the intersection segment
    (``AS/<surface>:<side>/<i>``: a weight reaching 0 or 1 inside it, a contact that releases
    and sticks again) has no new signature to build: the switch returns why (the branch then
    ends there with ``SWITCH_FAILED`` and that text). On this orbit the weights are linear in
    time along the segment (module docstring: ``S_i`` grows as ``k_i V t`` while both stick),
    so no such touch occurs on its branch; the reason is checked at the monitor's key."""
    from pwsdyn.continuation.dib import past_graze

    prob, u = OrbitProblem.from_orbit(on_signature)
    i = [f.kind for f in prob.fields].index("slide_multi")
    why = past_graze(prob, f"AS/w1:below/{i}", u, 2.0)
    assert isinstance(why, str)
    assert why.startswith("no orbit past the AS: a weight of segment")
    assert "reaches the edge of [0, 1] inside it" in why
