"""``pwsdyn manifold``: the saddle of a map model or of a forced flow, and its one-dimensional
stable and unstable manifolds (:func:`pwsdyn.manifold`).

The saddle of a map model is its periodic point found by Newton from ``--x0``
(:func:`pwsdyn.find_periodic_point`, ``--period`` iterations); that of a forced flow is the
periodic orbit ``pwsdyn orbit`` finds (``_find_orbit`` of ``pwsdyn.cli._orbits``: Newton
shooting from ``--x0``, ``--period`` forcing periods), on its stroboscopic section.
"""

from __future__ import annotations

from pathlib import Path

import click

from ._common import (_run_defaults, method_option, model_argument, output_options,
                      param_options, prepare, reported, sliding_option, tolerance_options,
                      x0_option)
from ._main import main
from ._orbits import _find_orbit, _multipliers
from ._output import _echo, _fail, _fmt, _rescue_data, _save_data, _write_figures


def _stable_path(out):
    """The second file of ``--kind both --out P``: the stable manifold in
    ``<stem>-stable<suffix>`` (the unstable one is in ``P``), as ``sweep --lyapunov`` names
    its second figure."""
    p = Path(out)
    return p.with_name(p.stem + "-stable" + p.suffix)


def _summary(m) -> None:
    for b, (status, length, pieces) in enumerate(zip(m.status, m.arclengths, m.branches)):
        sign = "+" if b == 0 else "-"
        _echo(f"{m.kind:<11} branch {sign}eigenvector: {sum(len(p) for p in pieces)} points in "
              f"{len(pieces)} piece(s), arclength {_fmt(length)}, stopped: {status}")
    _echo(f"{'':<11} {m.evaluations} map evaluations, {m.unresolved} unresolved point(s)")


@main.command("manifold")
@model_argument
@param_options()
@x0_option("The saddle: a guess of the map's periodic point, or of the forced flow's periodic "
           "orbit's state at t0, in state order (--x0 1,0) or NAME=VALUE pairs. Default: the "
           "model's [defaults] x0.")
@click.option("--period", type=int, default=1, show_default=True,
              help="Period of the saddle: iterations of a map model, forcing periods of a "
                   "flow's orbit.")
@click.option("--t0", type=float, default=None,
              help="Flows: time of x0, the phase of the stroboscopic section (default the "
                   "model's defaults.t0, else 0).")
@click.option("--transient", type=float, default=None,
              help="Flows: simulate this long from x0 first and take the orbit's guess from "
                   "the end of the run (default: none, --x0 is the guess; a saddle is not "
                   "reached by a transient run).")
@click.option("--kind", type=click.Choice(["unstable", "stable", "both"]), default="unstable",
              show_default=True, help="Which manifold(s) of the saddle to grow.")
@click.option("--arclength", type=float, default=1.0, show_default=True,
              help="Length of each branch (jumps not counted).")
@click.option("--max-points", "max_points", type=int, default=10_000, show_default=True,
              help="Points per branch at most.")
@click.option("--tol", type=float, default=1e-6, show_default=True,
              help="Accuracy of the polyline: the largest deviation of a chord from the "
                   "manifold.")
@tolerance_options()
@method_option()
@sliding_option()
@output_options("Write the manifold to this NetCDF file (with --kind both the unstable one; "
                "the stable one goes to <stem>-stable.nc next to it).",
                "Write a figure of the manifold(s) and the saddle (PNG; PDF, SVG... by "
                "suffix).")
