"""Designing the low-cost control of a grazing bifurcation (thesis Paper B).

The constraint position ``delta`` is moved once per period, at the stroboscopic section
``t = t_c``, by the linear law (thesis eq. 5.2; :func:`pwsdyn.with_discrete_control`)

    delta -> delta* + c . (x - x*) + c0 (delta - delta*),

``x*`` the grazing orbit's state at the section, so that the grazing orbit itself is not
disturbed. Near the graze the controlled system's smooth Poincaré map on the section
``h_turning = 0`` of the discontinuity map is block triangular (the smooth dynamics does not
depend on ``delta``)::

    z     -> P z
    delta -> c . J_C z + c0 delta

with ``P`` the uncontrolled map, ``J_C`` the Jacobian of the state at the control section
with respect to ``z`` at the grazing section (the flow from the graze to ``t_c``). An impact
kicks ``z`` by ``beta`` and leaves ``delta``; the surface ``h = h(x, delta)``. The terms of
the persistence sequence (eq. 2.35) of the controlled system are therefore

    s_n = h_z P^n beta + h_delta c . sum_{k<n} c0^(n-1-k) J_C P^k beta,

linear in ``c`` for a given ``c0``: persistence (every ``s_n > 0``) is a linear feasibility
problem. :func:`~pwsdyn.design_control` solves it for a grid of ``c0`` by linear programming,
maximising the smallest normalised term, and returns the gains, or says that none up to a
bound on the gains makes the bifurcation persistent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError


@dataclass
class ControlDesign:
    """Gains of the linear law (eq. 5.2) for a grazing point.

    Attributes
    ----------
    feasible : bool
        Whether gains were found that make every term of the controlled persistence sequence
        positive.
    c0 : float
    c : dict
        Gains by state name.
    x_star : dict
        The grazing orbit's state at the control section, by state name.
    delta_star : float
        The constraint position at the graze.
    t_c : float
        The time of the control section.
    margin : float
        The smallest term of the normalised sequence (positive when feasible).
    sequence : numpy.ndarray
        The predicted persistence sequence of the controlled system.
    reason : str
        Why no design was found (empty when feasible).
    """

    feasible: bool
    c0: float
    c: dict
    x_star: dict
    delta_star: float
    t_c: float
    margin: float
    sequence: np.ndarray
    reason: str = ""

    def params(self, parameter_states=None) -> dict:
        """The parameter values of :func:`pwsdyn.with_discrete_control`'s linear law."""
        out = {"delta_star": self.delta_star, "c0": self.c0, "t_c": self.t_c}
        for s, v in self.c.items():
            out[f"c_{s}"] = v
        for s, v in self.x_star.items():
            out[f"x_star_{s}"] = v
        return out


