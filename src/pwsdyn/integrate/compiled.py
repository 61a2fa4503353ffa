"""The compiled model at parameter values: the one layer between the kernel and the analyses.

Every analysis above the integrator (stability, periodic orbits, continuation, grazing,
exploration) and :func:`pwsdyn.simulate` itself reach the compiled kernel through this module
only. It holds

* :class:`ModelContext`: a compiled model (a flow or a map) with one parameter vector, and its
  named point evaluations: surface ``h`` with ``h_x`` and ``h_t``; the normal velocity
  ``hdot = h_t + h_x f_i`` of a mode, its gradient, rate and the normal acceleration
  ``d/dt hdot`` along a field (the terms of the sticking and sliding conditions, thesis eq.
  2.6-2.8); the vector field of a discrete state (the kernel's own, so sticking and sliding
  fields are the ones integrated); a reset ``g`` with ``g_x`` and ``g_t``; and the saltation
  matrix of an event (:meth:`ModelContext.saltation`, from :func:`event_map_saltation`, the
  one saltation formula of the Python side; thesis eq. 2.36);
* one run entry point, :meth:`ModelContext.run` (and :func:`run_compiled` for a compiled
  model without a context): a start state and discrete state, a time span, a stop condition
  (:class:`AfterEvents`, :class:`AtTime`), stroboscopic sampling and the variational
  equations on or off. It returns a :class:`RunResult` of plain arrays (end state, event
  columns, samples, Jacobians); :meth:`RunResult.trajectory` builds a
  :class:`~pwsdyn.Trajectory` from it only where one is wanted;
* :class:`KernelState`, the kernel's code of a discrete state, and the helpers that translate
  discrete-state names (``"flight"``, ``"stick:impact"``, ``"slide:slip"``) into it.

Stop conditions are small named types; the kernel's integer encoding (a kind bit mask, an
event or switch index, a count) is made here only (:meth:`AfterEvents.code`).
"""

from __future__ import annotations

import copy
import threading
from dataclasses import dataclass
from typing import Mapping

import numpy as np
import sympy as sp

from .._version import __version__
from .. import _validate as V
from ..errors import ArgumentError, SolveError, Status
from ..model import compile_model, load_model
from ..model.codegen import (W_F, W_G, W_GT, W_GUARD, W_GX, W_H, W_HD, W_HDT, W_HDX, W_HT,
                             W_HX)
from ..model.spec import as_model
from ._codes import (EVENT_LOG_KINDS, REGULAR, SAVE_DENSE, SAVE_EVENTS, SAVE_NODES, SLIDE,
                     SLIDE_MULTI, STATS,
                     STICK, VAR_NONE, VAR_SEGMENTS, KernelResult, kernel_options)
from ._intersection import intersection_detail
from ._load import kernel
from ._start import ADMIT_BEHIND, Start, abs_max, start_state
from ._variational import assemble_segments, segments_jacobian
from .options import (DEFAULT_CHATTER_RATIO, _check_options, _exact_code, _max_step,
                      kernel_tables, resolve_method)
from .tableaus import METHODS
from .trajectory import DiscreteState, EventLog, LazyDense, Trajectory

__all__ = ["AfterEvents", "AtTime", "KernelState", "ModelContext", "RunResult", "Start",
           "check_state_name", "event_map_saltation", "event_states", "initial_state",
           "load_kernel", "run_compiled", "trajectory_start_state"]


# --------------------------------------------------------------------------------------
# stop conditions
# --------------------------------------------------------------------------------------

#: Event kinds that name a model event (``ref`` its event index) and a switch (``ref`` its
#: switch index) in the kernel's event log.
_EVENT_REF_KINDS = ("impact", "transition", "chatter", "stick", "release")
_SWITCH_REF_KINDS = ("crossing", "slide_start", "slide_end")


@dataclass(frozen=True)
class AfterEvents:
    """Stop the run at the ``n``-th logged event of a kind and/or name (status
    ``TERMINAL_EVENT``).

    ``kind``: None (any), one kind of the event log (``"impact"``, ``"transition"``,
    ``"chatter"``, ``"stick"``, ``"release"``, ``"crossing"``, ``"slide_start"``,
    ``"slide_end"``) or a tuple of them. ``name``: None (any) or the name of a model event
    or switch; with a name and no kind, the kinds that name can log (an event's impact,
    transition, chatter, stick and release; a switch's crossing, slide start and end)."""

    n: int = 1
    kind: str | tuple | None = None
    name: str | None = None

    def __post_init__(self):
        V.integer("n", self.n, lo=1, hi=V.MAX_COUNT)
        kinds = (self.kind,) if isinstance(self.kind, str) else self.kind
        if kinds is not None:
            bad = [k for k in kinds if k not in EVENT_LOG_KINDS]
            if bad or not kinds:
                raise V.fail("kind", f"None, one of {list(EVENT_LOG_KINDS)} or a tuple of them",
                             self.kind)

    def code(self, model) -> tuple[int, int, int]:
        """The kernel's ``(kind_mask, ref, count)`` for ``model``."""
        kinds = (self.kind,) if isinstance(self.kind, str) else self.kind
        ref = -1
        if self.name is not None:
            ev_names = [e.name for e in model.events]
            sw_names = [s.name for s in model.switches]
            if self.name in ev_names:
                ref, allowed = ev_names.index(self.name), _EVENT_REF_KINDS
            elif self.name in sw_names:
                ref, allowed = sw_names.index(self.name), _SWITCH_REF_KINDS
            else:
                raise ArgumentError(f"`name` must be an event {ev_names} or a switch "
                                    f"{sw_names} of model {model.name!r}, got {self.name!r}")
            kinds = allowed if kinds is None else tuple(k for k in kinds if k in allowed)
            if not kinds:
                raise ArgumentError(f"{self.name!r} logs no event of kind {self.kind!r}")
        if kinds is None:
            mask = (1 << len(EVENT_LOG_KINDS)) - 1
        else:
            mask = 0
            for k in kinds:
                mask |= 1 << EVENT_LOG_KINDS.index(k)
        return mask, ref, int(self.n)


@dataclass(frozen=True)
class AtTime:
    """Stop the run at time ``t`` (the end of the time span: ``run(..., t_end=t)``)."""

    t: float


def _stop_code(stop, model):
    """The kernel's stop triple of ``stop`` (None, :class:`AfterEvents`, or the triple)."""
    if stop is None or isinstance(stop, AtTime):
        return None
    if isinstance(stop, AfterEvents):
        return stop.code(model)
    if isinstance(stop, tuple) and len(stop) == 3:
        return stop
    raise V.fail("stop", "None, AfterEvents(...) or AtTime(t)", stop)


