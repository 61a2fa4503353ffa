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


def test_no_crisis_in_the_span_and_a_two_dimensional_map_are_reported():
    with pytest.raises(ManifoldError, match="stays bounded"):
        locate_crisis(TENT, "b", (2.0, 2.5), x0=[0.1], steps=3, transient=100,
                      iterations=100)
    plane = {"name": "plane", "kind": "map", "states": ["x", "y"], "parameters": {"mu": 1.0},
             "pieces": [{"name": "P", "map": {"x": "mu - x*x + y", "y": "0.3*x"}}]}
    with pytest.raises(ArgumentError, match="one-dimensional"):
        locate_crisis(plane, "mu", (1.0, 2.0), x0=[0.0, 0.0])
    assert pwsdyn.locate_crisis is locate_crisis and pwsdyn.Crisis is Crisis
