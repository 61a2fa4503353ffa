"""``pwsdyn orbit``, ``pwsdyn continue`` and ``pwsdyn grazing``: periodic orbits by Newton
shooting, followed in a parameter, to a graze.

The three share the shooting's integrator defaults (``--rtol``, ``--method``: the library's
:data:`pwsdyn.orbits._base.SHOOTING_DEFAULTS`, tighter than a simulation's; the help says
why) and the way a starting orbit is found (:func:`_find_orbit`).
"""

from __future__ import annotations

import json

import click

from ._common import (_run_defaults, _stack, method_option, model_argument, output_options,
                      param_options, prepare, progress_option, reported, sliding_option,
                      tolerance_options, x0_option)
from ._main import main
from ._output import _echo, _fail, _fmt, _write_outputs


def _find_orbit(run, x0_val, t0, t_end, transient, period, periods, mode=None, **shooting):
    """The periodic orbit of ``orbit`` and the starting orbit of ``continue`` and
    ``grazing``: without a guess from the user (no --x0, or an autonomous model without
    --period) settle on the attractor first, over the model's typical run, and take the
    orbit from the end of that run; else shoot from --x0."""
    import pwsdyn
    from ..orbits import PeriodicOrbit, find_periodic_orbit

    autonomous = run.model.forcing_period is None
    if transient is None and period is None and (autonomous or not run.x0):
        transient = t_end - t0
    if transient:
        traj = pwsdyn.simulate(run.model, x0_val, (t0, t0 + transient), params=run.params,
                               mode=mode, **run.options)
        return PeriodicOrbit.from_trajectory(traj, period=period, periods=periods,
                                             **run.options, **shooting)
    return find_periodic_orbit(run.model, x0_val, params=run.params, period=period, t0=t0,
                               periods=periods or 1, mode=mode, **run.options, **shooting)


_TRANSIENT_HELP = ("Simulate this long from x0 first and take the guess from the end of the "
                   "run (default: the model's defaults.t_end when no --x0 is given or the "
                   "model is autonomous without --period; else none: --x0 is the guess).")


@main.command("orbit")
@model_argument
@param_options()
@x0_option("Guess of the state at t0: values in state order (--x0 1,0) or NAME=VALUE pairs. "
           "Default: the model's [defaults] x0.")
@click.option("--t0", type=float, default=None,
              help="Time of x0 (the phase of a forced orbit; default the model's defaults.t0, "
                   "else 0).")
@click.option("--period", type=float, default=None,
              help="Forced models: the period, a multiple of the forcing period (default "
                   "--periods forcing periods). Autonomous models: a guess (default: from the "
                   "recurrence of the events of a transient run).")
@click.option("--periods", type=int, default=None,
              help="Forced models: the period in forcing periods (default: after a transient "
                   "run, the number of forcing periods after which it repeats; else 1).")
@click.option("--transient", type=float, default=None, help=_TRANSIENT_HELP)
@click.option("--mode", default=None, metavar="STATE",
              help="Discrete state at t0: a mode, stick:<event> or slide:<switch>.")
@click.option("--nodes", default="auto", show_default=True,
              help="Shooting nodes: 'auto' (one per smooth segment) or a number (1: single "
                   "shooting).")
@click.option("--tol", type=float, default=1e-10, show_default=True,
              help="Newton tolerance on the shooting residual (relative).")
@tolerance_options(shooting=True)
@method_option(shooting=True)
@sliding_option()
@output_options("Write one period with its monodromy and multipliers to this NetCDF file.",
                "Write a figure of the orbit with its events and multipliers (PNG; PDF, "
                "SVG... by suffix).")
