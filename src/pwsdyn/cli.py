"""The ``pwsdyn`` command line.

``pwsdyn models`` lists the built-in models; ``pwsdyn simulate MODEL`` simulates a built-in
model or a model file and writes the trajectory (NetCDF) and a figure (PNG); ``pwsdyn sweep``
and ``pwsdyn basins`` compute bifurcation diagrams and basins of attraction (parallel on Dask,
resumable) and write their datasets and figures; ``pwsdyn orbit MODEL`` finds a periodic
orbit by Newton shooting and prints its period, signature and Floquet multipliers.

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

#: End time used when neither ``--t-end`` nor the model's ``[defaults]`` give one.
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
            _echo(f"note: no --x0 given and model {model.name!r} has no defaults.x0; "
                       f"starting from zero ({', '.join(f'{s}=0' for s in model.states)})",
                       err=True)
    if t_end is None:
        if defaults.get("t_end") is not None:
            t_end = float(defaults["t_end"])
        else:
            t_end = FALLBACK_T_END
            _echo(f"note: no --t-end given and model {model.name!r} has no "
                       f"defaults.t_end; using t_end = {FALLBACK_T_END:g}", err=True)
    if t0 is None:
        t0 = float(defaults.get("t0", 0.0))
    return x0, t0, t_end, all_params


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
    from .io import _check_output_path
    from .plot import figure_formats

    for option, path, kind in outputs:
        if path is None:
            continue
        p = Path(path)
        suffix = p.suffix.lower()
        hint = option.split()[0]
        if kind == "data":
            if suffix not in NETCDF_SUFFIXES:
                raise click.BadParameter(
                    f"{str(path)!r}: the data are written as NetCDF; give a file name ending "
                    f"in {', '.join(NETCDF_SUFFIXES)}", param_hint=hint)
        else:
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
@click.option("--exact", is_flag=True,
              help="Propagate the modes that are affine in the state with harmonic forcing "
                   "exactly (matrix exponential) instead of by the Runge-Kutta pair.")
@click.option("--mode", default=None, metavar="NAME", help="Initial mode.")
@click.option("--sliding", type=click.Choice(["convex", "utkin"], case_sensitive=False),
              default=None, help="Sliding vector field on Filippov surfaces: Filippov's convex "
                                 "combination (default) or Utkin's equivalent control.")
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write the trajectory to this NetCDF file (.nc).")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write a figure of the trajectory to this file (PNG; PDF, SVG... by "
                   "suffix).")
@click.option("--force", is_flag=True, help=_FORCE_HELP)
def simulate_cmd(model, params, x0, t0, t_end, rtol, atol, method, exact, mode, sliding, out,
                 plot, force):
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
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
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
    if exact:
        options["exact"] = True
    if mode is not None:
        options["mode"] = mode
    if sliding is not None:
        options["sliding"] = sliding.lower()

    try:
        traj = pwsdyn.simulate(mdl, x0_val, (t0, t_end), params=all_params, throw=False,
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


def _explore_common(model, sets, x0, method, rtol, atol, exact=False):
    """Load MODEL, check ``--set`` and ``--x0`` and collect integrator options."""
    import pwsdyn
    from .errors import ModelError

    params = _parse_params(sets)
    cli_x0 = _parse_x0(x0)
    try:
        mdl = pwsdyn.load_model(model)
        defaults = _model_defaults(mdl)
    except ModelError as exc:
        _fail(exc)
    unknown = [k for k in params if k not in mdl.parameters]
    if unknown:
        raise click.BadParameter(f"unknown parameter(s) {unknown} for model {mdl.name!r}; "
                                 f"parameters are {list(mdl.parameters)}", param_hint="--set")
    if cli_x0 is not None:
        _check_x0(mdl, cli_x0)
    all_params = dict(defaults.get("params", {}) or {})
    all_params.update(params)
    if cli_x0 is None:
        cli_x0 = defaults.get("x0")
    options = {}
    for k, v in (("rtol", rtol), ("atol", atol), ("method", method.upper() if method else None)):
        if v is not None:
            options[k] = v
    if exact:
        options["exact"] = True
    return mdl, all_params, cli_x0, options


def _run_store(out, store):
    """The store directory: ``--store``, else ``<out>.store`` (removed after success)."""
    from pathlib import Path

    if store is not None:
        return Path(store), False
    if out is not None:
        return Path(str(out) + ".store"), True
    return None, False


_EXPLORE_OPTIONS = [
    click.option("--set", "-s", "sets", multiple=True, metavar="NAME=VALUE",
                 help="Value of another parameter (repeatable); default: the model's."),
    click.option("--x0", "x0", multiple=True, metavar="VALUES",
                 help="Initial state (as for `simulate`); default: the model's [defaults]."),
    click.option("--transient", type=int, default=200, show_default=True,
                 help="Forcing periods (maps: iterations) discarded."),
    click.option("--samples", type=int, default=None,
                 help="Forcing periods (maps: iterations) recorded [sweep 100, basins 32]."),
    click.option("--section", default="stroboscopic", show_default=True,
                 help="'stroboscopic' or the name of an event (e.g. impact)."),
    click.option("--workers", type=int, default=None,
                 help="1: in this process; N: local Dask cluster of N processes "
                      "(default: one per core)."),
    click.option("--scheduler", default=None, metavar="ADDRESS",
                 help="Run on the Dask cluster of this scheduler instead."),
    click.option("--chunk-size", "chunk_size", type=int, default=None,
                 help="Values (basins: grid rows) per chunk (default: 1/16 of them)."),
    click.option("--store", default=None, type=click.Path(file_okay=False),
                 help="Resumable store directory (default: OUT.store, removed when done)."),
    click.option("--rtol", type=float, default=None, help="Relative tolerance (1e-10)."),
    click.option("--atol", type=float, default=None, help="Absolute tolerance (1e-12)."),
    click.option("--method", type=click.Choice(["RK45", "DOP853"], case_sensitive=False),
                 default=None, help="Runge-Kutta pair (default RK45)."),
    click.option("--exact", is_flag=True,
                 help="Propagate the modes that are affine in the state with harmonic forcing "
                      "exactly (matrix exponential) instead of by the Runge-Kutta pair."),
    click.option("--no-progress", "no_progress", is_flag=True, help="No progress bar."),
    click.option("--out", type=click.Path(dir_okay=False), default=None,
                 help="Write the dataset to this NetCDF file (.nc)."),
    click.option("--plot", type=click.Path(dir_okay=False), default=None,
                 help="Write the figure to this file (PNG; PDF, SVG... by suffix)."),
    click.option("--force", is_flag=True, help=_FORCE_HELP),
]


def _explore_options(fn):
    for opt in reversed(_EXPLORE_OPTIONS):
        fn = opt(fn)
    return fn


def _finish_explore(ds, out, store_path, remove_store, figures, force):
    """Write --out (then remove the default store), then the ``figures`` (see
    :func:`_write_figures`)."""
    import shutil

    from .io import save_dataset

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
@click.option("--param", "param", required=True, metavar="NAME", help="Parameter swept.")
@click.option("--from", "start", type=float, required=True, help="First value.")
@click.option("--to", "stop", type=float, required=True, help="Last value.")
@click.option("--num", type=int, required=True, help="Number of values (evenly spaced).")
@click.option("--direction", type=click.Choice(["up", "down", "both"]), default="both",
              show_default=True, help="Sweep up, down or both (hysteresis).")
@click.option("--lyapunov", is_flag=True, help="Also compute Lyapunov exponents (slower).")
@click.option("--state", default=None, help="State plotted (default: first, or last for an "
              "event section).")
@_explore_options
def sweep_cmd(model, param, start, stop, num, direction, lyapunov, state, sets, x0, transient,
              samples, section, workers, scheduler, chunk_size, store, rtol, atol, method,
              exact, no_progress, out, plot, force):
    """Brute-force bifurcation diagram of MODEL in parameter --param.

    For each of --num values from --from to --to, run --transient forcing periods, record
    --samples periods at the section and continue the final state into the next value.

    \b
    Examples:
      pwsdyn sweep impact-oscillator --param omega --from 2 --to 3.6 --num 400 \\
          --out diagram.nc --plot diagram.png
      pwsdyn sweep sqrt-map --param mu --from 0.001 --to 0.05 --num 200 --set lam=0.8 \\
          --lyapunov --plot sqrt.png
    """
    import numpy as np

    import pwsdyn
    from .plot import plot_bifurcation, plot_lyapunov

    if num < 1:
        raise click.BadParameter(f"must be at least 1, got {num}", param_hint="--num")
    lyap_plot = _lyapunov_path(plot) if plot is not None and lyapunov else None
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure"),
                           ("--plot (its Lyapunov figure)", lyap_plot, "figure")])
    mdl, params, x0v, options = _explore_common(model, sets, x0, method, rtol, atol, exact)
    if param not in mdl.parameters:
        raise click.BadParameter(f"unknown parameter {param!r} for model {mdl.name!r}; "
                                 f"parameters are {list(mdl.parameters)}", param_hint="--param")
    params.pop(param, None)
    store_path, remove_store = _run_store(out, store)
    values = np.linspace(start, stop, num) if num > 1 else np.array([start])
    try:
        ds = pwsdyn.sweep(mdl, param, values, x0v, params=params, transient=transient,
                          samples=100 if samples is None else samples, section=section,
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
    if plot is not None:
        figures.append((plot, lambda: plot_bifurcation(ds, state=state, path=plot,
                                                       overwrite=force)))
    if lyap_plot is not None:
        figures.append((lyap_plot, lambda: plot_lyapunov(ds, path=lyap_plot, overwrite=force)))
    # the data go to --out here, not in pwsdyn.sweep: --force applies and the figure follows
    _finish_explore(ds, out, store_path, remove_store, figures, force)


@main.command("basins")
@click.argument("model", metavar="MODEL|FILE")
@click.option("--x", "xname", required=True, metavar="STATE", help="State on the first axis.")
@click.option("--x-from", "x_from", type=float, required=True)
@click.option("--x-to", "x_to", type=float, required=True)
@click.option("--x-num", "x_num", type=int, required=True)
@click.option("--y", "yname", default=None, metavar="STATE",
              help="State on the second axis (flows: required; 1-D maps: omit).")
@click.option("--y-from", "y_from", type=float, default=None)
@click.option("--y-to", "y_to", type=float, default=None)
@click.option("--y-num", "y_num", type=int, default=None)
@_explore_options
def basins_cmd(model, xname, x_from, x_to, x_num, yname, y_from, y_to, y_num, sets, x0,
               transient, samples, section, workers, scheduler, chunk_size, store, rtol,
               atol, method, exact, no_progress, out, plot, force):
    """Basins of attraction of MODEL on a grid of initial conditions.

    \b
    Example:
      pwsdyn basins bouncing-ball --x y --x-from 0.1 --x-to 2 --x-num 100 \\
          --y v --y-from -4 --y-to 4 --y-num 100 --set A=0.2236 --set omega=6.2832 \\
          --out basins.nc --plot basins.png
    """
    import numpy as np

    import pwsdyn
    from .plot import plot_basins

    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
    mdl, params, x0v, options = _explore_common(model, sets, x0, method, rtol, atol, exact)
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
                           samples=32 if samples is None else samples, section=section,
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
    if plot is not None:
        figures.append((plot, lambda: plot_basins(ds, path=plot, overwrite=force)))
    _finish_explore(ds, out, store_path, remove_store, figures, force)


@main.command("orbit")
@click.argument("model", metavar="MODEL|FILE")
@click.option("--param", "-p", "params", multiple=True, metavar="NAME=VALUE",
              help="Parameter value (repeatable); overrides the model's defaults.")
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
@click.option("--method", type=click.Choice(["RK45", "DOP853"], case_sensitive=False),
              default=None, help="Runge-Kutta pair (default DOP853).")
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write one period with its monodromy and multipliers to this NetCDF file.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write a figure of the orbit with its events and multipliers (PNG; PDF, "
                   "SVG... by suffix).")
@click.option("--force", is_flag=True, help=_FORCE_HELP)
def orbit_cmd(model, params, x0, t0, period, periods, transient, mode, nodes, tol, rtol, atol,
              method, out, plot, force):
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

    cli_params = _parse_params(params)
    cli_x0 = _parse_x0(x0)
    _check_outputs(force, [("--out", out, "data"), ("--plot", plot, "figure")])
    try:
        mdl = pwsdyn.load_model(model)
        defaults = _model_defaults(mdl)
    except ModelError as exc:
        _fail(exc)
    _check_params(mdl, cli_params)
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
    try:
        x0_val, t0, t_end, all_params = _resolve_defaults(mdl, defaults, cli_x0, t0, None,
                                                          cli_params)
    except (TypeError, ValueError) as exc:
        _fail(f"model {mdl.name!r}: bad `defaults` table: {exc}")
    options = {"tol": tol, "nodes": nodes}
    for key, val in (("rtol", rtol), ("atol", atol),
                     ("method", method.upper() if method else None)):
        if val is not None:
            options[key] = val
    autonomous = mdl.forcing_period is None
    # without a guess from the user, settle on the attractor first (the model's typical run)
    if transient is None and period is None and (autonomous or not cli_x0):
        transient = t_end - t0
    try:
        if transient:
            sim_opts = {k: options[k] for k in ("rtol", "atol", "method") if k in options}
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
