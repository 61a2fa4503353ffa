"""Codimension-two points on two-parameter curves, normal-form coefficients, and round-off
that is not a zero of a test function (pwsdyn.continuation.codim2), against closed forms
derived here independently of pwsdyn.

The kicked shear: a forced model that relaxes ``y`` for half a period and shears ``x`` for the
other half (``T = 1``),

    relax (cos(2 pi t) > 0):  x' = 0,         y' = G(x) - (k + k2 x^2) y,
                              G = g0 + g1 x + g2 x^2 + g3 x^3
    shear (cos(2 pi t) < 0):  x' = y - m x,   y' = 0,

so that each phase has a closed-form flow (``x`` or ``y`` frozen, the other linear) and the
stroboscopic map from ``t = 0`` is the composition ``R_{1/4} S_{1/2} R_{1/4}`` with

    R_tau(x, y) = (x, e^{-K tau} y + G(x) (1 - e^{-K tau}) / K),   K = k + k2 x^2,
    S_s(x, y)   = (e^{-m s} x + y (1 - e^{-m s}) / m, y),

written out in SymPy below and differentiated exactly. Its fixed points are ``G(x*) = 0``,
``y* = 0`` (constant orbits): folds where ``G'(x*) = 0``, the cusp where also ``G''(x*) = 0``;
``det M = exp(-(k + m) / 2)`` (a Neimark-Sacker curve ``k = -m``) and ``tr M`` is affine in
``g1``, so the resonances on it and the period doubling ``1 + tr M + det M = 0`` are roots of
closed-form functions; the flip's normal-form coefficient is computed from the exact second
and third derivatives (Kuznetsov, Elements of Applied Bifurcation Theory, 3rd ed., section
5.4), so the generalized period doubling is the root of a closed-form function too.

Tolerances: orbits are integrated at rtol = atol = 1e-12, the curves' Newton converges to
1e-10 and special points are located to 1e-11 in arclength; the normal-form coefficients
come from fourth-order finite differences of the Poincaré map's Jacobian (step 1e-2, error
about 1e-8); the claims are 1e-7 for every located parameter value.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import sympy as sp
from scipy.linalg import expm
from scipy.optimize import brentq, minimize_scalar

import pwsdyn
from pwsdyn.continuation import codim2

from _orbit_cases import IO, closed_form_state, io_one_impact, io_orbit

M_DAMP = 0.1


def shear(**p) -> dict:
    params = {"g0": 0.0, "g1": -1.0, "g2": 0.0, "g3": 0.0, "k": 0.2, "k2": 0.0, "m": M_DAMP,
              "omega": 2 * math.pi}
    params.update(p)
    return {"name": "kicked-shear", "states": ["x", "y"], "parameters": params,
            "forcing_period": "2*pi/omega",
            "modes": {"relax": {"x": "0",
                                "y": "g0 + g1*x + g2*x**2 + g3*x**3 - (k + k2*x**2)*y"},
                      "shear": {"x": "y - m*x", "y": "0"}},
            "events": [{"name": "to_shear", "kind": "transition", "surface": "cos(omega*t)",
                        "direction": -1, "modes": ["relax"], "target": "shear"},
                       {"name": "to_relax", "kind": "transition", "surface": "cos(omega*t)",
                        "direction": 1, "modes": ["shear"], "target": "relax"}]}


# ---- the closed-form map -----------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def _map():
    x, y, g0, g1, g2, g3, k, k2, m = sp.symbols("x y g0 g1 g2 g3 k k2 m", real=True)

    def relax(X, Y, tau):
        kx = k + k2 * X**2
        a = sp.exp(-kx * tau)
        return X, a * Y + (g0 + g1 * X + g2 * X**2 + g3 * X**3) * (1 - a) / kx

    def shr(X, Y, s):
        e = sp.exp(-m * s)
        return e * X + Y * (1 - e) / m, Y

    X, Y = relax(x, y, sp.Rational(1, 4))
    X, Y = shr(X, Y, sp.Rational(1, 2))
    X, Y = relax(X, Y, sp.Rational(1, 4))
    P = [X, Y]
    v = (x, y)
    args = (x, y, g0, g1, g2, g3, k, k2, m)
    J = sp.lambdify(args, [[sp.diff(P[i], v[j]) for j in range(2)] for i in range(2)])
    B = sp.lambdify(args, [[[sp.diff(P[i], v[a], v[b]) for b in range(2)] for a in range(2)]
                           for i in range(2)])
    C = sp.lambdify(args, [[[[sp.diff(P[i], v[a], v[b], v[c]) for c in range(2)]
                             for b in range(2)] for a in range(2)] for i in range(2)])
    return J, B, C


def _params(**p):
    base = dict(g0=0.0, g1=-1.0, g2=0.0, g3=0.0, k=0.2, k2=0.0, m=M_DAMP)
    base.update(p)
    return [base[n] for n in ("g0", "g1", "g2", "g3", "k", "k2", "m")]


def map_jacobian(xs=(0.0, 0.0), **p) -> np.ndarray:
    return np.array(_map()[0](*xs, *_params(**p)), dtype=float)


def flip_coefficient(xs=(0.0, 0.0), **p) -> float:
    """Kuznetsov's flip coefficient from the exact derivatives of the closed-form map."""
    J, B, C = _map()
    A = map_jacobian(xs, **p)
    Bt = np.array(B(*xs, *_params(**p)), dtype=float)
    Ct = np.array(C(*xs, *_params(**p)), dtype=float)
    w, V = np.linalg.eig(A)
    q = V[:, np.argmin(abs(w + 1))].real
    q /= np.linalg.norm(q)
    wl, W = np.linalg.eig(A.T)
    pv = W[:, np.argmin(abs(wl + 1))].real
    pv /= pv @ q
    Bf = lambda u, v: np.einsum("iab,a,b->i", Bt, u, v)  # noqa: E731
    Cf = lambda u, v, z: np.einsum("iabc,a,b,c->i", Ct, u, v, z)  # noqa: E731
    return float(pv @ Cf(q, q, q) / 6 + 0.5 * pv @ Bf(q, np.linalg.solve(np.eye(2) - A,
                                                                           Bf(q, q))))


