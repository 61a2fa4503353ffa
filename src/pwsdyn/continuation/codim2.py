r"""Codimension-two points on the curves of fold, period-doubling and Neimark-Sacker points of
periodic orbits, and the normal-form coefficients that decide them.

The orbit is a fixed point :math:`x^*` of its Poincaré map :math:`P` with Jacobian
:math:`A = P_x(x^*)` (the monodromy matrix); write

.. math::

    P(x^* + \xi) = x^* + A \xi + \tfrac12 B(\xi, \xi) + \tfrac16 C(\xi, \xi, \xi) + O(|\xi|^4).

The critical normal-form coefficients of the codimension-one bifurcations of a fixed point of
an :math:`n`-dimensional map (Kuznetsov, *Elements of Applied Bifurcation Theory*, 3rd ed.,
section 5.4, the center-manifold reduction of maps), with :math:`\langle p, q\rangle =
\bar p^T q`:

* fold, :math:`A q = q`, :math:`A^T p = p`, :math:`\langle p, q\rangle = 1`:
  :math:`a = \tfrac12 \langle p, B(q, q)\rangle`; its zero on a fold curve is the cusp ``CP``;
* flip, :math:`A q = -q`, :math:`A^T p = -p`:
  :math:`c = \tfrac16 \langle p, C(q,q,q)\rangle + \tfrac12 \langle p, B(q, (I - A)^{-1}
  B(q, q))\rangle` (the restricted map is :math:`\eta \mapsto -\eta + c \eta^3`, its second
  iterate :math:`\eta - 2 c \eta^3`: for :math:`c > 0` the period-two orbit born is stable in
  the critical direction, supercritical; :math:`c < 0` subcritical); its zero on a
  period-doubling curve is the generalized period doubling ``GPD``;
* Neimark-Sacker, :math:`A q = e^{i\theta} q`, :math:`A^T p = e^{-i\theta} p`,
  :math:`0 < \theta < \pi`:
  :math:`d = \tfrac12 \operatorname{Re}\{ e^{-i\theta} \langle p, C(q,q,\bar q) +
  2 B(q, (I - A)^{-1} B(q, \bar q)) + B(\bar q, (e^{2i\theta} I - A)^{-1} B(q, q))\rangle\}`
  (:math:`d < 0`: supercritical, a stable invariant circle); its zero on a Neimark-Sacker
  curve is the Chenciner point ``CH``.

The codimension-two points of fixed points of maps (Kuznetsov, chapter 9, section 9.1) are
located as zeros of test functions along the curves:

* fold curves: ``CP`` (:math:`a = 0`), fold-flip ``LPPD`` (:math:`\prod_i (\mu_i + 1)`),
  fold-Neimark-Sacker ``LPNS`` (:math:`\prod_{i<j} (\mu_i\mu_j - 1)` over the multipliers
  other than the critical one, confirmed by a complex pair on the unit circle);
* period-doubling curves: 1:2 resonance ``R2`` (:math:`\prod (\mu_i + 1)` over the multipliers
  other than the critical one), fold-flip ``LPPD`` (:math:`\prod_i (\mu_i - 1)`), ``GPD``
  (:math:`c = 0`);
* Neimark-Sacker curves, with :math:`\kappa = \operatorname{Re}(\mu_1 + \mu_2)/2` of the
  critical pair (:math:`\cos\theta` while it is complex; :math:`(\mu + 1/\mu)/2` once it is a
  real pair :math:`\mu, 1/\mu`, a neutral saddle): ``R1`` (:math:`\kappa - 1`), ``R2``
  (:math:`\kappa + 1`), ``R3`` (:math:`\kappa + 1/2`), ``R4`` (:math:`\kappa`), ``CH``
  (:math:`d = 0`). Past ``R1`` or ``R2`` (:math:`|\kappa| > 1`) the curve is one of neutral
  saddles, not of Neimark-Sacker points, and it ends there.

The derivatives :math:`B` and :math:`C` come from the exact Jacobian :math:`P_x` of the
Poincaré map (variational equations with the saltation matrices, thesis eq. 2.25,
:func:`pwsdyn.poincare_map`) at points :math:`x^* \pm h d`, :math:`x^* \pm 2 h d` along a
real direction :math:`d`: :math:`B(d, v) = D_d P_x\, v`, :math:`C(d, d, v) = D_d^2 P_x\, v`
by the fourth-order central stencils

.. math::

    D_d P_x \approx \frac{-J_2 + 8 J_1 - 8 J_{-1} + J_{-2}}{12 h},\qquad
    D_d^2 P_x \approx \frac{-J_2 + 16 J_1 - 30 J_0 + 16 J_{-1} - J_{-2}}{12 h^2},

:math:`J_k = P_x(x^* + k h d)`. A complex :math:`q = a + i b` needs the directions :math:`a`
and :math:`b` only: :math:`C(q,q,\bar q) = C(a,a,a) + C(b,b,a) + i\,(C(a,a,b) + C(b,b,b))`,
:math:`B(q, \bar q) = B(a,a) + B(b,b)`, :math:`B(q,q) = B(a,a) - B(b,b) + 2i B(a,b)`.
The truncation error is :math:`O(h^4)` and the round-off :math:`O(\epsilon_J / h^2)` with
:math:`\epsilon_J` the error of :math:`P_x` (the integrator's tolerance, 1e-12 by default):
:data:`FD_STEP` balances them at about 1e-8 relative for maps of unit scale.

Only orbits of forced models are analysed here (the stroboscopic map from the middle of the
orbit's first segment), and only where every point of the stencils follows the orbit's
sequence of events (the map is smooth there: not within about ``FD_STEP`` of a graze);
elsewhere the coefficients are NaN and their test functions are never located.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PwsdynError
from ..orbits.problem import SegmentFailed

#: Step of the finite differences of the Poincaré map's Jacobian, relative to ``1 + |x|``.
FD_STEP = 1e-2

#: Test functions of the codimension-two points on each kind of curve.
CURVE_TESTS = {
    "LP": ("CP", "LPPD", "LPNS"),
    "PD": ("R2", "LPPD", "GPD"),
    "NS": ("R1", "R2", "R3", "R4", "CH"),
}

#: The codimension-two kinds, and the curves of codimension-one bifurcations that meet there
#: (a special point of one of these kinds starts each of them).
CODIM2_MEETS = {
    "CP": ("LP",),
    "LPPD": ("LP", "PD"),
    "LPNS": ("LP", "NS"),
    "GPD": ("PD",),
    "R1": ("NS", "LP"),
    "R2": ("NS", "PD"),
    "R3": ("NS",),
    "R4": ("NS",),
    "CH": ("NS",),
}

#: Where a Neimark-Sacker curve ends: past these its critical pair is real (neutral saddles).
NS_ENDS = ("R1", "R2")


def _critical_index(mu, target) -> int:
    return int(np.argmin(np.abs(np.asarray(mu, dtype=complex) - target)))


def _rest(mu, target):
    mu = np.asarray(mu, dtype=complex)
    return np.delete(mu, _critical_index(mu, target))


def _pair_product(z) -> float:
    out = 1.0 + 0.0j
    for i in range(len(z)):
        for j in range(i + 1, len(z)):
            out *= z[i] * z[j] - 1.0
    return float(out.real)


def critical_pair(mu):
    """``(i, j)``: the pair of multipliers whose product is nearest 1 (the Neimark-Sacker
    pair, or the real pair ``mu, 1/mu`` of a neutral saddle)."""
    mu = np.asarray(mu, dtype=complex)
    best, out = math.inf, (0, 1)
    for i in range(mu.size):
        for j in range(i + 1, mu.size):
            d = abs(mu[i] * mu[j] - 1.0)
            if d < best:
                best, out = d, (i, j)
    return out


def ns_kappa(mu) -> float:
    r""":math:`\kappa = \operatorname{Re}(\mu_i + \mu_j)/2` of the critical pair."""
    mu = np.asarray(mu, dtype=complex)
    if mu.size < 2 or not np.all(np.isfinite(mu)):
        return math.nan
    i, j = critical_pair(mu)
    return float(0.5 * (mu[i] + mu[j]).real)


def curve_tests(curve: str, mu, coefficient: float) -> dict:
    """``{kind: value}`` of the codimension-two test functions on a ``curve`` (``"LP"``,
    ``"PD"`` or ``"NS"``) at a point with multipliers ``mu`` and normal-form coefficient
    ``coefficient`` (:func:`normal_form_coefficient`)."""
    mu = np.asarray(mu, dtype=complex)
    if mu.size == 0 or not np.all(np.isfinite(mu)):
        return {}
    if curve == "LP":
        return {"CP": float(coefficient), "LPPD": float(np.prod(mu + 1.0).real),
                "LPNS": _pair_product(_rest(mu, 1.0))}
    if curve == "PD":
        return {"R2": float(np.prod(_rest(mu, -1.0) + 1.0).real),
                "LPPD": float(np.prod(mu - 1.0).real), "GPD": float(coefficient)}
    if curve == "NS":
        k = ns_kappa(mu)
        return {"R1": k - 1.0, "R2": k + 1.0, "R3": k + 0.5, "R4": k,
                "CH": float(coefficient)}
    return {}


def multiplier_error(mu, rtol: float) -> float:
    """An estimate of the error of computed multipliers: the monodromy matrix's relative
    error, taken as ``1e3 rtol`` (the integrator's tolerance accumulated over the steps of a
    period), times its scale; a nondefective eigenvalue moves by as much."""
    mu = np.asarray(mu, dtype=complex)
    scale = max(1.0, float(np.max(np.abs(mu)))) if mu.size else 1.0
    return 1e3 * max(float(rtol), 1e-16) * scale


def function_error(fun, mu, delta: float) -> float:
    """Error of ``fun(mu)`` (a function of the multipliers) when each multiplier is off by
    ``delta``: the sum over the multipliers of the change that moving each one by ``delta``
    (along the real and the imaginary axis, its conjugate with it) causes."""
    mu = np.asarray(mu, dtype=complex)
    if mu.size == 0 or not np.all(np.isfinite(mu)):
        return 0.0
    f0 = fun(mu)
    err = 0.0
    for k in range(mu.size):
        for step in (delta, 1j * delta):
            m = mu.copy()
            m[k] += step
            # keep the set closed under conjugation (the functions are real on such sets)
            if abs(mu[k].imag) > 0:
                conj = [j for j in range(mu.size) if j != k and abs(mu[j] - np.conj(mu[k]))
                        <= 1e-12 * (1 + abs(mu[k]))]
                if conj:
                    m[conj[0]] = np.conj(m[k])
            elif step.imag:
                continue
            err += abs(fun(m) - f0)
    return float(err)


# ---- the Poincaré map and its derivatives ----------------------------------------------

class SectionMap:
    """The stroboscopic Poincaré map of a forced orbit, from the middle of its first segment:
    ``jacobian(x)`` is :math:`P_x(x)`, ``x`` the orbit's state there.

    Parameters
    ----------
    orbit_problem : OrbitProblem
    u, p : numpy.ndarray
        A solution of ``orbit_problem`` and its parameters.
    """

    def __init__(self, orbit_problem, u, p):
        op = orbit_problem
        if not op.forced:
            raise PwsdynError("the normal-form coefficients are computed for orbits of forced "
                              "models (a stroboscopic section)")
        fk = op.fields[0]
        if fk.kind != "mode":
            raise PwsdynError("the orbit's first segment is not in a mode of the model")
        t0, xs, Ts = op.unpack(np.asarray(u, dtype=float))
        p = np.asarray(p, dtype=float)
        opts = op.segment_options(p, variational=False)
        z = np.append(xs[0], p)
        tm = 0.5 * Ts[0]
        y, _, _ = op.flow(0, t0, z, tm, opts)
        self.model = op.model
        self.t = float(t0 + tm)
        self.x = np.asarray(y, dtype=float)[:op.n].copy()
        self.mode = op.model.mode_names[fk.index]
        self.params = op.param_dict(p)
        self.returns = int(op.periods)
        self.rtol = float(op.opts.get("rtol", 1e-12))
        self.options = {k: op.opts[k] for k in ("rtol", "atol", "method") if k in op.opts}
        self.options["max_step"] = opts["max_step"]
        self._events = None     # the events of the orbit's own run (the first evaluation)

    def jacobian(self, x) -> np.ndarray:
        from ..stability import poincare_map

        res = poincare_map(self.model, np.asarray(x, dtype=float), "stroboscopic",
                           params=self.params, t0=self.t, returns=self.returns,
                           mode=self.mode, dense=False, **self.options)
        # the derivatives hold where the map is smooth: every point of the stencil on the
        # orbit's sequence of events (near a graze a point of it crosses the surface)
        events = tuple((e.kind, e.name) for e in res.trajectory.events)
        if self._events is None:
            # the orbit itself: a fixed point of the model's map (an orbit continued on its
            # signature past a graze is not: the model's flow has left that signature)
            if not np.linalg.norm(res.x - x) <= 1e-6 * (1.0 + np.linalg.norm(x)):
                raise PwsdynError("the orbit is not a fixed point of the model's map")
            self._events = events
        elif events != self._events:
            raise PwsdynError("the map is not smooth near the orbit: a point of the finite "
                              "differences has another sequence of events")
        return np.asarray(res.jacobian, dtype=float)


def _directional(jac, x, A, d, h):
    """``(D_d P_x, D_d^2 P_x)`` by the fourth-order stencils of the module docstring."""
    J = {k: jac(x + k * h * d) for k in (-2, -1, 1, 2)}
    D1 = (-J[2] + 8 * J[1] - 8 * J[-1] + J[-2]) / (12 * h)
    D2 = (-J[2] + 16 * J[1] - 30 * A + 16 * J[-1] - J[-2]) / (12 * h * h)
    return D1, D2


def _eig_pair(A, target):
    """Right and left eigenvectors of ``A`` for its eigenvalue nearest ``target``,
    ``|q| = 1`` and ``conj(p) . q = 1``."""
    w, V = np.linalg.eig(A)
    i = int(np.argmin(np.abs(w - target)))
    q = V[:, i] / np.linalg.norm(V[:, i])
    wl, W = np.linalg.eig(A.T)
    j = int(np.argmin(np.abs(wl - np.conj(w[i]))))
    p = W[:, j]
    p = p / np.vdot(q, p)        # conj(p) . q = 1
    return w[i], q, p


def normal_form_coefficient(curve: str, jac, x, A=None, *, h: float | None = None,
                            orient=None, vector: bool = False):
    """The critical coefficient of the fold (``a``), flip (``c``) or Neimark-Sacker (``d``)
    normal form of the map whose Jacobian is ``jac(x)``, at its fixed point ``x`` (see the
    module docstring), with ``|q| = 1`` (a positive factor: the sign and the zero of the
    coefficient do not depend on the scale of ``q``). ``orient``: a vector the fold's ``q`` is
    turned towards (``a`` changes sign with ``q``); with ``vector``, ``(coefficient, q)``."""
    x = np.asarray(x, dtype=float)
    A = np.asarray(jac(x) if A is None else A, dtype=float)
    n = x.size
    if h is None:
        h = FD_STEP * (1.0 + float(np.max(np.abs(x))))
    I = np.eye(n)
    if curve == "LP":
        _, q, p = _eig_pair(A, 1.0)
        q, p = q.real, p.real
        if orient is not None and q @ orient < 0:
            q, p = -q, -p
        D1, _ = _directional(jac, x, A, q, h)
        a = float(0.5 * p @ (D1 @ q))
        return (a, q) if vector else a
    if curve == "PD":
        _, q, p = _eig_pair(A, -1.0)
        q, p = q.real, p.real
        D1, D2 = _directional(jac, x, A, q, h)
        Bqq = D1 @ q
        w = np.linalg.solve(I - A, Bqq)
        c = float(p @ (D2 @ q) / 6.0 + 0.5 * p @ (D1 @ w))
        return (c, q) if vector else c
    if curve == "NS":
        mu, q, p = _eig_pair(A, _upper_unit(A))
        theta = float(np.angle(mu))
        a, b = q.real, q.imag
        Da1, Da2 = _directional(jac, x, A, a, h)
        Db1, Db2 = _directional(jac, x, A, b, h)

        def B(v):            # B(q, v) for complex v
            return Da1 @ v + 1j * (Db1 @ v)

        def Bbar(v):         # B(conj q, v)
            return Da1 @ v - 1j * (Db1 @ v)

        Cqqq = (Da2 @ a + Db2 @ a) + 1j * (Da2 @ b + Db2 @ b)
        Bqqbar = Da1 @ a + Db1 @ b
        Bqq = Da1 @ a - Db1 @ b + 2j * (Da1 @ b)
        r = (Cqqq + 2 * B(np.linalg.solve(I - A, Bqqbar))
             + Bbar(np.linalg.solve(np.exp(2j * theta) * I - A, Bqq)))
        d = float(0.5 * (np.exp(-1j * theta) * np.vdot(p, r)).real)
        return (d, q) if vector else d
    raise ValueError(f"no normal form for curve {curve!r}")


def _upper_unit(A):
    """The eigenvalue of ``A`` in the upper half plane nearest the unit circle."""
    w = np.linalg.eigvals(A)
    up = w[w.imag > 0]
    if not up.size:
        raise PwsdynError("no complex pair: the point is not a Neimark-Sacker point")
    return up[int(np.argmin(np.abs(np.abs(up) - 1.0)))]


def orbit_coefficient(curve: str, orbit_problem, u, p, *, orient=None, vector=False):
    """:func:`normal_form_coefficient` of a periodic orbit (``u`` a solution of
    ``orbit_problem`` at ``p``) on its stroboscopic map; NaN where it cannot be computed (an
    autonomous model, a first segment that is not in a mode, a map that cannot be evaluated
    near the orbit); with ``vector``, ``(coefficient, q)`` (``q`` None where NaN)."""
    try:
        sm = SectionMap(orbit_problem, u, p)
        with np.errstate(all="ignore"):
            return normal_form_coefficient(curve, sm.jacobian, sm.x, orient=orient,
                                           vector=vector)
    except (PwsdynError, SegmentFailed, np.linalg.LinAlgError, ValueError, ArithmeticError):
        # (a segment that cannot be integrated from the orbit's section, a singular
        # (I - A): the coefficient is not defined there)
        return (math.nan, None) if vector else math.nan
