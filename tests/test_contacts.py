"""Many friction contacts and two relays: motions that stick or slide on several switching
surfaces at once, against closed forms derived here (issue 27).

Each closed form is first checked against scipy's ``solve_ivp`` on its smooth pieces (tests
that need no kernel support for intersections); the tests marked ``needs_multi`` compare
pwsdyn's event-driven runs with them and are skipped while the kernel has no sliding state
for intersections of switching surfaces.

Closed forms (``s_i = sign(...)`` the contact's side, ``w = sqrt(k/m)``):

* one Coulomb oscillator ``x'' + k x = -F sign(v - V)`` (m = 1) slips harmonically about
  ``c = -s F / k`` (:func:`coulomb_oscillator`); arriving at ``v = V`` from above with
  ``|k x| < F`` it sticks (``x' = V``) until ``k x = F``, then slips about ``F / k`` as
  ``x = F/k + (V/w) sin(w (t - t_r))``, ``v = V cos(w (t - t_r))``, which touches ``v = V``
  again (tangentially) after one period ``2 pi / w``;
* two blocks on a belt, both stuck: spring forces ``S_i = k_i x_i + kc (x_i - x_j)`` grow as
  ``S_i(0) + k_i V t`` (:func:`two_block_releases`);
* the two-relay system of the zoo on its intersection: ``x3(t) = x3(te) exp(rho (t - te))``,
  ``rho = mu - 3 b / 2`` (:func:`relay_intersection`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, root

import pwsdyn
from pwsdyn import _codes

#: the kernel has a sliding state for intersections of switching surfaces
HAS_MULTI = any("multi" in kind for kind in _codes.STATE_KINDS)
needs_multi = pytest.mark.skipif(not HAS_MULTI, reason="the kernel has no sliding state on "
                                 "intersections of switching surfaces yet")

#: scipy's tolerance for the references (rtol = atol): the closed forms agree with it to
#: about 1e-10 over these short spans.
SCIPY_TOL = 1e-12


# ======================================================================================
# one Coulomb oscillator: slip, stick, release (closed form)
# ======================================================================================

def _harmonic(t, t0, x0, v0, c, w):
    """``x'' = -w^2 (x - c)`` from ``(x0, v0)`` at ``t0``."""
    tau = np.asarray(t, float) - t0
    x = c + (x0 - c) * np.cos(w * tau) + (v0 / w) * np.sin(w * tau)
    v = -(x0 - c) * w * np.sin(w * tau) + v0 * np.cos(w * tau)
    return x, v


def coulomb_oscillator(x0, v0, k, F, V):
    """Phases of ``x'' + k x = -F sign(v - V)`` from ``v0 > V`` with arrival at the belt
    speed in the sticking range: ``(ta, tr, tg, xa)``: arrival at ``v = V`` (at ``x = xa``),
    release at ``k x = F`` and the tangential return to ``v = V`` one period later.

    Slip above the belt (s = +1) is harmonic about ``c = -F/k``:
    ``v(tau) = R cos(w tau + phi)`` with ``R cos phi = v0``, ``R sin phi = w (x0 - c)``; it
    reaches ``V`` first where ``w tau + phi = arccos(V / R)`` (mod 2 pi), the first such
    ``tau > 0``."""
    assert v0 > V > 0
    w = math.sqrt(k)
    c = -F / k
    R = math.hypot(v0, w * (x0 - c))
    phi = math.atan2(w * (x0 - c), v0)
    theta = math.acos(V / R)
    tau = (theta - phi) % (2 * math.pi)
    ta = tau / w
    xa = float(_harmonic(ta, 0.0, x0, v0, c, w)[0])
    assert abs(k * xa) < F, "the arrival must be in the sticking range"
    tr = ta + (F / k - xa) / V
    return ta, tr, tr + 2 * math.pi / w, xa


def coulomb_state(t, x0, v0, k, F, V):
    """The closed-form state ``(x, v)`` at times ``t`` before the return ``tg``."""
    ta, tr, tg, xa = coulomb_oscillator(x0, v0, k, F, V)
    t = np.asarray(t, float)
    assert np.all(t <= tg)
    w = math.sqrt(k)
    x1, v1 = _harmonic(t, 0.0, x0, v0, -F / k, w)
    x3, v3 = _harmonic(t, tr, F / k, V, F / k, w)
    x = np.where(t < ta, x1, np.where(t < tr, xa + V * (t - ta), x3))
    v = np.where(t < ta, v1, np.where(t < tr, V, v3))
    return x, v


#: three uncoupled oscillators (k, F, x0, v0) with V = 0.2: their sticking intervals overlap,
#: first two, then all three at once, then two again
OSCILLATORS = [(1.0, 1.0, 0.0, 0.8), (2.0, 1.5, 0.3, 0.6), (0.5, 0.4, -0.2, 0.5)]
BELT = 0.2


def _coulomb_scipy(t_out, x0, v0, k, F, V):
    """The same motion from scipy on each smooth piece: slip with ``s = +1`` until
    ``v = V``, the stick ``x' = V`` until ``k x = F``, slip with ``s = -1``."""
    def slip(s):
        return lambda t, y: [y[1], -k * y[0] - F * s]

    def arrive(t, y):
        return y[1] - V
    arrive.terminal, arrive.direction = True, -1
    a = solve_ivp(slip(1), (0, 50), [x0, v0], events=arrive, rtol=SCIPY_TOL,
                  atol=SCIPY_TOL, dense_output=True)
    ta = a.t_events[0][0]

    def release(t, y):
        return k * y[0] - F
    release.terminal = True
    b = solve_ivp(lambda t, y: [V], (ta, ta + 50), [a.y_events[0][0][0]], events=release,
                  rtol=SCIPY_TOL, atol=SCIPY_TOL, dense_output=True)
    tr = b.t_events[0][0]
    c = solve_ivp(slip(-1), (tr, tr + 50), [b.y_events[0][0][0], V], rtol=SCIPY_TOL,
                  atol=SCIPY_TOL, dense_output=True)
    out = np.empty((2, len(t_out)))
    for i, t in enumerate(t_out):
        out[:, i] = (a.sol(t) if t < ta else [b.sol(t)[0], V] if t < tr else c.sol(t))
    return (ta, tr), out


