"""``pwsdyn sweep`` and ``pwsdyn basins``: the parallel, resumable explorations."""

from __future__ import annotations

import click

from ._common import (_stack, exact_option, method_option, model_argument, output_options,
                      parallel_options, param_options, prepare, progress_option, reported,
                      sliding_option, tolerance_options, x0_option)
from ._main import main
from ._output import _echo, _fail, _fmt, _lyapunov_path, _write_figures


def _run_store(out, store):
    """The store directory: ``--store``, else ``<out>.store`` (removed after success)."""
    from pathlib import Path

    if store is not None:
        return Path(store), False
    if out is not None:
        return Path(str(out) + ".store"), True
    return None, False


#: The options of sweep and basins after their own: the start, the parallel and resumable
#: run, the shared options.
explore_options = _stack(
    x0_option("Initial state (as for `simulate`); default: the model's [defaults]."),
    click.option("--transient", type=int, default=200, show_default=True,
                 help="Forcing periods (maps: iterations) discarded."),
    click.option("--section", default="stroboscopic", show_default=True,
                 help="'stroboscopic' or the name of an event (e.g. impact)."),
    parallel_options,
    click.option("--chunk-size", "chunk_size", type=int, default=None,
                 help="Values (basins: grid rows) per chunk (default: 1/16 of them)."),
    click.option("--store", default=None, type=click.Path(file_okay=False),
                 help="Resumable store directory (default: OUT.store, removed when done)."),
    tolerance_options(),
    method_option(),
    exact_option,
    sliding_option(),
    progress_option,
    output_options("Write the dataset to this NetCDF file (.nc).",
                   "Write the figure to this file (PNG; PDF, SVG... by suffix)."),
)


def _finish_explore(ds, out, store_path, remove_store, figures, force):
    """Write --out (then remove the default store), then the ``figures`` (see
    :func:`_write_figures`); every file or directory left behind is listed."""
    import shutil

    from ..io import save_dataset

    if store_path is not None and not remove_store:
        _echo(f"store       {store_path} (resumable; kept)")
    if out is not None:
        try:
            save_dataset(ds, out, overwrite=force)
        except (OSError, ValueError, TypeError) as exc:
            kept = ""
            if store_path is not None and store_path.is_dir():
                kept = (f"; the results are kept in the store {str(store_path)!r}: the same "
                        f"command resumes from it")
            _fail(f"{exc}{kept}")
        _echo(f"wrote       {out}")
        if remove_store and store_path is not None and store_path.is_dir():
            shutil.rmtree(store_path, ignore_errors=True)
    if figures:
        problem = _write_figures(figures, out, lambda: ds)
        if problem is not None:
            _fail(problem)



@main.command("sweep")
@model_argument
@click.option("--sweep", "swept", default=None, metavar="NAME", help="Parameter swept.")
@param_options("swept")
@click.option("--from", "start", type=float, required=True, help="First value.")
@click.option("--to", "stop", type=float, required=True, help="Last value.")
@click.option("--num", type=int, required=True, help="Number of values (evenly spaced).")
@click.option("--direction", type=click.Choice(["up", "down", "both"]), default="both",
              show_default=True, help="Sweep up, down or both (hysteresis).")
@click.option("--lyapunov", is_flag=True, default=False,
              help="Also compute Lyapunov exponents (slower).")
@click.option("--state", default=None, help="State plotted (default: first, or last for an "
              "event section).")
@click.option("--samples", type=int, default=None,
              help="Forcing periods (maps: iterations) recorded at each value [100, or 300 "
                   "with --lyapunov].")
@explore_options
def sweep_cmd(model, swept, params, sets, start, stop, num, direction, lyapunov, state,
              samples, x0, transient, section, workers, scheduler, chunk_size, store, rtol,
              atol, method, exact, sliding, no_progress, out, plot, force):
    """Brute-force bifurcation diagram of MODEL in the parameter --sweep NAME.

    For each of --num values from --from to --to, run --transient forcing periods, record
    --samples periods at the section and continue the final state into the next value.
    Parameters are set with -p/--param NAME=VALUE as in every command; a --param NAME
    without a value names the swept parameter (the spelling before --sweep, still valid).

    \b
    Examples:
      pwsdyn sweep impact-oscillator --sweep omega --from 2 --to 3.6 --num 400 \\
          --out diagram.nc --plot diagram.png
      pwsdyn sweep sqrt-map --sweep mu --from 0.001 --to 0.05 --num 200 -p lam=0.8 \\
          --lyapunov --plot sqrt.png
    """
    import numpy as np

    import pwsdyn

    if num < 1:
        raise click.BadParameter(f"must be at least 1, got {num}", param_hint="--num")
    lyap_plot = _lyapunov_path(plot) if plot is not None and lyapunov else None
    run = prepare(model, params, sets, x0, force=force, named="swept", swept=swept,
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure"),
                           ("--plot (its Lyapunov figure)", lyap_plot, "figure")],
                  rtol=rtol, atol=atol, method=method, exact=exact, sliding=sliding)
    param, mdl = run.named, run.model
    # a value given for the swept parameter is left out: the sweep sets it
    fixed = {k: v for k, v in run.params.items() if k != param}
    store_path, remove_store = _run_store(out, store)
    values = np.linspace(start, stop, num) if num > 1 else np.array([start])
    with reported():
        # parameters and x0 not given here: the model's defaults, applied by pwsdyn.sweep
        ds = pwsdyn.sweep(mdl, param, values, run.x0, params=fixed, transient=transient,
                          samples=samples, section=section,
                          direction=direction, lyapunov=lyapunov, workers=workers,
                          scheduler=scheduler, chunk_size=chunk_size, store=store_path,
                          out=None, progress=not no_progress, **run.options)
    per = ds.period.values
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"swept       {param} from {_fmt(values[0])} to {_fmt(values[-1])} "
          f"({num} values, {', '.join(map(str, ds.direction.values))})")
    _echo("periods     " + ", ".join(
        f"{k if k else 'none'}: {int(np.sum(per == k))}" for k in np.unique(per)))
    nbad = int(np.sum(ds.status.values != 0))
    if nbad:
        _echo(f"failed      {nbad} value(s) failed or diverged (status != 0)")

    figures = []
    if plot is not None:    # matplotlib is imported only for a figure
        from ..plot import plot_bifurcation, plot_lyapunov

        figures.append((plot, lambda: plot_bifurcation(ds, state=state, path=plot,
                                                       overwrite=force)))
    if lyap_plot is not None:
        figures.append((lyap_plot, lambda: plot_lyapunov(ds, path=lyap_plot, overwrite=force)))
    # the data go to --out here, not in pwsdyn.sweep: --force applies and the figure follows
    _finish_explore(ds, out, store_path, remove_store, figures, force)