# --------------------------------------------------------------------------------------
# the run and its lean result
# --------------------------------------------------------------------------------------

def _state_name(model, kind: int, idx: int, mode: int) -> DiscreteState:
    """The discrete state of the kernel's code ``(kind, index, mode)``."""
    if kind == 0:
        return DiscreteState("mode", model.modes[mode].name)
    if kind == 1:
        return DiscreteState("stick", model.events[idx].name)
    if kind == SLIDE_MULTI:
        return DiscreteState("slide_multi", _multi_name(model, idx))
    return DiscreteState("slide", model.switches[idx].name)


def _multi_name(model, mask: int) -> str:
    """The name of sliding on the intersection of the surfaces of the bit mask ``mask``: their
    names joined by ``&`` in increasing index (``slide_multi:v1&v2``)."""
    return "&".join(model.surfaces[k].name for k in range(len(model.surfaces)) if mask >> k & 1)


#: One-entry arrays of the discrete states' names, by model digest and kernel code.
_LABELS: dict = {}


def _label_array(model, code: tuple) -> np.ndarray:
    """``np.array([name], dtype=str)`` of the discrete state ``code`` of ``model`` (the
    names are part of the digest)."""
    key = (model.digest, code)
    arr = _LABELS.get(key)
    if arr is None:
        if len(_LABELS) >= 4096:
            _LABELS.clear()
        arr = _LABELS[key] = np.array([_state_name(model, *code)], dtype=str)
        arr.flags.writeable = False
    return arr


class RunResult:
    """What one kernel run gives back, as plain arrays (no :class:`~pwsdyn.Trajectory`).

    Attributes
    ----------
    status : Status
    t : float
        The end time; ``x`` the end state (``n`` entries), ``state`` its discrete state
        (:class:`KernelState`).
    event_t, event_t_after : numpy.ndarray
        Event log columns: time, and time after the event (later than ``t`` for a
        complete-chattering jump); ``event_kind`` the kind codes (index into
        ``EVENT_LOG_KINDS``), ``event_ref`` the event or switch index,
        ``event_state_before``/``event_state_after`` the kernel's ``(kind, index, mode)``
        rows, ``event_x_before``/``event_x_after`` the states (``m x n``).
    samples_t, samples_x : numpy.ndarray or None
        Stroboscopic samples of a run with ``sample=``.
    start_kind : int
        The kind of discrete state the run started in (0 a mode, 1 sticking, 2 sliding), after
        the start rule: a state at rest on an impact constraint starts sticking without any
        event at ``t0``, and the per-period measures of the analyses count that time.
    jacobian : numpy.ndarray or None
        ``dx(t)/dx0`` of a variational run; ``transfer_matrices`` the flow Jacobian of each
        smooth segment and the full saltation matrix of each event.
    stats : dict
        Steps, rejected steps, function evaluations, events, chattering sequences, landing
        steps.
    """

    __slots__ = ("status", "t", "x", "event_t", "event_t_after", "samples_t", "samples_x",
                 "start_kind", "jacobian", "transfer_matrices", "_raw", "_run", "_stats", "_model",
                 "_events", "_xb", "_xa")

    # the columns below are views of (or, for the states, copies made once from) the
    # kernel's arrays, made when read: simulate() reads none of them, and a one-period run
    # cost about as much in making them as in integrating

    @property
    def state(self) -> "KernelState":
        return KernelState(*self._raw.state.tolist())

    @property
    def event_kind(self) -> np.ndarray:
        return self._raw.ev_info[:, 0]

    @property
    def event_ref(self) -> np.ndarray:
        return self._raw.ev_info[:, 1]

    @property
    def event_state_before(self) -> np.ndarray:
        return self._raw.ev_info[:, 2:5]

    @property
    def event_state_after(self) -> np.ndarray:
        return self._raw.ev_info[:, 5:8]

    @property
    def event_x_before(self) -> np.ndarray:
        if self._xb is None:
            self._xb = self._raw.ev_xb[:, :self.x.shape[0]].copy()
        return self._xb

    @property
    def event_x_after(self) -> np.ndarray:
        if self._xa is None:
            self._xa = self._raw.ev_xa[:, :self.x.shape[0]].copy()
        return self._xa

    @property
    def failed(self) -> bool:
        return self.status.failed

    @property
    def message(self) -> str:
        if self.status == Status.SURFACE_INTERSECTION:
            # where it stopped and why sliding could not go on (the surface reached)
            return str(self.solve_error(self._model))
        return self.status.message

    @property
    def stats(self) -> dict:
        return dict(zip(STATS, self._stats.tolist()))

    @property
    def n_events(self) -> int:
        return len(self.event_t)

    @property
    def final_discrete_state(self) -> tuple:
        """The end's discrete state as the kernel's ``(kind, index, mode)`` (what
        ``Trajectory.final_discrete_state`` holds)."""
        return tuple(self._raw.state.tolist())

    @property
    def events(self) -> EventLog:
        """The event log of the run's model (:meth:`event_log`), made once."""
        if self._events is None:
            self._events = self.event_log(self._model)
        return self._events

    def event_kinds(self) -> np.ndarray:
        """The event kinds by name (``"impact"``, ...), one per logged event."""
        return np.asarray(EVENT_LOG_KINDS, dtype=object)[self.event_kind]

    def event_log(self, model) -> EventLog:
        """The events as an :class:`~pwsdyn.integrate.trajectory.EventLog` (records made
        when read)."""
        raw = self._raw
        return EventLog(model, raw.ev_t, raw.ev_t2, raw.ev_info, self.event_x_before,
                        self.event_x_after, _state_name)

    def trajectory(self, model, opts, t0: float, t_end: float) -> Trajectory:
        """The :class:`~pwsdyn.Trajectory` of this run (``opts``: the options it ran with;
        ``model`` the model it carries)."""
        return run_trajectory(self, model, opts, t0, t_end)

    def solve_error(self, model, result=None) -> SolveError:
        """The :class:`~pwsdyn.errors.SolveError` of a failed run."""
        raw = self._raw
        n = model.n_states
        detail = (intersection_detail(self, model)
                  if self.status == Status.SURFACE_INTERSECTION else "")
        return SolveError(self.status, float(raw.t), dict(zip(model.states, raw.y[:n])),
                          _state_name(model, *raw.state), result=result, detail=detail)


