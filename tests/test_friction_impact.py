"""The friction impact oscillator of thesis Papers D/E (zoo ``friction-impact-oscillator``):
condition 5.1 on both sides of it, the stick-position map and its multiplier gamma - 1, the
control law 5.3 with the fixed point and multiplier 2 c_x - 1 it predicts, its robustness
(5.7-5.13), and the Fs > Fd variant of section 5.3.1 (stick solutions up to a**).

The references are independent of the simulator: the closed-form one-step map from the
analytic solution (sin/cos ellipses and the constraint; :mod:`pwsdyn.grazing.friction_impact`,
eq. (2) there), whose fixed points solve a quadratic written out again below, and the
lowest-order map (3)/(4) of the thesis. With m = k = Fd = 1 the model's q is the thesis's
scaled x, and b = 1 puts the graze at a* = b + 1 = 2, where gamma = (1 + e)^2 omega^2 (eq. 5.1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn.errors import ArgumentError
from pwsdyn.grazing import ControlGains, FrictionImpact, controlled_model
from pwsdyn.model.control import with_discrete_control

MODEL = "friction-impact-oscillator"
E = 0.8
A_STAR = 2.0


def _omega(gamma):
    # eq. 5.1 with m = Fd = 1, a* = 2: gamma = (1 + e)^2 omega^2
    return math.sqrt(gamma) / (1 + E)


def _fio(gamma, a, Fs=1.0, **kw):
    return FrictionImpact.from_params({"Fs": Fs, "Fd": 1.0, "b": 1.0, "a": a, "e": E,
                                       "omega": _omega(gamma)}, **kw)


def _quadratic_fixed_point(gamma, a, b=1.0, upper=False):
    """Fixed point of the closed-form map x' = 3 - sqrt((x+1)^2 + K (a^2 - (x+b)^2)),
    K = (1+e)^2 omega^2 = gamma: squaring, K x^2 + (2 K b - 8) x + K b^2 + 8 - K a^2 = 0; the
    root below the edge x = 1 nearest it, or with ``upper`` the other one (the upper branch
    of thesis Fig. 2.3 (a): the larger excursion)."""
    K = gamma
    r = np.roots([K, 2 * K * b - 8, K * b * b + 8 - K * a * a])
    r = sorted(x.real for x in r if abs(x.imag) < 1e-12 and x.real < 1.0)
    return r[0] if upper else r[-1]


def _impact_velocity(omega, a, x, b=1.0):
    """Relative velocity of the constraint hitting the mass at rest at x: a omega cos(theta)
    with a sin(theta) = x + b on the rising branch."""
    return omega * math.sqrt(a * a - (x + b) ** 2)


def _sweep_impact_velocity(ds, omega):
    """Largest relative impact velocity over the window at each value, per direction (0 where
    the window has no impact: the mass sticks)."""
    a = ds["a"].values[None, :, None]
    w = a * omega * np.cos(2 * np.pi * ds["phase"].values) - ds["section"].values[..., 1]
    w = np.where(np.isnan(w), 0.0, w)
    return {str(d): w[i].max(axis=1) for i, d in enumerate(ds["direction"].values)}


# -------------------------------------------------------------------------------------------
# the thesis's quantities
# -------------------------------------------------------------------------------------------
def test_gamma_a_star_a_star_star_and_the_closed_form_map():
    s = FrictionImpact.from_params({"m": 2.0, "k": 3.0, "Fd": 0.5, "Fs": 0.7, "b": 0.4,
                                    "a": 0.6, "omega": 1.1, "e": 0.7})
    assert s.a_star == pytest.approx(0.4 + 0.5 / 3.0, rel=1e-15)
    assert s.a_star_star == pytest.approx(0.4 + 0.7 / 3.0, rel=1e-15)
    # eq. 5.1 as printed: m a* omega^2 (1 + e)^2 / (2 F_f)
    assert s.gamma == pytest.approx(2.0 * s.a_star * 1.1**2 * 1.7**2 / 1.0, rel=1e-15)
    assert s.persistent == (s.gamma < 2)
    # the scaled closed form (2) is the dimensional motion: one excursion from rest at q,
    # written here with the dimensional ellipses (frequency w0 = sqrt(k/m), centres -+Fd/k)
    q = 0.13
    th = math.asin((q + 0.4) / 0.6)
    vp = 1.7 * 0.6 * 1.1 * math.cos(th)
    w0 = math.sqrt(3.0 / 2.0)
    qmax = -0.5 / 3 + math.hypot(q + 0.5 / 3, vp / w0)
    assert qmax > 0.7 / 3   # it reverses
    q_next = 2 * 0.5 / 3 - qmax
    ex = s.excursion(s.scaled(q))
    assert ex["reversed"] and ex["x_next"] * s.scale == pytest.approx(q_next, rel=1e-13)


def test_bad_input_is_refused():
    with pytest.raises(ArgumentError, match="unknown parameter"):
        FrictionImpact.from_params({"mu": 1.0})
    with pytest.raises(ArgumentError, match="static friction"):
        FrictionImpact.from_params({"Fs": 0.5, "Fd": 1.0})
    with pytest.raises(ArgumentError, match="stick set"):
        _fio(1.5, 2.001).excursion(1.5)
    with pytest.raises(ArgumentError, match="c_x = 1/2"):
        _fio(1.5, 2.001).residual_error(ControlGains(0.3, 1.0))
    with pytest.raises(ArgumentError, match="not an impacting stick position"):
        _fio(2.5, 2.001).fixed_point()   # loss side: no small impacting orbit beyond a*


def test_the_closed_form_refuses_where_the_mass_is_hit_again():
    """For gamma < 1 the mass does not clear the top of the constraint (module docstring):
    the excursion is not the closed form's. Checked against the model: the simulated run
    from the same rest has a second impact before the mass comes to rest."""
    s = _fio(0.8, 2.001)
    with pytest.raises(ArgumentError, match="touches the mass again"):
        s.excursion(0.9995)
    T = 2 * math.pi / s.omega
    tr = pwsdyn.simulate(MODEL, {"q": 0.9995, "v": 0.0}, (0.0, T), params=s.params(),
                         mode="stick")
    names = [e.name for e in tr.events]
    first_stop = next(i for i, n in enumerate(names) if n.startswith("stop"))
    assert sum(n.startswith("impact") for n in names[:first_stop]) >= 2


# -------------------------------------------------------------------------------------------
# condition 5.1: persistence (gamma < 2) and loss (gamma > 2), brute force
# -------------------------------------------------------------------------------------------
DELTAS = np.array([-4e-3, -2e-3, -1e-3, 1e-3, 2e-3, 4e-3])


def test_persistence_when_gamma_below_two():
    """gamma = 1.5: up and down sweeps through a* from the edge of the stick set agree (no
    hysteresis); below a* the mass sticks, above it the impact velocity of the attractor is
    that of the closed-form map's fixed point, and falls to 0 with a - a* (like sqrt(a - a*):
    the small attractor persists)."""
    g = 1.5
    s = _fio(g, A_STAR)
    p = s.params()
    p.pop("a")
    ds = pwsdyn.sweep(MODEL, "a", A_STAR + DELTAS, {"q": 1.0, "v": 0.0}, params=p,
                      transient=60, samples=10, section="impact_up", workers=1,
                      progress=False, chunk_size=len(DELTAS))
    w = _sweep_impact_velocity(ds, s.omega)
    assert np.all(ds["status"].values == 0)
    np.testing.assert_allclose(w["up"], w["down"], rtol=0, atol=1e-9)
    assert np.all(w["up"][DELTAS < 0] == 0.0)
    pred = [_impact_velocity(s.omega, A_STAR + d, _quadratic_fixed_point(g, A_STAR + d))
            for d in DELTAS[DELTAS > 0]]
    # the transient (60 periods at the multiplier 0.5) leaves ~1e-18; the event location
    # and the section's phase ~1e-10
    np.testing.assert_allclose(w["up"][DELTAS > 0], pred, rtol=1e-8)
    # the velocity is O(sqrt(a - a*)): doubling a - a* multiplies it by sqrt(2) to O(a - a*)
    r = w["up"][DELTAS > 0]
    assert r[1] / r[0] == pytest.approx(math.sqrt(2), rel=1e-2)


def test_loss_and_hysteresis_when_gamma_above_two():
    """gamma = 2.5: the up sweep from the edge of the stick set sticks up to a* and jumps
    beyond it to a large impacting attractor, which the down sweep keeps below a*
    (hysteresis) down to the saddle-node of the closed-form map, where the quadratic's
    discriminant vanishes: a_SN^2 = (8 K (b + 1) - 16) / K^2 (K = gamma here)."""
    g = 2.5
    s = _fio(g, A_STAR)
    a_sn = math.sqrt(8 * g * 2 - 16) / g
    assert a_sn < A_STAR
    # (a_sn + 1e-2: nearer the fold the multiplier, near 1, makes the transient slow)
    vals = np.concatenate([[a_sn - 2e-3, a_sn + 1e-2], A_STAR + DELTAS])
    p = s.params()
    p.pop("a")
    # one chunk: each value starts from the last state of the one before (no restart from x0
    # at chunk borders), as hysteresis needs
    ds = pwsdyn.sweep(MODEL, "a", vals, {"q": 1.0, "v": 0.0}, params=p, transient=60,
                      samples=10, section="impact_up", workers=1, progress=False,
                      chunk_size=len(vals))
    w = _sweep_impact_velocity(ds, s.omega)
    a = ds["a"].values
    below, above = a < A_STAR, a > A_STAR
    assert np.all(w["up"][below] == 0.0)           # stick solutions up to a*
    # beyond a*: the upper branch of the closed-form map (its other fixed point), not a small
    # attractor of size sqrt(a - a*)
    big = [_impact_velocity(s.omega, v, _quadratic_fixed_point(g, v, upper=True))
           for v in a[above]]
    assert min(big) > 1.0
    np.testing.assert_allclose(w["up"][above], big, rtol=1e-8)
    np.testing.assert_allclose(w["down"][above], big, rtol=1e-8)
    # hysteresis: the down sweep stays on it below a*, and falls off below the saddle-node
    keep = (a > a_sn) & below
    big_below = [_impact_velocity(s.omega, v, _quadratic_fixed_point(g, v, upper=True))
                 for v in a[keep]]
    np.testing.assert_allclose(w["down"][keep], big_below, rtol=1e-6)
    assert w["down"][a < a_sn][0] == 0.0


def test_no_small_attractor_beyond_the_graze_when_gamma_above_two():
    """gamma = 2.5, a = a* + 1e-3: every rest in [1 - 20 (a - a*), 1] leaves the
    neighbourhood of the graze (the lowest-order map has no fixed point below x = 1 there;
    its multiplier 1.5 pushes away from x = 1 + 5 (a - a*))."""
    g, d = 2.5, 1e-3
    s = _fio(g, A_STAR + d)
    T = 2 * math.pi / s.omega
    for x0 in np.linspace(1 - 20 * d, 1.0, 5):
        tr = pwsdyn.simulate(MODEL, {"q": x0, "v": 0.0}, (0.0, 40 * T), params=s.params(),
                             mode="stick")
        stops = [e.x_before[0] for e in tr.events if e.name.startswith("stop")]
        assert stops and min(stops[-5:]) < 1 - 0.5   # far from the graze, x ~ 0.2


# -------------------------------------------------------------------------------------------
# the stick-position map against the period-one orbit
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [1.5, 1.2])
def test_stick_position_of_the_period_one_orbit_against_the_map(gamma):
    """On the persistent side the orbit's stick position is the closed-form map's fixed point
    (to the Newton tolerance) and the lowest-order map's x* = 1 - gamma (a - a*)/(2 - gamma)
    to second order: the error divides by ~4 each time a - a* is halved. The multiplier is
    gamma - 1 to first order (the error halves with a - a*)."""
    errs, merrs = [], []
    for d in (1e-3, 5e-4, 2.5e-4):
        s = _fio(gamma, A_STAR + d)
        x_lin, mu_lin = s.fixed_point()
        assert x_lin == pytest.approx(1 - gamma * d / (2 - gamma), abs=1e-15)
        assert mu_lin == pytest.approx(gamma - 1, abs=1e-15)
        orb = pwsdyn.find_periodic_orbit(MODEL, [x_lin, 0.0], t0=0.0, params=s.params(),
                                         mode="stick")
        assert [e.name for e in orb.events] == ["impact_up", "reverse_pos", "stop_neg"]
        x, mu = orb.x0[0], orb.multipliers[0].real
        assert x == pytest.approx(_quadratic_fixed_point(gamma, A_STAR + d), abs=1e-12)
        # the multiplier against the closed form's derivative (module, fixed_point)
        assert mu == pytest.approx(s.fixed_point(exact=True)[1], abs=1e-9)
        assert abs(orb.multipliers[1]) < 1e-9   # v is reset to 0 at the stop
        errs.append(abs(x - x_lin))
        merrs.append(abs(mu - (gamma - 1)))
    for r in np.array(errs[:-1]) / errs[1:]:
        assert 3.6 < r < 4.4
    for r in np.array(merrs[:-1]) / merrs[1:]:
        assert 1.8 < r < 2.2


def test_the_exact_map_against_simulated_excursions():
    """One excursion from rest, closed form against the simulator, for several rests (the
    control law on, so that b changes too)."""
    s = _fio(1.5, A_STAR + 1e-3)
    G = ControlGains(0.3, 0.7)
    cm = controlled_model()
    p = s.params()
    p.pop("b")
    p.update(s.law_params(G))
    T = 2 * math.pi / s.omega
    for x0 in (0.99, 0.995, 0.999):
        tr = pwsdyn.simulate(cm, {"q": x0, "v": 0.0, "b": s.law_b(x0, G)}, (0.0, T),
                             params=p, mode="stick", rtol=1e-12, atol=1e-12)
        stop = next(e for e in tr.events if e.name.startswith("stop"))
        assert stop.x_before[0] == pytest.approx(s.stick_map(x0, exact=True, gains=G),
                                                 abs=1e-11)
        # the law acted at the stop: b is the law at the new stick position
        assert stop.x_after[2] == pytest.approx(s.law_b(stop.x_before[0], G), abs=1e-14)


# -------------------------------------------------------------------------------------------
# law 5.3
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [2.5, 1.5])
def test_law_5_3_fixed_point_and_multiplier(gamma):
    """The controlled orbit's stick position and multiplier are the x* = 1 - gamma c_a (a -
    a*)/(2 - 2 c_x) and 2 c_x - 1 of the lowest-order map, to 1e-4 at a - a* = 1e-5, also on
    the loss side (gamma = 2.5); the errors are of second and first order in a - a*."""
    G = ControlGains(0.3, 0.7)
    cm = controlled_model()
    xerr, merr = [], []
    for d in (1e-3, 1e-4, 1e-5):
        s = _fio(gamma, A_STAR + d)
        x_pred = 1 - gamma * G.c_a * d / (2 - 2 * G.c_x)
        assert s.fixed_point(gains=G) == pytest.approx((x_pred, 2 * G.c_x - 1), abs=1e-15)
        p = s.params()
        p.pop("b")
        p.update(s.law_params(G))
        orb = pwsdyn.find_periodic_orbit(cm, [x_pred, 0.0, s.law_b(x_pred, G)], t0=0.0,
                                         params=p, mode="stick")
        assert [e.name for e in orb.events] == ["impact_up", "reverse_pos", "stop_neg"]
        x, mu = orb.x0[0], orb.multipliers[0].real
        # the closed form with the law (a quadratic as well)
        xe, mue = s.fixed_point(exact=True, gains=G)
        assert (x, mu) == pytest.approx((xe, mue), abs=1e-9)
        xerr.append(abs(x - x_pred))
        merr.append(abs(mu - (2 * G.c_x - 1)))
    assert xerr[-1] < 1e-8 and merr[-1] < 1e-4
    # O(d^2): 100 per decade, until the Newton tolerance (1e-10 relative) takes over
    assert xerr[0] / max(xerr[1], 1e-12) > 50
    assert 8 < merr[0] / merr[1] < 12 and 8 < merr[1] / merr[2] < 12   # O(d)


def test_law_5_3_acts_at_the_stops_only():
    m = controlled_model()
    assert m.states == ("q", "v", "b") and "b" not in m.parameters
    resets = {e["name"]: e for e in m.spec["events"]}
    assert set(resets["stop_neg"]["reset"]) == {"v", "b"}
    assert set(resets["stop_pos"]["reset"]) == {"v", "b"}
    assert "b" not in resets["reverse_pos"]["reset"] and "b" not in resets["impact_up"]["reset"]
    assert [e.name for e in m.events] == [e.name for e in pwsdyn.load_model(MODEL).events]


# -------------------------------------------------------------------------------------------
# robustness, thesis 5.5-5.13
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [2.5, 1.5])
def test_bound_5_8_on_eps2(gamma):
    """c_x = 1/2: the multiplier is (1 - gamma) eps_2 (5.7), so the fixed point is stable for
    |eps_2| < 1/|1 - gamma| (5.8) and not beyond. 5% inside the bound the orbit is stable
    and a perturbed rest converges to it; 5% outside the rest leaves it, on both signs of
    eps_2. (With gamma > 1, eps_2 < 0 gives mu > 0: beyond the bound the lowest-order map's
    fixed point 1 + c/(1 - mu) lies above the edge x = 1 -- no impacting orbit -- and the rest
    drifts away from the edge.) The orbit's multiplier is 5.7's to O((a - a*)/(1 - mu)) (the
    fixed point's distance to the edge): a - a* = 1e-6 makes that below 1e-4."""
    d = 1e-6
    s = _fio(gamma, A_STAR + d)
    bound = s.eps2_bound()
    assert bound == pytest.approx(1 / abs(1 - gamma), rel=1e-15)
    cm = controlled_model()
    T = 2 * math.pi / s.omega
    for sign in (1.0, -1.0):
        for f, stable in ((0.95, True), (1.05, False)):
            G = ControlGains(0.5, 1.0, eps_2=sign * f * bound)
            mu_pred, c = s.linear_map(G)
            assert mu_pred == pytest.approx((1 - gamma) * G.eps_2, abs=1e-15)
            x_lin = 1 + c / (1 - mu_pred)
            p = s.params()
            p.pop("b")
            p.update(s.law_params(G))
            if x_lin < 1:
                orb = pwsdyn.find_periodic_orbit(cm, [x_lin, 0.0, s.law_b(x_lin, G)], t0=0.0,
                                                 params=p, mode="stick", rtol=1e-13,
                                                 atol=1e-14)
                assert orb.multipliers[0].real == pytest.approx(mu_pred, abs=1e-4)
                assert orb.stable == stable
            else:
                assert not stable and mu_pred > 1
                with pytest.raises(ArgumentError, match="not an impacting stick position"):
                    s.fixed_point(gains=G)
            # simulation from a rest off x_lin by a tenth of its distance to the edge: 60
            # periods at |mu| = 0.95 shrink the offset ~20 times, at 1.05 grow it ~19 times
            x0 = min(x_lin, 1.0) - 0.1 * abs(1 - x_lin)
            tr = pwsdyn.simulate(cm, {"q": x0, "v": 0.0, "b": s.law_b(x0, G)},
                                 (0.0, 60 * T), params=p, mode="stick", rtol=1e-13,
                                 atol=1e-14)
            stops = [e.x_before[0] for e in tr.events if e.name.startswith("stop")]
            assert len(stops) >= 55
            off = abs(stops[-1] - x_lin) / abs(x0 - x_lin)
            assert (off < 0.1) if stable else (off > 2.0)


def test_residual_errors_5_10_and_5_13_against_simulation():
    """c_x = 1/2 (multiplier ~0: the rest settles in a few periods). The simulated stick
    position's offset from 1 - gamma c_a (a - a*) is eq. 5.10 (multiplicative errors; first
    order in them) and eq. 5.13 (additive errors), and the lowest-order map's fixed point
    (exact in the errors) to O(a - a*)^2.

    Note: eq. 5.10 as printed, gamma |c_a + (c_a - 1) eps_1 + c_a (1 - gamma) eps_2| |a - a*|,
    is not 0 without errors; from 5.9 the residual is gamma |(c_a - 1) eps_1 + c_a (1 - gamma)
    eps_2| |a - a*|, which is what is checked (the extra c_a is a misprint)."""
    g, d = 2.5, 1e-4
    s = _fio(g, A_STAR + d)
    cm = controlled_model()
    T = 2 * math.pi / s.omega
    cases = [(ControlGains(0.5, 0.5, eps_1=0.01, eps_2=0.01), "5.10"),
             (ControlGains(0.5, 0.5, eps_1=-0.02, eps_2=0.03), "5.10"),
             (ControlGains(0.5, 0.5, delta_1=2e-5, delta_2=1e-5), "5.13"),
             (ControlGains(0.5, 1.5, delta_1=-3e-5, delta_2=2e-5), "5.13")]
    for G, eq in cases:
        p = s.params()
        p.pop("b")
        p.update(s.law_params(G))
        x0 = 1 - g * G.c_a * d
        tr = pwsdyn.simulate(cm, {"q": x0, "v": 0.0, "b": s.law_b(x0, G)}, (0.0, 12 * T),
                             params=p, mode="stick", rtol=1e-12, atol=1e-12)
        x = [e.x_before[0] for e in tr.events if e.name.startswith("stop")][-1]
        res = abs(1 - g * G.c_a * d - x)
        thesis = s.residual_error(G)
        if eq == "5.10":
            written = g * abs((G.c_a - 1) * G.eps_1 + G.c_a * (1 - g) * G.eps_2) * d
        else:
            written = abs(g * (G.c_a - 1) * G.delta_1 + (1 - g) * G.delta_2)
        assert thesis == pytest.approx(written, rel=1e-12)
        # the lowest-order map's own fixed point: O(d^2) ~ 1e-8 off (4.5e-9 measured
        # without errors at this d)
        assert res == pytest.approx(s.residual_error(G, first_order=False), abs=2e-8)
        # 5.10 drops O(eps^2) terms: the multiplier (1 - gamma) eps_2 enters x* through
        # 1/(1 - mu) = 1 + mu + mu^2 ...; second order: gamma d (|eps|_max)^2 (1 + gamma)^2
        eps = max(abs(G.eps_1), abs(G.eps_2))
        assert res == pytest.approx(thesis, abs=2e-8 + g * d * eps**2 * (1 + g)**2)
        assert res > 1e-6   # the errors show: the check has something to see


def test_the_bound_5_8_is_a_period_doubling_of_the_controlled_branch():
    """Continued in eps_2 at c_x = 1/2 the controlled orbit's multiplier passes -1 where
    (1 - gamma) eps_2 = -1 (5.7-5.8): a PD at eps_2 = 1/(gamma - 1), to the O(a - a*) of the
    lowest-order map."""
    g, d = 2.5, 1e-5
    s = _fio(g, A_STAR + d)
    G = ControlGains(0.5, 1.0, eps_2=0.5)
    cm = controlled_model()
    p = s.params()
    p.pop("b")
    p.update(s.law_params(G))
    x_pred, _ = s.fixed_point(gains=G)
    orb = pwsdyn.find_periodic_orbit(cm, [x_pred, 0.0, s.law_b(x_pred, G)], t0=0.0, params=p,
                                     mode="stick")
    br = pwsdyn.continue_orbit(cm, orb, "eps_2", span=(0.4, 0.8), ds=0.02)
    pd = br.special("PD")
    assert len(pd) == 1
    assert pd[0].value == pytest.approx(1 / (g - 1), abs=1e-4)


# -------------------------------------------------------------------------------------------
# Fs > Fd (thesis section 5.3.1)
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [1.5, 2.5])
def test_stick_solutions_up_to_a_star_star_when_Fs_above_Fd(gamma):
    """Fs = 1.2 Fd: a* = 2, a** = 2.2 (section 5.3.1). Sweeping a up in steps of 0.01 from
    the edge q = Fd/k of the dynamic stick set, the mass ends every value at rest (no impact
    in the window) for a* < a < a**, between the top of the constraint a - b and Fs/k; beyond
    a** it impacts every period, on both sides of condition 5.1. (Each step's impact lifts
    the rest to just above the new top, by (gamma - 1) times the step to lowest order, so the
    last values below a** stick only for steps small against (a** - a)/(gamma - 1).)"""
    s = _fio(gamma, A_STAR, Fs=1.2)
    assert (s.a_star, s.a_star_star) == pytest.approx((2.0, 2.2), abs=1e-15)
    p = s.params()
    p.pop("a")
    vals = np.concatenate([np.arange(2.01, 2.175, 0.01), [2.21, 2.25]])
    ds = pwsdyn.sweep(MODEL, "a", vals, {"q": 1.0, "v": 0.0}, params=p, transient=30,
                      samples=10, section="impact_up", direction="up", workers=1,
                      progress=False, chunk_size=len(vals))
    n = ds["n_points"].values[0]
    inside = vals < s.a_star_star
    assert np.all(n[inside] == 0) and np.all(n[~inside] >= 10)
    q = ds["x_final"].values[0, :, 0]
    assert np.all((q[inside] >= vals[inside] - 1.0) & (q[inside] <= 1.2))