def ns_coefficient(xs=(0.0, 0.0), **p) -> float:
    """Kuznetsov's Neimark-Sacker coefficient ``d`` (``|q| = 1``) from the exact derivatives
    of the closed-form map."""
    J, B, C = _map()
    A = map_jacobian(xs, **p)
    Bt = np.array(B(*xs, *_params(**p)), dtype=float)
    Ct = np.array(C(*xs, *_params(**p)), dtype=float)
    w, V = np.linalg.eig(A)
    i = int(np.argmax(w.imag))
    mu, q = w[i], V[:, i] / np.linalg.norm(V[:, i])
    wl, W = np.linalg.eig(A.T)
    pv = W[:, int(np.argmin(abs(wl - np.conj(mu))))]
    pv = pv / np.vdot(q, pv)
    Bf = lambda u, v: np.einsum("iab,a,b->i", Bt, u, v)  # noqa: E731
    Cf = lambda u, v, z: np.einsum("iabc,a,b,c->i", Ct, u, v, z)  # noqa: E731
    I2 = np.eye(2)
    r = (Cf(q, q, q.conj()) + 2 * Bf(q, np.linalg.solve(I2 - A, Bf(q, q.conj())))
         + Bf(q.conj(), np.linalg.solve(mu**2 * I2 - A, Bf(q, q))))
    return float(0.5 * (np.conj(mu) / abs(mu) * np.vdot(pv, r)).real)


def g1_period_doubling(**p) -> float:
    def f(g):
        M = map_jacobian(g1=g, **p)
        return 1 + np.trace(M) + np.linalg.det(M)
    return brentq(f, -40.0, -2.0, xtol=1e-15)


def _orbit(model, x0):
    return pwsdyn.find_periodic_orbit(model, x0, t0=0.0)


# ---- the coefficients on maps given in closed form ------------------------------------------

