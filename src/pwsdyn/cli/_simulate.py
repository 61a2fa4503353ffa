"""``pwsdyn simulate``: one run of a model, its summary, its trajectory and its figure."""

from __future__ import annotations

import click

from ._common import (FALLBACK_T_END, _run_defaults, exact_option, method_option,
                      model_argument, output_options, param_options, prepare, reported,
                      sliding_option, tolerance_options, x0_option)
from ._main import main
from ._output import _echo, _fail, _fmt, _oneline, _write_outputs


@main.command("simulate")
@model_argument
@param_options()
@x0_option("Initial state: comma-separated values in state order (--x0 1,0) or NAME=VALUE "
           "pairs (--x0 y=1 --x0 v=0). Default: the model's [defaults].")
@click.option("--t0", type=float, default=None,
              help="Start time (default: the model's [defaults], else 0).")
@click.option("--t-end", "t_end", type=float, default=None,
              help=f"End time (default: the model's [defaults], else t0 + "
                   f"{FALLBACK_T_END:g}).")
@tolerance_options()
@method_option()
@exact_option
@click.option("--mode", default=None, metavar="NAME", help="Initial mode.")
@sliding_option()
@output_options("Write the trajectory to this NetCDF file (.nc).",
                "Write a figure of the trajectory to this file (PNG; PDF, SVG... by suffix).")
def simulate_cmd(model, params, sets, x0, t0, t_end, rtol, atol, method, exact, mode, sliding,
                 out, plot, force):
    """Simulate MODEL (a built-in name, see `pwsdyn models`, or a TOML file).

    Prints a summary; with --out and --plot also writes the trajectory and a figure.

    \b
    Examples:
      pwsdyn simulate bouncing-ball --out run.nc --plot run.png
      pwsdyn simulate bouncing-ball -p A=0.05 -p omega=10 --x0 y=0.5 --x0 v=0 --t-end 5
    """
    import pwsdyn

    run = prepare(model, params, sets, x0, force=force,
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")],
                  rtol=rtol, atol=atol, method=method, exact=exact, sliding=sliding)
    x0_val, t0, t_end = _run_defaults(run.model, run.x0, t0, t_end)
    options = dict(run.options, **({"mode": mode} if mode is not None else {}))
    with reported():
        traj = pwsdyn.simulate(run.model, x0_val, (t0, t_end), params=run.params,
                               throw=False, **options)

    _print_summary(traj)

    def draw():
        from ..plot import plot_trajectory

        plot_trajectory(traj, path=plot, overwrite=force)

    # a failed run is still written: its data and figure show where and why it stopped
    problem = _write_outputs(out, plot, traj.to_dataset, draw, force)
    if problem is not None:
        if not traj.status.failed:
            _fail(problem)
        _echo(f"Error: {_oneline(problem)}", err=True)
    if traj.status.failed:
        _fail(f"the simulation stopped early ({traj.status.name}) at t={traj.t_final:.17g} in "
              f"{traj.state[-1]}: {traj.message}")


def _print_summary(traj):
    model = traj.model
    counts = traj.event_counts()
    ev = ", ".join(f"{v} {k}" for k, v in counts.items()) or "none"
    st = traj.stats
    params = ", ".join(f"{k}={_fmt(v)}" for k, v in traj.params.items()) or "(none)"
    final = ", ".join(f"{s}={_fmt(v)}" for s, v in zip(model.states, traj.x_final))
    lines = [
        f"model       {model.name} (hash {model.hash})",
        f"parameters  {params}",
        f"time span   [{_fmt(traj.t0)}, {_fmt(traj.t_end)}]",
        f"steps       {st.get('steps', '?')} accepted, {st.get('rejected_steps', '?')} rejected, "
        f"{st.get('nfev', '?')} function evaluations",
        f"events      {ev}",
    ]
    if model.switches:
        # switching surfaces: crossings, sliding segments and the time spent sliding
        slides = traj.sliding_intervals()
        total = sum(b - a for a, b, _ in slides)
        span = max(traj.t_final - traj.t0, 1e-300)
        lines.append(f"switching   {counts.get('crossing', 0)} crossings, {len(slides)} sliding "
                     f"segments, total sliding time {_fmt(total)} "
                     f"({100.0 * total / span:.3g}% of the run)")
    lines += [
        f"final       t={_fmt(traj.t_final)}: {final} (in {traj.state[-1]})",
        f"status      {traj.status.name}: {traj.message}",
    ]
    _echo("\n".join(lines))