def orbit_cmd(model, params, sets, x0, t0, period, periods, transient, mode, nodes, tol, rtol,
              atol, method, sliding, out, plot, force):
    """Find a periodic orbit of MODEL by Newton shooting and print its Floquet multipliers.

    Prints the period, the signature (the events over one period) and the multipliers; with
    --out and --plot also writes the orbit and a figure. Unstable orbits are found as well as
    stable ones, from a guess near them.

    \b
    Examples:
      pwsdyn orbit impact-oscillator -p sigma=-0.5 -p eps=0.1 -p omega=2.8 --x0 -0.7,0 --plot o.png
      pwsdyn orbit one-legged-jumper --transient 400 --out gait.nc
    """
    run = prepare(model, params, sets, x0, force=force,
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")],
                  rtol=rtol, atol=atol, method=method, sliding=sliding)
    if periods is not None and periods < 1:
        raise click.BadParameter("must be a positive integer", param_hint="--periods")
    if nodes != "auto":
        try:
            nodes = int(nodes)
        except ValueError:
            raise click.BadParameter(f"'auto' or a positive integer, got {nodes!r}",
                                     param_hint="--nodes") from None
    x0_val, t0, t_end = _run_defaults(run.model, run.x0, t0, None)
    with reported("no periodic orbit"):
        orbit = _find_orbit(run, x0_val, t0, t_end, transient, period, periods, mode=mode,
                            tol=tol, nodes=nodes)
    _echo(orbit.summary())

    def draw():
        from ..plot import plot_orbit

        plot_orbit(orbit, path=plot, overwrite=force)

    with reported():
        problem = _write_outputs(out, plot, orbit.to_dataset, draw, force)
    if problem is not None:
        _fail(problem)


def _branch_options(what: str, to_help: str):
    """The options ``continue`` and ``grazing`` share: the continued parameter and its span,
    the starting orbit, the integrator, the progress bar (``what`` starts at --from)."""
    return _stack(
        model_argument,
        param_options("continued"),
        click.option("--from", "start", type=float, required=True,
                     help=f"Parameter value where the {what} starts (the starting orbit is "
                          f"found there)."),
        click.option("--to", "stop", type=float, required=True, help=to_help),
        x0_option("Guess of the starting orbit's state at t0: values in state order or "
                  "NAME=VALUE pairs. Default: settle from the model's [defaults] x0 first, "
                  "then shoot."),
        click.option("--t0", type=float, default=None,
                     help="Time of x0 (default the model's defaults.t0, else 0)."),
        click.option("--periods", type=int, default=None,
                     help="Forced models: the starting orbit's period in forcing periods "
                          "(default: from the recurrence of a transient run, else 1)."),
        click.option("--period", type=float, default=None,
                     help="Autonomous models: a guess of the period."),
        click.option("--transient", type=float, default=None, help=_TRANSIENT_HELP),
        tolerance_options(shooting=True),
        method_option(shooting=True),
        sliding_option(" The starting orbit's, which the branch keeps."),
        progress_option,
    )


def _span(start, stop):
    if start == stop:
        raise click.BadParameter("--from and --to must differ", param_hint="--to")
    return min(start, stop), max(start, stop)


@main.command("continue")
@_branch_options("branch", "Parameter value towards which the branch is followed (it may turn "
                           "back at folds; it ends on the boundary of [--from, --to] or after "
                           "--max-points).")
@click.option("--equilibrium", is_flag=True, default=False,
              help="Continue an equilibrium of the initial mode instead of a periodic orbit "
                   "(--x0 is then the guess of the equilibrium; no integration: --rtol, "
                   "--atol, --method and --sliding do not apply).")
@click.option("--ds", type=float, default=None,
              help="First step in arclength (default min(0.02, abs(to - from) / 100)).")
@click.option("--max-points", "max_points", type=int, default=200, show_default=True,
              help="Most points on the branch.")
@click.option("--y", "--state", "state", default=None,
              help="What the figure plots against the parameter: a state at the section, "
                   "max:STATE or min:STATE over the orbit, period or norm (default: "
                   "max:<first state> for orbits, continuous through grazes; for equilibria "
                   "the state that varies most).")
@click.option("--on-dib", "on_dib", type=click.Choice(["switch", "stop", "continue"]),
              default="switch", show_default=True,
              help="At a graze: go on with the orbit's new event sequence, stop there, or keep "
                   "the old one (its points past the graze are not admissible).")
