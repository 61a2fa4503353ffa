"""Fixed and periodic points of piecewise-smooth maps, with their multipliers.

A map counterpart of :func:`pwsdyn.find_periodic_orbit` rather than a branch inside it: a
map's periodic point is the root of ``F^k(x) - x`` in the state space alone, found by Newton
with the generated Jacobian of each piece, with no time, no shooting nodes and no event
signature; the result carries what a map's analysis needs (the ``k`` points of the cycle, the
pieces applied, the multipliers of ``D F^k``) and nothing of a flow's trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import _validate as V
from ..errors import PwsdynError
from ..model.spec import as_model
from ._sections import MapSection, StroboscopicSection


class ManifoldError(PwsdynError, RuntimeError):
    """A periodic point or a manifold could not be computed; ``result`` holds what was (the
    last Newton iterate as a :class:`~pwsdyn.PeriodicPoint`, or ``None``)."""

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result


@dataclass(eq=False)
class PeriodicPoint:
    """A fixed (``period = 1``) or period-``k`` point of a piecewise-smooth map.

    Attributes
    ----------
    model : MapModel
    params : dict
        Parameter values.
    x : numpy.ndarray, shape (n,)
        The point; ``cycle`` the ``period`` points of its orbit, ``x`` first.
    period : int
    pieces : tuple of str
        The piece applied at each point of the cycle (the cycle's symbolic itinerary).
    jacobian : numpy.ndarray, shape (n, n)
        ``D F^period`` at ``x``: the ordered product of the pieces' Jacobians.
    multipliers : numpy.ndarray
        Eigenvalues of ``jacobian``, by decreasing modulus.
    history : list of float
        Newton residual ``max|F^k(x) - x| / (1 + max|x|)`` of each iterate, the last one last.
    converged : bool
    t0, section_period : float or None
        A forced flow's point on its stroboscopic section: the section's phase and the
        forcing period ``T`` (``F`` is then ``x(t0) -> x(t0 + T)`` and the pieces are the
        events of each period); ``None`` for a map model.
    """

    model: object
    params: dict
    x: np.ndarray
    period: int
    cycle: np.ndarray
    pieces: tuple
    jacobian: np.ndarray
    multipliers: np.ndarray
    history: list = field(default_factory=list)
    converged: bool = True
    t0: float | None = None
    section_period: float | None = None

    @property
    def saddle(self) -> bool:
        """One multiplier outside the unit circle and one inside (a saddle)."""
        m = np.abs(self.multipliers)
        return bool(np.any(m > 1 + 1e-9) and np.any(m < 1 - 1e-9))

    @property
    def stable(self) -> bool:
        """Every multiplier inside the unit circle."""
        return bool(np.all(np.abs(self.multipliers) < 1 - 1e-8))

    def __repr__(self):
        mult = ", ".join(f"{complex(m).real:.6g}" if complex(m).imag == 0 else f"{m:.6g}"
                         for m in self.multipliers)
        return (f"PeriodicPoint({self.model.name!r}, period={self.period}, x={self.x.tolist()}, "
                f"pieces={list(self.pieces)}, multipliers=[{mult}])")


def _sorted_eigs(J):
    w = np.linalg.eigvals(J)
    return w[np.argsort(-np.abs(w), kind="stable")]


def find_periodic_point(model, x0, period: int = 1, *, params=None, tol: float = 1e-12,
                        max_iter: int = 50) -> PeriodicPoint:
    """A fixed or period-``period`` point of a map model, by Newton on ``F^k(x) - x``.

    Each Newton step solves ``(D F^k(x) - I) dx = -(F^k(x) - x)`` with the Jacobian of the
    pieces applied at the current iterate; on a piecewise-linear map it ends in one step once
    the iterate's pieces are the cycle's.

    Parameters
    ----------
    model : MapModel, str, path or dict
        A map model (``kind = "map"``) or anything :func:`pwsdyn.load_model` accepts.
    x0 : sequence or dict
        Initial guess, in state order or by state name.
    period : int
        ``k``: the number of iterations of the cycle.
    params : dict, optional
        Parameter values overriding the defaults.
    tol : float
        Converged when the residual ``max|F^k(x) - x| / (1 + max|x|)`` is below ``tol``.
    max_iter : int
        Newton iterations at most.

    Returns
    -------
    PeriodicPoint

    Raises
    ------
    ManifoldError
        Newton did not converge (a singular ``D F^k - I``, no piece applies, or the iterations
        ran out); its ``result`` is the last iterate as a :class:`~pwsdyn.PeriodicPoint` with
        ``converged = False``.

    Examples
    --------
    >>> pt = find_periodic_point("sqrt-map", [0.1], params={"mu": 0.2, "lam": 0.3})
    >>> round(float(pt.x[0]), 12)     # x = mu - sqrt(x): sqrt(x) = (-1 + sqrt(1 + 4 mu)) / 2
    0.02917960675
    """
    model = as_model(model, kind="map", caller="find_periodic_point()")
    period = V.integer("period", period, lo=1)
    max_iter = V.integer("max_iter", max_iter, lo=1)
    tol = V.positive("tol", tol)
    sec = MapSection(model, params, period)
    x = V.state_vector(model, x0).astype(float)
    x, history, converged, reason = _newton(
        sec, x, tol, max_iter,
        "no piece of the map applies (or the image is not finite) at the iterate")
    if converged:
        return _point(model, sec, x, period, history, True)
    last = _point(model, sec, x, period, history, False)
    raise ManifoldError(f"find_periodic_point(): Newton did not converge: {reason} "
                        "(residuals " + " ".join(f"{h:.2e}" for h in history) + ")",
                        result=last)


def multiplier_variables(mult) -> dict:
    """The saddle's multipliers as the two real variables of a result's NetCDF file (complex
    numbers have no NetCDF type): ``multiplier_real`` and ``multiplier_imag``."""
    return {"multiplier_real": (("multiplier",), mult.real,
                                {"long_name": "real part of the saddle's multiplier",
                                 "units": "1"}),
            "multiplier_imag": (("multiplier",), mult.imag,
                                {"long_name": "imaginary part of the saddle's multiplier",
                                 "units": "1"})}


def _newton(sec, x, tol: float, max_iter: int, no_image: str):
    """Newton's method on ``F^k(x) - x`` with the section's Jacobian ``D F^k`` (a map's pieces,
    or a flow's monodromy with its saltation matrices): ``(x, residuals, converged, reason)``,
    the residual relative to ``1 + |x|``; ``no_image`` is the reason where ``F^k`` has none."""
    history: list = []
    reason = "the iterations ran out"
    for _ in range(max_iter + 1):
        y, sig, J = sec.evaluate(x, jacobian=True)
        if sig is None:
            reason = no_image
            break
        r = y - x
        res = float(np.max(np.abs(r))) / (1.0 + float(np.max(np.abs(x))))
        history.append(res)
        if res <= tol:
            return x, history, True, ""
        if len(history) > max_iter:
            break
        try:
            dx = np.linalg.solve(J - np.eye(len(x)), -r)
        except np.linalg.LinAlgError:
            reason = "D F^k - I is singular at the iterate (a multiplier 1)"
            break
        x = x + dx
    return x, history, False, reason


def _point(model, sec, x, period, history, converged) -> PeriodicPoint:
    one = MapSection(model, sec.params, 1)
    cycle = [np.array(x, dtype=float)]
    pieces = []
    J = np.eye(len(x))
    y = cycle[0]
    for _ in range(period):
        z, sig, Jk = one.evaluate(y, jacobian=True)
        if sig is None:
            pieces.append("")
            J = J * np.nan
            break
        pieces.append(model.mode_names[sig[0]])
        J = Jk @ J
        y = z
        cycle.append(z)
    cycle = np.array(cycle[:period])
    return PeriodicPoint(model=model, params=dict(sec.params), x=cycle[0].copy(), period=period,
                         cycle=cycle, pieces=tuple(pieces), jacobian=J,
                         multipliers=_sorted_eigs(J) if np.all(np.isfinite(J))
                         else np.full(len(x), np.nan), history=history, converged=converged)


def section_point(model, x0, period: int = 1, *, params=None, t0: float = 0.0,
                  tol: float | None = None, max_iter: int = 30,
                  options=None) -> PeriodicPoint:
    """A fixed or period-``period`` point of a forced flow's stroboscopic map
    ``x(t0) -> x(t0 + T)`` (``T`` the forcing period at ``params``), by Newton on
    ``F^k(x) - x`` with the monodromy matrix of the runs (their saltation matrices included)
    as ``D F^k``: the planar map whose saddles and manifolds a flow's crisis is made of.

    ``tol`` defaults to ten times the integration tolerance (the residual can go no lower
    than the runs' error). The pieces are the events of each period, as
    ``"kind:index"`` names joined by ``","`` (``""`` for a period without events).
    """
    model = as_model(model, kind="flow", caller="section_point()")
    period = V.integer("period", period, lo=1)
    ctx = StroboscopicSection(model, params, t0, 1.0, 1, options)
    T = ctx.ctx.forcing_period
    if T is None:
        raise ManifoldError(f"{model.name!r} has no forcing period: no stroboscopic section")
    one = StroboscopicSection(model, ctx.params, t0, float(T), 1, options)
    sec = one.iterate(period)
    if tol is None:
        tol = 10.0 * max(one.opts["rtol"], one.opts["atol"])
    x = V.state_vector(model, x0).astype(float)
    x, history, converged, reason = _newton(
        sec, x, tol, max_iter,
        "the run failed or left the admissible side of an impact surface")
    # the cycle and its monodromy over the ``period`` forcing periods, from the last iterate
    cycle, pieces, Jt, z = [], [], np.eye(len(x)), x
    for _ in range(period):
        cycle.append(z)
        w, s, Jk = one.evaluate(z, jacobian=True)
        if s is None:
            Jt = Jt * np.nan
            pieces.append("")
            break
        pieces.append(",".join(one.piece_names(s)))
        Jt = Jk @ Jt
        z = w
    pt = PeriodicPoint(model=model, params=dict(one.params), x=np.array(x, dtype=float),
                       period=period, cycle=np.array(cycle), pieces=tuple(pieces), jacobian=Jt,
                       multipliers=_sorted_eigs(Jt) if np.all(np.isfinite(Jt))
                       else np.full(len(x), np.nan), history=history, converged=converged,
                       t0=float(t0), section_period=float(T))
    if not converged:
        raise ManifoldError("section_point(): Newton did not converge: " + reason
                            + " (residuals " + " ".join(f"{h:.2e}" for h in history) + ")",
                            result=pt)
    return pt


def refind(model, point: PeriodicPoint, params, options=None) -> PeriodicPoint:
    """``point`` found again at ``params`` from its position: a map's periodic point, or a
    flow's point on its stroboscopic section at the same phase (its runs with the integrator
    ``options``)."""
    if point.section_period is None:
        return find_periodic_point(model, point.x, point.period, params=params)
    return section_point(model, point.x, point.period, params=params, t0=point.t0,
                         options=options)