def _node_states(model, nodes_s) -> np.ndarray:
    """The discrete state of every node (kernel codes ``nodes_s``) as names."""
    # mapped through the few distinct codes (vectorised: runs can have millions of nodes)
    N = len(nodes_s)
    if N and (nodes_s == nodes_s[0]).all():
        # one discrete state throughout (most short runs): the same array, fewer steps
        return np.repeat(_label_array(model, tuple(nodes_s[0].tolist())), N)
    d = nodes_s[1:] != nodes_s[:-1]
    starts = np.concatenate(([0], np.flatnonzero(d[:, 0] | d[:, 1] | d[:, 2]) + 1))[:N]
    label: dict = {}
    for code in map(tuple, nodes_s[starts].tolist()):
        if code not in label:
            label[code] = _state_name(model, *code)
    run_names = np.array([label[c] for c in map(tuple, nodes_s[starts].tolist())], dtype=str)
    return (np.full(N, run_names[0]) if len(starts) == 1 else
            np.repeat(run_names, np.diff(np.append(starts, N))))


class _TrajectoryParts:
    """Makes the deferred fields of a run's trajectory (:class:`pwsdyn.integrate.trajectory.
    _Deferred`) from the run's arrays when they are first read.

    ``model`` is the model the run used, read only for names (states, modes, events,
    parameters) and its digest and hash; ``copy`` (or None) makes the model the trajectory
    hands out: a model given by name runs on the loaded original
    (:func:`pwsdyn.model.spec.loaded_original`), which is never handed out, and the
    trajectory's own copy is made only if ``traj.model`` (or the event log, which holds it)
    is read."""

    __slots__ = ("res", "model", "copy", "opts", "t0")

    def __init__(self, res, model, copy, opts, t0):
        self.res, self.model, self.copy, self.opts, self.t0 = res, model, copy, opts, t0

    def __call__(self, traj, name):
        res, model, opts = self.res, self.model, self.opts
        raw = res._raw
        if name == "state":
            return _node_states(model, raw.nodes_s)
        if name == "model":
            return model if self.copy is None else self.copy()
        if name == "events":
            # the event log as arrays; its records are made when it is read (sweeps read
            # columns); it holds the trajectory's model
            return res.event_log(traj.model)
        if name == "stats":
            return dict(zip(STATS, res._stats.tolist()))
        cm, pv, etab, stab, kopts, tab, x_start, method = res._run
        if name == "params":
            return dict(zip(model.parameters, pv.tolist()))
        if name == "options":
            return {**{k: v for k, v in opts.items() if k != "throw"}, "method": method}
        if name == "provenance":
            return {"model": model.name, "model_hash": model.hash,
                    "pwsdyn_version": __version__}
        if name == "_dense":
            if not opts["dense"]:
                return None
            if kopts[0]["save"] == SAVE_NODES:
                return _lazy_dense(cm, pv, etab, stab, kopts, tab, float(self.t0), x_start,
                                   raw.nodes_t, raw.nodes_y, raw.nodes_s, raw.hstep,
                                   raw.dense.shape[2])
            return raw.dense
        raise AttributeError(name)


def run_trajectory(res, model, opts, t0, t_end, copy=None) -> Trajectory:
    """:meth:`RunResult.trajectory`; ``copy`` (a model given by name): makes the model the
    trajectory hands out, ``model`` being the loaded original the run read
    (:class:`_TrajectoryParts`).

    The arrays and scalars are set now; the other fields when first read (the values are
    those :class:`~pwsdyn.Trajectory`'s constructor would have been given)."""
    raw = res._raw
    n = model.n_states
    tr = Trajectory.__new__(Trajectory)
    d = tr.__dict__
    d.update(t=raw.nodes_t, x=raw.nodes_y[:, :n].copy(), status=res.status,
             message=res.message, t0=t0, t_end=t_end, jacobian=res.jacobian,
             transfer_matrices=res.transfer_matrices,
             final_discrete_state=tuple(raw.state.tolist()),
             samples=None if res.samples_t is None else (res.samples_t, res.samples_x),
             _ikind=raw.ikind, _y=raw.nodes_y,
             # (the options as they are now: a caller may reuse and change its dict)
             _make=_TrajectoryParts(res, model, copy, dict(opts), t0))
    if copy is None:
        d["model"] = model
    return tr


def load_kernel() -> None:
    """Compile the integrator (or load it from numba's cache) now, in this process, with its
    notice (``integrate._load.kernel``): a caller about to hand runs to workers
    does it once, before them."""
    kernel()


def _lazy_dense(cm, p, etab, stab, kopts, tab, t0, x0, nodes_t, nodes_y, nodes_s, hstep,
                deg) -> LazyDense:
    """The dense output of a ``SAVE_NODES`` run, rebuilt from its nodes when it is read
    (:func:`pwsdyn.integrate._kernel.dense_coefficients`)."""
    ev = cm.evaluate

    def rebuild(which):
        return kernel().dense_coefficients(ev, p, etab, stab, kopts, tab.A, tab.C, tab.P,
                                           tab.n_stages, t0, x0, nodes_t, nodes_y, nodes_s,
                                           hstep, np.ascontiguousarray(which, dtype=np.int64),
                                           deg)

    return LazyDense((len(hstep), nodes_y.shape[1], deg), rebuild)


#: Kernel option records by the values they are made from (:func:`run_compiled`).
_KOPTS: dict = {}
#: The run statuses by the kernel's code.
_STATUS = {int(s): s for s in Status}


