"""Shared pieces of the global analyses: the model as it travels to workers, the integration
of one window of forcing periods with a stroboscopic section, and the period estimate.

Workers receive a model as its *spec* (the dict the TOML file holds), never as compiled
numba functions. Each worker process loads it once
(:meth:`pwsdyn.integrate.compiled.ModelContext.get`) and calls ``compile_model``, which finds
the generated module in the on-disk cache by the model hash and loads its machine code
(:mod:`pwsdyn.model.codegen`), so no task recompiles anything.

Stroboscopic section of a flow
------------------------------
The state at the times ``t_k = (k + phase) T`` is recorded by the compiled kernel itself, on
its dense output, as it steps (the internal runner's ``sample=(t_first, T)``): a whole
transient and window of hundreds of periods is one kernel call, with no event and no landing
step for the section.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import _validate as V
from ..errors import ArgumentError, Status
from ..integrate.compiled import ModelContext, Start, load_kernel
from ..integrate.options import check_mode, integrator_options

#: Event kinds counted in "events per period" (state changes -- stick, release, slide start
#: and end -- are reported as times instead).
COUNTED_KINDS = ("impact", "transition", "crossing", "chatter")

#: The outcomes of the analyses themselves (the rest are the integrator's), members of the
#: one :class:`pwsdyn.Status`.
DIVERGED = Status.DIVERGED
SECTION_MISSED = Status.SECTION_MISSED


def model_payload(model) -> dict:
    """What a worker needs to rebuild ``model``: its spec dict and origin (picklable).

    Called once per run in the calling process, after the arguments are checked and before
    any work is handed out: for a flow it also loads the compiled integrator here, so on a
    machine without numba's cache it is compiled once, in this process, with its message
    (:func:`pwsdyn.integrate.compiled.load_kernel`), not at the same time in every worker."""
    if not model.spec:
        raise ArgumentError(f"model {model.name!r} has no spec dict (it was not made by "
                         "pwsdyn.load_model); build it with load_model to use it here")
    if not getattr(model, "is_map", False):
        load_kernel()
    return {"spec": model.spec, "origin": model.origin, "hash": model.hash}


def readmit(ctx: ModelContext, t: float, x, p) -> np.ndarray:
    """``x`` moved onto the admissible side of every impact surface it lies behind, for a
    restart at time ``t`` (:func:`pwsdyn.integrate._start.start_state`, the rule every run of
    :func:`pwsdyn.simulate` and the internal runner starts with).

    A state carried from one kernel run to the next (to the next parameter value, the next
    Lyapunov segment) may be sticking on an impact surface, ``h = 0`` up to round-off and the
    tolerance the sticking motion holds it to, or the constraint may have moved onto it with
    the parameter (an impact oscillator's gap ``sigma`` swept past the carried position). In
    both cases the state is put on the surface, as a wall moved quasi-statically pushes the
    body with it; the run then starts sticking, with an impact or in free motion as the
    runner's start rule decides. (Left behind the wall, the kernel would integrate it there
    without ever meeting the surface: a silent run with no impacts.) The first state of a
    sweep is the user's ``x0`` and is checked, not moved (:func:`check_start`).
    """
    return start_of(ctx, t, x, p).x


def start_of(ctx: ModelContext, t: float, x, p) -> Start:
    """The start :func:`readmit` takes: the state and the discrete state (sticking on an
    impact surface, or regular) that a run from ``x`` at ``t`` begins in."""
    return ctx.start(t, x, p, behind_tol=math.inf)


def sorted_values(label: str, values) -> np.ndarray:
    """The values a sweep or scan runs over (``label`` names them in errors): a non-empty
    sequence of distinct finite numbers, returned sorted."""
    if V.is_real(values) or isinstance(values, (str, bytes)) or values is None:
        raise ArgumentError(f"{label} must be a non-empty sequence of numbers, got "
                            f"{V.describe(values)}")
    vals = V.vector(label, values, finite=False)
    if vals.size == 0:
        raise ArgumentError(f"{label} must be a non-empty sequence of numbers, got "
                            f"{V.describe(values)}")
    if not np.all(np.isfinite(vals)):
        raise ArgumentError(f"{label} must be finite, got {V.describe(values)}")
    vals = np.sort(vals)
    if np.any(np.diff(vals) == 0):
        raise ArgumentError(f"{label} must be distinct")
    return vals


def check_run_kind(model, section: str, period, options: dict, caller: str) -> None:
    """What a map or a flow accepts in a sweep or scan: a map records every iterate (no
    section, no integrator options); a flow needs a known section, a time unit (its forcing
    period or ``period``) and valid integrator options."""
    if not isinstance(section, str):
        # (compared with a string first, an array would be compared element by element)
        raise ArgumentError(f"`section` must be 'stroboscopic' or the name of an event or "
                            f"switch of model {model.name!r}, got {V.describe(section)}")
    if getattr(model, "is_map", False):
        if section != "stroboscopic":
            raise ArgumentError(f"model {model.name!r} is a map: every iterate is recorded; "
                                "`section` applies to flows only")
        if options:
            raise ArgumentError(f"integrator options {sorted(options, key=str)} apply to "
                                f"flows, not to map {model.name!r}")
        return
    check_section(model, section)
    if period is None and model.forcing_period is None:
        raise ArgumentError(f"model {model.name!r} is autonomous: give `period`, the time "
                            "unit of `transient` and `samples`")
    check_mode(model, integrator_options(options, caller))


def start_vector(model, x0) -> np.ndarray:
    """``x0`` as a state vector, the model's ``[defaults] x0`` when it is None."""
    if x0 is None:
        x0 = model.defaults.get("x0")
        if x0 is None:
            raise ArgumentError(f"give `x0`: model {model.name!r} has no [defaults] x0")
    return V.state_vector(model, x0)


