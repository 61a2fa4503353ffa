"""Brute-force bifurcation diagrams: parameter sweeps with continuation of the final state.

For each parameter value the model is run for a transient, then for a window of ``samples``
forcing periods (or iterations of a map) in which the state is recorded at a section; the
state at the end of the window is the initial state at the next parameter value, as users of
these diagrams do (thesis, section 2.7: the final state of one value continues into the next).
Sweeping up and down shows hysteresis where attractors coexist.

Chunks and warm-up
------------------
The ordered values are split into chunks of ``chunk_size`` consecutive values that run
independently (on Dask workers). Chunk ``c`` starts ``warmup`` values before its first value:
from the user's ``x0`` it runs the transient at each of those warm-up values (results
discarded), then continues through its own values. The first chunk starts at ``x0`` with no
warm-up. The chunking depends only on the values and ``chunk_size`` (never on the number of
workers), so serial and parallel runs give identical datasets.

Where attractors coexist, a chunk border can show: the warm-up starts from ``x0`` and may
settle on another attractor than the one the previous chunk was following, so a hysteresis
branch followed across the border by a single uninterrupted sweep can switch to the other
attractor exactly at a border. Example (tests/test_explore.py): the ball on a table vibrating
at 0.98 <= Gamma <= 1.05 has a period-1 orbit, continued from Gamma = 0.9, and a period-3 one,
reached by a ball dropped from 1.5 m; a single chunk follows period 1 throughout, chunks of
four values switch to period 3 at some chunk starts. Use ``chunk_size=len(values)`` (one
chunk, no parallelism within a direction) for an uninterrupted continuation, or a longer
``warmup``; the chunk starts are stored in the dataset (``chunk_start``) so borders can be
marked on plots.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import xarray as xr

from .. import _validate as V
from ..errors import ArgumentError
from .._netcdf import (check_output_path, cf_global_attrs, flag_attrs, inverse_time_units,
                       quantity_attrs, run_status_codes, state_attrs, state_coords, time_units)
from ..errors import Status
from ..integrate.options import DEFAULTS, check_mode, integrator_options
from ..model.spec import as_model
from ..integrate.compiled import ModelContext
from ..integrate.trajectory import DiscreteState, EventLog
from ._common import (check_common, check_section, check_time_unit, COUNTED_KINDS, DIVERGED,
                      SECTION_MISSED, check_bound, failed_status, model_payload,
                      period_estimate, readmit, state_times)
from ._executor import run_chunks
from ._lyapunov import flow_segments
from ._store import ChunkStore

if TYPE_CHECKING:
    from distributed import Client
    from numpy.typing import ArrayLike

    from .._typing import ModelLike, PathLike, StateLike

DIRECTIONS = ("up", "down", "both")
#: Default recording window of :func:`sweep`, in forcing periods (maps: iterations).
SAMPLES = 100
#: Default window with ``lyapunov=True``: finite-time exponents over 100 periods scatter by
#: about 0.02-0.05 between neighbouring parameter values in a chaotic band of the impact
#: oscillator (largest exponent 0.05-0.3 there); over 300 periods by 0.006-0.025, within
#: 0.02 of a 3000-period reference, at 2.4 times the cost (0.23 s per value, one core).
LYAPUNOV_SAMPLES = 300
#: Log records that count as a crossing of an event section (not chattering, sticking or
#: release, which are changes of the discrete state at the same surface).
SECTION_KINDS = ("impact", "transition", "crossing", "slide_start", "slide_end")


# ======================================================================================
# one parameter value
# ======================================================================================

def _period_function(ctx: ModelContext):
    """A fast numeric forcing period ``T(p)`` (or ``None`` for an autonomous model): the
    model's own (:attr:`Model.forcing_period_function <pwsdyn.model.Model.
    forcing_period_function>`)."""
    if ctx.model.forcing_period is None:
        return None
    return ctx.model.forcing_period_function


def _event_columns(events, n: int):
    """Times, kinds, names, states before and kinds of discrete state after (0 mode,
    1 sticking, 2 sliding) of an event log or a list of event records, as arrays."""
    if isinstance(events, EventLog):
        return (events.t, events.kind, events.name, events.x_before,
                events.state_after[:, 0])
    after = [DiscreteState.parse(e.mode_after).code for e in events]
    return (np.array([e.t for e in events], dtype=float),
            np.array([e.kind for e in events], dtype=object),
            np.array([e.name for e in events], dtype=object),
            np.array([e.x_before for e in events], dtype=float).reshape(len(events), n),
            np.array(after, dtype=int))


def run_window(ctx: ModelContext, x, p, T: float, phase: float, n_tr: int, n_s: int,
               section: str, max_points: int, opts: dict, bound: float,
               lyapunov: bool = False, record: bool = True) -> dict:
    """Transient of ``n_tr`` periods then a window of ``n_s`` periods, from ``x`` at
    ``t = phase * T``. Returns the section points and per-window statistics (see
    :func:`sweep` for their meaning). ``record=False`` runs only the transient (warm-up)."""
    n = ctx.model.n_states
    out = {"x_end": np.array(x, dtype=float), "status": 0}
    if ctx.is_map:
        return _map_window(ctx, x, p, n_tr, n_s, max_points, bound, lyapunov, record)
    t_start = phase * T
    t_w = t_start + n_tr * T
    x = readmit(ctx, t_start, x, p)
    if not record:
        if n_tr:
            tr = ctx.run(np.asarray(x, float), None, t_start, t_w, opts, p=p)
            out["status"] = failed_status(tr)
            out["x_end"] = tr.x.copy()
        return out
    t_end = t_w + n_s * T
    strobe = section == "stroboscopic"
    pts = np.full((max_points, n), np.nan)
    phs = np.full(max_points, np.nan)
    lyap = np.full(n, np.nan)
    if lyapunov:
        # per-period segments with the variational equations; the section points are the
        # segment start states (stroboscopic times)
        status = 0
        xx = np.asarray(x, float)
        if n_tr:
            tr = ctx.run(xx, None, t_start, t_w, opts, p=p)
            status = failed_status(tr)
            xx = tr.x.copy()
        events = []
        if not status:
            # exponents of the free motion: sticking episodes are resets (LyapunovSpectrum)
            fs = flow_segments(ctx, xx, t_w, T, n_s, p, opts, bound, keep_events=True)
            status, done, starts, events = fs.status, fs.done, fs.starts, fs.events
            if done:
                lyap = np.sort(fs.exponents)[::-1]
            xx = fs.x
            if strobe:
                m = min(max_points, done)
                pts[:m] = starts[:m]
        x_end = xx
        nsteps = 0
    else:
        events = []
        nsteps = 0
        xx = np.asarray(x, float)
        if strobe:
            # Transient and window in one kernel call that records the state at
            # t_w + k T (k = 0 .. n_s) on the dense output (no event, no landing step, so the
            # section costs a few percent; the state sticking or sliding at t_w just goes on).
            res = ctx.run(xx, None, t_start, t_end, opts, sample=(t_w, T), p=p)
            status = failed_status(res)
            nsteps = res.stats.get("steps", 0)
            events = res.events
            ts, xs = res.samples_t, res.samples_x
            j = np.rint((ts - t_w) / T).astype(int)
            keep = (j >= 0) & (j < min(max_points, n_s))
            pts[j[keep]] = xs[keep]
            x_end = res.x.copy()
            if not status and not (len(j) and j[-1] == n_s):
                status = SECTION_MISSED
        else:
            res = ctx.run(xx, None, t_start, t_end, opts, p=p)
            status = failed_status(res)
            x_end = res.x.copy()
            nsteps = res.stats.get("steps", 0)
            events = res.events
    t, kind, name, xb, after = _event_columns(events, n)
    in_window = (t >= t_w) & (t < t_end)
    if not strobe:
        hits = np.flatnonzero(in_window & (name == section) & np.isin(kind, SECTION_KINDS))
        m = min(len(hits), max_points)
        pts[:m] = xb[hits[:m]]
        phs[:m] = ((t[hits[:m]] - t_start) / T) % 1.0
    counted = int(np.sum(in_window & np.isin(kind, COUNTED_KINDS)))
    chatter = kind == "chatter"
    before = np.flatnonzero((t < t_w) & ~chatter)
    initial = int(after[before[-1]]) if len(before) else 0
    upto = t < t_end
    stick, slide = state_times(t[upto], after[upto], chatter[upto], t_w, t_end, initial)
    if status == 0 and not check_bound(x_end, bound):
        status = DIVERGED
    npts = int(np.sum(np.all(np.isfinite(pts), axis=1)))
    out.update(points=pts, phase=phs, n_points=npts, status=status, x_end=x_end,
               events_per_period=counted / n_s, stick_time=stick / n_s, slide_time=slide / n_s,
               lyapunov=lyap, steps=nsteps)
    return out


def _map_window(ctx, x, p, n_tr, n_s, max_points, bound, lyapunov, record):
    from ..model.maps import lyapunov_kernel, orbit_kernel

    n = ctx.model.n_states
    pv = p if p.size else np.zeros(1)
    x = np.asarray(x, dtype=float)
    if not record:
        st, _, _, xe, _ = orbit_kernel(ctx.cm.step, x, pv, int(n_tr), 0, float(bound))
        # the loops return Status values: no piece applies is not MAX_STEPS
        return {"x_end": xe, "status": Status(int(st))}
    st, xs, pieces, xe, _ = orbit_kernel(ctx.cm.step, x, pv, int(n_tr), int(n_s), float(bound))
    status = Status(int(st))
    pts = np.full((max_points, n), np.nan)
    m = min(max_points, n_s)
    pts[:m] = xs[:m]
    good = pieces >= 0
    crossings = int(np.sum(pieces[1:][good[1:] & good[:-1]] != pieces[:-1][good[1:] & good[:-1]]))
    lyap = np.full(n, np.nan)
    if lyapunov and status == 0:
        _, ex, _, _ = lyapunov_kernel(ctx.cm.step, x, pv, int(n_tr), int(n_s), float(bound))
        lyap = np.sort(ex)[::-1]
    return {"points": pts, "phase": np.full(max_points, np.nan),
            "n_points": int(np.sum(np.all(np.isfinite(pts), axis=1))), "status": status,
            "x_end": xe, "events_per_period": crossings / n_s, "stick_time": 0.0,
            "slide_time": 0.0, "lyapunov": lyap, "steps": 0}


# ======================================================================================
# chunks
# ======================================================================================

def sweep_chunk(task: dict) -> dict:
    """Run one chunk of a sweep (on a worker or in-process). Returns plain arrays."""
    ctx = ModelContext.get(task["model"])
    model = ctx.model
    s = task["settings"]
    n = model.n_states
    p = np.array(task["p"], dtype=float)
    pidx = task["pidx"]
    x0 = np.array(s["x0"], dtype=float)
    x = x0.copy()
    values = task["values"]
    nw = task["warmup"]
    nv = len(values) - nw
    maxp = s["max_points"]
    opts = task["opts"]
    fperiod = _period_function(ctx)
    res = {k: np.full(shp, np.nan) for k, shp in (
        ("section", (nv, maxp, n)), ("phase", (nv, maxp)), ("x_final", (nv, n)),
        ("lyapunov", (nv, n)), ("events_per_period", nv), ("stick_time", nv),
        ("slide_time", nv))}
    for k in ("n_points", "period", "status", "steps"):
        res[k] = np.zeros(nv, dtype=np.int64)
    for i, val in enumerate(values):
        p[pidx] = val
        T = s["period"] if s["period"] is not None else (
            float(fperiod(*p)) if fperiod is not None else 1.0)
        rec = i >= nw
        w = run_window(ctx, x, p, T, s["phase"], s["transient"], s["samples"], s["section"],
                       maxp, opts, s["bound"], s["lyapunov"], record=rec)
        if rec:
            r = i - nw
            res["section"][r] = w["points"]
            res["phase"][r] = w["phase"]
            res["x_final"][r] = w["x_end"]
            res["lyapunov"][r] = w["lyapunov"]
            for k in ("events_per_period", "stick_time", "slide_time", "n_points", "status",
                      "steps"):
                res[k][r] = w[k]
            if w["status"] == 0:
                pts = w["points"]
                # the phase of event-section points counts for a forced model (autonomous
                # flows have no phase: ``period`` is then only a unit of time)
                if (s["section"] != "stroboscopic" and not ctx.is_map
                        and model.forcing_period is not None):
                    ang = 2 * np.pi * w["phase"]
                    pts = np.column_stack([pts, np.cos(ang), np.sin(ang)])
                res["period"][r] = period_estimate(pts, s["max_period"], s["period_tol"])
        # continue the final state into the next value; restart from x0 after a failure
        ok = w["status"] == 0 and check_bound(w["x_end"], s["bound"])
        x = np.array(w["x_end"], dtype=float) if ok else x0.copy()
    return res


# ======================================================================================
# the public function
# ======================================================================================

def _settings_json(d: dict) -> dict:
    return json.loads(json.dumps(d, sort_keys=True, default=float))


def sweep(model: ModelLike, param: str, values: ArrayLike, x0: StateLike | None = None,
          *, transient: int = 200,
          samples: int | None = None, section: str = "stroboscopic", direction: str = "both",
          params: Mapping[str, float] | None = None, phase: float = 0.0,
          period: float | None = None, max_points: int | None = None,
          max_period: int | None = None, period_tol: float = 1e-6, bound: float = 1e8,
          lyapunov: bool = False, chunk_size: int | None = None, warmup: int = 2,
          workers: int | None = None, client: Client | None = None,
          scheduler: str | None = None, store: PathLike | None = None,
          out: PathLike | None = None, overwrite: bool = False, progress: bool = True,
          **options: Any) -> xr.Dataset:
    """Brute-force bifurcation diagram: sweep one parameter, continuing the final state.

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
        A flow or a piecewise-smooth map (anything :func:`pwsdyn.load_model` accepts).
    param : str
        The parameter swept.
    values : sequence of float
        Its values (distinct, finite; sorted here). ``direction="up"`` visits them in
        increasing order, ``"down"`` in decreasing order, ``"both"`` does both sweeps.
    x0 : sequence or dict, optional
        Initial state at the first value (default: the model's ``[defaults] x0``).
    transient : int
        Forcing periods (maps: iterations) run and discarded at each value (default 200).
    samples : int, optional
        Forcing periods (maps: iterations) of the recording window: default 100, or 300 with
        ``lyapunov=True`` (fewer make the exponents scatter between neighbouring values).
    section : str
        ``"stroboscopic"`` (default): the state at ``t = (k + phase) T`` for each period of
        the window. Or the name of an event or switch (e.g. ``"impact"``): the state just
        before each such event in the window (impacts, transitions, crossings, sliding starts
        and ends), with its phase ``(t / T) mod 1``. Maps record every iterate.
    direction : {'up', 'down', 'both'}
        Default ``"both"``: the up and the down sweep, which show hysteresis where
        attractors coexist (``pwsdyn sweep`` does the same).
    params : dict, optional
        Values of the other parameters (default: the model's, ``model.parameters``: the
        ``[parameters]`` table with ``[defaults] params`` over it, as on the command line).
    phase : float
        Phase of the stroboscopic section and of the start of each value, in periods.
    period : float, optional
        Time unit of ``transient`` and ``samples``: default the forcing period at each value
        (``model.forcing_period_value``); required for autonomous flows.
    max_points : int, optional
        Section points stored per value (default ``samples``; event sections keep the first
        ``max_points`` events of the window).
    max_period : int, optional
        Largest period looked for by the period estimate (default ``min(samples // 4, 64)``).
    period_tol : float
        Section points ``j`` and ``j + k`` count as equal within
        ``period_tol * (1 + max |point|)`` (default 1e-6).
    bound : float
        A state component beyond ``bound`` counts as divergence (``Status.DIVERGED``); the
        next value then starts again from ``x0``.
    lyapunov : bool
        Also compute the Lyapunov spectrum over the window (flows: variational equations with
        saltation matrices, one QR per period; maps: per iteration). Slower for flows.
    chunk_size : int, optional
        Values per chunk (default ``ceil(len(values) / 16)``, independent of the workers).
    warmup : int
        Values before a chunk's first value at which the chunk runs the transient first
        (default 2). See the module docstring for how chunk borders can show.
    workers : int, optional
        Threads running the chunks in this process (default: one per core; the compiled
        kernel releases the GIL, so they run in parallel and a script needs no ``__main__``
        guard); ``1``: one after the other. With ``scheduler="processes"``: the number of
        worker processes.
    client : dask.distributed.Client, optional
        Run on this Dask client's cluster.
    scheduler : str, optional
        ``"threads"`` (the default), ``"synchronous"``, ``"processes"`` (a local Dask
        cluster of ``workers`` processes; a script then needs ``if __name__ ==
        "__main__":``) or the address of a Dask scheduler to connect to.
    store : str or Path, optional
        Directory where each finished chunk is written as it completes. An existing store
        of the same model and settings is resumed (finished chunks are not recomputed); one
        of another model or settings is refused.
    out : str or Path, optional
        Write the dataset to this NetCDF file. Its directory must exist and be writable
        (checked before any work).
    overwrite : bool
        ``False`` (default): an existing ``out`` is refused before any work
        (:class:`~pwsdyn.OutputExistsError`); ``True``: it is replaced.
    progress : bool
        Show a progress bar (chunks, ETA).
    **options
        Integrator options of :func:`pwsdyn.simulate` (``rtol``, ``atol``, ``method``,
        ``max_steps`` (per value), ...).

    Returns
    -------
    xarray.Dataset
        Dimensions ``direction``, the parameter (named ``param``), ``sample``, ``state`` (and
        ``exponent`` with ``lyapunov``). Variables:

        - ``section`` (direction, param, sample, state): section points (NaN where none);
        - ``phase`` (direction, param, sample): phase of event-section points;
        - ``n_points``: section points recorded; ``period``: smallest ``k <= max_period``
          with repeating section points (in periods, events for event sections, iterations
          for maps; 0: none found);
        - ``events_per_period``: impacts, transitions, crossings and chattering sequences per
          period (maps: border crossings per iteration);
        - ``stick_time``, ``slide_time``: time per period spent sticking / sliding;
        - ``status``: the value of a :class:`pwsdyn.Status` member (its flags name them;
          :func:`pwsdyn.io.decode_status` gives the members): 0 success, the status of a
          failed run (maps: ``NO_PIECE_APPLIES``, ``NONFINITE``), ``DIVERGED`` (-1) or
          ``SECTION_MISSED`` (-3: the section at the end of the window was not logged; not
          expected to occur);
        - ``x_final``: the state handed on to the next value; ``steps``: integrator steps;
        - ``lyapunov`` (direction, param, exponent), with ``lyapunov=True`` (flows with
          sticking: exponents of the free motion, see :class:`pwsdyn.explore.LyapunovSpectrum`);
        - ``chunk_start`` (direction, param): True at the first value of each chunk.

        Attributes hold the provenance (model name and hash, pwsdyn version, settings).

    Raises
    ------
    ArgumentError
        (a ``ValueError``) Before any work: empty, repeated or non-finite values, an unknown
        parameter, section or direction, counts that are not ints in range, tolerances
        outside (0, 1), a value where the forcing period is not a positive finite number or
        is not resolved in double-precision time over the window (``2*pi/omega`` at
        ``omega = 0``), result arrays beyond ``pwsdyn._validate.MEMORY_LIMIT``.
    StoreMismatchError
        ``store`` holds results of another model or other settings.
    OutputExistsError
        (a ``FileExistsError``) ``out`` exists and ``overwrite`` is false.

    Examples
    --------
    >>> import numpy as np, pwsdyn
    >>> ds = pwsdyn.sweep("sqrt-map", "mu", np.linspace(0.01, 0.05, 5), [0.0],
    ...                   params={"lam": 0.8}, workers=1, progress=False)
    >>> ds.sizes["mu"], int(ds.period.sel(direction="up").min())
    (5, 0)
    """
    if samples is None:
        samples = LYAPUNOV_SAMPLES if V.flag("lyapunov", lyapunov) else SAMPLES
    (transient, samples, phase, period, max_period, period_tol, bound, chunk_size) = check_common(
        transient=transient, samples=samples, samples_min=1, phase=phase, period=period,
        max_period=max_period, period_tol=period_tol, bound=bound, chunk_size=chunk_size,
        workers=workers, progress=progress, store=store, out=out, scheduler=scheduler)
    direction = V.choice("direction", direction, DIRECTIONS)
    warmup = V.integer("warmup", warmup, lo=0)
    lyapunov = V.flag("lyapunov", lyapunov)
    overwrite = V.flag("overwrite", overwrite)
    max_points = V.integer("max_points", max_points, lo=1, allow_none=True)
    model = as_model(model, caller="sweep()")
    is_map = bool(getattr(model, "is_map", False))
    if not isinstance(param, str) or param not in model.parameters:
        raise ArgumentError(f"unknown parameter {V.describe(param)} for model {model.name!r}; "
                            f"`param` must be one of {list(model.parameters)}")
    if V.is_real(values) or isinstance(values, (str, bytes)) or values is None:
        raise ArgumentError(f"`values` of {param!r} must be a non-empty sequence of numbers, "
                            f"got {V.describe(values)}")
    vals = V.vector("values", values, finite=False)
    if vals.size == 0:
        raise ArgumentError(f"`values` of {param!r} must be a non-empty sequence of numbers, got "
                            f"{V.describe(values)}")
    if not np.all(np.isfinite(vals)):
        raise ArgumentError(f"`values` of {param!r} must be finite, got {V.describe(values)}")
    vals = np.sort(vals)
    if np.any(np.diff(vals) == 0):
        raise ArgumentError(f"`values` of {param!r} must be distinct")
    base = V.mapping("params", params)
    if param in base:
        raise ArgumentError(f"`params` must not set the swept parameter {param!r}")
    p = model.parameter_vector(base)
    pidx = list(model.parameters).index(param)
    if is_map:
        if section != "stroboscopic":
            raise ArgumentError(f"model {model.name!r} is a map: every iterate is recorded; "
                                "`section` applies to flows only")
        if options:
            raise ArgumentError(f"integrator options {sorted(options, key=str)} apply to "
                                f"flows, not to map {model.name!r}")
    else:
        check_section(model, section)
        if period is None and model.forcing_period is None:
            raise ArgumentError(f"model {model.name!r} is autonomous: give `period`, the time "
                                "unit of `transient` and `samples`")
        check_mode(model, integrator_options(options, "sweep()"))
        check_time_unit(model, p, period, phase, transient + samples, pidx=pidx,
                        values=vals, param=param)
    if x0 is None:
        x0 = model.defaults.get("x0")
        if x0 is None:
            raise ArgumentError(f"give `x0`: model {model.name!r} has no [defaults] x0")
    x0v = V.state_vector(model, x0)
    max_points = samples if max_points is None else max_points
    if max_period is None:
        max_period = max(1, min(samples // 4, 64))
    nd = 2 if direction == "both" else 1
    n = model.n_states
    V.memory(f"sweep() of {len(vals)} values with max_points={max_points}",
             8.0 * nd * len(vals) * (max_points * (n + 1) + 3 * n + 8))
    opts = {**DEFAULTS, **options, "dense": False, "throw": False}
    opts.pop("variational", None)
    opts["variational"] = False
    if chunk_size is None:
        chunk_size = max(1, math.ceil(len(vals) / 16))
    out_path = check_output_path(out, overwrite=overwrite) if out is not None else None

    settings = dict(param=param, values=[float(v) for v in vals], x0=[float(v) for v in x0v],
                    transient=int(transient), samples=int(samples), section=section,
                    direction=direction, params=dict(zip(model.parameters, map(float, p))),
                    phase=float(phase), period=None if period is None else float(period),
                    max_points=int(max_points), max_period=int(max_period),
                    period_tol=float(period_tol), bound=float(bound), lyapunov=bool(lyapunov),
                    chunk_size=int(chunk_size), warmup=int(warmup),
                    options={k: v for k, v in opts.items() if k not in ("throw", "dense")}
                    if not is_map else {})
    settings = _settings_json(settings)

    dirs = ["up", "down"] if direction == "both" else [direction]
    tasks = []
    payload = model_payload(model)
    nvals = len(vals)
    for d in dirs:
        order = np.arange(nvals) if d == "up" else np.arange(nvals)[::-1]
        for c0 in range(0, nvals, chunk_size):
            idx = order[c0:c0 + chunk_size]
            w0 = max(0, c0 - warmup)
            warm = order[w0:c0]
            tasks.append({"model": payload, "settings": settings, "p": p.tolist(),
                          "pidx": pidx, "opts": opts, "direction": d,
                          "index": idx.tolist(),
                          "values": [float(vals[i]) for i in np.concatenate([warm, idx])],
                          "warmup": len(warm)})

    results: dict[int, dict] = {}
    st = None
    chunk_attrs = _variable_attrs(model, settings)
    if store is not None:   # takes the store's lock, held until st.close()
        st = ChunkStore(store, "sweep", model.name, model.hash, settings, len(tasks),
                        attrs=cf_global_attrs(model, "sweep_chunk",
                                              f"chunk of a pwsdyn sweep of model {model.name}",
                                              "one chunk of a parameter sweep (pwsdyn.sweep); "
                                              "the store's manifest.json describes the run"))
    try:
        if st is not None:
            for i in st.done():
                results[i] = _from_chunk_dataset(st.read(i))

        def on_result(i, res):
            results[i] = res
            if st is not None:
                st.write(i, _chunk_dataset(res, i, chunk_attrs))

        todo = [i for i in range(len(tasks)) if i not in results]
        run_chunks(sweep_chunk, tasks, todo, on_result, workers=workers, client=client,
                   scheduler=scheduler, progress=progress, desc="sweep", n_done=len(results))
    finally:
        if st is not None:
            st.close()
    ds = _assemble(model, vals, tasks, results, dirs, settings, lyapunov)
    if out_path is not None:
        from .._netcdf import save_dataset

        save_dataset(ds, out_path, overwrite=overwrite)
    return ds


_CHUNK_VARS = ("section", "phase", "x_final", "lyapunov", "events_per_period", "stick_time",
               "slide_time", "n_points", "period", "status", "steps")
_CHUNK_DIMS = {"section": ("value", "sample", "state"), "phase": ("value", "sample"),
               "x_final": ("value", "state"), "lyapunov": ("value", "state")}


def _variable_attrs(model, settings: dict) -> dict:
    """CF attributes (``long_name``, ``units``, flags) of the variables of a sweep dataset
    and of its chunk files."""
    is_map = bool(getattr(model, "is_map", False))
    tunit = time_units(model)
    per = "iteration" if is_map else "period"
    lu = inverse_time_units(model)

    def counted(long_name):
        return {"long_name": long_name, "units": "1"}

    def timed(long_name):
        return {"long_name": long_name, **({"units": tunit} if tunit else {})}

    return {
        "section": state_attrs(model, "iterates (NaN where none)" if is_map
                               else "section points (NaN where none)"),
        "phase": {"long_name": "phase of the section point in the forcing period",
                  "units": "1"},
        "n_points": counted("number of section points recorded"),
        "period": counted("period estimate in forcing periods (event sections: events; maps: "
                          "iterations); 0: none found"),
        "events_per_period": counted("border crossings per iteration" if is_map else
                                     "impacts, transitions, crossings and chattering "
                                     "sequences per forcing period"),
        "stick_time": timed(f"time spent sticking per {per}"),
        "slide_time": timed(f"time spent sliding per {per}"),
        "status": {"long_name": "status of the run at this value",
                   **flag_attrs(run_status_codes(is_map=is_map, section_missed=True))},
        "x_final": state_attrs(model, "state handed on to the next value"),
        "steps": counted("integrator steps"),
        "lyapunov": {"long_name": "Lyapunov exponents, decreasing" + (
                         " (per iteration)" if is_map else " (per unit time)"),
                     **({"units": lu} if lu else {})},
        "chunk_start": {"long_name": "first value of a chunk (a continuation restarts there "
                                     "after its warm-up)"},
    }


def _chunk_dataset(res: dict, i: int, var_attrs: dict | None = None) -> xr.Dataset:
    var_attrs = var_attrs or {}
    return xr.Dataset({k: (_CHUNK_DIMS.get(k, ("value",)), res[k], var_attrs.get(k, {}))
                       for k in _CHUNK_VARS}, attrs={"chunk": i})


def _from_chunk_dataset(ds: xr.Dataset) -> dict:
    return {k: ds[k].values for k in _CHUNK_VARS}


def _assemble(model, vals, tasks, results, dirs, settings, lyapunov) -> xr.Dataset:
    n = model.n_states
    nv = len(vals)
    maxp = settings["max_points"]
    nd = len(dirs)
    arr = {k: np.full((nd, nv) + shp, np.nan) for k, shp in (
        ("section", (maxp, n)), ("phase", (maxp,)), ("x_final", (n,)), ("lyapunov", (n,)),
        ("events_per_period", ()), ("stick_time", ()), ("slide_time", ()))}
    for k in ("n_points", "period", "status", "steps"):
        arr[k] = np.zeros((nd, nv), dtype=np.int64)
    chunk_start = np.zeros((nd, nv), dtype=bool)
    for ti, task in enumerate(tasks):
        di = dirs.index(task["direction"])
        idx = np.asarray(task["index"])
        res = results[ti]
        for k in arr:
            arr[k][di, idx] = res[k]
        chunk_start[di, idx[0]] = True
    arr["chunk_start"] = chunk_start
    pname = settings["param"]
    vdim = pname
    is_map = bool(getattr(model, "is_map", False))
    dims = ("direction", vdim)
    va = _variable_attrs(model, settings)
    layout = {"section": ("sample", "state"), "x_final": ("state",), "phase": ("sample",),
              "lyapunov": ("exponent",)}
    names = ["section", "n_points", "period", "events_per_period", "stick_time", "slide_time",
             "status", "x_final", "steps", "chunk_start"]
    if settings["section"] != "stroboscopic":
        names.append("phase")
    if lyapunov:
        names.append("lyapunov")
    data = {k: (dims + layout.get(k, ()), arr[k], va[k]) for k in names}
    coords = {"direction": ("direction", list(dirs),
                            {"long_name": "direction of the sweep (up: increasing values)"}),
              vdim: (vdim, vals, {**quantity_attrs(model, pname),
                                  "comment": "the swept parameter"}),
              "sample": ("sample", np.arange(maxp), {"long_name": "index of the section point"}),
              **state_coords(model)}
    if lyapunov:
        coords["exponent"] = ("exponent", np.arange(n),
                              {"long_name": "index of the Lyapunov exponent"})
    what = "map" if is_map else "flow"
    attrs = {**cf_global_attrs(model, "sweep",
                               f"pwsdyn bifurcation diagram of model {model.name} in {pname}",
                               f"brute-force parameter sweep of a {what} with continuation "
                               f"(pwsdyn.sweep)"),
             "kind": "sweep", "parameter": pname,
             "section": settings["section"],
             "settings": json.dumps(settings, sort_keys=True)}
    return xr.Dataset(data, coords=coords, attrs=attrs)
