"""Newton's method with backtracking, for the square systems of the orbit code.

One solver, used by the free-running shooting of :func:`pwsdyn.find_periodic_orbit` and by
the orbit problems on a fixed signature (:class:`pwsdyn.orbits.OrbitProblem`), and meant for
any ``F(x) = 0`` with a Jacobian: a continuation corrector calls it the same way.

Iteration (the damped Newton method, e.g. Deuflhard, *Newton Methods for Nonlinear Problems*,
2004, ch. 3, here with the simplest acceptance test):

1. evaluate ``r = F(x)`` and its size ``norm(r, x)``; stop when it is at most ``tol``;
2. ``J = jac(x)``; refuse a singular ``J`` (smallest singular value at most ``singular_rtol``
   times ``jac_scale(J)``, by default its largest singular value);
3. ``dx = -J^-1 r``; refuse a step that is not finite or larger than ``max_step_ratio *
   (1 + max|x|)``;
4. try ``x + lam dx`` for ``lam = 1, 1/2, ..., 2^-(halvings-1)`` and accept the first trial
   whose residual is smaller (or at most ``tol``). A trial that cannot be evaluated --
   ``F`` raises :class:`TrialRejected` -- counts as a failed trial; its reason is kept.

Every loop is bounded: at most ``max_iter`` steps of at most ``halvings`` trials each.
Nothing is raised for a failure: the :class:`NewtonResult` says why (``reason``), with the
last accepted iterate and the residual history.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

#: Reasons of failure set by the solver itself (an evaluation's own reason is passed on).
REASONS = ("singular", "diverged", "no_progress", "budget", "nonfinite", "evaluation")


class TrialRejected(Exception):
    """Raised by a residual function at a point where it cannot be evaluated (an integration
    failed, a discrete structure changed, an unknown left its range). During the line search
    it rejects the trial; at the initial point it ends the solve with ``reason`` (default
    ``'evaluation'``)."""

    def __init__(self, message: str = "", reason: str = "evaluation", data=None):
        super().__init__(message)
        self.reason = reason
        self.message = message
        self.data = data


@dataclass
class NewtonResult:
    """Outcome of :func:`newton`.

    Attributes
    ----------
    x : numpy.ndarray
        The last accepted iterate (the solution when ``converged``).
    converged : bool
    reason : str
        ``'converged'``; or why not: ``'singular'`` (the Jacobian is singular to
        ``singular_rtol``), ``'diverged'`` (the step is not finite or larger than
        ``max_step_ratio (1 + |x|)``), ``'no_progress'`` (no trial of the line search reduced the
        residual), ``'budget'`` (``max_iter`` steps), ``'nonfinite'`` (the Jacobian has NaN or
        infinite entries), or the reason of a :class:`TrialRejected` raised at the initial
        point (``'evaluation'`` by default).
    message : str
        A sentence saying what happened.
    history : list of float
        ``norm(r, x)`` of every accepted iterate, the initial one first.
    iterations : int
        Newton steps taken.
    residual : numpy.ndarray or None
        ``F`` at ``x``.
    step : numpy.ndarray or None
        The last Newton step computed (also when it was not accepted).
    rejections : list of TrialRejected
        Trials refused during the last line search (``no_progress``: why).
    """

    x: np.ndarray
    converged: bool
    reason: str
    message: str
    history: list
    iterations: int
    residual: np.ndarray | None = None
    step: np.ndarray | None = None
    rejections: list = field(default_factory=list)


def max_norm(r, x) -> float:
    """``max|r| / (1 + max|x|)``: the default residual size."""
    r = np.asarray(r, dtype=float)
    x = np.asarray(x, dtype=float)
    return float(np.max(np.abs(r), initial=0.0) / (1.0 + np.max(np.abs(x), initial=0.0)))


def newton(fun: Callable, x0, *, jac: Callable, tol: float = 1e-10, max_iter: int = 30,
           norm: Callable = max_norm, halvings: int = 8, singular_rtol: float = 1e-9,
           jac_scale: Callable | None = None, max_step_ratio: float = 1e3,
           on_accept: Callable | None = None, history: list | None = None) -> NewtonResult:
    """Solve ``fun(x) = 0`` by Newton's method with backtracking (see the module docstring).

    Parameters
    ----------
    fun : callable
        ``fun(x) -> r``, a 1-D array of the size of ``x``; may raise :class:`TrialRejected`.
    x0 : array_like
        Initial iterate.
    jac : callable
        ``jac(x) -> J`` (square), called at accepted iterates only, right after ``fun`` was
        evaluated there (so it may reuse what ``fun`` computed).
    tol : float
        Converged when ``norm(r, x) <= tol``.
    max_iter : int
        Most Newton steps.
    norm : callable
        ``norm(r, x) -> float``; default :func:`max_norm`.
    halvings : int
        Trials of the line search (step lengths ``1, 1/2, ...``).
    singular_rtol : float
        ``J`` is singular when its smallest singular value is at most ``singular_rtol *
        jac_scale(J)`` (default scale: its largest singular value).
    jac_scale : callable, optional
        ``jac_scale(J, singular_values) -> float``.
    max_step_ratio : float
        Largest step relative to ``1 + max|x|``.
    on_accept : callable, optional
        ``on_accept(x, r, res)`` at every accepted iterate (the initial one included), before
        the convergence test; may return a new residual (the problem was updated there) or
        raise to end the solve (the exception propagates).
    history : list, optional
        List the residual norms are appended to (shared across restarts by a caller).

    Returns
    -------
    NewtonResult
    """
    history = [] if history is None else history
    x = np.array(x0, dtype=float, copy=True)
    try:
        r = np.asarray(fun(x), dtype=float)
    except TrialRejected as exc:
        return NewtonResult(x, False, exc.reason, exc.message or "the initial point cannot be "
                            "evaluated", history, 0, rejections=[exc])
    dx = None
    for it in range(max_iter + 1):
        res = norm(r, x)
        if on_accept is not None:
            new = on_accept(x, r, res)
            if new is not None:
                r = np.asarray(new, dtype=float)
                res = norm(r, x)
        history.append(res)
        if res <= tol:
            return NewtonResult(x, True, "converged", f"converged in {it} step(s) to "
                                f"{res:.2e} <= tol = {tol:.1e}", history, it, r, dx)
        if it == max_iter:
            break
        J = np.asarray(jac(x), dtype=float)
        # (array methods rather than the numpy functions: the same reductions, without the
        # functions' dispatch, which costs more than a reduction of a few entries)
        if not np.isfinite(J).all():
            return NewtonResult(x, False, "nonfinite", "the Jacobian is not finite", history,
                                it, r, dx)
        sv = np.linalg.svd(J, compute_uv=False)
        scale = sv[0] if jac_scale is None else jac_scale(J, sv)
        if not sv[-1] > singular_rtol * scale:
            return NewtonResult(x, False, "singular", f"singular Jacobian (condition "
                                f"{sv[0] / max(sv[-1], 1e-300):.1e}) at iteration {it}; "
                                f"residual {res:.3e}", history, it, r, dx)
        dx = np.linalg.solve(J, -r)
        size = 1.0 + np.abs(x).max(initial=0.0)
        if not np.isfinite(dx).all() or np.abs(dx).max() > max_step_ratio * size:
            return NewtonResult(x, False, "diverged", f"the Newton step "
                                f"({np.max(np.abs(dx)):.3e}) is far larger than the unknowns "
                                f"({size:.3e}) at iteration {it}", history, it, r, dx)
        lam = 1.0
        rejections = []
        for _ in range(halvings):
            xt = x + lam * dx
            try:
                rt = np.asarray(fun(xt), dtype=float)
            except TrialRejected as exc:
                rejections.append(exc)
                lam *= 0.5
                continue
            rest = norm(rt, xt)
            if rest < res or rest <= tol:
                x, r = xt, rt
                break
            lam *= 0.5
        else:
            return NewtonResult(x, False, "no_progress", f"no Newton step (down to "
                                f"1/{2 ** (halvings - 1)} of the full step) reduced the "
                                f"residual {res:.3e} at iteration {it}", history, it, r, dx,
                                rejections)
    return NewtonResult(x, False, "budget", f"no convergence in {max_iter} Newton iterations "
                        f"(residual {history[-1]:.3e}, tolerance {tol:.1e})", history, max_iter,
                        r, dx)