def test_curve_tests_of_multipliers():
    """The test functions of each curve from the multipliers (no coefficient needed for the
    resonances): on a Neimark-Sacker curve ``kappa`` is the real part of the critical pair,
    and stays continuous through the 1:2 resonance into a real pair ``mu, 1/mu``."""
    th = 2 * np.pi / 3
    t = codim2.curve_tests("NS", [np.exp(1j * th), np.exp(-1j * th), 0.3], 0.0)
    assert abs(t["R3"]) < 1e-15 and abs(t["R2"] - 0.5) < 1e-15
    t = codim2.curve_tests("NS", [-2.0, -0.5, 0.3], 0.0)
    assert t["R2"] == pytest.approx(-0.25, abs=1e-15)
    t = codim2.curve_tests("PD", [-1.0, -0.8], 0.1)
    assert t["R2"] == pytest.approx(0.2) and t["LPPD"] == pytest.approx(2 * 1.8)
    t = codim2.curve_tests("LP", [1.0, -1.0], 0.1)
    assert t["LPPD"] == 0.0 and t["CP"] == 0.1
    assert codim2.curve_tests("PD", [np.nan, 1.0], 0.1) == {}


def _jac_of(exprs, syms):
    J = sp.lambdify(syms, sp.Matrix(exprs).jacobian(syms))
    return lambda v: np.array(J(*v), dtype=float)


def test_normal_form_coefficients_of_polynomial_maps():
    """Against the center-manifold reductions done by hand: fold ``x -> x + a x^2`` (with a
    stable direction): ``a``; flip ``x -> -x + a x^2 + b x^3 + x y / 2``,
    ``y -> 3 y / 10 + x^2``: the center manifold ``y = x^2 / (1 - 0.3)`` gives
    ``c = b + a^2 + h / 2``; Neimark-Sacker ``z -> e^{i theta} z (1 + c |z|^2)``:
    ``d = Re c`` for ``q = (1, -i) / 2``, i.e. ``2 Re c`` for ``|q| = 1``. Fourth-order finite
    differences of exact Jacobians: 1e-8."""
    x, y = sp.symbols("x y", real=True)
    a, b = 0.7, -0.2
    jac = _jac_of([x + a * x**2 + 0.3 * x * y, 0.5 * y + x**2], (x, y))
    assert abs(codim2.normal_form_coefficient("LP", jac, np.zeros(2)) - a) < 1e-8
    jac = _jac_of([-x + a * x**2 + b * x**3 + 0.5 * x * y, 0.3 * y + x**2], (x, y))
    ref = b + a**2 + 0.5 / (1 - 0.3)
    assert abs(codim2.normal_form_coefficient("PD", jac, np.zeros(2)) - ref) < 1e-8
    theta, c = 1.1, -0.3 + 0.2j
    w = sp.exp(sp.I * theta) * (x + sp.I * y) * (1 + c * (x**2 + y**2))
    jac = _jac_of([sp.re(w), sp.im(w)], (x, y))
    assert abs(codim2.normal_form_coefficient("NS", jac, np.zeros(2)) - 2 * c.real) < 1e-8


# ---- period doubling: its coefficient, and the generalized period doubling ----------------

@pytest.fixture(scope="module")
def shear_pd():
    """The origin of the kicked shear with ``g2 = 1`` followed down in ``g1`` through its
    period doubling."""
    model = shear(g1=-10.0, g2=1.0)
    br = pwsdyn.continue_orbit(model, _orbit(model, [0.01, 0.01]), "g1", span=(-20, -5),
                               ds=-0.5)
    return model, br


@pytest.mark.slow   # ~30-50 s: among the long checks, run by CI
def test_period_doubling_reports_its_coefficient(shear_pd, tmp_path):
    _, br = shear_pd
    pd = br.special("PD")
    assert len(pd) == 1
    assert abs(pd[0].value - g1_period_doubling(g2=1.0)) < 1e-8
    c = flip_coefficient(g1=pd[0].value, g2=1.0)
    assert c > 0 and abs(pd[0].point.data["coefficient"] - c) < 1e-7
    assert pd[0].point.data["criticality"] == "supercritical"
    # the branch file keeps the coefficient and the criticality
    br.save(tmp_path / "pd.nc")
    back = pwsdyn.load_branch(tmp_path / "pd.nc").special("PD")[0].point.data
    assert back["coefficient"] == pd[0].point.data["coefficient"]
    assert back["criticality"] == "supercritical"


