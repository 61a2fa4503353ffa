r"""A hybrid periodic orbit on a fixed signature as a problem with exact Jacobians.

The problem is :math:`F(u, p) = 0`, with its Jacobians :math:`F_u` and :math:`F_p`.

Unknowns (the segment formulation of COCO's ``hspo`` toolbox, Dankowicz & Schilder,
*Recipes for Continuation*, SIAM 2013, ch. 4; Thota & Dankowicz, TC-HAT, SIAM J. Appl.
Dyn. Syst. 7 (2008)): the orbit's signature (:class:`~pwsdyn.orbits.signature.Signature`) is
cut into ``m`` segments, segment ``i`` ending with boundary ``i`` (one event, or an impact or a
chattering sequence followed at the same instant by the start of sticking). With :math:`n`
states,

.. math::

    u = (t_0, x_0, T_0, x_1, T_1, \ldots, x_{m-1}, T_{m-1}),

:math:`x_i` the state at the start of segment :math:`i` (just after boundary :math:`i - 1`),
:math:`T_i` its duration and :math:`t_0` the time segment 0 starts -- an unknown for a forced
model (the phase of the orbit), left out for an autonomous one. Segment :math:`i` starts at
:math:`t_i = t_0 + \sum_{j<i} (T_j + \delta_j)`, :math:`\delta_j` the jump in time of boundary
:math:`j` (the complete-chattering map; zero otherwise). Residual, per segment:

.. math::

    x_{i+1} - E_i(t_i + T_i, y_i) &= 0
        \qquad \text{($n$ rows: continuity through the event map $E_i$)}, \\
    c_i(t_i + T_i, y_i) &= 0 \qquad \text{(1 row: the event condition)},

with :math:`y_i = \varphi_i(t_i + T_i; t_i, x_i, p)` the segment's flow (:math:`x_m = x_0`),
:math:`c_i` the surface :math:`h` (impacts, transitions, crossings, sliding entry,
chattering), the normal velocity of the exit mode (sliding exit) or the free normal
acceleration (release), and :math:`E_i` the reset, the identity or the chattering map. A
forced model adds the period :math:`t_m - t_0 - k T_f(p) = 0` (:math:`k` forcing periods); an
autonomous one needs no phase condition: the event conditions fix where the segments start
(the section is the last event's surface). Square: :math:`1 + m (n + 1)` (forced) or
:math:`m (n + 1)` unknowns and equations. Without events (:math:`m = 0`) the problem is single
shooting: :math:`\varphi(t_0 + P; t_0, x_0) - x_0` with :math:`t_0` fixed, plus, autonomous,
the unknown :math:`P` and the phase condition :math:`n \cdot (x_0 - x_{ref}) = 0`.

Jacobians: each segment is integrated by the compiled kernel with its variational equations
in the state extended by the chosen parameters (:math:`p' = 0`; ``pwsdyn.orbits._segments``),
so :math:`\Phi = \partial(y, p)/\partial(x, p)` holds :math:`\partial y/\partial x` and
:math:`\partial y/\partial p`; :math:`\partial y/\partial T = f(t_e, y)` and
:math:`\partial y/\partial t_i = f(t_e, y) - \Phi f(t_i, x_i)`. The conditions and maps are
generated with their gradients over :math:`(x, p)` and :math:`t`; the chattering map's
projection onto the sticking manifold is differentiated implicitly. All are chained by the
product rule (forward mode) into :math:`[F_u \mid F_p]`: exact up to the integration
tolerance, no difference quotient of :math:`F`.

On a fixed signature nothing stops a segment at a surface it is not meant to end at: the orbit
can be followed past a grazing into the region where it is not a solution of the hybrid
model. :meth:`~pwsdyn.orbits.OrbitProblem.admissibility` says whether it is one and, if not,
why (a segment crossing a constraint or a switching surface, an impact with the flow leaving
the surface, sticking with a pulling contact force, sliding outside the sliding region, a
negative duration).
"""


