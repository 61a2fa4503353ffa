"""The ``pwsdyn`` command line.

``pwsdyn models`` lists the built-in models; ``pwsdyn simulate MODEL`` simulates a built-in
model or a model file and writes the trajectory (NetCDF) and a figure (PNG); ``pwsdyn sweep``
and ``pwsdyn basins`` compute bifurcation diagrams and basins of attraction (parallel on
threads or Dask, resumable) and write their datasets and figures; ``pwsdyn orbit MODEL``
finds a periodic orbit by Newton shooting and prints its period, signature and Floquet
multipliers.

One name for one thing in every command:

* ``-p/--param NAME=VALUE`` sets a parameter (repeatable) in ``simulate``, ``orbit``, ``sweep``
  and ``basins``; ``-s/--set NAME=VALUE`` is a synonym (hidden; ``sweep`` and ``basins`` used
  it first). In ``sweep`` the swept parameter is ``--sweep NAME``; ``--param NAME`` without
  ``=VALUE`` still names it (the spelling before ``--sweep``): an argument with ``=`` sets a
  value, one without names the swept parameter.
* ``--x0``, ``--rtol``, ``--atol``, ``--method``, ``--sliding``, ``--out``, ``--plot`` and
  ``--force`` mean the same wherever they appear (``--exact`` in the commands that integrate
  affine modes exactly: simulate, sweep, basins).

Defaults are the library's: a model's ``[defaults]`` table (``params``, ``x0``, ``t0``,
``t_end``) is applied by :func:`pwsdyn.simulate`, :func:`pwsdyn.sweep`, :func:`pwsdyn.basins`,
:func:`pwsdyn.lyapunov_spectrum` and :func:`pwsdyn.find_periodic_orbit` exactly as here
(:func:`pwsdyn.model.spec.run_defaults`; the parameters through ``model.parameters``), and the
option defaults equal the API's (``sweep --direction both`` as ``pwsdyn.sweep(direction=
"both")``, ``--transient``, ``--samples``, tolerances, methods; tests/test_defaults.py keeps
them equal).

Every file a command writes is listed on stdout (``wrote PATH``; a kept ``--store`` as
``store PATH``), the second figure ``<plot>-lyapunov.<ext>`` of ``sweep --lyapunov --plot``
included.

Errors in the arguments or the model, and failed simulations, are reported as one line
``Error: ...`` without a traceback: exit code 2 for a bad argument (click's convention for
usage errors), 1 for a model that cannot be loaded or a simulation that fails. Every error of
pwsdyn's own (:class:`pwsdyn.PwsdynError`) is reported that way (exit code 1); any other
exception is a bug and shows its traceback.

Output files (``--out``, ``--plot`` and the second figure ``<plot>-lyapunov.<ext>`` of
``sweep --lyapunov --plot``) are checked before any work starts: the directory must exist
and be writable, the suffix must be one the writer knows (NetCDF: ``.nc`` ...; figures: the
formats matplotlib writes, e.g. ``.png``, ``.pdf``, ``.svg``) and an existing file is never
replaced unless ``--force`` is given (exit code 2 for a wrong suffix, 1 for the others). The
data are written before the figure; if the figure still cannot be written at the end and no
``--out`` was given, the data are saved next to it as ``<plot stem>.nc`` (``-1``, ``-2``...
if that exists) and the error message says where. A sweep store (``--store``) is a resumable
directory: it is resumed, never replaced.

Text that comes from a model or a file (names, descriptions, messages) is printed through one
sanitiser, :func:`_safe`: control characters (C0, C1, ESC, DEL) and Unicode bidirectional
controls are shown as escapes (``\\x1b``, ``\\u202e``), so a model cannot drive the terminal.
"""

from __future__ import annotations

import math
import re
import textwrap
import warnings
from pathlib import Path

import click

#: End time used when neither ``--t-end`` nor the model's ``[defaults]`` give one (the
#: library's :data:`pwsdyn.model.spec.FALLBACK_T_END`; a test keeps them equal).
FALLBACK_T_END = 10.0


# ======================================================================================
# terminal output: model-provided text is never printed raw
# ======================================================================================

#: Characters printed as escapes: C0 and C1 controls (ESC starts terminal escape sequences),
#: DEL, the Unicode bidirectional controls (U+202E reverses what follows), line and paragraph
#: separators, and lone surrogates (which cannot be encoded at all).
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e"
                     "\u2066-\u2069\ud800-\udfff]")
_NAMED_ESCAPES = {"\t": "\\t", "\n": "\\n", "\r": "\\r"}


def _escape(match) -> str:
    ch = match.group()
    if ch in _NAMED_ESCAPES:
        return _NAMED_ESCAPES[ch]
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def _safe(text) -> str:
    """``text`` with every control character shown as a visible escape (``\\x1b``,
    ``\\u202e``, ``\\n``): the one sanitiser for text from models and files."""
    return _UNSAFE.sub(_escape, str(text))


def _oneline(text) -> str:
    """``text`` on one line (runs of blanks and line breaks become one space), sanitised."""
    return _safe(" ".join(re.split(r"[ \t\r\n]+", str(text).strip())))


