"""Two-parameter scans: period maps over a grid of two parameters.

A scan over ``(p1, p2)`` is a set of rows, one per value of ``p2``; each row is one
sequential sweep in ``p1`` (thesis, section 2.7: the final state at one value is the initial
state at the next), run as one task from ``x0``, so no row has a chunk border inside it and
the result at every grid point is that of the uninterrupted sequential sweep of its row. The
rows are independent of each other and run in parallel (threads or Dask, the sweep's
executor); each finished row is written to the same resumable store as a sweep's chunks. The
result therefore depends neither on ``workers`` nor on the scheduler nor on a resume.

Each row runs the sweep's own per-chunk machinery (``_sweep.sweep_chunk``: transient, window,
section, period estimate), so a scan and a sweep at the same settings agree value by value.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import xarray as xr

from .. import _validate as V
from .._netcdf import (check_output_path, cf_global_attrs, flag_attrs, inverse_time_units,
                       quantity_attrs, run_status_codes, state_attrs, state_coords, time_units)
from ..errors import ArgumentError
from ..integrate.options import DEFAULTS
from ..model.spec import as_model
from ._common import (check_common, check_run_kind, check_start, check_time_unit,
                      first_values, model_payload, sorted_values, start_vector)
from ._executor import run_chunks
from ._store import ChunkStore
from ._sweep import DIRECTIONS, LYAPUNOV_SAMPLES, SAMPLES, sweep_chunk

if TYPE_CHECKING:
    from distributed import Client

    from .._typing import ModelLike, PathLike, StateLike

#: The per-point variables of a scan (``lyapunov`` only with ``lyapunov=True``).
SCAN_VARS = ("period", "events_per_period", "stick_time", "slide_time", "n_points", "status",
             "steps", "x_final", "lyapunov")


def scan_row(task: dict) -> dict:
    """Run one row of a scan (``p2`` fixed, ``p1`` swept from ``x0`` in the order of
    ``task["values"]``) on a worker or in-process: the sweep's chunk runner with one chunk
    and no warm-up. Returns plain arrays of the row's values in increasing order of ``p1``
    (``SCAN_VARS``; ``lyapunov``: the largest exponent)."""
    res = sweep_chunk(task)
    out = {k: res[k] for k in SCAN_VARS if k != "lyapunov"}
    out["lyapunov"] = np.asarray(res["lyapunov"], dtype=float)[:, 0]
    if task["direction"] == "down":
        out = {k: v[::-1].copy() for k, v in out.items()}
    return out


def scan(model: ModelLike, grid: Mapping[str, Any], x0: StateLike | None = None, *,
         transient: int = 200, samples: int | None = None, section: str = "stroboscopic",
         direction: str = "both", params: Mapping[str, float] | None = None, phase: float = 0.0,
         period: float | None = None, max_period: int | None = None,
         period_tol: float = 1e-6, bound: float = 1e8, lyapunov: bool = False,
         workers: int | None = None, client: Client | None = None,
         scheduler: str | None = None, store: PathLike | None = None,
         out: PathLike | None = None, overwrite: bool = False, progress: bool = True,
         **options: Any) -> xr.Dataset:
    """Two-parameter scan: the period map of a model over a grid of two parameters.

    Each row of the grid (``p2`` fixed) is a sequential sweep of :func:`pwsdyn.sweep` in
    ``p1`` from ``x0``: at every value the run continues from the final state at the
    previous one, runs ``transient`` periods and records ``samples`` periods at the section.
    A row runs as one task (no chunk border within it); rows run in parallel, and the result
    does not depend on ``workers``, the scheduler or a resume. The arguments mean what they
    mean for :func:`pwsdyn.sweep` and have its defaults. Where attractors coexist the borders
    of the period regions differ between the sweeps up and down in ``p1`` (hysteresis): the
    up scan shows where the attractor followed upwards ends (a fold, a period doubling), the
    down scan where the one followed downwards does (e.g. a non-impacting orbit at its
    grazing).

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
        A flow or a piecewise-smooth map (anything :func:`pwsdyn.load_model` accepts).
    grid : dict
        ``{p1: values1, p2: values2}``: the two parameters and their values (each distinct
        and finite; sorted here). ``p1`` is swept within a row, ``p2`` is fixed per row.
    x0 : sequence or dict, optional
        Initial state at the first value of every row (default: the model's
        ``[defaults] x0``).
    transient, samples, section, params, phase, period, max_period, period_tol, bound
        As for :func:`pwsdyn.sweep` (``samples``: default 100, or 300 with ``lyapunov``).
    direction : {'up', 'down', 'both'}
        Rows swept in increasing ``p1``, decreasing ``p1``, or both (default, as
        :func:`pwsdyn.sweep`: the two period maps, which differ where attractors coexist;
        ``"up"`` alone costs half).
    lyapunov : bool
        Also compute the largest Lyapunov exponent at each point (slower for flows).
    workers, client, scheduler
        Where the rows run, as for :func:`pwsdyn.sweep` (one row is one task).
    store : str or Path, optional
        Directory where each finished row is written; an existing store of the same model
        and settings is resumed (finished rows are not recomputed), one of another model or
        other settings is refused.
    out : str or Path, optional
        Write the dataset to this NetCDF file (atomically; checked before any work).
    overwrite : bool
        Replace an existing ``out`` (default: refused before any work).
    progress : bool
        Show a progress bar (rows, ETA).
    **options
        Integrator options of :func:`pwsdyn.simulate`.

    Returns
    -------
    xarray.Dataset
        Dimensions ``direction``, ``p1``, ``p2`` (named by the parameters) and ``state``.
        Variables, each over ``(direction, p1, p2)`` as in :func:`pwsdyn.sweep`: ``period`` (0: none found),
        ``events_per_period``, ``stick_time``, ``slide_time``, ``n_points`` (section points
        recorded), ``status`` (0 success; see :func:`pwsdyn.io.decode_status`), ``steps``,
        ``x_final`` (direction, p1, p2, state): the state handed on to the next ``p1``, and with
        ``lyapunov=True`` ``lyapunov``: the largest exponent. Attributes: ``kind`` =
        ``"scan"``, ``parameter`` and ``parameter2`` (the two names), the settings and the
        provenance.

    Raises
    ------
    ArgumentError
        (a ``ValueError``) Before any work: ``grid`` not two parameters of the model with
        values as for :func:`pwsdyn.sweep`, any other argument :func:`pwsdyn.sweep` refuses.
    StoreMismatchError
        ``store`` holds results of another model or other settings.
    OutputExistsError
        (a ``FileExistsError``) ``out`` exists and ``overwrite`` is false.

    Examples
    --------
    >>> import numpy as np, pwsdyn
    >>> ds = pwsdyn.scan("sqrt-map", {"mu": np.linspace(0.01, 0.05, 3),
    ...                               "lam": [0.5, 0.8]}, [0.0], workers=1, progress=False)
    >>> dict(ds.sizes)
    {'direction': 2, 'mu': 3, 'lam': 2, 'state': 1}
    """
    if samples is None:
        samples = LYAPUNOV_SAMPLES if V.flag("lyapunov", lyapunov) else SAMPLES
    (transient, samples, phase, period, max_period, period_tol, bound, _) = check_common(
        transient=transient, samples=samples, samples_min=1, phase=phase, period=period,
        max_period=max_period, period_tol=period_tol, bound=bound, chunk_size=None,
        workers=workers, progress=progress, store=store, out=out, scheduler=scheduler)
    direction = V.choice("direction", direction, DIRECTIONS)
    lyapunov = V.flag("lyapunov", lyapunov)
    overwrite = V.flag("overwrite", overwrite)
    model = as_model(model, caller="scan()")
    is_map = bool(getattr(model, "is_map", False))
    if not isinstance(grid, Mapping) or len(grid) != 2:
        raise ArgumentError("`grid` must be a dict of two parameters and their values, "
                            f"{{p1: values1, p2: values2}}, got {V.describe(grid)}")
    (p1, values1), (p2, values2) = grid.items()
    for name in (p1, p2):
        if not isinstance(name, str) or name not in model.parameters:
            raise ArgumentError(f"unknown parameter {V.describe(name)} for model "
                                f"{model.name!r}; the keys of `grid` must be two of "
                                f"{list(model.parameters)}")
    vals1 = sorted_values(f"the values of {p1!r}", values1)
    vals2 = sorted_values(f"the values of {p2!r}", values2)
    base = V.mapping("params", params)
    for name in (p1, p2):
        if name in base:
            raise ArgumentError(f"`params` must not set the scanned parameter {name!r}")
    p = model.parameter_vector(base)
    names = list(model.parameters)
    i1, i2 = names.index(p1), names.index(p2)
    check_run_kind(model, section, period, options, "scan()")
    x0v = start_vector(model, x0)
    if not is_map:
        q = p.copy()
        for v2 in vals2:
            q[i2] = v2
            check_time_unit(model, q, period, phase, transient + samples, pidx=i1,
                            values=vals1, param=p1)
            # every row starts from x0 at its first value of p1 (both ends with "both")
            check_start(model, x0v, q, i1, first_values(vals1, direction), phase, period)
    if max_period is None:
        max_period = max(1, min(samples // 4, 64))
    n = model.n_states
    # a row holds its section points while it runs (samples x states per value)
    dirs = ["up", "down"] if direction == "both" else [direction]
    V.memory(f"scan() of {len(vals1)} x {len(vals2)} values",
             8.0 * len(dirs) * len(vals1) * len(vals2) * (n + 8)
             + 8.0 * len(vals1) * samples * (n + 1))
    opts = {**DEFAULTS, **options, "dense": False, "throw": False}
    opts["variational"] = False
    out_path = check_output_path(out, overwrite=overwrite) if out is not None else None

    settings = dict(param=p1, values=[float(v) for v in vals1], param2=p2,
                    values2=[float(v) for v in vals2], x0=[float(v) for v in x0v],
                    transient=int(transient), samples=int(samples), section=section,
                    direction=direction, params={k: float(v) for k, v in zip(names, p) if k not in (p1, p2)},
                    phase=float(phase), period=None if period is None else float(period),
                    max_points=int(samples), max_period=int(max_period),
                    period_tol=float(period_tol), bound=float(bound), lyapunov=bool(lyapunov),
                    options={k: v for k, v in opts.items() if k not in ("throw", "dense")}
                    if not is_map else {})
    settings = json.loads(json.dumps(settings, sort_keys=True, default=float))

    payload = model_payload(model)
    tasks = []      # row j of direction d is task d * len(vals2) + j
    for d in dirs:
        order = settings["values"] if d == "up" else settings["values"][::-1]
        for v2 in vals2:
            q = p.copy()
            q[i2] = v2
            tasks.append({"model": payload, "settings": settings, "p": q.tolist(),
                          "pidx": i1, "opts": opts, "values": order, "warmup": 0,
                          "direction": d})

    va = _variable_attrs(model)
    results: dict[int, dict] = {}
    st = None
    if store is not None:   # takes the store's lock, held until st.close()
        st = ChunkStore(store, "scan", model.name, model.hash, settings, len(tasks),
                        attrs=cf_global_attrs(model, "scan_row",
                                              f"row of a pwsdyn scan of model {model.name}",
                                              "one row of a two-parameter scan (pwsdyn.scan); "
                                              "the store's manifest.json describes the run"))
    try:
        if st is not None:
            for i in st.done():
                back = st.read(i)
                results[i] = {k: back[k].values for k in SCAN_VARS}

        def on_result(i, res):
            results[i] = res
            if st is not None:
                st.write(i, xr.Dataset(
                    {k: (("value", "state") if k == "x_final" else ("value",), res[k],
                         va.get(k, {})) for k in SCAN_VARS}, attrs={"row": i}))

        todo = [i for i in range(len(tasks)) if i not in results]
        run_chunks(scan_row, tasks, todo, on_result, workers=workers, client=client,
                   scheduler=scheduler, progress=progress, desc="scan", n_done=len(results))
    finally:
        if st is not None:
            st.close()
    ds = _assemble(model, dirs, p1, vals1, p2, vals2, results, settings, lyapunov, va)
    if out_path is not None:
        from .._netcdf import save_dataset

        save_dataset(ds, out_path, overwrite=overwrite)
    return ds


def _variable_attrs(model) -> dict:
    """CF attributes of the variables of a scan dataset and of its row files."""
    is_map = bool(getattr(model, "is_map", False))
    tunit = time_units(model)
    per = "iteration" if is_map else "period"
    lu = inverse_time_units(model)
    timed = {"units": tunit} if tunit else {}
    return {
        "period": {"long_name": "period estimate in forcing periods (event sections: events; "
                                "maps: iterations); 0: none found", "units": "1"},
        "events_per_period": {"long_name": "border crossings per iteration" if is_map else
                              "impacts, transitions, crossings and chattering sequences per "
                              "forcing period", "units": "1"},
        "stick_time": {"long_name": f"time spent sticking per {per}", **timed},
        "slide_time": {"long_name": f"time spent sliding per {per}", **timed},
        "n_points": {"long_name": "number of section points recorded", "units": "1"},
        "status": {"long_name": "status of the run at this point",
                   **flag_attrs(run_status_codes(is_map=is_map, section_missed=True))},
        "steps": {"long_name": "integrator steps", "units": "1"},
        "x_final": state_attrs(model, "state handed on to the next value of the row"),
        "lyapunov": {"long_name": "largest Lyapunov exponent" + (
                         " (per iteration)" if is_map else " (per unit time)"),
                     **({"units": lu} if lu else {})},
    }


def _assemble(model, dirs, p1, vals1, p2, vals2, results, settings, lyapunov,
              va) -> xr.Dataset:
    n2 = len(vals2)
    data = {}
    for k in SCAN_VARS:
        if k == "lyapunov" and not lyapunov:
            continue
        arr = np.stack([np.stack([np.asarray(results[d * n2 + j][k]) for j in range(n2)],
                                 axis=1) for d in range(len(dirs))])  # (dir, p1, p2[, state])
        dims = ("direction", p1, p2) + (("state",) if k == "x_final" else ())
        data[k] = (dims, arr, va[k])
    coords = {"direction": ("direction", list(dirs),
                            {"long_name": f"direction of the sweep in {p1} along each row "
                                          "(up: increasing values)"}),
              p1: (p1, vals1, {**quantity_attrs(model, p1),
                               "comment": "the parameter swept within a row"}),
              p2: (p2, vals2, {**quantity_attrs(model, p2),
                               "comment": "the parameter fixed per row"}),
              **state_coords(model)}
    what = "map" if getattr(model, "is_map", False) else "flow"
    attrs = {**cf_global_attrs(model, "scan",
                               f"pwsdyn period map of model {model.name} in {p1} and {p2}",
                               f"two-parameter scan of a {what}, rows swept in {p1} with "
                               f"continuation (pwsdyn.scan)"),
             "kind": "scan", "parameter": p1, "parameter2": p2,
             "section": settings["section"],
             "settings": json.dumps(settings, sort_keys=True)}
    return xr.Dataset(data, coords=coords, attrs=attrs)