from __future__ import annotations

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError
from ..integrate.compiled import event_map_saltation as event_map_saltation
from . import _admissibility, _guesses, _results, monitors
from ._admissibility import Admissibility as Admissibility
from ._base import ADMISSIBILITY_RTOL as ADMISSIBILITY_RTOL
from ._base import OrbitError
from ._orbit import PeriodicOrbit
from ._residual import _OrbitProblemBase
from ._residual import ProblemEvaluation as ProblemEvaluation
from ._residual import SegmentFailed as SegmentFailed
from ._results import OrbitSensitivity as OrbitSensitivity
from .monitors import DIB_KINDS as DIB_KINDS
from .monitors import Monitor as Monitor
from .monitors import MonitorKey as MonitorKey
from .signature import Signature
from .surfaces import model_context


def _same_doc(fn):
    """The method's docstring is its function's (one text for both)."""
    def take(method):
        method.__doc__ = fn.__doc__
        return method
    return take


class OrbitProblem(_OrbitProblemBase):
    """A periodic orbit of a hybrid model on a fixed signature: ``F(u, p) = 0``.

    See the module docstring for the unknowns ``u`` and the residual. The problem, the layout
    of ``u``, the evaluation of ``F`` with its Jacobians and Newton's method are defined in
    ``pwsdyn.orbits._residual``; the methods computed from a solution (guesses, admissibility,
    monitors, results) are functions of the problem in modules of their own, which import it
    and are not imported by it.

    Parameters
    ----------
    model : Model, str, path or dict
    signature : Signature or sequence
        The orbit's events over one period (``PeriodicOrbit.signature``); it must be closed
        (each event starts in the state the previous one ends in). Empty: an orbit without
        events, in discrete state ``state``.
    params : dict, optional
        Parameter values (the model's defaults otherwise).
    parameters : sequence of str, optional
        The parameters ``p`` of ``F(u, p)`` (columns of ``F_p``), in order; default all of
        the model's. The others are fixed at ``params``.
    periods : int
        Forced models: the period in forcing periods.
    t_ref : float
        Autonomous models (and orbits without events): the start time of segment 0.
    state : str, optional
        Orbits without events: their discrete state (a mode name).
    phase_ref, phase_normal : array_like, optional
        Autonomous orbits without events: the phase condition ``normal . (x_0 - ref) = 0``.
    sliding : {'convex', 'utkin'}
    **options
        Integrator options of :func:`pwsdyn.simulate` (defaults as
        :func:`pwsdyn.find_periodic_orbit`: DOP853, ``rtol = atol = 1e-12``).

    Examples
    --------
    >>> import pwsdyn
    >>> orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [0.0, -0.5])
    >>> prob, u = OrbitProblem.from_orbit(orbit, parameters=["sigma"])
    >>> F_u, F_p = prob.jacobian(u, prob.p0)
    """

    # ---- the problem's own interface: its definition, the layout of u, the evaluation of F
    # and its Jacobians, Newton (pwsdyn.orbits._residual), named here so that it is this
    # class's interface (and documented with it)
    replace = vars(_OrbitProblemBase)["replace"]
    from_orbit = vars(_OrbitProblemBase)["from_orbit"]
    pack = vars(_OrbitProblemBase)["pack"]
    unpack = vars(_OrbitProblemBase)["unpack"]
    param_dict = vars(_OrbitProblemBase)["param_dict"]
    period_value = vars(_OrbitProblemBase)["period_value"]
    evaluate = vars(_OrbitProblemBase)["evaluate"]
    residual = vars(_OrbitProblemBase)["residual"]
    jacobian = vars(_OrbitProblemBase)["jacobian"]
    norm = vars(_OrbitProblemBase)["norm"]
    solve = vars(_OrbitProblemBase)["solve"]
    segment_options = vars(_OrbitProblemBase)["segment_options"]
    flow = vars(_OrbitProblemBase)["flow"]
    dense_segment = vars(_OrbitProblemBase)["dense_segment"]

    # ---- guesses that follow the signature (pwsdyn.orbits._guesses) ----------------------
    @_same_doc(_guesses.follow)
    def follow(self, t0: float, x0, p=None, *, horizon: float | None = None) -> np.ndarray:
        return _guesses.follow(self, t0, x0, p, horizon=horizon)

    @_same_doc(_guesses.from_simulation)
    def from_simulation(self, t0: float, x0, p=None, *, horizon: float | None = None):
        return _guesses.from_simulation(self, t0, x0, p, horizon=horizon)

    # ---- admissibility (pwsdyn.orbits._admissibility) -------------------------------------
    @_same_doc(_admissibility.admissibility)
    def admissibility(self, u, p=None, evaluation: ProblemEvaluation | None = None
                      ) -> Admissibility:
        return _admissibility.admissibility(self, u, p, evaluation)

    # ---- monitors of discontinuity-induced bifurcations (pwsdyn.orbits.monitors) -----------
    @_same_doc(monitors.dib_monitors)
    def dib_monitors(self, u, p=None, evaluation: ProblemEvaluation | None = None) -> dict:
        return monitors.dib_monitors(self, u, p, evaluation)

    # ---- results (pwsdyn.orbits._results) --------------------------------------------------
    @_same_doc(_results.monodromy)
    def monodromy(self, ev: ProblemEvaluation) -> np.ndarray:
        return _results.monodromy(self, ev)

    @_same_doc(_results.boundary_saltation)
    def boundary_saltation(self, i: int, s) -> np.ndarray:
        return _results.boundary_saltation(self, i, s)

    @_same_doc(_results.multipliers)
    def multipliers(self, ev: ProblemEvaluation) -> np.ndarray:
        return _results.multipliers(self, ev)

    @_same_doc(_results.orbit)
    def orbit(self, u, p=None, *, t0=None, x_ref=None, phase_normal=None, history=None,
              converged: bool = True) -> PeriodicOrbit:
        return _results.orbit(self, u, p, t0=t0, x_ref=x_ref, phase_normal=phase_normal,
                              history=history, converged=converged)

    @_same_doc(_results.sensitivity)
    def sensitivity(self, u, p, name, *, t0=None, x_ref=None, phase_normal=None,
                    rel_step: float = 1e-4) -> OrbitSensitivity:
        return _results.sensitivity(self, u, p, name, t0=t0, x_ref=x_ref,
                                    phase_normal=phase_normal, rel_step=rel_step)


