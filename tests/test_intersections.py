"""Sliding on the intersection of switching surfaces (issue 27): the multilinear extension of
L. Dieci and L. Lopez, Numer. Math. 117 (2011) 779-811, in the kernel's ``slide_multi`` state.

Every number is checked against something independent of the kernel's intersection code: a
closed form derived here, each contact simulated alone (the kernel's one-surface sliding,
thesis eq. 2.7-2.8), scipy's ``solve_ivp`` with the sticking phases in closed form, or central
differences of the flow map.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import pwsdyn
from pwsdyn import _codes
from pwsdyn.errors import SolveError, Status
from pwsdyn.integrate.trajectory import DiscreteState
from pwsdyn.io import load_trajectory
from pwsdyn.stability import event_saltations

#: The integrator's tolerances for comparisons at 1e-8 (local errors ~1e-12 accumulate over
#: a few dozen events to ~1e-10).
TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-12)

# ======================================================================================
# models
# ======================================================================================

#: Two blocks on two belts (the zoo's stick-slip oscillator, m = 1, twice, with different
#: parameters): independent contacts, one model, four product variants of the field.
P1 = dict(k1=1.0, Fs1=1.0, V1=0.2, d1=3.0)
P2 = dict(k2=1.5, Fs2=0.8, V2=0.3, d2=2.0)


def two_blocks(p1=P1, p2=P2):
    return {"name": "two-stick-slip", "states": ["x1", "v1", "x2", "v2"],
            "parameters": {**p1, **p2},
            "definitions": {"vrel1": "v1 - V1", "vrel2": "v2 - V2"},
            "modes": {"block": {
                "x1": "v1", "v1": "-k1*x1 - Fs1*sign(vrel1)/(1 + d1*abs(vrel1))",
                "x2": "v2", "v2": "-k2*x2 - Fs2*sign(vrel2)/(1 + d2*abs(vrel2))"}}}


def one_block(k, Fs, V, d):
    """The zoo's 1-DOF oscillator with these parameters (m = 1)."""
    return "stick-slip-oscillator", dict(m=1.0, k=k, Fs=Fs, V=V, delta=d)


#: Two relays driving a third state through the product of their outputs (bilinear in the
#: signs): x' = 1/2 - sign(x), y' = sign(x) - 2 sign(y), z' = 1 + sign(x) sign(y).
RELAYS = {"name": "two-relays", "states": ["x", "y", "z"],
          "modes": {"m": {"x": "0.5 - sign(x)", "y": "sign(x) - 2*sign(y)",
                          "z": "1 + sign(x)*sign(y)"}}}


# ======================================================================================
# an independent reference: scipy for slipping, closed form for sticking
# ======================================================================================

def stick_slip_reference(k, Fs, V, d, x0, v0, t_end, ts):
    """x'' = -k x - Fs sign(v - V)/(1 + d |v - V|) at the times ``ts``: slip phases by
    ``solve_ivp`` (DOP853, rtol 1e-12) up to the arrival at v = V; there the block sticks if
    |k x| < Fs (x' = V, v = V, in closed form, until k x = Fs: V > 0 carries x up to the
    static bound) and crosses otherwise."""
    ts = np.asarray(ts, dtype=float)
    out = np.full((len(ts), 2), np.nan)
    t, x, v = 0.0, float(x0), float(v0)
    stick = v == V and abs(k * x) <= Fs
    while t < t_end:
        if stick:
            t_r = min(t + (Fs / k - x) / V, t_end)
            sel = (ts >= t) & (ts <= t_r)
            out[sel, 0] = x + V * (ts[sel] - t)
            out[sel, 1] = V
            x, v, t = Fs / k, V, t_r
            stick = False
            side = -1.0   # released: the spring pulls the block back, v falls below V
            continue
        if v != V:
            side = np.sign(v - V)

        def rhs(_, y, side=side):
            return [y[1], -k * y[0] - Fs * side / (1.0 + d * abs(y[1] - V))]

        def arrive(_, y):
            return y[1] - V
        arrive.terminal = True
        arrive.direction = -side
        sol = solve_ivp(rhs, (t, t_end), [x, v], method="DOP853", rtol=1e-12, atol=1e-14,
                        events=arrive, dense_output=True)
        t1 = sol.t[-1]
        sel = (ts >= t) & (ts <= t1)
        out[sel] = sol.sol(ts[sel]).T
        t, x, v = t1, sol.y[0, -1], V
        if sol.status == 1:
            stick = abs(k * x) < Fs
            side = -side
    return out


