"""`simulate`: the one entry point to event-driven simulation."""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .._version import __version__
from .. import _validate as V
from ..errors import ArgumentError, SolveError, Status
from ..model import codegen as _codegen, compile_model
from ..model.codegen import CompiledModel
from ..model.affine import affine_structure
from ..model.spec import as_model, run_defaults
from ._load import kernel
from ._codes import (EVENT_TABLE, SAVE_DENSE, SAVE_EVENTS, SAVE_NODES, STATS, SWITCH_TABLE,
                     VAR_NONE, VAR_SEGMENTS, KernelResult, kernel_options)
from ._start import ADMIT_BEHIND, STICK, abs_max, start_state
from ._variational import assemble_segments
from .tableaus import METHODS
from .trajectory import DiscreteState, EventLog, LazyDense, Trajectory

if TYPE_CHECKING:
    from .._typing import ModelLike, StateLike

#: Default options of :func:`~pwsdyn.simulate` (each documented there).
DEFAULTS = dict(method="auto", exact="auto", rtol=1e-10, atol=1e-12, first_step=None,
                max_step=math.inf, max_steps=1_000_000, max_events=100_000, chatter=True,
                chatter_ratio=None, chatter_velocity=None, sliding="convex", sliding_gain=0.0,
                variational=False, dense=True, mode=None, throw=True)

#: Ratio of the impact speed to the largest of its sequence below which the chattering map
#: applies by default, where it is accurate (option ``chatter_ratio``).
DEFAULT_CHATTER_RATIO = 1e-4

#: ``method="auto"`` takes the 8th-order pair below this relative tolerance, RK45 from it on
#: (measured: ``benchmarks/bench_defaults.py``).
AUTO_DOP853_BELOW = 1e-7

#: Sliding methods (option ``sliding``) and their kernel codes.
SLIDING_METHODS = {"convex": 0, "utkin": 1}


def integrator_options(options: Mapping, caller: str, reserved=()) -> dict:
    """``options`` merged over :data:`DEFAULTS` and checked (:func:`check_options`), after
    rejecting unknown names and those the caller sets itself (``reserved``), with an
    :class:`~pwsdyn.errors.ArgumentError` (a ``TypeError``) naming ``caller``."""
    bad = sorted(set(options) & set(reserved)) if reserved else None
    if bad:
        raise ArgumentError(f"{caller}: option(s) {bad} are set by {caller} itself; remove them")
    if not options.keys() <= DEFAULTS.keys():
        unknown = sorted(set(options) - set(DEFAULTS), key=str)
        raise ArgumentError(f"{caller} got unexpected keyword argument(s) {unknown}; "
                            f"integrator options are {sorted(set(DEFAULTS) - set(reserved))}")
    opts = {**DEFAULTS, **options}
    _check_options(opts)
    return opts


#: Kept importable from here (its home is the argument checks).
state_vector = V.state_vector


def check_mode(model, opts) -> None:
    """The ``mode`` option names a mode of ``model`` (or is None)."""
    mode = opts.get("mode")
    if mode is None:
        return
    if not isinstance(mode, str):
        raise V.fail("mode", f"None or a mode name of model {model.name!r} "
                     f"{list(model.mode_names)}", mode)
    try:
        model.mode_index(mode)
    except ValueError:
        raise ArgumentError(f"`mode` must be a mode of model {model.name!r}: unknown mode "
                            f"{mode!r}; modes are {list(model.mode_names)}") from None


def _state_name(model, kind: int, idx: int, mode: int) -> DiscreteState:
    """The discrete state of the kernel's code ``(kind, index, mode)``."""
    if kind == 0:
        return DiscreteState("mode", model.modes[mode].name)
    if kind == 1:
        return DiscreteState("stick", model.events[idx].name)
    return DiscreteState("slide", model.switches[idx].name)


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
                                  didx0=idx, refuse=True, model=model, checked=True)
    return _simulate_compiled(cm, x, t0, t_end, p, opts, refuse=True, model=model,
                              checked=True)


def _compiled(model) -> CompiledModel:
    """The compiled functions of ``model``, from :func:`compile_model`'s memo by digest
    without pairing them with ``model``: a model loaded by name is a new object on every
    load (:func:`pwsdyn.load_model`), which :func:`compile_model` would pair anew on every
    call. The ``cm.model`` returned may be another object with the same digest; the caller's
    model goes into the trajectory."""
    cm = _codegen._COMPILED.get(model.digest)
    return compile_model(model) if cm is None else cm


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