# ======================================================================================
# an orbit on a locked signature, and the orbit problem of a reported orbit
# ======================================================================================

def locked_orbit(model, x0, *, params, T, Tf, t0, mode, signature, phase, tol, max_iter,
                 options):
    """``find_periodic_orbit(..., signature=...)``: the orbit solved on a fixed signature
    (arguments validated by the caller)."""
    if isinstance(signature, str):
        try:
            signature = Signature.parse(signature)
        except ValueError as exc:
            raise ArgumentError(f"`signature`: {exc}") from None
    try:
        sig = Signature(signature)
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"`signature` must be a Signature (orbit.signature), a sequence of "
                            f"(kind, name, mode_before, mode_after) or its string: {exc}") \
            from None
    if sig:
        state = sig[0].mode_before
        if mode is not None and mode != state:
            raise ArgumentError(f"`mode` {mode!r} is not the state {state!r} of the segment "
                                f"the signature's first event ends (where the guess lies)")
    else:
        state = mode if mode is not None else model.mode_names[model.initial_mode]
    forced = Tf is not None
    periods = int(round(T / Tf)) if forced else 1
    kw = {}
    if not forced:
        ctx = model_context(model, params, options.get("sliding", "convex"))
        st = ctx.state(state)
        f0 = ctx.field(t0, x0, st, options.get("sliding_gain", 0.0))
        normal = f0 if phase is None else np.asarray(phase, dtype=float)
        if not np.any(normal) or abs(normal @ f0) <= 1e-8 * np.linalg.norm(normal) * \
                np.linalg.norm(f0):
            raise OrbitError("phase", "singular phase condition: the vector field vanishes at "
                             "the guess or the phase normal is tangent to the flow there")
        kw = dict(phase_ref=x0, phase_normal=normal)
    prob = OrbitProblem(model, sig, params=params, periods=periods, t_ref=t0, state=state,
                        **kw, **options)
    try:
        if sig:
            # the simulator's own events where they follow the signature; otherwise (a guess
            # past a grazing) each segment in its discrete state
            u0 = prob.from_simulation(t0, x0, horizon=None if forced else 2.5 * T)
            if u0 is None:
                u0 = prob.follow(t0, x0, horizon=None if forced else 2.0 * T)
        else:
            u0 = prob.pack(t0, [x0], [T])
    except ArgumentError as exc:
        raise OrbitError("signature", str(exc)) from None
    res = prob.solve(u0, tol=tol, max_iter=max_iter)
    if res.converged:
        try:
            return prob.orbit(res.x, t0=t0, x_ref=None if forced else x0,
                              phase_normal=None if forced else kw["phase_normal"],
                              history=res.history)
        except SegmentFailed as exc:
            raise OrbitError("simulation", exc.message, history=res.history) from None
    last = None
    try:
        last = prob.orbit(res.x, t0=t0, x_ref=None if forced else x0,
                          phase_normal=None if forced else kw["phase_normal"],
                          history=res.history, converged=False)
    except Exception:  # the last iterate may not even integrate; report what we have
        last = None
    reason = {"nonfinite": "simulation", "evaluation": "simulation"}.get(res.reason, res.reason)
    raise OrbitError(reason, f"Newton on the locked signature {sig}: {res.message}",
                     result=last, history=res.history)


