"""The :class:`PeriodicOrbit` result and the merging of shooting intervals into one trajectory."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .._version import __version__
from ..errors import Status
from ..integrate.trajectory import Trajectory

if TYPE_CHECKING:
    from pathlib import Path

    import xarray as xr

    from .._typing import PathLike



class RecurrenceWarning(UserWarning):
    """:meth:`PeriodicOrbit.from_trajectory` found that the trajectory does not recur after the
    period it would otherwise use: the period was changed to the one it recurs at, or (an
    explicit request, or no recurrence at all) the orbit refined need not be the motion of the
    run. The orbit's ``recurrence`` has the details."""


@dataclass(frozen=True)
class Recurrence:
    """How :meth:`~pwsdyn.PeriodicOrbit.from_trajectory` chose the period: the recurrence of the
    end of the trajectory.

    Attributes
    ----------
    period : float or None
        The smallest time after which the end of the trajectory recurs to ``tol``: ``periods``
        forcing periods (forced models) or the time between recurring events (autonomous);
        ``None`` when it does not recur within ``max_periods`` forcing periods (or the run).
    periods : int or None
        Forced models: ``period`` in forcing periods.
    requested : int or None
        Forced models: the forcing periods asked for explicitly (``periods=`` or ``period=``);
        ``None`` when the period was left to the recurrence.
    used : int or None
        Forced models: the forcing periods of the guess that was refined (``orbit.periods``).
    time : float
        Forced models: the time ``tc`` of the last forcing period whose state is compared with
        those at ``tc - k * forcing_period`` (the middle of the longest event-free stretch);
        autonomous models: the time of the last event.
    distances : tuple of float
        Forced models: ``max|x(tc - k T_f) - x(tc)| / (1 + max|x|)`` for ``k = 1, 2, ...``
        (``max|x|`` over the last forcing period); autonomous models: the same distance of the
        post-event states of the recurring event.
    same_state : tuple of bool
        Whether the discrete state (mode, or the sticking or sliding constraint) at
        ``tc - k T_f`` is the one at ``tc``; a recurrence needs both.
    tol : float
        ``recurrence_tol``.
    max_periods : int or None
        Forced models: the most forcing periods searched.
    message : str
        The :class:`~pwsdyn.RecurrenceWarning` issued, ``''`` if none.
    """

    period: float | None
    periods: int | None
    requested: int | None
    used: int | None
    time: float
    distances: tuple
    same_state: tuple
    tol: float
    max_periods: int | None
    message: str = ""

    @property
    def settled(self) -> bool:
        """The trajectory recurs within the periods searched."""
        return self.period is not None


