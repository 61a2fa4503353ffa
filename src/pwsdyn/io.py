"""Trajectories as labelled arrays (xarray) and NetCDF files.

A :class:`~pwsdyn.integrate.trajectory.Trajectory` becomes an :class:`xarray.Dataset` that
holds everything needed to rebuild it: the nodes, the event log, the dense output, and the
model itself (its definition as JSON in the attributes), so that a saved trajectory can be
reloaded in another process and evaluated at any time with results identical to the last bit.

Layout of the dataset
---------------------
Dimensions and coordinates:

``node``
    Stored nodes (accepted steps and both sides of every event).
``state``
    State names of the model.
``state_in``
    State names again, for the columns of ``jacobian`` (derivatives with respect to the
    initial state).
``ycomp``
    Components of the full node vector: the states, then the variational matrix ``Phi``
    (row-major) when the run had ``variational=True``.
``interval``
    The intervals between consecutive nodes; ``power`` indexes the coefficients of the dense
    output polynomial on each interval.
``event``
    Entries of the event log.

Attributes: ``pwsdyn_type`` (``"trajectory"``), ``model``, ``model_hash``, ``model_spec`` (the
model definition as JSON; ``pwsdyn.load_model(json.loads(...))`` rebuilds it), ``params``,
``options`` and ``stats`` (JSON), ``status`` (the :class:`~pwsdyn.Status` name),
``status_code``, ``message``, ``t0``, ``t_end``, ``pwsdyn_version`` and ``provenance`` (JSON).

This module only reads result objects; the numerical code never imports it.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import uuid
import warnings
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


def _dumps(obj) -> str:
    return json.dumps(_json_safe(obj), allow_nan=False, sort_keys=False)


def _spec_to_json(spec: dict) -> str:
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
    return json.dumps(spec, default=default)


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
# Trajectory <-> Dataset
# ======================================================================================

def _str_array(values) -> np.ndarray:
    # Fixed-width unicode arrays are written by h5netcdf as variable-length UTF-8 strings and
    # read back as unicode; `dtype=str` keeps an empty list a (0,) string array, not float.
    return np.array([str(v) for v in values], dtype=str)


def _ycomp_labels(state_names, ny: int) -> list:
    n = len(state_names)
    labels = list(state_names)
    if ny == n + n * n:
        labels += [f"Phi[{a},{b}]" for a in state_names for b in state_names]
    else:
        labels += [f"y{k}" for k in range(n, ny)]
    return labels


def trajectory_to_dataset(traj) -> xr.Dataset:
    """The trajectory as an :class:`xarray.Dataset`, with the model and provenance attached.

    Parameters
    ----------
    traj : Trajectory
        A result of :func:`pwsdyn.simulate`.

    Returns
    -------
    xarray.Dataset
        See the module docstring for the layout. ``dense`` is omitted when the trajectory has
        no dense output, ``jacobian`` when it has no variational part.

    Raises
    ------
    TypeError
        If ``traj`` is not a trajectory.
    """
    for attr in ("t", "x", "state", "events", "model", "status"):
        if not hasattr(traj, attr):
            raise ArgumentError(f"`traj` must be a Trajectory, got {type(traj).__name__}")
    model = traj.model
    names = list(model.states)
    n = len(names)
    t = np.asarray(traj.t, dtype=float)
    x = np.asarray(traj.x, dtype=float).reshape(len(t), n)
    y = np.asarray(traj._y if traj._y is not None else x, dtype=float)
    ny = y.shape[1]

    data_vars = {
        "t": (("node",), t, {"long_name": "time of the node"}),
        "x": (("node", "state"), x, {"long_name": "state at the node"}),
        "discrete_state": (("node",), _str_array(traj.state),
                           {"long_name": "mode name, stick:<event> or slide:<switch>"}),
        "y": (("node", "ycomp"), y,
              {"long_name": "full node vector: state, then variational matrix (row-major)"}),
    }
    if traj._ikind is not None:
        data_vars["interval_kind"] = (
            ("interval",), np.asarray(traj._ikind, dtype=np.int64),
            {"long_name": "0: dense polynomial, 1: jump or no dense output (linear), "
                          "2: chattering gap (linear)"})
    if traj._dense is not None:
        dense = np.asarray(traj._dense, dtype=float)
        data_vars["dense"] = (
            ("interval", "ycomp", "power"), dense,
            {"long_name": "dense output: y(t0 + theta h) = y0 + sum_k dense[k] theta^(k+1)"})

    ev = list(traj.events)
    ne = len(ev)

    def evx(attr):
        # reshape keeps an empty log a (0, n) array with the `state` dimension
        return np.array([getattr(e, attr)[:n] for e in ev], dtype=float).reshape(ne, n)

    data_vars.update({
        "event_t": (("event",), np.array([e.t for e in ev], dtype=float),
                    {"long_name": "time of the event (start of a chattering sequence)"}),
        "event_t_after": (("event",), np.array([e.t_after for e in ev], dtype=float),
                          {"long_name": "time after the event (accumulation time of chatter)"}),
        "event_name": (("event",), _str_array(e.name for e in ev), {}),
        "event_kind": (("event",), _str_array(e.kind for e in ev), {}),
        "event_mode_before": (("event",), _str_array(e.mode_before for e in ev), {}),
        "event_mode_after": (("event",), _str_array(e.mode_after for e in ev), {}),
        "event_x_before": (("event", "state"), evx("x_before"), {}),
        "event_x_after": (("event", "state"), evx("x_after"), {}),
    })
    if traj.jacobian is not None:
        data_vars["jacobian"] = (
            ("state", "state_in"), np.asarray(traj.jacobian, dtype=float),
            {"long_name": "derivative of the final state with respect to the initial state"})

    coords = {
        "node": np.arange(len(t)),
        "state": _str_array(names),
        "event": np.arange(ne),
        "ycomp": _str_array(_ycomp_labels(names, ny)),
    }
    if traj.jacobian is not None:
        coords["state_in"] = _str_array(names)

    provenance = dict(traj.provenance or {})
    status = Status(traj.status)
    attrs = {
        "pwsdyn_type": TRAJECTORY_TYPE,
        "title": f"pwsdyn trajectory of model {model.name}",
        "model": str(model.name),
        "model_hash": str(model.hash),
        "model_spec": _spec_to_json(model.spec),
        "params": _dumps(dict(traj.params)),
        "options": _dumps(dict(traj.options)),
        "status": status.name,
        "status_code": int(status),
        "message": str(traj.message),
        "stats": _dumps(dict(traj.stats)),
        "t0": float(traj.t0),
        "t_end": float(traj.t_end),
        "pwsdyn_version": str(provenance.get("pwsdyn_version", _library_version())),
        "provenance": _dumps(provenance),
    }
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)


def _library_version() -> str:
    from . import __version__

    return __version__


def _attr(ds: xr.Dataset, key: str):
    try:
        return ds.attrs[key]
    except KeyError:
        raise ArgumentError(f"the dataset has no attribute {key!r}; it was not written by "
                         f"pwsdyn.io.trajectory_to_dataset") from None


def _strings(da) -> list:
    # h5netcdf may hand back bytes or numpy str_ scalars; the Trajectory holds Python str
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.asarray(da).tolist()]


def trajectory_from_dataset(ds: xr.Dataset, model=None):
    """Rebuild a :class:`~pwsdyn.integrate.trajectory.Trajectory` from its dataset.

    Parameters
    ----------
    ds : xarray.Dataset
        A dataset made by :func:`trajectory_to_dataset` (or read from its NetCDF file).
    model : Model, str, path or dict, optional
        The model to attach. By default it is rebuilt from the ``model_spec`` attribute with
        :func:`pwsdyn.load_model`; a warning is issued if its hash differs from the stored
        ``model_hash`` (the file was written by a version of pwsdyn that read the model
        differently).

    Returns
    -------
    Trajectory
        With the same nodes, event log, status and dense output: ``traj(t)`` gives the same
        numbers as the trajectory that was saved.

    Raises
    ------
    ValueError
        If ``ds`` is not a pwsdyn trajectory dataset.
    """
    from .integrate.trajectory import EventRecord, Trajectory
    from .model import load_model

    if not isinstance(ds, xr.Dataset):
        raise ArgumentError(f"`ds` must be an xarray.Dataset, got {type(ds).__name__}")
    kind = ds.attrs.get("pwsdyn_type")
    if kind != TRAJECTORY_TYPE:
        raise ArgumentError(f"the dataset is not a pwsdyn trajectory (attribute pwsdyn_type="
                         f"{kind!r}, expected {TRAJECTORY_TYPE!r})")
    stored_hash = str(_attr(ds, "model_hash"))
    if model is None:
        spec = json.loads(_attr(ds, "model_spec"))
        if not spec:
            raise ArgumentError("the dataset holds no model definition (`model_spec` is empty); "
                             "pass the model with `model=`")
        model = load_model(spec)
        if model.hash != stored_hash:
            warnings.warn(f"the model rebuilt from the file has hash {model.hash}, the file "
                          f"records {stored_hash}: the model definition was read differently "
                          f"(written by pwsdyn {ds.attrs.get('pwsdyn_version')})", stacklevel=2)
    else:
        model = load_model(model)

    names = list(model.states)
    stored_names = _strings(ds["state"].values)
    if stored_names != names:
        raise ArgumentError(f"the dataset has states {stored_names}, the model has {names}")
    n = len(names)

    t = np.ascontiguousarray(ds["t"].values, dtype=float)
    x = np.ascontiguousarray(ds["x"].values, dtype=float).reshape(len(t), n)
    y = np.ascontiguousarray(ds["y"].values, dtype=float) if "y" in ds else x.copy()
    dense = np.ascontiguousarray(ds["dense"].values, dtype=float) if "dense" in ds else None
    ikind = (np.ascontiguousarray(ds["interval_kind"].values, dtype=np.int64)
             if "interval_kind" in ds else None)
    jac = np.ascontiguousarray(ds["jacobian"].values, dtype=float) if "jacobian" in ds else None

    ev_t = ds["event_t"].values
    ev_t2 = ds["event_t_after"].values
    ev_name = _strings(ds["event_name"].values)
    ev_kind = _strings(ds["event_kind"].values)
    ev_mb = _strings(ds["event_mode_before"].values)
    ev_ma = _strings(ds["event_mode_after"].values)
    ev_xb = np.asarray(ds["event_x_before"].values, dtype=float).reshape(len(ev_t), n)
    ev_xa = np.asarray(ds["event_x_after"].values, dtype=float).reshape(len(ev_t), n)
    events = [EventRecord(float(ev_t[r]), ev_name[r], ev_kind[r], ev_xb[r].copy(),
                          ev_xa[r].copy(), ev_mb[r], ev_ma[r], float(ev_t2[r]))
              for r in range(len(ev_t))]

    status_name = str(_attr(ds, "status"))
    try:
        status = Status[status_name]
    except KeyError:
        raise ArgumentError(f"unknown status {status_name!r} in the dataset; statuses are "
                         f"{[s.name for s in Status]}") from None
    provenance = _json_restore(json.loads(ds.attrs.get("provenance", "{}")))
    return Trajectory(
        t=t, x=x, state=np.array(_strings(ds["discrete_state"].values), dtype=str),
        events=events, status=status,
        message=str(ds.attrs.get("message", status.message)),
        stats=json.loads(ds.attrs.get("stats", "{}")),
        model=model,
        params={k: float(v) for k, v in _json_restore(json.loads(_attr(ds, "params"))).items()},
        options=_json_restore(json.loads(ds.attrs.get("options", "{}")),
                              keep_strings=_STRING_OPTIONS),
        t0=float(_attr(ds, "t0")), t_end=float(_attr(ds, "t_end")), jacobian=jac,
        _dense=dense, _ikind=ikind, _y=y, provenance=provenance,
    )


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
    one step, so ``path`` is never left half-written.

    Parameters
    ----------
    ds : xarray.Dataset or Trajectory
        A trajectory is converted with :func:`trajectory_to_dataset`.
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
        if hasattr(ds, "events") and hasattr(ds, "model"):
            ds = trajectory_to_dataset(ds)
        else:
            raise ArgumentError(f"`ds` must be an xarray.Dataset or a Trajectory, got "
                            f"{type(ds).__name__}")

    def write(tmp):
        with _engine_hint():
            ds.to_netcdf(tmp, engine=ENGINE)

    return atomic_write(path, write, overwrite=overwrite)


#: How to ask for an existing file to be replaced, in the API (the CLI says ``--force``).
OVERWRITE_HINT = "pass overwrite=True to replace it"


def _check_output_path(path, *, overwrite: bool = False, hint: str = OVERWRITE_HINT) -> Path:
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
    path = _check_output_path(path, overwrite=overwrite)
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
    with _engine_hint():
        if lazy:
            return xr.open_dataset(path, engine=ENGINE)
        return xr.load_dataset(path, engine=ENGINE)


def load_trajectory(path, model=None):
    """Read a trajectory saved with :meth:`Trajectory.save` or :func:`save_dataset`.

    Parameters
    ----------
    path : str or pathlib.Path
    model : optional
        See :func:`trajectory_from_dataset`.

    Returns
    -------
    Trajectory
    """
    return trajectory_from_dataset(open_dataset(path), model=model)
