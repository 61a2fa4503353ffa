"""Newton shooting for periodic orbits of hybrid models: single and multiple shooting.

Unknowns and equations (slides, "Locating periodic orbits"; multiple shooting over the smooth
segments of the orbit, as COCO's ``hspo`` toolbox splits a hybrid orbit):

* shooting nodes ``t_0 < t_1 < ... < t_{N-1}`` in one period, one in the middle of each smooth
  segment of the guess (``nodes='auto'``), with unknown states ``x_i`` and the discrete state
  of the segment;
* each interval ``[t_i, t_{i+1}]`` is integrated by the compiled kernel with every event on the
  way (impacts, resets, crossings, sliding, chattering, sticking) and the variational
  equations: end state ``y_i``, Jacobian ``M_i`` with all saltation matrices;
* residual ``r_i = y_i - x_{i+1}`` (``x_N = x_0``); Newton matrix with blocks ``M_i`` and
  ``-I`` (single shooting, ``N = 1``: ``Phi_x - I``, the slides' matrix).

For a forced model the period ``T = n * forcing_period`` and the node times are fixed. For an
autonomous model ``T`` is an unknown: the nodes sit at fixed fractions of ``T``, the intervals'
end states depend on ``T`` through ``dy_i/dT = (t_{i+1} - t_i)/T * f(y_i)`` (the slides'
column ``f_i(x_k)``), and a phase condition closes the system: the Poincaré section through
the initial guess ``x_ref`` orthogonal to the flow there, ``f(x_ref) . (x_0 - x_ref) = 0``
(the slides' ``h(x) = 0`` with a linear ``h``), or a given normal.

The event sequence of every interval (its signature: kinds, names, modes) is compared between
iterations. Early on it may change (a rough guess); once the residual is below ``lock_tol``
it is locked, and a later change is an error -- the orbit is near a grazing or sliding
bifurcation and its signature is not structurally stable. Every loop is bounded (Newton
iterations, line-search halvings, integrator steps); failure raises :class:`OrbitError`
naming the reason, with the last iterate as ``result``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError
from ..newton import TrialRejected, newton
from ..integrate.compiled import (KernelState, ModelContext, check_state_name, event_states,
                                  initial_state, run_compiled, trajectory_start_state)
from ..integrate.trajectory import DiscreteState, EventLog, Trajectory
from ..model.spec import as_model
from ..stability import floquet_multipliers
from ._base import (MAX_ITER, MAX_NODES, MAX_PERIODS, RECURRENCE_MAX_PERIODS,
                    STABILITY_MARGIN, OrbitError, shooting_options)
from ._base import SHOOTING_DEFAULTS as SHOOTING_DEFAULTS  # its old home, still imported
from ._orbit import (DeferredTrajectory, PeriodicOrbit, Recurrence, RecurrenceWarning,
                     merge_intervals)
from .problem import locked_orbit

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from .._typing import ModelLike, StateLike

class _SimulationFailed(Exception):
    def __init__(self, interval, traj=None, exc=None):
        self.interval = interval
        self.traj = traj
        self.exc = exc


def _trajectory(ctx: ModelContext, x0, state: KernelState, t0: float, t_end: float, opts, *,
                admit: bool = True, refuse: bool = False) -> Trajectory:
    """One run of the context's model from ``x0`` in ``state``, as a Trajectory (the guess's
    events and dense output place the nodes). ``admit=False``: the state exactly as given (a
    Newton iterate); ``refuse``: a guess inside an impact constraint is an error, as in
    :func:`pwsdyn.simulate`."""
    run = run_compiled(ctx.cm, np.asarray(x0, dtype=float), float(t0), float(t_end), ctx.p,
                       opts, mode0=state.mode, dkind0=state.kind, didx0=state.index,
                       admit=admit, refuse=refuse)
    return run.trajectory(ctx.cm.model, opts, float(t0), float(t_end))


class _Shooter:
    """The shooting problem: nodes, their discrete states, residual and Newton matrix.

    The Newton iterations read plain run results (:class:`~pwsdyn.integrate.compiled.
    RunResult`: end state, Jacobian, event columns); a :class:`~pwsdyn.Trajectory` is made
    only for the orbit returned, and only when its ``trajectory`` is read."""

    def __init__(self, ctx: ModelContext, t0: float, T: float, node_times, node_states,
                 autonomous: bool, opts: dict, phase_ref=None, phase_normal=None):
        self.ctx = ctx
        self.t0 = float(t0)
        self.T = float(T)
        self.autonomous = autonomous
        self.tau = np.asarray(node_times, dtype=float)       # absolute times for the guess T
        self.frac = (self.tau - self.t0) / self.T            # fractions (autonomous)
        self.states = list(node_states)
        self.opts = opts
        self.phase_ref = phase_ref
        self.phase_normal = phase_normal
        self.gain = float(opts.get("sliding_gain", 0.0))
        # the options of the Newton runs and of the orbit's dense runs: ``opts`` were checked
        # by shooting_options, and the flags set here are valid by construction, so the runs
        # skip the check (every interval of every iteration runs with one of the two)
        self.run_opts = {d: dict(opts, dense=d, variational=True, throw=False)
                         for d in (False, True)}
        # a forced orbit's node times are fixed (an autonomous one's: see times)
        self._ts = None if autonomous else np.append(self.tau, self.t0 + self.T)
        if self._ts is not None:
            self._ts.flags.writeable = False
        self._t_of = None
        # end state and event signature of an interval by its start state and event codes:
        # both are functions of the codes (the names are made from them), so the event log's
        # records and names are made once per distinct sequence, not once per run
        self._ends: dict = {}
        self._eye = np.eye(ctx.n)

    @property
    def N(self) -> int:
        return len(self.tau)

    def times(self, T: float) -> np.ndarray:
        """The node times and the end of the period, for the period ``T`` (read-only: an
        autonomous problem's are kept for the last ``T`` asked, which residual, Jacobian and
        node checks of one iterate all ask for)."""
        if not self.autonomous:
            return self._ts
        if T != self._t_of:
            ts = np.append(self.t0 + T * self.frac, self.t0 + T)
            ts.flags.writeable = False
            self._t_of, self._ts = T, ts
        return self._ts

    def run(self, X, T):
        """Integrate every interval with the variational equations; return the runs
        (:class:`~pwsdyn.integrate.compiled.RunResult`), their end states and signatures."""
        ts = self.times(T)
        ctx = self.ctx
        cm, p, opts = ctx.cm, ctx.p, self.run_opts[False]
        runs, ends, sig = [], [], []
        for i in range(self.N):
            st = self.states[i]
            try:
                # the Newton iterate exactly as it is (no start rule: the node's discrete
                # state is part of the locked signature)
                # (the end Jacobian only: the orbit's trajectory comes from dense runs)
                r = run_compiled(cm, np.asarray(X[i], dtype=float), float(ts[i]),
                                 float(ts[i + 1]), p, opts, mode0=st.mode, dkind0=st.kind,
                                 didx0=st.index, admit=False, checked=True,
                                 jacobian_only=True)
            except (ValueError, FloatingPointError) as exc:
                raise _SimulationFailed(i, exc=exc) from None
            if r.status.failed or not np.isfinite(r.jacobian).all():
                raise _SimulationFailed(i, traj=self._failed(X[i], st, ts[i], ts[i + 1]))
            end, s = self._end_of(r, st)
            runs.append(r)
            ends.append(end)
            sig.append(s)
        return runs, ends, tuple(sig)

    def _failed(self, x, st, t0, t1) -> Trajectory:
        """The failed run of an interval again, as a Trajectory (what the error reports)."""
        return _trajectory(self.ctx, x, st, t0, t1, self.run_opts[False], admit=False)

    def _end_of(self, r, st):
        """``(end state, signature)`` of run ``r`` started in ``st``."""
        info = r._raw.ev_info
        key = (st, info.shape[0], info[:, :8].tobytes())
        got = self._ends.get(key)
        if got is None:
            evs = r.events
            end = event_states(self.ctx, evs, st)[-1][1] if len(evs) else st
            got = self._ends[key] = (end, _signature_of(evs, end, self.ctx))
        return got

    def residual(self, X, T, runs):
        N, n = self.N, self.ctx.n
        r = np.empty(N * n + (1 if self.autonomous else 0))
        for i in range(N):
            r[i * n:(i + 1) * n] = runs[i].x - X[(i + 1) % N]
        if self.autonomous:
            r[-1] = self.phase_normal @ (X[0] - self.phase_ref)
        return r

    def jacobian(self, X, T, runs, ends):
        N, n = self.N, self.ctx.n
        m = N * n + (1 if self.autonomous else 0)
        J = np.zeros((m, m))
        ts = self.times(T)
        for i in range(N):
            rows = slice(i * n, (i + 1) * n)
            J[rows, i * n:(i + 1) * n] += runs[i].jacobian
            k = (i + 1) % N
            J[rows, k * n:(k + 1) * n] -= self._eye
            if self.autonomous:
                # y_i = flow over (t_{i+1} - t_i) = T (frac_{i+1} - frac_i): dy_i/dT
                f_end = self.ctx.field(ts[i + 1], runs[i].x, ends[i], self.gain)
                J[rows, -1] = (ts[i + 1] - ts[i]) / T * f_end
        if self.autonomous:
            J[-1, :n] = self.phase_normal
        return J

    @staticmethod
    def norm(r, X) -> float:
        return float(np.max(np.abs(r)) / (1.0 + np.max(np.abs(X))))

    def znorm(self, r, z) -> float:
        """:meth:`norm` of the residual at the unknowns ``z`` (the node states are its first
        ``N n`` entries: the same maximum, without making them a list)."""
        return float(np.abs(r).max() / (1.0 + np.abs(z[:self.N * self.ctx.n]).max()))


def _dense_intervals(ctx: ModelContext, states, X, ts, opts) -> list:
    """The shooting intervals from the node states ``X`` in discrete states ``states``
    between the node times ``ts``, as dense trajectories (for the orbit returned)."""
    out = []
    for i, st in enumerate(states):
        r = run_compiled(ctx.cm, np.asarray(X[i], dtype=float), float(ts[i]),
                         float(ts[i + 1]), ctx.p, opts, mode0=st.mode, dkind0=st.kind,
                         didx0=st.index, admit=False, checked=True)
        out.append(r.trajectory(ctx.cm.model, opts, float(ts[i]), float(ts[i + 1])))
    return out


def _signature_of(events, end: KernelState, ctx: ModelContext) -> tuple:
    return (tuple((e.kind, e.name, e.mode_before, e.mode_after) for e in events),
            ctx.state_name(end))


def _initial_state(ctx: ModelContext, mode) -> KernelState:
    return initial_state(ctx, mode)


def _orbit_period(model, p, period, periods, what="period"):
    """The period of an orbit: ``periods`` forcing periods, or ``period`` (a multiple of the
    forcing period of a forced model; a guess for an autonomous one). Validated."""
    Tf = model.forcing_period_at(p)
    if Tf is None:
        if period is None:
            raise ArgumentError(f"model {model.name!r} is autonomous (no `forcing_period`): "
                                f"give a guess of the period as `period`")
        return float(period), None
    if period is None:
        return periods * Tf, Tf
    T = float(period)
    k = round(T / Tf)
    if k < 1 or abs(T - k * Tf) > 1e-9 * T:
        raise ArgumentError(f"`period` = {T!r} of forced model {model.name!r} must be a "
                            f"multiple of its forcing period {Tf!r}")
    if k > MAX_PERIODS:
        raise V.fail("period", f"at most {MAX_PERIODS} forcing periods {Tf!r}", period)
    return k * Tf, Tf


def _state_at(ctx, traj, st0, t):
    """Discrete state of a trajectory at time ``t`` (after the events at or before it)."""
    st = st0
    for e, (_, after) in zip(traj.events, event_states(ctx, traj.events, st0)):
        if e.t_after <= t:
            st = after
        else:
            break
    return st


def _smooth_base_point(ctx, ref, st0, t0, T):
    """``(t, x, state)`` in the middle of the longest regular smooth segment of ``ref``."""
    evs = list(ref.events)
    states = event_states(ctx, evs, st0)
    spans = [(t0, evs[0].t if evs else t0 + T, st0)]
    for k, e in enumerate(evs):
        end = evs[k + 1].t if k + 1 < len(evs) else t0 + T
        spans.append((e.t_after, end, states[k][1]))
    regular = [s for s in spans if s[2].kind == 0] or spans
    a, b, st = max(regular, key=lambda s: s[1] - s[0])
    tm = 0.5 * (a + b)
    return tm, ref(tm, side="right"), st


def _place_nodes(ctx, ref, st0, t0, T, nodes, max_nodes):
    """Node times and discrete states from the guess trajectory ``ref`` over one period."""
    if isinstance(nodes, (int, np.integer)) and not isinstance(nodes, bool):
        if nodes < 1:
            raise ArgumentError(f"`nodes` must be 'auto' or a positive integer, got {nodes!r}")
        times = t0 + T * np.arange(nodes) / nodes
        return times, [st0] + [_state_at(ctx, ref, st0, t) for t in times[1:]]
    if nodes != "auto":
        raise ArgumentError(f"`nodes` must be 'auto' or a positive integer, got {nodes!r}")
    log = ref.events
    times = log.t.tolist() if isinstance(log, EventLog) else [e.t for e in log]
    if sum(t < t0 + T for t in times) < 2:
        # no smooth segment between two events (a one-impact orbit): one node, and the
        # log's records need not be made
        return np.array([t0]), [st0]
    evs = [e for e in log if e.t < t0 + T]
    cands = []
    states = event_states(ctx, evs, st0)
    for k in range(len(evs) - 1):
        a, b = evs[k].t_after, evs[k + 1].t
        st = states[k][1]
        if st.kind == 0 and b - a >= 1e-3 * T:
            cands.append((0.5 * (a + b), st))
    if len(cands) > max_nodes - 1:
        pick = np.unique(np.round(np.linspace(0, len(cands) - 1, max_nodes - 1)).astype(int))
        cands = [cands[i] for i in pick]
    return (np.array([t0] + [c[0] for c in cands]), [st0] + [c[1] for c in cands])


def find_periodic_orbit(model: ModelLike, x0: StateLike, *,
                        params: Mapping[str, float] | None = None,
                        period: float | None = None, t0: float | None = None, periods: int = 1,
                        mode: str | None = None, nodes: str | int = "auto",
                        phase: ArrayLike | None = None, tol: float = 1e-10,
                        max_iter: int = 30, lock_tol: float = 1e-6, max_nodes: int = 24,
                        signature: Any = None, **options: Any) -> PeriodicOrbit:
    """Find a periodic orbit by Newton shooting and compute its Floquet multipliers.

    Parameters
    ----------
    model : Model, str, path or dict
    x0 : sequence or dict
        Guess of the state at ``t0`` (for example the end of a short simulation).
    params : dict, optional
        Parameter values.
    period : float, optional
        Forced models (``forcing_period`` in the model): the exact period, a multiple of the
        forcing period (default ``periods * forcing_period``). Autonomous models: a guess of the
        period (required).
    t0 : float, optional
        Initial time (default: the model's ``[defaults] t0``, else 0, as on the command line);
        for a forced model it fixes the phase of ``x0``. A shooting node at an
        event makes the one-period map non-smooth, so when an event of the guess (or of an
        iterate) comes within 2% (1e-4) of a period of ``t0`` the base point is moved to the
        middle of the longest smooth segment: ``orbit.t0`` is the time used.
    periods : int
        Forced models: the period in forcing periods when ``period`` is not given.
    mode : str, optional
        Discrete state at ``t0``: a mode name, ``stick:<event>`` or ``slide:<switch>``
        (default: the model's initial mode).
    nodes : 'auto' or int
        ``'auto'``: multiple shooting with a node in the middle of each smooth segment of the
        guess (at most ``max_nodes``); an integer: that many nodes equally spaced in time
        (``1`` is single shooting, the slides' Newton method).
    phase : array_like, optional
        Autonomous models: normal of the phase-condition hyperplane through ``x0`` (default
        the vector field at ``x0``, the Poincaré phase condition).
    tol : float
        Converged when the residual max norm relative to ``1 + max|x|`` is at most ``tol``.
    max_iter : int
        Newton step budget.
    lock_tol : float
        The event sequence is locked once the residual is below this; a later change raises.
    max_nodes : int
    signature : Signature, sequence or str, optional
        Lock the orbit's signature (``orbit.signature`` of an earlier orbit, or its string):
        the orbit is then solved on that event sequence by :class:`~pwsdyn.orbits.OrbitProblem`
        (segment start states and durations; exact Jacobians) instead of free-running
        shooting. The guess ``(t0, x0)`` lies in the segment that the signature's first event
        ends (``mode``, if given, must be its state); each segment is integrated in its
        discrete state whatever surfaces it meets, so the orbit can be followed past a
        grazing: the result then has ``admissible = False`` and the ``reason``. ``nodes``,
        ``lock_tol`` and ``max_nodes`` do not apply.
    **options
        Integrator options of :func:`pwsdyn.simulate`; defaults here are ``method='DOP853'``
        (whatever ``rtol``), ``rtol=1e-12``, ``atol=1e-12``: tighter than a simulation's
        (``rtol=1e-10``), because Newton's method on the shooting residual and the Floquet
        multipliers need the flow and its derivatives to more digits (the command line's
        ``orbit``, ``continue`` and ``grazing`` have the same defaults).

    Returns
    -------
    PeriodicOrbit

    Raises
    ------
    OrbitError
        With ``reason`` ``'singular'``, ``'phase'``, ``'equilibrium'``, ``'signature'``,
        ``'budget'``, ``'no_progress'``, ``'diverged'`` or ``'simulation'`` and the last
        iterate as ``result`` (``converged`` False). With ``signature``: ``'signature'`` when
        the guess does not follow the signature (a segment never reaches its event).

    Examples
    --------
    >>> import pwsdyn
    >>> orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [0.0, -0.5])
    >>> orbit.events[0].kind, orbit.stable
    ('impact', True)
    """
    opts = shooting_options(options)
    model = as_model(model, kind="flow", caller="find_periodic_orbit()")
    p = model.parameter_vector(params)
    x0 = V.state_vector(model, x0)
    period = V.positive("period", period, allow_none=True)
    t0 = V.number("t0", model.defaults.get("t0", 0.0) if t0 is None else t0)
    periods = V.integer("periods", periods, lo=1, hi=MAX_PERIODS)
    if not (isinstance(nodes, str) and nodes == "auto"):
        V.integer("nodes", nodes, lo=1, hi=MAX_NODES)
    if phase is not None:
        phase = V.vector("phase", phase, size=model.n_states)
    tol = V.tolerance("tol", tol)
    max_iter = V.integer("max_iter", max_iter, lo=1, hi=MAX_ITER)
    lock_tol = V.positive("lock_tol", lock_tol)
    max_nodes = V.integer("max_nodes", max_nodes, lo=1, hi=MAX_NODES)
    check_state_name(model, mode)
    T, Tf = _orbit_period(model, p, period, periods)
    autonomous = Tf is None
    V.time_window("t0", t0, T, what="one period of the orbit")
    if signature is not None:
        return locked_orbit(model, x0, params=params, T=T, Tf=Tf, t0=t0, mode=mode,
                            signature=signature, phase=phase, tol=tol, max_iter=max_iter,
                            options=options)
    N = nodes if V.is_int(nodes) else max_nodes
    V.memory("find_periodic_orbit() with these `nodes`",
             8.0 * (N * model.n_states + 1) ** 2 * 3)
    ctx = ModelContext(model, params, opts.get("sliding", "convex"))
    st0 = _initial_state(ctx, mode)

    # guess trajectory: signature and node placement
    ref_opts = dict(opts, variational=False, dense=True, throw=False)
    # a guess on an impact constraint (the end of a run that sticks) starts sticking, with an
    # impact or in free motion, as simulate() starts it; one inside the wall is refused
    ref = _trajectory(ctx, x0, st0, t0, t0 + T, ref_opts, refuse=True)
    if ref.status.failed:
        raise OrbitError("simulation", f"the guess could not be simulated over one period: "
                         f"{ref.message} (stopped at t={ref.t_final:.17g} in {ref.state[-1]})")
    # the kernel starts on the side of each switching surface the state lies on, and the
    # start rule may have put the state on a constraint: the guess is the run's first node
    st0 = trajectory_start_state(ctx, ref)
    x0 = np.array(ref.x[0], dtype=float)
    history: list = []
    for rebase in range(3):
        if _events_near_nodes([ref], np.array([t0, t0 + T]), T, margin=0.02):
            # a node at an event makes the one-period map non-smooth (the event falls in or
            # out of the interval): move the base point into the longest smooth segment
            t0, x0, st0 = _smooth_base_point(ctx, ref, st0, t0, T)
            ref = _trajectory(ctx, x0, st0, t0, t0 + T, ref_opts)
            if ref.status.failed:
                raise OrbitError("simulation", f"the guess could not be simulated over one "
                                 f"period: {ref.message} (stopped at t={ref.t_final:.17g} in "
                                 f"{ref.state[-1]})", history=history)
        sh, X = _setup(ctx, ref, st0, t0, T, x0, nodes, max_nodes, autonomous, opts, phase)
        try:
            return _newton(sh, X, T, tol=tol, max_iter=max(max_iter - len(history), 1),
                           lock_tol=lock_tol, history=history, allow_rebase=rebase < 2)
        except _Rebase as rb:
            # an event of the iterate came too close to a node: restart from its node-0 state
            T = rb.T
            x0 = np.asarray(rb.X[0], dtype=float)
            ref = _trajectory(ctx, x0, st0, t0, t0 + T, ref_opts, admit=False)
            if ref.status.failed:
                raise OrbitError("simulation", f"the iterate could not be simulated over one "
                                 f"period: {ref.message}", history=history) from None
            if not _events_near_nodes([ref], np.array([t0, t0 + T]), T):
                # the event is near an interior node: re-placing the nodes is enough
                continue
    raise AssertionError("unreachable")  # pragma: no cover


def _setup(ctx, ref, st0, t0, T, x0, nodes, max_nodes, autonomous, opts, phase):
    """The shooting problem for the guess trajectory ``ref`` from ``(t0, x0)``."""
    times, states = _place_nodes(ctx, ref, st0, t0, T, nodes, max_nodes)
    phase_ref = phase_normal = None
    if autonomous:
        phase_ref = x0.copy()
        f_ref = ctx.field(t0, x0, st0, opts.get("sliding_gain", 0.0))
        phase_normal = f_ref if phase is None else np.asarray(phase, dtype=float).reshape(-1)
        if phase_normal.shape != (ctx.n,) or not np.all(np.isfinite(phase_normal)):
            raise ArgumentError(f"`phase` must be a finite vector of {ctx.n} entries")
        nf = np.linalg.norm(phase_normal)
        if nf == 0.0 or np.linalg.norm(f_ref) <= 1e-12 * (1.0 + np.linalg.norm(x0)):
            raise OrbitError("phase", f"singular phase condition: the vector field vanishes at "
                             f"the guess x0 = {x0.tolist()} (an equilibrium?) or the phase "
                             f"normal is zero; there is no Poincaré section through it")
        if abs(phase_normal @ f_ref) <= 1e-8 * nf * np.linalg.norm(f_ref):
            raise OrbitError("phase", "singular phase condition: the phase-condition "
                             "hyperplane is tangent to the flow at the guess (normal . f = 0)")
    sh = _Shooter(ctx, t0, T, times, states, autonomous, opts, phase_ref, phase_normal)
    X = [x0.copy()] + [ref(t, side="right") for t in times[1:]]
    return sh, X


class _Rebase(Exception):
    def __init__(self, X, T):
        self.X = X
        self.T = T


def _events_near_nodes(trajs, ts, T, margin=1e-4) -> bool:
    """An event within ``margin * T`` of the start or end of its interval (``trajs``:
    trajectories or run results, one per interval)."""
    for i, tr in enumerate(trajs):
        if not isinstance(tr, Trajectory):
            times = zip(tr.event_t.tolist(), tr.event_t_after.tolist())
        elif isinstance(tr.events, EventLog):
            # (the log's time columns: its records need not be made)
            times = zip(tr.events.t.tolist(), tr.events.t_after.tolist())
        else:
            times = ((e.t, e.t_after) for e in tr.events)
        a, b = ts[i], ts[i + 1]
        for t, t_after in times:
            if t - a < margin * T or b - t_after < margin * T:
                return True
    return False


class _Fail(Exception):
    def __init__(self, reason, message, X, T):
        self.reason = reason
        self.message = message
        self.X = X
        self.T = T


def _newton(sh: _Shooter, X, T, *, tol, max_iter, lock_tol, history, allow_rebase=False
            ) -> PeriodicOrbit:
    """Newton shooting on the unknowns ``z = (x_0, ..., x_{N-1}[, T])`` with the package's
    solver (:func:`pwsdyn.newton.newton`); what is particular to free-running shooting is in
    the residual function (the event sequence of a trial is compared with the locked one) and
    in ``on_accept`` (chaining the nodes' discrete states, locking the sequence, moving nodes
    away from events)."""
    ctx, n, N = sh.ctx, sh.ctx.n, sh.N
    T_fixed = T
    run: dict = {"locked": None}

    def unpack(z):
        Xc = [z[i * n:(i + 1) * n] for i in range(N)]
        return Xc, (float(z[-1]) if sh.autonomous else T_fixed)

    def evaluate(Xc, Tc, z):
        trajs, ends, sig = sh.run(Xc, Tc)
        # (``z``: the unknowns these runs are at, so that the orbit returned reuses them)
        run.update(trajs=trajs, ends=ends, sig=sig, z=z.copy())
        return sh.residual(Xc, Tc, trajs)

    def fun(z):
        Xc, Tc = unpack(z)
        if sh.autonomous and "trajs" in run and not (0.05 * sh.T < Tc < 20.0 * sh.T):
            raise TrialRejected("the period left its range", "period")
        saved = {k: run[k] for k in ("trajs", "ends", "sig", "z") if k in run}
        try:
            r = evaluate(Xc, Tc, z)
        except _SimulationFailed as exc:
            run.update(saved)
            raise TrialRejected(_sim_message(sh, exc, Xc), "simulation", exc) from None
        if run["locked"] is not None and run["sig"] != run["locked"]:
            sig = run["sig"]
            run.update(saved)
            raise TrialRejected("the event sequence changed", "signature", sig)
        return r

    def jac(z):
        Xc, Tc = unpack(z)
        return sh.jacobian(Xc, Tc, run["trajs"], run["ends"])

    def jac_scale(J, sv):
        # relative to the blocks' scale (M_i and I): a smallest singular value below 1e-9 of
        # it is a multiplier 1 to the accuracy of the variational solution; the step is noise
        return max(sv[0], 1.0 + max(float(np.abs(tr.jacobian).max()) for tr in run["trajs"]))

    norm = sh.znorm

    def on_accept(z, r, res):
        Xc, Tc = unpack(z)
        ends = run["ends"]
        new = None
        # discrete states must chain: interval i ends in the state node i+1 starts in
        mism = [i for i in range(N) if ends[i] != sh.states[(i + 1) % N]]
        if mism:
            if run["locked"] is not None:
                raise _Fail("signature", _sig_message(sh, mism[0], ends, history), Xc, Tc)
            for i in mism:
                sh.states[(i + 1) % N] = ends[i]
            try:
                new = evaluate(Xc, Tc, z)
            except _SimulationFailed as exc:
                raise _Fail("simulation", _sim_message(sh, exc, Xc), Xc, Tc) from None
            res = norm(new, z)
        if allow_rebase and _events_near_nodes(run["trajs"], sh.times(Tc), Tc):
            raise _Rebase(Xc, Tc)
        if run["locked"] is None and res <= lock_tol:
            run["locked"] = run["sig"]
        elif run["locked"] is not None and run["sig"] != run["locked"]:
            raise _Fail("signature", "the event sequence changed during the Newton iteration "
                        f"after it had converged to {res:.2e}: the orbit is near a grazing, "
                        f"sliding or chattering-count change and its signature is not "
                        f"structurally stable. Locked: {_fmt_sig(run['locked'])}; now: "
                        f"{_fmt_sig(run['sig'])}", Xc, Tc)
        return new

    def fail(reason, msg, Xc, Tc):
        res = None
        try:
            res = _build_orbit(sh, Xc, Tc, history, converged=False)
        except Exception:  # the last iterate may not even integrate; report what we have
            res = None
        raise OrbitError(reason, msg, result=res, history=history)

    z0 = np.concatenate([np.concatenate(X)] + ([np.array([T])] if sh.autonomous else []))
    try:
        out = newton(fun, z0, jac=jac, tol=tol, max_iter=max_iter, norm=norm, halvings=8,
                     singular_rtol=1e-9, jac_scale=jac_scale, max_step_ratio=1e3,
                     on_accept=on_accept, history=history)
    except _Fail as f:
        fail(f.reason, f.message, f.X, f.T)
    Xc, Tc = unpack(out.x)
    if out.converged:
        if sh.autonomous:
            f0 = ctx.field(sh.t0, Xc[0], sh.states[0], sh.gain)
            if np.max(np.abs(f0)) <= 1e-8 * (1.0 + np.max(np.abs(Xc[0]))):
                fail("equilibrium", f"Newton converged to an equilibrium (the vector field "
                     f"vanishes at x0 = {np.asarray(Xc[0]).tolist()}), not to a periodic "
                     f"orbit: the guess is not near one", Xc, Tc)
        # the last runs are at the converged unknowns (Newton stops right after evaluating
        # them): the orbit is made from them, not integrated again
        same = "z" in run and np.array_equal(run["z"], out.x)
        return _build_orbit(sh, Xc, Tc, history, converged=True,
                            runs=(run["trajs"], run["ends"]) if same else None)
    res = history[-1] if history else float("nan")
    it = out.iterations
    if out.reason == "simulation":
        fail("simulation", out.message, Xc, Tc)
    if out.reason == "nonfinite":
        fail("simulation", "the variational solution is not finite", Xc, Tc)
    if out.reason == "singular":
        what = ("a Floquet multiplier is 1 (the one-period map minus the identity is "
                "singular)" if not sh.autonomous else
                "a nontrivial multiplier is 1, or the phase condition is tangent to the "
                "flow at the current iterate")
        fail("singular", f"singular Newton matrix at iteration {it}: {what}; {out.message}",
             Xc, Tc)
    if out.reason == "diverged":
        fail("diverged", f"{out.message}: the guess is not near a periodic orbit", Xc, Tc)
    if out.reason == "no_progress":
        sigs = [e.data for e in out.rejections if e.reason == "signature"]
        if sigs:
            fail("signature", f"every Newton step from the iterate with residual {res:.2e} "
                 f"changes the event sequence, which was locked below lock_tol = "
                 f"{lock_tol:.1e}: the orbit near this guess has another signature, or it "
                 f"is at a grazing, sliding or chattering-count bifurcation. Locked: "
                 f"{_fmt_sig(run['locked'])}; proposed: {_fmt_sig(sigs[0])}", Xc, Tc)
        if sh.autonomous and out.step is not None and \
                not (0.05 * sh.T < float(out.x[-1] + out.step[-1]) < 20.0 * sh.T):
            fail("diverged", f"the period ran away (Newton proposes T = "
                 f"{float(out.x[-1] + out.step[-1]):.6g} from the guess {sh.T:.6g}): the guess "
                 f"is not near a periodic orbit", Xc, Tc)
        fail("no_progress", f"no Newton step (down to 1/128 of the full step) reduced the "
             f"residual {res:.3e} at iteration {it}: the guess is not near a periodic orbit "
             f"(or the orbit is at a grazing/sliding bifurcation)", Xc, Tc)
    fail("budget", f"no convergence in {max_iter} Newton iterations (residual {res:.3e}, "
         f"tolerance {tol:.1e}); residuals: " + " ".join(f"{h:.2e}" for h in history), Xc, Tc)


def _fmt_sig(sig) -> str:
    evs = [f"{k}:{nm}" for (evs_i, _end) in sig for (k, nm, _b, _a) in evs_i]
    return "[" + ", ".join(evs) + "]"


def _sig_message(sh, i, ends, history) -> str:
    return (f"the discrete state at shooting node {(i + 1) % sh.N} changed from "
            f"{sh.ctx.state_name(sh.states[(i + 1) % sh.N])} to {sh.ctx.state_name(ends[i])} "
            f"after the event sequence had been locked (residual "
            f"{history[-1] if history else float('nan'):.2e}): a change of signature")


def _sim_message(sh, exc: _SimulationFailed, X) -> str:
    if exc.traj is not None:
        tr = exc.traj
        return (f"shooting interval {exc.interval} could not be integrated: {tr.message} "
                f"(stopped at t={tr.t_final:.17g} in {tr.state[-1]})")
    return f"shooting interval {exc.interval} could not be integrated: {exc.exc}"


def _build_orbit(sh: _Shooter, X, T, history, *, converged, runs=None) -> PeriodicOrbit:
    """The orbit at the iterate ``(X, T)``, from the runs of its intervals there (``runs``:
    ``(results, end states)`` of :meth:`_Shooter.run` at ``(X, T)``, or None to make them).
    Its ``trajectory`` (the intervals' dense runs, merged) is integrated when first read: the
    same runs with dense output, so the same steps, events and Jacobians."""
    ctx = sh.ctx
    if runs is None:
        runs = sh.run(X, T)[:2]
    runs = runs[0]
    ts = sh.times(T)
    # the monodromy as merge_intervals makes the trajectory's Jacobian: the product of the
    # intervals' Jacobians, from the identity
    M = sh._eye
    events: list = []
    for r in runs:
        M = r.jacobian @ M
        events += list(r.events)
    gain = sh.gain
    st0 = sh.states[0]
    x0 = np.asarray(X[0], dtype=float).copy()
    trivial = pj = None
    if sh.autonomous:
        f0 = ctx.field(ts[0], x0, st0, gain)
        nv = sh.phase_normal
        mult = floquet_multipliers(M, flow_direction=f0, section_normal=nv)
        pj = M - np.outer(f0, nv @ M) / (nv @ f0)          # thesis eq. 2.25
        ev = np.linalg.eigvals(M)
        trivial = complex(ev[np.argmin(np.abs(ev - 1.0))])
    else:
        mult = floquet_multipliers(M)
    # largest mismatch at the junctions of the intervals (the last one closes the period)
    closure = max(float(np.max(np.abs(runs[i].x - X[(i + 1) % len(runs)])))
                  for i in range(len(runs)))
    # the dense runs, when the trajectory is read: the nodes' discrete states as they are
    # now, copies of the unknowns and node times
    states, Xd, tsd = list(sh.states), [np.array(x, dtype=float) for x in X], ts.copy()
    opts = sh.run_opts[True]

    def trajectory():
        return merge_intervals(_dense_intervals(ctx, states, Xd, tsd, opts), t0=tsd[0],
                               t_end=tsd[-1])

    return PeriodicOrbit(
        model=ctx.model, params=dict(ctx.params), t0=float(ts[0]), x0=x0,
        state0=ctx.state_name(st0), period=float(T), events=events,
        trajectory=DeferredTrajectory(trajectory), monodromy=M, multipliers=mult,
        stable=bool(np.all(np.abs(mult) < 1.0 - STABILITY_MARGIN)),
        history=list(history), converged=converged, autonomous=sh.autonomous,
        trivial_multiplier=trivial, poincare_jacobian=pj,
        phase_normal=None if sh.phase_normal is None else np.asarray(sh.phase_normal).copy(),
        nodes=ts[:-1].copy(), residual=float(history[-1]) if history else np.nan,
        closure=closure, options={k: v for k, v in sh.opts.items() if k != "throw"})


def orbit_at(model, x0, *, params=None, period, t0=0.0, mode=None, tol: float = 1e-8,
             **options) -> PeriodicOrbit:
    """One period from ``(t0, x0)`` reported as an orbit without Newton refinement
    (``converged`` says whether it closes to ``tol``). Newton-only options are ignored."""
    for key in ("nodes", "max_iter", "lock_tol", "max_nodes", "phase"):
        options.pop(key, None)
    opts = shooting_options(options, "PeriodicOrbit.from_trajectory()")
    model = as_model(model, kind="flow", caller="PeriodicOrbit.from_trajectory()")
    model.parameter_vector(params)      # unknown or non-finite values refused here
    x0 = V.state_vector(model, x0)
    period = V.positive("period", period)
    t0 = V.number("t0", t0)
    tol = V.tolerance("tol", tol)
    check_state_name(model, mode)
    V.time_window("t0", t0, period, what="one period of the orbit")
    ctx = ModelContext(model, params, opts.get("sliding", "convex"))
    st0 = _initial_state(ctx, mode)
    autonomous = ctx.forcing_period is None
    normal = ctx.field(t0, x0, st0, opts.get("sliding_gain", 0.0)) if autonomous else None
    sh = _Shooter(ctx, t0, period, np.array([float(t0)]), [st0], autonomous, opts, x0.copy(),
                  normal)
    try:
        trajs, ends, _ = sh.run([x0], float(period))
    except _SimulationFailed as exc:
        raise OrbitError("simulation", _sim_message(sh, exc, [x0])) from None
    t1 = float(t0) + float(period)
    sh.states[0] = trajectory_start_state(
        ctx, _trajectory(ctx, x0, sh.states[0], float(t0), t1, sh.run_opts[False], admit=False))
    res = sh.norm(sh.residual([x0], float(period), trajs), [x0])
    return _build_orbit(sh, [x0], float(period), [res], converged=res <= tol)


def _guess_from_trajectory(traj, *, t0=None, period=None, periods=None, recurrence_tol=1e-3,
                           max_periods=RECURRENCE_MAX_PERIODS):
    """``(t0, x0, T, state, recurrence)`` of a periodic-orbit guess at the end of a trajectory.

    ``recurrence`` (a :class:`Recurrence`, ``None`` for an autonomous model given ``period``)
    says how the period was chosen; its ``message`` is the warning to issue ('' if none).
    """
    if traj.dense is None:
        raise ArgumentError("the trajectory has no dense output (simulated with `dense=False`)")
    ctx = ModelContext(traj.model, traj.params, traj.options.get("sliding", "convex"))
    Tf = ctx.forcing_period
    recurrence = None
    if Tf is not None:
        requested = periods
        if period is not None:
            k = float(period) / Tf
            requested = int(round(k)) if abs(k - round(k)) <= 1e-9 * k and k >= 0.5 else None
        if period is None or requested is not None:
            # (a period that is not a multiple of the forcing period is refused downstream)
            recurrence = _forced_recurrence(traj, ctx, Tf, recurrence_tol, max_periods,
                                            requested, explicit=requested is not None)
        if period is None:
            period = recurrence.used * Tf
    elif period is None:
        period, recurrence = _recurrence_period(traj, recurrence_tol)
    T = float(period)
    t_end = float(traj.t[-1])
    if T > t_end - float(traj.t[0]):
        raise ArgumentError(f"the trajectory ({t_end - traj.t[0]:.6g} long) is shorter than the "
                         f"period {T:.6g}")
    if t0 is None:
        t0 = t_end - T
        if Tf is None:
            # autonomous: start in the middle of the longest smooth segment of the last period
            evs = [e for e in traj.events if e.t >= t0]
            bounds = [t0] + [x for e in evs for x in (e.t, e.t_after)] + [t_end]
            spans = [(bounds[i], bounds[i + 1]) for i in range(0, len(bounds) - 1, 2)]
            spans = [s for s in spans
                     if DiscreteState.parse(_name_at(traj, 0.5 * (s[0] + s[1]))).is_mode]
            if spans:
                a, b = max(spans, key=lambda s: s[1] - s[0])
                t0 = 0.5 * (a + b)
    t0 = float(t0)
    x0 = traj(t0, side="right")
    return t0, x0, T, _discrete_state_at(traj, ctx, t0), recurrence


def _discrete_state_at(traj, ctx, t) -> KernelState:
    """The discrete state of a trajectory at ``t``: its ``state`` entry there, a sticking
    state completed with the regular mode it constrains from the event log."""
    name = DiscreteState.parse(_name_at(traj, t))
    if name.kind != "stick":
        return ctx.state(name)
    hint = None
    for e in traj.events:
        if e.t_after > t:
            break
        if DiscreteState.parse(e.mode_after).is_mode:
            hint = e.mode_after
        elif DiscreteState.parse(e.mode_before).is_mode:
            hint = e.mode_before
    return ctx.state(name, mode_hint=hint)


def _forced_recurrence(traj, ctx, Tf, tol, max_periods, requested, *, explicit):
    """Recurrence of the end of a forced trajectory after ``k`` forcing periods.

    The state and the discrete state at a time ``tc`` of the last forcing period are compared
    with those at ``tc - k Tf``, ``k = 1, 2, ...`` up to ``max_periods`` (or ``requested``, if
    larger) and the length of the run. ``tc`` is the middle of the longest event-free stretch
    of the last forcing period, so that a recurring orbit is compared away from its jumps (an
    impact a rounding error before or after ``tc`` would otherwise count as a mismatch).
    """
    t_start, t_end = float(traj.t[0]), float(traj.t[-1])
    a0 = max(t_end - Tf, t_start)
    spans, cur = [], a0
    for e in traj.events:
        if e.t_after <= a0:
            continue
        if e.t > t_end:
            break
        spans.append((cur, max(cur, e.t)))
        cur = max(cur, e.t_after)
    spans.append((cur, max(cur, t_end)))
    a, b = max(spans, key=lambda s: s[1] - s[0])
    tc = 0.5 * (a + b) if b > a else t_end
    xc = traj(tc, side="right")
    sc = _discrete_state_at(traj, ctx, tc)
    last = np.asarray(traj.x)[np.asarray(traj.t) >= a0]
    scale = 1.0 + max(float(np.max(np.abs(xc))), float(np.max(np.abs(last))) if len(last) else 0.0)
    available = int(math.floor((tc - t_start) / Tf * (1.0 + 1e-12)))
    n_check = min(available, max(max_periods, requested or 0))
    dist, same = [], []
    for k in range(1, n_check + 1):
        tk = max(tc - k * Tf, t_start)
        dist.append(float(np.max(np.abs(traj(tk, side="right") - xc))) / scale)
        same.append(_discrete_state_at(traj, ctx, tk) == sc)
    recurs = [d <= tol and s for d, s in zip(dist, same)]
    found = next((k for k in range(1, n_check + 1) if recurs[k - 1]), None)
    base = requested or 1
    ok = base <= n_check and recurs[base - 1]
    used = base
    message = ""
    name = ctx.model.name
    covered = (f"{n_check} forcing period(s)" + (" (all the run covers)"
                                                 if n_check < max_periods else ""))
    if found is not None and found > 1 and requested is None:
        used = found
        message = (f"the trajectory of {name!r} does not recur after one forcing period "
                   f"(relative distance {dist[0]:.2e}"
                   + ("" if same[0] else ", another discrete state")
                   + f" > recurrence_tol = {tol:.1e}) but does "
                   f"after {found} ({dist[found - 1]:.2e}): its settled motion has period "
                   f"{found} (e.g. after a period doubling), and the orbit returned has period "
                   f"{found} * forcing_period = {found * Tf:.10g}. Pass periods={found} to ask "
                   f"for it without this warning, or periods=1 for the period-1 orbit (not the "
                   f"attractor of this run, likely unstable)")
    elif not ok and base > n_check:
        message = (f"the trajectory of {name!r} is too short to check its recurrence after "
                   f"the {base} forcing periods asked for; refining the guess of that period "
                   f"anyway")
    elif not ok and found is not None:
        message = (f"the trajectory of {name!r} does not recur after the {base} forcing "
                   f"period(s) asked for (relative distance {dist[base - 1]:.2e}"
                   + ("" if same[base - 1] else ", another discrete state")
                   + f" > recurrence_tol = {tol:.1e}) but does after {found} "
                   f"({dist[found - 1]:.2e}): the orbit of period {base} refined as asked is not "
                   f"the motion of the run (likely an unstable orbit near it); pass "
                   f"periods={found} for that")
    elif not ok:
        j = int(np.argmin(dist)) if dist else -1
        closest = (f"; closest after {j + 1} forcing period(s): {dist[j]:.2e}" if j >= 0 else "")
        message = (f"the trajectory of {name!r} does not recur within {covered} to "
                   f"recurrence_tol = {tol:.1e}{closest}: it has not settled on a periodic orbit "
                   f"(a transient, or quasi-periodic or chaotic motion). Refining the guess of "
                   f"{base} forcing period(s) {'as asked' if explicit else 'anyway'}: the orbit "
                   f"found need not be the one the run approaches; simulate longer, or give "
                   f"periods= (or a larger max_periods or recurrence_tol)")
    return Recurrence(period=None if found is None else found * Tf, periods=found,
                      requested=requested, used=used, time=float(tc), distances=tuple(dist),
                      same_state=tuple(same), tol=float(tol), max_periods=int(max_periods),
                      message=message)


def _name_at(traj, t) -> str:
    i = int(np.searchsorted(traj.t, t, side="right") - 1)
    i = min(max(i, 0), len(traj.t) - 1)
    return str(traj.state[i])


def _recurrence_period(traj, tol):
    """``(period, recurrence)`` of an autonomous trajectory: the time between its last event
    and the most recent earlier event of the same kind, name and modes whose post-event state
    agrees with it to ``tol`` (relative to ``1 + max|x|``): the smallest recurrence, so a
    period-2 cycle (two passes through the section per period) is not taken for one of half
    its period."""
    evs = list(traj.events)
    if not evs:
        raise ArgumentError("the trajectory has no events to estimate the period of an autonomous "
                         "orbit from; give `period`")
    last = evs[-1]
    scale = 1.0 + np.max(np.abs(traj.x))
    key = (last.kind, last.name, last.mode_before, last.mode_after)
    for e in reversed(evs[:-1]):
        if (e.kind, e.name, e.mode_before, e.mode_after) != key:
            continue
        d = float(np.max(np.abs(e.x_after - last.x_after)) / scale)
        if d <= tol:
            T = float(last.t - e.t)
            return T, Recurrence(period=T, periods=None, requested=None, used=None,
                                 time=float(last.t), distances=(d,), same_state=(True,),
                                 tol=float(tol), max_periods=None, message="")
    raise ArgumentError(f"no recurrence of the last event ({last!r}) within {tol:g} (relative) in "
                     f"the trajectory: it has not settled on a periodic orbit; simulate longer or "
                     f"give `period`")


# ======================================================================================
# the constructor of a PeriodicOrbit from a trajectory: it runs the shooting above, so it is
# defined here and given to the result type, which imports no solver
# ======================================================================================

def from_trajectory(cls, traj: Trajectory, *, t0: float | None = None,
                    period: float | None = None,
                    periods: int | None = None, refine: bool = True,
                    recurrence_tol: float = 1e-3,
                    max_periods: int = RECURRENCE_MAX_PERIODS,
                    **kwargs: Any) -> "PeriodicOrbit":
    """A periodic orbit from a simulated trajectory that has settled on it.

    The period is that of the motion at the end of the run, found by its recurrence (the
    guess is then the state one period before the end, at ``t0 = t_end - period`` unless
    ``t0`` is given):

    * forced model, neither ``periods`` nor ``period`` given: the smallest ``k`` (up to
      ``max_periods``) such that the state and the discrete state (mode, sticking or
      sliding constraint) ``k`` forcing periods before the end of the run agree with those
      at the end, to ``recurrence_tol`` relative to ``1 + max|x|``. They are compared at the
      middle of the longest event-free stretch of the last forcing period, through the dense
      output. ``k = 1`` for a period-1 motion (unchanged from before). A larger ``k`` -- a
      period-doubled motion, say -- is used, and a :class:`RecurrenceWarning` says so: the
      orbit's ``period`` is then ``k * forcing_period`` (``orbit.periods == k``), where one
      might have expected one forcing period. If the run does not recur at all (a
      transient, a quasi-periodic or chaotic motion) the guess of one forcing period is
      refined as before, with a :class:`RecurrenceWarning`: Newton may converge (from a
      rough guess near a stable orbit it does) but nothing says the orbit is the one the
      run approaches.
    * forced model, ``periods`` or ``period`` given: that period is used, as asked; when
      the run does not recur after it a :class:`RecurrenceWarning` says so and names the
      period it does recur at. An explicit request is never replaced: ``periods=1`` on a
      period-doubled run is how one finds the (unstable) period-1 orbit near it, as a
      continuation code (AUTO, COCO) would start from the period it is given.
    * autonomous model: the period is the time between the last event and the most recent
      earlier event of the same kind, name and modes whose post-event state agrees with it
      to ``recurrence_tol`` (relative), unless ``period`` (a guess) is given. No recurrence
      is an :class:`~pwsdyn.errors.ArgumentError`.

    ``orbit.recurrence`` (a :class:`~pwsdyn.orbits.Recurrence`) records what was found. With
    ``refine`` (default) the guess is refined by :func:`pwsdyn.find_periodic_orbit` (``kwargs``
    go there); otherwise one period is re-simulated from the guess and its monodromy reported
    as is (``converged`` then says whether it closed to ``tol``).

    Parameters
    ----------
    traj : Trajectory
        A run with dense output (the default of :func:`pwsdyn.simulate`).
    t0, period : float, optional
    periods : int, optional
        Forced models: the period in forcing periods (default: from the recurrence).
    refine : bool
    recurrence_tol : float
    max_periods : int
        Forced models: the most forcing periods searched for a recurrence.
    **kwargs
        Options of :func:`pwsdyn.find_periodic_orbit`.

    Returns
    -------
    PeriodicOrbit

    Warns
    -----
    RecurrenceWarning
        The run does not recur after one forcing period but after ``k`` (the orbit has
        period ``k``), or not after the period asked for, or not at all.

    Raises
    ------
    OrbitError
        As :func:`pwsdyn.find_periodic_orbit`; its ``result`` carries ``recurrence``.
    """
    if not isinstance(traj, Trajectory):
        raise V.fail("traj", "a Trajectory (the result of pwsdyn.simulate)", traj)
    if getattr(traj.model, "is_map", False) or traj.model is None:
        raise V.fail("traj", "a Trajectory of a flow", traj)
    t0 = V.number("t0", t0, allow_none=True)
    period = V.positive("period", period, allow_none=True)
    if periods is not None:
        periods = V.integer("periods", periods, lo=1, hi=MAX_PERIODS)
    refine = V.flag("refine", refine)
    recurrence_tol = V.positive("recurrence_tol", recurrence_tol)
    max_periods = V.integer("max_periods", max_periods, lo=1, hi=MAX_PERIODS)
    if t0 is not None and not (float(traj.t[0]) <= t0 <= float(traj.t[-1])):
        raise V.fail("t0", f"a time within the trajectory [{float(traj.t[0])!r}, "
                     f"{float(traj.t[-1])!r}] or None", t0)
    t0g, x0g, Tg, state, recurrence = _guess_from_trajectory(
        traj, t0=t0, period=period, periods=periods, recurrence_tol=recurrence_tol,
        max_periods=max_periods)
    if recurrence is not None and recurrence.message:
        warnings.warn(recurrence.message, RecurrenceWarning, stacklevel=2)
    try:
        if refine:
            orbit = find_periodic_orbit(traj.model, x0g, params=traj.params, period=Tg,
                                        t0=t0g, mode=state, **kwargs)
        else:
            orbit = orbit_at(traj.model, x0g, params=traj.params, period=Tg, t0=t0g,
                             mode=state, **kwargs)
    except OrbitError as exc:
        if exc.result is not None:
            exc.result.recurrence = recurrence
        raise
    orbit.recurrence = recurrence
    return orbit


from_trajectory.__qualname__ = "PeriodicOrbit.from_trajectory"
PeriodicOrbit.from_trajectory = classmethod(from_trajectory)