@dataclass(eq=False)
class PeriodicOrbit:
    """A periodic orbit of a hybrid model with its Floquet multipliers.

    Create one with :func:`pwsdyn.find_periodic_orbit` (from a guess) or
    :meth:`PeriodicOrbit.from_trajectory` (from a simulation).

    Attributes
    ----------
    model : Model
    params : dict
        Parameter values.
    t0 : float
        Initial time of the period (the phase of a forced orbit).
    x0 : numpy.ndarray
        State at ``t0``.
    state0 : str
        Discrete state at ``t0`` (mode name, ``stick:<event>``, ``slide:<switch>``).
    period : float
        ``n * forcing_period`` for a forced model; found by Newton for an autonomous one.
    events : list[EventRecord]
        The events over one period, as in ``Trajectory.events``: the orbit's signature.
    trajectory : Trajectory
        One period, with dense output and the variational solution (``transfer_matrices``).
    monodromy : numpy.ndarray, shape (n, n)
        Jacobian of the one-period map at ``(t0, x0)``, the ordered product of the flow
        Jacobians of the smooth segments and the **full** saltation matrices of the events
        (``trajectory.transfer_matrices``). An autonomous orbit's monodromy has the trivial
        multiplier 1 along the vector field.
    multipliers : numpy.ndarray
        Nontrivial Floquet multipliers, by decreasing modulus: all eigenvalues of
        ``monodromy`` for a forced orbit; for an autonomous one the eigenvalues of the Poincaré
        map on the phase-condition section (thesis eq. 2.25), ``n - 1`` of them.
    stable : bool
        Every multiplier inside the unit circle (modulus below ``1 - 1e-8``: a multiplier on
        the unit circle to the accuracy of the monodromy is not asymptotic stability).
    history : list[float]
        Newton residual norm (max norm of the shooting residual relative to ``1 + |x|``) of each
        iterate, the converged one last.
    converged : bool
    autonomous : bool
        The period is an unknown (no ``forcing_period``).
    trivial_multiplier : complex or None
        Autonomous orbits: the eigenvalue of ``monodromy`` nearest 1 (1 up to the accuracy
        of the variational solution).
    poincare_jacobian : numpy.ndarray or None
        Autonomous orbits: the Poincaré-map Jacobian of thesis eq. 2.25 on the phase-condition
        section through ``x0``, ``(I - f h_x / (h_x f)) monodromy``; it has eigenvalue 0 where
        the monodromy has the trivial 1.
    phase_normal : numpy.ndarray or None
        Autonomous orbits: normal ``h_x`` of the phase-condition section.
    nodes : numpy.ndarray
        Times of the multiple-shooting nodes (``t0`` first).
    residual : float
        Last entry of ``history``.
    closure : float
        ``|x(t0 + period) - x0|`` (max norm) of ``trajectory``: the junctions between the
        shooting intervals, at the Newton tolerance.
    options : dict
        Integrator and solver options used.
    recurrence : Recurrence or None
        Orbits from :meth:`from_trajectory`: how the period was chosen from the recurrence of
        the trajectory (``None`` for :func:`pwsdyn.find_periodic_orbit`, for an autonomous
        model given ``period``, and for a ``period`` that is not a multiple of the forcing
        period).
    admissible : bool
        The orbit is a solution of the hybrid model. Always true for an orbit found by
        free-running shooting (the simulator made it); an orbit solved on a locked signature
        (``find_periodic_orbit(..., signature=...)``, :class:`~pwsdyn.orbits.OrbitProblem`)
        may have been followed past a grazing or sliding bifurcation, where it crosses a
        surface it must not cross or meets one with the wrong sign of the normal velocity.
    reason : str or None
        Why it is not admissible (``None`` when it is).
    locked : bool
        Solved on a fixed signature (:class:`~pwsdyn.orbits.OrbitProblem`): its trajectory is
        assembled from the segments integrated in their discrete states.
    """

    model: object
    params: dict
    t0: float
    x0: np.ndarray
    state0: str
    period: float
    events: list
    trajectory: Trajectory | None
    monodromy: np.ndarray | None
    multipliers: np.ndarray | None
    stable: bool | None
    history: list
    converged: bool
    autonomous: bool
    trivial_multiplier: complex | None = None
    poincare_jacobian: np.ndarray | None = None
    phase_normal: np.ndarray | None = None
    nodes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    residual: float = np.nan
    closure: float = np.nan
    options: dict = field(default_factory=dict)
    recurrence: Recurrence | None = None
    admissible: bool = True
    reason: str | None = None
    locked: bool = False
    # (OrbitProblem, u, p) behind the orbit, made on demand for `sensitivity`
    _source: object = field(default=None, repr=False)

    # ------------------------------------------------------------------------------------
    @property
    def signature(self):
        """The events of one period from ``t0`` as a :class:`~pwsdyn.orbits.Signature`: a
        tuple of ``(kind, name, mode_before, mode_after)``, comparable, hashable and
        printable; pass it to ``find_periodic_orbit(..., signature=...)`` to lock it."""
        from .signature import Signature

        return Signature.from_events(self.events)

    # problem() and sensitivity() are given to this class by pwsdyn.orbits.problem, and
    # from_trajectory() by the shooting code (pwsdyn.orbits._shooting): they run a solver,
    # and the result type does not import its solvers (they import it)

    @property
    def transfer_matrices(self) -> list | None:
        """``[Phi_0, S_1, Phi_1, ..., S_m, Phi_m]`` over one period (full saltation form)."""
        return None if self.trajectory is None else self.trajectory.transfer_matrices

    @property
    def periods(self) -> int | None:
        """The period in forcing periods of a forced orbit (2 for a period-doubled orbit);
        ``None`` for an autonomous one."""
        if self.autonomous:
            return None
        Tf = self.model.forcing_period_at(self.model.parameter_vector(self.params))
        return None if Tf is None else int(round(self.period / Tf))

    @property
    def iterations(self) -> int:
        """Number of Newton steps taken."""
        return max(len(self.history) - 1, 0)

    def __repr__(self):
        from .._display import moduli, num

        status = ("stable" if self.stable else "unstable") if self.stable is not None else "?"
        conv = "" if self.converged else ", NOT converged"
        if not self.admissible:
            conv += ", NOT admissible"
        mods = "?" if self.multipliers is None else moduli(self.multipliers)
        return (f"PeriodicOrbit(model={getattr(self.model, 'name', '?')!r}, "
                f"period={num(self.period, 10)}, events={len(self.events or ())}, "
                f"|multipliers|={mods}, {status}{conv})")

    def _repr_html_(self):
        from .._display import html_table, moduli, num, state_text

        mult = self.multipliers
        rows = [("model", getattr(self.model, "name", "?")),
                ("period", num(self.period, 12)
                 + ("" if self.autonomous or self.periods is None
                    else f" ({self.periods} forcing period(s))")),
                ("start", f"t0 = {num(self.t0)}: "
                          f"{state_text(getattr(self.model, 'states', ()), self.x0)} "
                          f"in {self.state0}"),
                ("signature", f"{self.signature}" if self.events else "no events"),
                ("multipliers", "?" if mult is None else
                 ", ".join(_fmt_complex(m, 6) for m in np.atleast_1d(mult))),
                ("|multipliers|", "?" if mult is None else moduli(mult)),
                ("stable", "?" if self.stable is None else self.stable),
                ("converged", f"{self.converged} (residual {num(self.residual, 3)}, "
                              f"{self.iterations} Newton step(s))"),
                ("admissible", self.admissible if self.admissible else
                 f"False: {self.reason}")]
        if self.params:
            rows.append(("parameters", ", ".join(f"{k}={num(v)}"
                                                 for k, v in self.params.items())))
        return html_table("PeriodicOrbit", rows)

    def summary(self) -> str:
        """A multi-line human-readable report (period, signature, multipliers, Newton)."""
        lines = [f"model       {self.model.name}",
                 "parameters  " + (", ".join(f"{k}={v:.10g}" for k, v in self.params.items())
                                   or "(none)"),
                 f"period      {self.period:.15g}"
                 + ("  (autonomous: found by Newton)" if self.autonomous else
                    f"  (forced: {self.periods} forcing period(s))"),
                 f"t0          {self.t0:.15g}  in {self.state0}",
                 "x0          " + ", ".join(f"{s}={v:.15g}"
                                            for s, v in zip(self.model.states, self.x0))]
        lines.append(f"signature   {len(self.events)} event(s) per period"
                     + ("  (locked)" if self.locked else ""))
        for e in self.events:
            lines.append(f"  t0+{e.t - self.t0:<12.8g} {e.kind:<11} {e.name:<12} "
                         f"{e.mode_before} -> {e.mode_after}")
        if self.multipliers is not None:
            lines.append("multipliers " + ("(nontrivial; trivial 1 removed)"
                                           if self.autonomous else "(time-T map)"))
            for m in np.atleast_1d(self.multipliers):
                lines.append(f"  {_fmt_complex(m):<40} |mu| = {abs(m):.10g}")
            if self.trivial_multiplier is not None:
                lines.append(f"trivial     {_fmt_complex(self.trivial_multiplier)} "
                             f"(|mu - 1| = {abs(self.trivial_multiplier - 1):.2e})")
            lines.append(f"stability   {'stable' if self.stable else 'unstable'}")
        if not self.admissible:
            lines.append(f"NOT ADMISSIBLE: {self.reason}")
        lines.append(f"newton      {self.iterations} iteration(s), "
                     f"{len(self.nodes)} shooting node(s), residuals "
                     + " ".join(f"{r:.2e}" for r in self.history)
                     + ("" if self.converged else "  NOT CONVERGED"))
        return "\n".join(lines)

    # ------------------------------------------------------------------------------------
    def to_dataset(self) -> xr.Dataset:
        """One period as an :class:`xarray.Dataset`: the trajectory's layout plus
        ``monodromy``, ``multiplier_real``/``multiplier_imag``, ``newton_residual`` and the
        period, ``t0``, stability in the attributes."""
        import json

        if self.trajectory is None:
            raise ValueError("this orbit has no trajectory to save")
        from .._netcdf import library_version, quantity_attrs

        ds = self.trajectory.to_dataset()
        n = len(self.model.states)
        if "state_in" not in ds.coords:
            ds = ds.assign_coords(state_in=("state_in", ds["state"].values,
                                            {"long_name": "initial state variable"}))
        ds["monodromy"] = (("state", "state_in"), np.asarray(self.monodromy, dtype=float),
                           {"long_name": "one-period Jacobian with full saltation matrices"})
        mult = np.atleast_1d(np.asarray(self.multipliers, dtype=complex))
        ds["multiplier_real"] = (("multiplier",), mult.real,
                                 {"long_name": "real part of the Floquet multiplier",
                                  "units": "1"})
        ds["multiplier_imag"] = (("multiplier",), mult.imag,
                                 {"long_name": "imaginary part of the Floquet multiplier",
                                  "units": "1"})
        ds["newton_residual"] = (("newton_iterate",), np.asarray(self.history, dtype=float),
                                 {"long_name": "shooting residual (max norm relative to "
                                               "1 + max|x|) after each Newton iterate",
                                  "units": "1"})
        ds["shooting_node"] = (("node_index",), np.asarray(self.nodes, dtype=float),
                               {**quantity_attrs(self.model, "t", "time"),
                                "long_name": "time of the shooting node"})
        if self.poincare_jacobian is not None:
            ds["poincare_jacobian"] = (("state", "state_in"), self.poincare_jacobian,
                                       {"long_name": "Jacobian of the Poincare map"})
        ds.attrs.update({
            "pwsdyn_type": "periodic_orbit",
            "source": f"pwsdyn {library_version()}: Newton shooting "
                      "(pwsdyn.find_periodic_orbit), one period simulated",
            "title": f"pwsdyn periodic orbit of model {self.model.name}",
            "period": float(self.period), "orbit_t0": float(self.t0),
            "orbit_x0": json.dumps([float(v) for v in self.x0]),
            "orbit_state0": str(self.state0), "stable": int(bool(self.stable)),
            "converged": int(bool(self.converged)), "autonomous": int(bool(self.autonomous)),
            "signature": json.dumps([list(s) for s in self.signature]),
            "admissible": int(bool(self.admissible)), "locked": int(bool(self.locked)),
            "admissibility_reason": self.reason or "",
            "n_states": n,
        })
        return ds

    def save(self, path: PathLike, overwrite: bool = False) -> Path:
        """Write :meth:`to_dataset` to a NetCDF file; an existing file is refused
        (:class:`~pwsdyn.OutputExistsError`) unless ``overwrite=True``."""
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)


