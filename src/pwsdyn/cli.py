"""The ``pwsdyn`` command line.

``pwsdyn models`` lists the built-in models; ``pwsdyn simulate MODEL`` simulates a built-in
model or a model file and writes the trajectory (NetCDF) and a figure (PNG).

Errors in the arguments or the model, and failed simulations, are reported as one line
``Error: ...`` without a traceback: exit code 2 for a bad argument (click's convention for
usage errors), 1 for a model that cannot be loaded or a simulation that fails.
"""

from __future__ import annotations

import math
import textwrap

import click

#: End time used when neither ``--t-end`` nor the model's ``[defaults]`` give one.
FALLBACK_T_END = 10.0


# ======================================================================================
# argument parsing helpers
# ======================================================================================

def _number(text: str, what: str) -> float:
    """``text`` as a finite float; ``what`` names the argument in the message."""
    try:
        val = float(text)
    except ValueError:
        raise click.BadParameter(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(val):
        raise click.BadParameter(f"{what}: {text!r} is not a finite number")
    return val


def _parse_params(values) -> dict:
    """``--param NAME=VALUE`` options as a dict (names are checked against the model later)."""
    out = {}
    for item in values:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise click.BadParameter(f"expected NAME=VALUE, got {item!r}", param_hint="--param")
        try:
            out[name] = _number(text.strip(), f"parameter {name!r}")
        except click.BadParameter as exc:
            exc.param_hint = "--param"
            raise
    return out


def _parse_x0(values):
    """``--x0`` options: values in state order (``1,0``) or ``NAME=VALUE`` pairs.

    Each option may hold several comma-separated entries; all entries together must be of one
    form. Returns a list of floats, a dict by name, or ``None`` when no ``--x0`` was given.
    """
    tokens = [tok.strip() for item in values for tok in item.split(",")]
    if not tokens:
        return None
    if any(tok == "" for tok in tokens):
        raise click.BadParameter(f"empty entry in {','.join(values)!r}", param_hint="--x0")
    named = ["=" in tok for tok in tokens]
    if all(named):
        out = {}
        for tok in tokens:
            name, _, text = tok.partition("=")
            name = name.strip()
            if not name:
                raise click.BadParameter(f"missing state name in {tok!r}", param_hint="--x0")
            if name in out:
                raise click.BadParameter(f"state {name!r} given twice", param_hint="--x0")
            try:
                out[name] = _number(text.strip(), f"state {name!r}")
            except click.BadParameter as exc:
                exc.param_hint = "--x0"
                raise
        return out
    if any(named):
        raise click.BadParameter("give either values in state order (--x0 1,0) or NAME=VALUE "
                                 "pairs (--x0 y=1 --x0 v=0), not both", param_hint="--x0")
    out = []
    for k, tok in enumerate(tokens):
        try:
            out.append(_number(tok, f"entry {k + 1}"))
        except click.BadParameter as exc:
            exc.param_hint = "--x0"
            raise
    return out


def _check_x0(model, x0):
    """Check ``x0`` against the model's states, naming the problem."""
    names = list(model.states)
    if isinstance(x0, dict):
        unknown = [k for k in x0 if k not in names]
        if unknown:
            raise click.BadParameter(f"unknown state(s) {unknown} for model {model.name!r}; "
                                     f"states are {names}", param_hint="--x0")
        missing = [s for s in names if s not in x0]
        if missing:
            raise click.BadParameter(f"missing state(s) {missing}; give all of {names}",
                                     param_hint="--x0")
    elif len(x0) != len(names):
        raise click.BadParameter(f"model {model.name!r} has {len(names)} states {names}, got "
                                 f"{len(x0)} value(s)", param_hint="--x0")


def _check_params(model, params):
    unknown = [k for k in params if k not in model.parameters]
    if unknown:
        raise click.BadParameter(f"unknown parameter(s) {unknown} for model {model.name!r}; "
                                 f"parameters are {list(model.parameters)}",
                                 param_hint="--param")


def _model_defaults(model) -> dict:
    """The model's optional ``[defaults]`` table (``x0``, ``t0``, ``t_end``, ``params``)."""
    from .errors import ModelError

    defaults = model.spec.get("defaults", {}) or {}
    if not isinstance(defaults, dict):
        raise ModelError("`defaults` must be a table", source=model.origin, field="defaults")
    return defaults


def _resolve_defaults(model, defaults, x0, t0, t_end, params):
    """Command-line values first, then the model's ``[defaults]``, then zero / fallbacks."""
    all_params = dict(defaults.get("params", {}) or {})
    all_params.update(params)
    if x0 is None:
        if defaults.get("x0") is not None:
            x0 = defaults["x0"]
        else:
            x0 = [0.0] * model.n_states
            click.echo(f"note: no --x0 given and model {model.name!r} has no defaults.x0; "
                       f"starting from zero ({', '.join(f'{s}=0' for s in model.states)})",
                       err=True)
    if t_end is None:
        if defaults.get("t_end") is not None:
            t_end = float(defaults["t_end"])
        else:
            t_end = FALLBACK_T_END
            click.echo(f"note: no --t-end given and model {model.name!r} has no "
                       f"defaults.t_end; using t_end = {FALLBACK_T_END:g}", err=True)
    if t0 is None:
        t0 = float(defaults.get("t0", 0.0))
    return x0, t0, t_end, all_params


def _fmt(v: float) -> str:
    return f"{v:.10g}"


# ======================================================================================
# commands
# ======================================================================================

@click.group(invoke_without_command=True, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="pwsdyn", prog_name="pwsdyn")
@click.pass_context
def main(ctx):
    """Numerical analysis of piecewise-smooth dynamical systems.

    Impacts, dry friction, Filippov sliding and chattering: simulate a built-in model or a
    model file (TOML) and write the trajectory and a figure.
    """
    if ctx.invoked_subcommand is None:
        click.echo(ctx.get_help())


@main.command("models")
def models_cmd():
    """List the built-in models with their states and parameters."""
    import pwsdyn

    failed = 0
    for name in pwsdyn.zoo_names():
        try:
            model = pwsdyn.load_model(name)
        except Exception as exc:  # list the rest of the zoo even if one file is broken
            click.echo(f"{name}\n  failed to load: {exc}\n", err=True)
            failed += 1
            continue
        desc = model.description.strip().splitlines()[0] if model.description.strip() else ""
        # a listing, not the documentation: one line per model
        desc = textwrap.shorten(desc, width=90, placeholder=" ...")
        click.echo(click.style(model.name, bold=True) + (f"  {desc}" if desc else ""))
        click.echo(f"  states:     {', '.join(model.states)}")
        params = ", ".join(f"{k}={_fmt(v)}" for k, v in model.parameters.items())
        click.echo(f"  parameters: {params or '(none)'}")
        modes = ", ".join(model.mode_names)
        click.echo(f"  modes:      {modes}")
        click.echo("")
    if failed:
        raise SystemExit(1)


@main.command("simulate")
@click.argument("model", metavar="MODEL|FILE")
@click.option("--param", "-p", "params", multiple=True, metavar="NAME=VALUE",
              help="Parameter value (repeatable); overrides the model's defaults.")
@click.option("--x0", "x0", multiple=True, metavar="VALUES",
              help="Initial state: comma-separated values in state order (--x0 1,0) or "
                   "NAME=VALUE pairs (--x0 y=1 --x0 v=0). Default: the model's [defaults].")
@click.option("--t0", type=float, default=None, help="Start time (default 0).")
@click.option("--t-end", "t_end", type=float, default=None,
              help=f"End time (default: the model's [defaults], else {FALLBACK_T_END:g}).")
@click.option("--rtol", type=float, default=None, help="Relative tolerance (default 1e-10).")
@click.option("--atol", type=float, default=None, help="Absolute tolerance (default 1e-12).")
@click.option("--method", type=click.Choice(["RK45", "DOP853"], case_sensitive=False),
              default=None, help="Runge-Kutta pair (default RK45).")
@click.option("--mode", default=None, metavar="NAME", help="Initial mode.")
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write the trajectory to this NetCDF file.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write a figure of the trajectory to this PNG file.")
def simulate_cmd(model, params, x0, t0, t_end, rtol, atol, method, mode, out, plot):
    """Simulate MODEL (a built-in name, see `pwsdyn models`, or a TOML file).

    Prints a summary; with --out and --plot also writes the trajectory and a figure.

    \b
    Examples:
      pwsdyn simulate bouncing-ball --out run.nc --plot run.png
      pwsdyn simulate bouncing-ball -p A=0.05 -p omega=10 --x0 y=0.5 --x0 v=0 --t-end 5
    """
    import pwsdyn
    from .errors import ModelError, SolveError

    cli_params = _parse_params(params)
    cli_x0 = _parse_x0(x0)
    try:
        mdl = pwsdyn.load_model(model)
        defaults = _model_defaults(mdl)
    except ModelError as exc:
        _fail(exc)
    _check_params(mdl, cli_params)
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)

    try:
        x0_val, t0, t_end, all_params = _resolve_defaults(mdl, defaults, cli_x0, t0, t_end,
                                                          cli_params)
    except (TypeError, ValueError) as exc:
        _fail(f"model {mdl.name!r}: bad `defaults` table: {exc}")

    options = {}
    if rtol is not None:
        options["rtol"] = rtol
    if atol is not None:
        options["atol"] = atol
    if method is not None:
        options["method"] = method.upper()
    if mode is not None:
        options["mode"] = mode

    try:
        traj = pwsdyn.simulate(mdl, x0_val, (t0, t_end), params=all_params, throw=False,
                               **options)
    except (ModelError, SolveError, ValueError, TypeError) as exc:
        _fail(exc)

    _print_summary(traj)
    # a failed run is still written: its data and figure show where and why it stopped
    try:
        if out is not None:
            from .io import save_dataset

            save_dataset(traj.to_dataset(), out)
            click.echo(f"wrote       {out}")
        if plot is not None:
            from .plot import plot_trajectory

            plot_trajectory(traj, path=plot)
            click.echo(f"wrote       {plot}")
    except (OSError, ValueError) as exc:
        _fail(exc)
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
        f"final       t={_fmt(traj.t_final)}: {final} (in {traj.state[-1]})",
        f"status      {traj.status.name}: {traj.message}",
    ]
    click.echo("\n".join(lines))


def _fail(exc, code: int = 1):
    """Print ``Error: ...`` on one line (no traceback) and exit with ``code``."""
    text = " ".join(str(exc).split())
    click.echo(f"Error: {text}", err=True)
    raise SystemExit(code)


if __name__ == "__main__":  # pragma: no cover
    main()