def run_compiled(cm, x, t0, t_end, p, opts, mode0=None, dkind0=None, didx0=None, stop=None,
                 sample=None, admit=True, refuse=False, store_dense=False, model=None,
                 checked=False, jacobian_only=False) -> RunResult:
    """One kernel run of the compiled model ``cm`` at parameter vector ``p`` with the merged
    options ``opts`` (:func:`pwsdyn.integrate.options.integrator_options`), without
    re-validating model, state or parameters.

    ``dkind0``, ``didx0``: initial discrete state (0 mode, 1 sticking on event ``didx0``, 2
    sliding on switch ``didx0``; default a regular mode ``mode0``, else ``opts["mode"]``, else
    the model's initial mode). A start in a regular mode goes through
    ``integrate._start.start_state`` (``admit``, default True): a state on an
    impact constraint (within round-off or the position tolerance ``atol + rtol |x|``) starts
    sticking, with the impact at ``t0`` or in free motion, and one a little behind it
    (``ADMIT_BEHIND``) is put on it first; one further behind raises :class:`~pwsdyn.ArgumentError`
    with ``refuse`` (the public entry points) and is left alone otherwise. Newton iterations
    (shooting) pass ``admit=False``: they integrate exactly the state they are given.
    ``stop``: None, :class:`AfterEvents` or :class:`AtTime` (``t_end`` then stays the
    caller's). ``sample = (t_first, dt)`` records the state at ``t_first + k dt`` (``k >=
    0``, within the run) from the dense output, without events or landing steps.
    ``store_dense`` stores the dense output of every step as the run goes (as variational
    runs do) instead of rebuilding it from the nodes when it is read. ``model``: the model
    (default ``cm.model``; one with the same digest). ``checked``: ``opts`` passed
    :func:`~pwsdyn.integrate.options.check_options` already. ``jacobian_only`` (a
    variational run): the result's ``jacobian`` only, ``transfer_matrices`` None and its
    nodes and event states' variational parts left per segment, so no
    :meth:`RunResult.trajectory` is to be made from it (Newton iterations read the end state,
    the Jacobian and the events' states). Never raises for a failed run: the status says it.
    """
    if not checked:
        _check_options(opts)
    if model is None:
        model = cm.model
    if isinstance(stop, AtTime):
        t_end = float(stop.t)
    method = resolve_method(opts)
    tab = METHODS[method]
    etab, eact, stab = kernel_tables(cm, opts.get("sliding", "convex"))
    if mode0 is None:
        mode0 = model.initial_mode if opts["mode"] is None else model.mode_index(opts["mode"])
    if admit and not dkind0 and len(etab):
        x = np.asarray(x, dtype=float)
        xmax = abs_max(x) if x.size else 0.0
        st = start_state(cm, etab, eact, stab, t0, x, p, int(mode0),
                         pos_tol=opts["atol"] + opts["rtol"] * xmax,
                         behind_tol=ADMIT_BEHIND * (1.0 + xmax), refuse=refuse)
        x = st.x
        if st.kind == STICK:
            mode0, dkind0, didx0 = st.mode, st.kind, st.index
    K = kernel()  # compiled on the first run in this process (see integrate._load)
    # dense output: rebuilt on demand from the nodes and step lengths (SAVE_NODES), except
    # with the variational equations, whose nodes are transformed after the run
    save = (SAVE_EVENTS if not opts["dense"] else
            SAVE_DENSE if opts["variational"] or store_dense else SAVE_NODES)
    stop_code = _stop_code(stop, model)
    dkind0 = 0 if dkind0 is None else dkind0
    didx0 = -1 if didx0 is None else didx0
    exact = _exact_code(model, opts["exact"])
    max_step = _max_step(model, p, opts["max_step"])
    # the record is a function of these values (and of the types of those a caller passes,
    # which kernel_options checks): loops pass the same ones on every call. The kernel
    # reads the record only, so runs share it.
    key = (mode0, type(mode0), dkind0, type(dkind0), didx0, type(didx0), len(model.modes),
           tab.code, tab.order, opts["variational"], opts["chatter"], save, stop_code,
           None if stop_code is None else tuple(map(type, stop_code)), sample, exact,
           max_step, opts["max_steps"], opts["max_events"], opts["rtol"], opts["atol"],
           opts["first_step"], opts["chatter_ratio"], opts["chatter_velocity"],
           opts["sliding_gain"])
    try:
        kopts = _KOPTS.get(key)
    except TypeError:       # an unhashable value (a list for ``sample``): made every time
        key = kopts = None
    if kopts is None:
        kopts = kernel_options(
            mode0=mode0, n_modes=len(model.modes), max_steps=opts["max_steps"],
            max_events=opts["max_events"], method=tab.code, order=tab.order,
            variational=VAR_SEGMENTS if opts["variational"] else VAR_NONE,
            chatter=opts["chatter"], save=save, stop=stop_code, dkind0=dkind0, didx0=didx0,
            exact=exact, rtol=opts["rtol"], atol=opts["atol"],
            first_step=opts["first_step"] or 0.0, max_step=max_step,
            # negative: the default ratio, applied where the map is accurate
            chatter_ratio=(-DEFAULT_CHATTER_RATIO if opts["chatter_ratio"] is None
                           else opts["chatter_ratio"]),
            chatter_velocity=(-1.0 if opts["chatter_velocity"] is None
                              else opts["chatter_velocity"]),
            sliding_gain=opts["sliding_gain"], sample=sample)
        if key is not None:
            if len(_KOPTS) >= 1024:
                _KOPTS.clear()
            _KOPTS[key] = kopts
    pv = np.ascontiguousarray(p if p.size else np.zeros(1), dtype=float)
    x = np.array(x, dtype=float)
    raw = KernelResult(*K.run_kernel(cm.evaluate, float(t0), float(t_end), x, pv, etab, eact,
                                     stab, kopts, tab.A, tab.C, tab.E, tab.P, tab.n_stages))
    n = model.n_states
    r = RunResult()
    r.jacobian = r.transfer_matrices = None
    if opts["variational"] and jacobian_only:
        r.jacobian = segments_jacobian(n, raw.ev_info, raw.ev_xb, raw.ev_xa, raw.y)
    elif opts["variational"]:
        # per-segment transfer matrices; Phi made global in nodes, dense output and events
        r.transfer_matrices, r.jacobian = assemble_segments(n, raw.nodes_y, raw.dense,
                                                            raw.ev_info, raw.ev_xb, raw.ev_xa,
                                                            raw.y)
    r._raw = raw
    r._run = (cm, pv, etab, stab, kopts, tab, x, method)
    r._stats = raw.stats
    r._model = model
    r._events = None
    status = _STATUS.get(raw.status)
    r.status = Status(int(raw.status)) if status is None else status
    # the end as the trajectory's last node (``Trajectory.x_final``), the kernel's end state
    # for a run without nodes
    if len(raw.nodes_t):
        r.t, r.x = float(raw.nodes_t[-1]), raw.nodes_y[-1, :n]
    else:
        r.t, r.x = float(raw.t), raw.y[:n]
    r.event_t, r.event_t_after = raw.ev_t, raw.ev_t2
    r._xb = r._xa = None
    r.start_kind = int(dkind0)
    if sample is not None:
        r.samples_t, r.samples_x = raw.samples[:, 0].copy(), raw.samples[:, 1:].copy()
    else:
        r.samples_t = r.samples_x = None
    return r


# --------------------------------------------------------------------------------------
# the saltation formula (thesis eq. 2.36)
# --------------------------------------------------------------------------------------