def _echo(text="", err: bool = False):
    """``click.echo`` for text that may hold model-provided strings: each line sanitised."""
    click.echo("\n".join(_safe(line) for line in str(text).split("\n")), err=err)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    # warnings raised during a command may quote a model or a file: one sanitised line
    _echo(f"warning: {_oneline(message)}", err=True)


class _Group(click.Group):
    """The command group: every pwsdyn error is one clean ``Error:`` line, click's own
    messages and warnings are sanitised (they may quote model-provided names)."""

    def invoke(self, ctx):
        from .errors import PwsdynError

        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            try:
                return super().invoke(ctx)
            except click.ClickException as exc:
                exc.message = _safe(exc.message)
                raise
            except PwsdynError as exc:
                _fail(exc)


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
    from .model.spec import run_defaults

    run = run_defaults(model, x0=x0, t0=t0, t_end=t_end)
    for note in run.note(model, {"x0": "--x0", "t_end": "--t-end"}):
        _echo(f"note: {note}", err=True)
    return run.x0, run.t0, run.t_end


def _fmt(v: float) -> str:
    return f"{v:.10g}"


# ======================================================================================
# output files: checked before the work, never replaced without --force, data first
# ======================================================================================

#: Suffixes accepted for the NetCDF files of --out.
NETCDF_SUFFIXES = (".nc", ".nc4", ".netcdf", ".cdf", ".h5", ".hdf5")

_FORCE_HELP = "Replace existing output files (default: refuse to overwrite them)."


def _check_outputs(force: bool, outputs) -> None:
    """Check every output file before any work: ``outputs`` holds ``(option, path, kind)``
    with kind ``"data"`` (NetCDF) or ``"figure"``; ``None`` paths are skipped.

    A suffix the writer does not know is a bad argument (exit 2); a missing or unwritable
    directory, or an existing file without ``--force``, exits with 1. (The files cannot
    collide: data and figure suffixes differ, and the Lyapunov figure has its own stem.)
    """
    outputs = [o for o in outputs if o[1] is not None]
    if not outputs:     # nothing to check: xarray and matplotlib are not imported
        return
    from ._netcdf import _check_output_path

    for option, path, kind in outputs:
        p = Path(path)
        suffix = p.suffix.lower()
        hint = option.split()[0]
        if kind == "data":
            if suffix not in NETCDF_SUFFIXES:
                raise click.BadParameter(
                    f"{str(path)!r}: the data are written as NetCDF; give a file name ending "
                    f"in {', '.join(NETCDF_SUFFIXES)}", param_hint=hint)
        else:
            from .plot import figure_formats

            formats = figure_formats()
            if (suffix[1:] or "png") not in formats:
                raise click.BadParameter(
                    f"{str(path)!r}: unknown figure format {p.suffix!r}; supported formats: "
                    f"{', '.join('.' + f for f in formats)}", param_hint=hint)
        try:
            _check_output_path(p, overwrite=force, hint="pass --force to replace it")
        except OSError as exc:
            _fail(f"{option}: {exc}")


def _lyapunov_path(plot):
    """The second figure of ``sweep --lyapunov --plot P``: ``<stem>-lyapunov<suffix>``."""
    p = Path(plot)
    return p.with_name(p.stem + "-lyapunov" + p.suffix)


def _save_data(dataset, out, force: bool) -> None:
    """Write --out (``dataset`` is an xarray Dataset) or exit with one error line."""
    from .io import save_dataset

    try:
        save_dataset(dataset, out, overwrite=force)
    except (OSError, ValueError, TypeError) as exc:
        _fail(exc)
    _echo(f"wrote       {out}")


def _rescue_data(dataset, plot):
    """Save the data of a figure that could not be written next to it: ``<stem>.nc`` (then
    ``<stem>-1.nc``... if taken), else in the current directory. Returns ``(path, None)`` or
    ``(None, the last error)``; never replaces a file."""
    from .errors import OutputExistsError
    from .io import save_dataset

    try:
        ds = dataset()
    except Exception as exc:  # the data could not even be assembled: say so
        return None, exc
    p = Path(plot)
    err = None
    for directory in dict.fromkeys([p.parent, Path(".")]):
        for k in range(10):
            cand = directory / (f"{p.stem}.nc" if k == 0 else f"{p.stem}-{k}.nc")
            try:
                return save_dataset(ds, cand, overwrite=False), None
            except OutputExistsError:
                continue
            except Exception as exc:  # this directory cannot take it: try the next one
                err = exc
                break
    return None, err


def _write_figures(figures, out, dataset):
    """Draw and write the figures of --plot, after the data: ``figures`` holds
    ``(path, draw)`` pairs, ``draw()`` writes ``path``.

    If that fails, the data are not lost: they are in --out when it was given, else they are
    saved next to the (first) figure as ``<stem>.nc`` (:func:`_rescue_data`). Returns
    ``None`` or the error message (which says where the data are); an unexpected exception
    (a bug) is raised after that message is printed.
    """
    from .errors import PwsdynError

    plot = first = figures[0][0]
    try:
        for plot, draw in figures:
            draw()
            _echo(f"wrote       {plot}")
        return None
    except Exception as exc:
        msg = f"could not write the figure {str(plot)!r}: {exc}"
        if out is not None:
            msg += f"; the data are in {str(out)!r}"
        else:
            saved, err = _rescue_data(dataset, first)
            msg += (f"; the data were saved to {str(saved)!r} instead" if saved is not None
                    else f"; the data could not be saved either ({err})")
        if isinstance(exc, (OSError, ValueError, TypeError, PwsdynError)):
            return msg
        click.echo(f"Error: {_oneline(msg)}", err=True)
        raise