@main.command("basins")
@model_argument
@param_options()
@click.option("--x", "xname", required=True, metavar="STATE", help="State on the first axis.")
@click.option("--x-from", "x_from", type=float, required=True,
              help="First value of the --x state on the grid.")
@click.option("--x-to", "x_to", type=float, required=True,
              help="Last value of the --x state on the grid.")
@click.option("--x-num", "x_num", type=int, required=True,
              help="Number of --x values (evenly spaced).")
@click.option("--y", "yname", default=None, metavar="STATE",
              help="State on the second axis (flows: required; 1-D maps: omit).")
@click.option("--y-from", "y_from", type=float, default=None,
              help="First value of the --y state on the grid (required with --y).")
@click.option("--y-to", "y_to", type=float, default=None,
              help="Last value of the --y state on the grid (required with --y).")
@click.option("--y-num", "y_num", type=int, default=None,
              help="Number of --y values (evenly spaced; required with --y).")
@click.option("--samples", type=int, default=32, show_default=True,
              help="Forcing periods (maps: iterations) recorded from each start.")
@explore_options
def basins_cmd(model, params, sets, xname, x_from, x_to, x_num, yname, y_from, y_to, y_num,
               samples, x0, transient, section, workers, scheduler, chunk_size, store, rtol,
               atol, method, exact, sliding, no_progress, out, plot, force):
    """Basins of attraction of MODEL on a grid of initial conditions.

    The states not on the grid start from --x0 (default: the model's [defaults]).

    \b
    Example:
      pwsdyn basins bouncing-ball --x y --x-from 0.1 --x-to 2 --x-num 100 \\
          --y v --y-from -4 --y-to 4 --y-num 100 -p A=0.2236 -p omega=6.2832 \\
          --out basins.nc --plot basins.png
    """
    import numpy as np

    import pwsdyn

    run = prepare(model, params, sets, x0, force=force,
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")],
                  rtol=rtol, atol=atol, method=method, exact=exact, sliding=sliding)
    mdl = run.model
    grid = {}
    for name, a, b, n, hint in ((xname, x_from, x_to, x_num, "--x"),
                                (yname, y_from, y_to, y_num, "--y")):
        if name is None:
            if any(v is not None for v in (a, b, n)) and hint == "--y":
                raise click.BadParameter("--y-from/--y-to/--y-num need --y", param_hint="--y")
            continue
        if a is None or b is None or n is None:
            raise click.BadParameter(f"{hint} needs {hint}-from, {hint}-to and {hint}-num",
                                     param_hint=hint)
        if n < 1:
            raise click.BadParameter(f"{hint}-num must be at least 1, got {n}",
                                     param_hint=f"{hint}-num")
        if name not in mdl.states:
            raise click.BadParameter(f"unknown state {name!r}; states are "
                                     f"{list(mdl.states)}", param_hint=hint)
        grid[name] = np.linspace(a, b, n) if n > 1 else np.array([a])
    store_path, remove_store = _run_store(out, store)
    with reported():
        ds = pwsdyn.basins(mdl, grid, run.x0, params=run.params, transient=transient,
                           samples=samples, section=section,
                           workers=workers, scheduler=scheduler, chunk_size=chunk_size,
                           store=store_path, out=None, progress=not no_progress,
                           **run.options)
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo("grid        " + " x ".join(f"{k}: {len(v)}" for k, v in grid.items()))
    for b, f in zip(ds.basin.values, ds.fraction.values):
        if f == 0:
            continue
        if b >= 0:
            k = int(ds.attractor_period.values[b])
            what = f"period {k}" if k else "non-periodic"
            what += f", {float(ds.attractor_events_per_period.values[b]):.3g} events/period"
        else:
            what = "diverged" if b == -1 else "failed"
        _echo(f"basin {int(b):>3}   {100 * f:6.2f}%  {what}")

    figures = []
    if plot is not None:    # matplotlib is imported only for a figure
        from ..plot import plot_basins

        figures.append((plot, lambda: plot_basins(ds, path=plot, overwrite=force)))
    _finish_explore(ds, out, store_path, remove_store, figures, force)
