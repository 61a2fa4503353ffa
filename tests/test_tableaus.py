"""The Runge-Kutta tableaus checked against the theory they come from, not against another
library: Butcher's order conditions on rooted trees, the row-sum condition, and the order of
the dense output measured on a smooth problem."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest

import pwsdyn
from pwsdyn.integrate.tableaus import DOP853, METHODS, RK45


# --------------------------------------------------------------------------------------
# rooted trees (Butcher; Hairer, Norsett & Wanner, Solving ODEs I, section II.2)
# --------------------------------------------------------------------------------------

@lru_cache(maxsize=None)
def trees(order):
    """All rooted trees with ``order`` vertices, each a sorted tuple of its subtrees (the
    single vertex is ``()``)."""
    if order == 1:
        return ((),)
    out = set()
    for children in _forests(order - 1, order - 1):
        out.add(tuple(sorted(children)))
    return tuple(sorted(out))


def _forests(total, largest):
    """Multisets of trees with ``total`` vertices in all, as non-increasing lists by size."""
    if total == 0:
        yield []
        return
    for size in range(min(total, largest), 0, -1):
        for t in trees(size):
            for rest in _forests(total - size, size):
                # canonical order inside equal sizes avoids most duplicates; the set removes
                # the rest
                yield [t] + rest


def _order(t):
    return 1 + sum(_order(c) for c in t)


def _gamma(t):
    """The density gamma(t) = |t| prod gamma(children)."""
    g = _order(t)
    for c in t:
        g *= _gamma(c)
    return g


def _phi(A, c, t):
    """The stage vector of the elementary weight: Phi_i(()) = 1, Phi_i([t1..tm]) =
    prod_k (A Phi(t_k))_i."""
    v = np.ones(A.shape[0])
    for child in t:
        v = v * (A @ _phi(A, c, child))
    return v


def test_tree_counts_are_the_known_sequence():
    # number of rooted trees with n vertices (OEIS A000081)
    assert [len(trees(n)) for n in range(1, 9)] == [1, 1, 2, 4, 9, 20, 48, 115]


def _max_order_defect(A, b, order):
    worst = 0.0
    for q in range(1, order + 1):
        for t in trees(q):
            worst = max(worst, abs(b @ _phi(A, None, t) - 1.0 / _gamma(t)))
    return worst


def _defect_of_order(A, b, q):
    return max(abs(b @ _phi(A, None, t) - 1.0 / _gamma(t)) for t in trees(q))


def test_rk45_weights_have_order_5_and_the_embedded_order_4():
    s = RK45.n_stages
    A = RK45.A[: s + 1, : s + 1]          # the FSAL stage takes part in the embedded weights
    b = np.append(RK45.B, 0.0)
    assert _max_order_defect(A, b, 5) < 1e-14
    assert _defect_of_order(A, b, 6) > 1e-4   # not order 6
    bhat = b + RK45.E[0]                  # E = bhat - b
    assert _max_order_defect(A, bhat, 4) < 1e-14
    assert _defect_of_order(A, bhat, 5) > 1e-5


def test_dop853_weights_have_order_8():
    s = DOP853.n_stages
    A = DOP853.A[:s, :s]
    assert _max_order_defect(A, DOP853.B, 8) < 1e-14
    assert _defect_of_order(A, DOP853.B, 9) > 1e-8


def test_dop853_error_estimators():
    # E[0] are the weights of y8 - y5 (a 5th-order solution); E[1] of y8 - y3
    s = DOP853.n_stages
    A = DOP853.A[: s + 1, : s + 1]
    b = np.append(DOP853.B, 0.0)
    for row, order in ((0, 5), (1, 3)):
        assert _max_order_defect(A, b - DOP853.E[row], order) < 1e-13


@pytest.mark.parametrize("tab", [RK45, DOP853], ids=lambda t: t.name)
def test_row_sums_are_the_nodes(tab):
    np.testing.assert_allclose(tab.A.sum(axis=1), tab.C, rtol=0, atol=1e-14 * np.abs(tab.A).max())
    assert tab.C[tab.n_stages] == 1.0 and tab.C[0] == 0.0
    np.testing.assert_array_equal(tab.A[tab.n_stages, : tab.n_stages], tab.B)
    assert np.all(np.triu(tab.A) == 0.0)   # explicit


# --------------------------------------------------------------------------------------
# dense output, evaluated from the tableau alone
# --------------------------------------------------------------------------------------

def _pendulum(t, y):
    return np.array([y[1], -math.sin(y[0]) + 0.3 * math.cos(t)])


def _step(tab, f, t, y, h):
    K = np.zeros((tab.n_ext, y.size))
    for i in range(tab.n_ext):
        K[i] = f(t + tab.C[i] * h, y + h * (tab.A[i, :i] @ K[:i]))
    return K


def _dense(tab, y, h, K, theta):
    Q = K.T @ tab.P
    return y + h * sum(Q[:, k] * theta ** (k + 1) for k in range(Q.shape[1]))


def _reference(t0, y0, t1):
    # many small DOP853 steps from the same tableau: error far below the tested ones
    n = 400
    h = (t1 - t0) / n
    y = y0.copy()
    for i in range(n):
        K = _step(DOP853, _pendulum, t0 + i * h, y, h)
        y = y + h * (DOP853.B @ K[: DOP853.n_stages])
    return y


@pytest.mark.parametrize("tab", [RK45, DOP853], ids=lambda t: t.name)
def test_dense_output_ends(tab):
    y0 = np.array([0.7, -0.2])
    h = 0.3
    K = _step(tab, _pendulum, 0.0, y0, h)
    y1 = y0 + h * (tab.B @ K[: tab.n_stages])
    np.testing.assert_array_equal(_dense(tab, y0, h, K, 0.0), y0)
    # to rounding: the power form sums coefficients of size up to ~1e3 (DOP853)
    tol = 4 * np.finfo(float).eps * h * (np.abs(K).T @ np.abs(tab.P)).sum(axis=1)
    assert np.all(np.abs(_dense(tab, y0, h, K, 1.0) - y1) <= tol)


@pytest.mark.parametrize("tab", [RK45, DOP853], ids=lambda t: t.name)
def test_dense_output_order(tab):
    # local error of the interpolant at theta = 0.4 is O(h^(q+1)) for dense order q
    y0 = np.array([0.7, -0.2])
    errs = []
    for h in (0.4, 0.2, 0.1):
        K = _step(tab, _pendulum, 0.0, y0, h)
        exact = _reference(0.0, y0, 0.4 * h)
        errs.append(np.abs(_dense(tab, y0, h, K, 0.4) - exact).max())
    rates = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    q = tab.dense_order
    assert all(q + 1 - 0.4 < r < q + 1 + 0.8 for r in rates), (rates, errs)


# --------------------------------------------------------------------------------------
# the package's integrator with these tableaus
# --------------------------------------------------------------------------------------

HARMONIC = {"name": "harmonic", "states": ["x", "v"], "modes": {"m": {"x": "v", "v": "-x"}}}


@pytest.mark.parametrize("method, tol", [("RK45", 1e-10), ("DOP853", 1e-12)])
def test_harmonic_oscillator_over_ten_periods(method, tol):
    T = 20 * math.pi
    traj = pwsdyn.simulate(HARMONIC, [1.0, 0.0], (0, T), method=method, rtol=tol, atol=tol,
                           exact=False)
    ts = np.linspace(0, T, 1001)
    x = traj(ts)
    np.testing.assert_allclose(x[:, 0], np.cos(ts), rtol=0, atol=2000 * tol)
    np.testing.assert_allclose(x[:, 1], -np.sin(ts), rtol=0, atol=2000 * tol)


def test_method_names():
    assert METHODS["DOPRI5"] is RK45 and METHODS["DOP853"] is DOP853