# ======================================================================================
# options shared by the commands: one name for one thing
# ======================================================================================

_PARAM_HELP = ("Set a parameter: NAME=VALUE (repeatable), over the model's defaults. "
               "-s/--set NAME=VALUE is the same.")


def _param_options(fn, help_text: str = _PARAM_HELP):
    """``-p/--param NAME=VALUE`` and its synonym ``-s/--set NAME=VALUE`` (hidden; the
    spelling ``sweep`` and ``basins`` used first), in every command that runs a model."""
    fn = click.option("--set", "-s", "sets", multiple=True, metavar="NAME=VALUE", hidden=True,
                      help="The same as -p/--param NAME=VALUE.")(fn)
    return click.option("--param", "-p", "params", multiple=True, metavar="NAME=VALUE",
                        help=help_text)(fn)


_SWEEP_PARAM_HELP = ("Set a parameter: NAME=VALUE (repeatable), over the model's defaults. "
                     "A NAME without =VALUE names the swept parameter instead (the same as "
                     "--sweep NAME). -s/--set NAME=VALUE is the same as --param NAME=VALUE.")


def _sweep_param_options(fn):
    return _param_options(fn, _SWEEP_PARAM_HELP)


def _sliding_option(fn):
    return click.option(
        "--sliding", type=click.Choice(["convex", "utkin"], case_sensitive=False),
        default=None, help="Sliding vector field on Filippov surfaces: Filippov's convex "
                           "combination (default) or Utkin's equivalent control.")(fn)


def _method_name(method: str) -> str:
    """The library's spelling of a --method choice (case-insensitive on the command line)."""
    return "auto" if method.lower() == "auto" else method.upper()


def _method_option(default: str, fn=None):
    def deco(f):
        return click.option("--method", type=click.Choice(["auto", "RK45", "DOP853"],
                                                          case_sensitive=False),
                            default=None, help=f"Runge-Kutta pair (default {default}).")(f)
    return deco if fn is None else deco(fn)


# ======================================================================================
# commands
# ======================================================================================

@click.group(cls=_Group, invoke_without_command=True,
             context_settings={"help_option_names": ["-h", "--help"]})
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
            _echo(f"{name}\n  failed to load: {_oneline(exc)}\n", err=True)
            failed += 1
            continue
        desc = model.description.strip().splitlines()[0] if model.description.strip() else ""
        # a listing, not the documentation: one line per model
        desc = textwrap.shorten(desc, width=90, placeholder=" ...")
        # sanitised before styling: the bold escape sequence is ours, nothing in it is the model's
        click.echo(click.style(_safe(model.name), bold=True)
                   + (f"  {_safe(desc)}" if desc else ""))
        _echo(f"  states:     {', '.join(model.states)}")
        params = ", ".join(f"{k}={_fmt(v)}" for k, v in model.parameters.items())
        _echo(f"  parameters: {params or '(none)'}")
        modes = ", ".join(model.mode_names)
        _echo(f"  modes:      {modes}")
        _echo("")
    if failed:
        raise SystemExit(1)


@main.command("simulate")
@click.argument("model", metavar="MODEL|FILE")
@_param_options
@click.option("--x0", "x0", multiple=True, metavar="VALUES",
              help="Initial state: comma-separated values in state order (--x0 1,0) or "
                   "NAME=VALUE pairs (--x0 y=1 --x0 v=0). Default: the model's [defaults].")
@click.option("--t0", type=float, default=None,
              help="Start time (default: the model's [defaults], else 0).")
@click.option("--t-end", "t_end", type=float, default=None,
              help=f"End time (default: the model's [defaults], else t0 + "
                   f"{FALLBACK_T_END:g}).")
@click.option("--rtol", type=float, default=None, help="Relative tolerance (default 1e-10).")
@click.option("--atol", type=float, default=None, help="Absolute tolerance (default 1e-12).")
@_method_option("auto")
@click.option("--exact/--no-exact", default=None,
              help="Propagate the modes that are affine in the state with harmonic forcing "
                   "exactly (matrix exponential), or integrate every mode with the Runge-Kutta "
                   "pair; unset: exactly wherever a mode allows it (default auto).")
@click.option("--mode", default=None, metavar="NAME", help="Initial mode.")
@_sliding_option
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write the trajectory to this NetCDF file (.nc).")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write a figure of the trajectory to this file (PNG; PDF, SVG... by "
                   "suffix).")
