"""Lyapunov spectra of piecewise-smooth flows and maps.

Flows: the variational equations ``Phi' = f_x Phi`` are integrated with the state and, at
every event, ``Phi`` is multiplied by the event's saltation matrix (impacts, crossings,
sliding entry and exit, the complete-chattering map; slides "Saltation matrices"). Tangent
dynamics that ignore these jumps give wrong exponents (ChaosTools.jl issue 324).
The run is cut into segments (default one forcing period): each segment starts from the end
state of the previous one with ``Phi = I``, so the kernel returns the segment's Jacobian
``J_k`` (saltations included); the tangent basis is updated by ``J_k Q = Q' R`` (QR
re-orthonormalisation, Benettin et al. 1980) and ``lambda_i = sum_k log|R_ii| / total time``.

The sum of the exponents is then ``log|det prod J_k| / time``, which by Liouville's formula
and ``det(S Phi) = det S det Phi`` equals the mean divergence ``tr f_x`` along the orbit plus
the mean of ``log|det S|`` over the events per unit time -- the sum rule that
tests/test_explore.py checks against closed forms of ``tr f_x`` and ``det S``.

Sticking (contact) is a reset, not a collapse: the state of a flow sticking on an impact
surface lies on the sticking manifold, so its tangent dynamics collapse a direction in finite
time and any average over a run with one sticking episode would be ``-inf``. Contact
episodes (complete chattering to release) are therefore left out of the tangent dynamics
and of the averaging time, and their time is reported apart (:class:`LyapunovSpectrum`,
Notes); the sum rule then holds for the free motion.

Maps: the same QR iteration with the Jacobian of the applied piece at every iterate
(:func:`pwsdyn.model.maps.lyapunov_kernel`), per iteration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, NamedTuple

import numpy as np

from .._version import __version__
from .. import _validate as V
from ..errors import ArgumentError, Status
from ..integrate.compiled import AfterEvents, KernelState, ModelContext
from ..integrate.options import check_mode, integrator_options
from ..model.spec import as_model
from ..integrate.trajectory import EVENT_KINDS
from .._codes import STICK
from ._common import check_bound, failed_status, readmit, start_of

if TYPE_CHECKING:
    from .._typing import ModelLike, StateLike


@dataclass
class LyapunovSpectrum:
    """The result of :func:`~pwsdyn.lyapunov_spectrum`.

    Attributes
    ----------
    exponents : numpy.ndarray, shape (n,)
        Lyapunov exponents in decreasing order, per unit time (flows) or per iteration (maps);
        flows with sticking: of the free motion, per unit free time (Notes). ``-inf`` where
        the tangent dynamics collapse a direction exactly (Filippov sliding: the saltation
        matrix of sliding entry has rank n - 1), or for a run that ends stuck for good.
    time : float
        Averaging time (flows: time units; maps: iterations): ``span`` less the contact
        episodes.
    convergence : numpy.ndarray, shape (n_segments, n)
        Running estimates after each segment (Gram-Schmidt order), to judge convergence
        (NaN while no free time has been averaged).
    events : dict
        Number of events of each kind in the averaging window (flows).
    status : Status
        ``Status.SUCCESS``, the :class:`pwsdyn.Status` of a failed simulation (flows) or
        iteration (maps: ``NO_PIECE_APPLIES``, ``NONFINITE``), or ``DIVERGED``.
    x_final : numpy.ndarray
    provenance : dict
    span : float
        Length of the averaging window (flows: segments done times ``segment``; maps:
        iterations).
    contact_time : float
        Time spent sticking in the window (each ``stick`` record to its ``release``, or to
        the window's end): the ``stick_time`` of :func:`pwsdyn.sweep` times the periods.
        ``span - time - contact_time`` is the chattering gaps (complete-chattering map) of
        the episodes.
    contact_episodes : int
        Sticking episodes begun in the window (``stick`` records).
    ends_stuck : bool
        The run ends sticking for good (see Notes; exponents ``-inf``).
    model : Model or MapModel, optional
        The model of the run (for :meth:`to_dataset`).

    Notes
    -----
    With contact (sticking): while a flow sticks on an impact surface (after complete
    chattering, until release) its state lies on the sticking manifold ``h = 0 = hdot``:
    perturbations off it vanish in finite time (the chattering saltation is rank-deficient),
    so the tangent dynamics of a sticking episode would make exponents ``-inf`` however
    short the episode. As in the nonsmooth-dynamics literature (Müller 1995; exponents of
    the free motion of systems with sticking), a *contact episode* -- from the
    complete-chattering map that ends the approach (its ``chatter`` record; a ``stick``
    record reached without one) to the ``release`` -- is a reset of the tangent dynamics,
    not part of the average: the tangent frame is re-orthonormalised where the episode
    begins and resumes unchanged at release (the episode's saltations and flow, chattering
    to release, are left out), and its duration is left out of ``time``. So ``exponents``
    are the exponents of the free motion (flight, impacts, other events) per unit *free*
    time, finite for intermittent sticking, and ``sum * time`` is the sum of ``log|det|`` of
    the free motion's transfer matrices. A run that ends sticking for good (an open episode
    at the end that does not release within one more window length ``span``: permanent
    sticking, the state has collapsed) has ``ends_stuck`` and exponents ``-inf``; a window
    spent sticking entirely that releases later has nothing to average: ``NaN``. Without
    sticking nothing changes: ``time == span`` and the exponents are the plain Benettin QR
    averages. The exponents of the free motion measure how perturbations grow between
    contacts: a motion synchronised by its contacts (a periodic orbit with one sticking
    episode per period, whose perturbations sticking removes) can have a positive one, so
    read them with ``contact_episodes`` and ``contact_fraction``. Filippov sliding is not a
    contact episode here: sliding entry still gives ``-inf`` (see ``exponents``).
    """

    exponents: np.ndarray
    time: float
    convergence: np.ndarray
    events: dict = field(default_factory=dict)
    status: int = 0
    x_final: np.ndarray | None = None
    provenance: dict = field(default_factory=dict)
    span: float | None = None
    contact_time: float = 0.0
    contact_episodes: int = 0
    ends_stuck: bool = False
    model: object = field(default=None, repr=False)

    def __post_init__(self):
        # an int code (an older pickle, a caller) is read as the member it is
        self.status = Status(int(self.status))
        if self.span is None:
            self.span = self.time

    def __repr__(self):
        from .._display import num

        exps = ", ".join(num(v) for v in np.atleast_1d(self.exponents))
        return (f"LyapunovSpectrum(model={getattr(self.model, 'name', '?')!r}, "
                f"exponents=[{exps}], time={num(self.time)}, status={self.status.name})")

    def _repr_html_(self):
        from .._display import counts_text, html_table, num

        rows = [("model", getattr(self.model, "name", "?")),
                ("exponents", ", ".join(num(v) for v in np.atleast_1d(self.exponents))),
                ("averaged over", f"{num(self.time)} of {num(self.span)}"),
                ("events", counts_text(self.events or {})),
                ("status", f"{self.status.name}: {self.status.message}")]
        if self.contact_episodes:
            rows.append(("contact", f"{self.contact_episodes} episode(s), "
                                    f"{num(self.contact_time)} sticking"
                                    + (", ends stuck" if self.ends_stuck else "")))
        return html_table("LyapunovSpectrum", rows)

    @property
    def sum(self) -> float:
        return float(np.sum(self.exponents))

    @property
    def contact_fraction(self) -> float:
        """``contact_time / span``: the fraction of the window spent sticking (0 if empty)."""
        return self.contact_time / self.span if self.span else 0.0

    def to_dataset(self):
        """The result as an :class:`xarray.Dataset` with CF attributes: ``exponents``
        (exponent), ``convergence`` (segment, exponent), ``x_final`` (state), the scalars
        ``time``, ``span``, ``contact_time``, ``contact_episodes``, ``ends_stuck`` and
        ``status`` (with its flags); the event counts, the provenance and the model (its full
        text) in the attributes."""
        import json

        import xarray as xr

        from .._netcdf import (json_text, cf_global_attrs, flag_attrs, inverse_time_units,
                               run_status_codes, state_attrs, state_coords, time_units)

        model = self.model
        if model is None:
            raise ArgumentError("this result has no model attached (it was not made by "
                                "pwsdyn.lyapunov_spectrum); it cannot be saved")
        is_map = bool(getattr(model, "is_map", False))
        n = model.n_states
        lu = {"units": inverse_time_units(model)} if inverse_time_units(model) else {}
        tu = {"units": time_units(model)} if time_units(model) else {}
        per = "per iteration" if is_map else "per unit time"
        x_final = (np.full(n, np.nan) if self.x_final is None
                   else np.asarray(self.x_final, dtype=float))
        conv = np.asarray(self.convergence, dtype=float).reshape(-1, n)
        data = {
            "exponents": (("exponent",), np.asarray(self.exponents, dtype=float),
                          {"long_name": f"Lyapunov exponents, decreasing ({per})", **lu}),
            "convergence": (("segment", "exponent"), conv,
                            {"long_name": "running estimates after each segment "
                                          "(Gram-Schmidt order)", **lu}),
            "x_final": (("state",), x_final, state_attrs(model, "state at the end of the run")),
            "time": ((), float(self.time), {"long_name": "averaging time (the window less "
                                                         "the contact episodes)", **tu}),
            "span": ((), float(self.span), {"long_name": "length of the averaging window",
                                            **tu}),
            "contact_time": ((), float(self.contact_time),
                             {"long_name": "time spent sticking in the window", **tu}),
            "contact_episodes": ((), np.int64(self.contact_episodes),
                                 {"long_name": "sticking episodes begun in the window",
                                  "units": "1"}),
            "ends_stuck": ((), np.int8(bool(self.ends_stuck)),
                           {"long_name": "the run ends sticking for good",
                            **flag_attrs({0: "false", 1: "true"}, np.int8)}),
            "status": ((), np.int64(self.status),
                       {"long_name": "status of the run",
                        **flag_attrs(run_status_codes(is_map=is_map))}),
        }
        coords = {"exponent": ("exponent", np.arange(n),
                               {"long_name": "index of the exponent (decreasing)"}),
                  "segment": ("segment", np.arange(conv.shape[0]),
                              {"long_name": "index of the averaged segment"}),
                  **state_coords(model)}
        attrs = {**cf_global_attrs(model, "lyapunov_spectrum",
                                   f"pwsdyn Lyapunov spectrum of model {model.name}",
                                   "QR re-orthonormalisation of the tangent dynamics with "
                                   "saltation matrices (pwsdyn.lyapunov_spectrum)"),
                 "events": json.dumps(dict(self.events)),
                 "provenance": json_text(dict(self.provenance))}
        if "params" in self.provenance:
            attrs["params"] = json_text(dict(self.provenance["params"]))
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path, overwrite: bool = False):
        """Write :meth:`to_dataset` to a NetCDF file; an existing file is refused
        (:class:`~pwsdyn.OutputExistsError`) unless ``overwrite=True``."""
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)


#: Kernel event kind codes (``EventLog.kind_code``) that delimit contact episodes.
_CHATTER, _STICK, _RELEASE = (EVENT_KINDS.index(k) for k in ("chatter", "stick", "release"))


class FlowSegments(NamedTuple):
    """What :func:`flow_segments` returns (see :class:`LyapunovSpectrum` for the meaning of
    ``time``, ``contact_time``, ``contact_episodes``, ``ends_stuck``)."""

    exponents: np.ndarray     # (n,), Gram-Schmidt order (unsorted); NaN when nothing averaged
    sums: np.ndarray          # (n,) sums of log|R_ii|
    done: int                 # segments completed
    x: np.ndarray             # end state
    status: int
    starts: np.ndarray        # (n_seg, n) state at the start of each segment
    events: list              # with ``keep_events``
    running: np.ndarray       # (n_seg, n) running estimates
    span: float               # done * seg
    time: float               # averaging time: span less the contact episodes
    contact_time: float
    contact_episodes: int
    ends_stuck: bool


def _contact_marks(log, final_kind: int, in_contact: bool) -> list:
    """The records of one segment's event log at which a contact episode begins or ends:
    ``(record, +1)`` where an episode begins (the complete-chattering record whose
    accumulation point the ball sticks at, or a stick record reached without one), ``(record,
    0)`` at its stick record, ``(record, -1)`` where it ends (the release). A chattering record
    not followed by sticking is an episode of its own (its saltation is rank-deficient too):
    ``(record, +1)`` then ``(record, -1)``. ``in_contact``: the segment starts in one."""
    kinds = np.asarray(log.kind_code)
    m = len(kinds)
    marks = []
    for r in range(m):
        k = int(kinds[r])
        if not in_contact and k == _CHATTER:
            sticks = (kinds[r + 1] == _STICK) if r + 1 < m else (final_kind == 1)
            marks.append((r, 1))
            if not sticks:
                marks.append((r, -1))
            else:
                in_contact = True
        elif k == _STICK:
            if not in_contact:
                marks.append((r, 1))
                in_contact = True
            marks.append((r, 0))
        elif k == _RELEASE and in_contact:
            marks.append((r, -1))
            in_contact = False
    return marks


def flow_segments(ctx: ModelContext, x, t0: float, seg: float, n_seg: int, p, opts,
                  bound: float, keep_events: bool = False, discrete=None) -> FlowSegments:
    """Integrate ``n_seg`` segments of length ``seg`` with the variational equations and QR,
    excluding contact episodes (sticking on an impact surface, see :class:`LyapunovSpectrum`)
    from the tangent dynamics and from the averaging time. ``discrete``: the discrete state
    ``x`` is in (a run's ``final_discrete_state``; None: found from ``x``)."""
    n = ctx.model.n_states
    Q = np.eye(n)
    sums = np.zeros(n)
    starts = np.full((n_seg, n), np.nan)
    running = np.full((n_seg, n), np.nan)
    events = []
    vopts = {**opts, "variational": True, "dense": False, "throw": False}
    status = Status.SUCCESS
    done = 0
    x = np.array(x, dtype=float)
    # ``discrete``: the discrete state the previous segment ended in
    excluded = 0.0    # time in contact episodes (chattering gap + sticking)
    contact = 0.0     # time sticking
    episodes = 0
    ep_start = st_start = None   # start of the open episode, of its sticking

    def advance(J):
        nonlocal Q, sums
        Qn, R = np.linalg.qr(J @ Q)
        d = np.abs(np.diag(R))
        if not np.all(np.isfinite(d)):
            return False
        # R_ii = 0: the segment maps a direction to zero (sliding collapses the normal
        # direction onto the switching surface): that exponent is -inf
        with np.errstate(divide="ignore"):
            sums += np.log(d)
        Q = Qn
        return True

    for k in range(n_seg):
        ta = t0 + k * seg
        if discrete is not None and discrete[0] == 1:
            # still sticking: continue in the sticking state (a restart in free flight would
            # register the contact again with a chattering saltation each segment)
            if ep_start is None:        # stuck from the start (the transient ended stuck)
                ep_start = st_start = ta
                episodes += 1
            traj = ctx.run(x, KernelState(1, discrete[1], discrete[2]), ta, ta + seg, vopts,
                           p=p)
        else:
            start = start_of(ctx, ta, x, p)
            x = start.x
            if start.kind == STICK:
                # a segment that starts sticking (the transient ended stuck) starts a contact
                # episode: its kernel log has no chatter or stick record to mark it
                if ep_start is None:
                    ep_start = st_start = ta
                    episodes += 1
                traj = ctx.run(x, KernelState(STICK, start.index, start.mode), ta, ta + seg,
                               vopts, p=p)
            else:
                traj = ctx.run(x, None, ta, ta + seg, vopts, p=p)
        starts[k] = x
        status = failed_status(traj)
        if status:
            break
        if keep_events:
            events.extend(traj.events)
        x = traj.x.copy()
        was_stuck = ep_start is not None
        discrete = traj.final_discrete_state
        if not check_bound(x, bound):
            status = Status.DIVERGED
            break
        log = traj.events
        saved = (Q, sums.copy(), excluded, contact, episodes, ep_start, st_start)
        marks = _contact_marks(log, discrete[0] if discrete else 0, was_stuck)
        if not marks and not was_stuck:
            ok = advance(traj.jacobian)       # the whole segment is free motion
        else:
            # transfer = [Phi_0, S_1, Phi_1, ..., S_m, Phi_m]; the factors of a contact
            # episode (its chattering saltation .. its release saltation) are left out: the
            # tangent frame, re-orthonormalised where the episode begins, resumes at release.
            # The frame is re-orthonormalised at every event here: the approach to sticking (a
            # chattering sequence of ever slower impacts) multiplies shears of size ~ 1/v, and
            # their product over a segment is too ill-conditioned (cond ~ 1e11 .. 1e15) for
            # its QR factor R to keep log|det| (the sum of the exponents) to round-off
            F = traj.transfer_matrices
            mk: dict = {}
            for r, what in marks:
                mk.setdefault(r, []).append(what)
            ok = True if was_stuck else advance(F[0])
            for r in range(len(log)):
                for what in mk.get(r, ()):
                    if what == 1:
                        ep_start = float(log.t[r])
                    elif what == 0:
                        st_start = float(log.t[r])
                        episodes += 1
                    else:
                        t_end = float(log.t[r]) if int(log.kind_code[r]) == _RELEASE \
                            else float(log.t_after[r])
                        excluded += t_end - ep_start
                        if st_start is not None:
                            contact += t_end - st_start
                        ep_start = st_start = None
                        ok = ok and advance(F[2 * r + 2])     # Phi after the release
                if ep_start is None and r not in mk:
                    ok = ok and advance(F[2 * r + 2] @ F[2 * r + 1])
            if ep_start is not None:
                te = ta + seg
                excluded += te - ep_start
                ep_start = te
                if st_start is not None:
                    contact += te - st_start
                    st_start = te
        if not ok:
            Q, sums, excluded, contact, episodes, ep_start, st_start = saved
            status = Status.DIVERGED
            break
        done = k + 1
        time = done * seg - excluded
        running[k] = sums / time if time > 0 else np.nan
    span = done * seg
    time = span - excluded
    with np.errstate(invalid="ignore"):
        ex = sums / time if (done and time > 0) else np.full(n, np.nan)
    ends_stuck = False
    if ep_start is not None and st_start is not None and status == 0 and done:
        # the run ends sticking: an episode that lasts beyond one more window length is taken
        # as permanent sticking -- the state has collapsed onto the sticking manifold for good
        # (in chunks of 100 segments, each well within max_steps)
        te, t_look = t0 + span, t0 + 2 * span
        released = failed = False
        xs, ds = x, discrete
        while te < t_look and not (released or failed):
            t1 = min(te + 100 * seg, t_look)
            look = ctx.run(xs, KernelState(ds[0], ds[1], ds[2]), te, t1,
                           {**opts, "dense": False, "throw": False},
                           stop=AfterEvents(1, kind="release"), p=p)
            released = any(int(c) == _RELEASE for c in look.event_kind)
            failed = bool(failed_status(look))
            xs, ds, te = look.x, look.final_discrete_state, t1
        if not (released or failed):
            ends_stuck = True
            ex = np.full(n, -np.inf)
    return FlowSegments(ex, sums, done, x, status, starts, events, running, span, time,
                        contact, episodes, ends_stuck)


def lyapunov_spectrum(model: ModelLike, x0: StateLike | None = None,
                      params: Mapping[str, float] | None = None, *,
                      transient: int = 100, duration: int = 1000, segment: float | None = None,
                      t0: float | None = None, bound: float = 1e8,
                      **options: Any) -> LyapunovSpectrum:
    """The full Lyapunov spectrum of a piecewise-smooth flow (with saltation matrices at every
    event) or map, by QR re-orthonormalisation.

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
    x0 : sequence or dict, optional
        Initial state (default: the model's ``[defaults] x0``).
    params : dict, optional
        Parameter values by name, over the model's defaults (``model.parameters``: the
        ``[parameters]`` table with ``[defaults] params`` over it).
    transient : int
        Segments (flows) or iterations (maps) discarded before averaging (default 100).
    duration : int
        Segments (flows) or iterations (maps) averaged over (default 1000).
    segment : float, optional
        Length of a segment (flows): default the forcing period; required for autonomous
        flows. The basis is re-orthonormalised once per segment.
    t0 : float, optional
        Start time (flows; default: the model's ``[defaults] t0``, else 0).
    bound : float
        A state component beyond this magnitude counts as divergence
        (``Status.DIVERGED``).
    **options
        Integrator options of :func:`pwsdyn.simulate` (``rtol``, ``atol``, ``method``, ...).

    Returns
    -------
    LyapunovSpectrum
        With sticking (flows): the exponents of the free motion, sticking episodes being
        resets of the tangent dynamics, and the time in contact apart (``contact_time``,
        ``contact_episodes``, ``ends_stuck``; :class:`~pwsdyn.explore.LyapunovSpectrum`, Notes).

    Raises
    ------
    ArgumentError
        (a ``ValueError``) Before any work: a non-positive duration, an autonomous flow
        without ``segment``, a non-finite ``t0``, a run not resolved in double-precision time
        from ``t0`` (see ``pwsdyn._validate``), a ``duration`` whose per-segment records
        would exceed ``pwsdyn._validate.MEMORY_LIMIT``, ...

    Examples
    --------
    >>> res = lyapunov_spectrum("sqrt-map", [0.0], {"mu": 0.02, "lam": 0.8},
    ...                         duration=20000)
    >>> bool(res.exponents[0] > 0)
    True
    """
    transient = V.integer("transient", transient, lo=0)
    duration = V.integer("duration", duration, lo=1)
    segment = V.positive("segment", segment, allow_none=True)
    bound = V.positive("bound", bound, allow_inf=True)
    model = as_model(model, caller="lyapunov_spectrum()")
    t0 = V.number("t0", model.defaults.get("t0", 0.0) if t0 is None else t0)
    p = model.parameter_vector(params)
    if x0 is None:
        x0 = model.defaults.get("x0")
        if x0 is None:
            raise ArgumentError(f"give `x0`: model {model.name!r} has no [defaults] x0")
    x = V.state_vector(model, x0)
    n = model.n_states
    prov = {"model": model.name, "model_hash": model.hash, "pwsdyn_version": __version__,
            "params": dict(zip(model.parameters, map(float, p)))}
    if getattr(model, "is_map", False):
        if options or segment is not None:
            raise ArgumentError("integrator options and `segment` apply to flows only, not to "
                                f"map {model.name!r}")
        ctx = ModelContext.get(model)
        from ..model.maps import lyapunov_kernel

        st, ex, xe, done = lyapunov_kernel(ctx.cm.step, x, p if p.size else np.zeros(1),
                                           int(transient), int(duration), float(bound))
        status = Status(int(st))      # the loops return Status values
        return LyapunovSpectrum(np.sort(ex)[::-1], float(done), ex[None, :], {}, status, xe,
                                prov, model=model)
    opts = {**integrator_options(options, "lyapunov_spectrum()"), "dense": False,
            "throw": False}
    check_mode(model, opts)
    if segment is None:
        segment = model.forcing_period_at(p)       # checked: positive and finite
        if segment is None:
            raise ArgumentError(f"model {model.name!r} is autonomous: give `segment`, the time "
                                "between re-orthonormalisations")
    total = (transient + duration) * segment
    V.time_window("t0", t0, total, what=f"the run of {transient} + {duration} segments of "
                  f"{segment!r}")
    V.time_window("segment", t0 + total - segment, segment,
                  what="the last segment of the run")
    # per segment: its start state and running estimates (n floats each), and the events
    V.memory(f"lyapunov_spectrum() with duration={duration}", 8.0 * duration * (2 * n + 2))
    ctx = ModelContext.get(model)
    t = float(t0)
    status = Status.SUCCESS
    discrete = None
    if transient:
        x = readmit(ctx, t, x, p)
        tr = ctx.run(x, None, t, t + transient * segment, opts, p=p)
        status = failed_status(tr)
        x, discrete = tr.x.copy(), tr.final_discrete_state
        t += transient * segment
    if status:
        n = model.n_states
        return LyapunovSpectrum(np.full(n, np.nan), 0.0, np.zeros((0, n)), {}, status, x, prov,
                                model=model)
    fs = flow_segments(ctx, x, t, segment, int(duration), p, opts, bound, keep_events=True,
                       discrete=discrete)
    counts: dict = {}
    for e in fs.events:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    prov.update(segment=segment, transient=int(transient), duration=int(duration),
                options={k: v for k, v in opts.items() if k not in ("throw",)})
    return LyapunovSpectrum(np.sort(fs.exponents)[::-1], fs.time, fs.running[:fs.done],
                            counts, fs.status, fs.x, prov, span=fs.span,
                            contact_time=fs.contact_time, contact_episodes=fs.contact_episodes,
                            ends_stuck=fs.ends_stuck, model=model)