def design_control(point, *, t_c: float = 0.0, c0_values=None, max_gain: float = 10.0,
                   terms: int = 60) -> ControlDesign:
    """Gains ``c``, ``c0`` of the linear law 5.2 at the stroboscopic section ``t = t_c`` that
    make the grazing bifurcation at ``point`` persistent, or the reason there are none.

    Parameters
    ----------
    point : SpecialPoint
        A grazing point of a forced orbit branch continued in the constraint position (the
        parameter of the branch; the surface must depend on it): a ``GR`` point, or a ``CC``
        point that is a graze at a kink of the field (as :func:`pwsdyn.discontinuity_map`
        accepts).
    t_c : float
        The control section's time (modulo the forcing period).
    c0_values : sequence of float, optional
        The ``c0`` tried (default 0, 0.05, ..., 0.95).
    max_gain : float
        Bound on each ``|c_i|``.
    terms : int
        Terms of the persistence sequence made positive.

    Returns
    -------
    ControlDesign
    """
    from scipy.optimize import linprog

    from .. import _validate as V
    from ..orbits.surfaces import model_context
    from .discontinuity import _tangency, discontinuity_map

    dm = discontinuity_map(point)
    prob = point.problem.orbit_problem
    if not prob.forced:
        raise ArgumentError("the control design acts at the stroboscopic section: the model "
                            "must be forced")
    t_c = V.number("t_c", t_c)
    max_gain = V.positive("max_gain", max_gain)
    terms = V.integer("terms", terms, lo=1, hi=10_000)
    c0_values = (np.arange(0.0, 0.96, 0.05) if c0_values is None
                 else np.asarray([V.number("c0_values", v, lo=-1, hi=1, lo_open=True,
                                           hi_open=True) for v in c0_values]))
    m, n = prob.model, prob.n
    param = point.parameter
    mon = _tangency(point)[3]          # a graze at a kink: on the segment after it
    k = m.events[[j for j, e in enumerate(m.events)
                  if e.kind == "impact" and m.surfaces[e.surface].name == mon.surface][0]].surface
    p = np.array([point.value])
    ctx = model_context(m, prob.param_dict(p), prob.sliding)
    # dh/d(delta): the surface's derivative in the controlled parameter
    h_delta = _surface_parameter_derivative(m, k, param, ctx, mon.t, mon.x)
    if h_delta == 0.0:
        raise ArgumentError(f"surface {mon.surface!r} does not depend on {param!r}: moving it "
                            f"cannot control the graze")
    # the flow from the graze to the control section (within the grazing segment)
    P_T = prob.period_value(p)
    dt = (t_c - mon.t) % P_T
    seg = mon.segment
    s = prob.evaluate(point.point.u, p).segs[seg]
    if mon.t + dt > s.t + s.T + 1e-12 * P_T:
        raise ArgumentError("the control section must lie in the grazing segment (between "
                            "the graze and the segment's end)")
    z = np.append(mon.x, p)
    x_c, Phi, _ = prob.flow(seg, mon.t, z, dt, prob.segment_options(p))
    Phi = Phi[:n, :n]
    f_star = ctx.mode_field(prob.fields[seg].index, mon.t, mon.x)
    J_C = np.hstack([Phi, -(Phi @ f_star)[:, None]])       # d x_C / d (x, t) at the graze
    # the uncontrolled terms and the control's directions
    PkB = [dm.beta]
    for _ in range(terms):
        PkB.append(dm.P @ PkB[-1])
    a = np.array([dm.h_x @ PkB[j] for j in range(1, terms + 1)])
    best = None
    for c0 in c0_values:
        B = np.zeros((terms, n))
        acc = np.zeros(n)
        for j in range(terms):
            acc = c0 * acc + J_C @ PkB[j]                  # sum_{k<=j} c0^(j-k) J_C P^k beta
            B[j] = h_delta * acc
        scale = np.abs(a) + np.linalg.norm(B, axis=1) * max_gain + 1e-300
        # maximise tau subject to a_n + B_n c >= tau scale_n, |c_i| <= max_gain
        cost = np.zeros(n + 1)
        cost[-1] = -1.0
        A_ub = np.hstack([-B, scale[:, None]])
        res = linprog(cost, A_ub=A_ub, b_ub=a,
                      bounds=[(-max_gain, max_gain)] * n + [(None, 1.0)], method="highs")
        if res.status != 0:
            continue
        c, tau = res.x[:n], res.x[-1]
        if best is None or tau > best[0]:
            best = (tau, float(c0), c, a + B @ c)
    x_star = dict(zip(m.states, (float(v) for v in x_c[:n])))
    if best is None:
        return ControlDesign(False, 0.0, {}, x_star, point.value, t_c, -np.inf, np.zeros(0),
                             "the linear programs failed")
    tau, c0, c, seq = best
    feasible = tau > 0
    return ControlDesign(feasible, c0, dict(zip(m.states, (float(v) for v in c))), x_star,
                         float(point.value), float(t_c), float(tau), seq,
                         "" if feasible else f"no gains up to |c_i| <= {max_gain} make every "
                         f"term of the persistence sequence positive (best margin {tau:.3e})")


def _surface_parameter_derivative(model, k, param, ctx, t, x) -> float:
    """``d h_k / d param`` at ``(t, x)`` (symbolic)."""
    import sympy as sp

    expr = model.surfaces[k].expr
    d = sp.diff(expr, sp.Symbol(param, real=True))
    subs = {sp.Symbol(s, real=True): float(v) for s, v in zip(model.states, x)}
    subs.update({sp.Symbol(q, real=True): float(v) for q, v in ctx.params.items()})
    subs[model.t] = float(t)
    return float(d.subs(subs))