@click.option("--force", is_flag=True, default=False, help=_FORCE_HELP)
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
    from .errors import ModelError, SolveError

    cli_params, hints = _all_params(params, sets)
    cli_x0 = _parse_x0(x0)
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
    try:
        mdl = pwsdyn.load_model(model)
    except ModelError as exc:
        _fail(exc)
    _check_params(mdl, cli_params, hints)
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)
    x0_val, t0, t_end = _run_defaults(mdl, cli_x0, t0, t_end)

    options = {}
    if rtol is not None:
        options["rtol"] = rtol
    if atol is not None:
        options["atol"] = atol
    if method is not None:
        options["method"] = _method_name(method)
    if exact is not None:
        options["exact"] = exact
    if mode is not None:
        options["mode"] = mode
    if sliding is not None:
        options["sliding"] = sliding.lower()

    try:
        traj = pwsdyn.simulate(mdl, x0_val, (t0, t_end), params=cli_params, throw=False,
                               **options)
    except (ModelError, SolveError, ValueError, TypeError) as exc:
        _fail(exc)

    _print_summary(traj)
    # a failed run is still written: its data and figure show where and why it stopped
    if out is not None:
        _save_data(traj.to_dataset(), out, force)
    if plot is not None:
        from .plot import plot_trajectory

        problem = _write_figures(
            [(plot, lambda: plot_trajectory(traj, path=plot, overwrite=force))], out,
            traj.to_dataset)
        if problem is not None:
            if not traj.status.failed:
                _fail(problem)
            _echo(f"Error: {_oneline(problem)}", err=True)
    if traj.status.failed:
        _fail(f"the simulation stopped early ({traj.status.name}) at t={traj.t_final:.17g} in "
              f"{traj.state[-1]}: {traj.message}")


def _explore_common(model, params, sets, x0, method, rtol, atol, exact=None, sliding=None,
                    swept=None):
    """Load MODEL, check ``-p/--param`` (``-s/--set``) and ``--x0`` and collect integrator
    options. ``swept`` (sweep) is the swept parameter: it must be one of the model's, and
    a value given for it is left out (the sweep sets it)."""
    import pwsdyn
    from .errors import ModelError

    cli_params, hints = _all_params(params, sets)
    cli_x0 = _parse_x0(x0)
    try:
        mdl = pwsdyn.load_model(model)
    except ModelError as exc:
        _fail(exc)
    if swept is not None and swept not in mdl.parameters:
        raise click.BadParameter(f"unknown parameter {swept!r} for model {mdl.name!r}; "
                                 f"parameters are {list(mdl.parameters)}",
                                 param_hint="--sweep/--param")
    _check_params(mdl, cli_params, hints)
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)
    cli_params.pop(swept, None)
    options = {}
    for k, v in (("rtol", rtol), ("atol", atol), ("method", _method_name(method) if method else None),
                 ("sliding", sliding.lower() if sliding else None)):
        if v is not None:
            options[k] = v
    if exact is not None:
        options["exact"] = exact
    # parameters and x0 not given here: the model's defaults, applied by pwsdyn.sweep/basins
    return mdl, cli_params, cli_x0, options


def _run_store(out, store):
    """The store directory: ``--store``, else ``<out>.store`` (removed after success)."""
    from pathlib import Path

    if store is not None:
        return Path(store), False
    if out is not None:
        return Path(str(out) + ".store"), True
    return None, False


_EXPLORE_OPTIONS = [
    click.option("--x0", "x0", multiple=True, metavar="VALUES",
                 help="Initial state (as for `simulate`); default: the model's [defaults]."),
    click.option("--transient", type=int, default=200, show_default=True,
                 help="Forcing periods (maps: iterations) discarded."),
    click.option("--section", default="stroboscopic", show_default=True,
                 help="'stroboscopic' or the name of an event (e.g. impact)."),
    click.option("--workers", type=int, default=None,
                 help="Threads (default: one per core; 1: one after the other), or worker "
                      "processes with --scheduler processes."),
    click.option("--scheduler", default=None, metavar="ADDRESS",
                 help="'processes' for a local Dask cluster of worker processes, or the "
                      "address of a Dask scheduler to run on (default: threads here)."),
    click.option("--chunk-size", "chunk_size", type=int, default=None,
                 help="Values (basins: grid rows) per chunk (default: 1/16 of them)."),
    click.option("--store", default=None, type=click.Path(file_okay=False),
                 help="Resumable store directory (default: OUT.store, removed when done)."),
    click.option("--rtol", type=float, default=None,
                 help="Relative tolerance (default 1e-10)."),
    click.option("--atol", type=float, default=None,
                 help="Absolute tolerance (default 1e-12)."),
    _method_option("auto"),
    click.option("--exact/--no-exact", default=None,
                 help="Propagate the modes that are affine in the state with harmonic forcing "
                      "exactly (matrix exponential), or integrate every mode with the "
                      "Runge-Kutta pair; unset: exactly wherever a mode allows it (default auto)."),
    _sliding_option,
    click.option("--no-progress", "no_progress", is_flag=True, default=False,
                 help="No progress bar."),
    click.option("--out", type=click.Path(dir_okay=False), default=None,
                 help="Write the dataset to this NetCDF file (.nc)."),
    click.option("--plot", type=click.Path(dir_okay=False), default=None,
                 help="Write the figure to this file (PNG; PDF, SVG... by suffix)."),
    click.option("--force", is_flag=True, default=False, help=_FORCE_HELP),
]


def _explore_options(fn):
    for opt in reversed(_EXPLORE_OPTIONS):
        fn = opt(fn)
    return fn


