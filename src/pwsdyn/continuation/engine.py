"""Pseudo-arclength continuation of ``F(u, lam) = 0``: one engine for every problem.

The branch is a curve ``X(s) = (u(s), lam(s))`` in ``R^(N+1)`` through solutions of ``N``
equations, parametrised by (pseudo-)arclength ``s`` (Keller's method; e.g. Allgower & Georg,
*Introduction to Numerical Continuation Methods*, SIAM 2003, ch. 2 and 6; Kuznetsov,
*Elements of Applied Bifurcation Theory*, 3rd ed. 2004, section 10.2; the slides' "Numerical
continuation"). From an accepted point ``X_k`` with unit tangent ``v_k``:

* predictor: ``X = X_k + ds v_k`` (tangent) or along the secant of the last two points;
* corrector: Newton on the bordered system ``F(X) = 0``, ``v_k . (X - X_k) - ds = 0`` with
  Jacobian ``[[F_u, F_lam], [v_k^T]]``, nonsingular at regular points and at folds;
* the new tangent solves ``[[F_u, F_lam], [v_k^T]] v = (0, 1)``, normalised; it keeps the
  direction of travel (``v . v_k > 0``);
* step size: shorter after a failed corrector or a turn of the tangent by more than
  ``max_angle``, longer after an easy one (few Newton iterations), within
  ``[ds_min, ds_max]``.

Test functions are evaluated at every point. Two are generic and computed here: the fold
(``LP``), where the tangent's ``lam`` component changes sign, and the branch point (``BP``),
where the determinant of the bordered Jacobian changes sign (it does not at a fold; Allgower &
Georg, section 8.1). A problem adds its own from its point data (period doubling and
Neimark-Sacker from Floquet multipliers, Hopf from eigenvalues). A sign change between two
points is located by the Illinois variant of regula falsi in the arclength, each trial a
corrected point on the hyperplane ``v_k . (X - X_k) = s``, to ``locate_tol`` in ``s`` (which
bounds the error in ``lam``, ``|d lam / ds| <= 1``). The located point joins the branch as a
point of its own, between the two that bracketed it, so it is reported once, whatever the step
size.

A problem is any object with

* ``size``: the number ``N`` of unknowns ``u``;
* ``evaluate(u, lam) -> (F, F_u, F_lam)``, raising :class:`~pwsdyn.newton.TrialRejected` where
  it cannot be evaluated;
* ``analyse(u, lam, evaluation) -> dict``: the data kept with a point (multipliers,
  ``stable``, ``admissible``, ...), reusing what ``evaluate`` returned last;
* ``test_functions(data) -> dict``: ``{kind: value}`` of its own test functions;
* ``confirm(kind, data) -> bool``: whether a located zero of ``kind`` is that bifurcation (a
  zero of the Neimark-Sacker function with a real pair of multipliers, a neutral saddle, is
  not);
* optionally ``test_errors(data) -> dict``: ``{kind: error}`` of its test functions' values; a
  sign change between two points whose values both lie within their error is not located;
* optionally ``special_data(kind, u, lam, data) -> dict``: what a located point of ``kind``
  carries besides its data (normal-form coefficients, the curves meeting there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ArgumentError, PwsdynError, Status
from ..newton import TrialRejected, newton
from ..orbits import SegmentFailed

#: What a trial step may raise where the problem cannot be evaluated: the model refusing a
#: predicted parameter (an :class:`~pwsdyn.ArgumentError` of its domain), a segment that
#: cannot be integrated, a singular linear system, an overflow. Each rejects the step (it is
#: retaken shorter): no failure inside a step ends the branch without its points.
STEP_FAILURES = (PwsdynError, TrialRejected, SegmentFailed, np.linalg.LinAlgError,
                 ArithmeticError, ValueError)


def _failure_text(exc) -> str:
    return f"{type(exc).__name__}: {getattr(exc, 'message', '') or exc}"


@dataclass(frozen=True)
class ContinuationSettings:
    """How a branch is followed (the algorithm; what is followed is the problem).

    Attributes
    ----------
    ds : float
        First step, in arclength of ``(u, lam)``. Its sign sets the direction: positive
        follows the parameter upwards at the start, negative downwards.
    ds_min, ds_max : float
        Bounds on ``|ds|``: below ``ds_min`` the branch stops (a point the corrector cannot
        pass: a singular or nonsmooth point).
    max_points : int
        Most points on the branch, the start and located special points included.
    max_arclength : float
        Most arclength.
    span : (float, float)
        The parameter's range; the branch ends on its boundary (the last point solved with
        the parameter fixed there).
    tol : float
        Corrector tolerance on ``max|F| / (1 + max|X|)``.
    max_iter : int
        Newton steps of one corrector.
    target_iter : int
        Newton steps aimed at: fewer lengthen the next step, more shorten it.
    max_angle : float
        Largest angle (radians) between consecutive tangents; a larger turn is retaken shorter.
    locate : tuple of str
        Kinds of special points detected and located (``"LP"``, ``"BP"`` and the problem's).
    locate_tol : float
        Arclength to which a special point is located.
    predictor : {'tangent', 'secant'}
    stop_at : tuple of str
        Kinds of special points at which the branch ends once located (the point is its
        last): a caller that switches to another problem there (a new signature after a
        graze) goes on from it.
    """

    ds: float = 0.02
    ds_min: float = 1e-7
    ds_max: float = 0.2
    max_points: int = 200
    max_arclength: float = math.inf
    span: tuple = (-math.inf, math.inf)
    tol: float = 1e-10
    max_iter: int = 10
    target_iter: int = 3
    max_angle: float = 0.35
    locate: tuple = ("LP", "BP", "PD", "NS", "HB", "GR", "GS", "SS", "CS", "AS", "CC", "BEB")
    locate_tol: float = 1e-11
    predictor: str = "tangent"
    stop_at: tuple = ()

    def __post_init__(self):
        from .. import _validate as V

        V.number("ds", self.ds)
        if self.ds == 0.0:
            raise ArgumentError("`ds` must be nonzero (its sign is the direction)")
        V.positive("ds_min", self.ds_min)
        V.positive("ds_max", self.ds_max)
        if not self.ds_min <= abs(self.ds) <= self.ds_max:
            raise ArgumentError(f"`ds` must satisfy ds_min <= |ds| <= ds_max, got ds={self.ds}, "
                                f"ds_min={self.ds_min}, ds_max={self.ds_max}")
        V.integer("max_points", self.max_points, lo=1)
        V.positive("max_arclength", self.max_arclength, allow_inf=True)
        lo, hi = _span(self.span)
        object.__setattr__(self, "span", (lo, hi))
        V.positive("tol", self.tol)
        V.integer("max_iter", self.max_iter, lo=1)
        V.integer("target_iter", self.target_iter, lo=1)
        V.positive("max_angle", self.max_angle)
        V.positive("locate_tol", self.locate_tol)
        V.choice("predictor", self.predictor, ("tangent", "secant"))
        for name in ("locate", "stop_at"):
            val = getattr(self, name)
            object.__setattr__(self, name, (val,) if isinstance(val, str) else tuple(val))


def _span(span):
    from .. import _validate as V

    if span is None:
        return (-math.inf, math.inf)
    try:
        lo, hi = span
    except (TypeError, ValueError):
        raise ArgumentError(f"`span` must be a pair (lo, hi), got {span!r}") from None
    lo = V.number("span[0]", lo, allow_inf=True)
    hi = V.number("span[1]", hi, allow_inf=True)
    if not lo < hi:
        raise ArgumentError(f"`span` must have lo < hi, got ({lo}, {hi})")
    return (float(lo), float(hi))


@dataclass
class Point:
    """One solution on a branch.

    Attributes
    ----------
    u : numpy.ndarray
    lam : float
        The continued parameter.
    tangent : numpy.ndarray
        Unit tangent of the branch in ``(u, lam)``, in the direction of travel.
    ds : float
        The step that reached the point (0 for the start).
    iterations : int
        Newton steps of its corrector.
    arclength : float
        Arclength from the start.
    data : dict
        What the problem reports (multipliers, stability, admissibility, ...).
    tests : dict
        Test-function values ``{kind: value}``.
    special : str
        ``""`` for a regular point, or the kind of special point located here (``"LP"``,
        ``"PD"``, ..., ``"EP"`` for an end point).
    signature_index : int
        Which problem of its branch the point solves (``Branch.problems``): a branch that
        switched to a new signature at a graze holds points of several.
    """

    u: np.ndarray
    lam: float
    tangent: np.ndarray
    ds: float = 0.0
    iterations: int = 0
    arclength: float = 0.0
    data: dict = field(default_factory=dict)
    tests: dict = field(default_factory=dict)
    special: str = ""
    signature_index: int = 0

    @property
    def X(self) -> np.ndarray:
        return np.append(self.u, self.lam)


class ContinuationError(ArgumentError):
    """A branch cannot be started (the start is not a solution, or the problem is singular
    there), or cannot go on past a discontinuity-induced bifurcation.

    Attributes
    ----------
    status : Status
        ``Status.START_FAILED`` or ``Status.SWITCH_FAILED``.
    """

    def __init__(self, message: str, status: Status = Status.START_FAILED):
        super().__init__(message)
        self.status = status


class Continuation:
    """Follows a branch of ``problem`` from ``(u0, lam0)``, a point at a time.

    Iterate over it (``for point in cont``) to take one step at a time -- each accepted point
    and each located special point is yielded -- or call :meth:`run`. ``points`` holds the
    branch so far, ``stop_reason`` why it ended (``stop_status`` the same as a
    :class:`~pwsdyn.Status` member).

    Parameters
    ----------
    problem : object
        See the module docstring.
    u0 : array_like
        A guess of the start (corrected at ``lam0`` before the first step).
    lam0 : float
    settings : ContinuationSettings
    tangent : array_like, optional
        The start's tangent (resuming a branch, or leaving a branch point along another
        branch); default from the Jacobian, pointing the way ``ds`` says.
    correct_start : bool
        Correct ``u0`` at fixed ``lam0`` first (Newton on ``F(u, lam0) = 0``).
    progress : bool
        A progress bar (points).
    arclength0 : float
        Arclength of the start (resuming a branch).
    start_kind : str
        The start is a special point of this kind (a branch switch starts at a ``BP``): it is
        marked so, and no zero of a test function is located in the first step.
    """

    def __init__(self, problem, u0, lam0: float, settings: ContinuationSettings | None = None,
                 *, tangent=None, correct_start: bool = True, progress: bool = False,
                 arclength0: float = 0.0, start_kind: str = ""):
        self.problem = problem
        self.settings = settings or ContinuationSettings()
        self.points: list[Point] = []
        self.stop_reason = ""
        self.stop_status: Status | None = None
        self._progress = progress
        self._bar = None
        self._started = False
        self._u0 = np.array(u0, dtype=float)
        self._lam0 = float(lam0)
        self._t0 = None if tangent is None else np.array(tangent, dtype=float)
        self._correct = correct_start
        self._s0 = float(arclength0)
        self._start_kind = start_kind
        self._ds = float(self.settings.ds)
        self._ev = None   # the last evaluation (F, F_u, F_lam) and where it was taken
        self.stop_point = None   # the special point of `stop_at` the branch ended at
        if self._u0.shape != (problem.size,):
            raise ArgumentError(f"the start has {self._u0.size} unknowns, the problem "
                                f"{problem.size}")

    # ------------------------------------------------------------------------------
    # evaluation
    # ------------------------------------------------------------------------------
    def _eval(self, X):
        X = np.asarray(X, dtype=float)
        # the last evaluation again (the corrector's last iterate is the point, its tangent
        # and its data): compared as numpy.array_equal does, without its wrapper's cost
        if self._ev is not None:
            X0 = self._ev[0]
            if X0.shape == X.shape and bool((X0 == X).all()):
                return self._ev[1]
        F, F_u, F_lam = self.problem.evaluate(X[:-1], float(X[-1]))
        out = (np.asarray(F, dtype=float), np.asarray(F_u, dtype=float),
               np.asarray(F_lam, dtype=float).reshape(-1))
        self._ev = (X.copy(), out)
        return out

    def _bordered(self, X, v):
        """``[[F_u, F_lam], [v^T]]`` at ``X``."""
        _, F_u, F_lam = self._eval(X)
        N = F_u.shape[0]
        B = np.empty((N + 1, N + 1))
        B[:N, :N] = F_u
        B[:N, N] = F_lam
        B[N] = v
        return B

    def _tangent(self, X, v_prev):
        """Unit tangent at ``X`` oriented along ``v_prev``: the solution of the bordered
        system with right-hand side ``(0, 1)``."""
        B = self._bordered(X, v_prev)
        rhs = np.zeros(B.shape[0])
        rhs[-1] = 1.0
        try:
            v = np.linalg.solve(B, rhs)
        except np.linalg.LinAlgError:
            v = _null_vector(B[:-1])
        if not np.all(np.isfinite(v)) or not np.any(v):
            v = _null_vector(B[:-1])
        v = v / np.linalg.norm(v)
        return v if v @ v_prev >= 0.0 else -v

    def _correct_on(self, Xp, v, c):
        """Newton on ``F(X) = 0``, ``v . X = c`` from ``Xp``: (X, iterations) or None."""
        def fun(X):
            F, _, _ = self._eval(X)
            if not np.isfinite(F).all():
                raise TrialRejected("the residual is not finite", "nonfinite")
            G = np.empty(F.size + 1)
            G[:-1] = F
            G[-1] = v @ X - c
            return G

        def jac(X):
            return self._bordered(X, v)

        res = newton(fun, Xp, jac=jac, tol=self.settings.tol, max_iter=self.settings.max_iter,
                     max_step_ratio=10.0, halvings=4,
                     # near a branch point the bordered Jacobian is nearly singular by nature
                     # (its located zero is the point): only a numerically singular one stops
                     singular_rtol=1e-14)
        if not res.converged:
            return None, res
        if res.iterations == 0:
            # the predictor already within tol (a short step, a branch where F is flat): one
            # Newton step all the same, so that a point is never a mere prediction
            X = res.x
            G = fun(X)
            dX = np.linalg.lstsq(jac(X), -G, rcond=None)[0]
            try:
                G1 = fun(X + dX)
            except STEP_FAILURES:
                return X, res
            if np.max(np.abs(G1)) <= np.max(np.abs(G)):
                res.x = X + dX
                res.iterations = 1
        return res.x, res

    # ------------------------------------------------------------------------------
    # the start
    # ------------------------------------------------------------------------------
    def _start(self):
        try:
            return self._start_point()
        except ContinuationError:
            raise
        except STEP_FAILURES as exc:
            raise ContinuationError(f"the start cannot be evaluated at the parameter value "
                                    f"{self._lam0:.10g}: {_failure_text(exc)}") from None

    def _start_point(self):
        st = self.settings
        u = self._u0
        lam = self._lam0
        if self._correct:
            def fun(uu):
                F, _, _ = self.problem.evaluate(uu, lam)
                return F

            def jac(uu):
                return self.problem.evaluate(uu, lam)[1]

            res = newton(fun, u, jac=jac, tol=st.tol, max_iter=30)
            if not res.converged:
                raise ContinuationError(f"the start is not a solution at the parameter value "
                                        f"{lam:.10g}: Newton {res.reason} ({res.message})")
            u = res.x
        X = np.append(u, lam)
        F, F_u, F_lam = self._eval(X)
        if self._t0 is not None:
            # as given: at a branch point the bordered system is singular and would not
            # single out the direction asked for
            v = self._t0 / np.linalg.norm(self._t0)
        else:
            # the tangent with lam increasing, then turned by the sign of ds
            try:
                w = np.linalg.solve(F_u, -F_lam)
                v = np.append(w, 1.0)
            except np.linalg.LinAlgError:
                v = _null_vector(np.column_stack([F_u, F_lam]))
            if not np.all(np.isfinite(v)):
                v = _null_vector(np.column_stack([F_u, F_lam]))
            v = v / np.linalg.norm(v)
            if v[-1] < 0.0:
                v = -v
            if self.settings.ds < 0.0:
                v = -v
        self._ds = abs(self._ds)
        return self._point(X, v, ds=0.0, iterations=0, arclength=self._s0,
                           special=self._start_kind)

    def _point(self, X, v, *, ds, iterations, arclength, special=""):
        data = dict(self.problem.analyse(X[:-1], float(X[-1]), self._eval(X)))
        tests = self._tests(X, v, data)
        return Point(u=X[:-1].copy(), lam=float(X[-1]), tangent=v.copy(), ds=float(ds),
                     iterations=int(iterations), arclength=float(arclength), data=data,
                     tests=tests, special=special)

    def _tests(self, X, v, data):
        want = self.settings.locate
        tests = {}
        if "LP" in want:
            tests["LP"] = float(v[-1])
        if "BP" in want:
            B = self._bordered(X, v)
            sign, logdet = np.linalg.slogdet(B)
            # scaled by the norm of the rows, so that the value is comparable along the branch
            scale = np.sum(np.log(np.linalg.norm(B, axis=1) + 1e-300))
            tests["BP"] = float(sign * math.exp(min(logdet - scale, 700.0)))
        for k, val in self.problem.test_functions(data).items():
            # a key "KIND/detail" is one of several monitors of a kind (one per surface and
            # segment): located on its own, reported as KIND
            if k.split("/", 1)[0] in want:
                tests[k] = float(val)
        return tests

    # ------------------------------------------------------------------------------
    # stepping
    # ------------------------------------------------------------------------------
    def __iter__(self):
        st = self.settings
        if not self._started:
            self._started = True
            if self._progress:
                from tqdm.auto import tqdm
                self._bar = tqdm(total=st.max_points, desc="branch", unit="point")
            first = self._start()
            self.points.append(first)
            self._tick()
            yield first
        try:
            while not self.stop_reason:
                for p in self._bounded(self._step()):
                    self._fold_at_special(p)
                    self.points.append(p)
                    self._tick()
                    yield p
        finally:
            if self._bar is not None:
                self._bar.close()
                self._bar = None

    def _bounded(self, out: list) -> list:
        """``out`` cut to the room ``max_points`` leaves: special points located in the last
        step count like any other (the bound is hard)."""
        room = self.settings.max_points - len(self.points)
        if len(out) > room:
            out = out[:max(room, 0)]
            self._stop(Status.MAX_POINTS, f"max_points = {self.settings.max_points} reached")
        return out

    def _fold_at_special(self, p: Point) -> None:
        """A fold (or a branch point) located at the very point of another special point
        (before or after it) is that point's consequence, not a second bifurcation: the branch
        of an orbit's locked signature turns back where a segment shrinks to nothing at a
        graze (its duration grows like the square root of the parameter's distance), and its
        Jacobian is singular there. The fold keeps its point but loses its label."""
        if not p.special:
            return
        # at the same parameter (the fold's arclength may differ: the unknowns that vanish
        # at the graze move like a square root there)
        near = 1e-8 * (1.0 + abs(p.lam))
        generic = {"LP", "BP"}
        for q in reversed(self.points[-3:]):
            if abs(q.lam - p.lam) > near or not q.special:
                continue
            if (p.special in generic) != (q.special in generic):
                if p.special in generic:
                    p.special = ""
                    return
                # every fold and branch point there loses its label (one label per special
                # point: the relay's cycle had LP, BP and AS at one parameter value)
                q.special = ""

    def _tick(self):
        if self._bar is not None:
            last = self.points[-1]
            self._bar.update(1)
            self._bar.set_postfix(lam=f"{last.lam:.6g}", refresh=False)

    def run(self) -> list[Point]:
        """Follow the branch to its end; returns ``points``."""
        for _ in self:
            pass
        return self.points

    def _stop(self, status: Status, reason: str):
        """End the branch: why as a member (``stop_status``) and as the text that names the
        values (``stop_reason``)."""
        self.stop_status = status
        self.stop_reason = reason
        return []

    def _step(self):
        st = self.settings
        prev = self.points[-1]
        if len(self.points) >= st.max_points:
            return self._stop(Status.MAX_POINTS, f"max_points = {st.max_points} reached")
        if prev.arclength - self._s0 >= st.max_arclength:
            return self._stop(Status.MAX_ARCLENGTH,
                              f"max_arclength = {st.max_arclength} reached")
        Xk, vk = prev.X, prev.tangent
        ds = self._ds
        last_failure = ""
        while True:
            if ds < st.ds_min:
                return self._stop(Status.STEP_BELOW_DS_MIN,
                                  f"the step fell below ds_min = {st.ds_min:g} at "
                                  f"{self._lam_name()} = {prev.lam:.12g} ({last_failure}): "
                                  f"a singular or nonsmooth point of the branch")
            d = vk
            if st.predictor == "secant" and len(self.points) >= 2 and not prev.special:
                sec = Xk - self.points[-2].X
                if np.linalg.norm(sec) > 0:
                    d = sec / np.linalg.norm(sec)
                    d = d if d @ vk > 0 else vk
            Xp = Xk + ds * d
            try:
                X, res = self._correct_on(Xp, vk, vk @ Xk + ds)
                if X is None:
                    last_failure = f"corrector: {res.reason}" + (
                        f" ({res.message})" if getattr(res, "message", "") else "")
                elif not _near_span(X[-1], st.span, ds):
                    # the corrector left the span by more than a step: it has jumped (a
                    # Newton step on the hyperplane with a small parameter component of the
                    # tangent); a shorter step keeps it on the branch
                    X, last_failure = None, (f"the corrector went to {self._lam_name()} = "
                                             f"{X[-1]:.6g}, outside the span")
                else:
                    v = self._tangent(X, vk)
            except STEP_FAILURES as exc:
                X, last_failure = None, _failure_text(exc)
            if X is not None:
                angle = math.acos(min(1.0, max(-1.0, float(v @ vk))))
                # leaving a branch point the start direction is not the new branch's tangent
                leaving = len(self.points) == 1 and bool(prev.special)
                if angle > st.max_angle and ds > st.ds_min * 2 and not leaving:
                    X, last_failure = None, f"the tangent turned by {angle:.2f} rad"
            if X is not None and st.span[0] <= X[-1] <= st.span[1]:
                # the point's data (multipliers, monitors) may fail where the corrector did
                # not (an integration of the variational equations): a failed step too
                try:
                    new = self._point(X, v, ds=ds, iterations=res.iterations,
                                      arclength=prev.arclength + ds)
                except STEP_FAILURES as exc:
                    X, last_failure = None, _failure_text(exc)
            if X is None:
                ds *= 0.5
                continue
            break
        lo, hi = st.span
        out = []
        if not lo <= X[-1] <= hi:
            end = self._end_at_bound(prev, X, lo if X[-1] < lo else hi)
            if end is not None:
                out.extend(self._located(prev, end))
                if self._stops_at(out):
                    return out[:self._stops_at(out)]
                end.special = "EP"
                out.append(end)
            return out + self._stop(Status.SPAN_END, f"the parameter reached the end of "
                                    f"span ({lo:.10g}, {hi:.10g})")
        if not (len(self.points) == 1 and prev.special):
            # leaving a special point (a branch switch, a restart there), the test functions
            # are zero at the start: its own zero is not located again. A monitor that dips
            # below zero and back within the step is seen at its least value in between
            dip = self._dip(prev, new)
            if dip is None:
                out.extend(self._located(prev, new))
            else:
                out.extend(self._located(prev, dip) + self._located(dip, new))
        if self._stops_at(out):
            return out[:self._stops_at(out)]
        out.append(new)
        # the next step: from the Newton iterations and the turn of the tangent
        it = res.iterations
        factor = 1.5 if it < st.target_iter else (0.6 if it > st.target_iter + 1 else 1.0)
        if angle > 0.5 * st.max_angle:
            factor = min(factor, 0.8)
        self._ds = min(st.ds_max, max(st.ds_min, ds * factor))
        if not np.all(np.isfinite(X)):
            return self._stop(Status.BRANCH_NONFINITE, "the branch left the finite numbers")
        return out

    def _stops_at(self, located) -> int:
        """With a located point of a kind in ``stop_at``: the branch ends there (its
        ``stop_reason`` and ``stop_point`` set); returns how many of ``located`` to keep
        (0: none of them is such a point)."""
        for k, q in enumerate(located):
            if q.special in self.settings.stop_at:
                self.stop_point = q
                self._stop(Status.STOP_AT_SPECIAL_POINT,
                           f"{q.special} located at {self._lam_name()} = {q.lam:.12g}")
                return k + 1
        return 0

    def _lam_name(self):
        return getattr(self.problem, "parameter", "lam")

    def _end_at_bound(self, prev, X, bound):
        """The point of the branch on ``lam = bound`` between ``prev`` and ``X``."""
        frac = (bound - prev.lam) / (X[-1] - prev.lam)
        Xg = prev.X + frac * (X - prev.X)
        e = np.zeros(X.size)
        e[-1] = 1.0
        try:
            Xb, res = self._correct_on(Xg, e, bound)
            if Xb is None:
                return None
            v = self._tangent(Xb, prev.tangent)
            ds = float(prev.tangent @ (Xb - prev.X))
            return self._point(Xb, v, ds=ds, iterations=res.iterations,
                               arclength=prev.arclength + ds)
        except STEP_FAILURES:
            return None

    # ------------------------------------------------------------------------------
    # special points
    # ------------------------------------------------------------------------------
    def _dip(self, a: Point, b: Point) -> Point | None:
        """A point between ``a`` and ``b`` where a monitor of a discontinuity-induced
        bifurcation (a test ``KIND/...``) positive at both is negative: two bifurcations
        inside one step (an orbit that grazes a surface, penetrates it for a short stretch
        of the parameter and leaves it again). Sought only where the monitor's values at
        the last three points suggest it (:func:`pwsdyn.continuation.dib.dip_suspected`),
        by minimising it along the branch between ``a`` and ``b`` (each trial a corrected
        point); ``None`` where none is found."""
        from .dib import dip_suspected

        if len(self.points) < 2 or self.points[-1] is not a:
            return None
        z = self.points[-2]
        keys = [k for k, vb in b.tests.items()
                if "/" in k and k in a.tests and k in z.tests and
                dip_suspected((z.arclength, a.arclength, b.arclength),
                              (z.tests[k], a.tests[k], vb))]
        if not keys:
            return None
        from scipy.optimize import minimize_scalar

        found = []

        def least(sig):
            p = self._between(a, b, sig)
            if p is None:
                return math.inf
            v = min(p.tests.get(k, math.inf) for k in keys)
            if v < 0.0:
                found.append(p)
                raise StopIteration
            return v
        try:
            minimize_scalar(least, bounds=(0.0, 1.0), method="bounded",
                            options={"xatol": 1e-6, "maxiter": 60})
        except StopIteration:
            return found[-1]
        return None

    def _between(self, a: Point, b: Point, sig: float) -> Point | None:
        """The point of the branch at the fraction ``sig`` of the chord from ``a`` to ``b``:
        predicted on their cubic Hermite curve and corrected on the hyperplane through the
        prediction orthogonal to the chord (as in :meth:`_locate`)."""
        chord = b.X - a.X
        L = float(np.linalg.norm(chord))
        if not L > 0.0:
            return None
        e = chord / L
        h00, h10 = 2 * sig**3 - 3 * sig**2 + 1, sig**3 - 2 * sig**2 + sig
        h01, h11 = -2 * sig**3 + 3 * sig**2, sig**3 - sig**2
        Xg = h00 * a.X + h10 * L * a.tangent + h01 * b.X + h11 * L * b.tangent
        try:
            X, res = self._correct_on(Xg, e, float(e @ Xg))
            if X is None or np.linalg.norm(X - Xg) > 0.05 * L:
                return None
            v = self._tangent(X, a.tangent)
            return self._point(X, v, ds=sig * L, iterations=res.iterations,
                               arclength=a.arclength + sig * (b.arclength - a.arclength))
        except TrialRejected:
            return None

    def _located(self, a: Point, b: Point) -> list[Point]:
        """Special points between ``a`` and ``b``, located, in the order of the arclength."""
        found = []
        errors = getattr(self.problem, "test_errors", None)
        err_a = err_b = None
        for key, vb in b.tests.items():
            va = a.tests.get(key)
            if va is None or not (va * vb < 0.0):
                continue
            if errors is not None:
                if err_a is None:
                    err_a, err_b = errors(a.data), errors(b.data)
                # both values within the function's own evaluation error: round-off (an orbit
                # whose multipliers stay on the unit circle), not a zero
                if abs(va) <= err_a.get(key, 0.0) and abs(vb) <= err_b.get(key, 0.0):
                    continue
            kind = key.split("/", 1)[0]
            p = self._locate(key, a, b)
            if p is not None and self.problem_confirms(kind, p):
                p.special = kind
                p.data["located"] = key
                extra = getattr(self.problem, "special_data", None)
                if extra is not None:
                    # what the point carries besides its data (a normal-form coefficient, the
                    # curves that meet at a codimension-two point)
                    p.data.update(extra(kind, p.u, p.lam, p.data))
                found.append(p)
        found.sort(key=lambda q: q.arclength)
        # one bifurcation seen by two monitors (a corner collision by the surface at each of
        # the two events that meet there) is one special point
        kept = []
        for q in found:
            if kept and q.special == kept[-1].special and abs(q.arclength - kept[-1].arclength) \
                    <= 100.0 * self.settings.locate_tol * (1.0 + abs(q.arclength)):
                continue
            kept.append(q)
        return kept

    def problem_confirms(self, kind, p) -> bool:
        confirm = getattr(self.problem, "confirm", None)
        return True if confirm is None or kind in ("LP", "BP") else bool(confirm(kind, p.data))

    def _locate(self, kind, a: Point, b: Point) -> Point | None:
        """Zero of test function ``kind`` between ``a`` and ``b``: Illinois regula falsi in
        the fraction ``sigma`` of the chord from ``a`` to ``b``. Each trial is predicted on the
        cubic Hermite curve through ``a`` and ``b`` with their tangents (error fourth order
        in the step) and corrected onto the branch on the hyperplane through the prediction
        orthogonal to the chord. A correction that lands far from its prediction has left for
        another branch (near a branch point both cross the hyperplane) and is refused; the
        search then bisects. Returns the best point found (``None`` only when no trial could
        be corrected)."""
        st = self.settings
        Xa, Xb = a.X, b.X
        chord = Xb - Xa
        L = float(np.linalg.norm(chord))
        if not L > 0.0:
            return None
        e = chord / L
        # Hermite tangents scaled to the chord length, oriented along the travel
        ta = a.tangent * L
        tb = b.tangent * L

        def predict(sig):
            h00 = 2 * sig**3 - 3 * sig**2 + 1
            h10 = sig**3 - 2 * sig**2 + sig
            h01 = -2 * sig**3 + 3 * sig**2
            h11 = sig**3 - sig**2
            return h00 * Xa + h10 * ta + h01 * Xb + h11 * tb

        def direction(sig):
            d = ((6 * sig**2 - 6 * sig) * Xa + (3 * sig**2 - 4 * sig + 1) * ta
                 + (-6 * sig**2 + 6 * sig) * Xb + (3 * sig**2 - 2 * sig) * tb)
            return d / np.linalg.norm(d)

        sa, sb = 0.0, 1.0
        fa, fb = a.tests[kind], b.tests[kind]
        best = None
        side = 0
        for _ in range(80):
            if (sb - sa) * L <= st.locate_tol * (1.0 + L):
                break
            sig = sb - fb * (sb - sa) / (fb - fa) if fb != fa else 0.5 * (sa + sb)
            if not sa < sig < sb or side == 2:
                sig = 0.5 * (sa + sb)
            X = None
            # the cubic prediction first; where its correction fails or lands far off (near
            # a fold whose tangents turn fast, or where another branch crosses) the chord's
            for Xg in (predict(sig), Xa + sig * chord):
                try:
                    X, res = self._correct_on(Xg, e, float(e @ Xg))
                except STEP_FAILURES:
                    X = None
                if X is not None and np.linalg.norm(X - Xg) > 0.05 * L:
                    X = None
                if X is not None:
                    break
            if X is None:
                if side == 2:
                    break
                side = 2      # bisect next
                continue
            # at a branch point the bordered system that gives the tangent is singular: the
            # branch's direction there is that of the Hermite curve
            arc = a.arclength + sig * (b.arclength - a.arclength)
            try:
                tv = direction(sig) if kind == "BP" else self._tangent(X, a.tangent)
                p = self._point(X, tv, ds=sig * L, iterations=res.iterations, arclength=arc)
            except STEP_FAILURES:
                break
            f = p.tests.get(kind)
            if f is None or not math.isfinite(f):
                break
            best = p
            if f == 0.0:
                break
            if (f < 0.0) == (fa < 0.0):
                sa, fa = sig, f
                if side == -1:
                    fb *= 0.5
                side = -1
            else:
                sb, fb = sig, f
                if side == 1:
                    fa *= 0.5
                side = 1
        return best


def _near_span(lam: float, span, ds: float) -> bool:
    """Whether ``lam`` lies within one step ``|ds|`` of ``span`` (a corrected point beyond
    that has jumped off the branch, which moves ``lam`` by at most the arclength)."""
    lo, hi = span
    return lo - abs(ds) <= lam <= hi + abs(ds)


def _null_vector(A):
    """Unit vector spanning the (numerical) null space of the ``N x (N+1)`` matrix ``A``."""
    _, _, Vt = np.linalg.svd(A)
    return Vt[-1]


def null_space(A, k: int):
    """The ``k`` right singular vectors of ``A`` of the smallest singular values."""
    _, _, Vt = np.linalg.svd(A)
    return Vt[-k:]


def replace_settings(settings: ContinuationSettings, **kw) -> ContinuationSettings:
    return replace(settings, **kw)
