"""Poincaré maps on event sections and stroboscopic sections, with their Jacobians.

An event section is the surface of a model event (an impact, a transition) or of a Filippov
switch; the map runs the compiled kernel until the ``returns``-th crossing of it (one kernel
call: the kernel's stop-at-the-k-th-event option) and projects the variational solution onto
the section with thesis eq. 2.25,

    P_x = (I - f_in h_x / (h_t + h_x f_in)) Phi_x,

where ``Phi_x`` is the flow Jacobian just before the crossing (with every saltation matrix on
the way). On the ``after`` side the reset is applied too: ``g_x P_x + g_t t_x``, for an
autonomous model the projected saltation matrix of thesis eq. 2.36 times ``Phi_x``.

A stroboscopic section of a forced model (``forcing_period`` in the model) samples the state
every ``returns`` forcing periods; its Jacobian is the flow Jacobian ``Phi_x`` itself (full
saltation matrices, no projection: the return time is fixed).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError, PwsdynError, SolveError, Status
from ..integrate.compiled import (AfterEvents, KernelState, ModelContext, check_state_name,
                                  event_states, initial_state, trajectory_start_state)
from ..integrate.options import integrator_options
from ..model.spec import as_model
from ..integrate.trajectory import EVENT_KINDS

if TYPE_CHECKING:
    from .._typing import ModelLike, StateLike

#: Kinds that count as a crossing of an event section / of a switch section.
_EVENT_SECTION_KINDS = ("impact", "transition")
_SWITCH_SECTION_KINDS = ("crossing", "slide_start")
#: Step budget of one Poincaré-map evaluation unless ``max_steps`` is given.
DEFAULT_MAX_STEPS = 200_000
#: Largest number of returns of one Poincaré-map evaluation.
MAX_RETURNS = 1_000_000


class SectionNotReachedError(PwsdynError, RuntimeError):
    """The flow did not reach the Poincaré section the requested number of times.

    Attributes
    ----------
    result : Trajectory
        The run up to where it stopped.
    crossings : int
        How many times the section was reached.
    """

    def __init__(self, message: str, result=None, crossings: int = 0):
        super().__init__(message)
        self.result = result
        self.crossings = crossings


@dataclass(eq=False)
class PoincareResult:
    """One evaluation of a Poincaré map and its Jacobian.

    Attributes
    ----------
    section : str
        The section: an event or switch name, or ``'stroboscopic'``.
    t0, x0 : float, numpy.ndarray
        Initial time and state.
    t, x : float, numpy.ndarray
        Time of the ``returns``-th crossing and the state there (on the requested side).
    jacobian : numpy.ndarray, shape (n, n)
        ``dx / dx0`` at fixed ``t0``: thesis eq. 2.25 (with the reset on the ``after`` side)
        for an event section; the flow Jacobian for a stroboscopic section.
    time_gradient : numpy.ndarray, shape (n,)
        ``dt / dx0`` (zero for a stroboscopic section).
    extended_jacobian : numpy.ndarray, shape (n + 1, n + 1)
        Derivative of ``(t, x)`` with respect to ``(t0, x0)`` (phase-extended state, time
        first), using ``dx(t)/dt0 = -Phi_x f(t0, x0)``. At a periodic point of a forced system
        its eigenvalues are the Floquet multipliers and 0 (event section: the projection
        direction) or 1 (stroboscopic section: the time direction).
    flow_jacobian : numpy.ndarray, shape (n, n)
        The unprojected ``Phi_x`` up to just before the crossing (event section) or to ``t``.
    side : {'before', 'after'}
    returns : int
    trajectory : Trajectory
        The run from ``t0`` to the crossing.
    event : EventRecord or None
        The crossing (``None`` for a stroboscopic section).
    """

    section: str
    t0: float
    x0: np.ndarray
    t: float
    x: np.ndarray
    jacobian: np.ndarray
    time_gradient: np.ndarray
    extended_jacobian: np.ndarray
    flow_jacobian: np.ndarray
    side: str
    returns: int
    trajectory: object
    event: object = None


def _initial_state(ctx: ModelContext, mode) -> KernelState:
    return initial_state(ctx, mode)


def _run(ctx, x0, t0, t_end, st0: KernelState, opts, stop=None):
    """One run of the layer, as the :class:`~pwsdyn.Trajectory` the result keeps."""
    res = ctx.run(np.asarray(x0, dtype=float), st0, float(t0), float(t_end), opts, stop=stop)
    traj = res.trajectory(ctx.model, opts, float(t0), float(t_end))
    if res.failed and opts["throw"]:
        raise res.solve_error(ctx.model, result=traj)
    return traj


def _options(options: dict, *, dense: bool, variational: bool = True) -> dict:
    opts = integrator_options({"max_steps": DEFAULT_MAX_STEPS, **options}, "poincare_map()",
                              ("variational", "throw", "mode"))
    opts.update(variational=variational, throw=False, dense=dense)
    return opts


def section_spec(ctx: ModelContext, section: str):
    """``(kind_mask, ref, surface, kinds)`` of an event or switch section name."""
    ev_names = [e.name for e in ctx.model.events]
    sw_names = [s.name for s in ctx.model.switches]
    if section in ev_names:
        kinds = _EVENT_SECTION_KINDS
        ref = ev_names.index(section)
        surface = int(ctx.etab[ref]["surface"])
    elif section in sw_names:
        kinds = _SWITCH_SECTION_KINDS
        ref = sw_names.index(section)
        surface = int(ctx.stab[ref]["surface"])
    else:
        raise ArgumentError(f"unknown section {section!r}: give 'stroboscopic' or the name of an "
                         f"event {ev_names} or switch {sw_names} of model {ctx.model.name!r}")
    mask = 0
    for k in kinds:
        mask |= 1 << EVENT_KINDS.index(k)
    return mask, ref, surface, kinds


def poincare_map(model: ModelLike, x0: StateLike, section: str, *,
                 params: Mapping[str, float] | None = None, t0: float = 0.0,
                 returns: int = 1, side: str = "after", mode: str | None = None,
                 t_max: float | None = None, **options: Any) -> PoincareResult:
    """Evaluate a Poincaré map and its Jacobian.

    The map and its Jacobian from the saltation matrices of its events (thesis eq. 2.25).

    Parameters
    ----------
    model : Model, str, path or dict
    x0 : sequence or dict
        Initial state (need not lie on the section).
    section : str
        The name of a model event (``impact``/``transition``: its surface, crossed in the
        event's direction where its guard holds; an impact that starts a complete chattering
        sequence is logged as ``chatter`` and does not count) or of a Filippov switch
        (crossings and sliding entries), or ``'stroboscopic'`` for the time-``returns * T``
        map of a forced model (``T = model.forcing_period_value(params)``).
    params : dict, optional
    t0 : float
        Initial time.
    returns : int
        Number of crossings of the section (or forcing periods) to map over.
    side : {'after', 'before'}
        For an event section, the state after the event's reset or before it (on the surface).
    mode : str, optional
        Initial discrete state: a mode name, ``stick:<event>`` or ``slide:<switch>``.
    t_max : float, optional
        Give up if the section is not reached by this time (default ``t0 + 100 returns T`` for
        forced models, unbounded otherwise, with a budget of ``max_steps`` steps, 200000 by
        default).
    **options
        Integrator options of :func:`pwsdyn.simulate` (``rtol``, ``atol``, ``method``, ...).

    Returns
    -------
    PoincareResult

    Raises
    ------
    SectionNotReachedError
        The flow did not reach the section ``returns`` times (the message says how often it
        did, and why the run stopped).
    SolveError
        The simulation itself failed.
    """
    dense = V.flag("dense", options.pop("dense", True))
    opts = _options(options, dense=dense)
    model = as_model(model, kind="flow", caller="poincare_map()")
    p = model.parameter_vector(params)
    x0 = V.state_vector(model, x0)
    names = ["stroboscopic"] + [e.name for e in model.events] + [s.name for s in model.switches]
    if not isinstance(section, str) or section not in names:
        raise ArgumentError(f"unknown section {V.describe(section)}: `section` must be "
                            f"'stroboscopic' or the name of an event "
                            f"{[e.name for e in model.events]} or switch "
                            f"{[s.name for s in model.switches]} of model {model.name!r}")
    t0 = V.number("t0", t0)
    returns = V.integer("returns", returns, lo=1, hi=MAX_RETURNS)
    side = V.choice("side", side, ("after", "before"))
    check_state_name(model, mode)
    t_max = V.number("t_max", t_max, allow_none=True)
    Tf = model.forcing_period_at(p)
    if section == "stroboscopic":
        if Tf is None:
            raise ArgumentError(f"model {model.name!r} has no `forcing_period`: it has no "
                                f"stroboscopic section")
        V.time_window("t0", t0, returns * Tf, what=f"{returns} forcing period(s)")
    else:
        if t_max is None:
            t_max = t0 + 100.0 * returns * Tf if Tf is not None else t0 + 1e12
        V.time_span("t_max", t0, t_max, what="the time allowed to reach the section")
    ctx = ModelContext(model, params, opts["sliding"] if "sliding" in opts else "convex")
    st0 = _initial_state(ctx, mode)
    n = ctx.n
    gain = float(opts.get("sliding_gain", 0.0) or 0.0)
    if section == "stroboscopic":
        t_end = t0 + returns * Tf
        traj = _run(ctx, x0, t0, t_end, st0, opts)
        if traj.status.failed:
            _raise_failed(ctx, traj)
        # the kernel starts on the side of each switching surface the state lies on
        st0 = trajectory_start_state(ctx, traj)
        f0 = ctx.field(t0, x0, st0, gain)
        J = traj.jacobian
        st_end = _end_state(ctx, traj, st0)
        f_end = ctx.field(t_end, traj.x_final, st_end, gain)
        ext = np.zeros((n + 1, n + 1))
        ext[0, 0] = 1.0
        ext[1:, 0] = f_end - J @ f0
        ext[1:, 1:] = J
        return PoincareResult(section, float(t0), x0, float(traj.t_final), traj.x_final.copy(), J,
                              np.zeros(n), ext, J, "after", int(returns), traj)
    mask, ref, k, kinds = section_spec(ctx, section)
    traj = _run(ctx, x0, t0, t_max, st0, opts,
                stop=AfterEvents(int(returns), kind=kinds, name=section))
    hits = [e for e in traj.events if e.kind in kinds and e.name == section]
    if traj.status != Status.TERMINAL_EVENT or len(hits) < returns:
        why = (f"the run stopped early ({traj.status.name}: {traj.message})"
               if traj.status.failed else f"t_max = {t_max:.6g} was reached")
        raise SectionNotReachedError(
            f"the flow reached section {section!r} {len(hits)} of {returns} time(s) from "
            f"t0 = {t0:.6g}; {why}. The section may not be visited from this state (check "
            f"`x0`, the event's direction and guard), or raise `t_max`/`max_steps`.",
            result=traj, crossings=len(hits))
    ev = traj.events[-1]
    tm = traj.transfer_matrices
    st0 = trajectory_start_state(ctx, traj)
    f0 = ctx.field(t0, x0, st0, gain)
    # flow Jacobian just before the last event: everything but its saltation and the
    # zero-length segment after it
    phi = tm[0].copy()
    for m in tm[1:-2]:
        phi = m @ phi
    st_b, st_a = event_states(ctx, traj.events, st0)[-1]
    f_in = ctx.field(ev.t, ev.x_before, st_b, gain)
    hx = ctx.h_x(k, ev.t, ev.x_before)
    den = ctx.h_t(k, ev.t, ev.x_before) + hx @ f_in
    if abs(den) <= 1e-13 * np.linalg.norm(hx) * max(np.linalg.norm(f_in), 1e-300):
        raise ArgumentError(f"the flow from this `x0` grazes `section` {section!r} at "
                            f"t={ev.t:.17g}: eq. 2.25 is singular there")
    proj = np.eye(n) - np.outer(f_in, hx) / den                # thesis eq. 2.25
    A = np.column_stack([-phi @ f0, phi])                      # d x(t_ev) / d(t0, x0)
    dt = -(hx @ A) / den
    dx = proj @ A
    x_out = ev.x_before.copy()
    if side == "after":
        x_out = ev.x_after.copy()
        if section in [e.name for e in ctx.model.events]:
            gx = ctx.g_x(ref, ev.t, ev.x_before)
            gt = ctx.g_t(ref, ev.t, ev.x_before)
            dx = gx @ dx + np.outer(gt, dt)
    ext = np.vstack([dt[None, :], dx])
    return PoincareResult(section, float(t0), x0, float(ev.t), x_out, dx[:, 1:].copy(),
                          dt[1:].copy(), ext, phi, side, int(returns), traj, ev)


def _end_state(ctx: ModelContext, traj, st0: KernelState) -> KernelState:
    if not traj.events:
        return st0
    return event_states(ctx, traj.events, st0)[-1][1]


def _raise_failed(ctx, traj):
    raise SolveError(traj.status, traj.t_final, dict(zip(ctx.model.states, traj.x_final)),
                     traj.state[-1], result=traj)