@output_options("Write the branch to this NetCDF file.",
                "Write the bifurcation diagram (stable solid, unstable dashed, not "
                "admissible dotted, special points labelled).")
def continue_cmd(model, params, sets, start, stop, x0, t0, periods, period, transient,
                 equilibrium, ds, max_points, rtol, atol, method, sliding, no_progress, out,
                 plot, state, on_dib, force):
    """Follow a periodic orbit (or an equilibrium) of MODEL in the parameter --param NAME by
    pseudo-arclength continuation, from --from towards --to.

    Without --x0 the starting orbit is found as `pwsdyn orbit` finds it: a transient run
    from the model's defaults, then Newton shooting. Folds (LP), period doublings (PD),
    Neimark-Sacker points (NS), branch points (BP) and, for equilibria, Hopf points (HB) are
    located and printed with their multipliers (eigenvalues).

    \b
    Examples:
      pwsdyn continue impact-oscillator --param omega --from 2.8 --to 4.6 \\
          -p eps=0.1 -p sigma=-0.5 --out branch.nc --plot branch.png
      pwsdyn continue bouncing-ball --param A --from 0.224 --to 0.32 --plot ball.png
    """
    import numpy as np

    import pwsdyn

    if max_points < 2:
        raise click.BadParameter(f"must be at least 2, got {max_points}",
                                 param_hint="--max-points")
    span = _span(start, stop)
    if equilibrium:
        given = [f for f, v in (("--rtol", rtol), ("--atol", atol), ("--method", method),
                                ("--sliding", sliding)) if v is not None]
        if given:
            raise click.BadParameter("an equilibrium is continued without integrating: "
                                     f"{', '.join(given)} do(es) not apply",
                                     param_hint="--equilibrium")
    run = prepare(model, params, sets, x0, force=force, named="continued",
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")],
                  rtol=rtol, atol=atol, method=method, sliding=sliding)
    param, mdl = run.named, run.model
    run.params[param] = start
    x0_val, t0, t_end = _run_defaults(mdl, run.x0, t0, None)
    step = ds if ds is not None else min(0.02, abs(stop - start) / 100.0)
    step = abs(step) if stop > start else -abs(step)
    all_params = {**mdl.parameters, **run.params}
    with reported("no starting orbit"):
        if equilibrium:
            branch = pwsdyn.continue_equilibrium(mdl, x0_val, param, span=span, ds=step,
                                                 max_points=max_points, params=all_params,
                                                 progress=not no_progress)
        else:
            orbit = _find_orbit(run, x0_val, t0, t_end, transient, period, periods)
            _echo(f"start       orbit of period {_fmt(orbit.period)} at {param} = "
                  f"{_fmt(start)}, {orbit.signature}, "
                  f"{'stable' if orbit.stable else 'unstable'}")
            branch = pwsdyn.continue_orbit(mdl, orbit, param, span=span, ds=step,
                                           max_points=max_points, progress=not no_progress,
                                           on_dib=on_dib, **run.options)
    vals = branch.values
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"branch      {branch.kind}, {len(branch)} points, {param} in "
          f"[{_fmt(vals.min())}, {_fmt(vals.max())}]; {int(np.sum(branch.stable))} stable, "
          f"{int(np.sum(~branch.admissible))} not admissible")
    _print_special_points(branch, param)
    if len(branch.problems) > 1:
        _echo("signatures  " + "  ->  ".join(str(s_) for s_ in branch.signatures))
    why = f"{branch.stop_status}: " if branch.stop_status is not None else ""
    _echo(f"stopped     {why}{branch.stop_reason}")

    def draw():
        from ..plot import plot_branch

        plot_branch(branch, y=state, path=plot, overwrite=force)

    with reported():
        problem = _write_outputs(out, plot, branch.to_dataset, draw, force)
    if problem is not None:
        _fail(problem)
    if branch.stop_status is not None and branch.stop_status.failed:
        # the branch so far is written (above); that it ended before the span's end, and
        # why, is the command's outcome
        _fail(f"the branch ended early ({branch.stop_status}): {branch.stop_reason}")


