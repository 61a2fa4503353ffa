r"""What is continued: periodic orbits on a fixed signature, and equilibria of a mode.

Each problem gives the engine (:mod:`pwsdyn.continuation.engine`) :math:`F(u, \lambda)` with its
Jacobians, the data of a point and its own test functions:

* periodic orbits (:class:`OrbitBranchProblem`, on :class:`~pwsdyn.orbits.OrbitProblem`):
  Floquet multipliers :math:`\mu` (the trivial one of an autonomous orbit left out),
  stability, admissibility; period doubling ``PD``, :math:`\prod_i (\mu_i + 1)` (a real
  multiplier through -1; a complex pair contributes :math:`|\mu + 1|^2 > 0`) and
  Neimark-Sacker ``NS``, :math:`\prod_{i<j} (\mu_i \mu_j - 1)` (a pair with
  :math:`\mu_i \mu_j = 1`: a complex pair on the unit circle, or a real pair
  :math:`\mu, 1/\mu` -- a neutral saddle, which
  :meth:`~pwsdyn.continuation.OrbitBranchProblem.confirm` refuses); Kuznetsov, *Elements of Applied
  Bifurcation Theory*, 3rd ed., section 10.3.
* equilibria (:class:`EquilibriumProblem`): :math:`f(x, p) = 0` in one mode, eigenvalues of
  :math:`f_x`, Hopf ``HB``, :math:`\prod_{i<j} (\lambda_i + \lambda_j)` (the bialternate
  product; zero for a pair :math:`\pm i \omega`, and for a real pair :math:`\lambda, -\lambda`
  -- a neutral saddle, refused), Kuznetsov section 10.2.
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from ..newton import TrialRejected
from ..orbits.monitors import DIB_KINDS
from . import codim2
from .branch import Branch, SpecialPoint
from .engine import Point

#: A located zero is the bifurcation its test function stands for when the critical
#: multipliers (eigenvalues) are this close to the critical set.
CONFIRM_TOL = 1e-5


def _pair_product(z, op):
    """Real part of ``prod_{i<j} op(z_i, z_j)`` (real for a set closed under conjugation)."""
    out = 1.0 + 0.0j
    for i in range(len(z)):
        for j in range(i + 1, len(z)):
            out *= op(z[i], z[j])
    return float(out.real)


class OrbitBranchProblem:
    """A periodic orbit on a fixed signature, ``F(u, lam)`` with ``lam`` one parameter.

    Parameters
    ----------
    problem : OrbitProblem
        Built with ``parameters=[parameter]``.
    """

    kind = "orbit"

    def __init__(self, problem, *, monitors: bool = True):
        self.monitors = monitors
        if problem.q != 1:
            raise ArgumentError("an orbit branch continues one parameter: build the "
                                "OrbitProblem with parameters=[name]")
        self.orbit_problem = problem
        self.parameter = problem.parameters[0]
        self.size = problem.size
        self._last = None

    def _evaluation(self, u, lam, jacobian=True):
        from ..orbits.problem import SegmentFailed

        key = (np.asarray(u, dtype=float).tobytes(), float(lam))
        if self._last is not None and self._last[0] == key and (
                self._last[1].F_u is not None or not jacobian):
            return self._last[1]
        try:
            ev = self.orbit_problem.evaluate(np.asarray(u, dtype=float), np.array([lam]),
                                             jacobian=jacobian)
        except SegmentFailed as exc:
            raise TrialRejected(str(exc), "simulation") from None
        self._last = (key, ev)
        return ev

    def evaluate(self, u, lam):
        ev = self._evaluation(u, lam)
        return ev.F, ev.F_u, ev.F_p[:, 0]

    def analyse(self, u, lam, _evaluation=None) -> dict:
        prob = self.orbit_problem
        ev = self._evaluation(u, lam)
        # the multipliers build the monodromy matrix once (it used to be built a second time
        # only to see whether it is finite: the multipliers refuse a matrix that is not)
        try:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                mu = np.asarray(prob.multipliers(ev), dtype=complex)
        except ArgumentError:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                M = prob.monodromy(ev)
            if np.all(np.isfinite(M)):
                raise
            # an event of the orbit at zero normal velocity (the orbit grazes the surface:
            # its saltation matrix is infinite): no multipliers, and the point counts as
            # unstable; the test functions built on them are NaN (never a sign change)
            mu = np.full(self.orbit_problem.n - (0 if prob.forced else 1), np.nan + 0j)
        adm = prob.admissibility(u, np.array([lam]), evaluation=ev)
        stable = bool(mu.size == 0 or np.max(np.abs(mu)) < 1.0)
        out = {"multipliers": mu, "stable": stable, "admissible": bool(adm),
               "reason": adm.reason or "", "period": float(ev.period)}
        if self.monitors:
            out["monitors"] = prob.dib_monitors(u, np.array([lam]), evaluation=ev)
        return out

    def test_functions(self, data) -> dict:
        mu = data["multipliers"]
        out = {"PD": float(np.prod(mu + 1.0).real) if mu.size else 1.0}
        if mu.size >= 2:
            out["NS"] = _pair_product(mu, lambda a, b: a * b - 1.0)
        for key, mon in data.get("monitors", {}).items():
            out[key] = mon.value
        return out

    def confirm(self, kind, data) -> bool:
        mu = data["multipliers"]
        if kind == "PD":
            return bool(mu.size and np.min(np.abs(mu + 1.0)) < CONFIRM_TOL ** 0.5)
        if kind == "NS":
            cx = mu[np.abs(mu.imag) > CONFIRM_TOL]
            return bool(cx.size and np.min(np.abs(np.abs(cx) - 1.0)) < CONFIRM_TOL ** 0.5)
        return True

    def test_errors(self, data) -> dict:
        """``{kind: error}`` of the test functions of the multipliers: each multiplier off by
        :func:`~pwsdyn.continuation.codim2.multiplier_error`. A sign change of a test function
        whose values on both sides lie within this is round-off (an orbit of a conservative
        model keeps its multipliers on the unit circle), not a zero."""
        return _multiplier_test_errors(self.orbit_problem, data, {
            "PD": lambda m: float(np.prod(m + 1.0).real),
            "NS": lambda m: _pair_product(m, lambda a, b: a * b - 1.0)})

    def special_data(self, kind, u, lam, data) -> dict:
        """What a located point of ``kind`` carries besides its data: at a period doubling
        the flip coefficient ``c``, at a Neimark-Sacker point the coefficient ``d``
        (:mod:`pwsdyn.continuation.codim2`), with ``criticality`` (``"supercritical"``,
        ``"subcritical"``, or ``""`` where it is not computed)."""
        if kind not in ("PD", "NS"):
            return {}
        c = codim2.orbit_coefficient(kind, self.orbit_problem, u, np.array([lam]))
        return _criticality(kind, c)

    # ---- what a point is -------------------------------------------------------------
    def orbit(self, u, lam):
        """The :class:`~pwsdyn.PeriodicOrbit` at a point."""
        return self.orbit_problem.orbit(np.asarray(u, dtype=float), np.array([lam]))

    def section_state(self, u) -> np.ndarray:
        """The state at the start of segment 0 (after the last event of the period)."""
        _, xs, _ = self.orbit_problem.unpack(np.asarray(u, dtype=float))
        return np.asarray(xs[0], dtype=float)

    @property
    def state_names(self):
        return tuple(self.orbit_problem.model.states)


class _PointProblem:
    """What equilibria and pseudo-equilibria share: the model compiled with the continued
    parameter made a state (so that its ``f_x`` and ``h_x`` carry ``f_p`` and ``h_p`` in their
    last column, :func:`pwsdyn.model.augment.with_parameters_as_states`), eigenvalue test
    functions (Hopf) and their confirmation."""

    def __init__(self, model, parameter: str, params, caller: str):
        from ..model import compile_model
        from ..model.augment import with_parameters_as_states
        from ..model.spec import as_model

        model = as_model(model, kind="flow", caller=caller)
        if parameter not in model.parameters:
            raise ArgumentError(f"model {model.name!r} has no parameter {parameter!r}; its "
                                f"parameters: {list(model.parameters)}")
        self.model = model
        self.parameter = parameter
        self.params = dict(zip(model.parameters, model.parameter_vector(params)))
        ext = with_parameters_as_states(model, [parameter])
        self._cm = compile_model(ext)
        self._pv = ext.parameter_vector({k: v for k, v in self.params.items()
                                         if k != parameter})
        if not self._pv.size:
            self._pv = np.zeros(1)
        self._n = model.n_states

    @property
    def state_names(self):
        return tuple(self.model.states)

    def _call(self, which, idx, x, lam, size):
        """Generated quantity ``which`` (case ``idx``) at ``(x, lam)`` of the extended model."""
        z = np.append(np.asarray(x, dtype=float), lam)
        out = np.zeros(max(size, 2))
        self._cm.evaluate(which, idx, 0.0, z, self._pv, out)
        return out[:size]

    def _h(self, k, x, lam) -> float:
        from ..model.codegen import W_H

        return float(self._call(W_H, k, x, lam, 1)[0])

    @staticmethod
    def _hopf(ev) -> dict:
        return {"HB": _pair_product(ev, lambda a, b: a + b)} if ev.size >= 2 else {}

    def confirm(self, kind, data) -> bool:
        if kind == "HB":
            ev = data["eigenvalues"]
            cx = ev[np.abs(ev.imag) > CONFIRM_TOL]
            return bool(cx.size and np.min(np.abs(cx.real)) < CONFIRM_TOL ** 0.5)
        return True


class EquilibriumProblem(_PointProblem):
    """Equilibria ``f(x, p) = 0`` of one mode of an autonomous model, watched against the
    surfaces that bound the mode's region (boundary equilibrium bifurcations, ``BEB``)."""

    kind = "equilibrium"

    def __init__(self, model, parameter: str, *, params=None, mode=None):
        super().__init__(model, parameter, params, "continue_equilibrium()")
        model = self.model
        if model.forcing_period is not None:
            raise ArgumentError(f"model {model.name!r} is forced (time-periodic): it has "
                                f"periodic orbits, not equilibria; use continue_orbit")
        if mode is None:
            mode = model.mode_names[model.initial_mode]
        if mode not in model.mode_names:
            raise ArgumentError(f"model {model.name!r} has no mode {mode!r}; its modes: "
                                f"{list(model.mode_names)}")
        self.mode = mode
        self._mode = model.mode_names.index(mode)
        self.size = self._n

    def evaluate(self, u, lam):
        from ..model.codegen import W_F, W_FX

        n = self._n
        F = self._call(W_F, self._mode, u, lam, n + 1)[:n]
        J = self._call(W_FX, self._mode, u, lam, (n + 1) ** 2).reshape(n + 1, n + 1)
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(J))):
            raise TrialRejected("the vector field is not finite here", "nonfinite")
        return F, J[:n, :n], J[:n, n]

    def _region(self, u, lam) -> dict:
        """``{surface: signed h}`` of the surfaces bounding the mode's region: positive
        inside (above a switch for its upper mode, below for its lower one, the admissible
        side of an impact surface)."""
        m = self.model
        out = {}
        for sw in m.switches:
            if self._mode in (sw.above, sw.below):
                sign = 1.0 if self._mode == sw.above else -1.0
                out[m.surfaces[sw.surface].name] = sign * self._h(sw.surface, u, lam)
        for e in m.events:
            if e.kind == "impact" and self._mode in e.modes:
                out[m.surfaces[e.surface].name] = self._h(e.surface, u, lam)
        return out

    def analyse(self, u, lam, _evaluation=None) -> dict:
        _, A, _ = self.evaluate(u, lam)
        ev = np.linalg.eigvals(A)
        region = self._region(u, lam)
        out = [f"the equilibrium lies outside the region of mode {self.mode!r}: {name} = "
               f"{val:.3e} on the wrong side" for name, val in region.items() if val < 0]
        return {"eigenvalues": ev, "stable": bool(np.max(ev.real) < 0.0),
                "admissible": not out, "reason": out[0] if out else "", "region": region}

    def test_functions(self, data) -> dict:
        out = self._hopf(data["eigenvalues"])
        # boundary equilibrium bifurcation: the equilibrium reaches a surface of its region
        for name, val in data.get("region", {}).items():
            out[f"BEB/{name}"] = val
        return out

    def section_state(self, u):
        return np.asarray(u, dtype=float)