def event_map_saltation(X_x, X_t, f_in, f_out, c_x, den, tau_x=None,
                        tau_t: float = 1.0) -> np.ndarray:
    r"""The saltation formula, the one every Python caller uses (the compiled kernel keeps
    its own copy, ``_event_saltation``, with the same order of operations).

    For an event map ``(t, x) -> (tau, X)`` applied where ``c(t, x) = 0``, with ``f_in`` the
    field before the event and ``f_out`` the field after it, at ``(tau, X)``:

    .. math::

        S = C + \frac{(f_{out} \tau_t - C f_{in} - X_t)\, c_x}{c_t + c_x f_{in}},
        \qquad C = X_x - f_{out} \tau_x.

    A reset ``x -> g(t, x)`` (``tau = t``: ``tau_x = 0``, ``tau_t = 1``) gives the full
    saltation matrix of the slides ("Saltation matrices"; Adolfsson et al. 2001),
    ``S = g_x + (f_out - g_x f_in - g_t) h_x / (h_t + h_x f_in)``; with ``f_out = 0`` it is
    the projected form of thesis eq. 2.36,
    ``S_p = g_x (I - f_in h_x / (h_t + h_x f_in)) - g_t h_x / (h_t + h_x f_in)`` (eq. 2.36
    exactly for time-independent ``h`` and ``g``; the ``h_t``, ``g_t`` terms are the time
    components of the same projection in phase-extended state space). The
    complete-chattering map moves time as well (the kernel's ``_chatter_saltation``).

    Parameters
    ----------
    X_x, X_t : numpy.ndarray
        Derivatives of the new state ``X`` in ``x`` (n x n) and in ``t`` (n).
    f_in, f_out : numpy.ndarray
        The fields before and after the event (``f_out = 0`` for the projected form).
    c_x : numpy.ndarray
        Gradient of the event function ``c`` in ``x``.
    den : float
        ``c_t + c_x f_in``, the rate at which the flow crosses the surface; the caller
        checks it for grazing (zero gives an infinite matrix, ``inf``/``nan`` entries).
    tau_x, tau_t : numpy.ndarray or None, float
        Derivatives of the new time ``tau`` in ``x`` and ``t`` (default: a reset, ``None``
        for ``tau_x = 0`` and ``tau_t = 1``).
    """
    C = X_x if tau_x is None else X_x - np.outer(f_out, tau_x)
    return C + np.outer(f_out * tau_t - C @ f_in - X_t, c_x) / den


# --------------------------------------------------------------------------------------
# the compiled model at parameter values
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class KernelState:
    """A discrete state as the kernel codes it: ``kind`` 0 regular mode, 1 sticking on impact
    event ``index``, 2 sliding on switch ``index``; ``mode`` the mode index (for sticking the
    mode whose field is constrained). :meth:`ModelContext.state` and
    :meth:`ModelContext.state_name` translate to and from
    :class:`~pwsdyn.integrate.trajectory.DiscreteState`."""

    kind: int
    index: int
    mode: int


#: The contexts of this process by model hash (:meth:`ModelContext.get`); worker threads
#: share them, so each model is built once per process.
_CONTEXTS: dict = {}
_CONTEXTS_LOCK = threading.RLock()