def _multipliers(values) -> str:
    return ", ".join(f"{complex(z).real:.6g}{complex(z).imag:+.6g}j" for z in values)


def _print_special_points(branch, param):
    for sp in branch.special_points:
        if sp.kind == "EP":
            continue
        spec = sp.multipliers if sp.multipliers is not None else sp.eigenvalues
        what = "multipliers" if sp.multipliers is not None else "eigenvalues"
        where = ""
        if sp.monitor is not None:
            mon = sp.monitor
            where = (f" ({'impact velocity zero' if '@' in sp.key else 'grazing'} on "
                     f"{mon.surface!r}, segment {mon.segment}, t = {_fmt(mon.t)})")
        _echo(f"{sp.kind:<11} {param} = {_fmt(sp.value)}{where}; {what} " + _multipliers(spec))


@main.command("grazing")
@_branch_options("search", "Parameter value towards which the orbit is followed to its first "
                           "graze.")
@click.option("--terms", type=int, default=10, show_default=True,
              help="Terms of the persistence sequence printed (and written to --out).")
@output_options("Write the branch up to the graze (as `continue --out` does, readable by "
                "pwsdyn.load_branch) with the discontinuity map at the graze (its x*, a*, "
                "beta, P, h_x, the persistence sequence and the scenario) to this NetCDF "
                "file.",
                "Write a figure of the grazing orbit, as `orbit --plot` draws an orbit: "
                "the impact surface it touches, its events and multipliers (PNG; PDF, "
                "SVG... by suffix).")
def grazing_cmd(model, params, sets, start, stop, x0, t0, periods, period, transient, rtol,
                atol, method, sliding, no_progress, terms, out, plot, force):
    """Follow a periodic orbit of MODEL in --param NAME from --from towards --to to its first
    graze of an impact surface, and print Nordmark's discontinuity map there (x*, a*, beta),
    the persistence sequence h_x P^n beta and the predicted scenario: persistence of a local
    attractor, or its loss (with hysteresis).

    \b
    Example:
      pwsdyn grazing impact-oscillator --param sigma --from 0.45 --to 0.0 \\
          -p omega=2.8 -p eps=0.1 --x0 x=-0.006,v=-0.41 --t0 0 --out graze.nc --plot graze.png
    """
    import pwsdyn
    from ..errors import ArgumentError

    if terms < 1:
        raise click.BadParameter(f"must be at least 1, got {terms}", param_hint="--terms")
    span = _span(start, stop)
    run = prepare(model, params, sets, x0, force=force, named="continued",
                  outputs=[("--out", out, "data"), ("--plot", plot, "figure")],
                  rtol=rtol, atol=atol, method=method, sliding=sliding)
    param, mdl = run.named, run.model
    run.params[param] = start
    x0_val, t0, t_end = _run_defaults(mdl, run.x0, t0, None)
    step = min(0.02, abs(stop - start) / 100.0) * (1 if stop > start else -1)
    with reported("no starting orbit"):
        orbit = _find_orbit(run, x0_val, t0, t_end, transient, period, periods)
        branch = pwsdyn.continue_orbit(mdl, orbit, param, span=span, ds=step, on_dib="stop",
                                       locate=("GR", "CC"), progress=not no_progress,
                                       **run.options)
        # a segment touching an impact surface inside it, or at a kink of the field (a
        # corner collision that is a graze: the quarter-car's bumpstop at its damper's kink)
        gr, dm, why = None, None, ""
        for sp in branch.special_points:
            if sp.kind in ("GR", "CC"):
                try:
                    dm = pwsdyn.discontinuity_map(sp)
                except ArgumentError as exc:
                    why = f"; the {sp.kind} at {param} = {_fmt(sp.value)} is not one: {exc}"
                    continue
                gr = sp
                break
        if gr is None:
            _fail(f"no graze of an impact surface between {param} = {_fmt(start)} and "
                  f"{_fmt(stop)} ({branch.stop_reason}{why})")
    seq = dm.persistence(terms)
    vec = ", ".join(f"{n_}={_fmt(v)}" for n_, v in zip(dm.names, dm.x_star))
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"graze       {param} = {_fmt(gr.value)}: orbit {gr.problem.orbit_problem.signature} "
          f"touches {gr.monitor.surface!r} (event {dm.event!r}) in segment "
          f"{gr.monitor.segment}")
    _echo(f"x*          {vec}")
    _echo(f"a*          {_fmt(dm.a_star)}")
    _echo("beta        " + ", ".join(f"{n_}={_fmt(v)}" for n_, v in zip(dm.names, dm.beta)))
    _echo("multipliers " + _multipliers(gr.multipliers))
    _echo("h_x P^n beta " + " ".join(f"{v:.3e}" for v in seq))
    # the scenario is about the orbit that grazes: an attractor's only if that orbit is
    # stable and of period one (without --x0 the settling run may find another orbit)
    before = branch.points[gr.index - 1] if gr.index > 0 else gr.point
    stable = bool(before.data.get("stable", True))
    k = int(getattr(gr.problem.orbit_problem, "periods", 1) or 1)
    if stable:
        _echo(f"scenario    {dm.scenario}"
              + (" of a local attractor" if dm.scenario == "persistence" else
                 " of the local attractor (a jump to a distant one, hysteresis)"))
    else:
        _echo(f"scenario    {dm.scenario} of a neighbourhood of the grazing orbit (it is "
              f"unstable: no attractor grazes here)")
    what = (["unstable"] if not stable else []) + ([f"of period {k}"] if k > 1 else [])
    if what:
        _echo(f"note        the orbit analysed is {' and '.join(what)} (forcing periods: "
              f"{k}); to analyse another, start from it with --x0 and --periods")

    def draw():
        from ..plot import plot_orbit

        plot_orbit(gr.orbit, path=plot, overwrite=force)

    with reported():
        problem = _write_outputs(out, plot, lambda: _grazing_dataset(branch, gr, dm, seq),
                                 draw, force)
    if problem is not None:
        _fail(problem)