#: Test functions of the bifurcations of periodic orbits followed in two parameters.
#: (The DIB kinds' defining condition is a monitor of the orbit problem, not a test function
#: of the multipliers.)
CURVE_KINDS = ("LP", "PD", "NS") + DIB_KINDS


def _multiplier_test_errors(orbit_problem, data, funs) -> dict:
    mu = np.asarray(data.get("multipliers", ()), dtype=complex)
    if not mu.size or not np.all(np.isfinite(mu)):
        return {}
    delta = codim2.multiplier_error(mu, orbit_problem.opts.get("rtol", 1e-12))
    return {k: codim2.function_error(f, mu, delta) for k, f in funs.items()}


def _criticality(kind, c) -> dict:
    """The coefficient of a fold (``a``), flip (``c``) or Neimark-Sacker point (``d``) and,
    for the latter two, whether the bifurcation is super- or subcritical (flip: ``c > 0``
    supercritical; Neimark-Sacker: ``d < 0``)."""
    out = {"coefficient": float(c), "criticality": ""}
    # within the finite differences' error (about 1e-7 for a map of unit scale) the sign is
    # not known: a linear map's coefficient is zero
    if np.isfinite(c) and abs(c) > 1e-7 and kind in ("PD", "NS"):
        sup = c > 0 if kind == "PD" else c < 0
        out["criticality"] = "supercritical" if sup else "subcritical"
    return out


