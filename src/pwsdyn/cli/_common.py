"""The options every model-running command shares, and the one preamble that reads them.

The commands that run a model (``simulate``, ``orbit``, ``sweep``, ``basins``, ``continue``,
``grazing``) take ``MODEL|FILE`` and, with the same names, types and meanings:

* ``-p/--param NAME=VALUE`` (``-s/--set`` hidden, the same), ``--x0``;
* ``--rtol``, ``--atol``, ``--method``, ``--sliding``: integrator options, passed on only when
  given, so that the library's defaults apply (those of :func:`pwsdyn.simulate`, or the
  tighter ones of shooting in ``orbit``, ``continue`` and ``grazing``: the help says why);
* ``--exact`` where the run is a simulation (``simulate``, ``sweep``, ``basins``): shooting
  integrates the variational equations, which the exact propagator does not carry;
* ``--out``, ``--plot``, ``--force``; ``--no-progress`` where there is a progress bar;
  ``--workers`` and ``--scheduler`` where the work is parallel.

:func:`prepare` is the preamble of them all: it parses the parameters and ``--x0``, checks
the output files before any work, loads the model and checks the names against it, and
collects the integrator options given. :func:`reported` turns the errors of the run into one
``Error:`` line.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Any

import click

from ._output import _FORCE_HELP, _check_outputs, _echo, _fail

#: End time used when neither ``--t-end`` nor the model's ``[defaults]`` give one (the
#: library's :data:`pwsdyn.model.spec.FALLBACK_T_END`; a test keeps them equal).
FALLBACK_T_END = 10.0


# ======================================================================================
# parsing: -p/--param, -s/--set, --x0
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


def _parse_params(values, hint: str = "--param") -> dict:
    """``--param NAME=VALUE`` options as a dict (names are checked against the model later);
    ``hint`` is the option named in errors."""
    out = {}
    for item in values:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise click.BadParameter(f"expected NAME=VALUE, got {item!r}", param_hint=hint)
        try:
            out[name] = _number(text.strip(), f"parameter {name!r}")
        except click.BadParameter as exc:
            exc.param_hint = hint
            raise
    return out


def _all_params(params, sets) -> tuple[dict, dict]:
    """The parameter values of ``-p/--param`` and of its synonym ``-s/--set``, parsed, and
    the option that set each name (for error messages). A name set by both to different
    values is an error."""
    a, b = _parse_params(params, "--param"), _parse_params(sets, "--set")
    clash = [k for k in a if k in b and a[k] != b[k]]
    if clash:
        raise click.BadParameter(f"parameter {clash[0]!r} is given different values by "
                                 f"--param and --set", param_hint="--param")
    hints = {**{k: "--set" for k in b}, **{k: "--param" for k in a}}
    return {**b, **a}, hints


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


def _check_params(model, params, hints=None):
    unknown = [k for k in params if k not in model.parameters]
    if unknown:
        raise click.BadParameter(f"unknown parameter(s) {unknown} for model {model.name!r}; "
                                 f"parameters are {list(model.parameters)}",
                                 param_hint=(hints or {}).get(unknown[0], "--param"))


def _run_defaults(model, x0, t0, t_end):
    """Command-line values first, then the model's ``[defaults]``, then zero / fallbacks: the
    library's rule (:func:`pwsdyn.model.spec.run_defaults`, the one :func:`pwsdyn.simulate`
    applies), with a note on stderr for each fallback. Parameters need nothing: the
    model's ``[defaults] params`` are in ``model.parameters`` for the API and the CLI
    alike."""
    from ..model.spec import run_defaults

    run = run_defaults(model, x0=x0, t0=t0, t_end=t_end)
    for note in run.note(model, {"x0": "--x0", "t_end": "--t-end"}):
        _echo(f"note: {note}", err=True)
    return run.x0, run.t0, run.t_end


def _method_name(method: str) -> str:
    """The library's spelling of a --method choice (case-insensitive on the command line)."""
    return "auto" if method.lower() == "auto" else method.upper()


# ======================================================================================
# the preamble
# ======================================================================================