# ======================================================================================
# uncoupled contacts
# ======================================================================================

def test_uncoupled_blocks_reproduce_each_block_alone_and_scipy():
    """Each block of the two-block model moves as it does alone -- through the intervals
    where both stick (slide_multi), entered and left one contact at a time -- to 1e-8, against
    the 1-DOF pwsdyn runs and scipy with closed-form sticking."""
    T = 40.0
    tr = pwsdyn.simulate(two_blocks(), [0.0, 0.0, 0.0, 0.0], (0.0, T), **TIGHT)
    kinds = [(e.kind, e.mode_after) for e in tr.events]
    assert ("slide_start", "slide_multi:vrel1&vrel2") in kinds
    assert any(e.kind == "slide_end" and e.mode_before.startswith("slide_multi:")
               for e in tr.events)
    both = [iv for iv in tr.sliding_intervals() if iv[2] == "vrel1&vrel2"]
    assert len(both) >= 3 and sum(b - a for a, b, _ in both) > 5.0
    ts = np.linspace(0.0, T, 801)
    X = tr(ts)
    for i, (k, Fs, V, d) in enumerate([P1.values(), P2.values()]):
        name, params = one_block(k, Fs, V, d)
        alone = pwsdyn.simulate(name, [0.0, 0.0], (0.0, T), params=params, **TIGHT)
        np.testing.assert_allclose(X[:, 2 * i:2 * i + 2], alone(ts), rtol=0, atol=1e-8)
        ref = stick_slip_reference(k, Fs, V, d, 0.0, 0.0, T, ts)
        np.testing.assert_allclose(X[:, 2 * i:2 * i + 2], ref, rtol=0, atol=1e-8)
    # while both stick, both velocities are the belts' to round-off (the projection)
    for a, b, _ in both:
        mid = tr(np.linspace(a, b, 7)[1:-1])
        np.testing.assert_allclose(mid[:, 1], P1["V1"], rtol=0, atol=1e-13)
        np.testing.assert_allclose(mid[:, 3], P2["V2"], rtol=0, atol=1e-13)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(k2=st.floats(0.5, 2.0), Fs2=st.floats(0.5, 1.5), V2=st.floats(0.1, 0.5),
       d2=st.floats(1.0, 4.0), x1=st.floats(-0.9, 0.9), x2=st.floats(-0.4, 0.4),
       start=st.sampled_from(["both", "one"]))
def test_uncoupled_blocks_random_parameters_and_starts(k2, Fs2, V2, d2, x1, x2, start):
    """Random parameters of the second block, starts stuck on both belts (a start on the
    intersection: the state resolved at t0) or on the first only: each block as alone, to
    1e-8. (Velocity-weakening friction, d > 0: with pure Coulomb friction on a belt the slip
    orbit returns to v = V exactly at the static bound, a tangency, non-generic.)"""
    p2 = dict(k2=k2, Fs2=Fs2, V2=V2, d2=d2)
    x2 = x2 * Fs2 / k2
    v2 = V2 if start == "both" else 0.0
    T = 12.0
    tr = pwsdyn.simulate(two_blocks(P1, p2), [x1, P1["V1"], x2, v2], (0.0, T), **TIGHT)
    assert tr.status == Status.SUCCESS
    if start == "both":
        assert tr.state[0] == "slide_multi:vrel1&vrel2"
    ts = np.linspace(0.0, T, 121)
    X = tr(ts)
    for i, (k, Fs, V, d, x0, v0) in enumerate([(*P1.values(), x1, P1["V1"]),
                                               (k2, Fs2, V2, d2, x2, v2)]):
        name, params = one_block(k, Fs, V, d)
        alone = pwsdyn.simulate(name, [x0, v0], (0.0, T), params=params, **TIGHT)
        np.testing.assert_allclose(X[:, 2 * i:2 * i + 2], alone(ts), rtol=0, atol=1e-8)


