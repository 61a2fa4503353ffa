"""`simulate`: the one entry point to event-driven simulation for users.

It checks the arguments, resolves the model, state, time span and parameters, and makes one
run through the compiled-model layer (:func:`pwsdyn.integrate.compiled.run_compiled`), whose
lean result becomes the :class:`~pwsdyn.Trajectory` it returns."""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError
from ..model import codegen as _codegen, compile_model
from ..model.codegen import CompiledModel
from ..model.spec import as_model, loaded_original, run_defaults
from .compiled import (_state_name, run_compiled,  # noqa: F401 (_state_name: kept importable)
                       run_trajectory)
# the options live in .options; kept importable from here (tests, the command line)
from .options import (AUTO_DOP853_BELOW, DEFAULT_CHATTER_RATIO, DEFAULTS,  # noqa: F401
                      MAX_BUDGET, SLIDING_METHODS, _check_exact, _check_options, check_mode,
                      check_options, integrator_options, kernel_tables, resolve_method)
from .trajectory import Trajectory

#: Kept importable from here (its home is the argument checks).
state_vector = V.state_vector

if TYPE_CHECKING:
    from .._typing import ModelLike, StateLike


def simulate(model: ModelLike, x0: StateLike | Trajectory | None = None,
             t_span: float | tuple[float, float] | Sequence[float] | None = None,
             params: Mapping[str, float] | None = None, **options: Any) -> Trajectory:
    """Simulate a piecewise-smooth model with events located to near machine precision.

    Parameters
    ----------
    model : Model, str, path or dict
        A model or anything :func:`pwsdyn.load_model` accepts.
    x0 : sequence, dict or Trajectory, optional
        Initial state, in state order or by state name. Default: the model's ``[defaults]
        x0``, else the zero state (with a warning), as on the command line. A state on an
        impact constraint (see "Starts on a constraint" below) starts sticking, with an impact
        at ``t0``, or in free motion, as the constraint requires. A :class:`Trajectory` of
        the same model is *continued*: the run starts from its ``x_final`` in its final
        discrete state (``final_discrete_state``: sticking, sliding or a mode) with its
        parameters (``params`` overrides some), exactly where it stopped; ``mode`` must then
        be None.
    t_span : (float, float) or float, optional
        ``(t0, t_end)``, or ``t_end`` from the model's ``[defaults] t0`` (else 0;
        ``t0 = traj.t_final`` when ``x0`` is a trajectory ``traj``). Default: the model's
        ``[defaults] t_end``, else ``t0 + 10`` (with a warning). Finite, ``t_end > t0``, and
        at least 1024 units of the time resolution ``eps * max(1, |t|)`` long
        (``(1e16, 1e16 + 2)`` is refused: doubles are 2 apart there; see
        ``pwsdyn._validate``). A trajectory continued from another time than its
        ``t_final`` starts from ``x_final`` by the rule for plain states.
    params : dict, optional
        Parameter values by name, over the model's defaults (``model.parameters``: the
        ``[parameters]`` table with ``[defaults] params`` over it, as on the command line).
    method : {'auto', 'RK45', 'DOP853'}
        The Runge-Kutta pair: Dormand-Prince 5(4) or the 8th-order Dormand-Prince pair.
        Default ``'auto'``: DOP853 for ``rtol`` below 1e-7 (the default tolerances included),
        RK45 from 1e-7 on, where each is the faster one (``benchmarks/bench_defaults.py``).
        The pair that ran is recorded in ``traj.options["method"]``.
    exact : {'auto', True, False}
        Propagate the modes that are affine in the state with harmonic forcing,
        ``x' = A x + b + sum_j c_j cos(w_j t) + d_j sin(w_j t)`` (impact and friction
        oscillators with linear springs, a ball in flight, relay feedback of a linear plant),
        by the exact flow ``exp(h M)`` of the system augmented with the forcing (Van Loan
        1978; :mod:`pwsdyn.model.affine`) instead of ``method``: the solution, its dense
        output and the events on it are then exact to rounding, whatever ``rtol``. ``method``
        still integrates the other modes, sticking, sliding and the variational equations.
        Default ``'auto'``: every affine mode is propagated exactly and the others are
        integrated, so a model without any runs on ``method`` alone. ``True`` does the same
        but raises a ``ValueError`` naming the reason of each mode if none is affine;
        ``False`` integrates every mode with ``method``. Exact steps are limited to
        ``||h D^-1 M D|| <= 1`` (``D`` a balancing scaling: a stiff spring's steps follow its
        frequency), so they cost about what an explicit method's stability would allow,
        with no error.
    rtol, atol : float
        Local error tolerances (defaults 1e-10, 1e-12).
    first_step, max_step : float
        Initial step (default: estimated) and largest step. For a forced model (one with a
        ``forcing_period`` T) the default largest step is T/4: where the vector field is
        polynomial (a ball in flight) the error control alone would let a step span many
        periods of a moving surface.
    max_steps, max_events : int
        Budgets; exhausting one ends the run with a status naming time, state and mode.
    chatter : bool
        Detect chattering on ``impact`` events and jump over its accumulation point with the
        complete-chattering map (default True); without it a Zeno sequence exhausts
        ``max_events``.
    chatter_ratio, chatter_velocity : float
        Apply the chattering map once the impact velocity falls below ``chatter_velocity``,
        or below ``chatter_ratio`` times the largest one of the current sequence of impacts.
        By default (``chatter_ratio=None``) that ratio is 1e-4 and applies only where the map
        is accurate (below); a ratio given is applied as given (``1`` jumps at the first
        impact that can chatter). The default ``chatter_velocity`` is
        ``sqrt(2 |a| (atol + rtol |x|))`` with ``a`` the normal acceleration: a bounce that
        rises less than the position tolerance cannot be told from sticking. The map takes
        ``a`` as constant over the sequence (Nordmark & Piiroinen 2009); above the floor it is
        applied only where the change of ``a`` over the sequence's duration ``dt`` moves the
        state by less than the position tolerance (``dt^2 |a(t + dt) - a(t)| <= atol + rtol
        |x|``), so the accumulation point does not depend on where the sequence began (a run
        restarted inside it gives the same one).
    sliding : {'convex', 'utkin'}
        The vector field on a Filippov sliding surface: Filippov's convex combination of the
        fields on either side (thesis eq. 2.7-2.8; default) or Utkin's equivalent control
        (slides, "Simulation: Filippov systems"): for a model written with ``sign(s)`` the
        field ``f(t, x, u)`` with the switching term replaced by ``u`` in ``[-1, 1]`` solving
        ``h_t + h_x f = 0``. The two agree where ``f`` is affine in the switching term (every
        switch written as two explicit modes, dry friction ``mu*sign(v)``, relays ``B sign(y)``)
        and differ where it enters nonlinearly (``sign(s)**2``, a relay inside a nonlinear
        actuator).
    sliding_gain : float
        The rate ``C`` (1/time) of the stabilising term of the sliding field, the slides'
        ``-C h grad h`` divided by ``|grad h|^2``: a drift off the surface decays as
        ``exp(-C t)`` whatever the scale of ``h``. Default 0: every accepted sliding step is
        projected back onto ``h = 0`` instead (one Newton step along ``grad h``), which holds
        the surface to round-off without making the sliding field stiff (a gain ``C`` limits
        explicit steps to about ``3/C`` while sliding).
    variational : bool
        Integrate the variational equations with saltation matrices at every event; the
        result then has ``jacobian`` (``dx(t_end)/dx0``) and ``transfer_matrices`` (the flow
        Jacobian of each smooth segment and the full saltation matrix of each event, see
        :mod:`pwsdyn.stability`). At a grazing event (the flow tangent to the surface,
        ``|h_t + h_x f| <= 1e-13 |h_x| |f|``) the saltation matrix is unbounded: the kernel
        makes it NaN, so that event's transfer matrix and ``jacobian`` are NaN (marked
        singular; :func:`pwsdyn.saltation_matrix` raises there).
    dense : bool
        Store every step with its dense output (default; ``traj(t)`` evaluates it). Only the
        steps' nodes and lengths are stored during the run; the interpolant of a step is
        rebuilt from its start node when it is first evaluated (the same coefficients: the
        step is taken again), so the default costs about what ``dense=False`` does.
        ``False`` keeps only the event log and the end state (for sweeps).
    mode : str, optional
        Initial mode (default: the model's ``initial_mode``). Where modes are joined by
        switching surfaces the side of each surface decides: the mode is replaced by the one
        on the side of ``x0`` (a mode split at ``sign(...)`` may be named by its user name,
        ``"slip"`` for ``slip[v-V>0]``), and a start on a Filippov surface into which both
        fields point starts sliding.
    throw : bool
        Raise :class:`SolveError` if the run fails (default). With ``False`` the failed
        trajectory is returned with its ``status`` and ``message``.

    Returns
    -------
    Trajectory

    Starts on a constraint
    ----------------------
    A state carried over from a run (``traj.x_final``) lies on a constraint only up to
    round-off and the tolerance the sticking motion holds it to, and may be a little behind
    it. Before integrating, every impact constraint ``h >= 0`` active in the initial mode is
    examined (:mod:`pwsdyn.integrate._start`): where ``|h|`` is within
    ``max(64 eps max(1, |x|), atol + rtol |x|) max(1, |h_x|)`` (the kernel's round-off band,
    the one that decides the side of a switching surface, or the position tolerance if
    larger) the state is on the constraint and starts

    * sticking on it (projected onto ``h = 0, hdot = 0``) when the normal velocity ``hdot``
      is within its band (the same rule on ``hdot_x``) and the free normal acceleration
      points into the constraint;
    * with the impact at ``t0`` when ``hdot < 0`` beyond that band;
    * in free motion otherwise (leaving the constraint).

    A state a little behind a constraint is put on it first: within
    ``1e-8 (1 + |x|) max(1, |h_x|)`` (a long sticking run drifts behind the wall by more than
    the tolerances; ``pwsdyn.integrate._start.ADMIT_BEHIND``). A state further behind is
    inside the wall: an :class:`ArgumentError` names the event and the value of ``h``. A
    start within round-off of a Filippov switching surface into which both fields point
    starts sliding.

    Raises
    ------
    ArgumentError
        (a ``ValueError`` and ``TypeError``) Before any work: a bad model, state, time span,
        parameter or option, naming it and what it must be; a state inside an impact
        constraint.
    SolveError
        The run failed (with ``throw=True``).

    Examples
    --------
    >>> import pwsdyn
    >>> traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 5))
    >>> traj.events[0].kind
    'impact'
    """
    opts = integrator_options(options, "simulate()")
    copy = None
    if type(model) is str:
        # a name (or path) loaded before and unchanged: the run reads the loaded original,
        # the trajectory makes its own copy when its model is read (loaded_original). Not a
        # cheaper copy per call: load_model's copy (dicts and the parsed file unmarshalled,
        # then freed) cost ~10 us, a one-period run ~4 us; checking the file's key costs a
        # stat, and every trajectory still hands out a model of its own, so a caller that
        # changes it changes no other trajectory and no later load.
        hit = loaded_original(model)
        if hit is not None and not getattr(hit[0], "is_map", False):
            model, copy = hit
    if copy is None:
        model = as_model(model, kind="flow", caller="simulate()")
    cont = x0 if isinstance(x0, Trajectory) else None
    if cont is not None:
        params = _continued_params(model, cont, opts, params)
        x0 = cont.x_final
    if cont is None and x0 is not None and type(t_span) is tuple:
        t0_default = None       # no default needed: the caller gives the state and both ends
    elif cont is None:
        t_end = t_span if t_span is None or V.is_real(t_span) else 0.0
        run = run_defaults(model, x0=x0, t_end=t_end)
        if run.fallback:
            for note in run.note(model):
                warnings.warn(note, stacklevel=2)
        x0, t0_default = run.x0, run.t0
        if t_span is None:
            t_span = (run.t0, run.t_end)
    else:
        t0_default = cont.t_final
        if t_span is None:
            raise ArgumentError("`t_span` is required to continue a trajectory: give t_end "
                                "or (t0, t_end)")
    p = model.parameter_vector(params)
    x = _state(model, x0)
    t0, t_end = _time_span(t_span, t0=t0_default)
    check_mode(model, opts)
    if not isinstance(opts["exact"], str) and opts["exact"]:
        _check_exact(model)
    cm = _compiled(model)
    state = None if cont is None else cont.final_discrete_state
    if state is not None and t0 == cont.t_final and len(state) == 3:
        kind, idx, mode0 = (int(v) for v in state)
        return _simulate_compiled(cm, x, t0, t_end, p, opts, mode0=mode0, dkind0=kind,
                                  didx0=idx, refuse=True, model=model, checked=True,
                                  copy=copy)
    return _simulate_compiled(cm, x, t0, t_end, p, opts, refuse=True, model=model,
                              checked=True, copy=copy)