def _finish_explore(ds, out, store_path, remove_store, figures, force):
    """Write --out (then remove the default store), then the ``figures`` (see
    :func:`_write_figures`); every file or directory left behind is listed."""
    import shutil

    from .io import save_dataset

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


def _explore_errors():
    from .errors import ModelError, SolveError
    from .explore import StoreMismatchError

    return (ModelError, SolveError, StoreMismatchError, ValueError, TypeError,
            FileExistsError, OSError)


@main.command("sweep")
@click.argument("model", metavar="MODEL|FILE")
@click.option("--sweep", "swept", default=None, metavar="NAME", help="Parameter swept.")
@_sweep_param_options
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
@_explore_options
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

    # --sweep NAME, or the older spelling --param NAME (a --param without "=VALUE")
    named = list(dict.fromkeys(([swept] if swept is not None else [])
                               + [v.strip() for v in params if "=" not in v]))
    if not named:
        raise click.UsageError("Missing option '--sweep' (the swept parameter: --sweep NAME, "
                               "or --param NAME)")
    if len(named) > 1:
        raise click.BadParameter(f"one swept parameter, got {named}",
                                 param_hint="--sweep/--param")
    param = named[0]
    params = [v for v in params if "=" in v]
    if num < 1:
        raise click.BadParameter(f"must be at least 1, got {num}", param_hint="--num")
    lyap_plot = _lyapunov_path(plot) if plot is not None and lyapunov else None
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure"),
                           ("--plot (its Lyapunov figure)", lyap_plot, "figure")])
    mdl, params, x0v, options = _explore_common(model, params, sets, x0, method, rtol, atol,
                                                exact, sliding, swept=param)
    store_path, remove_store = _run_store(out, store)
    values = np.linspace(start, stop, num) if num > 1 else np.array([start])
    try:
        ds = pwsdyn.sweep(mdl, param, values, x0v, params=params, transient=transient,
                          samples=samples, section=section,
                          direction=direction, lyapunov=lyapunov, workers=workers,
                          scheduler=scheduler, chunk_size=chunk_size, store=store_path,
                          out=None, progress=not no_progress, **options)
    except _explore_errors() as exc:
        _fail(exc)
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
        from .plot import plot_bifurcation, plot_lyapunov

        figures.append((plot, lambda: plot_bifurcation(ds, state=state, path=plot,
                                                       overwrite=force)))
    if lyap_plot is not None:
        figures.append((lyap_plot, lambda: plot_lyapunov(ds, path=lyap_plot, overwrite=force)))
    # the data go to --out here, not in pwsdyn.sweep: --force applies and the figure follows
    _finish_explore(ds, out, store_path, remove_store, figures, force)


@main.command("basins")
@click.argument("model", metavar="MODEL|FILE")
@_param_options
@click.option("--x", "xname", required=True, metavar="STATE", help="State on the first axis.")
@click.option("--x-from", "x_from", type=float, required=True)
@click.option("--x-to", "x_to", type=float, required=True)
@click.option("--x-num", "x_num", type=int, required=True)
@click.option("--y", "yname", default=None, metavar="STATE",
              help="State on the second axis (flows: required; 1-D maps: omit).")
@click.option("--y-from", "y_from", type=float, default=None)
@click.option("--y-to", "y_to", type=float, default=None)
@click.option("--y-num", "y_num", type=int, default=None)
@click.option("--samples", type=int, default=32, show_default=True,
              help="Forcing periods (maps: iterations) recorded from each start.")
@_explore_options
def basins_cmd(model, params, sets, xname, x_from, x_to, x_num, yname, y_from, y_to, y_num,
               samples, x0, transient, section, workers, scheduler, chunk_size, store, rtol,
               atol, method, exact, sliding, no_progress, out, plot, force):
    """Basins of attraction of MODEL on a grid of initial conditions.

    \b
    Example:
      pwsdyn basins bouncing-ball --x y --x-from 0.1 --x-to 2 --x-num 100 \\
          --y v --y-from -4 --y-to 4 --y-num 100 -p A=0.2236 -p omega=6.2832 \\
          --out basins.nc --plot basins.png
    """
    import numpy as np

    import pwsdyn

    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
    mdl, params, x0v, options = _explore_common(model, params, sets, x0, method, rtol, atol,
                                                exact, sliding)
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
    try:
        ds = pwsdyn.basins(mdl, grid, x0v, params=params, transient=transient,
                           samples=samples, section=section,
                           workers=workers, scheduler=scheduler, chunk_size=chunk_size,
                           store=store_path, out=None, progress=not no_progress, **options)
    except _explore_errors() as exc:
        _fail(exc)
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
        from .plot import plot_basins

        figures.append((plot, lambda: plot_basins(ds, path=plot, overwrite=force)))
    _finish_explore(ds, out, store_path, remove_store, figures, force)


@main.command("orbit")
@click.argument("model", metavar="MODEL|FILE")
@_param_options
@click.option("--x0", "x0", multiple=True, metavar="VALUES",
              help="Guess of the state at t0: values in state order (--x0 1,0) or NAME=VALUE "
                   "pairs. Default: the model's [defaults] x0.")
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
@click.option("--transient", type=float, default=None,
              help="Simulate this long from x0 first and take the guess from the end of the "
                   "run (default: the model's defaults.t_end when no --x0 is given or the "
                   "model is autonomous without --period; else none: --x0 is the guess).")