def test_hysteresis_with_Fs_above_Fd_even_when_5_1_holds():
    """gamma = 1.5 (5.1 holds), Fs = 1.2: sweeping down from beyond a**, the impacting orbit
    (it reverses above Fs/k and rests below Fd/k) persists below a** down to where its
    reversal point x_max = 2 - x* reaches Fs/Fd; then the mass rests at x_max instead and
    sticks -- a jump, and with the up sweep's stick solutions up to a**, hysteresis (thesis
    section 5.3.1, Fig. 5.4 (b)). The end of the impacting orbits from the closed-form fixed
    point with x* = 2 - Fs/Fd: a^2 = (x* + b)^2 + 8 (1 - x*)/K, K = gamma."""
    g = 1.5
    s = _fio(g, A_STAR, Fs=1.2)
    xs = 2 - 1.2
    a_end = math.sqrt((xs + 1) ** 2 + 8 * (1 - xs) / g)
    assert s.a_star < a_end < s.a_star_star
    p = s.params()
    p.pop("a")
    vals = np.array([a_end - 0.01, a_end + 0.01, 2.15, 2.25])
    ds = pwsdyn.sweep(MODEL, "a", vals, {"q": 1.0, "v": 0.0}, params=p, transient=60,
                      samples=10, section="impact_up", workers=1, progress=False,
                      chunk_size=len(vals))
    w = _sweep_impact_velocity(ds, s.omega)
    assert w["up"][0] == w["up"][1] == w["up"][2] == 0.0 and w["up"][3] > 0
    assert w["down"][0] == 0.0 and np.all(w["down"][1:] > 0)
    pred = [_impact_velocity(s.omega, v, _quadratic_fixed_point(g, v)) for v in vals[1:]]
    np.testing.assert_allclose(w["down"][1:], pred, rtol=1e-7)


