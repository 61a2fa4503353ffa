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

This module is the public face of the files: every result lays out its own dataset
(``to_dataset()``; a trajectory's layout is in ``pwsdyn._trajectory_file``, which
``Trajectory.to_dataset`` and ``Trajectory.from_dataset`` call) with the shared plumbing of
``pwsdyn._netcdf``, re-exported here. Imports run one way: this module ->
:mod:`pwsdyn.integrate.trajectory` -> ``pwsdyn._trajectory_file`` -> ``pwsdyn._netcdf``.
"""

from __future__ import annotations

from ._netcdf import (CONVENTIONS, ENGINE, OVERWRITE_HINT, TRAJECTORY_TYPE,
                      VERSIONED_PACKAGES, atomic_write, cf_global_attrs,
                      decode_status, flag_attrs, inverse_time_units, model_attrs, model_text,
                      open_dataset, package_versions, quantity_attrs, run_status_codes,
                      save_dataset, stamp, state_attrs, state_coords, status_codes,
                      time_units)
from .integrate.trajectory import trajectory_from_dataset, trajectory_to_dataset

__all__ = ["CONVENTIONS", "ENGINE", "OVERWRITE_HINT", "TRAJECTORY_TYPE", "VERSIONED_PACKAGES",
           "atomic_write", "cf_global_attrs", "decode_status", "flag_attrs",
           "inverse_time_units", "load_trajectory", "model_attrs", "model_text",
           "open_dataset", "package_versions", "quantity_attrs", "run_status_codes",
           "save_dataset", "stamp", "state_attrs", "state_coords", "status_codes",
           "time_units", "trajectory_from_dataset", "trajectory_to_dataset"]


def load_trajectory(path, model=None):
    """Read a trajectory saved with :meth:`~pwsdyn.Trajectory.save` or :func:`save_dataset`.

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
