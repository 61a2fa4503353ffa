"""``pwsdyn scan``: the period map of a model over two parameters (pwsdyn.scan)."""

from __future__ import annotations

import click

from ._common import (_stack, exact_option, method_option, model_argument, output_options,
                      parallel_options, param_options, prepare, progress_option, reported,
                      sliding_option, tolerance_options, x0_option)
from ._explore import _finish_explore, _run_store
from ._main import main
from ._output import _echo, _fmt

#: The options of ``scan`` after its grid: those of ``sweep`` (the same names and defaults)
#: without ``--chunk-size`` (a row is one task).
scan_options = _stack(
    x0_option("Initial state at the first value of every row (as for `simulate`); default: "
              "the model's [defaults]."),
    click.option("--transient", type=int, default=200, show_default=True,
                 help="Forcing periods (maps: iterations) discarded at each point."),
    click.option("--section", default="stroboscopic", show_default=True,
                 help="'stroboscopic' or the name of an event (e.g. impact)."),
    parallel_options,
    click.option("--store", default=None, type=click.Path(file_okay=False),
                 help="Resumable store directory (default: OUT.store, removed when done)."),
    tolerance_options(),
    method_option(),
    exact_option,
    sliding_option(),
    progress_option,
    output_options("Write the dataset to this NetCDF file (.nc).",
                   "Write the period map to this file (PNG; PDF, SVG... by suffix)."),
)


def _grid(start, stop, num, hint):
    import numpy as np

    if num < 1:
        raise click.BadParameter(f"must be at least 1, got {num}", param_hint=hint)
    return np.linspace(start, stop, num) if num > 1 else np.array([start])


@main.command("scan")
@model_argument
@click.option("--sweep", "swept", default=None, metavar="NAME",
              help="First parameter: swept along each row (also --param NAME).")
@param_options("swept")
@click.option("--from", "start", type=float, required=True, help="First value of the first.")
@click.option("--to", "stop", type=float, required=True, help="Last value of the first.")
@click.option("--num", type=int, required=True,
              help="Number of values of the first (evenly spaced).")
@click.option("--param2", "param2", required=True, metavar="NAME",
              help="Second parameter: one row per value.")
@click.option("--from2", "start2", type=float, required=True, help="First value of the second.")
@click.option("--to2", "stop2", type=float, required=True, help="Last value of the second.")
@click.option("--num2", type=int, required=True,
              help="Number of values of the second (evenly spaced).")
@click.option("--direction", type=click.Choice(["up", "down", "both"]), default="both",
              show_default=True, help="Sweep each row up, down or both (hysteresis).")
@click.option("--lyapunov", is_flag=True, default=False,
              help="Also compute the largest Lyapunov exponent (slower).")
@click.option("--samples", type=int, default=None,
              help="Forcing periods (maps: iterations) recorded at each point [100, or 300 "
                   "with --lyapunov].")
@scan_options
def scan_cmd(model, swept, params, sets, start, stop, num, param2, start2, stop2, num2,
             direction, lyapunov, samples, x0, transient, section, workers, scheduler, store,
             rtol, atol, method, exact, sliding, no_progress, out, plot, force):
    """Period map of MODEL over two parameters.

    Each row (one value of --param2) is a sweep in the first parameter (--param NAME or
    --sweep NAME) from --from to --to, continuing the final state from one value to the
    next as `pwsdyn sweep` does; rows run in parallel. --plot draws the map of the up
    sweep (the down sweep where only that was run).

    \b
    Example:
      pwsdyn scan impact-oscillator --param omega --from 2.5 --to 5 --num 100 \\
          --param2 sigma --from2 -0.8 --to2 0.3 --num2 100 -p eps=0.1 \\
          --section impact --direction up --out map.nc --plot map.png
    """
    import numpy as np

    import pwsdyn

    values = _grid(start, stop, num, "--num")
    values2 = _grid(start2, stop2, num2, "--num2")
    run = prepare(model, params, sets, x0, force=force, named="swept", swept=swept,
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")],
                  rtol=rtol, atol=atol, method=method, exact=exact, sliding=sliding)
    p1, mdl = run.named, run.model
    if param2 == p1:
        raise click.BadParameter(f"must differ from the first parameter {p1!r}",
                                 param_hint="--param2")
    # values given for the scanned parameters are left out: the scan sets them
    fixed = {k: v for k, v in run.params.items() if k not in (p1, param2)}
    store_path, remove_store = _run_store(out, store)
    with reported():
        ds = pwsdyn.scan(mdl, {p1: values, param2: values2}, run.x0, params=fixed,
                         transient=transient, samples=samples, section=section,
                         direction=direction, lyapunov=lyapunov, workers=workers,
                         scheduler=scheduler, store=store_path, out=None,
                         progress=not no_progress, **run.options)
    per = ds.period.values
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"scanned     {p1} from {_fmt(values[0])} to {_fmt(values[-1])} ({num} values) x "
          f"{param2} from {_fmt(values2[0])} to {_fmt(values2[-1])} ({num2} values), "
          f"{', '.join(map(str, ds.direction.values))}")
    _echo("periods     " + ", ".join(
        f"{k if k else 'none'}: {int(np.sum(per == k))}" for k in np.unique(per)))
    nbad = int(np.sum(ds.status.values != 0))
    if nbad:
        _echo(f"failed      {nbad} point(s) failed or diverged (status != 0)")
    figures = []
    if plot is not None:    # matplotlib is imported only for a figure
        from ..plot import plot_scan

        figures.append((plot, lambda: plot_scan(ds, path=plot, overwrite=force)))
    # the data go to --out here, not in pwsdyn.scan: --force applies and the figure follows
    _finish_explore(ds, out, store_path, remove_store, figures, force)