def first_values(vals: np.ndarray, direction: str) -> np.ndarray:
    """The values (sorted ``vals``) at which a sweep in ``direction`` starts from ``x0``."""
    return {"up": vals[:1], "down": vals[-1:], "both": vals[[0, -1]]}[direction]


def check_start(model, x0, p, pidx, starts, phase: float, period, what: str = "x0") -> None:
    """Refuse ``x0`` where a run of a sweep or scan starts from it (the parameter values
    ``starts`` of parameter ``pidx``, the others ``p``) and it lies inside an impact
    constraint, with the error :func:`pwsdyn.simulate` gives for it: a run from there would
    meet no surface and report a motion without impacts."""
    if getattr(model, "is_map", False) or not model.events:
        return
    ctx = ModelContext(model, dict(zip(model.parameters, map(float, p))))
    for value in starts:
        pv = np.array(p, dtype=float)
        pv[pidx] = float(value)
        T = period if period is not None else model.forcing_period_at(pv)
        try:
            ctx.start(float(phase) * float(T), x0, pv, refuse=True, names=what)
        except ArgumentError as exc:
            raise ArgumentError(f"{exc} (at {list(model.parameters)[pidx]} = {float(value)!r}, "
                                "where the sweep starts from it)") from None


def period_estimate(points: np.ndarray, max_period: int, tol: float) -> int:
    """The smallest ``k <= max_period`` such that the section points repeat after ``k``.

    ``points`` (m, d) are consecutive section points (NaN rows are ignored at the end). Points
    ``j`` and ``j + k`` must agree within ``tol * (1 + max |P|)`` in every component for all
    ``j`` in the second half of the record (at least ``k`` pairs). Returns 0 when no such
    ``k`` exists (non-periodic within the record, or too few points).
    """
    pts = np.asarray(points, dtype=float)
    good = np.all(np.isfinite(pts), axis=1)
    if not good.all():
        pts = pts[: np.argmin(good)] if not good[0] or good.any() else pts[:0]
    m = len(pts)
    if m < 2:
        return 0
    scale = tol * (1.0 + float(np.max(np.abs(pts))))
    return int(_first_shift(np.ascontiguousarray(pts), int(max_period), scale))


@njit(cache=True, nogil=True)
def _first_shift(pts, max_period, scale):
    """The loop of :func:`period_estimate` over the shifts, compiled (a sweep estimates a
    period per value; in numpy it cost three array calls per shift tried)."""
    m, d = pts.shape
    start = m // 2
    for k in range(1, max_period + 1):
        if m - start - k < k:
            break
        same = True
        for j in range(start, m - k):
            for c in range(d):
                if not abs(pts[j + k, c] - pts[j, c]) <= scale:
                    same = False
                    break
            if not same:
                break
        if same:
            return k
    return 0


def state_times(t, after, chatter, t_lo: float, t_hi: float, initial: int = 0
                ) -> tuple[float, float]:
    """Total time in sticking and in sliding states within ``[t_lo, t_hi]`` from the columns
    of an event log (:class:`~pwsdyn.integrate.trajectory.EventLog`): event times ``t``, the
    kind of discrete state after each event ``after`` (0 a mode, 1 sticking, 2 sliding) and
    a mask of ``chatter`` records (which leave the state to the record that follows them);
    ``initial`` is the kind of state before the first event.
    """
    t = np.asarray(t, dtype=float)
    after = np.asarray(after)
    if initial == 0 and not (len(after) and after.max() > 0):
        # never sticking nor sliding (an impact oscillator): nothing to add up
        return 0.0, 0.0
    # the state after each event: that of the last non-chatter record up to it
    last = np.where(np.asarray(chatter, dtype=bool), -1, np.arange(len(t)))
    if len(t):
        last = np.maximum.accumulate(last)
    st_after = np.where(last >= 0, after[np.maximum(last, 0)], initial)
    during = np.concatenate(([initial], st_after))
    d = np.diff(np.concatenate(([t_lo], np.clip(t, t_lo, t_hi), [t_hi])))
    return float(d[during == 1].sum()), float(d[during == 2].sum())


