"""The plumbing of every file pwsdyn writes: CF attributes (units, long names, flags, the
model and the versions that made the data), the one table of status codes, JSON that
survives non-finite numbers, and atomic writes that never leave half a file.

Every result lays out its own dataset with these helpers (trajectories in
:mod:`pwsdyn._trajectory_file`, periodic orbits, sweeps, basins, Lyapunov spectra beside
their code); :mod:`pwsdyn.io` is the public face that reads and writes them all. This module
imports no result type, so any layer may use it.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import uuid
from pathlib import Path

import numpy as np
import xarray as xr

from .errors import ArgumentError, Status

#: Value of the ``pwsdyn_type`` attribute of a trajectory dataset.
TRAJECTORY_TYPE = "trajectory"
#: NetCDF engine used for every file pwsdyn writes.
ENGINE = "h5netcdf"
#: Option values that are names, never numbers (kept as strings when decoding JSON).
_STRING_OPTIONS = frozenset({"method", "mode"})


# ======================================================================================
# JSON helpers
# ======================================================================================

def _json_safe(obj):
    """A copy of ``obj`` that strict JSON accepts: non-finite floats become ``"inf"``,
    ``"-inf"`` or ``"nan"``, NumPy scalars and arrays become Python numbers and lists."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_json_safe(v) for v in obj.tolist()]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, Status):
        return obj.name
    return obj


def _json_restore(obj, *, keep_strings=frozenset()):
    """Inverse of :func:`_json_safe`: the strings ``"inf"``, ``"-inf"`` and ``"nan"`` become
    floats again, except under the top-level keys in ``keep_strings`` (options whose values
    are names, such as a mode that happens to be called ``inf``)."""
    special = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}
    if isinstance(obj, dict):
        return {k: (v if k in keep_strings else _json_restore(v)) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_json_restore(v) for v in obj]
    if isinstance(obj, str) and obj in special:
        return special[obj]
    return obj


def json_text(obj) -> str:
    """``obj`` as JSON text for a file attribute (non-finite floats spelled out)."""
    return json.dumps(_json_safe(obj), allow_nan=False, sort_keys=False)


def _spec_to_json(spec: dict, indent: int | None = None) -> str:
    """The model definition as JSON text that :func:`pwsdyn.load_model` accepts back.

    A TOML file gives plain strings, numbers, tables and arrays, which JSON holds as they are.
    A model built in Python may carry SymPy expressions; those are printed in the syntax of
    the safe expression parser (``e_const``, ``inf``, ``and``/``or``, floats with all their
    digits) so the rebuilt model is the same model.
    """
    def default(obj):
        import sympy as sp

        if isinstance(obj, sp.Basic):
            return _expr_printer().doprint(obj)
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
        raise ArgumentError(f"the model definition holds a {type(obj).__name__} ({obj!r}), which "
                        f"cannot be stored in a trajectory file")

    # TOML allows inf/nan floats; Python's JSON writes and reads them as Infinity/NaN, which is
    # what a round trip through `load_model` needs (a string "inf" would be an expression).
    return json.dumps(spec, default=default, indent=indent)


@functools.lru_cache(maxsize=None)
def _expr_printer_class():
    # built on first use: SymPy's printers are only needed for models made of SymPy objects
    from sympy.printing.str import StrPrinter

    class ExprPrinter(StrPrinter):
        """Prints SymPy expressions in the language of :mod:`pwsdyn.model.expressions`."""

        def _print_Float(self, expr):
            # str(Float) rounds to 15 digits; repr of the double is exact
            return repr(float(expr))

        def _print_Exp1(self, expr):
            return "e_const"

        def _print_Infinity(self, expr):
            return "inf"

        def _print_NegativeInfinity(self, expr):
            return "(-inf)"

        def _print_And(self, expr):
            return " and ".join(f"({self._print(a)})" for a in expr.args)

        def _print_Or(self, expr):
            return " or ".join(f"({self._print(a)})" for a in expr.args)

        def _print_Not(self, expr):
            return f"not ({self._print(expr.args[0])})"

        def _print_BooleanTrue(self, expr):
            return "(0 < 1)"

        def _print_BooleanFalse(self, expr):
            return "(1 < 0)"

    return ExprPrinter