def test_generalized_period_doubling_on_a_period_doubling_curve(shear_pd):
    """c = g2^2 c2 + g3 c3 with c2, c3 > 0 at the period doubling: along the curve in
    ``(g3, g1)`` (``g1`` stays on the period doubling: the multipliers do not depend on
    ``g3``) the coefficient vanishes at ``g3 = -c2 / c3``."""
    model, br = shear_pd
    cur = pwsdyn.continue_bifurcation(model, br.special("PD")[0], ("g3", "g1"),
                                      span=(-0.5, 0.1), ds=-0.05, max_points=30)
    g1_pd = g1_period_doubling(g2=1.0)
    c2 = flip_coefficient(g1=g1_pd, g2=1.0)
    c3 = flip_coefficient(g1=g1_pd, g3=1.0)
    g3_gpd = -c2 / c3
    gpd = cur.special("GPD")
    assert len(gpd) == 1, cur.special_points
    assert abs(gpd[0].value - g3_gpd) < 1e-7
    assert abs(cur.values_of("g1")[gpd[0].index] - g1_pd) < 1e-9
    assert gpd[0].point.data["meets"] == ("PD",)
    # supercritical before it, subcritical after
    i = gpd[0].index
    assert cur.points[i - 1].data["coefficient"] > 0 > cur.points[i + 1].data["coefficient"]


# ---- resonances on a Neimark-Sacker curve ---------------------------------------------------

def _g1_where_trace(tr, **p):
    # tr M is affine in g1 (and det M = 1 on the curve k = -m)
    return brentq(lambda g: np.trace(map_jacobian(g1=g, **p)) - tr, -40.0, -1.0, xtol=1e-15)


def test_resonances_on_a_neimark_sacker_curve(tmp_path):
    """The origin with ``m = 0.1`` followed in ``k``: Neimark-Sacker at ``k = -m``
    (``det M = exp(-(k + m) / 2)``). Its curve in ``(g1, k)`` is ``k = -m``; along it
    ``tr M = 2 cos(theta)`` passes 0 (1:4), -1 (1:3) and -2 (1:2), where the pair becomes a real
    pair ``mu, 1/mu`` (neutral saddles): the curve ends there."""
    model = shear(g1=-6.0, g3=1.0)
    br = pwsdyn.continue_orbit(model, _orbit(model, [0.01, 0.01]), "k", span=(-0.3, 0.2),
                               ds=-0.05)
    ns = br.special("NS")
    assert len(ns) == 1 and abs(ns[0].value + M_DAMP) < 1e-9
    cur = pwsdyn.continue_bifurcation(model, ns[0], ("g1", "k"), span=(-25.0, -5.0), ds=-0.2,
                                      max_points=200)
    kinds = [s.kind for s in cur.special_points]
    assert kinds[-3:] == ["R4", "R3", "R2"], cur.special_points
    for kind, tr in (("R4", 0.0), ("R3", -1.0), ("R2", -2.0)):
        sp_ = cur.special(kind)[0]
        ref = _g1_where_trace(tr, k=-M_DAMP, g3=1.0)
        assert abs(sp_.value - ref) < 1e-7, (kind, sp_.value, ref)
        assert abs(cur.values_of("k")[sp_.index] + M_DAMP) < 1e-9
    assert "R2" in cur.stop_reason
    assert cur.special("R2")[0].point.data["meets"] == ("NS", "PD")
    assert np.allclose(cur.special("R2")[0].multipliers, -1.0, atol=1e-4)
    # the file keeps the kinds and their test functions
    back = pwsdyn.load_branch(cur.save(tmp_path / "ns.nc"))
    assert [s.kind for s in back.special_points] == kinds
    assert np.allclose([p.tests["R3"] for p in back.points],
                       [p.tests["R3"] for p in cur.points], rtol=0, atol=0)