def failed_status(traj) -> Status:
    """The run's status for the result arrays: ``SUCCESS`` when it did not fail (a
    terminal event ends a window as planned)."""
    return traj.status if traj.status.failed else Status.SUCCESS


def check_section(model, section: str) -> None:
    """``section`` is 'stroboscopic' or the name of an event or switch of the flow ``model``."""
    if not isinstance(section, str) or section != "stroboscopic":
        names = {e.name for e in model.events} | {s.name for s in model.switches}
        if not isinstance(section, str) or section not in names:
            raise ArgumentError(f"`section` must be 'stroboscopic' or an event of model "
                             f"{model.name!r} ({sorted(names)}), got {section!r}")


#: Largest number of Dask worker processes accepted.
MAX_WORKERS = 4096


def check_common(*, transient, samples, samples_min, phase, period, max_period, period_tol,
                 bound, chunk_size, workers, progress, store=None, out=None, scheduler=None
                 ) -> tuple:
    """Check the arguments that :func:`pwsdyn.sweep` and :func:`pwsdyn.basins` share; return
    ``(transient, samples, phase, period, max_period, period_tol, bound, chunk_size)``
    normalised (``max_period``, ``chunk_size`` may be None: defaults chosen later)."""
    V.integer("workers", workers, lo=1, hi=MAX_WORKERS, allow_none=True)
    V.flag("progress", progress)
    V.path("store", store)
    V.path("out", out)
    V.text("scheduler", scheduler, allow_none=True)
    return (V.integer("transient", transient, lo=0),
            V.integer("samples", samples, lo=samples_min),
            V.number("phase", phase, lo=-1e6, hi=1e6),
            V.positive("period", period, allow_none=True),
            V.integer("max_period", max_period, lo=1, allow_none=True),
            V.tolerance("period_tol", period_tol),
            V.positive("bound", bound, allow_inf=True),
            V.integer("chunk_size", chunk_size, lo=1, allow_none=True))


def check_time_unit(model, p, period, phase: float, n_periods: int, *, pidx=None,
                    values=(None,), param: str | None = None) -> None:
    """The time unit ``T`` of a window of ``n_periods`` (``period``, else the forcing period
    at each of ``values`` of parameter ``pidx``) is a positive finite number, and the window
    from ``phase * T`` and each period in it are resolvable in double-precision time
    (:func:`pwsdyn._validate.time_window`). Flows only."""
    p = np.array(p, dtype=float)
    fn = None if period is not None else model.forcing_period_function
    for v in values:
        if v is not None:
            v = float(v)
            p[pidx] = v
        if period is not None:
            T = float(period)
        else:
            try:
                T = float(fn(*(float(q) for q in p)))
                got = repr(T)
            except (ArithmeticError, ValueError, TypeError) as exc:
                T, got = math.nan, f"undefined ({exc})"
            if not (math.isfinite(T) and T > 0):
                at = (f" at {param} = {v!r}" if v is not None else "")
                raise ArgumentError(
                    f"the forcing period {model.forcing_period} of model {model.name!r} must be "
                    f"a positive finite number, got {got}{at}"
                    + (": remove that value from `values` (or give `period`)"
                       if v is not None else ": check `params` (or give `period`)"))
        name = "values" if (v is not None and period is None) else "period"
        t_start = phase * T
        V.time_window(name, t_start, max(n_periods, 1) * T,
                      what=f"the window of {n_periods} period(s) of {T!r}"
                      + (f" at {param} = {v!r}" if v is not None else ""))
        V.time_window(name, t_start + (max(n_periods, 1) - 1) * T, T,
                      what=f"one period ({T!r}) at the end of the window"
                      + (f" at {param} = {v!r}" if v is not None else ""))


def check_bound(x: np.ndarray, bound: float) -> bool:
    """True while every component is finite and within ``bound``."""
    # (the largest magnitude is NaN where a component is, inf where one is infinite)
    big = float(np.max(np.abs(x))) if np.size(x) else 0.0
    return math.isfinite(big) and big <= bound


__all__ = ["period_estimate", "readmit", "state_times"]