# ======================================================================================
# two relays: a closed form on the intersection
# ======================================================================================

def relays_closed_form(t):
    """RELAYS from (1, 1/2, 0). Until t = 1/2: x' = -1/2, y' = -1, z' = 2, so y = 0 at
    t = 1/2, x = 3/4, z = 1. Sliding on y = 0 (x > 0): y' = 1 - 2 u_y = 0, u_y = 1/2,
    x' = -1/2, z' = 1 + u_y = 3/2, so x = 0 at t = 2, z = 13/4; beyond x = 0 sliding on y = 0
    has u_y = -1/2 and x' = 3/2: both sliding fields press into x = 0. On the intersection the
    bilinear weights solve 1/2 - u_x = 0 and u_x - 2 u_y = 0: u_x = 1/2, u_y = 1/4 (lambda =
    (1 - u)/2 = (1/4, 3/8), inside the square), and z' = 1 + u_x u_y = 9/8 -- the bilinear
    term, which no single convex combination along one surface gives."""
    t = np.asarray(t, dtype=float)
    x = np.where(t < 2.0, np.where(t < 0.5, 1.0 - 0.5 * t, 0.75 - 0.5 * (t - 0.5)), 0.0)
    y = np.where(t < 0.5, 0.5 - t, 0.0)
    z = np.where(t < 0.5, 2.0 * t, np.where(t < 2.0, 1.0 + 1.5 * (t - 0.5),
                                             3.25 + 1.125 * (t - 2.0)))
    return np.stack([x, y, z], axis=-1)


@pytest.mark.parametrize("exact", [False, True])
def test_two_relays_slide_on_the_intersection_as_the_closed_form(exact):
    """The events at t = 1/2 and 2 and the motion on the intersection against the closed
    form, to 1e-12 (constant fields: only rounding), on the Runge-Kutta path and with
    ``exact=True`` (sliding stays on the Runge-Kutta pair there)."""
    tr = pwsdyn.simulate(RELAYS, [1.0, 0.5, 0.0], (0.0, 5.0), exact=exact, **TIGHT)
    assert tr.status == Status.SUCCESS
    assert [(e.kind, e.name, e.mode_after) for e in tr.events] == [
        ("slide_start", "y", "slide:y"), ("slide_start", "x", "slide_multi:x&y")]
    assert [e.t for e in tr.events] == [pytest.approx(0.5, abs=1e-12),
                                        pytest.approx(2.0, abs=1e-12)]
    st_ = DiscreteState.parse(str(tr.state[-1]))
    assert st_.kind == "slide_multi" and st_.surfaces == ("x", "y")
    ts = np.linspace(0.0, 5.0, 51)
    np.testing.assert_allclose(tr(ts), relays_closed_form(ts), rtol=0, atol=1e-12)


def test_a_start_on_the_intersection_slides_on_it():
    """x0 on both surfaces: the state at t0 is slide_multi (no event), z' = 9/8."""
    tr = pwsdyn.simulate(RELAYS, [0.0, 0.0, 1.0], (0.0, 2.0), **TIGHT)
    assert tr.events == [] or all(e.kind != "slide_end" for e in tr.events)
    assert tr.state[0] == "slide_multi:x&y"
    np.testing.assert_allclose(tr.x_final, [0.0, 0.0, 1.0 + 2.0 * 1.125], rtol=0, atol=1e-12)


def test_non_attracting_intersection_ends_the_run():
    """Beyond x = 0 the surface y = 0 repels (tests/test_filippov.py derives lambda_y = 5/4):
    ST_INTERSECTION at t = 1 with the message saying why."""
    m = {"name": "corner", "states": ["x", "y"],
         "modes": {"m": {"x": "-sign(x)", "y": "sign(y)*(0.5 - 1.5*sign(x)) + 0.75"}}}
    tr = pwsdyn.simulate(m, [1.0, 0.125], (0.0, 3.0), throw=False)
    assert tr.status == Status.SURFACE_INTERSECTION
    assert tr.t_final == pytest.approx(1.0, abs=1e-12)
    assert "not attracting" in tr.message and "[0, 1]^k" in tr.message