def manifold_cmd(model, params, sets, x0, period, t0, transient, kind, arclength, max_points,
                 tol, rtol, atol, method, sliding, out, plot, force):
    """Grow the stable or unstable manifold of a saddle of MODEL, both branches, from its
    eigendirection to --arclength.

    A map model's saddle is its periodic point of --period iterations found by Newton from
    --x0; a forced flow's is the periodic orbit of --period forcing periods found by shooting
    from --x0 (as `pwsdyn orbit` finds one), on the stroboscopic section at --t0. The saddle
    needs exactly one unstable (for --kind stable: one stable) real multiplier.

    Flows only: --rtol, --atol, --method and --sliding apply to the shooting and to the
    manifold's runs; not given, each takes the library's default (the tighter shooting
    ones for the orbit, a simulation's for the manifold, as pwsdyn.find_periodic_orbit and
    pwsdyn.manifold take them).

    \b
    Examples:
      pwsdyn manifold sqrt-map -p mu=0.2 -p lam=0.3 --x0 0.03 --arclength 0.1 --out w.nc
      pwsdyn manifold impact-oscillator -p omega=2.8 --x0 -0.29,-0.58 --kind both \\
          --arclength 0.3 --out w.nc --plot w.png
    """
    import numpy as np

    import pwsdyn

    if arclength <= 0 or not np.isfinite(arclength):
        raise click.BadParameter(f"must be a positive number, got {arclength}",
                                 param_hint="--arclength")
    if tol <= 0 or not np.isfinite(tol):
        raise click.BadParameter(f"must be a positive number, got {tol}", param_hint="--tol")
    if max_points < 3:
        raise click.BadParameter(f"must be at least 3, got {max_points}",
                                 param_hint="--max-points")
    if period < 1:
        raise click.BadParameter(f"must be a positive integer, got {period}",
                                 param_hint="--period")
    outputs = [("--out", out, "data"), ("--plot", plot, "figure")]
    if kind == "both" and out is not None:
        outputs.append(("--out (its stable manifold)", _stable_path(out), "data"))
    run = prepare(model, params, sets, x0, force=force, outputs=outputs, rtol=rtol, atol=atol,
                  method=method, sliding=sliding)
    mdl = run.model
    kinds = ("unstable", "stable") if kind == "both" else (kind,)
    grow = {"arclength": arclength, "max_points": max_points, "tol": tol}
    if getattr(mdl, "is_map", False):
        flow_only = [f for f, v in (("--t0", t0), ("--transient", transient), ("--rtol", rtol),
                                    ("--atol", atol), ("--method", method),
                                    ("--sliding", sliding)) if v is not None]
        if flow_only:
            raise click.BadParameter(f"{mdl.name!r} is a map: {', '.join(flow_only)} "
                                     f"{'applies' if len(flow_only) == 1 else 'apply'} to "
                                     "flows only", param_hint=flow_only[0])
        guess = run.x0 if run.x0 is not None else mdl.defaults.get("x0")
        if guess is None:
            raise click.BadParameter(f"model {mdl.name!r} has no [defaults] x0: give a guess "
                                     "of the saddle", param_hint="--x0")
        with reported():
            saddle = pwsdyn.find_periodic_point(mdl, guess, period, params=run.params)
        _echo(f"saddle      period {saddle.period}, x = {_vector(mdl, saddle.x)}, pieces "
              f"{', '.join(saddle.pieces)}")
        _echo("multipliers " + _multipliers(saddle.multipliers))
    else:
        if mdl.forcing_period is None:      # before any shooting: the API would refuse it after
            _fail(f"{mdl.name!r} is autonomous: its orbits have no stroboscopic section, the "
                  "only section manifolds are grown on so far (maps and forced flows)")
        x0_val, t0, t_end = _run_defaults(mdl, run.x0, t0, None)
        with reported("no periodic orbit"):
            saddle = _find_orbit(run, x0_val, t0, t_end, transient or 0.0, None, period)
        _echo(f"saddle      orbit of period {_fmt(saddle.period)} at t0 = {_fmt(saddle.t0)}, "
              f"x0 = {_vector(mdl, saddle.x0)}, {saddle.signature}")
        _echo("multipliers " + _multipliers(saddle.multipliers))
        grow.update(run.options)
    with reported():
        results = [pwsdyn.manifold(mdl, saddle, k, **grow) for k in kinds]
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    for m in results:
        _summary(m)
    if out is not None:
        _save_data(results[0].to_dataset(), out, force)
        if len(results) == 2:
            _save_data(results[1].to_dataset(), _stable_path(out), force)
    if plot is not None:
        problem = _write_figures([(plot, lambda: _draw(results, plot, force))], out,
                                 results[0].to_dataset)
        if problem is not None and len(results) == 2 and out is None:
            # the stable manifold is not lost either: next to the unstable one's rescue
            saved, err = _rescue_data(results[1].to_dataset, _stable_path(plot))
            problem += (f"; the stable manifold to {str(saved)!r}" if saved is not None
                        else f"; the stable manifold could not be saved ({err})")
        if problem is not None:
            _fail(problem)


def _vector(model, x) -> str:
    return ", ".join(f"{n}={_fmt(v)}" for n, v in zip(model.states, x))


def _draw(results, path, force):
    """The manifolds on one axes, the saddle marked, written atomically (never a
    half-written figure, an existing one replaced only with --force)."""
    from matplotlib.figure import Figure

    from .._netcdf import atomic_write

    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    for k, m in enumerate(results):
        m.plot(ax=ax, saddle=k == 0)
    if len(results[0].model.states) == 1:    # a one-state map is drawn along its axis
        ax.set_xlabel(results[0].model.states[0])
        ax.set_yticks([])
    ax.legend(loc="best")
    ax.set_title(f"{results[0].model.name}: saddle of period {results[0].period}")
    fmt = Path(path).suffix[1:].lower() or "png"
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120, format=fmt), overwrite=force)