# PeriodicOrbit.problem() and PeriodicOrbit.sensitivity() solve the orbit's problem: they are
# defined here and given to the result type, which imports no solver

def _orbit_problem(self, parameters=None):
    """The orbit problem of this orbit's signature and the orbit's unknowns:
    ``(OrbitProblem, u, p)`` (see :class:`~pwsdyn.orbits.OrbitProblem`; ``parameters``
    default all of the model's)."""
    if self._source is not None and (parameters is None or tuple(parameters)
                                     == self._source[0].parameters):
        return self._source
    prob, u = OrbitProblem.from_orbit(self, parameters=parameters)
    p = prob.p0.copy()
    # the orbit's events give u to the Newton tolerance; solve once more on the segments
    res = prob.solve(u, p)
    if res.converged:
        u = res.x
    src = (prob, u, p)
    if parameters is None:
        self._source = src
    return src

def _orbit_sensitivity(self, name: str):
    """Derivatives of the orbit with respect to parameter ``name`` along its branch.

    Returns an :class:`~pwsdyn.orbits.OrbitSensitivity`: ``x0`` (``d x0/d p``; forced
    orbits at the fixed time ``t0``, autonomous ones in the fixed section through ``x0``
    with normal ``phase_normal``), ``period`` (``d period/d p``), ``multipliers``
    (``d mu/d p`` of each of :attr:`multipliers`), and the derivatives of the events' times
    and states. They come from the orbit problem on the orbit's signature:
    ``du/dp = -F_u^-1 F_p`` (exact Jacobians), the multipliers by a central difference of
    the monodromy along that tangent (:meth:`~pwsdyn.orbits.OrbitProblem.sensitivity`).

    Examples
    --------
    >>> import pwsdyn
    >>> orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [0.0, -0.5])
    >>> d = orbit.sensitivity("sigma")
    >>> d.x0.shape
    (2,)
    """
    if not isinstance(name, str) or name not in self.model.parameters:
        raise V.fail("name", f"a parameter of model {self.model.name!r} "
                     f"{list(self.model.parameters)}", name)
    if not self.converged:
        raise ValueError("the orbit did not converge: it has no sensitivity")
    prob, u, p = _orbit_problem(self)
    if self.autonomous:
        return prob.sensitivity(u, p, name, x_ref=self.x0, phase_normal=self.phase_normal)
    return prob.sensitivity(u, p, name, t0=self.t0)


_orbit_problem.__name__ = "problem"
_orbit_problem.__qualname__ = "PeriodicOrbit.problem"
_orbit_sensitivity.__name__ = "sensitivity"
_orbit_sensitivity.__qualname__ = "PeriodicOrbit.sensitivity"
PeriodicOrbit.problem = _orbit_problem
PeriodicOrbit.sensitivity = _orbit_sensitivity