@pytest.mark.parametrize("case", OSCILLATORS)
def test_coulomb_closed_form_against_scipy(case):
    k, F, x0, v0 = case
    ta, tr, tg, _ = coulomb_oscillator(x0, v0, k, F, BELT)
    ts = np.linspace(0.0, tg, 400)
    (sa, sr), ref = _coulomb_scipy(ts, x0, v0, k, F, BELT)
    # scipy's event location and its integration at 1e-12 over a few periods: 1e-9
    assert (ta, tr) == pytest.approx((sa, sr), abs=1e-9)
    np.testing.assert_allclose(np.array(coulomb_state(ts, x0, v0, k, F, BELT)), ref,
                               rtol=0, atol=1e-9)


def _uncoupled_model(cases):
    """Independent 1-DOF Coulomb oscillators in one model, one sign() per contact."""
    mode, states, params = {}, [], {"V": BELT}
    for i, (k, F, _, _) in enumerate(cases, 1):
        params[f"k{i}"], params[f"F{i}"] = k, F
        states += [f"x{i}", f"v{i}"]
        mode[f"x{i}"] = f"v{i}"
        mode[f"v{i}"] = f"-k{i}*x{i} - F{i}*sign(v{i} - V)"
    return {"name": "uncoupled-contacts", "states": states, "parameters": params,
            "modes": {"contacts": mode}}


def _uncoupled_span(cases):
    """End of the common span before any oscillator returns tangentially to its belt."""
    return min(coulomb_oscillator(x0, v0, k, F, BELT)[2] for k, F, x0, v0 in cases) - 0.05


def test_uncoupled_sticking_intervals_overlap():
    """The test case is what it claims: the oscillators stick together for a while, two at
    once and all three at once."""
    phases = [coulomb_oscillator(x0, v0, k, F, BELT)[:2] for k, F, x0, v0 in OSCILLATORS]
    end = _uncoupled_span(OSCILLATORS)
    ts = np.linspace(0.0, end, 20001)
    sticking = sum(((ta <= ts) & (ts < tr)).astype(int) for ta, tr in phases)
    assert sticking.max() == 3 and (sticking == 2).any()
    assert all(tr < end for _, tr in phases)


def test_one_contact_against_its_closed_form():
    """The single-contact path the multi-contact runs reduce to, today: each oscillator
    alone, through its slip, stick and release, to 1e-8."""
    for k, F, x0, v0 in OSCILLATORS:
        ta, tr, tg, _ = coulomb_oscillator(x0, v0, k, F, BELT)
        traj = pwsdyn.simulate(_uncoupled_model([(k, F, x0, v0)]), [x0, v0], tg - 0.05,
                               rtol=1e-12, atol=1e-12)
        assert traj.success
        ts = np.linspace(0.0, tg - 0.05, 500)
        np.testing.assert_allclose(traj(ts).T, np.array(coulomb_state(ts, x0, v0, k, F, BELT)),
                                   rtol=0, atol=1e-8)
        kinds = [e.kind for e in traj.events]
        assert kinds == ["slide_start", "slide_end"], traj.events
        assert [e.t for e in traj.events] == pytest.approx([ta, tr], abs=1e-9)