@dataclass
class Prepared:
    """What the shared options of a command give, checked against the model."""

    #: The loaded model.
    model: Any
    #: Parameter values of ``-p/--param`` and ``-s/--set`` (the model's fill in the rest).
    params: dict
    #: The swept or continued parameter (``--param NAME`` without a value), else None.
    named: str | None
    #: ``--x0`` as given: values in state order, a dict by name, or None (the defaults').
    x0: Any
    #: The integrator options given (``rtol``, ``atol``, ``method``, ``exact``,
    #: ``sliding``): only those, so that the library's defaults apply to the rest.
    options: dict


#: How a ``--param NAME`` without a value is read: not at all (an error), as the swept
#: parameter of ``sweep`` (which also takes ``--sweep NAME``) or the continued one.
_NAMED = {None: None, "swept": "--sweep/--param", "continued": "--param",
          "varied": "--param"}


def prepare(model, params, sets, x0, *, outputs=(), force: bool = False,
            named: str | None = None, swept: str | None = None, **options) -> Prepared:
    """The preamble of every model-running command.

    ``params``, ``sets`` and ``x0`` are the values of ``-p/--param``, ``-s/--set`` and
    ``--x0``; ``outputs`` holds ``(option, path, kind)`` for :func:`_check_outputs`;
    ``named`` (``"swept"``, ``"continued"`` or ``"varied"``) lets one ``--param NAME`` name a
    parameter (``swept`` is ``sweep --sweep NAME``); ``options`` are the integrator options of the
    command (None: not given). Bad arguments are click errors (exit 2); a model that cannot
    be loaded, or an output file that cannot be written, is one ``Error:`` line (exit 1).
    """
    import pwsdyn
    from ..errors import ModelError

    hint = _NAMED[named]
    name = None
    if named is not None:
        names = list(dict.fromkeys(([swept] if swept is not None else [])
                                   + [v.strip() for v in params if "=" not in v]))
        if not names:
            if named == "swept":
                raise click.UsageError("Missing option '--sweep' (the swept parameter: "
                                       "--sweep NAME, or --param NAME)")
            raise click.UsageError(f"name the {named} parameter once: --param NAME")
        if len(names) > 1:
            raise click.BadParameter(f"one {named} parameter, got {names}", param_hint=hint)
        name = names[0]
        params = [v for v in params if "=" in v]
    cli_params, hints = _all_params(params, sets)
    cli_x0 = _parse_x0(x0)
    _check_outputs(force, outputs)
    try:
        mdl = pwsdyn.load_model(model)
    except ModelError as exc:
        _fail(exc)
    if name is not None and name not in mdl.parameters:
        raise click.BadParameter(f"unknown parameter {name!r} for model {mdl.name!r}; "
                                 f"parameters are {list(mdl.parameters)}", param_hint=hint)
    _check_params(mdl, cli_params, hints)
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)
    given = {}
    for key, val in options.items():
        if val is None:
            continue
        if key == "method":
            val = _method_name(val)
        elif key == "sliding":
            val = val.lower()
        given[key] = val
    return Prepared(mdl, cli_params, name, cli_x0, given)


@contextlib.contextmanager
def reported(orbit: str = "no periodic orbit"):
    """Errors of the run as one ``Error:`` line (exit 1): pwsdyn's own and the
    ``ValueError``, ``TypeError`` and ``OSError`` the library raises for values it refuses or
    files it cannot write. A failed Newton shooting says ``orbit`` (what was not found),
    its reason and, when there were iterations, their residuals."""
    from ..errors import PwsdynError

    try:
        yield
    except (PwsdynError, ValueError, TypeError, OSError) as exc:
        from ..orbits import OrbitError

        if isinstance(exc, OrbitError):
            if exc.history:
                _echo("newton residuals: " + " ".join(f"{r:.2e}" for r in exc.history),
                      err=True)
            _fail(f"{orbit} ({exc.reason}): {exc}")
        _fail(exc)


# ======================================================================================
# the shared options: one name, one type, one meaning
# ======================================================================================

def _stack(*decorators):
    """One decorator applying ``decorators`` so that the options appear in their order."""
    def deco(fn):
        for d in reversed(decorators):
            fn = d(fn)
        return fn
    return deco


def model_argument(fn):
    return click.argument("model", metavar="MODEL|FILE")(fn)