def _expr_printer():
    return _expr_printer_class()()


# ======================================================================================
# CF conventions: units, long names, flags, global attributes
# ======================================================================================

#: The metadata conventions of every file pwsdyn writes.
CONVENTIONS = "CF-1.10"
#: The packages whose versions every file records (``<name>_version`` attributes).
VERSIONED_PACKAGES = ("pwsdyn", "numpy", "scipy", "numba", "xarray", "sympy")


@functools.lru_cache(maxsize=None)
def package_versions() -> dict:
    """``{"pwsdyn_version": ..., "numpy_version": ..., ...}`` for
    ``VERSIONED_PACKAGES`` (``"unknown"`` where a version cannot be found)."""
    from importlib import metadata

    out = {}
    for name in VERSIONED_PACKAGES:
        if name == "pwsdyn":
            out["pwsdyn_version"] = library_version()
            continue
        try:
            out[f"{name}_version"] = metadata.version(name)
        except metadata.PackageNotFoundError:
            mod = __import__(name)
            out[f"{name}_version"] = str(getattr(mod, "__version__", "unknown"))
    return out


def model_text(model) -> tuple[str, str]:
    """The model's full text and its format: the TOML source it was read from
    (``"toml"``), else a canonical serialisation of its definition (``"json"``, indented;
    ``pwsdyn.load_model(json.loads(text))`` rebuilds it)."""
    text = getattr(model, "text", "") or ""
    if text:
        return text, "toml"
    return _spec_to_json(model.spec, indent=1), "json"


def model_attrs(model) -> dict:
    """Global attributes that describe the model: name, hash, kind, definition (JSON and full
    text), units and descriptions of its quantities (JSON), its description and reference."""
    text, fmt = model_text(model)
    attrs = {
        "model": str(model.name),
        "model_hash": str(model.hash),
        "model_kind": "map" if getattr(model, "is_map", False) else "flow",
        "model_spec": _spec_to_json(model.spec),
        "model_text": text,
        "model_text_format": fmt,
        "model_units": json.dumps(dict(getattr(model, "units", {}) or {})),
        "model_descriptions": json.dumps(dict(getattr(model, "descriptions", {}) or {})),
    }
    if getattr(model, "description", ""):
        attrs["model_description"] = str(model.description)
    if getattr(model, "reference", ""):
        attrs["references"] = str(model.reference)
    return attrs


def cf_global_attrs(model, kind: str, title: str, source: str) -> dict:
    """The global attributes of a pwsdyn dataset: ``Conventions``, ``title``, ``source``,
    the versions of pwsdyn and its numerical dependencies, and :func:`model_attrs`.
    ``date_created`` and ``history`` are added when the file is written
    (:func:`save_dataset`)."""
    return {
        "Conventions": CONVENTIONS,
        "title": title,
        "source": f"pwsdyn {library_version()}: {source}",
        "pwsdyn_type": kind,
        **package_versions(),
        **model_attrs(model),
    }


def time_units(model) -> str | None:
    """The unit of time of ``model`` (``[units] t``); ``"1"`` for a map (iterations)."""
    if getattr(model, "is_map", False):
        return "1"
    return model.unit("t") if hasattr(model, "unit") else None


def inverse_time_units(model) -> str | None:
    """The unit of a rate per unit time (Lyapunov exponents): ``1/<time unit>``."""
    tu = time_units(model)
    if tu is None:
        return None
    if tu == "1":
        return "1"
    return f"{tu}-1" if tu.isidentifier() else f"1/({tu})"