@click.option("--mode", default=None, metavar="STATE",
              help="Discrete state at t0: a mode, stick:<event> or slide:<switch>.")
@click.option("--nodes", default="auto", show_default=True,
              help="Shooting nodes: 'auto' (one per smooth segment) or a number (1: single "
                   "shooting).")
@click.option("--tol", type=float, default=1e-10, show_default=True,
              help="Newton tolerance on the shooting residual (relative).")
@click.option("--rtol", type=float, default=None, help="Relative tolerance (default 1e-12).")
@click.option("--atol", type=float, default=None, help="Absolute tolerance (default 1e-12).")
@_method_option("DOP853")
@_sliding_option
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write one period with its monodromy and multipliers to this NetCDF file.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write a figure of the orbit with its events and multipliers (PNG; PDF, "
                   "SVG... by suffix).")
@click.option("--force", is_flag=True, default=False, help=_FORCE_HELP)
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
    import pwsdyn
    from .errors import ModelError, SolveError
    from .orbits import OrbitError, PeriodicOrbit, find_periodic_orbit

    cli_params, hints = _all_params(params, sets)
    cli_x0 = _parse_x0(x0)
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
    try:
        mdl = pwsdyn.load_model(model)
    except ModelError as exc:
        _fail(exc)
    _check_params(mdl, cli_params, hints)
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)
    if periods is not None and periods < 1:
        raise click.BadParameter("must be a positive integer", param_hint="--periods")
    if nodes != "auto":
        try:
            nodes = int(nodes)
        except ValueError:
            raise click.BadParameter(f"'auto' or a positive integer, got {nodes!r}",
                                     param_hint="--nodes") from None
    x0_val, t0, t_end = _run_defaults(mdl, cli_x0, t0, None)
    all_params = cli_params
    options = {"tol": tol, "nodes": nodes}
    for key, val in (("rtol", rtol), ("atol", atol),
                     ("method", _method_name(method) if method else None),
                     ("sliding", sliding.lower() if sliding else None)):
        if val is not None:
            options[key] = val
    autonomous = mdl.forcing_period is None
    # without a guess from the user, settle on the attractor first (the model's typical run)
    if transient is None and period is None and (autonomous or not cli_x0):
        transient = t_end - t0
    try:
        if transient:
            sim_opts = {k: options[k] for k in ("rtol", "atol", "method", "sliding")
                        if k in options}
            traj = pwsdyn.simulate(mdl, x0_val, (t0, t0 + transient), params=all_params,
                                   mode=mode, **sim_opts)
            orbit = PeriodicOrbit.from_trajectory(traj, period=period, periods=periods,
                                                  **options)
        else:
            orbit = find_periodic_orbit(mdl, x0_val, params=all_params, period=period, t0=t0,
                                        periods=periods or 1, mode=mode, **options)
    except OrbitError as exc:
        if exc.history:
            _echo("newton residuals: " + " ".join(f"{r:.2e}" for r in exc.history),
                       err=True)
        _fail(f"no periodic orbit ({exc.reason}): {exc}")
    except (ModelError, SolveError, ValueError, TypeError) as exc:
        _fail(exc)
    _echo(orbit.summary())
    if out is not None:
        try:
            data = orbit.to_dataset()
        except (ValueError, TypeError) as exc:
            _fail(exc)
        _save_data(data, out, force)
    if plot is not None:
        from .plot import plot_orbit

        problem = _write_figures([(plot, lambda: plot_orbit(orbit, path=plot, overwrite=force))],
                                 out, orbit.to_dataset)
        if problem is not None:
            _fail(problem)


@main.command("continue")
@click.argument("model", metavar="MODEL|FILE")
@_sweep_param_options
@click.option("--from", "start", type=float, required=True,
              help="Parameter value where the branch starts (the starting orbit is found "
                   "there).")
@click.option("--to", "stop", type=float, required=True,
              help="Parameter value towards which the branch is followed (it may turn back at "
                   "folds; it ends on the boundary of [--from, --to] or after --max-points).")
@click.option("--x0", "x0", multiple=True, metavar="VALUES",
              help="Guess of the starting orbit's state at t0 (or of the equilibrium): values "
                   "in state order or NAME=VALUE pairs. Default: settle from the model's "
                   "[defaults] x0 first, then shoot.")
@click.option("--t0", type=float, default=None, help="Time of x0 (default the model's).")
@click.option("--periods", type=int, default=None,
              help="Forced models: the starting orbit's period in forcing periods (default: "
                   "from the recurrence of a transient run, else 1).")
@click.option("--period", type=float, default=None,
              help="Autonomous models: a guess of the period.")
@click.option("--transient", type=float, default=None,
              help="Simulate this long before shooting (default: the model's t_end without "
                   "--x0).")
@click.option("--equilibrium", is_flag=True, default=False,
              help="Continue an equilibrium of the initial mode instead of a periodic orbit.")
@click.option("--ds", type=float, default=None,
              help="First step in arclength (default min(0.02, abs(to - from) / 100)).")