def test_neimark_sacker_coefficient_and_chenciner_point():
    """With ``k = -m`` and ``k2 = 0`` the map is area-preserving (each phase's Jacobian has a
    constant determinant), so its Neimark-Sacker coefficient vanishes; ``k2 x^2 y`` is
    cubic, so ``d`` is linear in ``k2``: the Chenciner point of the curve in ``(k2, k)`` is
    ``k2 = 0``. At ``k2 = 0.5`` the coefficient against the closed-form map's."""
    model = shear(g1=-6.0, g2=1.0, k2=0.5)
    br = pwsdyn.continue_orbit(model, _orbit(model, [0.01, 0.01]), "k", span=(-0.3, 0.2),
                               ds=-0.05)
    ns = br.special("NS")
    assert len(ns) == 1
    d = ns_coefficient(g1=-6.0, g2=1.0, k2=0.5, k=ns[0].value)
    assert d < 0 and abs(ns[0].point.data["coefficient"] - d) < 1e-7
    assert ns[0].point.data["criticality"] == "supercritical"
    cur = pwsdyn.continue_bifurcation(model, ns[0], ("k2", "k"), span=(-0.5, 1.0), ds=-0.05,
                                      max_points=40)
    ch = cur.special("CH")
    assert len(ch) == 1, cur.special_points
    assert abs(ch[0].value) < 1e-7 and abs(cur.values_of("k")[ch[0].index] + M_DAMP) < 1e-9
    assert ch[0].point.data["meets"] == ("NS",)


# ---- the cusp on a fold curve ---------------------------------------------------------------

def test_cusp_on_a_fold_curve():
    """``G = g0 + g1 x + x^3``. A fixed point shears by ``y (1 - e^{-m/2}) / m`` and is damped
    back by ``e^{-m/2}``, so ``y`` after the first quarter is ``m x``; the relaxations then
    give ``G(x) = k m x``: the fixed points are the roots of ``g0 + (g1 - k m) x + x^3``, folds
    where also ``g1 - k m + 3 x^2 = 0``, i.e. ``x* = s``, ``g1 = k m - 3 s^2``, ``g0 = 2 s^3``;
    the fold coefficient is ``6 s`` times a positive factor, zero at the cusp
    ``(g1, g0) = (k m, 0)``."""
    k, m = 0.2, M_DAMP
    model = shear(g1=-0.3, g3=1.0, k=k, m=m)
    br = pwsdyn.continue_orbit(model, _orbit(model, [math.sqrt(0.3), 0.0]), "g0",
                               span=(-0.2, 0.2), ds=0.01)
    s_fold = math.sqrt((0.3 + k * m) / 3)
    lp = br.special("LP")
    assert len(lp) == 2
    assert sorted(abs(p.value - 2 * s_fold**3) for p in lp)[0] < 1e-8
    start = min(lp, key=lambda p: abs(p.value - 2 * s_fold**3))
    cur = pwsdyn.continue_bifurcation(model, start, ("g1", "g0"), span=(-0.5, 0.5), ds=0.02,
                                      max_points=60)
    g1s, g0s = cur.values, cur.values_of("g0")
    s = cur.states[:, 0]
    assert np.allclose(g1s, k * m - 3 * s**2, atol=1e-9)
    assert np.allclose(g0s, 2 * s**3, atol=1e-9)
    cp = cur.special("CP")
    assert len(cp) == 1, cur.special_points
    assert abs(cp[0].value - k * m) < 1e-7 and abs(cur.values_of("g0")[cp[0].index]) < 1e-7
    assert abs(cp[0].state[0]) < 1e-6
    assert cp[0].point.data["meets"] == ("LP",)


# ---- a DIB on a fold curve ------------------------------------------------------------------

def _flight_velocities(A, z0, zp, t0, T, n=800):
    """Sample times inside a flight and the velocity there (the homogeneous part stepped by
    ``expm(A dt)``), where the sign changes of the velocity are bracketed."""
    ts = t0 + np.linspace(0, T, n + 1)
    step = expm(A * (T / n))
    zh, vs = z0.copy(), []
    for t in ts:
        vs.append(zh[1] + zp(t)[1])
        zh = step @ zh
    return ts[1:-1], np.array(vs[1:-1])