def quantity_attrs(model, name: str, default_long_name: str | None = None) -> dict:
    """``long_name`` (the ``[descriptions]`` entry, else ``default_long_name``, else the
    name) and ``units`` (where ``[units]`` gives one) of a state, parameter or ``t``."""
    unit = time_units(model) if name == "t" else model.unit(name)
    attrs = {"long_name": model.describe(name) or default_long_name or name}
    if unit is not None:
        attrs["units"] = unit
    return attrs


def state_attrs(model, long_name: str, **extra) -> dict:
    """Attributes of a variable over the ``state`` dimension: ``long_name`` and ``units``
    where all states share one unit; otherwise a ``comment`` pointing to the per-state
    units (the ``state_units`` coordinate)."""
    attrs = {"long_name": long_name, **extra}
    units = {model.unit(s) for s in model.states}
    if len(units) == 1 and None not in units:
        attrs["units"] = units.pop()
    elif units != {None}:
        attrs["comment"] = "units differ by state: see the state_units coordinate"
    return attrs


def state_coords(model) -> dict:
    """The ``state`` coordinate with its per-state units and long names as auxiliary
    coordinates (``""`` where the model gives no unit)."""
    names = list(model.states)
    return {
        "state": ("state", string_array(names), {"long_name": "state variable"}),
        "state_units": ("state", string_array(model.unit(s) or "" for s in names),
                        {"long_name": "unit of the state variable (empty: not given)"}),
        "state_long_name": ("state", string_array(model.describe(s) or s for s in names),
                            {"long_name": "description of the state variable"}),
    }


def flag_attrs(codes: dict, dtype=np.int64) -> dict:
    """``flag_values`` and ``flag_meanings`` (CF) of an integer code variable from
    ``{value: meaning}`` (meanings are words joined by ``_``); ``flag_values`` has the
    variable's type ``dtype``, as CF requires."""
    items = sorted(codes.items())
    return {"flag_values": np.array([k for k, _ in items], dtype=dtype),
            "flag_meanings": " ".join(m for _, m in items)}


def run_status_codes(*, is_map: bool = False, section_missed: bool = False) -> dict:
    """The codes of a ``status`` variable of a sweep, basins or a Lyapunov result, ``{value:
    meaning}``, all members of :class:`~pwsdyn.Status`: success, the ways a run can fail
    (flows: the integrator's; maps: no applicable piece, non-finite) and diverged; with
    ``section_missed`` (sweeps and basins of flows) also section missed."""
    if is_map:
        members = [Status.SUCCESS, Status.NO_PIECE_APPLIES, Status.NONFINITE]
    else:
        members = [s for s in Status.integrator_outcomes() if s.failed or s == Status.SUCCESS]
        if section_missed:
            members.append(Status.SECTION_MISSED)
    members.append(Status.DIVERGED)
    return status_codes(members)


def status_codes(members) -> dict:
    """``{value: meaning}`` of the given :class:`~pwsdyn.Status` members, for
    :func:`flag_attrs`: the one source of every file's status flags."""
    return {int(s): s.meaning for s in members}


#: The codes of map runs in files written before every status was a member of
#: :class:`~pwsdyn.Status` (their ``flag_meanings`` name them: decoded by meaning).
_OLD_MAP_MEANINGS = {"no_piece_applies": Status.NO_PIECE_APPLIES, "nonfinite": Status.NONFINITE}


def decode_status(var) -> np.ndarray:
    """The :class:`~pwsdyn.Status` members of a ``status`` variable of a file or dataset, as
    an object array of its shape (a 0-d variable gives a 0-d array: ``.item()``).

    The variable's own ``flag_values`` and ``flag_meanings`` say what each value means, so a
    file written with other values for a meaning (map runs before every status was a member
    of one enumeration) decodes to the same members; a variable without flags (files written
    before flags existed) holds :class:`~pwsdyn.Status` values."""
    values = np.asarray(getattr(var, "values", var))
    attrs = getattr(var, "attrs", {}) or {}
    table = {}
    if "flag_values" in attrs and "flag_meanings" in attrs:
        for v, word in zip(np.atleast_1d(attrs["flag_values"]).tolist(),
                           str(attrs["flag_meanings"]).split()):
            member = _OLD_MAP_MEANINGS.get(word)
            if member is None:
                try:
                    member = Status.from_meaning(word)
                except KeyError:
                    raise ArgumentError(f"`{getattr(var, 'name', 'status')}` has the flag "
                                        f"{word!r}, which is no status") from None
            table[int(v)] = member
    out = np.empty(values.shape, dtype=object)
    flat = out.reshape(-1)
    for i, v in enumerate(values.reshape(-1).tolist()):
        member = table.get(int(v))
        flat[i] = member if member is not None else Status(int(v))
    return out