def test_section_on_events_of_with_discrete_control():
    """The update joins the named events' resets, evaluated at the state before the event;
    bad names are refused; the other sections are as before."""
    m = with_discrete_control(MODEL, "b", section="event:stop_neg", law="2*q + c",
                              law_params={"c": 0.25})
    assert m.parameters["c"] == 0.25 and "b" in m.states
    tr = pwsdyn.simulate(m, {"q": 0.5, "v": 0.0, "b": 1.0}, (0.0, 30.0),
                         params={"a": 2.3, "omega": 0.8})
    stops = [e for e in tr.events if e.name == "stop_neg"]
    assert stops
    for e in stops:
        assert e.x_after[2] == pytest.approx(2 * e.x_before[0] + 0.25, abs=1e-14)
    others = [e for e in tr.events if e.name != "stop_neg"]
    assert all(e.x_after[2] == e.x_before[2] for e in others)
    with pytest.raises(ArgumentError, match="must name distinct events"):
        with_discrete_control(MODEL, "b", section="event:stop", law="q")
    with pytest.raises(ArgumentError, match="must name distinct events"):
        with_discrete_control(MODEL, "b", section="event:stop_neg,stop_neg", law="q")
    with pytest.raises(ArgumentError, match="taken"):
        with_discrete_control(MODEL, "b", section="event:stop_neg", law="q",
                              law_params={"a": 1.0})
    with pytest.raises(ArgumentError, match="law_params"):
        with_discrete_control(MODEL, "b", section="event:stop_neg", law="q",
                              law_params={"c": "x"})
    with pytest.raises(ArgumentError, match="expression law"):
        with_discrete_control(MODEL, "b", law="linear", law_params={"c": 1.0})


