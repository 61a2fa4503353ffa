"""Trajectories as labelled arrays (xarray) and NetCDF files; the metadata of every file.

A :class:`~pwsdyn.integrate.trajectory.Trajectory` becomes an :class:`xarray.Dataset` that
holds everything needed to rebuild it: the nodes, the event log, the dense output, and the
model itself (its definition as JSON in the attributes), so that a saved trajectory can be
reloaded in another process and evaluated at any time with results identical to the last bit.

Self-describing files
---------------------
Every file pwsdyn writes (trajectories, periodic orbits, sweeps, basins, Lyapunov spectra and
the chunk files of their stores) follows the CF conventions (``Conventions = "CF-1.10"``):

* variables have a ``long_name`` and, where the model's ``[units]`` table gives them, ``units``
  (UDUNITS strings as the model writes them; ``"1"`` for counts, phases, multipliers). A
  variable over the ``state`` dimension has ``units`` when all states share one; otherwise
  the per-state units are the auxiliary coordinate ``state_units`` (and ``state_long_name``
  the ``[descriptions]``);
* integer codes (``status``, ``interval_kind``, basin ``label``) have ``flag_values`` and
  ``flag_meanings``;
* global attributes: ``title``, ``source``, ``references`` (the model's), the versions of
  pwsdyn, numpy, scipy, numba, xarray and sympy (``<name>_version``), the model's name, hash,
  definition (``model_spec``, JSON) and full text (``model_text``: the TOML source, or for a
  model built from a dict its definition as indented JSON; ``model_text_format`` says which),
  ``model_units`` and ``model_descriptions`` (JSON); ``date_created`` (ISO 8601, UTC) and
  ``history`` are added when the file is written (:func:`save_dataset`).

Files are read back with the times and units as numbers (:func:`open_dataset` decodes no
dates or time deltas). Files written before these attributes existed read as before.

Layout of a trajectory dataset
------------------------------
Dimensions and coordinates:

``node``
    Stored nodes (accepted steps and both sides of every event). The coordinate ``t``
    (over ``node``) is the time of each node: a coordinate, not an index, because both sides
    of an event share one time.
``state``
    State names of the model, with ``state_units`` and ``state_long_name``.
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

Variables: ``x``, ``discrete_state``, ``y``, ``interval_kind``, ``dense``, the event log
(``event_t``, ``event_t_after``, ``event_name``, ``event_kind``, ``event_mode_before``,
``event_mode_after``, ``event_x_before``, ``event_x_after``), ``jacobian`` and the scalar
``status`` (a :class:`~pwsdyn.Status` code with its flags).

Attributes: those above, ``pwsdyn_type`` (``"trajectory"``), ``params``, ``parameter_units``,
``options`` and ``stats`` (JSON), ``status`` (the :class:`~pwsdyn.Status` name),
``status_code``, ``message``, ``t0``, ``t_end`` and ``provenance`` (JSON).

This module only reads result objects; the numerical code never imports it.
"""

from __future__ import annotations