def _utc_now() -> str:
    import datetime

    now = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0)
    return now.strftime("%Y-%m-%dT%H:%M:%SZ")


def stamp(ds: xr.Dataset) -> xr.Dataset:
    """A shallow copy of ``ds`` with ``date_created`` (ISO 8601, UTC; kept if it has one)
    and a line appended to ``history``, as a file is written."""
    now = _utc_now()
    ds = ds.copy()
    ds.attrs.setdefault("date_created", now)
    line = f"{now} written by pwsdyn {library_version()}"
    old = str(ds.attrs.get("history", "") or "")
    ds.attrs["history"] = f"{old}\n{line}" if old else line
    return ds


# ======================================================================================
# strings
# ======================================================================================

def string_array(values) -> np.ndarray:
    """``values`` as a string array for a NetCDF variable."""
    # Fixed-width unicode arrays are written by h5netcdf as variable-length UTF-8 strings and
    # read back as unicode; `dtype=str` keeps an empty list a (0,) string array, not float.
    return np.array([str(v) for v in values], dtype=str)


def library_version() -> str:
    """The version of pwsdyn, as files record it."""
    from ._version import __version__

    return __version__



# ======================================================================================
# files
# ======================================================================================

@contextlib.contextmanager
def _engine_hint():
    # recent h5netcdf releases make h5py an optional extra; say what to install instead of
    # surfacing an ImportError from deep inside xarray
    try:
        yield
    except ImportError as exc:
        if "h5py" in str(exc) or "h5netcdf" in str(exc):
            raise ImportError(f"pwsdyn reads and writes NetCDF files with h5netcdf and h5py: "
                              f"`pip install h5netcdf h5py` ({exc})") from exc
        raise


def save_dataset(ds, path, *, overwrite: bool = False) -> Path:
    """Write a dataset (or a trajectory) to a NetCDF-4 file, atomically.

    The data go to a temporary file in the same directory, which is then moved to ``path`` in
    one step, so ``path`` is never left half-written. The file gets the global attributes
    ``date_created`` (ISO 8601, UTC; a dataset that has one keeps it) and ``history`` (a
    line appended); ``ds`` itself is not changed.

    Parameters
    ----------
    ds : xarray.Dataset or a result
        A result (a trajectory, a periodic orbit, a Lyapunov spectrum) is converted with its
        own ``to_dataset()``.
    path : str or pathlib.Path
        The file to write (conventionally ``*.nc``).
    overwrite : bool
        ``False`` (default): an existing ``path`` is refused with
        :class:`~pwsdyn.OutputExistsError` and left alone. ``True``: it is replaced (it holds
        the old content or the new one, never a mix).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and ``overwrite`` is false (also a ``FileExistsError``).
    FileNotFoundError
        If the directory of ``path`` does not exist.
    """
    if not isinstance(ds, xr.Dataset):
        if callable(getattr(ds, "to_dataset", None)):
            ds = ds.to_dataset()
        else:
            raise ArgumentError(f"`ds` must be an xarray.Dataset or a Trajectory, got "
                                f"{type(ds).__name__}")

    ds = stamp(ds)

    def write(tmp):
        with _engine_hint():
            ds.to_netcdf(tmp, engine=ENGINE)

    return atomic_write(path, write, overwrite=overwrite)