def orbit_test_function(kind: str, mu) -> float:
    r"""The defining function of a bifurcation of a periodic orbit from its multipliers.

    Of the nontrivial multipliers :math:`\mu`: ``LP`` :math:`\prod_i (\mu_i - 1)`, ``PD``
    :math:`\prod_i (\mu_i + 1)`, ``NS`` :math:`\prod_{i<j} (\mu_i \mu_j - 1)` (real for a set
    closed under conjugation)."""
    mu = np.asarray(mu, dtype=complex)
    if kind == "LP":
        return float(np.prod(mu - 1.0).real)
    if kind == "PD":
        return float(np.prod(mu + 1.0).real)
    if kind == "NS":
        return _pair_product(mu, lambda a, b: a * b - 1.0)
    raise ArgumentError(f"no curve of kind {kind!r}; kinds: {CURVE_KINDS}")


def curve_locate(curve: str) -> tuple:
    """The kinds located on a two-parameter curve of ``curve``: its codimension-two points
    (:data:`~pwsdyn.continuation.codim2.CURVE_TESTS`) and the discontinuity-induced
    bifurcations it meets."""
    return tuple(codim2.CURVE_TESTS.get(curve, ())) + DIB_KINDS


def curve_stop_at(curve: str) -> tuple:
    """Where a curve of ``curve`` ends: a Neimark-Sacker curve at its 1:1 and 1:2
    resonances, past which its points are neutral saddles."""
    return codim2.NS_ENDS if curve == "NS" else ()