# ======================================================================================
# where and why a run ends at an intersection: the message
# ======================================================================================

def _intersection_message(model, x0, t_end):
    """The run's message (``throw=False``) and the :class:`SolveError` text (``throw=True``),
    which are the same; the run must end with ``SURFACE_INTERSECTION``."""
    tr = pwsdyn.simulate(model, x0, (0.0, t_end), throw=False)
    assert tr.status == Status.SURFACE_INTERSECTION, tr.message
    with pytest.raises(SolveError) as info:
        pwsdyn.simulate(model, x0, (0.0, t_end))
    assert str(info.value) == tr.message
    return tr, tr.message


def _says_where(msg, t, state, values):
    """The message names the time (to 1e-12), the discrete state and the state."""
    found = re.search(r"Stopped at t=([-0-9.e+]+) in mode '([^']+)' with state \(([^)]*)\)",
                      msg)
    assert found, msg
    assert float(found.group(1)) == pytest.approx(t, abs=1e-12)
    assert found.group(2) == state
    got = dict(kv.split("=") for kv in found.group(3).split(", "))
    assert {k: float(v) for k, v in got.items()} == pytest.approx(values, abs=1e-12)


def test_message_of_a_non_attracting_intersection_names_surface_and_weights():
    """The corner model above: sliding on y = 0 reaches x = 0 at t = 1, at the origin. The
    bilinear weights there (tests/test_filippov.py): u_x = 0, u_y = -3/2, i.e. lambda =
    (1 - u)/2 = (1/2, 5/4); the message names the surface reached, the intersection, the
    weights and the one outside [0, 1]."""
    m = {"name": "corner", "states": ["x", "y"],
         "modes": {"m": {"x": "-sign(x)", "y": "sign(y)*(0.5 - 1.5*sign(x)) + 0.75"}}}
    tr, msg = _intersection_message(m, [1.0, 0.125], 3.0)
    _says_where(msg, 1.0, "slide:y", {"x": 0.0, "y": 0.0})
    assert "reached surface 'x', on the intersection x&y" in msg
    assert "lambda[x] = 0.5, lambda[y] = 1.25" in msg
    assert "the weight of y lies outside [0, 1]" in msg and "not attracting" in msg


def test_message_when_the_rule_has_no_weights():
    """x' = -sign(x) - sign(y), y' = 1 - 2 sign(x) sign(y) from (2, 1/2): y = 0 at t = 1/2
    (y' = -1, x' = -2: x = 1), then sliding on y = 0 (y' = -1 above, 3 below) with
    u_y = 1/2 and x' = -1 - u_y = -3/2, so x = 0 at t = 1/2 + 2/3 = 7/6. Beyond x = 0
    (u_x = -1) sliding on y has u_y = -1/2 and x' = 3/2: both sides press into x = 0. On
    the intersection the tangency conditions -u_x - u_y = 0 and 1 - 2 u_x u_y = 0 give
    1 + 2 u_x^2 = 0: no real weights."""
    m = {"name": "no-weights", "states": ["x", "y"],
         "modes": {"m": {"x": "-sign(x) - sign(y)", "y": "1 - 2*sign(x)*sign(y)"}}}
    tr, msg = _intersection_message(m, [2.0, 0.5], 3.0)
    _says_where(msg, 7.0 / 6.0, "slide:y", {"x": 0.0, "y": 0.0})
    assert "reached surface 'x', on the intersection x&y" in msg
    assert "has no weights" in msg and "no solution" in msg