import contextlib
import dataclasses
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
    :data:`VERSIONED_PACKAGES` (``"unknown"`` where a version cannot be found)."""
    from importlib import metadata

    out = {}
    for name in VERSIONED_PACKAGES:
        if name == "pwsdyn":
            out["pwsdyn_version"] = _library_version()
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
        "source": f"pwsdyn {_library_version()}: {source}",
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
        "state": ("state", _str_array(names), {"long_name": "state variable"}),
        "state_units": ("state", _str_array(model.unit(s) or "" for s in names),
                        {"long_name": "unit of the state variable (empty: not given)"}),
        "state_long_name": ("state", _str_array(model.describe(s) or s for s in names),
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
    """The codes of a ``status`` variable of a sweep or a Lyapunov result: 0 success, the
    :class:`~pwsdyn.Status` of a failed flow run (maps: 2 no piece applies, 3 non-finite),
    -1 diverged, -3 the section at the end of the window was not logged (sweeps)."""
    if is_map:
        codes = {0: "success", 2: "no_piece_applies", 3: "nonfinite"}
    else:
        codes = {int(s): s.name.lower() for s in Status if s.failed}
        codes[0] = "success"
        if section_missed:
            codes[-3] = "section_missed"
    codes[-1] = "diverged"
    return codes


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
    line = f"{now} written by pwsdyn {_library_version()}"
    old = str(ds.attrs.get("history", "") or "")
    ds.attrs["history"] = f"{old}\n{line}" if old else line
    return ds


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

    tattrs = quantity_attrs(model, "t", "time")
    data_vars = {
        "x": (("node", "state"), x, state_attrs(model, "state at the node")),
        "discrete_state": (("node",), _str_array(traj.state),
                           {"long_name": "discrete state at the node: mode name, "
                                         "stick:<event> or slide:<switch>"}),
        "y": (("node", "ycomp"), y,
              {"long_name": "full node vector: state, then variational matrix (row-major)"}),
    }
    if traj._ikind is not None:
        data_vars["interval_kind"] = (
            ("interval",), np.asarray(traj._ikind, dtype=np.int64),
            {"long_name": "how the interval after the node is evaluated",
             **flag_attrs({0: "dense_polynomial", 1: "linear_jump_or_no_dense_output",
                           2: "linear_chattering_gap"})})
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
                    {**tattrs, "long_name": "time of the event (start of a chattering "
                                            "sequence)"}),
        "event_t_after": (("event",), np.array([e.t_after for e in ev], dtype=float),
                          {**tattrs, "long_name": "time after the event (accumulation time "
                                                  "of chatter)"}),
        "event_name": (("event",), _str_array(e.name for e in ev),
                       {"long_name": "name of the event or switch"}),
        "event_kind": (("event",), _str_array(e.kind for e in ev),
                       {"long_name": "kind of the event record (impact, transition, "
                                     "crossing, chatter, stick, release, slide_start, "
                                     "slide_end, ...)"}),
        "event_mode_before": (("event",), _str_array(e.mode_before for e in ev),
                              {"long_name": "discrete state before the event"}),
        "event_mode_after": (("event",), _str_array(e.mode_after for e in ev),
                             {"long_name": "discrete state after the event"}),
        "event_x_before": (("event", "state"), evx("x_before"),
                           state_attrs(model, "state just before the event")),
        "event_x_after": (("event", "state"), evx("x_after"),
                          state_attrs(model, "state just after the event")),
    })
    if traj.jacobian is not None:
        data_vars["jacobian"] = (
            ("state", "state_in"), np.asarray(traj.jacobian, dtype=float),
            {"long_name": "derivative of the final state with respect to the initial state"})

    status = Status(traj.status)
    data_vars["status"] = ((), np.int64(int(status)),
                           {"long_name": "how the simulation ended",
                            **flag_attrs({int(s): s.name.lower() for s in Status})})

    coords = {
        "node": ("node", np.arange(len(t)), {"long_name": "index of the stored node"}),
        # the time of each node: a coordinate, not an index (both sides of an event share it)
        "t": ("node", t, tattrs),
        **state_coords(model),
        "event": ("event", np.arange(ne), {"long_name": "index of the event record"}),
        "ycomp": ("ycomp", _str_array(_ycomp_labels(names, ny)),
                  {"long_name": "component of the full node vector"}),
    }
    if traj.jacobian is not None:
        coords["state_in"] = ("state_in", _str_array(names),
                              {"long_name": "initial state variable"})

    provenance = dict(traj.provenance or {})
    attrs = {
        **cf_global_attrs(model, TRAJECTORY_TYPE,
                          f"pwsdyn trajectory of model {model.name}",
                          f"event-driven simulation (pwsdyn.simulate, method "
                          f"{traj.options.get('method', '?')})"),
        "params": _dumps(dict(traj.params)),
        "parameter_units": json.dumps({k: model.unit(k) for k in model.parameters
                                       if model.unit(k) is not None}),
        "options": _dumps(dict(traj.options)),
        "status": status.name,
        "status_code": int(status),
        "message": str(traj.message),
        "stats": _dumps(dict(traj.stats)),
        "t0": float(traj.t0),
        "t_end": float(traj.t_end),
        "provenance": _dumps(provenance),
    }
    # the version that made the data (a reloaded trajectory keeps its own)
    attrs["pwsdyn_version"] = str(provenance.get("pwsdyn_version", _library_version()))
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
        elif ds.attrs.get("model_text_format") == "toml" and ds.attrs.get("model_text"):
            # keep the TOML source with the model, so that the next file carries it too
            model = dataclasses.replace(model, text=str(ds.attrs["model_text"]))
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
    one step, so ``path`` is never left half-written. The file gets the global attributes
    ``date_created`` (ISO 8601, UTC; a dataset that has one keeps it) and ``history`` (a
    line appended); ``ds`` itself is not changed.

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

    ds = stamp(ds)

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
    # times and rates carry the model's units ("s", "seconds"...): numbers, never decoded to
    # dates or timedeltas
    kwargs = {"engine": ENGINE, "decode_times": False, "decode_timedelta": False}
    with _engine_hint():
        if lazy:
            return xr.open_dataset(path, **kwargs)
        return xr.load_dataset(path, **kwargs)


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