class ModelContext:
    """A compiled model with parameter values: point evaluations and runs for the analyses.

    The evaluations (``h``, ``h_x``, ``h_t``, ``hdot``, ``acceleration``, ``field``, ``g``,
    ``g_x``, ``g_t``, ``saltation``, ...) are named methods; :meth:`run` is the one way to
    integrate (:func:`run_compiled` at this context's parameters, or another vector ``p``).

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
        Anything :func:`pwsdyn.load_model` accepts.
    params : dict, optional
        Parameter values by name (defaults of the model otherwise).
    sliding : str
        The sliding method of Filippov switches (the ``sliding`` option of
        :func:`pwsdyn.simulate`).
    kind : {'flow', 'map', None}
        The kind of model required (None: either).

    Attributes
    ----------
    model : Model or MapModel
    is_map : bool
    cm : CompiledModel or CompiledMap
    p : numpy.ndarray
        The parameter vector; ``params`` the same by name.
    """

    def __init__(self, model, params: Mapping[str, float] | None = None,
                 sliding: str = "convex", *, kind: str | None = "flow"):
        self.model = as_model(model, kind=kind)
        self.is_map = bool(getattr(self.model, "is_map", False))
        self.p = self.model.parameter_vector(params)
        self.params = dict(zip(self.model.parameters, (float(v) for v in self.p)))
        self.n = self.model.n_states
        if self.is_map:
            from ..model.maps import compile_map

            self.cm = compile_map(self.model)
            return
        self.cm = compile_model(self.model)
        self._pv = np.ascontiguousarray(self.p if self.p.size else np.zeros(1), dtype=float)
        self.etab, self.eact, self.stab = kernel_tables(self.cm, sliding)
        self.nm = len(self.model.modes)

    def with_params(self, params: Mapping[str, float] | None) -> "ModelContext":
        """The same context at other parameter values (by name; the model's defaults for the
        others): the compiled model and its tables are shared, only the parameter vector is
        new (an analysis that moves along a parameter asks for one context per value)."""
        new = copy.copy(self)
        new.p = self.model.parameter_vector(params)
        new.params = dict(zip(self.model.parameters, (float(v) for v in new.p)))
        if not self.is_map:
            new._pv = np.ascontiguousarray(new.p if new.p.size else np.zeros(1), dtype=float)
        return new

    @classmethod
    def get(cls, payload_or_model) -> "ModelContext":
        """The context of a model in this process, built once: from a model (anything
        :func:`pwsdyn.load_model` accepts) or from the payload a worker receives (``spec``,
        ``origin`` and ``hash`` of the model: a worker never receives compiled functions).
        A flow or a map, with the model's default parameters."""
        with _CONTEXTS_LOCK:
            if isinstance(payload_or_model, dict):
                key = payload_or_model["hash"]
                if key not in _CONTEXTS:
                    from ..model.spec import model_from_dict

                    model = model_from_dict(dict(payload_or_model["spec"]),
                                            origin=payload_or_model["origin"])
                    if model.hash != key:
                        raise RuntimeError(f"model {model.name!r} rebuilt on a worker has hash "
                                           f"{model.hash}, expected {key} (different pwsdyn "
                                           "versions on the client and the workers?)")
                    _CONTEXTS[key] = cls(model, kind=None)
                return _CONTEXTS[key]
            model = load_model(payload_or_model)
            if model.hash not in _CONTEXTS:
                _CONTEXTS[model.hash] = cls(model, kind=None)
            return _CONTEXTS[model.hash]

    # ---- identity -----------------------------------------------------------------------
    @property
    def forcing_period(self) -> float | None:
        """The forcing period at the context's parameters (:meth:`Model.forcing_period_at
        <pwsdyn.model.Model.forcing_period_at>`)."""
        return self.model.forcing_period_at(self.p)

    @property
    def autonomous(self) -> bool:
        """True when no vector field, surface or reset depends explicitly on time."""
        t = self.model.t
        exprs = [e for m in self.model.modes for e in m.rhs]
        exprs += [s.expr for s in self.model.surfaces]
        exprs += [e for ev in self.model.events if ev.reset is not None for e in ev.reset]
        return not any(sp.sympify(e).has(t) for e in exprs)

    # ---- point evaluations ----------------------------------------------------------------
    def _eval(self, which: int, idx: int, t: float, x, size: int) -> np.ndarray:
        """The model's generated ``evaluate(which, idx, t, x, p, out)`` at this context's
        parameters: private to this layer (the analyses call the named methods below)."""
        out = np.zeros(max(size, self.n * self.n, 2))
        self.cm.evaluate(which, int(idx), float(t), np.ascontiguousarray(x, dtype=float),
                         self._pv, out)
        return out[:size].copy()

    def h(self, k: int, t: float, x) -> float:
        """Surface ``k`` at ``(t, x)``."""
        return float(self._eval(W_H, k, t, x, 1)[0])

    def h_rows(self, k: int, ts, X) -> np.ndarray:
        """Surface ``k`` at the points ``(ts[i], X[i])``, in one compiled loop."""
        from ._rows import first_of_rows

        ts = np.ascontiguousarray(ts, dtype=float)
        X = np.ascontiguousarray(X, dtype=float)
        out = np.empty(ts.shape[0])
        buf = np.zeros(max(self.n * self.n, self.n, 2))
        first_of_rows(self.cm.evaluate, W_H, int(k), ts, X, self._pv, buf, out)
        return out

    def h_x(self, k: int, t: float, x) -> np.ndarray:
        """Gradient ``h_x`` of surface ``k``."""
        return self._eval(W_HX, k, t, x, self.n)

    def h_t(self, k: int, t: float, x) -> float:
        """Explicit time derivative ``h_t`` of surface ``k``."""
        return float(self._eval(W_HT, k, t, x, 1)[0])

    def g(self, j: int, t: float, x) -> np.ndarray:
        """Reset map of event ``j``."""
        return self._eval(W_G, j, t, x, self.n)

    def g_x(self, j: int, t: float, x) -> np.ndarray:
        """Jacobian ``g_x`` of the reset of event ``j``."""
        return self._eval(W_GX, j, t, x, self.n * self.n).reshape(self.n, self.n)

    def g_t(self, j: int, t: float, x) -> np.ndarray:
        """Time derivative ``g_t`` of the reset of event ``j``."""
        return self._eval(W_GT, j, t, x, self.n)

    def mode_field(self, mode: int, t: float, x) -> np.ndarray:
        """The vector field ``f`` of regular mode ``mode``."""
        return self._eval(W_F, mode, t, x, self.n)

    def field(self, t: float, x, state: KernelState, sliding_gain: float = 0.0) -> np.ndarray:
        """The vector field the kernel integrates in discrete state ``state``."""
        out = np.zeros(self.n)
        kernel().state_field(self.cm.evaluate, self._pv, int(state.kind), int(state.index),
                             int(state.mode), self.nm, float(t),
                             np.ascontiguousarray(x, dtype=float), self.etab, self.stab,
                             float(sliding_gain), out)
        return out

    def hdot(self, k: int, mode: int, t: float, x) -> float:
        """Normal velocity ``h_t + h_x f_mode`` of surface ``k`` along regular mode ``mode``."""
        return float(self._eval(W_HD, k * self.nm + mode, t, x, 1)[0])

    def hdot_x(self, k: int, mode: int, t: float, x) -> np.ndarray:
        """Gradient in ``x`` of :meth:`hdot`."""
        return self._eval(W_HDX, k * self.nm + mode, t, x, self.n)

    def hdot_t(self, k: int, mode: int, t: float, x) -> float:
        """Explicit time derivative of :meth:`hdot`."""
        return float(self._eval(W_HDT, k * self.nm + mode, t, x, 1)[0])

    def hdot_rate(self, k: int, mode: int, t: float, x, f) -> float:
        """``d/dt (h_t + h_x f_mode)`` along the field ``f`` at ``(t, x)``: the rate of the
        normal velocity of mode ``mode`` on surface ``k`` (the release condition of sticking,
        the boundary of a sliding region, thesis eq. 2.6-2.8)."""
        i = k * self.nm + mode
        return float(self._eval(W_HDT, i, t, x, 1)[0] + self._eval(W_HDX, i, t, x, self.n) @ f)

    def acceleration(self, k: int, mode: int, t: float, x) -> float:
        """Normal acceleration of surface ``k`` in free motion in mode ``mode``:
        :meth:`hdot_rate` along the mode's own field."""
        return self.hdot_rate(k, mode, t, x, self.mode_field(mode, t, x))

    def boundary_rate(self, j: int, mode: int, t: float, x) -> float:
        """``d/dt (h_t + h_x f_mode)`` along the sliding field of switch ``j`` at ``(t, x)``
        (its convex combination extended smoothly where the point is not in the sliding
        region): the rate at which the sliding flow crosses the sliding region's boundary
        ``h_t + h_x f_mode = 0``."""
        k = self.model.switches[j].surface
        return self.hdot_rate(k, mode, t, x, self.field(t, x, self.sliding_state(j)))

    def guard(self, j: int, t: float, x) -> bool:
        """Whether the guard of event ``j`` holds at ``(t, x)`` (True without a guard)."""
        if self.model.events[j].guard is None:
            return True
        return bool(self._eval(W_GUARD, j, t, x, 1)[0] != 0.0)

    def sliding_state(self, j: int) -> KernelState:
        """The kernel code of sliding on switch ``j`` (the kernel keeps the ``above`` mode)."""
        return KernelState(SLIDE, int(j), int(self.stab[j]["above"]))

    # ---- saltation -------------------------------------------------------------------------
    def chatter_saltation(self, name: str, t: float, x_before, mode: int,
                          sliding_gain: float = 0.0) -> np.ndarray:
        """Full saltation matrix of the complete-chattering map of impact event ``name``
        entered from mode ``mode`` at ``(t, x_before)``: the kernel's function, the matrix it
        applies."""
        S = np.zeros((self.n, self.n))
        kernel().chatter_saltation(self.cm.evaluate, self._pv, self.event_index(name),
                                   int(mode), self.nm, float(t),
                                   np.ascontiguousarray(x_before, dtype=float), self.etab,
                                   self.stab, float(sliding_gain), S)
        return S

    def saltation(self, kind: str, name: str, t: float, x_before, x_after,
                  st_before: KernelState, st_after: KernelState, sliding_gain: float = 0.0):
        """Full and projected saltation matrices at one event (:func:`event_map_saltation`
        with the reset's ``g_x``, ``g_t``, the surface's ``h_x``, ``h_t`` and the fields of
        the discrete states before and after). For ``chatter``: the kernel's full matrix and
        None (it has no projected form). Raises :class:`~pwsdyn.ArgumentError` at a grazing event
        (``|h_t + h_x f_in| <= GRAZING_RTOL |h_x| |f_in|``, the kernel's test)."""
        n = self.n
        x_before = np.asarray(x_before, dtype=float)
        x_after = np.asarray(x_after, dtype=float)
        if kind == "chatter":
            return self.chatter_saltation(name, t, x_before, st_before.mode, sliding_gain), None
        if kind in ("impact", "transition"):
            j = self.event_index(name)
            k = int(self.etab[j]["surface"])
            gx = self.g_x(j, t, x_before)
            gt = self.g_t(j, t, x_before)
        elif kind in ("crossing", "slide_start"):
            k = int(self.stab[self.switch_index(name)]["surface"])
            gx = np.eye(n)
            gt = np.zeros(n)
        else:
            raise ValueError(f"no saltation formula for a {kind!r} event (its saltation matrix "
                             f"is the identity)")
        f_in = self.field(t, x_before, st_before, sliding_gain)
        f_out = self.field(t, x_after, st_after, sliding_gain)
        hx = self.h_x(k, t, x_before)
        den = self.h_t(k, t, x_before) + hx @ f_in
        scale = np.linalg.norm(hx) * max(np.linalg.norm(f_in), 1e-300)
        if not np.isfinite(den) or abs(den) <= kernel().GRAZING_RTOL * scale:
            raise ArgumentError(f"{kind} {name!r} at t={t:.17g} is grazing (h_t + h_x f = "
                                f"{den:.3e}, |h_x| |f| = {scale:.3e}): its saltation matrix is "
                                f"unbounded (a simulation with variational=True gives NaN "
                                f"there)")
        full = event_map_saltation(gx, gt, f_in, f_out, hx, den)
        # the projected form is the full one without the field after the event
        proj = event_map_saltation(gx, gt, f_in, np.zeros(n), hx, den)
        return full, proj

    # ---- runs ------------------------------------------------------------------------------
    def start(self, t: float, x, p=None, *, behind_tol: float | None = None,
              refuse: bool = False, names: str | None = None) -> Start:
        """The start a run from ``x`` at ``t`` in the model's initial mode takes
        (``integrate._start.start_state``): the state, moved onto an impact
        constraint it lies within ``behind_tol`` (default ``ADMIT_BEHIND (1 + |x|)``) behind,
        and the discrete state (sticking on it, or regular). ``refuse``: a state further
        behind raises :class:`~pwsdyn.errors.ArgumentError` (calling it ``names``, default
        ``x0``), as :func:`pwsdyn.simulate` does; otherwise it is left as it is."""
        x = np.array(x, dtype=float)
        model = self.model
        if self.is_map or not model.events:
            return Start(x, REGULAR, -1, int(getattr(model, "initial_mode", 0)))
        if behind_tol is None:
            scale = 1.0 + float(np.max(np.abs(x))) if x.size else 1.0
            behind_tol = ADMIT_BEHIND * scale
        pv = self.p if p is None else np.asarray(p, dtype=float)
        return start_state(self.cm, self.etab, self.eact, self.stab, float(t), x, pv,
                           int(model.initial_mode), behind_tol=behind_tol, refuse=refuse,
                           names=names)

    def run(self, x0, state: KernelState | None = None, t0: float = 0.0,
            t_end: float | None = None, opts: Mapping | None = None, *, stop=None,
            sample=None, variational: bool | None = None, p=None, admit: bool = True,
            store_dense: bool = False) -> RunResult:
        """One run of the kernel from ``x0`` at ``t0`` to ``t_end`` (or to ``stop``).

        Parameters
        ----------
        x0 : array_like
        state : KernelState, optional
            The discrete state at ``t0`` (default: the regular mode of ``opts["mode"]`` or the
            model's initial mode; a regular start goes through the start rule, see
            :func:`run_compiled`).
        t0, t_end : float
            The time span (``t_end`` may be given by ``stop=AtTime(t)`` instead).
        opts : dict
            Merged integrator options (:func:`pwsdyn.integrate.options.integrator_options`;
            default: the defaults). Its ``sliding`` must be this context's.
        stop : AfterEvents or AtTime, optional
        sample : (float, float), optional
            ``(t_first, dt)``: stroboscopic samples at ``t_first + k dt``.
        variational : bool, optional
            Override ``opts["variational"]``.
        p : array_like, optional
            Another parameter vector than the context's (a sweep's).
        admit, store_dense
            As in :func:`run_compiled`.

        Returns
        -------
        RunResult
            Never raises for a failed run (``result.status``); with ``opts["throw"]`` the
            caller decides (:meth:`RunResult.solve_error`).
        """
        if opts is None:
            from .options import DEFAULTS

            opts = DEFAULTS
        if variational is not None and bool(variational) != bool(opts["variational"]):
            opts = {**opts, "variational": bool(variational)}
        if t_end is None:
            if not isinstance(stop, AtTime):
                raise ArgumentError("`t_end` is required unless `stop` is AtTime(t)")
            t_end = stop.t
        pv = self.p if p is None else np.asarray(p, dtype=float)
        if state is None:
            return run_compiled(self.cm, x0, float(t0), float(t_end), pv, opts, stop=stop,
                                sample=sample, admit=admit, store_dense=store_dense,
                                model=self.model)
        return run_compiled(self.cm, x0, float(t0), float(t_end), pv, opts, mode0=state.mode,
                            dkind0=state.kind, didx0=state.index, stop=stop, sample=sample,
                            admit=admit, store_dense=store_dense, model=self.model)

    # ---- names ---------------------------------------------------------------------------
    def event_index(self, name: str) -> int:
        return self.model.event_index(name)

    def switch_index(self, name: str) -> int:
        for i, s in enumerate(self.model.switches):
            if s.name == name:
                return i
        raise ValueError(f"unknown switch {name!r}; switches are "
                         f"{[s.name for s in self.model.switches]}")

    def surface_of(self, kind: str, name: str) -> int:
        """Index of the surface of the event (impact, transition, chatter) or switch
        (crossing, slide_start) ``name``."""
        if kind in ("crossing", "slide_start", "slide_end"):
            return int(self.stab[self.switch_index(name)]["surface"])
        return int(self.etab[self.event_index(name)]["surface"])

    def state(self, name, mode_hint: str | int | None = None) -> KernelState:
        """The kernel code of a discrete state (a
        :class:`~pwsdyn.integrate.trajectory.DiscreteState` or its text, as in
        ``Trajectory.state``).

        ``mode_hint`` is the regular mode a sticking state constrains (the ``mode_before`` of
        the ``stick`` event that started it); by default the first mode of the impact event.
        """
        st = DiscreteState.parse(name)
        if st.kind == "mode":
            return KernelState(REGULAR, -1, self.model.mode_index(st.name))
        if st.kind == "stick":
            j = self.event_index(st.name)
            if mode_hint is None:
                mode = self.model.events[j].modes[0]
            elif isinstance(mode_hint, str):
                mode = self.model.mode_index(mode_hint)
            else:
                mode = int(mode_hint)
            return KernelState(STICK, j, mode)
        if st.kind == "slide_multi":
            return self._multi_state(st.surfaces)
        s = self.switch_index(st.name)
        # the kernel keeps the `above` mode while sliding (only the switch index matters
        # for the sliding field)
        return KernelState(SLIDE, s, int(self.stab[s]["above"]))

    def _multi_state(self, names) -> KernelState:
        """The kernel code of sliding on the intersection of the surfaces ``names``: the bit
        mask of their indices and the first mode above all of them (the reference corner the
        kernel keeps; as for ``slide:<switch>``, only the surfaces matter for the field where
        one mode's variants meet there)."""
        idx = {s.name: k for k, s in enumerate(self.model.surfaces)}
        unknown = [nm for nm in names if nm not in idx]
        if unknown or len(names) < 2:
            raise ValueError(f"slide_multi names two or more surfaces of "
                             f"{list(idx)} joined by '&', got {'&'.join(names)!r}")
        mask = 0
        for nm in names:
            mask |= 1 << idx[nm]
        ks = {idx[nm] for nm in names}
        for m in range(self.nm):
            above = {int(r["surface"]) for r in self.stab if int(r["above"]) == m}
            if ks <= above:
                return KernelState(SLIDE_MULTI, mask, m)
        raise ValueError(f"no mode lies above all of the surfaces {'&'.join(names)!r}")

    def state_name(self, st: KernelState) -> DiscreteState:
        if st.kind == REGULAR:
            return DiscreteState("mode", self.model.modes[st.mode].name)
        if st.kind == STICK:
            return DiscreteState("stick", self.model.events[st.index].name)
        if st.kind == SLIDE_MULTI:
            return DiscreteState("slide_multi", _multi_name(self.model, st.index))
        return DiscreteState("slide", self.model.switches[st.index].name)