def test_message_when_a_corner_mode_is_missing():
    """Four modes written out with their switches, one missing (C | D on y would close the
    square; x: A | B and C | D, y: A | C only): sliding on y = 0 from t = 1/2 (A: y' = -1,
    C: y' = 1) reaches x = 0 at t = 2 (x' = -1 in A and C), where the corner below both
    surfaces cannot be reached from B across y."""
    m = {"name": "no-corner", "states": ["x", "y"],
         "modes": {"A": {"x": "-1", "y": "-1"}, "B": {"x": "1", "y": "-1"},
                   "C": {"x": "-1", "y": "1"}, "D": {"x": "1", "y": "1"}},
         "switches": [{"name": "sx", "surface": "x", "above": "A", "below": "B"},
                      {"name": "sy", "surface": "y", "above": "A", "below": "C"},
                      {"name": "sx2", "surface": "x", "above": "C", "below": "D"}],
         "initial_mode": "A"}
    tr, msg = _intersection_message(m, [2.0, 0.5], 5.0)
    _says_where(msg, 2.0, "slide:sy", {"x": 0.0, "y": 0.0})
    assert "reached surface 'sx', on the intersection sx&sy" in msg
    assert "lacks a corner mode: no switch on surface 'sy' joins mode 'B'" in msg


# (2**11 variants: about a minute to load and compile, so among the long checks)
@pytest.mark.slow
def test_message_when_more_surfaces_meet_than_the_rule_takes(monkeypatch):
    """K = ``MULTI_MAX`` relays x_i' = -i sign(x_i) from 1 (x_i = 0 at t = 1/i: sliding on all
    K from t = 1) and one more, x_{K+1}' = -sign(x_{K+1}) from 2: at t = 2 K + 1 surfaces
    would meet, one more than ``MULTI_MAX`` (one sign family of 2**(K+1) variants, over the
    loader's bounds on the surfaces of a mode and the variants of a family, which are raised
    here)."""
    from pwsdyn.model import discontinuities
    K = _codes.MULTI_MAX
    monkeypatch.setattr(discontinuities, "MAX_SURFACES_PER_MODE", K + 1)
    monkeypatch.setattr(discontinuities, "MAX_FAMILY_MODES", 2 ** (K + 1))
    m = {"name": "one-too-many", "states": [f"x{i + 1}" for i in range(K + 1)],
         "modes": {"relays": {**{f"x{i + 1}": f"-{i + 1}*sign(x{i + 1})" for i in range(K)},
                              f"x{K + 1}": f"-sign(x{K + 1})"}}}
    tr, msg = _intersection_message(m, [1.0] * K + [2.0], 5.0)
    all_k = "&".join(f"x{i}" for i in range(1, K + 1))
    _says_where(msg, 2.0, f"slide_multi:{all_k}", {f"x{i}": 0.0 for i in range(1, K + 2)})
    assert (f"reached surface 'x{K + 1}', on the intersection {all_k}&x{K + 1}: {K + 1} "
            f"surfaces, more than the {K}") in msg
    assert f"or more than {K} surfaces meet" in msg