class DeferredTrajectory:
    """A :class:`PeriodicOrbit`'s trajectory not made yet: ``make()`` integrates it when the
    orbit's ``trajectory`` is first read (the dense runs of the shooting intervals, which the
    Newton iterations and the multipliers do not need)."""

    __slots__ = ("make",)

    def __init__(self, make):
        self.make = make


class _TrajectoryField:
    """One period as a :class:`~pwsdyn.Trajectory`, with dense output and the variational
    solution (``transfer_matrices``); for an orbit found by shooting it is integrated when
    first read."""

    # a plain attribute, except that a ``DeferredTrajectory`` given to it is made (once)
    # when it is read; this docstring is the attribute's on the API pages

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        value = obj.__dict__["_trajectory"]
        if isinstance(value, DeferredTrajectory):
            value = obj.__dict__["_trajectory"] = value.make()
        return value

    def __set__(self, obj, value):
        obj.__dict__["_trajectory"] = value


def _orbit_getstate(self):
    # a deferred trajectory holds the solver's closure: made before the orbit is pickled
    # or deep-copied
    self.trajectory
    return dict(self.__dict__)


# (set after the dataclass is made, so that its __init__ assigns through the descriptor)
PeriodicOrbit.trajectory = _TrajectoryField()
PeriodicOrbit.__getstate__ = _orbit_getstate