def _grazing_dataset(branch, gr, dm, seq):
    """The branch up to the graze (:meth:`pwsdyn.Branch.to_dataset`, which
    :func:`pwsdyn.load_branch` reads back) with the discontinuity map at the graze: variables
    and attributes named ``graze_*``, on the dimensions ``graze_coordinate`` (the map's
    coordinates: the states, then ``t`` for a forced model; their names in the attribute
    ``graze_coordinates``) and ``graze_term`` (n = 1, 2, ... of h_x P^n beta)."""
    import numpy as np

    ds = branch.to_dataset()
    xy = ("graze_coordinate", "graze_coordinate_to")
    ds["graze_x_star"] = (xy[0], np.asarray(dm.x_star, dtype=float),
                          {"long_name": "grazing point x* of the discontinuity map"})
    ds["graze_beta"] = (xy[0], np.asarray(dm.beta, dtype=float),
                        {"long_name": "direction beta of the square-root correction"})
    ds["graze_h_x"] = (xy[0], np.asarray(dm.h_x, dtype=float),
                       {"long_name": "gradient h_x of the impact surface at x*"})
    ds["graze_P"] = ((xy[1], xy[0]), np.asarray(dm.P, dtype=float),
                     {"long_name": "Jacobian P of the smooth Poincare map at x* (rows: "
                                   "graze_coordinate_to, columns: graze_coordinate)"})
    ds["graze_persistence"] = ("graze_term", np.asarray(seq, dtype=float),
                               {"long_name": "persistence sequence h_x P^n beta, n = 1, 2, ..."})
    ds.attrs.update({
        "graze_kind": gr.kind,
        "graze_value": float(gr.value),
        "graze_surface": str(gr.monitor.surface),
        "graze_segment": int(gr.monitor.segment),
        "graze_event": str(dm.event),
        "graze_a_star": float(dm.a_star),
        "graze_scenario": dm.scenario,
        "graze_coordinates": json.dumps(list(dm.names)),
    })
    return ds