def test_weights_found_where_newton_from_the_centre_is_singular():
    """x' = -sign(x) sign(y), y' = 1/2 - sign(y), z' = sign(x) + 2 sign(y) from (2, 1/2, 0):
    y = 0 at t = 1 (x = 1, z = 3); sliding on y = 0 with u_y = 1/2: x' = -1/2, z' = 2, so
    x = 0 at t = 3 (z = 7); beyond x = 0 the sliding field is x' = +1/2: both press. On the
    intersection -u_x u_y = 0 and 1/2 - u_y = 0: u = (0, 1/2), lambda = (1/2, 1/4), inside
    the square, and z' = u_x + 2 u_y = 1, z(5) = 9. At the centre lambda = (1/2, 1/2) the
    first condition's gradient (-u_y, -u_x) vanishes: Newton starts elsewhere."""
    m = {"name": "centre-singular", "states": ["x", "y", "z"],
         "modes": {"m": {"x": "-sign(x)*sign(y)", "y": "0.5 - sign(y)",
                         "z": "sign(x) + 2*sign(y)"}}}
    tr = pwsdyn.simulate(m, [2.0, 0.5, 0.0], (0.0, 5.0), **TIGHT)
    assert tr.status == Status.SUCCESS, tr.message
    assert [str(e.mode_after) for e in tr.events] == ["slide:y", "slide_multi:x&y"]
    np.testing.assert_allclose([e.t for e in tr.events], [1.0, 3.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.x_final, [0.0, 0.0, 9.0], rtol=0, atol=1e-12)


# ======================================================================================
# the switch table's sign-family blocks
# ======================================================================================

#: models whose switch tables mix sign-family blocks with other switches: a chain of four
#: contacts (four blocks of eight), and fields with kinks (``abs``: continuous switches, no
#: block) and a product of signs next to the family's surfaces
TABLE_MODELS = [
    lambda: pwsdyn.burridge_knopoff(4),
    lambda: {"name": "kinks", "states": ["x", "y", "z"],
             "modes": {"m": {"x": "-sign(x) + abs(y)", "y": "1 - 2*sign(y - x)",
                             "z": "sign(x)*sign(y) + abs(z - 1)"}}},
    lambda: {"name": "two-kinds", "states": ["x", "y"],
             "modes": {"m": {"x": "-sign(x)", "y": "0.5 - sign(y)"},
                       "n": {"x": "1", "y": "-1"}},
             "switches": [{"name": "mn", "surface": "x + y - 3", "above": "n", "below": "m"}]},
]


def _linear_touching(stab, s, m):
    for r in range(s, len(stab)):
        if stab[r]["above"] == m or stab[r]["below"] == m:
            return r
    return len(stab)


@pytest.mark.parametrize("make", TABLE_MODELS)
def test_switch_lookups_by_block_agree_with_a_search_of_the_table(make):
    """The kernel finds the switch of a sign family's block that touches a mode by arithmetic
    (``_block_row``); every lookup of the table -- the next switch touching a mode from every
    record, the partner across every surface of every mode, every switch by its two modes --
    agrees with a plain search of the table in order, and the chain's Filippov switches are
    all in blocks (so the arithmetic is what ran)."""
    from pwsdyn.integrate.compiled import ModelContext
    from pwsdyn.integrate._kernel.fields import _find_switch, _next_touching, _partner
    model = pwsdyn.load_model(make())
    stab = ModelContext(model).stab
    nm, ns = len(model.modes), len(stab)
    if model.name.startswith("burridge"):
        assert np.all(stab["block"] >= 0) and ns == 4 * 8
    assert any(stab["block"] >= 0)
    for m in range(nm):
        for s in range(ns + 1):
            assert _next_touching(stab, s, m) == _linear_touching(stab, s, m), (m, s)
        for k in sorted(set(stab["surface"].tolist())):
            rows = [r for r in range(ns) if stab[r]["surface"] == k
                    and m in (stab[r]["above"], stab[r]["below"])]
            want = -1 if not rows else int(stab[rows[0]]["below"] if stab[rows[0]]["above"] == m
                                           else stab[rows[0]]["above"])
            assert _partner(stab, k, m) == want, (m, k)
    def linear_find(k, a, b):
        return next((r for r in range(ns) if (stab[r]["surface"], stab[r]["above"],
                                              stab[r]["below"]) == (k, a, b)), -1)

    for r in range(ns):
        k, a, b = (int(stab[r][f]) for f in ("surface", "above", "below"))
        assert _find_switch(stab, k, a, b) == r
        for args in ((k, b, a), (k + 1, a, b), (k, a, (b + 1) % nm)):
            assert _find_switch(stab, *args) == linear_find(*args), args


# ======================================================================================
# exact propagation, names, files
# ======================================================================================

def test_exact_and_runge_kutta_agree_through_double_sticking():
    """Coulomb friction with viscous damping, x'' = -k x - c x' - Fs sign(x' - V): the
    slipping modes are affine and run on the exact flow with ``exact=True``; sticking on both
    belts stays on the Runge-Kutta pair. Both paths agree to 1e-9 (each within ~1e-10 of the
    exact solution). (The damping keeps the returns to v = V off the static bound, where
    undamped Coulomb slip would touch it tangentially.)"""
    m = {"name": "two-coulomb", "states": ["x1", "v1", "x2", "v2"],
         "parameters": {"c": 0.1, **P1, **P2},
         "modes": {"block": {"x1": "v1", "v1": "-k1*x1 - c*v1 - Fs1*sign(v1 - V1)",
                             "x2": "v2", "v2": "-k2*x2 - c*v2 - Fs2*sign(v2 - V2)"}}}
    ts = np.linspace(0.0, 30.0, 301)
    a = pwsdyn.simulate(m, [0.0] * 4, (0.0, 30.0), exact=False, **TIGHT)
    b = pwsdyn.simulate(m, [0.0] * 4, (0.0, 30.0), exact=True, **TIGHT)
    assert b.stats["nfev"] < a.stats["nfev"]
    assert [e.kind for e in a.events] == [e.kind for e in b.events]
    assert any(e.mode_after.startswith("slide_multi") for e in b.events)
    np.testing.assert_allclose(a(ts), b(ts), rtol=0, atol=1e-9)


def test_state_names_and_trajectory_file_round_trip(tmp_path):
    """``slide_multi:<surface>&<surface>`` parses, names its surfaces, and survives a
    trajectory file."""
    s = DiscreteState.parse("slide_multi:x&y")
    assert (s.kind, s.surfaces, s.code) == ("slide_multi", ("x", "y"), 3)
    tr = pwsdyn.simulate(RELAYS, [1.0, 0.5, 0.0], (0.0, 3.0), **TIGHT)
    back = load_trajectory(tr.save(tmp_path / "relays.nc"))
    assert list(back.state) == list(tr.state)
    assert [(e.kind, e.mode_after) for e in back.events] == [
        (e.kind, e.mode_after) for e in tr.events]
    # a run continued from a trajectory that ends on the intersection stays on it
    more = pwsdyn.simulate(RELAYS, tr, (3.0, 4.0), **TIGHT)
    assert more.state[0] == "slide_multi:x&y"
    np.testing.assert_allclose(more.x_final, relays_closed_form(4.0), rtol=0, atol=1e-12)


# ======================================================================================
# saltation matrices: the variational Jacobian against central differences of the flow map
# ======================================================================================

def _fd_jacobian(model, x0, span, step):
    x0 = np.asarray(x0, dtype=float)
    J = np.zeros((len(x0), len(x0)))
    for c in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[c] = step
        up = pwsdyn.simulate(model, x0 + dx, span, **TIGHT).x_final
        dn = pwsdyn.simulate(model, x0 - dx, span, **TIGHT).x_final
        J[:, c] = (up - dn) / (2 * step)
    return J


def test_jacobian_through_codim2_entry_matches_finite_differences():
    """Relays from (1, 1/2, 0) to t = 3 through sliding entry on y = 0 and on the
    intersection: the flow map is piecewise affine (constant fields), so central differences
    are exact up to rounding (1e-9 with step 1e-4). Both normal directions are lost: the
    rows of x and y are zero."""
    tr = pwsdyn.simulate(RELAYS, [1.0, 0.5, 0.0], (0.0, 3.0), variational=True, **TIGHT)
    J_fd = _fd_jacobian(RELAYS, [1.0, 0.5, 0.0], (0.0, 3.0), 1e-4)
    np.testing.assert_allclose(tr.jacobian, J_fd, rtol=0, atol=1e-9)
    assert np.max(np.abs(tr.jacobian[:2])) <= 1e-12


def test_jacobian_through_codim2_entry_and_exit_matches_finite_differences():
    """Two blocks from a state slipping on both belts to t = 3: sliding on the first belt,
    on both (entry at ~0.51), the second released (exit at ~2.05). Kernel Jacobian (saltation
    at each event, central-difference Jacobian of the sliding fields) against central
    differences of the flow map with step 1e-5: truncation ~1e-10, rounding ~1e-12/1e-5, so
    5e-6."""
    x0 = [0.0, 0.0, 0.0, 0.0]
    tr = pwsdyn.simulate(two_blocks(), x0, (0.0, 3.0), variational=True, **TIGHT)
    kinds = [(e.kind, e.mode_after) for e in tr.events]
    assert kinds == [("slide_start", "slide:vrel1"),
                     ("slide_start", "slide_multi:vrel1&vrel2"),
                     ("slide_end", "slide:vrel1")]
    J_fd = _fd_jacobian(two_blocks(), x0, (0.0, 3.0), 1e-5)
    np.testing.assert_allclose(tr.jacobian, J_fd, rtol=0, atol=5e-6)


def test_saltation_matrices_at_entry_and_exit():
    """The matrices the kernel applied. Relays, entry into x = y = 0 at t = 2 from sliding on
    y = 0: S = I + (f_after - f_before) h_x / (h_x f_before) with f_before = (-1/2, 0, 3/2),
    f_after = (0, 0, 9/8), h_x = (1, 0, 0): its first column is (0, 0, 3/4), the rest the
    identity's. Two blocks, release of the second belt: the field is continuous there (at
    lambda_2 = 0 the bilinear field is the first belt's sliding field), so the kernel applies
    S = I; that this is right is what the Jacobian through the exit against central
    differences (the test above) verifies."""
    tr = pwsdyn.simulate(RELAYS, [1.0, 0.5, 0.0], (0.0, 3.0), variational=True, **TIGHT)
    S = event_saltations(tr)[1]
    expected = np.eye(3)
    expected[:, 0] = [0.0, 0.0, 0.75]
    np.testing.assert_allclose(S, expected, rtol=0, atol=1e-12)
    # the projected form (between sections) S_p = S - f_after h_x / (h_x f_before): the
    # first column gains (0, 0, 9/8) / (1/2), so it is (0, 0, 3); it kills f_before
    S_p = event_saltations(tr, "projected")[1]
    expected[:, 0] = [0.0, 0.0, 3.0]
    np.testing.assert_allclose(S_p, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(S_p @ [-0.5, 0.0, 1.5], 0.0, rtol=0, atol=1e-12)
    tr = pwsdyn.simulate(two_blocks(), [0.0] * 4, (0.0, 3.0), variational=True, **TIGHT)
    assert tr.events[2].kind == "slide_end"
    np.testing.assert_allclose(event_saltations(tr)[2], np.eye(4), rtol=0, atol=1e-12)


def test_three_relays_slide_on_the_triple_intersection():
    """x' = -sign(x), y' = -2 sign(y), z' = -4 sign(z) from (1, 1/2, 1/2): z = 0 at 1/8,
    y = 0 at 1/4, x = 0 at 1; then at rest on the codimension-3 intersection."""
    m = {"name": "three-relays", "states": ["x", "y", "z"],
         "modes": {"m": {"x": "-sign(x)", "y": "-2*sign(y)", "z": "-4*sign(z)"}}}
    tr = pwsdyn.simulate(m, [1.0, 0.5, 0.5], (0.0, 2.0), **TIGHT)
    assert [str(e.mode_after) for e in tr.events] == [
        "slide:z", "slide_multi:y&z", "slide_multi:x&y&z"]
    np.testing.assert_allclose([e.t for e in tr.events], [0.125, 0.25, 1.0], rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(tr.x_final, 0.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("y_field, x0, kinds, y_end", [
    # y attracting too: both slide from the instant of arrival
    ("-2*sign(y)", [1.0, 2.0], ["slide_multi:x&y"], 0.0),
    # y crossed downwards (y' = -3/2 above, -1/2 below): slides on x, crosses y
    ("-1 - 0.5*sign(y)", [1.0, 1.5], ["slide:x"], -1.0),
    # the same with the faster field below (y' = -3/2 above, -5/2 below)
    ("-2 + 0.5*sign(y)", [1.0, 1.5], ["slide:x"], -5.0),
])
def test_a_regular_arrival_exactly_at_the_intersection(y_field, x0, kinds, y_end):
    """x' = -sign(x) and the motion reaches x = 0 and y = 0 at the same instant t = 1
    (non-generic): it slides on both where both attract, and on x = 0 only where the flow
    crosses y = 0 (every corner field moves y the same way), then y(3) = y_end in closed
    form."""
    m = {"name": "corner", "states": ["x", "y"], "modes": {"m": {"x": "-sign(x)", "y": y_field}}}
    tr = pwsdyn.simulate(m, x0, (0.0, 3.0), **TIGHT)
    assert [str(e.mode_after) for e in tr.events] == kinds
    assert tr.events[0].t == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(tr.x_final, [0.0, y_end], rtol=0, atol=1e-12)
    # a start at the intersection resolves the same way
    tr0 = pwsdyn.simulate(m, [0.0, 0.0], (1.0, 3.0), **TIGHT)
    np.testing.assert_allclose(tr0.x_final, [0.0, y_end], rtol=0, atol=1e-12)