@needs_multi
def test_uncoupled_contacts_reproduce_each_closed_form():
    """Issue 27 acceptance: independent contacts stick and slip contact by contact; through
    the intervals where two and three stick at once each one follows its own closed form,
    to 1e-8."""
    end = _uncoupled_span(OSCILLATORS)
    x0 = [c for k, F, x, v in OSCILLATORS for c in (x, v)]
    traj = pwsdyn.simulate(_uncoupled_model(OSCILLATORS), x0, end, rtol=1e-12, atol=1e-12)
    assert traj.success, traj.message
    ts = np.linspace(0.0, end, 2000)
    got = traj(ts)
    for i, (k, F, x, v) in enumerate(OSCILLATORS):
        np.testing.assert_allclose(got[:, 2 * i:2 * i + 2].T,
                                   np.array(coulomb_state(ts, x, v, k, F, BELT)),
                                   rtol=0, atol=1e-8)
    # each contact's arrival and release among the events, to 1e-9
    times = np.array([e.t for e in traj.events])
    for k, F, x, v in OSCILLATORS:
        ta, tr, _, _ = coulomb_oscillator(x, v, k, F, BELT)
        assert np.abs(times - ta).min() < 1e-9 and np.abs(times - tr).min() < 1e-9


# ======================================================================================
# two blocks on a belt, both stuck
# ======================================================================================

#: the zoo's two-block-belt with pure Coulomb friction (delta = 0: the friction is Fs_i in
#: every slip), so that the slip of the first block to release is in closed form too
BELT2 = {"delta": 0.0}


def two_block_releases(p, x10=0.0, x20=0.0):
    """Release times ``(t1, t2)`` of the two-block belt started with both blocks stuck at
    ``(x10, x20)`` (``v1 = v2 = V``), block 1 releasing first, for ``delta = 0``.

    Both stuck: ``x_i = x_i0 + V t``, so ``S_i(t) = k_i x_i + kc (x_i - x_j) = S_i(0) +
    k_i V t`` (the coupling spring keeps its length) and block ``i`` would release at
    ``(Fs_i - S_i(0)) / (k_i V)``. After block 1 releases at ``t1`` it slips backwards
    (``v1 < V``, friction ``+Fs1``) while block 2 moves on at ``V``:
    ``m1 x1'' = -(k1 + kc) x1 + kc x2(t) + Fs1`` with ``x2`` linear in ``t``, whose solution
    is the particular ``x1p = (kc x2(t) + Fs1) / (k1 + kc)`` plus a harmonic of
    ``W = sqrt((k1 + kc) / m1)``; at ``t1``, ``x1 - x1p = (S_1 - Fs1) / (k1 + kc) = 0`` and
    ``v1 - x1p' = V k1 / (k1 + kc)``, so
    ``x1 = x1p + V k1 / ((k1 + kc) W) sin(W (t - t1))``, ``v1 = V (kc + k1 cos(W (t - t1)))
    / (k1 + kc) <= V``. Block 2 releases at the first root of
    ``S_2(t) = (k2 + kc) x2(t) - kc x1(t) = Fs2``, if that comes before block 1 is back at
    the belt speed (``W (t - t1) = 2 pi``)."""
    k1, k2, kc, V, m1 = p["k1"], p["k2"], p["kc"], p["V"], p["m1"]
    s1 = k1 * x10 + kc * (x10 - x20)
    s2 = k2 * x20 + kc * (x20 - x10)
    t1 = (p["Fs1"] - s1) / (k1 * V)
    assert t1 < (p["Fs2"] - s2) / (k2 * V), "block 1 must release first"
    W = math.sqrt((k1 + kc) / m1)
    x2_at = lambda t: x20 + V * t  # noqa: E731

    def x1_at(t):
        return ((kc * x2_at(t) + p["Fs1"]) / (k1 + kc)
                + V * k1 / ((k1 + kc) * W) * math.sin(W * (t - t1)))

    def g(t):
        return (k2 + kc) * x2_at(t) - kc * x1_at(t) - p["Fs2"]
    end = t1 + 2 * math.pi / W
    assert g(t1) < 0 < g(end)
    return t1, brentq(g, t1, end, xtol=1e-15), x1_at


def _belt_params():
    m = pwsdyn.load_model("two-block-belt")
    return {**m.parameters, **BELT2}


def test_two_block_closed_form_against_scipy():
    """Both stuck, then block 1 slipping and block 2 stuck: the releases from scipy on those
    two smooth pieces (the stick condition of each block an event on its spring force)."""
    p = _belt_params()
    t1, t2, x1_at = two_block_releases(p)
    k1, k2, kc, V = p["k1"], p["k2"], p["kc"], p["V"]

    def rel1(t, y):   # y = (x1, x2) with both stuck
        return k1 * y[0] + kc * (y[0] - y[1]) - p["Fs1"]
    rel1.terminal = True
    a = solve_ivp(lambda t, y: [V, V], (0, 50), [0.0, 0.0], events=rel1, rtol=SCIPY_TOL,
                  atol=SCIPY_TOL)
    assert a.t_events[0][0] == pytest.approx(t1, abs=1e-9)
    x1, x2 = a.y_events[0][0]

    def rhs(t, y):    # y = (x1, v1, x2): block 1 slips backwards (friction +Fs1)
        return [y[1], (-k1 * y[0] - kc * (y[0] - y[2]) + p["Fs1"]) / p["m1"], V]

    def rel2(t, y):
        return k2 * y[2] + kc * (y[2] - y[0]) - p["Fs2"]
    rel2.terminal = True
    b = solve_ivp(rhs, (t1, t1 + 50), [x1, V, x2], events=rel2, rtol=SCIPY_TOL,
                  atol=SCIPY_TOL, dense_output=True)
    assert b.t_events[0][0] == pytest.approx(t2, abs=1e-9)
    ts = np.linspace(t1, t2, 50)
    np.testing.assert_allclose(b.sol(ts)[0], [x1_at(t) for t in ts], rtol=0, atol=1e-9)
    # block 1 slips (v1 < V) all the way to block 2's release
    assert np.all(b.sol(ts[1:])[1] < V)