_PARAM_HELP = "Set a parameter: NAME=VALUE (repeatable), over the model's defaults."
_NAMED_HELP = {
    None: "",
    "swept": " A NAME without =VALUE names the swept parameter instead (the same as "
             "--sweep NAME).",
    "continued": " A NAME without =VALUE names the continued parameter (required, once).",
    "varied": " A NAME without =VALUE names the varied parameter (required, once).",
}


def param_options(named: str | None = None):
    """``-p/--param NAME=VALUE`` and its hidden synonym ``-s/--set NAME=VALUE`` (the
    spelling ``sweep`` and ``basins`` used first); ``named`` as in :func:`prepare`."""
    return _stack(
        click.option("--param", "-p", "params", multiple=True, metavar="NAME=VALUE",
                     help=_PARAM_HELP + _NAMED_HELP[named]
                     + " -s/--set NAME=VALUE is the same as --param NAME=VALUE."),
        click.option("--set", "-s", "sets", multiple=True, metavar="NAME=VALUE", hidden=True,
                     help="The same as -p/--param NAME=VALUE."))


def x0_option(help_text: str):
    return click.option("--x0", "x0", multiple=True, metavar="VALUES", help=help_text)


#: Why shooting (``orbit``, ``continue``, ``grazing``) has its own integrator defaults, the
#: library's :data:`pwsdyn.orbits._base.SHOOTING_DEFAULTS`.
_SHOOTING_WHY = ("tighter than a simulation's 1e-10: Newton's method on the shooting "
                 "residual and the Floquet multipliers need the flow and its derivatives to "
                 "more digits")


def tolerance_options(shooting: bool = False):
    """``--rtol`` and ``--atol``: None (not given) stands for the library's default, which
    the help names (tests/test_defaults.py checks it)."""
    rtol = (f"Relative tolerance (default 1e-12, {_SHOOTING_WHY})." if shooting else
            "Relative tolerance (default 1e-10).")
    atol = ("Absolute tolerance (default 1e-12, as in a simulation)." if shooting else
            "Absolute tolerance (default 1e-12).")
    return _stack(click.option("--rtol", type=float, default=None, help=rtol),
                  click.option("--atol", type=float, default=None, help=atol))


def method_option(shooting: bool = False):
    text = ("Runge-Kutta pair (default DOP853, the 8th-order pair, whatever --rtol: shooting "
            "needs accurate derivatives of the flow, where auto, a simulation's default, "
            "takes RK45 from rtol 1e-7 on)." if shooting else
            "Runge-Kutta pair (default auto: DOP853 below rtol 1e-7, RK45 from there on).")
    return click.option("--method", type=click.Choice(["auto", "RK45", "DOP853"],
                                                      case_sensitive=False),
                        default=None, help=text)


exact_option = click.option(
    "--exact/--no-exact", default=None,
    help="Propagate the modes that are affine in the state with harmonic forcing exactly "
         "(matrix exponential), or integrate every mode with the Runge-Kutta pair; unset: "
         "exactly wherever a mode allows it (default auto).")


def sliding_option(help_text: str = ""):
    return click.option(
        "--sliding", type=click.Choice(["convex", "utkin"], case_sensitive=False),
        default=None, help="Sliding vector field on Filippov surfaces: Filippov's convex "
                           "combination or Utkin's equivalent control (default convex)."
                           + help_text)


def output_options(out_help: str, plot_help: str):
    """``--out`` (NetCDF), ``--plot`` (a figure) and ``--force``."""
    return _stack(
        click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
                     help=out_help),
        click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
                     help=plot_help),
        click.option("--force", is_flag=True, default=False, help=_FORCE_HELP))


progress_option = click.option("--no-progress", "no_progress", is_flag=True, default=False,
                               help="No progress bar.")


parallel_options = _stack(
    click.option("--workers", type=int, default=None,
                 help="Threads (default: one per core; 1: one after the other), or worker "
                      "processes with --scheduler processes."),
    click.option("--scheduler", default=None, metavar="ADDRESS",
                 help="'processes' for a local Dask cluster of worker processes, or the "
                      "address of a Dask scheduler to run on (default: threads here)."))