def _compiled(model) -> CompiledModel:
    """The compiled functions of ``model``, from :func:`compile_model`'s memo by digest
    without pairing them with ``model``: a model loaded by name is a new object on every
    load (:func:`pwsdyn.load_model`), which :func:`compile_model` would pair anew on every
    call. The ``cm.model`` returned may be another object with the same digest; the caller's
    model goes into the trajectory."""
    cm = _codegen._COMPILED.get(model.digest)
    return compile_model(model) if cm is None else cm


def _state(model, x0) -> np.ndarray:
    """:func:`state_vector`, with a shortcut for a tuple or list of finite floats."""
    if (type(x0) is tuple or type(x0) is list) and len(x0) == model.n_states \
            and all(type(v) is float and math.isfinite(v) for v in x0):
        return np.array(x0, dtype=float)
    return state_vector(model, x0)


def _continued_params(model, traj, opts, params):
    """The parameters of a run continuing ``traj``: its own, with ``params`` over them;
    ``traj`` must be a trajectory of ``model`` and ``mode`` unset."""
    if getattr(traj.model, "hash", None) != model.hash:
        raise ArgumentError(f"`x0` is a trajectory of model "
                            f"{getattr(traj.model, 'name', '?')!r}, not of {model.name!r}: a "
                            "trajectory is continued with its own model")
    if opts.get("mode") is not None:
        raise ArgumentError("`mode` must be None when `x0` is a trajectory to continue (the "
                            "run starts in its final discrete state)")
    if not len(traj.t):
        raise ArgumentError("`x0` is an empty trajectory: there is no state to continue from")
    merged = {k: v for k, v in (traj.params or {}).items() if k in model.parameters}
    if params is not None:
        if not isinstance(params, Mapping):
            raise V.fail("params", "a dict of parameter values by name", params)
        merged.update(params)
    return merged