def _fold_orbit_max(sigma, side):
    """A fold of the impact oscillator's one-impact orbits at ``sigma`` (the discriminant of
    the impact-velocity quadratic vanishes, tests/_orbit_cases.py; near ``omega = 2`` it has
    two zeros, ``side`` -1 the lower and +1 the upper, which merge where the fold curve turns
    back in ``sigma``) and the largest interior maximum of ``x`` over its free flight minus
    ``sigma`` (zero: the flight grazes the wall)."""
    disc = lambda om: io_one_impact(om, 1, sigma=sigma)[3]  # noqa: E731
    w_min = minimize_scalar(disc, bounds=(1.9, 2.2), method="bounded",
                            options={"xatol": 1e-12}).x
    w = brentq(disc, *((1.9, w_min) if side < 0 else (w_min, 2.3)), xtol=1e-15)
    v, t0, _, _ = io_one_impact(w, 1, sigma=sigma)
    eps = IO["eps"]
    A = np.array([[0.0, 1.0], [-1.0, -eps]])
    X, Y = np.linalg.solve(np.array([[1 - w**2, -eps * w], [eps * w, 1 - w**2]]), [1.0, 0.0])

    def zp(t):
        return np.array([X * np.sin(w * t) + Y * np.cos(w * t),
                         w * (X * np.cos(w * t) - Y * np.sin(w * t))])

    z0 = np.array([sigma, -IO["r"] * v]) - zp(t0)

    def z(t):
        return expm(A * (t - t0)) @ z0 + zp(t)

    T = 2 * np.pi / w
    ts, vs = _flight_velocities(A, z0, zp, t0, T)
    best = -np.inf
    for i in np.nonzero((vs[:-1] > 0) & (vs[1:] <= 0))[0]:
        tm = brentq(lambda t: z(t)[1], ts[i], ts[i + 1], xtol=1e-15)
        best = max(best, z(tm)[0])
    return w, best - sigma


@pytest.fixture(scope="module")
def io_fold_curve():
    down = pwsdyn.continue_orbit("impact-oscillator", io_orbit("stable"), "omega",
                                 span=(1.9, 3.2), ds=-0.05)
    return pwsdyn.continue_bifurcation("impact-oscillator", down.special("LP")[0],
                                       ("sigma", "omega"), span=(-0.8, -0.2), ds=0.02,
                                       ds_max=0.05, max_points=55)


def test_a_fold_curve_meets_a_graze(io_fold_curve):
    """Up in ``sigma`` the fold orbit's free flight reaches the wall in its interior (the
    ``GR`` monitor of segment 0): the fold curve meets the grazing curve there."""
    cur = io_fold_curve
    gr = cur.special("GR")
    assert gr, cur.special_points
    w_gr = cur.values_of("omega")[gr[0].index]
    side = -1 if w_gr < minimize_scalar(
        lambda om: io_one_impact(om, 1, sigma=gr[0].value)[3], bounds=(1.9, 2.2),
        method="bounded").x else 1
    sig_ref = brentq(lambda s: _fold_orbit_max(s, side)[1], gr[0].value - 1e-4,
                     gr[0].value + 1e-4, xtol=1e-15)
    w_ref = _fold_orbit_max(sig_ref, side)[0]
    assert abs(gr[0].value - sig_ref) < 1e-7
    assert abs(w_gr - w_ref) < 1e-7
    assert gr[0].key == "GR/impact/0"
    assert gr[0].point.data["meets"] == ("LP", "GR")
    # past it no codimension-two point of the fold is reported: the model's map there is not
    # the orbit's (its flight passes through the wall)
    assert not [s for s in cur.special_points if s.kind in ("CP", "LPPD", "LPNS")]


