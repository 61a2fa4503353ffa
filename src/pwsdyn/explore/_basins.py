"""Basins of attraction on a grid of initial conditions, with attractor classification.

Every start of the grid (the other states and the initial phase fixed) is run for a transient
and then recorded at a section for a window of periods, exactly as one value of a sweep
(:mod:`pwsdyn.explore._sweep`). Its fingerprint is the period ``k`` of the section points, the
last ``k`` section points (one cycle), and the event signature of the cycle (events per
period, time sticking and sliding per period). After all chunks are done the fingerprints are
matched in grid order (row by row) -- so labels do not depend on chunking or workers:

* two periodic starts land on the same attractor when their periods and event signatures are
  equal and their cycles agree, up to a cyclic shift, within ``match_tol * (1 + max |point|)``;
  attractors are numbered 0, 1, ... in order of first appearance;
* all non-periodic starts (no period up to ``max_period`` within ``period_tol``: quasi-periodic,
  chaotic, or not yet settled) share one label, listed in the table with period 0;
* ``-1``: diverged (a state beyond ``bound``, or a non-finite state);
* ``-2``: the run failed (a step or event budget spent, step size underflow, Zeno).

Labels are ints with ``-1`` for divergence as in Attractors.jl; basin fractions
are counts over the grid and sum to 1.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import xarray as xr

from .. import _validate as V
from ..errors import ArgumentError, Status
from .._netcdf import (check_output_path, cf_global_attrs, flag_attrs, quantity_attrs,
                       run_status_codes, state_attrs, state_coords, time_units)
from ..integrate.options import DEFAULTS, check_mode, integrator_options
from ..model.spec import as_model
from ..integrate.compiled import ModelContext
from ._common import (check_common, check_section, check_time_unit, DIVERGED,
                      model_payload, period_estimate)
from ._executor import run_chunks
from ._store import ChunkStore
from ._sweep import _period_function, _settings_json, run_window

if TYPE_CHECKING:
    from distributed import Client

    from .._typing import ModelLike, PathLike, StateLike

LABEL_DIVERGED = -1
LABEL_FAILED = -2


def _chunk_attrs(model) -> dict:
    """Attributes of the variables of a chunk file (fingerprints of the starts of a chunk)."""
    is_map = bool(getattr(model, "is_map", False))
    timed = {"units": time_units(model)} if time_units(model) else {}
    return {
        "status": {"long_name": "status of the run from the start",
                   **flag_attrs(run_status_codes(is_map=is_map, section_missed=True))},
        "period": {"long_name": "period of the section points (0: none found)", "units": "1"},
        "cycle": {"long_name": "the last cycle of section points"},
        "events_per_period": {"long_name": "events per period", "units": "1"},
        "stick_time": {"long_name": "time spent sticking per period", **timed},
        "slide_time": {"long_name": "time spent sliding per period", **timed},
    }


def basins_chunk(task: dict) -> dict:
    """Fingerprints of the starts of one chunk (see module docstring). Plain arrays."""
    ctx = ModelContext.get(task["model"])
    s = task["settings"]
    n = ctx.model.n_states
    starts = np.asarray(task["starts"], dtype=float)
    m = len(starts)
    p = np.array(task["p"], dtype=float)
    fperiod = _period_function(ctx)
    T = s["period"] if s["period"] is not None else (
        float(fperiod(*p)) if fperiod is not None else 1.0)
    mp = s["max_period"]
    out = {"status": np.zeros(m, dtype=np.int64), "period": np.zeros(m, dtype=np.int64),
           "cycle": np.full((m, mp, n), np.nan), "events_per_period": np.full(m, np.nan),
           "stick_time": np.full(m, np.nan), "slide_time": np.full(m, np.nan)}
    for r, x in enumerate(starts):
        w = run_window(ctx, x, p, T, s["phase"], s["transient"], s["samples"], s["section"],
                       s["samples"], task["opts"], s["bound"])
        out["status"][r] = w["status"]
        out["events_per_period"][r] = w["events_per_period"]
        out["stick_time"][r] = w["stick_time"]
        out["slide_time"][r] = w["slide_time"]
        if w["status"] != 0:
            continue
        pts = w["points"][: w["n_points"]]
        k = period_estimate(pts, mp, s["period_tol"])
        out["period"][r] = k
        if k:
            out["cycle"][r, :k] = pts[-k:]
        elif len(pts):  # non-periodic: the last section points show where the motion lies
            out["cycle"][r, :min(mp, len(pts))] = pts[-mp:]
    return out


def _same_cycle(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """``a`` and ``b`` (k, n) agree within ``tol`` up to a cyclic shift."""
    for shift in range(len(a)):
        if np.all(np.abs(np.roll(a, shift, axis=0) - b) <= tol):
            return True
    return False


def classify(fp: dict, match_tol: float) -> tuple[np.ndarray, list[dict]]:
    """Labels (flat, in grid order) and the attractor table from the fingerprints."""
    m = len(fp["status"])
    labels = np.empty(m, dtype=np.int64)
    table: list[dict] = []
    nonper = None
    for i in range(m):
        st = fp["status"][i]
        if st == DIVERGED or st == int(Status.NONFINITE):
            labels[i] = LABEL_DIVERGED
            continue
        if st != 0:
            labels[i] = LABEL_FAILED
            continue
        k = int(fp["period"][i])
        if k == 0:
            if nonper is None:
                nonper = len(table)
                table.append({"period": 0, "kind": "non-periodic",
                              "events_per_period": fp["events_per_period"][i],
                              "stick_time": fp["stick_time"][i],
                              "slide_time": fp["slide_time"][i],
                              "cycle": fp["cycle"][i].copy(), "first": i})
            labels[i] = nonper
            continue
        cyc = fp["cycle"][i, :k]
        tol = match_tol * (1.0 + float(np.max(np.abs(cyc))))
        sig = (round(fp["events_per_period"][i] * k), fp["stick_time"][i] > 0,
               fp["slide_time"][i] > 0)
        for j, att in enumerate(table):
            if att["kind"] != "periodic" or att["period"] != k or att["sig"] != sig:
                continue
            if _same_cycle(att["cycle"], cyc, tol):
                labels[i] = j
                break
        else:
            labels[i] = len(table)
            table.append({"period": k, "kind": "periodic", "sig": sig, "cycle": cyc.copy(),
                          "events_per_period": fp["events_per_period"][i],
                          "stick_time": fp["stick_time"][i], "slide_time": fp["slide_time"][i],
                          "first": i})
    return labels, table


def basins(model: ModelLike, grid: Mapping[str, object], x0: StateLike | None = None, *,
           params: Mapping[str, float] | None = None, transient: int = 200,
           samples: int = 32, section: str = "stroboscopic", phase: float = 0.0,
           period: float | None = None, max_period: int | None = None,
           period_tol: float = 1e-6, match_tol: float = 1e-4, bound: float = 1e8,
           chunk_size: int | None = None, workers: int | None = None,
           client: Client | None = None, scheduler: str | None = None,
           store: PathLike | None = None, out: PathLike | None = None,
           overwrite: bool = False, progress: bool = True,
           **options: Any) -> xr.Dataset:
    """Basins of attraction on a grid of initial conditions.

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
    grid : dict
        One or two entries ``state name -> 1-D array of values`` (the grid axes, in order;
        two for a flow's 2-D grid, one for a 1-D map).
    x0 : sequence or dict, optional
        Values of the states not on the grid (default: the model's ``[defaults] x0``, else 0).
    params : dict, optional
        Parameter values by name, over the model's (``model.parameters``: the
        ``[parameters]`` table with ``[defaults] params`` over it, as on the command line).
    transient, samples : int
        Forcing periods (maps: iterations) discarded, then recorded (defaults 200 and 32).
    section : str
        ``"stroboscopic"`` or the name of an event (see :func:`pwsdyn.sweep`).
    phase : float
        Initial phase (in periods) of every start, and phase of the section.
    period : float, optional
        Time unit of ``transient``/``samples`` (default: the forcing period; required for
        autonomous flows).
    max_period : int, optional
        Longest period looked for (default ``min(samples // 4, 64)``).
    period_tol, match_tol : float
        Tolerances (relative to ``1 + max |point|``) for periodicity and for matching two
        starts' cycles to one attractor.
    bound : float
        Divergence threshold (label -1).
    chunk_size : int, optional
        Grid rows (first axis) per chunk (default ``ceil(rows / 16)``).
    workers, client, scheduler, store, out, overwrite, progress
        As for :func:`pwsdyn.sweep`.
    **options
        Integrator options of :func:`pwsdyn.simulate`.

    Returns
    -------
    xarray.Dataset
        ``label`` over the grid axes (attractor index >= 0, -1 diverged, -2 failed); the
        attractor table over ``attractor``: ``attractor_period`` (0: the non-periodic class),
        ``attractor_kind``, ``attractor_events_per_period``, ``attractor_stick_time``,
        ``attractor_slide_time``, ``attractor_points`` (attractor, cycle_point, state: one
        cycle of section points; for the non-periodic class the last ``max_period`` section
        points of its first start, to show where it lies), ``attractor_start`` (state: the
        first start that reached it); and ``fraction`` over ``basin`` (-2, -1, 0, 1, ...),
        summing to 1.

    Raises
    ------
    ArgumentError
        (a ``ValueError``) Before any work: an empty grid axis, an unknown or repeated state,
        non-finite values, counts that are not ints in range, tolerances outside (0, 1), a
        forcing period that is not a positive finite number, ...

    Examples
    --------
    >>> import numpy as np, pwsdyn
    >>> ds = pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.5, 0.5, 11)},
    ...                    params={"mu": 0.1, "lam": 0.1}, workers=1, progress=False)
    >>> float(ds.fraction.sum())
    1.0
    """
    (transient, samples, phase, period, max_period, period_tol, bound, chunk_size) = check_common(
        transient=transient, samples=samples, samples_min=2, phase=phase, period=period,
        max_period=max_period, period_tol=period_tol, bound=bound, chunk_size=chunk_size,
        workers=workers, progress=progress, store=store, out=out, scheduler=scheduler)
    match_tol = V.tolerance("match_tol", match_tol)
    overwrite = V.flag("overwrite", overwrite)
    model = as_model(model, caller="basins()")
    is_map = bool(getattr(model, "is_map", False))
    if not isinstance(grid, Mapping) or not 1 <= len(grid) <= 2:
        raise ArgumentError("`grid` must be a dict of one or two entries: state name -> values, "
                            f"got {V.describe(grid)}")
    axes = []
    for name, v in grid.items():
        if not isinstance(name, str) or name not in model.states:
            raise ArgumentError(f"`grid` names unknown state {name!r}; states are "
                                f"{list(model.states)}")
        if V.is_real(v) or v is None or isinstance(v, (str, bytes)):
            raise ArgumentError(f"`grid` axis {name!r} must be a sequence of numbers, got "
                                f"{V.describe(v)}")
        arr = V.vector(f"grid[{name!r}]", v, finite=False)
        if arr.size == 0:
            raise ArgumentError(f"`grid` axis {name!r} has zero size: give at least one value")
        if not np.all(np.isfinite(arr)):
            raise ArgumentError(f"`grid` axis {name!r} must be finite")
        axes.append((name, arr))
    if len(axes) == 2 and axes[0][0] == axes[1][0]:
        raise ArgumentError("the two `grid` axes must be different states")
    p = model.parameter_vector(params)
    if is_map:
        if section != "stroboscopic" or options:
            raise ArgumentError(f"model {model.name!r} is a map: `section` and integrator "
                                "options apply to flows only")
    else:
        check_section(model, section)
        if period is None and model.forcing_period is None:
            raise ArgumentError(f"model {model.name!r} is autonomous: give `period`")
        check_mode(model, integrator_options(options, "basins()"))
        check_time_unit(model, p, period, phase, transient + samples)
    if x0 is None:
        x0 = model.defaults.get("x0")
    base = V.state_vector(model, x0) if x0 is not None else np.zeros(model.n_states)
    if max_period is None:
        max_period = max(1, min(samples // 4, 64))
    shape = tuple(len(a) for _, a in axes)
    m = float(np.prod([float(k) for k in shape]))
    n = model.n_states
    V.memory(f"basins() on a grid of {' x '.join(map(str, shape))} starts",
             8.0 * m * (2 * n + max_period * n + 8) + 8.0 * samples * (n + 1))
    opts = {**DEFAULTS, **options, "dense": False, "throw": False, "variational": False}
    rows = shape[0]
    if chunk_size is None:
        chunk_size = max(1, math.ceil(rows / 16))
    out_path = check_output_path(out, overwrite=overwrite) if out is not None else None

    idx = [model.states.index(nm_) for nm_, _ in axes]
    mesh = np.meshgrid(*[a for _, a in axes], indexing="ij")
    starts = np.tile(base, (int(np.prod(shape)), 1))
    for j, mg in zip(idx, mesh):
        starts[:, j] = mg.reshape(-1)
    starts = starts.reshape(shape + (model.n_states,))
    settings = _settings_json(dict(
        grid={nm_: a.tolist() for nm_, a in axes}, x0=base.tolist(),
        params=dict(zip(model.parameters, map(float, p))), transient=int(transient),
        samples=int(samples), section=section, phase=float(phase),
        period=None if period is None else float(period), max_period=int(max_period),
        period_tol=float(period_tol), bound=float(bound), chunk_size=int(chunk_size),
        options={k: v for k, v in opts.items() if k not in ("throw", "dense")}
        if not is_map else {}))
    payload = model_payload(model)
    tasks = []
    for r0 in range(0, rows, chunk_size):
        blk = starts[r0:r0 + chunk_size].reshape(-1, model.n_states)
        tasks.append({"model": payload, "settings": settings, "p": p.tolist(), "opts": opts,
                      "starts": blk.tolist()})

    results: dict[int, dict] = {}
    st = None
    chunk_attrs = _chunk_attrs(model)
    if store is not None:   # takes the store's lock, held until st.close()
        st = ChunkStore(store, "basins", model.name, model.hash, settings, len(tasks),
                        attrs=cf_global_attrs(model, "basins_chunk",
                                              f"chunk of pwsdyn basins of model {model.name}",
                                              "one chunk of a basin computation "
                                              "(pwsdyn.basins); the store's manifest.json "
                                              "describes the run"))
    try:
        if st is not None:
            for i in st.done():
                with_ds = st.read(i)
                results[i] = {k: with_ds[k].values for k in with_ds.data_vars}

        def on_result(i, res):
            results[i] = res
            if st is not None:
                st.write(i, xr.Dataset({k: (("start",) + tuple(f"d{j}"
                                                               for j in range(v.ndim - 1)),
                                            v, chunk_attrs.get(k, {}))
                                        for k, v in res.items()}, attrs={"chunk": i}))

        todo = [i for i in range(len(tasks)) if i not in results]
        run_chunks(basins_chunk, tasks, todo, on_result, workers=workers, client=client,
                   scheduler=scheduler, progress=progress, desc="basins", n_done=len(results))
    finally:
        if st is not None:
            st.close()
    fp = {k: np.concatenate([results[i][k] for i in range(len(tasks))])
          for k in results[0]} if tasks else {}
    labels, table = classify(fp, match_tol)
    ds = _assemble(model, axes, shape, labels, table, fp, starts, settings)
    if out_path is not None:
        from .._netcdf import save_dataset

        save_dataset(ds, out_path, overwrite=overwrite)
    return ds


def _assemble(model, axes, shape, labels, table, fp, starts, settings) -> xr.Dataset:
    n = model.n_states
    K = len(table)
    # a periodic attractor's cycle; the non-periodic class: the section points of its first
    # start (NaN where there were fewer)
    size = [t["period"] or (0 if t["cycle"] is None else len(t["cycle"])) for t in table]
    mp = max(size + [1])
    pts = np.full((K, mp, n), np.nan)
    for j, t in enumerate(table):
        if t["cycle"] is not None:
            pts[j, : size[j]] = t["cycle"][: size[j]]
    flat = starts.reshape(-1, n)
    dims = tuple(nm_ for nm_, _ in axes)
    basin_ids = np.array([LABEL_FAILED, LABEL_DIVERGED] + list(range(K)), dtype=np.int64)
    total = labels.size
    frac = np.array([np.count_nonzero(labels == b) / total for b in basin_ids])
    tunit = time_units(model)
    timed = {"units": tunit} if tunit else {}
    is_map = bool(getattr(model, "is_map", False))
    per = "iteration" if is_map else "forcing period"
    codes = {LABEL_FAILED: "failed", LABEL_DIVERGED: "diverged"}
    codes.update({j: "non_periodic" if t["period"] == 0 else f"attractor_{j}"
                  for j, t in enumerate(table)})
    data = {
        "label": (dims, labels.reshape(shape),
                  {"long_name": "attractor reached from this start (its index in the attractor "
                                "table; -1 diverged, -2 failed)", **flag_attrs(codes)}),
        "attractor_period": (("attractor",), np.array([t["period"] for t in table],
                                                       dtype=np.int64),
                             {"long_name": f"period of the attractor in {per}s (0: the "
                                           "non-periodic class)", "units": "1"}),
        "attractor_kind": (("attractor",), np.array([t["kind"] for t in table], dtype=str),
                           {"long_name": "periodic or non-periodic"}),
        "attractor_events_per_period": (("attractor",),
                                        np.array([t["events_per_period"] for t in table]),
                                        {"long_name": f"events per {per} on the attractor",
                                         "units": "1"}),
        "attractor_stick_time": (("attractor",), np.array([t["stick_time"] for t in table]),
                                 {"long_name": f"time spent sticking per {per}", **timed}),
        "attractor_slide_time": (("attractor",), np.array([t["slide_time"] for t in table]),
                                 {"long_name": f"time spent sliding per {per}", **timed}),
        "attractor_points": (("attractor", "cycle_point", "state"), pts,
                             state_attrs(model, "one cycle of section points of the attractor "
                                                "(NaN beyond its period)")),
        "attractor_start": (("attractor", "state"),
                            flat[[t["first"] for t in table]].reshape(K, n),
                            state_attrs(model, "first start of the grid that reached the "
                                               "attractor")),
        "fraction": (("basin",), frac, {"long_name": "fraction of the grid in the basin",
                                        "units": "1"}),
    }
    coords = {nm_: (nm_, a, quantity_attrs(model, nm_, f"initial {nm_}")) for nm_, a in axes}
    coords.update(
        attractor=("attractor", np.arange(K), {"long_name": "index of the attractor"}),
        basin=("basin", basin_ids, {"long_name": "basin label (-2 failed, -1 diverged, >= 0 "
                                                 "attractor index)"}),
        cycle_point=("cycle_point", np.arange(mp), {"long_name": "index of the cycle point"}),
        **state_coords(model))
    what = "map" if is_map else "flow"
    attrs = {**cf_global_attrs(model, "basins",
                               f"pwsdyn basins of attraction of model {model.name}",
                               f"attractors reached from a grid of initial conditions of a "
                               f"{what} (pwsdyn.basins)"),
             "kind": "basins", "settings": json.dumps(settings, sort_keys=True)}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def basin_fractions(ds: xr.Dataset) -> dict:
    """``{label: fraction}`` of a :func:`~pwsdyn.basins` result (labels with zero fraction
    left out)."""
    return {int(b): float(f) for b, f in zip(ds.basin.values, ds.fraction.values) if f > 0}
