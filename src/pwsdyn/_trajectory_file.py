"""The layout of a trajectory file: a trajectory as an :class:`xarray.Dataset` and back.

The layout (nodes, event log, dense output, the model as JSON, provenance) is described in
:mod:`pwsdyn.io`; the attributes every file shares come from :mod:`pwsdyn._netcdf`.

This module imports no result type, so that :class:`~pwsdyn.integrate.trajectory.Trajectory`
can call it to save and load itself without a circle: it reads a trajectory through its
public attributes, and :func:`dataset_fields` gives back the fields
:meth:`~pwsdyn.integrate.trajectory.Trajectory.from_parts` takes, the event log as rows in
the order of :class:`~pwsdyn.integrate.trajectory.EventRecord`'s fields. The direction is
``pwsdyn.io`` -> ``pwsdyn.integrate.trajectory`` -> this module -> ``pwsdyn._netcdf``,
``pwsdyn.model``.
"""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import xarray as xr

from ._netcdf import (TRAJECTORY_TYPE, _STRING_OPTIONS, json_text, _json_restore,
                      library_version, string_array, cf_global_attrs, flag_attrs,
                      quantity_attrs, state_attrs, state_coords, status_codes)
from .errors import ArgumentError, Status
from .model import load_model


def _ycomp_labels(state_names, ny: int) -> list:
    n = len(state_names)
    labels = list(state_names)
    if ny == n + n * n:
        labels += [f"Phi[{a},{b}]" for a in state_names for b in state_names]
    else:
        labels += [f"y{k}" for k in range(n, ny)]
    return labels


def trajectory_dataset(traj) -> xr.Dataset:
    """The dataset of a trajectory (see :func:`pwsdyn.io.trajectory_to_dataset`).

    ``traj`` is read through the public attributes of a
    :class:`~pwsdyn.integrate.trajectory.Trajectory`; the caller checks its type.
    """
    model = traj.model
    names = list(model.states)
    n = len(names)
    t = np.asarray(traj.t, dtype=float)
    x = np.asarray(traj.x, dtype=float).reshape(len(t), n)
    y = np.asarray(traj.y, dtype=float)
    ny = y.shape[1]

    tattrs = quantity_attrs(model, "t", "time")
    data_vars = {
        "x": (("node", "state"), x, state_attrs(model, "state at the node")),
        "discrete_state": (("node",), string_array(traj.state),
                           {"long_name": "discrete state at the node: mode name, "
                                         "stick:<event> or slide:<switch>"}),
        "y": (("node", "ycomp"), y,
              {"long_name": "full node vector: state, then variational matrix (row-major)"}),
    }
    if traj.interval_kind is not None:
        data_vars["interval_kind"] = (
            ("interval",), np.asarray(traj.interval_kind, dtype=np.int64),
            {"long_name": "how the interval after the node is evaluated",
             **flag_attrs({0: "dense_polynomial", 1: "linear_jump_or_no_dense_output",
                           2: "linear_chattering_gap"})})
    if traj.dense is not None:
        dense = np.asarray(traj.dense, dtype=float)
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
        "event_name": (("event",), string_array(e.name for e in ev),
                       {"long_name": "name of the event or switch"}),
        "event_kind": (("event",), string_array(e.kind for e in ev),
                       {"long_name": "kind of the event record (impact, transition, "
                                     "crossing, chatter, stick, release, slide_start, "
                                     "slide_end, ...)"}),
        "event_mode_before": (("event",), string_array(e.mode_before for e in ev),
                              {"long_name": "discrete state before the event"}),
        "event_mode_after": (("event",), string_array(e.mode_after for e in ev),
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
                            **flag_attrs(status_codes(Status.integrator_outcomes()))})

    coords = {
        "node": ("node", np.arange(len(t)), {"long_name": "index of the stored node"}),
        # the time of each node: a coordinate, not an index (both sides of an event share it)
        "t": ("node", t, tattrs),
        **state_coords(model),
        "event": ("event", np.arange(ne), {"long_name": "index of the event record"}),
        "ycomp": ("ycomp", string_array(_ycomp_labels(names, ny)),
                  {"long_name": "component of the full node vector"}),
    }
    if traj.jacobian is not None:
        coords["state_in"] = ("state_in", string_array(names),
                              {"long_name": "initial state variable"})

    provenance = dict(traj.provenance or {})
    attrs = {
        **cf_global_attrs(model, TRAJECTORY_TYPE,
                          f"pwsdyn trajectory of model {model.name}",
                          f"event-driven simulation (pwsdyn.simulate, method "
                          f"{traj.options.get('method', '?')})"),
        "params": json_text(dict(traj.params)),
        "parameter_units": json.dumps({k: model.unit(k) for k in model.parameters
                                       if model.unit(k) is not None}),
        "options": json_text(dict(traj.options)),
        "status": status.name,
        "status_code": int(status),
        "message": str(traj.message),
        "stats": json_text(dict(traj.stats)),
        "t0": float(traj.t0),
        "t_end": float(traj.t_end),
        "provenance": json_text(provenance),
    }
    # the version that made the data (a reloaded trajectory keeps its own)
    attrs["pwsdyn_version"] = str(provenance.get("pwsdyn_version", library_version()))
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)