def _one_impact_max(sigma, omega):
    """Over the two one-impact orbits at ``(sigma, omega)``: the smallest distance of the
    largest interior maximum of ``x`` over the flight from ``sigma``."""
    eps = IO["eps"]
    A = np.array([[0.0, 1.0], [-1.0, -eps]])
    X, Y = np.linalg.solve(np.array([[1 - omega**2, -eps * omega],
                                     [eps * omega, 1 - omega**2]]), [1.0, 0.0])
    T = 2 * np.pi / omega
    out = np.inf
    for root in (1, -1):
        v, t0, _, _ = io_one_impact(omega, root, sigma=sigma)
        zp = lambda t: np.array([X * np.sin(omega * t) + Y * np.cos(omega * t),  # noqa: E731
                                 omega * (X * np.cos(omega * t) - Y * np.sin(omega * t))])
        z0 = np.array([sigma, -IO["r"] * v]) - zp(t0)
        z = lambda t: expm(A * (t - t0)) @ z0 + zp(t)  # noqa: E731
        ts, vs = _flight_velocities(A, z0, zp, t0, T)
        for i in np.nonzero((vs[:-1] > 0) & (vs[1:] <= 0))[0]:
            tm = brentq(lambda t: z(t)[1], ts[i], ts[i + 1], xtol=1e-15)
            out = min(out, abs(z(tm)[0] - sigma))
    return out


def test_the_grazing_curve_starts_where_it_meets_the_fold_curve(io_fold_curve):
    """``curve_start`` turns the ``GR`` point of the fold curve into the start of the grazing
    curve; each of its points is a one-impact orbit whose flight touches the wall."""
    from pwsdyn.continuation.problems import curve_start

    gr = io_fold_curve.special("GR")[0]
    start = curve_start(gr, "GR")
    assert start.kind == "GR" and start.key == "GR/impact/0"
    graze = pwsdyn.continue_bifurcation("impact-oscillator", start, ("sigma", "omega"),
                                        span=(-0.5, -0.2), ds=-0.01, max_points=8)
    assert graze.curve == "GR" and len(graze) >= 5
    assert np.ptp(graze.values) > 0.01
    # (the start, the fold itself, is checked above: there the closed form's velocity is the
    # square root of a discriminant that is zero, and its round-off 1e-6)
    for s_, w in zip(graze.values[1:], graze.values_of("omega")[1:]):
        assert _one_impact_max(s_, w) < 1e-7
    with pytest.raises(pwsdyn.ArgumentError, match="no PD curve"):
        curve_start(gr, "PD")


# ---- round-off is not a zero ----------------------------------------------------------------

@pytest.fixture(scope="module")
def conservative_orbit():
    """Without damping and with elastic impacts (``eps = 0``, ``r = 1``) the one-impact orbit
    on the larger root of the impact-velocity quadratic (tests/_orbit_cases.py) has a complex
    pair of multipliers on the unit circle (the impact map preserves area)."""
    params = dict(IO, eps=0.0, r=1.0)
    w, sig = IO["omega"], IO["sigma"]
    v, t0, M, _ = io_one_impact(w, 1, eps=0.0, r=1.0)
    mu = np.linalg.eigvals(M)
    assert np.allclose(np.abs(mu), 1.0, atol=1e-12) and np.all(np.abs(mu.imag) > 0.5)
    T = 2 * np.pi / w
    cf = dict(v=v, t0=t0, T=T, X=1.0 / (1 - w**2), Y=0.0,
              A=np.array([[0.0, 1.0], [-1.0, 0.0]]))
    t = t0 + 0.3 * T
    return pwsdyn.find_periodic_orbit("impact-oscillator", closed_form_state(cf, sig, 1.0, t),
                                      params=params, t0=t), params


@pytest.mark.parametrize("ds", [0.005, 0.02, 0.04])
def test_conservative_orbit_reports_no_neimark_sacker_points(conservative_orbit, ds):
    """Along the conservative branch in ``omega`` the Neimark-Sacker test function
    ``det M - 1`` is round-off of either sign: no point is reported, whatever the step."""
    orb, params = conservative_orbit
    assert np.allclose(np.abs(orb.multipliers), 1.0, atol=1e-9)
    br = pwsdyn.continue_orbit("impact-oscillator", orb, "omega",
                               span=(IO["omega"] - 0.2, IO["omega"] + 0.2), ds=ds)
    assert len(br) > 4
    assert np.allclose(np.abs(np.concatenate([p.data["multipliers"] for p in br.points])),
                       1.0, atol=1e-8)
    assert not br.special("NS"), br.special_points
