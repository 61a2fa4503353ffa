"""``pwsdyn crisis``: a crisis of a map model's (or a forced flow's, through its stroboscopic
section) attractor located from the geometry
(:func:`pwsdyn.locate_crisis`), with a figure of the attractor at the located value, the
boundary saddle's stable manifold and the contact point (:func:`pwsdyn.plot.plot_crisis`)."""

from __future__ import annotations

import click

from ._common import (method_option, model_argument, output_options, param_options, prepare,
                      reported, sliding_option, tolerance_options, x0_option)
from ._main import main
from ._output import _echo, _fail, _fmt, _write_outputs


@main.command("crisis")
@model_argument
@param_options("varied")
@click.option("--from", "start", type=float, required=True,
              help="First value: the attractor reached from --x0 must be bounded there.")
@click.option("--to", "stop", type=float, required=True, help="Last value.")
@x0_option("Initial state of the followed attractor, in state order (--x0 0.1,0) or "
           "NAME=VALUE pairs. Default: the model's [defaults] x0.")
@click.option("--tol", type=float, default=1e-12, show_default=True,
              help="Absolute tolerance on the located value.")
@click.option("--steps", type=int, default=41, show_default=True,
              help="Values of the bracketing sweep.")
@click.option("--arclength", type=float, default=None,
              help="Planar maps: length of each branch of the manifolds (default four times "
                   "the attractor's diameter).")
@click.option("--t0", type=float, default=None,
              help="Flows: the phase of the stroboscopic section x(t0) -> x(t0 + T) (default "
                   "the model's defaults.t0, else 0).")
@click.option("--seed", "seeds", multiple=True, metavar="VALUES",
              help="Planar maps and flows: a state (in state order, 1,0) from which Newton "
                   "also looks for a saddle, as for a boundary saddle far from the attractor; "
                   "may be repeated.")
@tolerance_options()
@method_option()
@sliding_option()
@output_options("Write the crisis (pwsdyn.Crisis.save) to this NetCDF file.",
                "Write a figure of the attractor at the located value, the saddle's stable "
                "manifold and the contact point (PNG; PDF, SVG... by suffix).")
def crisis_cmd(model, params, sets, start, stop, x0, tol, steps, arclength, t0, seeds,
               rtol, atol, method, sliding, out, plot, force):
    """Locate a boundary (or, for a one-state map, interior) crisis of the attractor of the map
    MODEL reached from --x0, in the parameter --param NAME between --from and --to. A forced
    two-state flow is taken through its stroboscopic section at phase --t0 (a planar map).

    The attractor is followed through --steps values; where its orbit leaves (or, one-state
    maps, its extent jumps) the value is located from the geometry as the root of a contact
    function: the attractor's edge against the saddle's stable set (one-state maps), or the
    unstable manifold of a saddle against the stable manifold of the boundary saddle (planar
    maps), to --tol.

    Flows only: --rtol, --atol, --method and --sliding apply to the runs of the section map
    (its saddles and manifolds); not given, each takes a simulation's default, as
    pwsdyn.locate_crisis takes them.

    \b
    Examples:
      pwsdyn crisis sqrt-map --param mu --from 0.5 --to 0.125 -p lam=2 --out c.nc
      pwsdyn crisis bcnf.toml --param tL --from 1.8 --to 2 --x0 0.1,0 --steps 11 \\
          --out c.nc --plot c.png
    """
    import numpy as np

    import pwsdyn

    if tol <= 0 or not np.isfinite(tol):
        raise click.BadParameter(f"must be a positive number, got {tol}", param_hint="--tol")
    if steps < 2:
        raise click.BadParameter(f"must be at least 2, got {steps}", param_hint="--steps")
    if arclength is not None and (arclength <= 0 or not np.isfinite(arclength)):
        raise click.BadParameter(f"must be a positive number, got {arclength}",
                                 param_hint="--arclength")
    run = prepare(model, params, sets, x0, force=force, named="varied",
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")], rtol=rtol,
                  atol=atol, method=method, sliding=sliding)
    mdl, param = run.model, run.named
    is_map = bool(getattr(mdl, "is_map", False))
    if is_map:
        flow_only = [f for f, v in (("--rtol", rtol), ("--atol", atol), ("--method", method),
                                    ("--sliding", sliding)) if v is not None]
        if flow_only:
            raise click.BadParameter(f"{mdl.name!r} is a map: {', '.join(flow_only)} "
                                     f"{'applies' if len(flow_only) == 1 else 'apply'} to "
                                     "flows only", param_hint=flow_only[0])
    if not is_map and (mdl.forcing_period is None or mdl.n_states != 2):
        _fail(f"{mdl.name!r} is a flow: its crises are located through its stroboscopic "
              "section, which needs a forcing period and two states")
    seed_states = []
    for text in seeds:
        try:
            seed_states.append([float(v) for v in text.split(",")])
        except ValueError:
            raise click.BadParameter(f"expected numbers in state order, got {text!r}",
                                     param_hint="--seed") from None
        if len(seed_states[-1]) != mdl.n_states:
            raise click.BadParameter(f"expected {mdl.n_states} values, got {text!r}",
                                     param_hint="--seed")
    if is_map and t0 is not None:
        raise click.BadParameter(f"{mdl.name!r} is a map: --t0 applies to flows only",
                                 param_hint="--t0")
    # the section's phase: --t0, else the model's [defaults] t0 (as every command with --t0)
    phase = float(t0 if t0 is not None else (mdl.defaults.get("t0") or 0.0))
    fixed = {k: v for k, v in run.params.items() if k != param}
    guess = run.x0 if run.x0 is not None else mdl.defaults.get("x0")
    if guess is None:
        raise click.BadParameter(f"model {mdl.name!r} has no [defaults] x0: give a state on "
                                 "the attractor's basin", param_hint="--x0")
    with reported():
        c = pwsdyn.locate_crisis(mdl, param, (start, stop), x0=guess, params=fixed, tol=tol,
                                 steps=steps, arclength=arclength,
                                 seeds=seed_states or None, t0=phase, **run.options)
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"crisis      {c.kind} at {param} = {c.value!r}")
    _echo(f"bracket     {param} in [{_fmt(c.bracket[0])}, {_fmt(c.bracket[1])}] (the sweep)")
    _echo(f"saddle      period {c.saddle.period}, x = "
          + ", ".join(f"{n}={_fmt(v)}" for n, v in zip(mdl.states, c.saddle.x))
          + f", pieces {', '.join(c.saddle.pieces)}")
    if c.unstable is not None:
        what = ("its own (a homoclinic tangency)" if c.unstable is c.saddle
                else f"the saddle of period {c.unstable.period} at "
                + ", ".join(f"{n}={_fmt(v)}" for n, v in zip(mdl.states, c.unstable.x)))
        _echo(f"unstable    manifold of {what}")
    _echo("contact     " + ", ".join(f"{n}={_fmt(v)}" for n, v in zip(mdl.states, c.point)))

    def draw():
        from ..model.iteration import iterate
        from ..plot import plot_crisis

        if not is_map:
            # a flow's attractor is drawn as the unstable manifold whose closure it is
            plot_crisis(c, plot, overwrite=force)
            return
        xs, _ = iterate(mdl, guess, 4000, params={**fixed, param: c.value}, transient=1000)
        plot_crisis(c, plot, attractor=xs, overwrite=force)

    problem = _write_outputs(out, plot, c.to_dataset, draw, force)
    if problem is not None:
        _fail(problem)
