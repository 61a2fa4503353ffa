"""Boundary crises of one-dimensional maps located from the geometry (issue 25).

The skew tent map ``x -> mu + a x (x <= 0), mu - b x (x > 0)`` (the 1-D border-collision
normal form) with ``mu > 0``, ``a > 1``, ``b > 1``: its attractor is the interval
``[f(mu), mu] = [mu (1 - b), mu]`` (both pieces expanding, so it is chaotic); its basin's lower
boundary is the repelling fixed point of the left piece ``x_L = mu / (1 - a) < 0``, the upper
one that point's right preimage ``(mu - x_L) / b``. The edge ``f(mu)`` reaches ``x_L`` when
``mu (1 - b) = mu / (1 - a)``, i.e. ``(a - 1)(b - 1) = 1``: the crisis is at
``b_c = a / (a - 1)`` (for fixed ``a``) or ``a_c = b / (b - 1)`` (for fixed ``b``), independent
of ``mu``. Below, ``[f(mu), mu]`` maps into itself (``f(f(mu)) >= f(mu)`` exactly when
``(a - 1)(b - 1) <= 1``); above, the part of the attractor left of ``x_L`` escapes to minus
infinity, which the brute-force check confirms.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import pwsdyn
from pwsdyn.errors import ArgumentError
from pwsdyn.manifolds import Crisis, ManifoldError, locate_crisis

TENT = {"name": "skew-tent", "kind": "map", "states": ["x"],
        "parameters": {"mu": 1.0, "a": 1.5, "b": 2.0},
        "pieces": [{"name": "L", "condition": "x <= 0", "map": {"x": "mu + a*x"}},
                   {"name": "R", "map": {"x": "mu - b*x"}}]}


def tent_orbits(x, mu, a, b, n):
    """Iterate many initial conditions at once; ``True`` where the orbit stayed bounded (never
    below the left fixed point's 1e6 multiple)."""
    x = np.array(x, dtype=float)
    alive = np.ones(x.shape, bool)
    for _ in range(n):
        x = np.where(x <= 0, mu + a * x, mu - b * x)
        alive &= x > -1e6 * (1 + mu)
        x = np.where(alive, x, 0.0)
    return alive


def test_the_skew_tent_maps_crisis_in_b_against_its_closed_form():
    a, mu = 1.5, 1.0
    c = locate_crisis(TENT, "b", (2.0, 3.5), x0=[0.1], params={"a": a, "mu": mu}, tol=1e-12)
    bc = a / (a - 1)
    assert isinstance(c, Crisis) and c.kind == "boundary"
    # brentq to xtol 1e-12 on a contact function linear in b (slope mu): 1e-10 covers its
    # rounding; the acceptance is 1e-6
    assert abs(c.value - bc) < 1e-10
    assert c.bracket[0] < bc < c.bracket[1]
    # the saddle is the left piece's fixed point mu / (1 - a) with multiplier a
    assert c.saddle.period == 1 and c.saddle.pieces == ("L",)
    assert abs(c.saddle.x[0] - mu / (1 - a)) < 1e-12
    assert abs(c.saddle.multipliers[0] - a) < 1e-12
    # where they touch: x_L itself (met by f(mu) = f^2(0)) or its right preimage (met by mu)
    xl = mu / (1 - a)
    assert min(abs(c.point[0] - xl), abs(c.point[0] - (mu - xl) / bc)) < 1e-9


def test_a_sweep_too_short_to_see_the_orbit_leave_still_brackets_the_geometric_value():
    # 5 + 5 iterations per value: near b_c the orbit needs far more to find the hole, so the
    # sweep sees it leave only at b ~ 3.4 and a record of ten points under-fills the
    # attractor; the contact is searched back from there and is still the closed form
    c = locate_crisis(TENT, "b", (2.0, 3.5), x0=[0.1], params={"a": 1.5, "mu": 1.0},
                      transient=5, iterations=5, tol=1e-12)
    assert c.kind == "boundary" and abs(c.value - 3.0) < 1e-10 and c.bracket[1] > 3.2


def test_the_crisis_in_a_against_its_closed_form_and_mu_scaling():
    b, mu = 2.5, 0.3
    c = locate_crisis(TENT, "a", (1.2, 2.5), x0=[0.05], params={"b": b, "mu": mu}, tol=1e-12)
    assert abs(c.value - b / (b - 1)) < 1e-10
    assert abs(c.saddle.x[0] - mu / (1 - c.value)) < 1e-9


def test_brute_force_bounded_below_and_escaping_above():
    a, mu = 1.5, 1.0
    c = locate_crisis(TENT, "b", (2.0, 3.5), x0=[0.1], params={"a": a, "mu": mu})
    x0 = np.linspace(-1.9, 0.9, 400)       # inside the basin (x_L, (mu - x_L) / b) = (-2, 1)
    # below: every orbit stays in the basin for 20000 iterations
    assert tent_orbits(x0, mu, a, c.value - 1e-2, 20000).all()
    # above: the hole left of x_L has width ~1e-2 in an interval of width ~3, so an orbit
    # leaves after some hundreds of iterations; 20000 leave none behind
    assert not tent_orbits(x0, mu, a, c.value + 1e-2, 20000).any()


def test_a_smooth_critical_point_the_logistic_maps_crisis_at_r_4():
    # x -> r x (1 - x): the edge is the critical point's image r / 4, the basin is [0, 1] (the
    # repelling fixed point 0, multiplier r, and its preimage 1); they touch at r = 4 exactly,
    # where f^2(1/2) = f(1) = 0 as well, so either contact may be the one reported
    log = {"name": "logistic", "kind": "map", "states": ["x"], "parameters": {"r": 3.9},
           "pieces": [{"name": "P", "map": {"x": "r*x*(1 - x)"}}]}
    c = locate_crisis(log, "r", (3.9, 4.2), x0=[0.3], tol=1e-12)
    # the contact function is smooth with a nonzero slope in r; the critical point is found
    # to 1e-15 and enters the edge quadratically, so 1e-10 is loose
    assert abs(c.value - 4.0) < 1e-10
    assert abs(c.edge[1] - 0.5) < 1e-12
    assert abs(c.saddle.x[0]) < 1e-12 and abs(c.saddle.multipliers[0] - 4.0) < 1e-9
    assert min(abs(c.point[0]), abs(c.point[0] - 1.0)) < 1e-9


# Nordmark's square-root map (the zoo's sqrt-map): x -> mu + lam x (x <= 0), mu - sqrt(x)
# (x > 0), with lam > 1. Its edges are f(0) = mu and f(mu) = mu - sqrt(mu); the left piece's
# fixed point x_L = mu / (1 - lam) < 0 repels, and [f(mu), mu] maps into itself while
# f(mu) >= x_L, i.e. sqrt(mu) lam / (lam - 1) >= 1: the attractor exists for
# mu >= mu_c = ((lam - 1) / lam)^2 and is destroyed below (the square root's edge, -sqrt(mu),
# outruns x_L ~ -mu as mu decreases).

@pytest.mark.parametrize("lam", [1.5, 2.0, 3.0])
def test_nordmarks_square_root_map_crisis_against_its_closed_form(lam):
    muc = ((lam - 1) / lam) ** 2
    # a decreasing span: the attractor exists at its start
    c = locate_crisis("sqrt-map", "mu", (2 * muc, 0.5 * muc), params={"lam": lam}, tol=1e-13)
    # the saddle is found by Newton to a residual of 1e-12, which bounds the contact's
    # accuracy: 1e-10 (the acceptance is 1e-6)
    assert c.kind == "boundary" and abs(c.value - muc) < 1e-10
    assert c.saddle.pieces == ("no_impact",) and abs(c.saddle.multipliers[0] - lam) < 1e-12
    assert abs(c.point[0] - muc / (1 - lam)) < 1e-10
    # brute force: orbits from [f(mu), mu] stay bounded just above mu_c, all leave below
    for mu, bounded in ((muc * (1 + 1e-2), True), (muc * (1 - 1e-2), False)):
        x = np.linspace(mu - np.sqrt(mu), mu, 300)
        alive = np.ones(x.shape, bool)
        for _ in range(20000):
            x = np.where(x <= 0, mu + lam * x, mu - np.sqrt(np.abs(x)))
            alive &= x > -1e6
            x = np.where(alive, x, 0.0)
        assert alive.all() if bounded else not alive.any()


# The cubic map x -> r x - x^3 is odd: for r < r_i its attractors are symmetric twins on either
# side of the repelling fixed point 0. The positive one is [f^2(x_c), f(x_c)], x_c =
# sqrt(r / 3) the critical point, f(x_c) = (2 r / 3) sqrt(r / 3); (0, sqrt(r)) maps into
# itself while f(x_c) < sqrt(r) (the positive preimage of 0). They merge (an interior crisis:
# the extent doubles) when f(x_c) = sqrt(r), i.e. 2 r / (3 sqrt 3) = 1, r_i = 3 sqrt(3) / 2.
# The merged attractor [-f(x_c), f(x_c)] is destroyed (a boundary crisis) when f(x_c) reaches
# the period-2 saddle sqrt(r + 1) (f(s) = -s): at r = 3, f(1) = 2 = sqrt(4).
CUBIC = {"name": "cubic", "kind": "map", "states": ["x"], "parameters": {"r": 2.5},
         "pieces": [{"name": "P", "map": {"x": "r*x - x**3"}}]}


def test_an_interior_crisis_the_cubic_maps_attractors_merge_at_3_sqrt3_over_2():
    ri = 1.5 * np.sqrt(3.0)
    c = locate_crisis(CUBIC, "r", (2.45, 2.75), x0=[0.6], tol=1e-12)
    # a smooth contact function with a nonzero slope: 1e-10 leaves room for its rounding
    assert c.kind == "interior" and abs(c.value - ri) < 1e-10
    assert abs(c.saddle.x[0]) < 1e-10 and abs(c.saddle.multipliers[0] - ri) < 1e-9
    assert abs(c.edge[1] - np.sqrt(ri / 3)) < 1e-12
    # brute force: below, orbits from (0, sqrt r) stay positive; above, every one crosses
    x = np.linspace(0.05, 1.5, 300)
    for r, crossed in ((ri - 1e-2, False), (ri + 1e-2, True)):
        y, neg = x.copy(), np.zeros(x.shape, bool)
        for _ in range(20000):
            y = r * y - y ** 3
            neg |= y < 0
        assert neg.all() if crossed else not neg.any()


def test_the_cubic_maps_boundary_crisis_at_r_3_on_the_period_two_saddle():
    c = locate_crisis(CUBIC, "r", (2.7, 3.2), x0=[0.6], tol=1e-12)
    assert c.kind == "boundary" and abs(c.value - 3.0) < 1e-10
    assert c.saddle.period == 2 and abs(abs(c.saddle.x[0]) - 2.0) < 1e-10


def test_no_crisis_in_the_span_and_a_three_dimensional_map_are_reported():
    with pytest.raises(ManifoldError, match="stays bounded"):
        locate_crisis(TENT, "b", (2.0, 2.5), x0=[0.1], steps=3, transient=100,
                      iterations=100)
    space = {"name": "space", "kind": "map", "states": ["x", "y", "z"],
             "parameters": {"mu": 1.0},
             "pieces": [{"name": "P", "map": {"x": "mu - x*x + y", "y": "0.3*x",
                                              "z": "0.5*z"}}]}
    with pytest.raises(ArgumentError, match="two-dimensional"):
        locate_crisis(space, "mu", (1.0, 2.0), x0=[0.0, 0.0, 0.0])
    assert pwsdyn.locate_crisis is locate_crisis and pwsdyn.Crisis is Crisis


# ======================================================================================
# planar maps: the border-collision normal form's boundary crisis, a homoclinic tangency
# ======================================================================================
#
# x -> A_L x + mu e1 (x1 <= 0), A_R x + mu e1 (x1 > 0), A = [[tau, 1], [-delta, 0]] (Nusse &
# Yorke 1992), with tau_L > 1 + delta_L and tau_R < -(1 + delta_R): a chaotic attractor around
# the flip saddle R* in R; the saddle L* = mu (1, -delta_L) / (1 - tau_L + delta_L) in L, with
# multipliers l1 > 1 > l2 > 0 (roots of l^2 - tau_L l + delta_L), bounds its basin. Derived
# here: the stable line of L*, through L* along w = (1, -delta_L / l2), is W^s(L*) within L;
# its part below the x1-axis has the preimage F_R^{-1} in R (F_R maps R below the axis,
# F_L maps L above it). The unstable line of L*, along u = (1, -delta_L / l1), reaches the
# border at B = L* - x_L* u; both pieces send B to T = (B_2 + mu, 0), a fold of W^u(L*) on the
# x1-axis, the attractor's rightmost tip. T lies on F_R^{-1}(stable line) exactly when
# Q = A_R T + mu e1 lies on the stable line: the contact g = (w x (Q - L*)) / |w| = 0, a
# homoclinic tangency of L*, is the crisis (beyond it the tip crosses into the escaping side).
# Closed form up to one scalar root, found here by brentq at xtol 1e-15.

def bcnf_planar(tL, dL=0.3, tR=-1.8, dR=0.3, mu=1.0):
    return {"name": "bcnf", "kind": "map", "states": ["x", "y"],
            "parameters": {"tL": tL, "dL": dL, "tR": tR, "dR": dR, "mu": mu},
            "pieces": [{"name": "L", "condition": "x <= 0",
                        "map": {"x": "tL*x + y + mu", "y": "-dL*x"}},
                       {"name": "R", "map": {"x": "tR*x + y + mu", "y": "-dR*x"}}]}


def bcnf_contact(tL, dL=0.3, tR=-1.8, dR=0.3, mu=1.0):
    """The signed distance of Q = F(T) from the stable line of L* (see above), and L*."""
    AR = np.array([[tR, 1.0], [-dR, 0.0]])
    s = np.sqrt(tL * tL - 4 * dL)
    l1, l2 = (tL + s) / 2, (tL - s) / 2
    xL = mu / (1 - tL + dL)
    L = np.array([xL, -dL * xL])
    u, w = np.array([1.0, -dL / l1]), np.array([1.0, -dL / l2])
    B = L - xL * u
    T = np.array([B[1] + mu, 0.0])
    d = AR @ T + [mu, 0.0] - L
    return (w[0] * d[1] - w[1] * d[0]) / np.linalg.norm(w), L, T


def bcnf_alive(tL, n, dL=0.3, tR=-1.8, dR=0.3, mu=1.0, count=300):
    """Brute force: iterate ``count`` initial conditions around R* for ``n`` iterations; the
    fraction that stayed bounded."""
    AL = np.array([[tL, 1.0], [-dL, 0.0]])
    AR = np.array([[tR, 1.0], [-dR, 0.0]])
    x = np.random.default_rng(0).uniform(-0.3, 0.3, (count, 2)) + [0.3, -0.1]
    ok = np.ones(count, bool)
    for _ in range(n):
        y = np.where((x[:, 0] <= 0)[:, None], x @ AL.T, x @ AR.T)
        y[:, 0] += mu
        ok &= np.abs(y[:, 0]) < 1e6
        x = np.where(ok[:, None], y, 0.0)
    return ok.mean()


@pytest.fixture(scope="module")
def planar_crisis():
    return locate_crisis(bcnf_planar(1.8), "tL", (1.8, 2.0), x0=[0.1, 0.0], steps=11)


def test_a_planar_maps_boundary_crisis_against_its_closed_form_and_brute_force(planar_crisis):
    from scipy.optimize import brentq

    tLc = brentq(lambda t: bcnf_contact(t)[0], 1.85, 1.95, xtol=1e-15)
    c = planar_crisis
    # piecewise-linear: the fold T is a vertex of the manifold computed as the image of the
    # border point (its bisection to a few ulp) and W^s is straight there, so the contact
    # is exact to rounding; brentq's xtol is 1e-12: 1e-10 (the acceptance is 1e-6)
    assert c.kind == "boundary" and abs(c.value - tLc) < 1e-10
    assert c.bracket[0] < tLc < c.bracket[1]
    _, L, T = bcnf_contact(c.value)
    assert c.saddle.pieces == ("L",) and np.allclose(c.saddle.x, L, atol=1e-12)
    assert c.unstable is c.saddle                   # a homoclinic tangency
    assert np.linalg.norm(c.point - T) < 1e-9       # the fold touches W^s(L*)
    Wu, Ws = c.manifolds
    assert Wu.kind == "unstable" and Ws.kind == "stable" and Ws.distance(T)[0] < 1e-9
    # brute force: bounded for 20000 iterations just below, all gone just above (escape
    # times grow as the crisis is approached, so the margin above is wider)
    assert bcnf_alive(tLc - 5e-3, 20000) == 1.0
    assert bcnf_alive(tLc + 2e-2, 20000) == 0.0


def test_a_homoclinic_tangency_in_another_parameter_against_its_closed_form():
    from scipy.optimize import brentq

    tRc = brentq(lambda t: bcnf_contact(1.89, tR=t)[0], -1.75, -1.85, xtol=1e-15)
    model = bcnf_planar(1.89, tR=-1.75)
    L = pwsdyn.find_periodic_point(model, [-1.7, 0.5])
    c = pwsdyn.locate_tangency(model, "tR", (-1.75, -1.85), L, tol=1e-13)
    # exact contact (see above): brentq's xtol 1e-13 and rounding
    assert c.kind == "tangency" and abs(c.value - tRc) < 1e-11
    assert c.saddle is c.unstable and len(c.history) >= 3


def test_locate_tangency_refuses_what_it_cannot_do():
    with pytest.raises(ArgumentError):
        pwsdyn.locate_tangency(TENT, "b", (2.0, 3.0), [0.1])
    model = bcnf_planar(1.8)
    with pytest.raises(ArgumentError):
        pwsdyn.locate_tangency(model, "nope", (1.8, 1.85), [-2.0, 0.6])
    # no contact over the span: the manifolds stay apart
    with pytest.raises(ManifoldError):
        pwsdyn.locate_tangency(model, "tL", (1.8, 1.85), [-2.0, 0.6])


# ======================================================================================
# the result
# ======================================================================================

@pytest.mark.parametrize("which", ["tent", "planar"])
def test_a_crisis_round_trips_through_netcdf(which, planar_crisis, tmp_path):
    import xarray as xr

    from pwsdyn.errors import OutputExistsError

    c = planar_crisis if which == "planar" else locate_crisis(
        TENT, "b", (2.0, 3.5), x0=[0.1], params={"a": 1.5, "mu": 1.0})
    path = c.save(tmp_path / "c.nc")
    with pytest.raises(OutputExistsError):
        c.save(path)
    with xr.open_dataset(path) as ds:
        got = ds.load()
    want = c.to_dataset()
    for name in want.data_vars:
        assert np.array_equal(got[name].values, want[name].values), name
    for k, v in want.attrs.items():
        assert np.all(got.attrs[k] == v), k
    assert got.attrs["value"] == c.value and got.attrs["crisis_kind"] == "boundary"
    assert got.attrs["pwsdyn_type"] == "crisis" and "model_text" in got.attrs
    assert np.array_equal(got["point"].values, c.point)
    if which == "planar":
        Wu, Ws = c.manifolds
        assert got["stable_x"].shape == (Ws.n_points, 2)
        assert np.array_equal(got["unstable_saddle"].values, c.unstable.x)
    else:
        assert json.loads(got.attrs["edge"])[0] == c.edge[0] and "stable_x" not in got


def test_the_crisis_figure_has_every_part_in_its_legend(planar_crisis):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from pwsdyn.plot import plot_crisis

    A = np.random.default_rng(1).normal(size=(50, 2)) * 0.1
    fig = plot_crisis(planar_crisis, attractor=A)
    ax = fig.axes[0]
    labels = {t.get_text() for t in ax.get_legend().get_texts()}
    assert {"attractor", "contact", "saddle (period 1)",
            "stable manifold of the boundary saddle"} <= labels
    drawn = {ln.get_label() for ln in ax.get_lines() if not ln.get_label().startswith("_")}
    assert drawn <= labels
    # into the user's axes: that figure is returned
    mine = Figure()
    assert plot_crisis(planar_crisis, ax=mine.subplots()) is mine
    with pytest.raises(ArgumentError):
        plot_crisis(object())