def _fmt_complex(m, digits: int = 12) -> str:
    m = complex(m)
    if m.imag == 0:
        return f"{m.real:.{digits}g}"
    return f"{m.real:.{digits}g}{m.imag:+.{digits}g}j"


def merge_intervals(trajs: list, *, t0: float, t_end: float) -> Trajectory:
    """Concatenate the trajectories of consecutive shooting intervals into one.

    Each interval's variational solution starts at the identity; here it is multiplied by the
    Jacobian accumulated over the previous intervals, and the transfer matrices are joined (the
    last flow matrix of one interval and the first of the next belong to one smooth segment).
    The junctions between intervals are stored as jumps of the size of the shooting residual.
    """
    first = trajs[0]
    model = first.model
    n = model.n_states
    variational = first.transfer_matrices is not None
    P = np.eye(n)
    ts, xs, ys, states, dense, ikind, events = [], [], [], [], [], [], []
    transfer = None
    stats: dict = {}
    for i, tr in enumerate(trajs):
        y = np.array(tr.y, dtype=float, copy=True)
        d = None if tr.dense is None else np.array(tr.dense, dtype=float, copy=True)
        if variational:
            N = len(y)
            y[:, n:n + n * n] = np.matmul(y[:, n:n + n * n].reshape(N, n, n), P).reshape(N, -1)
            if d is not None and len(d):
                d[:, n:n + n * n, :] = np.einsum("iabk,bc->iack",
                                                 d[:, n:n + n * n, :].reshape(len(d), n, n, -1),
                                                 P).reshape(len(d), n * n, -1)
            tm = [m.copy() for m in tr.transfer_matrices]
            if transfer is None:
                transfer = tm
            else:
                transfer[-1] = tm[0] @ transfer[-1]
                transfer += tm[1:]
            P = tr.jacobian @ P
        if i > 0:
            # a zero-length jump interval joins the previous interval's end to this start
            ikind.append(np.array([1], dtype=np.int64))
            if d is not None:
                dense.append(np.zeros((1,) + d.shape[1:]))
        ts.append(np.asarray(tr.t, dtype=float))
        xs.append(np.asarray(tr.x, dtype=float))
        ys.append(y)
        states.append(np.asarray(tr.state))
        ikind.append(np.asarray(tr.interval_kind, dtype=np.int64))
        if d is not None:
            dense.append(d)
        events += list(tr.events)
        for k, v in tr.stats.items():
            stats[k] = stats.get(k, 0) + v
    has_dense = all(tr.dense is not None for tr in trajs)
    return Trajectory.from_parts(
        t=np.concatenate(ts), x=np.concatenate(xs), state=np.concatenate(states), events=events,
        status=Status.SUCCESS, message=Status.SUCCESS.message, stats=stats, model=model,
        params=dict(first.params), options=dict(first.options), t0=float(t0), t_end=float(t_end),
        jacobian=P if variational else None, transfer_matrices=transfer,
        dense=np.concatenate(dense) if has_dense else None, interval_kind=np.concatenate(ikind),
        y=np.concatenate(ys),
        provenance={"model": model.name, "model_hash": model.hash, "pwsdyn_version": __version__},
    )