#: Largest step and event budgets (the kernel counts in int64).
MAX_BUDGET = V.MAX_COUNT


def check_options(opts) -> None:
    """Check every integrator option of a merged option dict (types, ranges, finiteness),
    raising :class:`~pwsdyn.errors.ArgumentError` naming the option."""
    if not isinstance(opts["method"], str) or (opts["method"] not in METHODS
                                                and opts["method"] != "auto"):
        raise V.fail("method", f"'auto' or one of {sorted(METHODS)}", opts["method"])
    if "exact" in opts and not (isinstance(opts["exact"], str) and opts["exact"] == "auto"):
        if not isinstance(opts["exact"], (bool, np.bool_)):
            raise V.fail("exact", "'auto', True or False", opts["exact"])
    for k in ("chatter", "variational", "dense", "throw"):
        if k in opts:
            V.flag(k, opts[k])
    for k in ("rtol", "atol"):
        V.positive(k, opts[k])
    if opts["rtol"] < 1e-15:
        raise ArgumentError("`rtol` below 1e-15 cannot be met in double precision, got "
                            f"{opts['rtol']!r}")
    if not opts["rtol"] < 1.0:
        raise V.fail("rtol", "a number in [1e-15, 1) (a relative tolerance)", opts["rtol"])
    for k in ("max_steps", "max_events"):
        V.integer(k, opts[k], lo=1, hi=MAX_BUDGET)
    V.positive("first_step", opts["first_step"], allow_none=True)
    V.positive("max_step", opts["max_step"], allow_inf=True)
    # >= 1: the chattering map applies at the first impact (ratio to the largest impact speed)
    V.positive("chatter_ratio", opts["chatter_ratio"], allow_none=True)
    V.nonnegative("chatter_velocity", opts["chatter_velocity"], allow_none=True)
    if not isinstance(opts.get("sliding", "convex"), str) \
            or opts.get("sliding", "convex") not in SLIDING_METHODS:
        raise V.fail("sliding", f"one of {sorted(SLIDING_METHODS)}", opts.get("sliding"))
    V.nonnegative("sliding_gain", opts.get("sliding_gain", 0.0))
    mode = opts.get("mode")
    if mode is not None and not isinstance(mode, str):
        raise V.fail("mode", "None or a mode name", mode)


#: Option sets that passed :func:`check_options`, as their items and the values' types: the
#: check is a function of the values and their types alone, and loops (sweeps, shooting,
#: continuation) pass the same options on every call.
_CHECKED: set = set()
_CHECKED_MAX = 512


def _check_options(opts):
    """:func:`check_options`, once per set of option values."""
    try:
        key = (tuple(opts.items()), tuple(map(type, opts.values())))
        known = key in _CHECKED
    except TypeError:       # an unhashable value: checked every time
        key, known = None, False
    if known:
        return
    check_options(opts)
    if key is not None:
        if len(_CHECKED) >= _CHECKED_MAX:
            _CHECKED.clear()
        _CHECKED.add(key)


def resolve_method(opts) -> str:
    """The Runge-Kutta pair that runs: ``method``, or for ``'auto'`` DOP853 below
    ``rtol = AUTO_DOP853_BELOW`` and RK45 from it on."""
    method = opts["method"]
    if method != "auto":
        return method
    return "DOP853" if opts["rtol"] < AUTO_DOP853_BELOW else "RK45"


def _exact_code(model, exact) -> int:
    """The kernel option ``exact``: 1 (the affine modes propagated exactly) for ``exact=True``, after
    checking that the model has one, and for ``'auto'`` (the kernel finds the affine modes;
    a model without any runs on the Runge-Kutta pair alone); 0 for False."""
    if isinstance(exact, str):
        return 1
    if exact:
        _check_exact(model)
        return 1
    return 0


def _max_step(model, p, max_step) -> float:
    """The largest step: the user's, else a quarter forcing period for forced models."""
    if math.isfinite(max_step) or model.forcing_period is None:
        return min(max_step, 1e300)
    period = model.forcing_period_function(*p)
    return period / 4.0 if math.isfinite(period) and period > 0 else 1e300


_TABLES: dict = {}
_AFFINE_CHECKED: set = set()