@needs_multi
def test_two_blocks_stuck_release_one_by_one():
    """Issue 27 acceptance: from both blocks stuck, block 1 releases at the closed-form time
    ``Fs1 / (k1 V)``; block 2 keeps sticking (v2 = V, x2 = V t) until its own spring force
    reaches ``Fs2``, at the root of the closed form; event times to 1e-9."""
    p = _belt_params()
    t1, t2, x1_at = two_block_releases(p)
    V = p["V"]
    traj = pwsdyn.simulate("two-block-belt", [0.0, V, 0.0, V], t2 + 0.5, params=BELT2,
                           rtol=1e-12, atol=1e-12)
    assert traj.success, traj.message
    times = np.array([e.t for e in traj.events])
    assert times[(times > 1e-12)].min() == pytest.approx(t1, abs=1e-9)
    assert np.abs(times - t2).min() < 1e-9
    ts = np.linspace(0.0, t2, 300)
    got = traj(ts)
    np.testing.assert_allclose(got[:, 3], V, rtol=0, atol=1e-10)        # block 2 stuck
    np.testing.assert_allclose(got[:, 2], V * ts, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[ts <= t1, 1], V, rtol=0, atol=1e-10)
    after = ts[ts > t1]
    np.testing.assert_allclose(traj(after)[:, 0], [x1_at(t) for t in after], rtol=0,
                               atol=1e-8)


# ======================================================================================
# two relays sliding on the intersection x1 = x2 = 0
# ======================================================================================

def _relay_params():
    return pwsdyn.load_model("two-relay").parameters


def relay_field(x, s1, s2, p):
    """The zoo's two-relay field with the relay values ``s_i`` in place of ``sign(x_i)``."""
    return np.array([-x[0] + x[2] - s1, -x[1] + x[2] / 4 + s1 / 4 - s2,
                     p["mu"] * x[2] - p["b"] * (s1 + s2)])


def relay_intersection(t, te, ze, p):
    """Sliding on ``x1 = x2 = 0``: ``x1' = 0`` and ``x2' = 0`` fix ``s1 = x3`` and
    ``s2 = x3 / 4 + s1 / 4 = x3 / 2``, so ``x3' = (mu - 3 b / 2) x3``; it ends where
    ``|x3| = 1`` (relay 1 leaves the intersection). Returns ``x3(t)`` and the exit time."""
    rho = p["mu"] - 1.5 * p["b"]
    return ze * np.exp(rho * (np.asarray(t, float) - te)), te + math.log(1 / abs(ze)) / rho


def relay_entry(p, x0=(0.2, 0.4, 0.4)):
    """Entry into the intersection from scipy on the smooth pieces of the zoo's default
    start: both relays at +1 until ``x1 = 0``; sliding on ``x1 = 0`` (``s1 = x3``) until
    ``x2 = 0``. Returns ``(t_x1, te, x3e)``."""
    def hit(i):
        ev = lambda t, y: y[i]   # noqa: E731
        ev.terminal = True
        return ev
    a = solve_ivp(lambda t, y: relay_field(y, 1, 1, p), (0, 20), x0, events=hit(0),
                  rtol=SCIPY_TOL, atol=SCIPY_TOL)
    t_a = a.t_events[0][0]
    y = a.y_events[0][0]
    b = solve_ivp(lambda t, y: relay_field(y, y[2], 1, p), (t_a, 20), [0.0, y[1], y[2]],
                  events=hit(1), rtol=SCIPY_TOL, atol=SCIPY_TOL)
    return t_a, b.t_events[0][0], b.y_events[0][0][2]


def _bilinear_rate(z, p):
    """``x3'`` on the intersection from the Dieci-Lopez bilinear combination of the four
    corner fields, its weights solved numerically (an independent check of the closed form's
    equivalent relay values)."""
    x = np.array([0.0, 0.0, z])

    def combo(ab):
        a, b = ab
        f = ((1 - a) * (1 - b) * relay_field(x, -1, -1, p)
             + a * (1 - b) * relay_field(x, 1, -1, p)
             + (1 - a) * b * relay_field(x, -1, 1, p)
             + a * b * relay_field(x, 1, 1, p))
        return f
    sol = root(lambda ab: combo(ab)[:2], [0.5, 0.5], method="lm", options={"xtol": 1e-15})
    assert sol.success
    ab = sol.x
    assert np.all((0 < ab) & (ab < 1))
    return combo(ab)[2]


