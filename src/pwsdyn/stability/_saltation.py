"""Saltation matrices: the full form and the projected form.

Two forms are in use and they must not be mixed up; both come from the one formula,
:func:`event_map_saltation`, where their equations and sources are given:

``full``
    The jump of the variational solution, ``Phi+ = S Phi-``, for a perturbation compared at a
    common time. Products of flow Jacobians and full saltation matrices are Jacobians of
    time-``T`` maps; the monodromy matrix of an autonomous periodic orbit keeps its trivial
    multiplier 1 (eigenvector ``f``), since ``S f_in = f_out``. This is what the kernel applies
    (``Trajectory.jacobian``, ``Trajectory.transfer_matrices``).

``projected`` (the transfer matrices of COCO's ``hspo`` toolbox)
    The derivative of the point where the perturbed solution hits the surface, mapped by the
    reset, i.e. the Jacobian between Poincaré sections: the full form without the field after
    the event, ``S_p = S - f_out h_x / (h_t + h_x f_in)``. It kills the flow direction
    (``S_p f_in = 0``), so products have eigenvalue 0 where the full monodromy has 1.

Both are defined at events applied at the crossing time: ``impact`` and ``transition`` events
and the Filippov ``crossing`` and ``slide_start`` of a switch (``g`` the identity). Events that
do not change the field (``release``, ``slide_end``; ``S = I``) and the complete-chattering map
(a jump in time as well as in state) have the full form only. The chattering one is the
kernel's own (:func:`pwsdyn.integrate._kernel.chatter_saltation`): one formula, one answer.

Grazing: where the flow is tangent to the surface, ``|h_t + h_x f_in| <= GRAZING_RTOL |h_x|
|f_in|`` (``GRAZING_RTOL = 1e-13``, shared with the kernel), both forms are unbounded. The
functions here raise :class:`~pwsdyn.errors.ArgumentError` saying so; the kernel, which cannot
raise in the middle of a run, makes the event's saltation matrix all NaN (so
``Trajectory.transfer_matrices`` at that event and ``Trajectory.jacobian`` are NaN: the
variational result is marked singular, never silently finite without its singular term).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError
from .._codes import REGULAR, SLIDE
# event_map_saltation: the one saltation formula, kept importable from here
from ..integrate.compiled import (KernelState, ModelContext, check_state_name,  # noqa: F401
                                  event_map_saltation, event_states, trajectory_start_state)
from ..integrate.trajectory import DiscreteState
from ..model.spec import as_model

if TYPE_CHECKING:
    from .._typing import ModelLike, StateLike

#: Event kinds that have a projected (eq. 2.36) saltation matrix.
PROJECTABLE_KINDS = ("impact", "transition", "crossing", "slide_start")
FORMS = ("full", "projected")


def _check_form(form: str) -> str:
    return V.choice("form", form, FORMS)


def _check_trajectory(traj, name: str = "traj") -> None:
    """``traj`` is a Trajectory with transfer matrices (a run with ``variational=True``)."""
    from ..integrate.trajectory import Trajectory

    if not isinstance(traj, Trajectory):
        raise V.fail(name, "a Trajectory (the result of pwsdyn.simulate with "
                     "variational=True)", traj)
    if traj.transfer_matrices is None:
        raise ArgumentError(f"`{name}` has no transfer matrices: simulate it with "
                            "`variational=True`")


def _chatter_full(ctx: ModelContext, name: str, t: float, x_before, mode: int,
                  sliding_gain: float = 0.0) -> np.ndarray:
    """Full saltation matrix of the complete-chattering map (the layer's, the kernel's own)."""
    return ctx.chatter_saltation(name, t, x_before, mode, sliding_gain)


def _saltation_pair(ctx: ModelContext, kind: str, name: str, t: float, x_before, x_after,
                    st_before: KernelState, st_after: KernelState, sliding_gain: float = 0.0):
    """Full and projected saltation matrices at one event
    (:meth:`~pwsdyn.integrate.compiled.ModelContext.saltation`)."""
    return ctx.saltation(kind, name, t, x_before, x_after, st_before, st_after, sliding_gain)


def saltation_matrix(model: ModelLike, event: str, t: float, x: StateLike, *,
                     params: Mapping[str, float] | None = None, mode: str | None = None,
                     form: str = "full", sliding: str = "convex",
                     sliding_gain: float = 0.0, chatter: bool = False) -> np.ndarray:
    r"""Saltation matrix of a model event or switch at a point of its surface.

    Parameters
    ----------
    model : Model, str, path or dict
    event : str
        Name of an ``impact``/``transition`` event or of a Filippov switch.
    t : float
    x : array_like
        State just before the event, on the surface (``h(t, x) = 0``).
    params : dict, optional
    mode : str, optional
        The mode before the event (default: the event's first mode; for a switch, the side
        the flow arrives from, which must then be unique).
    form : {'full', 'projected'}
        ``full`` (slides, Adolfsson et al. 2001), the jump of the variational solution:

        .. math::

            S = g_x + \frac{(f_{out} - g_x f_{in} - g_t)\, h_x}{h_t + h_x f_{in}}.

        ``projected`` (thesis eq. 2.36), the Jacobian between Poincaré sections (COCO
        ``hspo``):

        .. math::

            S_p = g_x \left(I - \frac{f_{in} h_x}{h_t + h_x f_{in}}\right)
                - \frac{g_t h_x}{h_t + h_x f_{in}}.
    sliding, sliding_gain : str, float
        The sliding field's method and stabilising rate (as in :func:`pwsdyn.simulate`); the
        stabilising term vanishes on the surface.
    chatter : bool
        For an ``impact`` event: the saltation matrix of the complete-chattering map applied
        at this impact instead (the jump to the accumulation point of the impacts and on to
        sticking; ``form='full'`` only), the matrix :func:`pwsdyn.simulate` applies at a
        ``chatter`` event. Default False.

    Returns
    -------
    numpy.ndarray, shape (n, n)

    Raises
    ------
    ArgumentError
        The flow grazes the surface at ``x`` (``|h_t + h_x f_in| <= 1e-13 |h_x| |f_in|``): the
        saltation matrix is unbounded (see the module docstring; the kernel gives NaN there).

    Examples
    --------
    >>> import numpy as np, pwsdyn
    >>> S = pwsdyn.saltation_matrix("impact-oscillator", "impact", 0.3, [0.0, 1.0])
    >>> round(float(np.linalg.det(S)), 12)   # r^2 for Newton restitution, r = 0.8
    0.64
    """
    _check_form(form)
    if not isinstance(chatter, bool):
        raise V.fail("chatter", "True or False", chatter)
    if chatter and form != "full":
        raise ArgumentError("the complete-chattering map has no projected saltation matrix: "
                            "use form='full' with chatter=True")
    model = as_model(model, kind="flow", caller="saltation_matrix()")
    model.parameter_vector(params)
    names = [e.name for e in model.events] + [s.name for s in model.switches]
    if not isinstance(event, str) or event not in names:
        raise ArgumentError(f"unknown switch or event {V.describe(event)}: `event` must be "
                            f"the name of an event or switch of model {model.name!r} {names}")
    t = V.number("t", t)
    x = V.vector("x", x, size=model.n_states)
    check_state_name(model, mode)
    if mode is not None and not (isinstance(mode, str) and DiscreteState.parse(mode).is_mode):
        raise V.fail("mode", f"None or a mode of model {model.name!r} "
                     f"{list(model.mode_names)}", mode)
    sliding = V.choice("sliding", sliding, ("convex", "utkin"))
    sliding_gain = V.nonnegative("sliding_gain", sliding_gain)
    ctx = ModelContext(model, params, sliding)
    names = [e.name for e in ctx.model.events]
    if event in names:
        j = names.index(event)
        ev = ctx.model.events[j]
        m = ctx.model.mode_index(mode) if mode is not None else ev.modes[0]
        st_b = KernelState(REGULAR, -1, m)
        st_a = KernelState(REGULAR, -1, ev.target if ev.target is not None else m)
        kind = ev.kind
        x_after = ctx.g(j, t, x)
        if chatter:
            if kind != "impact":
                raise ArgumentError(f"chatter=True needs an impact event; {event!r} is a "
                                    f"{kind} event")
            return _chatter_full(ctx, event, t, x, m, sliding_gain)
    elif chatter:
        raise ArgumentError(f"chatter=True needs an impact event; {event!r} is a switch")
    else:
        s = ctx.switch_index(event)
        sw = ctx.stab[s]
        k, a, b = int(sw["surface"]), int(sw["above"]), int(sw["below"])
        ha = ctx.h_t(k, t, x) + ctx.h_x(k, t, x) @ ctx.mode_field(a, t, x)
        hb = ctx.h_t(k, t, x) + ctx.h_x(k, t, x) @ ctx.mode_field(b, t, x)
        if mode is None:
            arrive = [m for m, ok in ((a, ha < 0), (b, hb > 0)) if ok]
            if len(arrive) != 1:
                raise ArgumentError(f"give `mode`: the flow arrives at switch {event!r} from "
                                 f"{'both sides' if arrive else 'neither side'} here")
            m = arrive[0]
        else:
            m = ctx.model.mode_index(mode)
        st_b = KernelState(REGULAR, -1, m)
        if ha < 0 and hb > 0:
            kind, st_a = "slide_start", KernelState(SLIDE, s, a)
        else:
            kind, st_a = "crossing", KernelState(REGULAR, -1, b if m == a else a)
        x_after = x
    full, proj = _saltation_pair(ctx, kind, event, t, x, x_after, st_b, st_a, sliding_gain)
    return full if form == "full" else proj


def event_saltations(traj, form: str = "full") -> list:
    """The saltation matrix of each event of a trajectory, in the order of ``traj.events``.

    Parameters
    ----------
    traj : Trajectory
        With ``form='full'`` a run with ``variational=True`` (the matrices the kernel applied,
        ``traj.transfer_matrices[1::2]``).
    form : {'full', 'projected'}
        ``projected`` (thesis eq. 2.36) is computed from the model's derivatives at each event;
        it is ``None`` for events without a projected form (``chatter``, ``stick``,
        ``release``, ``slide_end``; see the module docstring).

    Returns
    -------
    list of numpy.ndarray (or None)
    """
    _check_form(form)
    if form == "full":
        _check_trajectory(traj)
        return list(traj.transfer_matrices[1::2])
    ctx = ModelContext(traj.model, traj.params, traj.options.get("sliding", "convex"))
    gain = float(traj.options.get("sliding_gain", 0.0) or 0.0)
    states = event_states(ctx, traj.events, trajectory_start_state(ctx, traj))
    out = []
    for e, (sb, sa) in zip(traj.events, states):
        if e.kind in PROJECTABLE_KINDS:
            out.append(_saltation_pair(ctx, e.kind, e.name, e.t, e.x_before, e.x_after, sb, sa,
                                       gain)[1])
        else:
            out.append(None)
    return out