@click.option("--max-points", "max_points", type=int, default=200, show_default=True,
              help="Most points on the branch.")
@click.option("--rtol", type=float, default=None, help="Relative tolerance (default 1e-12).")
@click.option("--atol", type=float, default=None, help="Absolute tolerance (default 1e-12).")
@_method_option("DOP853")
@click.option("--no-progress", "no_progress", is_flag=True, default=False,
              help="No progress bar.")
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write the branch to this NetCDF file.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write the bifurcation diagram (stable solid, unstable dashed, not "
                   "admissible dotted, special points labelled).")
@click.option("--state", default=None, help="State plotted (default: the one that varies most).")
@click.option("--on-dib", "on_dib", type=click.Choice(["switch", "stop", "continue"]),
              default="switch", show_default=True,
              help="At a graze: go on with the orbit's new event sequence, stop there, or keep "
                   "the old one (its points past the graze are not admissible).")
@click.option("--force", is_flag=True, default=False, help=_FORCE_HELP)
def continue_cmd(model, params, sets, start, stop, x0, t0, periods, period, transient,
                 equilibrium, ds, max_points, rtol, atol, method, no_progress, out, plot, state,
                 on_dib, force):
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
    from .errors import PwsdynError
    from .orbits import OrbitError

    if max_points < 2:
        raise click.BadParameter(f"must be at least 2, got {max_points}",
                                 param_hint="--max-points")
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
    mdl, param, all_params, cli_x0, x0_val, t0, t_end, span = _branch_setup(
        model, params, sets, start, stop, x0, t0)
    step = ds if ds is not None else min(0.02, abs(stop - start) / 100.0)
    step = abs(step) if stop > start else -abs(step)
    options = {}
    for key, val in (("rtol", rtol), ("atol", atol),
                     ("method", _method_name(method) if method else None)):
        if val is not None:
            options[key] = val
    try:
        if equilibrium:
            branch = pwsdyn.continue_equilibrium(mdl, x0_val, param, span=span, ds=step,
                                                 max_points=max_points, params=all_params,
                                                 progress=not no_progress)
        else:
            orbit = _start_orbit(mdl, x0_val, t0, t_end, all_params, cli_x0, transient, period,
                                 periods, options)
            _echo(f"start       orbit of period {_fmt(orbit.period)} at {param} = "
                  f"{_fmt(start)}, {orbit.signature}, "
                  f"{'stable' if orbit.stable else 'unstable'}")
            branch = pwsdyn.continue_orbit(mdl, orbit, param, span=span, ds=step,
                                           max_points=max_points, progress=not no_progress,
                                           on_dib=on_dib, **options)
    except OrbitError as exc:
        _fail(f"no starting orbit ({exc.reason}): {exc}")
    except (PwsdynError, ValueError, TypeError) as exc:
        _fail(exc)
    vals = branch.values
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"branch      {branch.kind}, {len(branch)} points, {param} in "
          f"[{_fmt(vals.min())}, {_fmt(vals.max())}]; {int(np.sum(branch.stable))} stable, "
          f"{int(np.sum(~branch.admissible))} not admissible")
    _print_special_points(branch, param)
    if len(branch.problems) > 1:
        _echo("signatures  " + "  ->  ".join(str(s_) for s_ in branch.signatures))
    _echo(f"stopped     {branch.stop_reason}")
    if out is not None:
        _save_data(branch.to_dataset(), out, force)
    if plot is not None:
        from .plot import plot_branch

        problem = _write_figures([(plot, lambda: plot_branch(branch, y=state, path=plot,
                                                             overwrite=force))],
                                 out, branch.to_dataset)
        if problem is not None:
            _fail(problem)


def _branch_setup(model, params, sets, start, stop, x0, t0):
    """What `continue` and `grazing` read the same way: the model, the continued parameter
    (--param NAME, no value), the parameter values (the model's, -p NAME=VALUE, and the
    parameter at --from), --x0, the run defaults and the span [--from, --to]."""
    import pwsdyn
    from .errors import ModelError

    named = list(dict.fromkeys(v.strip() for v in params if "=" not in v))
    if len(named) != 1:
        raise click.UsageError("name the continued parameter once: --param NAME")
    param = named[0]
    params = [v for v in params if "=" in v]
    if start == stop:
        raise click.BadParameter("--from and --to must differ", param_hint="--to")
    cli_params, hints = _all_params(params, sets)
    cli_x0 = _parse_x0(x0)
    try:
        mdl = pwsdyn.load_model(model)
    except ModelError as exc:
        _fail(exc)
    if param not in mdl.parameters:
        raise click.BadParameter(f"unknown parameter {param!r} for model {mdl.name!r}; "
                                 f"parameters are {list(mdl.parameters)}", param_hint="--param")
    _check_params(mdl, cli_params, hints)
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)
    all_params = {**mdl.parameters, **cli_params, param: start}
    x0_val, t0, t_end = _run_defaults(mdl, cli_x0, t0, None)
    return mdl, param, all_params, cli_x0, x0_val, t0, t_end, (min(start, stop), max(start, stop))


