"""The branch past a discontinuity-induced bifurcation (issue 23, items 2 and 3), against the
closed forms of the impact oscillator

    x'' + c x' + k x = A cos(w t),  x <= d,  at x = d: v -> -e v,

with (k, c, d, e) = (1, 0.1, 1, 0.8), derived here from the linear flow between impacts.

* Without impacts the orbit is the forced response z_p(t) = (X sin(w t) + Y cos(w t),
  w (X cos(w t) - Y sin(w t))), (k - w^2) X - c w Y = 0, (k - w^2) Y + c w X = A, of
  amplitude R = A R1, R1 = 1 / sqrt((k - w^2)^2 + (c w)^2); it grazes the wall where R = d.
* An orbit with one impact per period T = 2 pi / w, at time t0 with velocity v > 0, leaves
  the wall at (d, -e v) and comes back to (d, v) after T: with z' = M z + forcing,
  E = expm(M T), (d, v) - z_p(t0) = E ((d, -e v) - z_p(t0)), so z_p(t0) = (d, 0) + v b,
  b = (I - E)^{-1} (I + e E) (0, 1). As x_p^2 + (v_p / w)^2 = R^2 at every t0,

      (d + v b1)^2 + (v b2 / w)^2 = A^2 R1^2,                                   (1)

  a quadratic in v: qa v^2 + qb v + qc = 0, qa = b1^2 + (b2 / w)^2, qb = 2 d b1,
  qc = d^2 - A^2 R1^2. At w = 1, b1 < 0: for A R1 < d both roots are positive -- the
  small-velocity orbit and the large one exist on the side where the non-impacting orbit
  does; the small root reaches v = 0 at the graze A R1 = d (a non-smooth fold: both branches
  meet there from one side) and the two meet at the smooth fold where the discriminant
  vanishes, qb^2 = 4 qa qc, i.e. A_fold = d |b2| / (w R1 sqrt(qa)), just below the graze.

The small root is found with a scalar root finder (``brentq`` on (1) in v, bracketed by 0 and
the fold's double root -qb / (2 qa)) to 1e-15; the fold is the least A of (1) over v, in
closed form. Tolerances: 1e-7 asked for, the located points agree to 1e-10 (the continuation
locates to ``locate_tol`` 1e-11 in arclength; Newton's tolerance is 1e-10).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

import pwsdyn

K, C, D, E_R = 1.0, 0.1, 1.0, 0.8
COCO = {"name": "coco-impact-oscillator", "states": ["x", "v"],
        "parameters": {"k": K, "c": C, "A": 1.0, "w": 1.0, "d": D, "e": E_R},
        "forcing_period": "2*pi/w",
        "modes": {"free": {"x": "v", "v": "A*cos(w*t) - c*v - k*x"}},
        "events": [{"name": "impact", "kind": "impact", "surface": "d - x", "direction": -1,
                    "reset": {"v": "-e*v"}}]}


@pytest.fixture(scope="module")
def model():
    return pwsdyn.load_model(COCO)


def _quadratic(w):
    """``(qa, qb, R1)`` of (1) at forcing frequency ``w``."""
    T = 2 * np.pi / w
    E = expm(np.array([[0.0, 1.0], [-K, -C]]) * T)
    b = np.linalg.solve(np.eye(2) - E, (np.eye(2) + E_R * E) @ np.array([0.0, 1.0]))
    return b[0] ** 2 + (b[1] / w) ** 2, 2 * D * b[0], 1.0 / math.hypot(K - w * w, C * w)


def _fold(w=1.0):
    """The smooth fold of the one-impact orbit: ``(A_fold, v_fold)``."""
    qa, qb, R1 = _quadratic(w)
    v = -qb / (2 * qa)
    return math.sqrt(D * D - qb * qb / (4 * qa)) / R1, v


def _roots(A, w=1.0):
    """Impact velocities of the one-impact orbits at ``(A, w)``: the small root by ``brentq``
    on (1) (where it is positive: A R1 < d) and the large one, each ``None`` where absent."""
    qa, qb, R1 = _quadratic(w)

    def f(v):
        return qa * v * v + qb * v + D * D - (A * R1) ** 2
    vf = -qb / (2 * qa)
    if f(vf) > 0.0:
        return None, None
    small = brentq(f, 0.0, vf, xtol=1e-16) if f(0.0) > 0.0 else None
    big = brentq(f, vf, vf + 10.0 * (1.0 + A * R1), xtol=1e-16)
    return small, big


def _non_impacting(model, A, w):
    X, Y = np.linalg.solve(np.array([[K - w * w, -C * w], [C * w, K - w * w]]), [0.0, A])
    return pwsdyn.find_periodic_orbit(model, [Y, w * X], t0=0.0, params={"A": A, "w": w})


def _impact_velocity(br, i):
    """The impact velocity of an impacting point (its section state is just after the
    impact: x = d, v = -e v_impact)."""
    x = br.states[i]
    assert abs(x[0] - D) < 1e-12
    return -x[1] / E_R


def test_closed_form_is_consistent():
    """The fold is the double root, the graze the zero root of (1)."""
    Af, vf = _fold()
    assert _roots(Af * (1 - 1e-12))[0] is None
    s, b = _roots(Af * (1 + 1e-9))
    assert abs(s - vf) < 1e-3 and abs(b - vf) < 1e-3
    assert _roots(0.1 * (1 - 1e-12))[0] < 1e-9 and 0.0999 < Af < 0.1


def test_down_the_impacting_branch_through_the_fold_and_the_graze(model, tmp_path):
    """From the stable impacting orbit at A = 1 down in A: the smooth fold, the small-velocity
    orbits up to the graze at A = d / R1 = 0.1 (a non-smooth fold), then the non-impacting
    orbit down to the end of the span (before: the branch stopped at the graze, 'the orbit of
    the new signature () is not admissible')."""
    orb = pwsdyn.PeriodicOrbit.from_trajectory(
        pwsdyn.simulate(model, [0.0, 0.0], (0, 300), params={"A": 1.0}))
    br = pwsdyn.continue_orbit(model, orb, "A", span=(0.05, 1.0), ds=-0.02)
    Af, vf = _fold()
    kinds = [sp.kind for sp in br.special_points]
    assert kinds == ["LP", "GR", "EP"], br.stop_reason
    lp, gr, ep = br.special_points
    assert abs(lp.value - Af) < 1e-10
    assert abs(_impact_velocity(br, lp.index) - vf) < 1e-7
    assert abs(gr.value - 0.1) < 1e-10 and gr.key == "GR/impact@0"
    assert gr.nonsmooth_fold and not lp.nonsmooth_fold and "non-smooth fold" in repr(gr)
    # the branch file keeps it (before, a loaded branch lost what the graze was)
    br.save(tmp_path / "b.nc")
    back = pwsdyn.load_branch(tmp_path / "b.nc")
    assert [(sp.kind, sp.nonsmooth_fold) for sp in back.special_points] == [
        ("LP", False), ("GR", True), ("EP", False)]
    assert ep.value == pytest.approx(0.05)
    assert br.admissible.all()
    after = [i for i, p in enumerate(br.points) if i > gr.index]
    assert len(after) >= 4 and all(len(br.problem_of(br.points[i]).orbit_problem.signature)
                                   == 0 for i in after)
    assert np.all(np.diff(br.values[after]) < 0)           # turned back down in A
    for i in after:                                          # the linear response
        A = br.points[i].lam
        X, Y = np.linalg.solve(np.array([[K - 1, -C], [C, K - 1]]), [0.0, A])
        t = br.problem_of(br.points[i]).orbit_problem.t_ref
        want = [X * math.sin(t) + Y * math.cos(t), X * math.cos(t) - Y * math.sin(t)]
        assert np.max(np.abs(br.states[i] - want)) < 1e-9
    for i in range(gr.index):                                # the impacting orbits
        if i == lp.index:
            continue                                         # the double root, above
        small, big = _roots(br.points[i].lam)
        v = _impact_velocity(br, i)
        ref = big if i <= lp.index else small
        assert abs(v - ref) < 1e-7, (i, br.points[i].lam, v, small, big)


def test_up_the_non_impacting_branch_turns_back_at_the_graze(model):
    """From the non-impacting orbit at A = 0.05 up in A: at the graze the branch turns back
    onto the unstable small-velocity impacting orbits, through the smooth fold, and up the
    stable large-velocity ones (before: it jumped to the stable orbit, skipping the fold)."""
    br = pwsdyn.continue_orbit(model, _non_impacting(model, 0.05, 1.0), "A", span=(0.05, 1.0),
                               ds=0.02)
    Af, vf = _fold()
    assert [sp.kind for sp in br.special_points] == ["GR", "LP", "EP"], br.stop_reason
    gr, lp, ep = br.special_points
    assert abs(gr.value - 0.1) < 1e-10 and gr.key == "GR/impact/0"
    assert gr.nonsmooth_fold
    assert abs(lp.value - Af) < 1e-10 and abs(_impact_velocity(br, lp.index) - vf) < 1e-7
    assert ep.value == pytest.approx(1.0) and br.admissible.all()
    small_side = list(range(gr.index + 1, lp.index))
    assert small_side                                 # an orbit on the small-velocity side
    for i in small_side:
        assert not br.points[i].data["stable"]
        assert abs(_impact_velocity(br, i) - _roots(br.points[i].lam)[0]) < 1e-7
    for i in range(lp.index + 1, len(br)):
        assert abs(_impact_velocity(br, i) - _roots(br.points[i].lam)[1]) < 1e-7


def _window(width):
    """``(A, w1, w2)``: the forcing amplitude for which the non-impacting orbit penetrates the
    wall on a window (w1, w2) of the given width, and its ends. With s = w^2 the amplitude
    is d where A^2 = (1 - s)^2 + c^2 s, i.e. (s - s*)^2 = A^2 - A*^2 with s* = 1 - c^2 / 2 =
    0.995, A*^2 = c^2 - c^4 / 4 = 0.009975: w1,2 = sqrt(s* -+ r), A^2 = A*^2 + r^2."""
    s_star = 1 - C * C / 2
    r = brentq(lambda r: math.sqrt(s_star + r) - math.sqrt(s_star - r) - width, 0.0, 0.1,
               xtol=1e-18)
    return math.sqrt(C * C - C ** 4 / 4 + r * r), math.sqrt(s_star - r), math.sqrt(s_star + r)


@pytest.mark.parametrize("width, start, ds", [(1e-3, 0.9, None), (1e-4, 0.9, None),
                                               (1e-4, 1.1, -0.02), (1e-4, 0.9, 0.0005)])
def test_no_graze_stepped_over(model, width, start, ds):
    """The non-impacting orbit continued in w over (0.9, 1.1) penetrates the wall on a window
    of w narrower than a step (before: stepped over, nothing reported): both grazes are
    located at their closed forms, once each, at default settings, in either direction and
    for steps over a 40x range; the orbit in between has one impact (the offset of the
    restart past the first graze, 2e-4 by default, shrinks below the window's width)."""
    A, w1, w2 = _window(width)
    orb = _non_impacting(model, A, start)
    kw = {} if ds is None else {"ds": ds}
    br = pwsdyn.continue_orbit(model, orb, "w", span=(0.9, 1.1), params={"A": A}, **kw)
    gr = sorted(br.special("GR"), key=lambda sp: sp.value)
    assert len(gr) == 2, br.stop_reason
    assert abs(gr[0].value - w1) < 1e-9 and abs(gr[1].value - w2) < 1e-9
    assert not any(sp.nonsmooth_fold for sp in gr)
    assert br.values.min() == pytest.approx(0.9) and br.values.max() == pytest.approx(1.1)
    assert br.admissible.all()
    for i, p in enumerate(br.points):
        if len(br.problem_of(p).orbit_problem.signature):
            assert w1 - 1e-9 <= p.lam <= w2 + 1e-9
            v = _impact_velocity(br, i)
            assert min(abs(v - r) for r in _roots_any(A, p.lam)) < 1e-7


def _roots_any(A, w):
    """Both roots of (1) at ``(A, w)`` (either sign)."""
    qa, qb, R1 = _quadratic(w)
    disc = qb * qb - 4 * qa * (D * D - (A * R1) ** 2)
    return [(-qb + s * math.sqrt(max(disc, 0.0))) / (2 * qa) for s in (-1, 1)]