def _time_span(t_span, name: str = "t_span", t0=None):
    """``(t0, t_end)`` from ``t_span``: finite, ``t_end > t0`` and resolvable in double
    precision (:func:`pwsdyn._validate.time_span`: at least 1024 units ``eps max(1, |t|)``).
    A single number is ``t_end`` from ``t0`` (default 0)."""
    if type(t_span) is tuple and len(t_span) == 2:
        # two finite floats (most calls): what the checks below return for them
        a, b = t_span
        if type(a) is float and type(b) is float and math.isfinite(a) and math.isfinite(b):
            V.time_span(name, a, b)
            return a, b
    must = "(t0, t_end) or t_end, with finite numbers"
    if V.is_real(t_span):
        t0, t_end = (0.0 if t0 is None else float(t0)), V.number(name, t_span, must=must)
    else:
        if isinstance(t_span, (str, bytes, Mapping)) or not hasattr(t_span, "__len__"):
            raise V.fail(name, must, t_span)
        ts = list(t_span)
        if len(ts) != 2:
            raise ArgumentError(f"`{name}` must be (t0, t_end) or t_end, got "
                                f"{V.describe(t_span)}")
        t0, t_end = (V.number(name, v, must=must) for v in ts)
    V.time_span(name, t0, t_end)
    return t0, t_end



def _simulate_compiled(cm: CompiledModel, x, t0, t_end, p, opts, mode0=None, dkind0=None,
                       didx0=None, stop=None, sample=None, admit=True, refuse=False,
                       store_dense=False, model=None, checked=False,
                       copy=None) -> Trajectory:
    """:func:`~pwsdyn.integrate.compiled.run_compiled` (the one run entry point, arguments
    as there) with its result made a :class:`Trajectory`, raising :class:`SolveError` for a
    failed run with ``opts["throw"]``: the run behind :func:`simulate`. ``copy``: makes the
    trajectory's model where ``model`` is a loaded original that is not handed out
    (:func:`~pwsdyn.integrate.compiled.run_trajectory`)."""
    if not checked:
        _check_options(opts)
    if model is None:
        model = cm.model
    res = run_compiled(cm, x, t0, t_end, p, opts, mode0=mode0, dkind0=dkind0, didx0=didx0,
                       stop=stop, sample=sample, admit=admit, refuse=refuse,
                       store_dense=store_dense, model=model, checked=True)
    traj = run_trajectory(res, model, opts, t0, t_end, copy)
    if res.status.failed and opts["throw"]:
        raise res.solve_error(model, result=traj)
    return traj