def _start_orbit(mdl, x0_val, t0, t_end, all_params, cli_x0, transient, period, periods,
                 options):
    """The starting orbit of `continue` and `grazing`, found as `orbit` finds it: after a
    transient run from the defaults when no --x0 is given, else by shooting from --x0."""
    import pwsdyn
    from .orbits import PeriodicOrbit, find_periodic_orbit

    autonomous = mdl.forcing_period is None
    if transient is None and period is None and (autonomous or not cli_x0):
        transient = t_end - t0
    if transient:
        traj = pwsdyn.simulate(mdl, x0_val, (t0, t0 + transient), params=all_params,
                               **{k: v for k, v in options.items() if k != "method"})
        return PeriodicOrbit.from_trajectory(traj, period=period, periods=periods, **options)
    return find_periodic_orbit(mdl, x0_val, params=all_params, period=period, t0=t0,
                               periods=periods or 1, **options)


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
        _echo(f"{sp.kind:<11} {param} = {_fmt(sp.value)}{where}; {what} "
              + ", ".join(f"{complex(z).real:.6g}{complex(z).imag:+.6g}j" for z in spec))


@main.command("grazing")
@click.argument("model", metavar="MODEL|FILE")
@_sweep_param_options
@click.option("--from", "start", type=float, required=True,
              help="Parameter value where the search starts (the starting orbit is found "
                   "there).")
@click.option("--to", "stop", type=float, required=True,
              help="Parameter value towards which the orbit is followed to its first graze.")
@click.option("--x0", "x0", multiple=True, metavar="VALUES",
              help="Guess of the starting orbit's state at t0 (default: settle from the "
                   "model's [defaults], then shoot).")
@click.option("--t0", type=float, default=None, help="Time of x0 (default the model's).")
@click.option("--periods", type=int, default=None,
              help="Forced models: the starting orbit's period in forcing periods.")
@click.option("--period", type=float, default=None,
              help="Autonomous models: a guess of the period.")
@click.option("--transient", type=float, default=None,
              help="Simulate this long before shooting (default: the model's t_end without "
                   "--x0).")
@click.option("--terms", type=int, default=10, show_default=True,
              help="Terms of the persistence sequence printed.")
def grazing_cmd(model, params, sets, start, stop, x0, t0, periods, period, transient, terms):
    """Follow a periodic orbit of MODEL in --param NAME from --from towards --to to its first
    graze of an impact surface, and print Nordmark's discontinuity map there (x*, a*, beta),
    the persistence sequence h_x P^n beta and the predicted scenario: persistence of a local
    attractor, or its loss (with hysteresis).

    \b
    Example:
      pwsdyn grazing impact-oscillator --param sigma --from 0.45 --to 0.0 \\
          -p omega=2.8 -p eps=0.1 --x0 x=-0.006,v=-0.41 --t0 0
    """
    import pwsdyn
    from .errors import ArgumentError, PwsdynError
    from .orbits import OrbitError

    mdl, param, all_params, cli_x0, x0_val, t0, t_end, span = _branch_setup(
        model, params, sets, start, stop, x0, t0)
    step = min(0.02, abs(stop - start) / 100.0) * (1 if stop > start else -1)
    try:
        orbit = _start_orbit(mdl, x0_val, t0, t_end, all_params, cli_x0, transient, period,
                             periods, {})
        branch = pwsdyn.continue_orbit(mdl, orbit, param, span=span, ds=step, on_dib="stop",
                                       locate=("GR", "CC"))
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
    except OrbitError as exc:
        _fail(f"no starting orbit ({exc.reason}): {exc}")
    except (PwsdynError, ValueError, TypeError) as exc:
        _fail(exc)
    seq = dm.persistence(max(terms, 1))
    vec = ", ".join(f"{n_}={_fmt(v)}" for n_, v in zip(dm.names, dm.x_star))
    _echo(f"model       {mdl.name} (hash {mdl.hash})")
    _echo(f"graze       {param} = {_fmt(gr.value)}: orbit {gr.problem.orbit_problem.signature} "
          f"touches {gr.monitor.surface!r} (event {dm.event!r}) in segment "
          f"{gr.monitor.segment}")
    _echo(f"x*          {vec}")
    _echo(f"a*          {_fmt(dm.a_star)}")
    _echo("beta        " + ", ".join(f"{n_}={_fmt(v)}" for n_, v in zip(dm.names, dm.beta)))
    _echo("multipliers " + ", ".join(f"{complex(z).real:.6g}{complex(z).imag:+.6g}j"
                                     for z in gr.multipliers))
    _echo("h_x P^n beta " + " ".join(f"{v:.3e}" for v in seq))
    _echo(f"scenario    {dm.scenario}"
          + (" of a local attractor" if dm.scenario == "persistence" else
             " of the local attractor (a jump to a distant one, hysteresis)"))


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


def _fail(exc, code: int = 1):
    """Print ``Error: ...`` on one line, sanitised (no traceback), and exit with ``code``."""
    from .io import OVERWRITE_HINT

    # a file that appeared while the command ran: the CLI's way to replace it is --force
    text = _oneline(exc).replace(OVERWRITE_HINT, "pass --force to replace it")
    click.echo(f"Error: {text}", err=True)
    raise SystemExit(code)


if __name__ == "__main__":  # pragma: no cover
    main()