class BifurcationCurveProblem:
    r"""A fold, period-doubling or Neimark-Sacker point of a periodic orbit in two parameters.

    Unknowns :math:`U = (u, p_2)`, continued parameter :math:`\lambda = p_1`, and

    .. math::

        G(U, \lambda) = \begin{pmatrix} F(u, p_1, p_2) \\ \psi(u, p_1, p_2) \end{pmatrix} = 0

    with :math:`F` the orbit problem and :math:`\psi` the bifurcation's test function of the
    multipliers (:func:`~pwsdyn.continuation.problems.orbit_test_function`) -- the orbit problem
    bordered by its defining condition, the augmented system of two-parameter continuation
    (Kuznetsov, section 10.3; the slides' "two-parameter continuation" of bifurcation curves).
    :math:`F_u`, :math:`F_p` are the problem's own; the row of :math:`\psi`'s derivatives is a
    central difference (its accuracy decides how fast Newton converges, not where: the curve is
    where :math:`\psi = 0`)."""

    kind = "orbit"

    def __init__(self, problem, curve: str, *, fd_step: float = 1e-6, key: str = ""):
        self._qref = None      # the fold's critical eigenvector at the last point (its sign)
        if curve in DIB_KINDS and not key.startswith(curve + "/"):
            raise ArgumentError(f"a {curve} curve needs the key of its monitor ({curve}/...)")
        self.key = key
        if curve not in CURVE_KINDS:
            raise ArgumentError(f"no two-parameter curve of kind {curve!r}; kinds: "
                                f"{CURVE_KINDS}")
        if problem.q != 2:
            raise ArgumentError("a bifurcation curve needs the OrbitProblem of two parameters")
        self.orbit_problem = problem
        self.curve = curve
        self.parameter, self.parameter2 = problem.parameters
        self.size = problem.size + 1
        self.fd_step = fd_step
        self._last = None

    def _ev(self, u, p, jacobian=True):
        from ..orbits.problem import SegmentFailed

        try:
            return self.orbit_problem.evaluate(u, p, jacobian=jacobian)
        except SegmentFailed as exc:
            raise TrialRejected(str(exc), "simulation") from None

    def _psi(self, u, p, ev) -> float:
        if self.curve in DIB_KINDS:
            # the grazing monitor itself: the segment's interior minimum of h (or an impact's
            # normal velocity) is zero on the grazing curve
            mon = self.orbit_problem.dib_monitors(u, p, evaluation=ev).get(self.key)
            if mon is None:
                raise TrialRejected(f"the graze {self.key} is no longer an interior minimum",
                                    "monitor")
            return mon.value
        return orbit_test_function(self.curve, self.orbit_problem.multipliers(ev))

    def evaluate(self, U, lam):
        U = np.asarray(U, dtype=float)
        u, p2 = U[:-1], float(U[-1])
        p = np.array([lam, p2])
        ev = self._ev(u, p)
        psi = self._psi(u, p, ev)
        # central differences of psi over (u, p1, p2)
        w = np.append(u, p)
        grad = np.zeros(w.size)
        for k in range(w.size):
            h = self.fd_step * (1.0 + abs(w[k]))
            wp, wm = w.copy(), w.copy()
            wp[k] += h
            wm[k] -= h
            fp = self._psi(wp[:-2], wp[-2:], self._ev(wp[:-2], wp[-2:], jacobian=False))
            fm = self._psi(wm[:-2], wm[-2:], self._ev(wm[:-2], wm[-2:], jacobian=False))
            grad[k] = (fp - fm) / (2 * h)
        n = u.size
        G = np.append(ev.F, psi)
        G_U = np.zeros((n + 1, n + 1))
        G_U[:n, :n] = ev.F_u
        G_U[:n, n] = ev.F_p[:, 1]
        G_U[n, :n] = grad[:n]
        G_U[n, n] = grad[n + 1]
        G_lam = np.append(ev.F_p[:, 0], grad[n])
        self._last = (U.tobytes(), float(lam), ev)
        return G, G_U, G_lam

    def analyse(self, U, lam, _evaluation=None) -> dict:
        U = np.asarray(U, dtype=float)
        if self._last is not None and self._last[0] == U.tobytes() and self._last[1] == lam:
            ev = self._last[2]
        else:
            ev = self._ev(U[:-1], np.array([lam, U[-1]]))
        prob = self.orbit_problem
        p = np.array([lam, U[-1]])
        mu = np.asarray(prob.multipliers(ev), dtype=complex)
        adm = prob.admissibility(U[:-1], p, evaluation=ev)
        out = {"multipliers": mu, "stable": bool(mu.size == 0 or np.max(np.abs(mu)) < 1.0),
               "admissible": bool(adm), "reason": adm.reason or "",
               "period": float(ev.period), self.parameter2: float(U[-1])}
        # the monitors of discontinuity-induced bifurcations: where one vanishes on the curve
        # the orbit there grazes (starts to slide, collides with a corner) -- the curve meets
        # that DIB's curve; on a DIB's own curve another DIB coinciding with it
        out["monitors"] = prob.dib_monitors(U[:-1], p, evaluation=ev)
        if self.curve in codim2.CURVE_TESTS:
            # of an admissible orbit only (past a graze the model's map is another one)
            coef, q = (codim2.orbit_coefficient(self.curve, prob, U[:-1], p,
                                                orient=self._qref, vector=True)
                       if adm else (np.nan, None))
            if q is not None and self.curve == "LP":
                self._qref = np.real(q)
            out["coefficient"] = coef
        return out

    def test_functions(self, data) -> dict:
        out = {}
        if self.curve in codim2.CURVE_TESTS:
            out.update(codim2.curve_tests(self.curve, data["multipliers"],
                                          data.get("coefficient", np.nan)))
        for key, mon in data.get("monitors", {}).items():
            if key != self.key:
                out[key] = mon.value
        return out

    def test_errors(self, data) -> dict:
        """``{kind: error}`` of the test functions (see
        :meth:`~pwsdyn.continuation.OrbitBranchProblem.test_errors`); the normal-form
        coefficients' error is that of their finite differences
        (:data:`~pwsdyn.continuation.codim2.FD_STEP`), about 1e-7 of their scale."""
        if self.curve not in codim2.CURVE_TESTS:
            return {}
        curve = self.curve
        out = _multiplier_test_errors(self.orbit_problem, data, {
            k: (lambda m, k=k: codim2.curve_tests(curve, m, 0.0)[k])
            for k in codim2.CURVE_TESTS[curve] if k not in ("CP", "GPD", "CH")})
        coef = data.get("coefficient", np.nan)
        if np.isfinite(coef):
            for k in ("CP", "GPD", "CH"):
                out[k] = 1e-7 * (1.0 + abs(coef))
        return out

    def confirm(self, kind, data) -> bool:
        mu = data["multipliers"]
        if kind == "LPNS":
            # a complex pair on the unit circle besides the multiplier 1 (not a neutral saddle)
            rest = np.delete(mu, int(np.argmin(np.abs(mu - 1.0))))
            cx = rest[np.abs(rest.imag) > CONFIRM_TOL]
            return bool(cx.size and np.min(np.abs(np.abs(cx) - 1.0)) < CONFIRM_TOL ** 0.5)
        if kind == "CH":
            return abs(codim2.ns_kappa(mu)) < 1.0
        return True

    def special_data(self, kind, U, lam, data) -> dict:
        """What a located codimension-two point carries to start the curves that meet there:
        ``meets``, their kinds (:data:`~pwsdyn.continuation.codim2.CODIM2_MEETS`; for a
        discontinuity-induced bifurcation on the curve, the curve's kind and that DIB's), and
        the normal-form coefficient of the curve with its ``criticality``."""
        kind0 = kind.split("/", 1)[0]
        meets = codim2.CODIM2_MEETS.get(kind0, (self.curve, kind0))
        out = {"meets": tuple(meets), "curve": self.curve}
        if self.curve in codim2.CURVE_TESTS:
            out.update(_criticality(self.curve, data.get("coefficient", np.nan)))
        return out

    def orbit(self, U, lam):
        U = np.asarray(U, dtype=float)
        return self.orbit_problem.orbit(U[:-1], np.array([lam, U[-1]]))

    def section_state(self, U) -> np.ndarray:
        _, xs, _ = self.orbit_problem.unpack(np.asarray(U, dtype=float)[:-1])
        return np.asarray(xs[0], dtype=float)

    @property
    def state_names(self):
        return tuple(self.orbit_problem.model.states)