def check_state_name(model, mode, name: str = "mode") -> None:
    """``mode`` names a discrete state of the (symbolic) flow ``model``: None, a
    :class:`KernelState`, a mode name, ``stick:<event>`` or ``slide:<switch>`` (a
    :class:`~pwsdyn.integrate.trajectory.DiscreteState` or its text). Checked before
    anything is compiled; :func:`initial_state` then makes the kernel's code."""
    if mode is None or isinstance(mode, KernelState):
        return
    must = (f"None or a discrete state of model {model.name!r}: a mode "
            f"{list(model.mode_names)}, 'stick:<event>' with an event "
            f"{[e.name for e in model.events]}, 'slide:<switch>' with a switch "
            f"{[s.name for s in model.switches]} or 'slide_multi:<surface>&<surface>...' "
            f"with two or more surfaces {[s.name for s in model.surfaces]}")
    try:
        st = DiscreteState.parse(mode)
    except ValueError:
        raise V.fail(name, must, mode) from None
    if st.kind == "mode" and st.name in model.mode_names:
        return
    if st.kind == "stick" and st.name in [e.name for e in model.events]:
        return
    if st.kind == "slide" and st.name in [s.name for s in model.switches]:
        return
    if (st.kind == "slide_multi" and len(st.surfaces) >= 2
            and set(st.surfaces) <= {s.name for s in model.surfaces}):
        return
    raise V.fail(name, must, mode)