def test_relay_closed_form_against_scipy():
    p = _relay_params()
    t_a, te, ze = relay_entry(p)
    assert 0 < t_a < te and 0 < ze < 1
    # the bilinear rule's rate equals (mu - 3b/2) x3 on the intersection
    for z in (-0.9, -0.3, 0.2, 0.7):
        assert _bilinear_rate(z, p) == pytest.approx((p["mu"] - 1.5 * p["b"]) * z, abs=1e-13)
    sol = solve_ivp(lambda t, y: [_bilinear_rate(y[0], p)], (te, te + 3), [ze],
                    rtol=SCIPY_TOL, atol=SCIPY_TOL, dense_output=True)
    ts = np.linspace(te, te + 3, 30)
    np.testing.assert_allclose(sol.sol(ts)[0], relay_intersection(ts, te, ze, p)[0], rtol=0,
                               atol=1e-10)


@needs_multi
def test_two_relays_slide_on_the_intersection():
    """Issue 27 acceptance: the zoo's two-relay run reaches the intersection where scipy's
    piecewise reference does, slides on it as ``x3(te) exp((mu - 3b/2)(t - te))`` and leaves
    it along x2 = 0 where ``|x3| = 1``."""
    p = _relay_params()
    t_a, te, ze = relay_entry(p)
    _, t_exit = relay_intersection(te, te, ze, p)
    traj = pwsdyn.simulate("two-relay", rtol=1e-12, atol=1e-12)
    assert traj.success, traj.message
    times = np.array([e.t for e in traj.events])
    for t in (t_a, te, t_exit):
        assert np.abs(times - t).min() < 1e-8, (t, traj.events)
    ts = np.linspace(te, t_exit, 200)[1:-1]
    got = traj(ts)
    np.testing.assert_allclose(got[:, :2], 0.0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(got[:, 2], relay_intersection(ts, te, ze, p)[0], rtol=0,
                               atol=1e-8)
    # after the exit relay 2 keeps sliding, relay 1 has switched (x1 > 0)
    later = traj(np.linspace(t_exit + 0.1, t_exit + 1.0, 10))
    assert np.all(later[:, 0] > 0) and np.allclose(later[:, 1], 0.0, atol=1e-10)


# ======================================================================================
# the Burridge-Knopoff chain builder
# ======================================================================================

def test_burridge_knopoff_field_is_the_chain():
    """The built field against the chain's equations evaluated here with numpy, at a point
    off every surface: free ends, neighbour springs, the friction law of each block."""
    n = 3
    model = pwsdyn.burridge_knopoff(n, Fs=[1.0, 1.3, 0.9], Fd=0.4, kc=2.0, delta=1.5)
    assert model.name == "burridge-knopoff-3" and len(model.mode_names) == 2 ** n
    p = model.parameters
    rng = np.random.default_rng(27)
    x, v = rng.normal(size=n), rng.normal(size=n)
    w = v - p["V"]
    xs = np.concatenate([x[:1], x, x[-1:]])          # free ends: no force past the ends
    spring = p["kc"] * (xs[2:] - 2 * x + xs[:-2]) - p["kp"] * x
    fs, fd = np.array([1.0, 1.3, 0.9]), 0.4
    friction = np.sign(w) * (fd + (fs - fd) / (1 + p["delta"] * np.abs(w)))
    expected = np.empty(2 * n)
    expected[0::2], expected[1::2] = v, (spring - friction) / p["m"]
    # the variant on the sides of this point
    label = ",".join(f"w{i + 1}{'>' if w[i] > 0 else '<'}0" for i in range(n))
    (mode,) = [md for md in model.modes if md.name.endswith(f"[{label}]")]
    args = {model.t: 0.0, **dict(zip(model.state_symbols, np.ravel(np.column_stack([x, v])))),
            **dict(zip(model.parameter_symbols, model.parameter_vector(None)))}
    got = np.array([float(e.subs(args)) for e in mode.rhs])
    np.testing.assert_allclose(got, expected, rtol=1e-14, atol=1e-14)


@needs_multi
@pytest.mark.parametrize("delta", [0.0, 3.0])
def test_stick_forces_from_the_sign_family_are_the_corner_sum(delta):
    """While several contacts of a chain stick the kernel solves their stick forces from the
    chain's sign family (Newton on the sides); the same chain with its family removed sums
    the 2**k corner fields with multilinear weights (Dieci & Lopez). Coupled (kc = 1), with
    Coulomb (delta = 0: the family is affine in the sides) and velocity-weakening friction
    (delta = 3: affine on the surfaces only), the two runs agree: the same events to 1e-9 in
    time and the states to 1e-8, through intervals where two and three contacts stick."""
    import dataclasses
    chain = pwsdyn.burridge_knopoff(3, kc=1.0, delta=delta)
    assert chain.families and chain.families[0].multilinear
    corners = dataclasses.replace(chain, families=())
    x0 = [0.3, -0.1, -0.2, 0.4, 0.1, 0.0]
    runs = [pwsdyn.simulate(m, x0, 30.0, rtol=1e-12, atol=1e-12) for m in (chain, corners)]
    for r in runs:
        assert r.success, r.message
    a, b = runs
    from pwsdyn.integrate.trajectory import DiscreteState
    stuck = {len(DiscreteState.parse(str(q)).surfaces) for q in a.state
             if DiscreteState.parse(str(q)).kind == "slide_multi"}
    assert {2, 3} <= stuck, stuck
    assert [e.kind for e in a.events] == [e.kind for e in b.events]
    np.testing.assert_allclose([e.t for e in a.events], [e.t for e in b.events], rtol=0,
                               atol=1e-9)
    ts = np.linspace(0.0, 30.0, 3001)
    np.testing.assert_allclose(a(ts), b(ts), rtol=0, atol=1e-8)


def test_burridge_knopoff_one_block_is_the_stick_slip_oscillator():
    """n = 1 with no dynamic friction floor is the zoo's stick-slip oscillator: the same run
    (the expressions differ in form only: rounding)."""
    chain = pwsdyn.burridge_knopoff(1, Fs=1.0, Fd=0.0, kp=1.0, V=0.2, delta=3.0)
    a = pwsdyn.simulate(chain, [0.0, 0.0], 40.0, rtol=1e-10, atol=1e-10)
    b = pwsdyn.simulate("stick-slip-oscillator", [0.0, 0.0], 40.0, rtol=1e-10, atol=1e-10)
    assert [e.kind for e in a.events] == [e.kind for e in b.events]
    np.testing.assert_allclose(a.event_times(), b.event_times(), rtol=0, atol=1e-9)
    ts = np.linspace(0, 40, 200)
    np.testing.assert_allclose(a(ts), b(ts), rtol=0, atol=1e-8)


#: blocks with no coupling (kc = 0) and Coulomb friction (delta = 0): each is the
#: oscillator x'' + x = -Fs sign(v - V); (Fs, x0, v0) chosen so that all of them (the first
#: four, six, eight or all ten) stick at once on [0.518, 2.784] (the closed form's arrival
#: and release times)
CHAIN10 = [(1.0, 0.0, 0.8), (0.8, 0.2, 0.5), (1.2, 0.1, 0.7), (0.9, -0.1, 0.6),
           (1.1, 0.0, 0.7), (0.85, 0.05, 0.55), (0.95, 0.0, 0.65), (1.05, 0.05, 0.6),
           (1.15, -0.05, 0.75), (0.9, 0.1, 0.55)]


@needs_multi
# (8 and 10 blocks: ~25 s and ~60 s to compile the 256- and 1024-variant models on a cold
# cache, so among the long checks)
@pytest.mark.parametrize("n", [4, 6, pytest.param(8, marks=pytest.mark.slow),
                               pytest.param(10, marks=pytest.mark.slow)])
def test_block_chain_follows_each_closed_form_while_all_stick(n):
    """Chains of 4 blocks (16 modes), 6, 8 and the longest the builder makes (10 contacts,
    1024 modes, sliding on the intersection of all ten surfaces, the stick forces solved
    from the chain's sign family): uncoupled, each block follows its own Coulomb
    oscillator's closed form to 1e-8 through the interval where all of them stick at once,
    and each block's arrival and release are events at their closed-form times (1e-9)."""
    from pwsdyn.model.chains import MAX_BLOCKS
    assert MAX_BLOCKS == len(CHAIN10)
    blocks = CHAIN10[:n]
    phases = [coulomb_oscillator(x0, v0, 1.0, F, BELT) for F, x0, v0 in blocks]
    assert max(ta for ta, *_ in phases) < min(tr for _, tr, *_ in phases)   # all stick
    end = min(tg for *_, tg, _ in phases) - 0.05
    chain = pwsdyn.burridge_knopoff(n, kc=0.0, kp=1.0, m=1.0, V=BELT, delta=0.0,
                                    Fs=[F for F, _, _ in blocks])
    x0 = [c for _, x, v in blocks for c in (x, v)]
    traj = pwsdyn.simulate(chain, x0, end, rtol=1e-12, atol=1e-12)
    assert traj.success, traj.message
    ts = np.linspace(0.0, end, 2000)
    got = traj(ts)
    for i, (F, x, v) in enumerate(blocks):
        np.testing.assert_allclose(got[:, 2 * i:2 * i + 2].T,
                                   np.array(coulomb_state(ts, x, v, 1.0, F, BELT)),
                                   rtol=0, atol=1e-8)
    times = np.array([e.t for e in traj.events])
    for ta, tr, *_ in phases:
        assert np.abs(times - ta).min() < 1e-9 and np.abs(times - tr).min() < 1e-9
    # the run was on the intersection of all the surfaces while they all stuck
    mid = 0.5 * (max(ta for ta, *_ in phases) + min(tr for _, tr, *_ in phases))
    k = int(np.searchsorted(traj.t, mid)) - 1
    from pwsdyn.integrate.trajectory import DiscreteState
    state = DiscreteState.parse(str(traj.state[k]))
    assert state.kind == "slide_multi" and len(state.surfaces) == n, state


def test_burridge_knopoff_refuses_what_it_cannot_build():
    from pwsdyn.model.chains import MAX_BLOCKS
    from pwsdyn.model.codegen import MAX_SOURCE_CHARS, _generate_body
    assert 2 ** MAX_BLOCKS <= pwsdyn.model.discontinuities.MAX_FAMILY_MODES
    # the longest chain it builds fits the code generator
    assert len(_generate_body(pwsdyn.burridge_knopoff(MAX_BLOCKS))) <= MAX_SOURCE_CHARS
    for n in (0, MAX_BLOCKS + 1, 2.0, True):
        with pytest.raises(pwsdyn.ArgumentError, match="n must be an integer"):
            pwsdyn.burridge_knopoff(n)
    with pytest.raises(pwsdyn.ArgumentError, match="2 values for 3 blocks"):
        pwsdyn.burridge_knopoff(3, Fs=[1.0, 2.0])
    # per-block values become per-block parameters
    m = pwsdyn.burridge_knopoff(2, Fs=[1.0, 1.5])
    assert (m.parameters["Fs2"], m.parameters["Fd2"]) == (1.5, 0.75)
    assert set(m.units) == set(m.descriptions) == {"t", *m.states, *m.parameters}


# ======================================================================================
# a periodic orbit with a segment on the intersection
# ======================================================================================

#: the two-block belt with a stiffer coupling spring: an orbit on which block 1 sticks, block
#: 2 joins it (both stuck, on the intersection), block 1 releases, then block 2
BELT_ORBIT = {"kc": 2.0}
#: a state near it (rounded from the run's 300th time unit) and its period
BELT_ORBIT_GUESS = ([0.9596, -0.4364, 0.9704, -0.4544], 8.735)


@needs_multi
def test_orbit_with_a_codimension_two_segment_and_its_multipliers():
    """Issue 27 acceptance: a periodic orbit whose signature slides on the intersection of
    both contacts' surfaces, found by shooting from a guess, and its multipliers against
    central differences of its return map to the hyperplane through ``x0`` normal to the
    field (pwsdyn runs at 1e-13). Sliding removes one dimension per surface slid on, so the
    return map's Jacobian has rank 1: one nontrivial multiplier, the others 0.

    Tolerance 1e-6 on the multiplier: central differences with h = 1e-6 err by about
    h^2 |P'''| (1e-12) plus the runs' error over h (1e-13 / 1e-6 = 1e-7)."""
    x_guess, period = BELT_ORBIT_GUESS
    orbit = pwsdyn.find_periodic_orbit("two-block-belt", x_guess, period=period,
                                       params=BELT_ORBIT)
    assert "slide_multi" in str(orbit.signature)
    x0, T, t0 = np.asarray(orbit.x0, float), orbit.period, orbit.t0
    model = pwsdyn.load_model("two-block-belt")
    p = {**model.parameters, **BELT_ORBIT}

    def field(x):       # the slip field of both blocks, for the section's normal
        def friction(w, fs, fd):
            return math.copysign(fd + (fs - fd) / (1 + p["delta"] * abs(w)), w)
        w1, w2 = x[1] - p["V"], x[3] - p["V"]
        return np.array([x[1], (-p["k1"] * x[0] - p["kc"] * (x[0] - x[2])
                                - friction(w1, p["Fs1"], p["Fd1"])) / p["m1"],
                         x[3], (-p["k2"] * x[2] - p["kc"] * (x[2] - x[0])
                                - friction(w2, p["Fs2"], p["Fd2"])) / p["m2"]])
    assert abs(x0[1] - p["V"]) > 0.1 and abs(x0[3] - p["V"]) > 0.1   # both slip at x0
    normal = field(x0)

    def ret(x):
        run = pwsdyn.simulate("two-block-belt", x, (t0, t0 + 1.2 * T), params=BELT_ORBIT,
                              rtol=1e-13, atol=1e-13)
        t = brentq(lambda s: normal @ (run(s) - x0), t0 + 0.9 * T, t0 + 1.1 * T, xtol=1e-14)
        return run(t)

    assert np.abs(ret(x0) - x0).max() < 1e-10
    h = 1e-6
    J = np.column_stack([(ret(x0 + h * e) - ret(x0 - h * e)) / (2 * h) for e in np.eye(4)])
    fd = sorted(np.linalg.eigvals(J), key=abs)
    mult = sorted(np.asarray(orbit.multipliers), key=abs)
    assert abs(mult[-1].real) > 1.5 and abs(mult[-1].imag) < 1e-12   # unstable, flip
    assert fd[-1] == pytest.approx(mult[-1], rel=1e-6)
    assert max(abs(v) for v in fd[:-1]) < 1e-6 and max(abs(v) for v in mult[:-1]) < 1e-6


# ======================================================================================
# undamped Coulomb friction: tangential returns to the belt speed
# ======================================================================================

def coulomb_periodic(t, k, F, x0, v0, V=BELT):
    """``x'' + k x = -F sign(v - V)`` (m = 1) from a slip above the belt (``v0 > V``) or a
    stick (``v0 = V``, ``|k x0| < F``), for all ``t``. After the release at ``k x = F`` the
    block slips below the belt about ``F / k``: ``x = F/k + (V/w) sin(w (t - t_r))``,
    ``v = V cos(w (t - t_r))``. That motion comes back to ``v = V`` every period ``2 pi / w``
    exactly at ``x = F / k``, tangentially (``v' = -w^2 (x - F/k) = 0``): the stick
    condition holds there with equality and sticking would end at once (``x`` grows at
    ``V``), so the harmonic motion goes on -- undamped Coulomb slip is periodic after the
    first release."""
    t = np.asarray(t, float)
    w = math.sqrt(k)
    if v0 > V:
        ta, tr, _, xa = coulomb_oscillator(x0, v0, k, F, V)
        x1, v1 = _harmonic(t, 0.0, x0, v0, -F / k, w)
    else:
        ta, tr, xa = 0.0, (F / k - x0) / V, x0
        x1, v1 = x0 + V * t, np.full_like(t, V)
    x3, v3 = _harmonic(t, tr, F / k, V, F / k, w)
    x = np.where(t < ta, x1, np.where(t < tr, xa + V * (t - ta), x3))
    v = np.where(t < ta, v1, np.where(t < tr, V, v3))
    return x, v


#: (k, F, x0, v0) of two contacts that slip, then stick on [0.518, 4.193] (A) and
#: [0.788, 4.372] (B)
TANGENT_A = (1.0, 1.0, 0.0, 0.8)
TANGENT_B = (0.5, 0.4, -0.2, 0.5)


@needs_multi
@pytest.mark.parametrize("k, offset, with_b", [
    (9.0, 0.02, False), (16.0, 0.03, False), (36.0, 0.02, False),
    (25.0, 0.02, True), (36.0, 0.05, True), (9.0, 0.02, True)])
@pytest.mark.parametrize("exact", [False, True])
def test_tangential_returns_to_the_belt_speed_go_on(k, offset, with_b, exact):
    """A contact C (k, F = 1) that starts stuck ``offset / V`` before its release and then
    slips back to the belt speed tangentially every ``2 pi / sqrt(k)`` (undamped Coulomb
    friction), next to A (and B), which stick for a while: C's returns happen while the others
    slip, while A sticks (sliding on one surface) and while A and B stick (on their
    intersection). Every run goes on to t = 14 (before the kernel took a tangential return
    while sliding for an arrival at the intersection, and these runs -- chosen among those
    where it did, by the sign of the integration error at the touch -- ended with
    ``SURFACE_INTERSECTION`` at a return) and each block follows its own closed form
    :func:`coulomb_periodic` to 1e-8 (the tolerance of the other acceptance tests; measured
    below 5e-11), on the Runge-Kutta path and with ``exact=True``."""
    cases = [TANGENT_A] + ([TANGENT_B] if with_b else []) + [(k, 1.0, 1.0 / k - offset, BELT)]
    x0 = [c for kk, F, x, v in cases for c in (x, v)]
    T = 14.0
    traj = pwsdyn.simulate(_uncoupled_model(cases), x0, T, rtol=1e-12, atol=1e-12,
                           exact=exact, throw=False)
    assert traj.status == pwsdyn.Status.SUCCESS, traj.message
    ts = np.linspace(0.0, T, 1401)
    got = traj(ts)
    for i, case in enumerate(cases):
        np.testing.assert_allclose(got[:, 2 * i:2 * i + 2].T,
                                   np.array(coulomb_periodic(ts, *case)), rtol=0, atol=1e-8)


def test_one_coulomb_oscillator_through_its_tangential_returns():
    """One undamped Coulomb oscillator through three tangential returns to the belt speed,
    against :func:`coulomb_periodic`, to 1e-8."""
    k, F, x, v = TANGENT_A
    T = 20.0
    traj = pwsdyn.simulate(_uncoupled_model([TANGENT_A]), [x, v], T, rtol=1e-12, atol=1e-12)
    ts = np.linspace(0.0, T, 801)
    np.testing.assert_allclose(traj(ts).T, np.array(coulomb_periodic(ts, k, F, x, v)), rtol=0,
                               atol=1e-8)