def _check_exact(model) -> None:
    """``exact=True`` needs at least one affine mode; say why each mode is not one."""
    if model.hash in _AFFINE_CHECKED:
        return
    aff = affine_structure(model)
    if not aff.any:
        why = "; ".join(f"mode {m.name!r}: {r}" for m, r in zip(model.modes, aff.reasons))
        raise ArgumentError(f"`exact=True` needs a mode that is affine in the states with harmonic "
                         f"forcing; model {model.name!r} has none ({why})")
    _AFFINE_CHECKED.add(model.hash)


def kernel_tables(cm: CompiledModel, sliding: str = "convex"):
    """The kernel's event table (records of ``EVENT_TABLE``: surface, direction, kind,
    target, terminal, has_reset, time_dependent), event activity per mode and switch table
    (records of ``SWITCH_TABLE``: surface, above, below, kind, sliding, time_dependent).
    Built once per model and sliding method: loops (shooting, sweeps) call the kernel many
    times."""
    key = (cm.model.hash, cm.source_path, sliding)
    if key not in _TABLES:
        _TABLES[key] = _build_kernel_tables(cm, sliding)
    return _TABLES[key]


def _build_kernel_tables(cm: CompiledModel, sliding: str):
    model = cm.model
    ne = len(model.events)
    tdep = cm.surface_time_dependent
    if tdep is None:
        tdep = np.zeros(len(model.surfaces), dtype=np.int64)
    etab = np.zeros(max(ne, 0), dtype=EVENT_TABLE)
    for j in range(ne):
        etab[j] = (cm.event_surface[j], cm.event_direction[j], cm.event_kind[j],
                   cm.event_target[j], cm.event_terminal[j], cm.event_has_reset[j],
                   tdep[cm.event_surface[j]])
    eact = np.ascontiguousarray(cm.event_active[:ne].astype(np.int64)).reshape(ne, len(model.modes))
    ns = len(model.switches)
    if sliding not in SLIDING_METHODS:
        raise ArgumentError(f"`sliding` must be one of {sorted(SLIDING_METHODS)}, got {sliding!r}")
    stab = np.zeros(ns, dtype=SWITCH_TABLE)
    kinds = cm.switch_kind if cm.switch_kind is not None else np.zeros(ns, dtype=np.int64)
    for s in range(ns):
        stab[s] = (cm.switch_surface[s], cm.switch_above[s], cm.switch_below[s], kinds[s],
                   SLIDING_METHODS[sliding], tdep[cm.switch_surface[s]])
    return etab, eact, stab


