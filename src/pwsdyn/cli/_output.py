"""Terminal output and output files of the command line.

Text from a model or a file is printed through one sanitiser (:func:`_safe`). Output files
(``--out``, ``--plot``) are checked before any work (:func:`_check_outputs`), never replaced
without ``--force``, and written data first, figures after (:func:`_write_figures`), each
listed as ``wrote PATH``.
"""

from __future__ import annotations

import re
from pathlib import Path

import click

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
    from .._netcdf import check_output_path

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
            from ..plot import figure_formats

            formats = figure_formats()
            if (suffix[1:] or "png") not in formats:
                raise click.BadParameter(
                    f"{str(path)!r}: unknown figure format {p.suffix!r}; supported formats: "
                    f"{', '.join('.' + f for f in formats)}", param_hint=hint)
        try:
            check_output_path(p, overwrite=force, hint="pass --force to replace it")
        except OSError as exc:
            _fail(f"{option}: {exc}")


def _lyapunov_path(plot):
    """The second figure of ``sweep --lyapunov --plot P``: ``<stem>-lyapunov<suffix>``."""
    p = Path(plot)
    return p.with_name(p.stem + "-lyapunov" + p.suffix)


def _save_data(dataset, out, force: bool) -> None:
    """Write --out (``dataset`` is an xarray Dataset) or exit with one error line."""
    from ..io import save_dataset

    try:
        save_dataset(dataset, out, overwrite=force)
    except (OSError, ValueError, TypeError) as exc:
        _fail(exc)
    _echo(f"wrote       {out}")


def _rescue_data(dataset, plot):
    """Save the data of a figure that could not be written next to it: ``<stem>.nc`` (then
    ``<stem>-1.nc``... if taken), else in the current directory. Returns ``(path, None)`` or
    ``(None, the last error)``; never replaces a file."""
    from ..errors import OutputExistsError
    from ..io import save_dataset

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
    from ..errors import PwsdynError

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


def _fail(exc, code: int = 1):
    """Print ``Error: ...`` on one line, sanitised (no traceback), and exit with ``code``."""
    from ..io import OVERWRITE_HINT

    # a file that appeared while the command ran: the CLI's way to replace it is --force
    text = _oneline(exc).replace(OVERWRITE_HINT, "pass --force to replace it")
    click.echo(f"Error: {text}", err=True)
    raise SystemExit(code)



def _write_outputs(out, plot, dataset, draw, force: bool):
    """The results of a command that writes one dataset and one figure: ``dataset()`` to
    --out (if given), then ``draw()`` writes --plot (if given; see :func:`_write_figures`).
    Returns None or the message of a figure that could not be written."""
    if out is not None:
        _save_data(dataset(), out, force)
    if plot is None:
        return None
    return _write_figures([(plot, draw)], out, dataset)