def _attr(ds, key: str):
    try:
        return ds.attrs[key]
    except KeyError:
        raise ArgumentError(f"the dataset has no attribute {key!r}; it was not written by "
                            f"pwsdyn.io.trajectory_to_dataset") from None


def _strings(da) -> list:
    # h5netcdf may hand back bytes or numpy str_ scalars; the Trajectory holds Python str
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.asarray(da).tolist()]


def dataset_fields(ds: xr.Dataset, model=None) -> tuple[dict, list]:
    """What a trajectory dataset holds: ``(fields, event_rows)``.

    ``fields`` are the keyword arguments of
    :meth:`~pwsdyn.integrate.trajectory.Trajectory.from_parts` but ``events``; each of
    ``event_rows`` is ``(t, name, kind, x_before, x_after, mode_before, mode_after,
    t_after)``, the fields of an :class:`~pwsdyn.integrate.trajectory.EventRecord` in order.
    ``model`` as in :func:`pwsdyn.io.trajectory_from_dataset`; a :class:`ValueError` (an
    :class:`~pwsdyn.errors.ArgumentError`) if ``ds`` is not a pwsdyn trajectory dataset.
    """
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
            raise ArgumentError("the dataset holds no model definition (`model_spec` is "
                                "empty); pass the model with `model=`")
        model = load_model(spec)
        if model.hash != stored_hash:
            # stacklevel: the caller of Trajectory.from_dataset
            warnings.warn(f"the model rebuilt from the file has hash {model.hash}, the file "
                          f"records {stored_hash}: the model definition was read differently "
                          f"(written by pwsdyn {ds.attrs.get('pwsdyn_version')})", stacklevel=3)
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
    event_rows = [(float(ev_t[r]), ev_name[r], ev_kind[r], ev_xb[r].copy(), ev_xa[r].copy(),
                   ev_mb[r], ev_ma[r], float(ev_t2[r])) for r in range(len(ev_t))]

    status_name = str(_attr(ds, "status"))
    try:
        status = Status[status_name]
    except KeyError:
        raise ArgumentError(f"unknown status {status_name!r} in the dataset; statuses are "
                            f"{[s.name for s in Status]}") from None
    provenance = _json_restore(json.loads(ds.attrs.get("provenance", "{}")))
    fields = dict(
        t=t, x=x, state=np.array(_strings(ds["discrete_state"].values), dtype=str),
        status=status,
        message=str(ds.attrs.get("message", status.message)),
        stats=json.loads(ds.attrs.get("stats", "{}")),
        model=model,
        params={k: float(v) for k, v in _json_restore(json.loads(_attr(ds, "params"))).items()},
        options=_json_restore(json.loads(ds.attrs.get("options", "{}")),
                              keep_strings=_STRING_OPTIONS),
        t0=float(_attr(ds, "t0")), t_end=float(_attr(ds, "t_end")), jacobian=jac,
        dense=dense, interval_kind=ikind, y=y, provenance=provenance,
    )
    return fields, event_rows