def _simulate_compiled(cm: CompiledModel, x, t0, t_end, p, opts, mode0=None, dkind0=None,
                       didx0=None, stop=None, sample=None, admit=True, refuse=False,
                       store_dense=False, model=None, checked=False):
    """The kernel run behind :func:`simulate`, without re-validating model, state, params.

    ``dkind0``, ``didx0``: initial discrete state (0 mode, 1 sticking on event ``didx0``, 2
    sliding on switch ``didx0``; default a regular mode). A start in a regular mode goes
    through :func:`pwsdyn.integrate._start.start_state` (``admit``, default True): a state on
    an impact constraint (within round-off or the position tolerance ``atol + rtol |x|``)
    starts sticking, with the impact at ``t0`` or in free motion, and one a little behind it
    (``ADMIT_BEHIND``) is put on it first; one further behind raises :class:`ArgumentError`
    with ``refuse`` (the public entry points) and is left alone otherwise. Newton
    iterations (shooting) pass ``admit=False``: they integrate exactly the state they are
    given. ``stop = (kind_mask, ref, count)``
    ends the run (status TERMINAL_EVENT) at the ``count``-th logged event whose kind code
    (``EVENT_KINDS`` index) has its bit set in ``kind_mask`` and whose event or switch index is
    ``ref`` (-1: any), so Poincaré maps on event sections run in one kernel call.
    ``sample = (t_first, dt)`` records the state at ``t_first + k dt`` (``k >= 0``, within the
    run) from the dense output, without events or landing steps: stroboscopic sections
    (``traj.samples``). ``store_dense`` stores the dense output of every step as the run
    goes (as variational runs do) instead of rebuilding it from the nodes when it is read.
    ``model``: the model the trajectory carries (default ``cm.model``; one with the same
    digest); ``checked``: ``opts`` passed :func:`check_options` already.
    """
    if not checked:
        _check_options(opts)
    if model is None:
        model = cm.model
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
    kopts = kernel_options(
        mode0=mode0, n_modes=len(model.modes), max_steps=opts["max_steps"],
        max_events=opts["max_events"], method=tab.code, order=tab.order,
        variational=VAR_SEGMENTS if opts["variational"] else VAR_NONE, chatter=opts["chatter"],
        save=save, stop=stop, dkind0=0 if dkind0 is None else dkind0,
        didx0=-1 if didx0 is None else didx0, exact=_exact_code(model, opts["exact"]),
        rtol=opts["rtol"], atol=opts["atol"], first_step=opts["first_step"] or 0.0,
        max_step=_max_step(model, p, opts["max_step"]),
        # negative: the default ratio, applied where the map is accurate
        chatter_ratio=(-DEFAULT_CHATTER_RATIO if opts["chatter_ratio"] is None
                       else opts["chatter_ratio"]),
        chatter_velocity=-1.0 if opts["chatter_velocity"] is None else opts["chatter_velocity"],
        sliding_gain=opts["sliding_gain"], sample=sample)
    pv = np.ascontiguousarray(p if p.size else np.zeros(1), dtype=float)
    x = np.array(x, dtype=float)
    res = KernelResult(*K.run_kernel(cm.evaluate, float(t0), float(t_end), x, pv, etab, eact,
                                     stab, kopts, tab.A, tab.C, tab.E, tab.P, tab.n_stages))
    (status, t_fin, y_fin, dstate, nodes_t, nodes_y, nodes_s, dense, ikind, ev_t, ev_t2, ev_info,
     ev_xb, ev_xa, stats, samples, hstep) = res
    if save == SAVE_NODES:
        dense = _lazy_dense(cm, pv, etab, stab, kopts, tab, float(t0), x, nodes_t, nodes_y,
                            nodes_s, hstep, dense.shape[2])
    n = model.n_states
    jac = transfer = None
    if opts["variational"]:
        # per-segment transfer matrices; Phi made global in nodes, dense output and events
        transfer, jac = assemble_segments(n, nodes_y, dense, ev_info, ev_xb, ev_xa, y_fin)
    status = Status(int(status))
    # discrete state per node, mapped through the few distinct codes (vectorised: runs can
    # have millions of nodes)
    N = len(nodes_s)
    if N and (nodes_s == nodes_s[0]).all():
        # one discrete state throughout (most short runs): the same array, fewer steps
        states = np.repeat(_label_array(model, tuple(nodes_s[0].tolist())), N)
    else:
        d = nodes_s[1:] != nodes_s[:-1]
        starts = np.concatenate(([0], np.flatnonzero(d[:, 0] | d[:, 1] | d[:, 2]) + 1))[:N]
        label: dict = {}
        for code in map(tuple, nodes_s[starts].tolist()):
            if code not in label:
                label[code] = _state_name(model, *code)
        run_names = np.array([label[c] for c in map(tuple, nodes_s[starts].tolist())],
                             dtype=str)
        states = (np.full(N, run_names[0]) if len(starts) == 1 else
                  np.repeat(run_names, np.diff(np.append(starts, N))))
    # the event log as arrays; its records are made when it is read (sweeps read columns)
    events = EventLog(model, ev_t, ev_t2, ev_info, ev_xb[:, :n].copy(), ev_xa[:, :n].copy(),
                      _state_name)
    stat = dict(zip(STATS, stats.tolist()))
    params = dict(zip(model.parameters, pv.tolist()))
    traj = Trajectory(
        t=nodes_t, x=nodes_y[:, :n].copy(), state=states, events=events, status=status,
        message=status.message, stats=stat, model=model, params=params,
        options={**{k: v for k, v in opts.items() if k != "throw"}, "method": method},
        t0=t0, t_end=t_end,
        jacobian=jac, transfer_matrices=transfer,
        final_discrete_state=tuple(dstate.tolist()),
        samples=(samples[:, 0].copy(), samples[:, 1:].copy()) if sample is not None else None,
        _dense=dense if opts["dense"] else None,
        _ikind=ikind, _y=nodes_y,
        provenance={"model": model.name, "model_hash": model.hash, "pwsdyn_version": __version__},
    )
    if status.failed and opts["throw"]:
        mode_name = _state_name(model, *dstate)
        raise SolveError(status, float(t_fin), dict(zip(model.states, y_fin[:n])), mode_name,
                         result=traj)
    return traj