def curve_start(special_point, curve: str):
    """A start for :func:`~pwsdyn.continue_bifurcation` of the curve of kind ``curve`` through
    a codimension-two point of a two-parameter curve, or a DIB located on one.

    Parameters
    ----------
    special_point : SpecialPoint
        A located point of a curve (:func:`~pwsdyn.continue_bifurcation`'s branch) whose
        ``point.data["meets"]`` names ``curve``: ``"PD"`` at a fold-flip ``LPPD``, ``"GR"`` at
        a graze on a fold curve, ...
    curve : str
        The kind of the curve to follow from there.

    Returns
    -------
    SpecialPoint
        A point of kind ``curve`` of a one-point orbit branch in the first of the curve's
        parameters, at the same orbit and parameter values; pass it to
        :func:`~pwsdyn.continue_bifurcation` with the two parameters. (Where the two curves'
        defining functions meet degenerately -- a period-doubling curve at a 1:2 resonance,
        whose function has a double zero there -- that continuation may not start.)
    """
    sp = special_point
    if not isinstance(sp, SpecialPoint) or not isinstance(sp.problem, BifurcationCurveProblem):
        raise ArgumentError("`special_point` must be a special point of a two-parameter curve")
    meets = tuple(sp.point.data.get("meets", ()))
    if curve not in meets:
        raise ArgumentError(f"no {curve} curve meets at this {sp.kind} point; the curves "
                            f"that meet there: {list(meets)}")
    prob = sp.problem
    U, lam = np.asarray(sp.point.u, dtype=float), float(sp.point.lam)
    op = prob.orbit_problem
    base = OrbitBranchProblem(op.replace(params=op.param_dict(np.array([lam, U[-1]])),
                                         parameters=[prob.parameter]))
    data = dict(sp.point.data)
    if curve not in DIB_KINDS:
        data["located"] = curve
    tangent = np.zeros(U.size)
    tangent[-1] = 1.0
    pt = Point(u=U[:-1].copy(), lam=lam, tangent=tangent, data=data,
               tests=dict(sp.point.tests), special=curve)
    br = Branch(base, [pt], stop_reason=f"a start at the {sp.kind} point of a {prob.curve} "
                f"curve", model=getattr(sp.branch, "model", None))
    return br.special_points[0]