# -------------------------------------------------------------------------------------------
# continuation through the saddle-node to the non-smooth fold, and the gallery
# -------------------------------------------------------------------------------------------
def test_continued_branch_folds_at_the_closed_form_saddle_node_and_ends_at_the_graze():
    """gamma = 2.5 (Fig. 2.3 (a)): continued down from the upper stable orbit, the branch
    passes the saddle-node where the closed-form map's quadratic has a double root, a_SN =
    sqrt(8 K (b + 1) - 16)/K (K = gamma), and ends at its graze at a* (the non-smooth fold:
    the impact velocity falls to zero; there the saltation matrix is infinite and the point
    has no multipliers, which must not stop the branch)."""
    g = 2.5
    s = _fio(g, 2.03)
    x_up = _quadratic_fixed_point(g, 2.03, upper=True)
    orb = pwsdyn.find_periodic_orbit(MODEL, [x_up, 0.0], t0=0.0, params=s.params(),
                                     mode="stick")
    assert orb.stable
    br = pwsdyn.continue_orbit(MODEL, orb, "a", span=(1.9, 2.05), ds=-0.005)
    lp = [sp for sp in br.special("LP") if sp.value < 1.99]
    assert len(lp) == 1
    assert lp[0].value == pytest.approx(math.sqrt(8 * g * 2 - 16) / g, abs=1e-8)
    gr = br.special("GR")
    assert len(gr) == 1 and gr[0].value == pytest.approx(A_STAR, abs=1e-8)
    # the unstable part between: multiplier > 1 (gamma - 1 near the graze)
    k = lp[0].index
    assert np.all(~br.stable[k + 1:gr[0].index])
    end = br.problem_of(br.points[-1]).orbit(br.points[-1].u, br.points[-1].lam)
    assert end.events[0].kind == "impact"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["plot_friction_impact_fig_2_3.py",
                                  "plot_friction_impact_fig_5_4.py"])
def test_gallery_scripts_run(name, tmp_path, monkeypatch):
    import runpy
    from pathlib import Path

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    path = Path(__file__).resolve().parents[1] / "examples" / name
    runpy.run_path(str(path), run_name="__main__")
    fig = plt.gcf()
    assert len(fig.axes) == 2 and all(len(ax.get_lines()) > 5 for ax in fig.axes)
    plt.close("all")