#: How to ask for an existing file to be replaced, in the API (the CLI says ``--force``).
OVERWRITE_HINT = "pass overwrite=True to replace it"


def check_output_path(path, *, overwrite: bool = False, hint: str = OVERWRITE_HINT) -> Path:
    """Check that ``path`` can be written, before any work is done; return it as a Path.

    Its directory must exist and be writable, ``path`` must not be a directory and, unless
    ``overwrite``, must not exist (:class:`~pwsdyn.OutputExistsError`, whose message ends
    with ``hint``). Raises ``FileNotFoundError``, ``NotADirectoryError``,
    ``IsADirectoryError`` or ``PermissionError`` naming the path otherwise.
    """
    from .errors import OutputExistsError

    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise IsADirectoryError(f"cannot write {str(path)!r}: it is a directory")
    if not directory.is_dir():
        # name the first ancestor that exists and is no directory, else the missing one
        for anc in [directory, *directory.parents]:
            if anc.exists() or anc.is_symlink():
                if not anc.is_dir():
                    raise NotADirectoryError(f"cannot write {str(path)!r}: {str(anc)!r} is "
                                             f"not a directory")
                break
        raise FileNotFoundError(f"cannot write {str(path)!r}: directory {str(directory)!r} "
                                f"does not exist")
    if not overwrite and (path.exists() or path.is_symlink()):
        raise OutputExistsError(f"output file {str(path)!r} exists; nothing was overwritten "
                                f"({hint})")
    # os.access also reports a read-only file system (EROFS), even to root
    if not os.access(directory, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot write {str(path)!r}: directory {str(directory)!r} is "
                              f"not writable")
    return path


def atomic_write(path, write, *, overwrite: bool = False) -> Path:
    """Write a file through ``write(tmp_path)`` and move it into place in one step, so a
    failed write never leaves a half-written file or destroys the old one.

    With ``overwrite=False`` (default) an existing ``path`` is refused before ``write`` is
    called (:class:`~pwsdyn.OutputExistsError`), and the final move never replaces a file that
    appeared in the meantime. With ``overwrite=True`` an existing file is replaced.
    """
    path = check_output_path(path, overwrite=overwrite)
    directory = path.parent if str(path.parent) else Path(".")
    # hidden name in the same directory: os.replace is atomic only within one file system
    tmp = directory / f".{path.name}.{uuid.uuid4().hex}.tmp"
    try:
        write(tmp)
        if overwrite:
            os.replace(tmp, path)
        else:
            _move_no_clobber(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        raise
    return path


def _move_no_clobber(tmp: Path, path: Path) -> None:
    """Move ``tmp`` to ``path`` unless ``path`` exists (then OutputExistsError)."""
    from .errors import OutputExistsError

    exists = OutputExistsError(f"output file {str(path)!r} exists; nothing was overwritten "
                               f"({OVERWRITE_HINT})")
    try:
        os.link(tmp, path)  # fails if path exists: no window between check and move
    except FileExistsError:
        raise exists from None
    except OSError:
        # file systems without hard links: check, then move (a small window remains)
        if path.exists() or path.is_symlink():
            raise exists from None
        os.replace(tmp, path)
        return
    tmp.unlink()


def open_dataset(path, *, lazy: bool = False) -> xr.Dataset:
    """Read a NetCDF file written by pwsdyn.

    Parameters
    ----------
    path : str or pathlib.Path
    lazy : bool
        ``False`` (default): read everything into memory and close the file, so the file can
        be replaced or deleted while the dataset is in use. ``True``: keep it open and read
        on demand (for large files); close the dataset when done.

    Returns
    -------
    xarray.Dataset
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {str(path)!r}")
    # times and rates carry the model's units ("s", "seconds"...): numbers, never decoded to
    # dates or timedeltas
    kwargs = {"engine": ENGINE, "decode_times": False, "decode_timedelta": False}
    with _engine_hint():
        if lazy:
            return xr.open_dataset(path, **kwargs)
        return xr.load_dataset(path, **kwargs)