class PseudoEquilibriumProblem(_PointProblem):
    """Pseudo-equilibria of a Filippov switching surface: points on ``h(x) = 0`` where the
    sliding vector field vanishes, followed in a parameter.

    Unknowns ``u = (x, alpha)``; with ``f_+`` (``f_-``) the field above (below) the surface::

        (1 - alpha) f_-(x) + alpha f_+(x) = 0,    h(x) = 0

    (``n + 1`` equations: Filippov's convex combination, thesis eq. 2.7, vanishing on the
    surface; Kuznetsov, Rinaldi & Gragnani, Int. J. Bifurcation and Chaos 13 (2003) 2157-2188,
    section 3). It is a solution of the Filippov system while ``0 <= alpha <= 1`` (the point
    lies in the sliding region); where ``alpha`` leaves ``[0, 1]`` it meets an equilibrium of
    one of the two modes (a boundary equilibrium), and the points beyond are reported not
    admissible. Stability: the eigenvalues of the sliding field's Jacobian on the tangent
    space of the surface (``alpha(x) = h_x f_- / h_x (f_- - f_+)``, by central differences),
    and Hopf points from them.
    """

    kind = "pseudo-equilibrium"

    def __init__(self, model, parameter: str, *, params=None, switch=None,
                 fd_step: float = 1e-7):
        super().__init__(model, parameter, params, "continue_equilibrium()")
        model = self.model
        sws = [s for s in model.switches if s.kind == "filippov"]
        if not sws:
            raise ArgumentError(f"model {model.name!r} has no Filippov switching surface")
        if switch is None:
            sw = sws[0]
        else:
            match = [s for s in sws if s.name == switch]
            if not match:
                raise ArgumentError(f"model {model.name!r} has no Filippov switch {switch!r}; "
                                    f"its switches: {[s.name for s in sws]}")
            sw = match[0]
        self.switch = sw.name
        self.mode = f"slide:{sw.name}"
        self._sw = sw
        self.size = self._n + 1
        self.fd_step = fd_step

    def _fields(self, x, lam):
        from ..model.codegen import W_F, W_FX, W_HX

        n, n1 = self._n, self._n + 1
        sw = self._sw
        fp = self._call(W_F, sw.above, x, lam, n1)[:n]
        fm = self._call(W_F, sw.below, x, lam, n1)[:n]
        Jp = self._call(W_FX, sw.above, x, lam, n1 * n1).reshape(n1, n1)[:n]
        Jm = self._call(W_FX, sw.below, x, lam, n1 * n1).reshape(n1, n1)[:n]
        h = self._h(sw.surface, x, lam)
        hx = self._call(W_HX, sw.surface, x, lam, n1)
        return fp, fm, Jp, Jm, h, hx

    def evaluate(self, u, lam):
        u = np.asarray(u, dtype=float)
        n = self._n
        x, a = u[:n], float(u[n])
        fp, fm, Jp, Jm, h, hx = self._fields(x, lam)
        F = np.append((1 - a) * fm + a * fp, h)
        F_u = np.zeros((n + 1, n + 1))
        F_u[:n, :n] = (1 - a) * Jm[:, :n] + a * Jp[:, :n]
        F_u[:n, n] = fp - fm
        F_u[n, :n] = hx[:n]
        F_lam = np.append((1 - a) * Jm[:, n] + a * Jp[:, n], hx[n])
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(F_u))):
            raise TrialRejected("the vector field is not finite here", "nonfinite")
        return F, F_u, F_lam

    def sliding_field(self, x, lam) -> np.ndarray:
        """Filippov's sliding field at ``x`` (``alpha`` from the fields, not an unknown)."""
        fp, fm, _, _, _, hx = self._fields(x, lam)
        g = hx[:self._n]
        den = g @ (fm - fp)
        a = (g @ fm) / den if den != 0 else 0.5
        return (1 - a) * fm + a * fp

    def analyse(self, u, lam, _evaluation=None) -> dict:
        u = np.asarray(u, dtype=float)
        n = self._n
        x, a = u[:n], float(u[n])
        _, _, _, _, _, hx = self._fields(x, lam)
        g = hx[:n]
        # orthonormal basis of the surface's tangent space
        _, _, Vt = np.linalg.svd(g[None, :])
        T = Vt[1:].T
        J = np.zeros((n, n))
        for k in range(n):
            h = self.fd_step * (1.0 + abs(x[k]))
            e = np.zeros(n)
            e[k] = h
            J[:, k] = (self.sliding_field(x + e, lam) - self.sliding_field(x - e, lam)) / (2 * h)
        ev = np.linalg.eigvals(T.T @ J @ T) if n > 1 else np.zeros(0)
        inside = -1e-12 <= a <= 1 + 1e-12
        reason = "" if inside else (f"alpha = {a:.6g} outside [0, 1]: the point is not in the "
                                    f"sliding region (past a boundary equilibrium)")
        return {"eigenvalues": ev, "alpha": a,
                "stable": bool(ev.size == 0 or np.max(ev.real) < 0.0),
                "admissible": bool(inside), "reason": reason}

    def test_functions(self, data) -> dict:
        out = self._hopf(data["eigenvalues"])
        # boundary equilibrium bifurcation: the pseudo-equilibrium leaves the sliding region
        # (alpha through 0 or 1) where it meets an equilibrium of the mode below or above
        a = data["alpha"]
        out["BEB/below"] = a
        out["BEB/above"] = 1.0 - a
        return out

    def section_state(self, u):
        return np.asarray(u, dtype=float)[:self._n]


def equilibrium_problem(model, parameter, *, params=None, mode=None):
    """The problem of equilibria of ``mode`` (a mode name), or of pseudo-equilibria of the
    switch ``name`` for ``mode = "slide:<name>"``."""
    if isinstance(mode, str) and mode.startswith("slide:"):
        return PseudoEquilibriumProblem(model, parameter, params=params,
                                        switch=mode.split(":", 1)[1])
    return EquilibriumProblem(model, parameter, params=params, mode=mode)