def initial_state(ctx, mode, name: str = "mode") -> KernelState:
    """The kernel code of the discrete state named by ``mode`` (None: the model's initial
    mode; a :class:`KernelState`; a mode name, ``stick:<event>`` or ``slide:<switch>``), with
    an :class:`~pwsdyn.ArgumentError` naming ``name`` otherwise."""
    if mode is None:
        return KernelState(REGULAR, -1, ctx.model.initial_mode)
    if isinstance(mode, KernelState):
        return mode
    if not isinstance(mode, str):
        raise V.fail(name, "None, a mode name, 'stick:<event>' or 'slide:<switch>'", mode)
    try:
        return ctx.state(mode)
    except (ValueError, IndexError, KeyError) as exc:
        raise ArgumentError(f"`{name}` must name a discrete state of model "
                            f"{ctx.model.name!r} (a mode {list(ctx.model.mode_names)}, "
                            f"'stick:<impact event>' or 'slide:<switch>'): {exc}") from None


def event_states(ctx: ModelContext, events, start: KernelState):
    """The kernel codes of the discrete states before and after each event of a log,
    starting in ``start``.

    Sticking states take their constrained mode from the regular mode before them.
    """
    out = []
    cur = start
    last_mode = ctx.model.modes[start.mode].name
    for e in events:
        before = cur
        if DiscreteState.parse(e.mode_after).is_mode:
            last_mode = e.mode_after
        after = ctx.state(e.mode_after, mode_hint=last_mode)
        out.append((before, after))
        cur = after
    return out


def trajectory_start_state(ctx: ModelContext, traj) -> KernelState:
    """Kernel code of the discrete state of a trajectory at its start (its first node)."""
    name = DiscreteState.parse(str(traj.state[0]))
    hint = None
    if name.kind == "stick" and traj.events:
        # a run that starts sticking releases (or leaves) into the constrained mode
        e = traj.events[0]
        hint = next((m for m in (e.mode_before, e.mode_after)
                     if DiscreteState.parse(m).is_mode), None)
    return ctx.state(name, mode_hint=hint)
