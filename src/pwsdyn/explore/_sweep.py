"""Brute-force bifurcation diagrams: parameter sweeps with continuation of the final state.

For each parameter value the model is run for a transient, then for a window of ``samples``
forcing periods (or iterations of a map) in which the state is recorded at a section; the
state at the end of the window is the initial state at the next parameter value, as users of
these diagrams do (thesis, section 2.7: the final state of one value continues into the next).
Sweeping up and down shows hysteresis where attractors coexist.

Chunks and stitching
--------------------
A sweep means one uninterrupted sequence per direction: every value starts from the state
the previous value ends in (and from ``x0`` again after a value that failed or diverged).
The result does not depend on ``workers``, ``chunk_size``, the scheduler or a resume.

For speed the ordered values are split into chunks of ``chunk_size`` consecutive values
that run independently (on threads or Dask workers), each from a *guess*: chunk ``c`` starts
``warmup`` values before its first value, from ``x0``, runs the transient at each of those
warm-up values (results discarded) and continues through its own values. The first chunk
starts at ``x0`` with no warm-up: it is exact.

The chunks are then stitched into the sequence (:func:`stitch`, in the manner of parareal
iterations): the first value of every later chunk is run again from the state the chunk
before it hands on, and compared with the guess's first window -- not as raw states, which
differ along any attractor, but as recorded windows: status, period, events per period,
sticking and sliding time and the section points of the cycle, to a tolerance
(:func:`same_attractor`). Where they agree the guess stands; where they do not (the guess
settled on another of coexisting attractors), the chunk is rerun from that state in the
same task until a value whose window lies on the guess's attractor at that value (the rerun
has rejoined the guess; the guess's later values stand) or to its end, which may change the
state it hands on: the chunk after it is then checked again, and where it was rerun before
(from the state that has just been replaced) its new rerun resumes from those stored windows
at the first value that lies on their attractor instead of integrating the rest again. Windows with no period found
(chaos, a long transient) never agree: nothing tells one attractor from another there and
the state handed on depends sensitively on the start (chaotic stretches cost what a
sequential sweep costs).
Rounds of these checks run in parallel until every border agrees. Where the attractors agree
at the borders the cost is one value per border; the dataset records the chunks rerun
(``chunk_rerun``) and the cost (attributes ``stitch_borders``, ``stitch_reruns`` and
``stitch_values``: the values integrated to stitch, one per border checked and every value
rerun). Example (tests/test_explore.py): the ball on a table vibrating at
0.98 <= Gamma <= 1.05 has a period-1 orbit, continued from Gamma = 0.9, and a period-3 one,
reached by a ball dropped from 1.5 m; chunks of four values whose guesses land on period 3
are rerun, and the sweep follows period 1 throughout, as a single chunk does.

A stitched value lies on the attractor of the sequential sweep: its period, events and
section points agree with those of the sequential run to the integrator's tolerance on
periodic attractors. Where a value has no period (chaos, chattering transients) its points
and counts are those of a run from a state that agrees with the sequential one to the
integrator's tolerance, and chaos amplifies that difference: other points of the attractor,
and past it possibly another of coexisting attractors, as between two integrator tolerances
of the sequential sweep.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import xarray as xr

from .. import _validate as V
from ..errors import ArgumentError
from .._netcdf import (check_output_path, cf_global_attrs, flag_attrs, inverse_time_units,
                       quantity_attrs, run_status_codes, state_attrs, state_coords, time_units)
from ..errors import Status
from ..integrate.options import DEFAULTS
from ..model.spec import as_model
from ..integrate.compiled import ModelContext
from ..integrate.trajectory import EVENT_KINDS, SWITCH_EVENT_KINDS, DiscreteState, EventLog
from ._common import (check_common, check_time_unit, COUNTED_KINDS, DIVERGED,
                      SECTION_MISSED, check_bound, failed_status, model_payload,
                      period_estimate, readmit, start_of, state_times,
                      check_run_kind, check_start, first_values, sorted_values,
                      start_vector)
from ._executor import run_chunks
from ._lyapunov import flow_segments
from ._store import ChunkStore

if TYPE_CHECKING:
    from distributed import Client
    from numpy.typing import ArrayLike

    from .._typing import ModelLike, PathLike, StateLike

DIRECTIONS = ("up", "down", "both")
#: Default recording window of :func:`sweep`, in forcing periods (maps: iterations).
SAMPLES = 100
#: Default window with ``lyapunov=True``: finite-time exponents over 100 periods scatter by
#: about 0.02-0.05 between neighbouring parameter values in a chaotic band of the impact
#: oscillator (largest exponent 0.05-0.3 there); over 300 periods by 0.006-0.025, within
#: 0.02 of a 3000-period reference, at 2.4 times the cost (0.23 s per value, one core).
LYAPUNOV_SAMPLES = 300
#: Log records that count as a crossing of an event section (not chattering, sticking or
#: release, which are changes of the discrete state at the same surface).
SECTION_KINDS = ("impact", "transition", "crossing", "slide_start", "slide_end")


# ======================================================================================
# one parameter value
# ======================================================================================

def _period_function(ctx: ModelContext):
    """A fast numeric forcing period ``T(p)`` (or ``None`` for an autonomous model): the
    model's own (:attr:`Model.forcing_period_function <pwsdyn.model.Model.
    forcing_period_function>`)."""
    if ctx.model.forcing_period is None:
        return None
    return ctx.model.forcing_period_function


def _event_columns(events, n: int):
    """Times, kinds, names, states before and kinds of discrete state after (0 mode,
    1 sticking, 2 sliding) of an event log or a list of event records, as arrays."""
    if isinstance(events, EventLog):
        return (events.t, events.kind, events.name, events.x_before,
                events.state_after[:, 0])
    after = [DiscreteState.parse(e.mode_after).code for e in events]
    return (np.array([e.t for e in events], dtype=float),
            np.array([e.kind for e in events], dtype=object),
            np.array([e.name for e in events], dtype=object),
            np.array([e.x_before for e in events], dtype=float).reshape(len(events), n),
            np.array(after, dtype=int))


#: Kind codes of the kernel's event log (``RunResult.event_kind``): lookup tables of the
#: kinds counted per period, of those that cross a section, of the kinds logged on a switch
#: (their ``event_ref`` is a switch index, else an event index) and the chatter code.
_COUNTED_LUT = np.isin(np.arange(len(EVENT_KINDS)), [EVENT_KINDS.index(k) for k in COUNTED_KINDS])
_SECTION_LUT = np.isin(np.arange(len(EVENT_KINDS)), [EVENT_KINDS.index(k) for k in SECTION_KINDS])
_SWITCH_LUT = np.isin(np.arange(len(EVENT_KINDS)),
                      [EVENT_KINDS.index(k) for k in SWITCH_EVENT_KINDS])
_CHATTER = EVENT_KINDS.index("chatter")


def _section_refs(model, section: str) -> tuple[int, int]:
    """The event index and the switch index named ``section`` (-1 where none)."""
    ev = next((j for j, e in enumerate(model.events) if e.name == section), -1)
    sw = next((j for j, e in enumerate(model.switches) if e.name == section), -1)
    return ev, sw


def _code_columns(res, model, section: str):
    """Times, masks (counted, on the section, chatter), states before and kinds of discrete
    state after of a run's events, straight from the kernel's columns (no event log is
    made)."""
    kc = res.event_kind
    ref = res.event_ref
    on_switch = _SWITCH_LUT[kc]
    counted = _COUNTED_LUT[kc]
    if section == "stroboscopic":
        on_section = np.zeros(len(kc), dtype=bool)
    else:
        ev, sw = _section_refs(model, section)
        on_section = _SECTION_LUT[kc] & np.where(on_switch, ref == sw, ref == ev)
    return (res.event_t, counted, on_section, kc == _CHATTER, res.event_state_after[:, 0])


def run_window(ctx: ModelContext, x, p, T: float, phase: float, n_tr: int, n_s: int,
               section: str, max_points: int, opts: dict, bound: float,
               lyapunov: bool = False, record: bool = True) -> dict:
    """Transient of ``n_tr`` periods then a window of ``n_s`` periods, from ``x`` at
    ``t = phase * T``. Returns the section points and per-window statistics (see
    :func:`sweep` for their meaning). ``record=False`` runs only the transient (warm-up)."""
    n = ctx.model.n_states
    out = {"x_end": np.array(x, dtype=float), "status": 0}
    if ctx.is_map:
        return _map_window(ctx, x, p, n_tr, n_s, max_points, bound, lyapunov, record)
    t_start = phase * T
    t_w = t_start + n_tr * T
    x = readmit(ctx, t_start, x, p)
    if not record:
        if n_tr:
            tr = ctx.run(np.asarray(x, float), None, t_start, t_w, opts, p=p)
            out["status"] = failed_status(tr)
            out["x_end"] = tr.x.copy()
        return out
    t_end = t_w + n_s * T
    strobe = section == "stroboscopic"
    pts = np.full((max_points, n), np.nan)
    phs = np.full(max_points, np.nan)
    lyap = np.full(n, np.nan)
    if lyapunov:
        # per-period segments with the variational equations; the section points are the
        # segment start states (stroboscopic times)
        status = 0
        xx = np.asarray(x, float)
        if n_tr:
            tr = ctx.run(xx, None, t_start, t_w, opts, p=p)
            status = failed_status(tr)
            xx = tr.x.copy()
        events = []
        if not status:
            # exponents of the free motion: sticking episodes are resets (LyapunovSpectrum)
            fs = flow_segments(ctx, xx, t_w, T, n_s, p, opts, bound, keep_events=True)
            status, done, starts, events = fs.status, fs.done, fs.starts, fs.events
            if done:
                lyap = np.sort(fs.exponents)[::-1]
            xx = fs.x
            if strobe:
                m = min(max_points, done)
                pts[:m] = starts[:m]
        x_end = xx
        nsteps = 0
        start_kind = int(start_of(ctx, t_start, x, p).kind)
    else:
        events = []
        nsteps = 0
        xx = np.asarray(x, float)
        if strobe:
            # Transient and window in one kernel call that records the state at
            # t_w + k T (k = 0 .. n_s) on the dense output (no event, no landing step, so the
            # section costs a few percent; the state sticking or sliding at t_w just goes on).
            res = ctx.run(xx, None, t_start, t_end, opts, sample=(t_w, T), p=p)
            start_kind = res.start_kind
            status = failed_status(res)
            nsteps = res.stats.get("steps", 0)
            ts, xs = res.samples_t, res.samples_x
            j = np.rint((ts - t_w) / T).astype(int)
            keep = (j >= 0) & (j < min(max_points, n_s))
            pts[j[keep]] = xs[keep]
            x_end = res.x.copy()
            if not status and not (len(j) and j[-1] == n_s):
                status = SECTION_MISSED
        else:
            res = ctx.run(xx, None, t_start, t_end, opts, p=p)
            start_kind = res.start_kind
            status = failed_status(res)
            x_end = res.x.copy()
            nsteps = res.stats.get("steps", 0)
    if lyapunov:
        t, kind, name, xb, after = _event_columns(events, n)
        is_counted = np.isin(kind, COUNTED_KINDS)
        on_section = (name == section) & np.isin(kind, SECTION_KINDS)
        chatter = kind == "chatter"
    else:
        # the kernel's columns as they are (an event log would name every record)
        t, is_counted, on_section, chatter, after = _code_columns(res, ctx.model, section)
        xb = None
    in_window = (t >= t_w) & (t < t_end)
    if not strobe:
        hits = np.flatnonzero(in_window & on_section)
        m = min(len(hits), max_points)
        if m:
            pts[:m] = (xb if xb is not None else res.event_x_before)[hits[:m]]
        phs[:m] = ((t[hits[:m]] - t_start) / T) % 1.0
    counted = int(np.sum(in_window & is_counted))
    before = np.flatnonzero((t < t_w) & ~chatter)
    # the discrete state at t_w: that after the last event before it, else the one the run
    # started in (a ball put at rest on its table sticks from t_start without any event)
    initial = int(after[before[-1]]) if len(before) else start_kind
    upto = t < t_end
    stick, slide = state_times(t[upto], after[upto], chatter[upto], t_w, t_end, initial)
    if status == 0 and not check_bound(x_end, bound):
        status = DIVERGED
    npts = int(np.sum(np.all(np.isfinite(pts), axis=1)))
    out.update(points=pts, phase=phs, n_points=npts, status=status, x_end=x_end,
               events_per_period=counted / n_s, stick_time=stick / n_s, slide_time=slide / n_s,
               lyapunov=lyap, steps=nsteps)
    return out


def _map_window(ctx, x, p, n_tr, n_s, max_points, bound, lyapunov, record):
    from ..model.maps import lyapunov_kernel, orbit_kernel

    n = ctx.model.n_states
    pv = p if p.size else np.zeros(1)
    x = np.asarray(x, dtype=float)
    if not record:
        st, _, _, xe, _ = orbit_kernel(ctx.cm.step, x, pv, int(n_tr), 0, float(bound))
        # the loops return Status values: no piece applies is not MAX_STEPS
        return {"x_end": xe, "status": Status(int(st))}
    st, xs, pieces, xe, _ = orbit_kernel(ctx.cm.step, x, pv, int(n_tr), int(n_s), float(bound))
    status = Status(int(st))
    pts = np.full((max_points, n), np.nan)
    m = min(max_points, n_s)
    pts[:m] = xs[:m]
    good = pieces >= 0
    crossings = int(np.sum(pieces[1:][good[1:] & good[:-1]] != pieces[:-1][good[1:] & good[:-1]]))
    lyap = np.full(n, np.nan)
    if lyapunov and status == 0:
        _, ex, _, _ = lyapunov_kernel(ctx.cm.step, x, pv, int(n_tr), int(n_s), float(bound))
        lyap = np.sort(ex)[::-1]
    return {"points": pts, "phase": np.full(max_points, np.nan),
            "n_points": int(np.sum(np.all(np.isfinite(pts), axis=1))), "status": status,
            "x_end": xe, "events_per_period": crossings / n_s, "stick_time": 0.0,
            "slide_time": 0.0, "lyapunov": lyap, "steps": 0}


# ======================================================================================
# chunks
# ======================================================================================

def _rows(nv: int, maxp: int, n: int) -> dict:
    """The result arrays of ``nv`` values (NaN / 0 where not run)."""
    res = {k: np.full(shp, np.nan) for k, shp in (
        ("section", (nv, maxp, n)), ("phase", (nv, maxp)), ("x_final", (nv, n)),
        ("lyapunov", (nv, n)), ("events_per_period", nv), ("stick_time", nv),
        ("slide_time", nv))}
    for k in ("n_points", "period", "status", "steps"):
        res[k] = np.zeros(nv, dtype=np.int64)
    res["rerun"] = np.zeros(nv, dtype=bool)
    return res


def _uses_phase(ctx: ModelContext, section: str) -> bool:
    """The phase of event-section points counts for a forced flow (autonomous flows have no
    phase: ``period`` is then only a unit of time)."""
    return (section != "stroboscopic" and not ctx.is_map
            and ctx.model.forcing_period is not None)


def _cycle_points(points, phase, use_phase: bool) -> np.ndarray:
    """The finite section points of a window, with the phase as a point on the circle where
    it counts (what :func:`~pwsdyn.explore._common.period_estimate` compares)."""
    pts = np.asarray(points, dtype=float)
    if use_phase:
        ang = 2 * np.pi * np.asarray(phase, dtype=float)
        pts = np.column_stack([pts, np.cos(ang), np.sin(ang)])
    return pts


#: Relative distance (of ``1 + max |P|``) within which the cycles of two windows are the same
#: attractor: a thousand times the default ``period_tol`` (points of one window repeat to
#: ``period_tol``; two runs settling on one stable orbit from different states agree to about
#: that after the transient, distinct coexisting orbits differ by far more).
STITCH_RTOL = 1e-3


def same_attractor(a: dict, b: dict, T: float, samples: int, use_phase: bool) -> bool:
    """Whether two recorded windows at one parameter value lie on the same attractor: same
    status, period and number of section points, events per period within two events over
    the window, sticking and sliding time per period within 1 % of the period, and the last
    ``period`` section points the same set to :data:`STITCH_RTOL`. Windows with section
    points but no period found are never the same (a chunk starting there is rerun). ``a``
    and ``b`` hold one row of the
    chunk arrays (``status``, ``period``, ``n_points``, ``events_per_period``,
    ``stick_time``, ``slide_time``, ``section``, ``phase``)."""
    if int(a["status"]) != int(b["status"]):
        return False
    if int(a["status"]):
        return True         # both failed: the sequence goes on from x0 after either
    if int(a["period"]) != int(b["period"]) or int(a["n_points"]) != int(b["n_points"]):
        return False
    if int(a["period"]) == 0 and int(a["n_points"]):
        # no period found (chaos, a long transient): the windows cannot tell one attractor
        # from another, and the state handed on depends sensitively on the start, so the
        # chunk is rerun
        return False
    if abs(float(a["events_per_period"]) - float(b["events_per_period"])) > 2.0 / samples + 1e-12:
        return False
    for k in ("stick_time", "slide_time"):
        if abs(float(a[k]) - float(b[k])) > 0.01 * T:
            return False
    pa = _cycle_points(a["section"], a["phase"], use_phase)
    pb = _cycle_points(b["section"], b["phase"], use_phase)
    pa = pa[np.all(np.isfinite(pa), axis=1)]
    pb = pb[np.all(np.isfinite(pb), axis=1)]
    if not len(pa):
        return True
    scale = 1.0 + max(float(np.max(np.abs(pa))), float(np.max(np.abs(pb))))
    k = int(a["period"])
    ca, cb = pa[-k:], pb[-k:]
    d = np.max(np.abs(ca[:, None, :] - cb[None, :, :]), axis=2)
    return bool(max(d.min(axis=1).max(), d.min(axis=0).max()) <= STITCH_RTOL * scale)


def row(res: dict, r: int) -> dict:
    """Row ``r`` of chunk arrays (one value's record) as a dict of arrays and scalars."""
    return {k: res[k][r] for k in _CHUNK_VARS if k != "x_start"}


def handed_on(res: dict, x0, bound: float) -> np.ndarray:
    """The state a chunk hands on to the next value: its last final state, or ``x0`` where
    the last value failed or left ``bound`` (a sequence restarts from ``x0`` then)."""
    x = res["x_final"][-1]
    ok = int(res["status"][-1]) == 0 and check_bound(x, bound)
    return np.array(x if ok else x0, dtype=float)


def sweep_chunk(task: dict) -> dict:
    """Run one chunk of a sweep (on a worker or in-process). Returns plain arrays.

    ``task["x_start"]`` (optional): the state the chunk starts from at its first value (the
    previous chunk's handed-on state, a stitching run); default ``x0`` after ``warmup``
    values run for their transient only (a guess). ``task["check"]`` (optional): the first
    row of the guess of this chunk; when the first value run from ``x_start`` lies on the
    same attractor (:func:`same_attractor`) the run stops there and returns
    ``{"matched": True}``. ``task["guess"]`` (optional): the whole guess of this chunk (its
    first row is then the check); where a later value run from ``x_start`` lies on the
    guess's attractor at that value the rerun has rejoined the guess: it stops, and the
    guess's rows after that value complete the result. ``rerun`` marks the rows run from
    ``x_start``. ``task["alts"]`` (optional): earlier reruns of this chunk from other
    starts; where a value lies on the attractor of one of them at that value, the rerun
    resumes from it (its later rows complete the result) instead of integrating them again.
    """
    ctx = ModelContext.get(task["model"])
    model = ctx.model
    s = task["settings"]
    n = model.n_states
    p = np.array(task["p"], dtype=float)
    pidx = task["pidx"]
    x0 = np.array(s["x0"], dtype=float)
    start = task.get("x_start")
    x = x0.copy() if start is None else np.array(start, dtype=float)
    guess = task.get("guess")
    check = task.get("check") if guess is None else row(guess, 0)
    alts = task.get("alts") or ()
    values = task["values"]
    nw = task["warmup"]
    nv = len(values) - nw
    maxp = s["max_points"]
    opts = task["opts"]
    fperiod = _period_function(ctx)
    use_phase = _uses_phase(ctx, s["section"])
    res = _rows(nv, maxp, n)
    res["x_start"] = np.full(n, np.nan) if start is None else x.copy()
    for i, val in enumerate(values):
        p[pidx] = val
        T = s["period"] if s["period"] is not None else (
            float(fperiod(*p)) if fperiod is not None else 1.0)
        rec = i >= nw
        w = run_window(ctx, x, p, T, s["phase"], s["transient"], s["samples"], s["section"],
                       maxp, opts, s["bound"], s["lyapunov"], record=rec)
        if rec:
            r = i - nw
            res["section"][r] = w["points"]
            res["phase"][r] = w["phase"]
            res["x_final"][r] = w["x_end"]
            res["lyapunov"][r] = w["lyapunov"]
            for k in ("events_per_period", "stick_time", "slide_time", "n_points", "status",
                      "steps"):
                res[k][r] = w[k]
            if w["status"] == 0:
                pts = _cycle_points(w["points"], w["phase"], use_phase)
                res["period"][r] = period_estimate(pts, s["max_period"], s["period_tol"])
            if start is not None:
                res["rerun"][r] = True
            if r == 0 and check is not None and same_attractor(
                    row(res, 0), check, T, s["samples"], use_phase):
                return {"matched": True}
            if r > 0 and guess is not None and r + 1 < nv and same_attractor(
                    row(res, r), row(guess, r), T, s["samples"], use_phase):
                for k, v in res.items():
                    if k not in ("x_start", "rerun"):
                        v[r + 1:] = guess[k][r + 1:]
                return res
            for alt in alts:
                if r + 1 < nv and same_attractor(row(res, r), row(alt, r), T, s["samples"],
                                                 use_phase):
                    # on the attractor of an earlier rerun of this chunk (from a state that
                    # a rerun of the chunk before has since replaced): its later rows are
                    # the sequence from here, to the same tolerance as a rejoined guess
                    for k, v in res.items():
                        if k != "x_start":
                            v[r + 1:] = alt[k][r + 1:]
                    return res
        # continue the final state into the next value; restart from x0 after a failure
        ok = w["status"] == 0 and check_bound(w["x_end"], s["bound"])
        x = np.array(w["x_end"], dtype=float) if ok else x0.copy()
    return res


def stitch(tasks: list, chains: list, guesses: dict, reruns: dict, run, x0, bound: float
           ) -> tuple[dict, dict]:
    """Make the chunk results those of one uninterrupted sequence per direction.

    ``chains``: the task indices of each direction in order; ``guesses[i]``: chunk ``i`` run
    from its guess (the first chunk of a chain from ``x0``: already exact); ``reruns[i]``:
    chunk ``i`` rerun from a start known before (a resumed store), by its ``x_start``;
    ``run(items) -> {i: result}`` runs stitching tasks ``(i, task)`` (in parallel).

    In rounds: in the first, every chunk has its first value run from the state its
    predecessor's guess hands on; in later ones, every chunk not yet confirmed whose
    predecessor is confirmed, from its confirmed state. Where that window lies on the
    attractor of the guess's first window (:func:`same_attractor`) the guess stands, else the
    chunk is rerun from that state in the same task (until it rejoins the guess). Then, in
    order, a chunk whose predecessor is confirmed and whose run used the predecessor's
    confirmed state is confirmed: a rerun that rejoined its guess hands on the guess's state,
    so the first round's check of the chunk after it stands. Each round confirms at least the
    first unconfirmed chunk of every chain; where all borders agree, one round (one value per
    border, in parallel) confirms them all. Returns ``(final, info)``:
    ``final[i]`` the confirmed result, ``info[i]`` ``"first"``, ``"matched"`` or
    ``"rerun"``.
    """
    final, info = {}, {}
    tried: dict = {}        # (i, start bytes) -> result, or "matched"
    latest = dict(guesses)  # the last result known of each chunk
    for i, r in reruns.items():
        tried[(i, np.asarray(r["x_start"], dtype=float).tobytes())] = latest[i] = r
    for chain in chains:
        final[chain[0]] = guesses[chain[0]]
        info[chain[0]] = "first"
    rounds = 0
    while True:
        # confirm, in order, what the runs so far allow
        for chain in chains:
            for k in range(1, len(chain)):
                i, prev = chain[k], chain[k - 1]
                if i in final:
                    continue
                if prev not in final:
                    break
                got = tried.get((i, handed_on(final[prev], x0, bound).tobytes()))
                if got is None:
                    break
                final[i], info[i] = ((guesses[i], "matched") if isinstance(got, str)
                                     else (got, "rerun"))
                latest[i] = final[i]
        todo, starts = [], {}
        for chain in chains:
            for k in range(1, len(chain)):
                i, prev = chain[k], chain[k - 1]
                if i in final:
                    continue
                if prev not in final and rounds:
                    # after the first round only from a confirmed state: checks from states
                    # that a rerun before them may still change would be repeated in every
                    # round of a stretch of reruns (quadratic work)
                    continue
                xs = handed_on(final.get(prev, latest[prev]), x0, bound)
                if (i, xs.tobytes()) in tried:
                    continue
                t = tasks[i]
                starts[i] = xs
                # earlier reruns of the chunk (from states since replaced): a rerun that
                # reaches one of their attractors resumes from their windows
                alts = [r for (j, _), r in tried.items() if j == i and not isinstance(r, str)]
                todo.append((i, {**t, "x_start": xs.tolist(), "warmup": 0,
                                 "values": t["values"][t["warmup"]:],
                                 "guess": guesses[i], "alts": alts}))
        if not todo:
            if all(i in final for chain in chains for i in chain):
                return final, info
            raise RuntimeError("sweep stitching made no progress")  # not expected
        rounds += 1
        for i, r in run(todo).items():
            got = "matched" if r.get("matched") else r
            tried[(i, starts[i].tobytes())] = got
            latest[i] = guesses[i] if isinstance(got, str) else got


# ======================================================================================
# the public function
# ======================================================================================

def _settings_json(d: dict) -> dict:
    return json.loads(json.dumps(d, sort_keys=True, default=float))


def sweep(model: ModelLike, param: str, values: ArrayLike, x0: StateLike | None = None,
          *, transient: int = 200,
          samples: int | None = None, section: str = "stroboscopic", direction: str = "both",
          params: Mapping[str, float] | None = None, phase: float = 0.0,
          period: float | None = None, max_points: int | None = None,
          max_period: int | None = None, period_tol: float = 1e-6, bound: float = 1e8,
          lyapunov: bool = False, chunk_size: int | None = None, warmup: int = 2,
          workers: int | None = None, client: Client | None = None,
          scheduler: str | None = None, store: PathLike | None = None,
          out: PathLike | None = None, overwrite: bool = False, progress: bool = True,
          **options: Any) -> xr.Dataset:
    """Brute-force bifurcation diagram: sweep one parameter, continuing the final state.

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
        A flow or a piecewise-smooth map (anything :func:`pwsdyn.load_model` accepts).
    param : str
        The parameter swept.
    values : sequence of float
        Its values (distinct, finite; sorted here). ``direction="up"`` visits them in
        increasing order, ``"down"`` in decreasing order, ``"both"`` does both sweeps.
    x0 : sequence or dict, optional
        Initial state at the first value (default: the model's ``[defaults] x0``).
    transient : int
        Forcing periods (maps: iterations) run and discarded at each value (default 200).
    samples : int, optional
        Forcing periods (maps: iterations) of the recording window: default 100, or 300 with
        ``lyapunov=True`` (fewer make the exponents scatter between neighbouring values).
    section : str
        ``"stroboscopic"`` (default): the state at ``t = (k + phase) T`` for each period of
        the window. Or the name of an event or switch (e.g. ``"impact"``): the state just
        before each such event in the window (impacts, transitions, crossings, sliding starts
        and ends), with its phase ``(t / T) mod 1``. Maps record every iterate.
    direction : {'up', 'down', 'both'}
        Default ``"both"``: the up and the down sweep, which show hysteresis where
        attractors coexist (``pwsdyn sweep`` does the same).
    params : dict, optional
        Values of the other parameters (default: the model's, ``model.parameters``: the
        ``[parameters]`` table with ``[defaults] params`` over it, as on the command line).
    phase : float
        Phase of the stroboscopic section and of the start of each value, in periods.
    period : float, optional
        Time unit of ``transient`` and ``samples``: default the forcing period at each value
        (``model.forcing_period_value``); required for autonomous flows.
    max_points : int, optional
        Section points stored per value (default ``samples``; event sections keep the first
        ``max_points`` events of the window).
    max_period : int, optional
        Largest period looked for by the period estimate (default ``min(samples // 4, 64)``).
    period_tol : float
        Section points ``j`` and ``j + k`` count as equal within
        ``period_tol * (1 + max |point|)`` (default 1e-6).
    bound : float
        A state component beyond ``bound`` counts as divergence (``Status.DIVERGED``); the
        next value then starts again from ``x0``.
    lyapunov : bool
        Also compute the Lyapunov spectrum over the window (flows: variational equations with
        saltation matrices, one QR per period; maps: per iteration). Slower for flows.
    chunk_size : int, optional
        Values per chunk (default ``ceil(len(values) / 16)``, independent of the workers).
        The result does not depend on it: the chunks, run in parallel from a guess, are
        stitched into one sequence per direction (the module docstring of
        ``pwsdyn.explore._sweep``); it sets the parallelism and what stitching costs.
    warmup : int
        Values before a chunk's first value at which the chunk's guess runs the transient
        first, from ``x0`` (default 2): a better guess needs fewer reruns.
    workers : int, optional
        Threads running the chunks in this process (default: one per core; the compiled
        kernel releases the GIL, so they run in parallel and a script needs no ``__main__``
        guard); ``1``: one after the other. With ``scheduler="processes"``: the number of
        worker processes.
    client : dask.distributed.Client, optional
        Run on this Dask client's cluster.
    scheduler : str, optional
        ``"threads"`` (the default), ``"synchronous"``, ``"processes"`` (a local Dask
        cluster of ``workers`` processes; a script then needs ``if __name__ ==
        "__main__":``) or the address of a Dask scheduler to connect to.
    store : str or Path, optional
        Directory where each finished chunk is written as it completes. An existing store
        of the same model and settings is resumed (finished chunks are not recomputed); one
        of another model or settings is refused.
    out : str or Path, optional
        Write the dataset to this NetCDF file. Its directory must exist and be writable
        (checked before any work).
    overwrite : bool
        ``False`` (default): an existing ``out`` is refused before any work
        (:class:`~pwsdyn.OutputExistsError`); ``True``: it is replaced.
    progress : bool
        Show a progress bar (chunks, ETA).
    **options
        Integrator options of :func:`pwsdyn.simulate` (``rtol``, ``atol``, ``method``,
        ``max_steps`` (per value), ...).

    Returns
    -------
    xarray.Dataset
        Dimensions ``direction``, the parameter (named ``param``), ``sample``, ``state`` (and
        ``exponent`` with ``lyapunov``). Variables:

        - ``section`` (direction, param, sample, state): section points (NaN where none);
        - ``phase`` (direction, param, sample): phase of event-section points;
        - ``n_points``: section points recorded; ``period``: smallest ``k <= max_period``
          with repeating section points (in periods, events for event sections, iterations
          for maps; 0: none found);
        - ``events_per_period``: impacts, transitions, crossings and chattering sequences per
          period (maps: border crossings per iteration);
        - ``stick_time``, ``slide_time``: time per period spent sticking / sliding (a run
          that starts sticking, as a ball put at rest on its table, counts from its start);
        - ``status``: the value of a :class:`pwsdyn.Status` member (its flags name them;
          :func:`pwsdyn.io.decode_status` gives the members): 0 success, the status of a
          failed run (maps: ``NO_PIECE_APPLIES``, ``NONFINITE``), ``DIVERGED`` (-1) or
          ``SECTION_MISSED`` (-3: the section at the end of the window was not logged; not
          expected to occur);
        - ``x_final``: the state handed on to the next value; ``steps``: integrator steps;
        - ``lyapunov`` (direction, param, exponent), with ``lyapunov=True`` (flows with
          sticking: exponents of the free motion, see :class:`pwsdyn.explore.LyapunovSpectrum`);
        - ``chunk_start`` (direction, param): True at the first value of each chunk;
          ``chunk_rerun``: True at the values rerun from the state the chunk before hands on
          (the chunk's guess lay on another attractor), up to the value where the rerun
          rejoined the guess's attractor.

        Attributes hold the provenance (model name and hash, pwsdyn version, settings) and
        the cost of the stitching: ``stitch_borders`` (chunk borders checked),
        ``stitch_reruns`` (chunks rerun) and ``stitch_values`` (values integrated again to
        stitch: one per border checked and every value rerun).

    Raises
    ------
    ArgumentError
        (a ``ValueError``) Before any work: empty, repeated or non-finite values, an unknown
        parameter, section or direction, counts that are not ints in range, tolerances
        outside (0, 1), a value where the forcing period is not a positive finite number or
        is not resolved in double-precision time over the window (``2*pi/omega`` at
        ``omega = 0``), result arrays beyond ``pwsdyn._validate.MEMORY_LIMIT``.
    StoreMismatchError
        ``store`` holds results of another model or other settings.
    OutputExistsError
        (a ``FileExistsError``) ``out`` exists and ``overwrite`` is false.

    Examples
    --------
    >>> import numpy as np, pwsdyn
    >>> ds = pwsdyn.sweep("sqrt-map", "mu", np.linspace(0.01, 0.05, 5), [0.0],
    ...                   params={"lam": 0.8}, workers=1, progress=False)
    >>> ds.sizes["mu"], int(ds.period.sel(direction="up").min())
    (5, 0)
    """
    if samples is None:
        samples = LYAPUNOV_SAMPLES if V.flag("lyapunov", lyapunov) else SAMPLES
    (transient, samples, phase, period, max_period, period_tol, bound, chunk_size) = check_common(
        transient=transient, samples=samples, samples_min=1, phase=phase, period=period,
        max_period=max_period, period_tol=period_tol, bound=bound, chunk_size=chunk_size,
        workers=workers, progress=progress, store=store, out=out, scheduler=scheduler)
    direction = V.choice("direction", direction, DIRECTIONS)
    warmup = V.integer("warmup", warmup, lo=0)
    lyapunov = V.flag("lyapunov", lyapunov)
    overwrite = V.flag("overwrite", overwrite)
    max_points = V.integer("max_points", max_points, lo=1, allow_none=True)
    model = as_model(model, caller="sweep()")
    is_map = bool(getattr(model, "is_map", False))
    if not isinstance(param, str) or param not in model.parameters:
        raise ArgumentError(f"unknown parameter {V.describe(param)} for model {model.name!r}; "
                            f"`param` must be one of {list(model.parameters)}")
    vals = sorted_values(f"`values` of {param!r}", values)
    base = V.mapping("params", params)
    if param in base:
        raise ArgumentError(f"`params` must not set the swept parameter {param!r}")
    p = model.parameter_vector(base)
    pidx = list(model.parameters).index(param)
    check_run_kind(model, section, period, options, "sweep()")
    if not is_map:
        check_time_unit(model, p, period, phase, transient + samples, pidx=pidx,
                        values=vals, param=param)
    x0v = start_vector(model, x0)
    if not is_map:
        # the first value of each direction starts from x0 as it is (later chunks' guesses
        # from x0 are readmitted like carried states: a guess, checked by the stitching)
        check_start(model, x0v, p, pidx, first_values(vals, direction), phase, period)
    max_points = samples if max_points is None else max_points
    if max_period is None:
        max_period = max(1, min(samples // 4, 64))
    nd = 2 if direction == "both" else 1
    n = model.n_states
    V.memory(f"sweep() of {len(vals)} values with max_points={max_points}",
             8.0 * nd * len(vals) * (max_points * (n + 1) + 3 * n + 8))
    opts = {**DEFAULTS, **options, "dense": False, "throw": False}
    opts.pop("variational", None)
    opts["variational"] = False
    if chunk_size is None:
        chunk_size = max(1, math.ceil(len(vals) / 16))
    out_path = check_output_path(out, overwrite=overwrite) if out is not None else None

    settings = dict(param=param, values=[float(v) for v in vals], x0=[float(v) for v in x0v],
                    transient=int(transient), samples=int(samples), section=section,
                    direction=direction, params=dict(zip(model.parameters, map(float, p))),
                    phase=float(phase), period=None if period is None else float(period),
                    max_points=int(max_points), max_period=int(max_period),
                    period_tol=float(period_tol), bound=float(bound), lyapunov=bool(lyapunov),
                    chunk_size=int(chunk_size), warmup=int(warmup),
                    options={k: v for k, v in opts.items() if k not in ("throw", "dense")}
                    if not is_map else {})
    settings = _settings_json(settings)

    dirs = ["up", "down"] if direction == "both" else [direction]
    tasks = []
    payload = model_payload(model)
    nvals = len(vals)
    for d in dirs:
        order = np.arange(nvals) if d == "up" else np.arange(nvals)[::-1]
        for c0 in range(0, nvals, chunk_size):
            idx = order[c0:c0 + chunk_size]
            w0 = max(0, c0 - warmup)
            warm = order[w0:c0]
            tasks.append({"model": payload, "settings": settings, "p": p.tolist(),
                          "pidx": pidx, "opts": opts, "direction": d,
                          "index": idx.tolist(),
                          "values": [float(vals[i]) for i in np.concatenate([warm, idx])],
                          "warmup": len(warm)})

    guesses: dict[int, dict] = {}
    reruns: dict[int, dict] = {}
    nt = len(tasks)
    chains = [[i for i, t in enumerate(tasks) if t["direction"] == d] for d in dirs]
    st = None
    chunk_attrs = _variable_attrs(model, settings)
    if store is not None:   # takes the store's lock, held until st.close()
        # slots 0 .. nt-1: the chunks run from their guess; nt + i: chunk i rerun from the
        # state the chunk before it hands on (stored once confirmed)
        st = ChunkStore(store, "sweep", model.name, model.hash, settings, 2 * nt,
                        attrs=cf_global_attrs(model, "sweep_chunk",
                                              f"chunk of a pwsdyn sweep of model {model.name}",
                                              "one chunk of a parameter sweep (pwsdyn.sweep); "
                                              "the store's manifest.json describes the run"))
    try:
        if st is not None:
            for i in st.done():
                (guesses if i < nt else reruns)[i % nt] = _from_chunk_dataset(st.read(i))

        def on_result(i, res):
            guesses[i] = res
            if st is not None:
                st.write(i, _chunk_dataset(res, i, chunk_attrs))

        todo = [i for i in range(nt) if i not in guesses]
        run_chunks(sweep_chunk, tasks, todo, on_result, workers=workers, client=client,
                   scheduler=scheduler, progress=progress, desc="sweep", n_done=len(guesses))

        def run_stitch(items):
            got = {}
            run_chunks(sweep_chunk, [t for _, t in items], range(len(items)),
                       lambda k, r: got.__setitem__(items[k][0], r), workers=workers,
                       client=client, scheduler=scheduler, progress=False, desc="stitch")
            return got

        x0_arr = np.array(settings["x0"], dtype=float)
        results, info = stitch(tasks, chains, guesses, reruns, run_stitch, x0_arr,
                               settings["bound"])
        if st is not None:
            for i, how in info.items():
                if how == "rerun" and i not in reruns:
                    st.write(nt + i, _chunk_dataset(results[i], nt + i, chunk_attrs))
    finally:
        if st is not None:
            st.close()
    ds = _assemble(model, vals, tasks, results, dirs, settings, lyapunov, info)
    if out_path is not None:
        from .._netcdf import save_dataset

        save_dataset(ds, out_path, overwrite=overwrite)
    return ds


_CHUNK_VARS = ("section", "phase", "x_final", "lyapunov", "events_per_period", "stick_time",
               "slide_time", "n_points", "period", "status", "steps", "x_start", "rerun")
_CHUNK_DIMS = {"section": ("value", "sample", "state"), "phase": ("value", "sample"),
               "x_final": ("value", "state"), "lyapunov": ("value", "state"),
               "x_start": ("state",)}


def _variable_attrs(model, settings: dict) -> dict:
    """CF attributes (``long_name``, ``units``, flags) of the variables of a sweep dataset
    and of its chunk files."""
    is_map = bool(getattr(model, "is_map", False))
    tunit = time_units(model)
    per = "iteration" if is_map else "period"
    lu = inverse_time_units(model)

    def counted(long_name):
        return {"long_name": long_name, "units": "1"}

    def timed(long_name):
        return {"long_name": long_name, **({"units": tunit} if tunit else {})}

    return {
        "section": state_attrs(model, "iterates (NaN where none)" if is_map
                               else "section points (NaN where none)"),
        "phase": {"long_name": "phase of the section point in the forcing period",
                  "units": "1"},
        "n_points": counted("number of section points recorded"),
        "period": counted("period estimate in forcing periods (event sections: events; maps: "
                          "iterations); 0: none found"),
        "events_per_period": counted("border crossings per iteration" if is_map else
                                     "impacts, transitions, crossings and chattering "
                                     "sequences per forcing period"),
        "stick_time": timed(f"time spent sticking per {per}"),
        "slide_time": timed(f"time spent sliding per {per}"),
        "status": {"long_name": "status of the run at this value",
                   **flag_attrs(run_status_codes(is_map=is_map, section_missed=True))},
        "x_final": state_attrs(model, "state handed on to the next value"),
        "steps": counted("integrator steps"),
        "lyapunov": {"long_name": "Lyapunov exponents, decreasing" + (
                         " (per iteration)" if is_map else " (per unit time)"),
                     **({"units": lu} if lu else {})},
        "chunk_start": {"long_name": "first value of a chunk"},
        "chunk_rerun": {"long_name": "value rerun from the state the chunk before hands on "
                                     "(the chunk's guess lay on another attractor)"},
        # the chunk files' own: where the chunk's run started, and which of its values
        # belong to a rerun from the state handed on (stitching)
        "x_start": state_attrs(model, "state the chunk's run started from"),
        "rerun": {"long_name": "value of a rerun from the state the chunk before hands on"},
    }


def _chunk_dataset(res: dict, i: int, var_attrs: dict | None = None) -> xr.Dataset:
    var_attrs = var_attrs or {}
    return xr.Dataset({k: (_CHUNK_DIMS.get(k, ("value",)), res[k], var_attrs.get(k, {}))
                       for k in _CHUNK_VARS}, attrs={"chunk": i})


def _from_chunk_dataset(ds: xr.Dataset) -> dict:
    return {k: ds[k].values for k in _CHUNK_VARS}


def _assemble(model, vals, tasks, results, dirs, settings, lyapunov, info=None
              ) -> xr.Dataset:
    n = model.n_states
    nv = len(vals)
    maxp = settings["max_points"]
    nd = len(dirs)
    arr = {k: np.full((nd, nv) + shp, np.nan) for k, shp in (
        ("section", (maxp, n)), ("phase", (maxp,)), ("x_final", (n,)), ("lyapunov", (n,)),
        ("events_per_period", ()), ("stick_time", ()), ("slide_time", ()))}
    for k in ("n_points", "period", "status", "steps"):
        arr[k] = np.zeros((nd, nv), dtype=np.int64)
    chunk_start = np.zeros((nd, nv), dtype=bool)
    chunk_rerun = np.zeros((nd, nv), dtype=bool)
    info = info or {}
    checks = reran = cost = 0
    for ti, task in enumerate(tasks):
        di = dirs.index(task["direction"])
        idx = np.asarray(task["index"])
        res = results[ti]
        for k in arr:
            arr[k][di, idx] = res[k]
        chunk_start[di, idx[0]] = True
        how = info.get(ti, "first")
        rows_rerun = np.asarray(res.get("rerun", np.zeros(len(idx))), dtype=bool)
        chunk_rerun[di, idx] = rows_rerun
        if how != "first":
            checks += 1
            reran += how == "rerun"
            cost += int(rows_rerun.sum()) if how == "rerun" else 1
    arr["chunk_start"] = chunk_start
    arr["chunk_rerun"] = chunk_rerun
    pname = settings["param"]
    vdim = pname
    is_map = bool(getattr(model, "is_map", False))
    dims = ("direction", vdim)
    va = _variable_attrs(model, settings)
    layout = {"section": ("sample", "state"), "x_final": ("state",), "phase": ("sample",),
              "lyapunov": ("exponent",)}
    names = ["section", "n_points", "period", "events_per_period", "stick_time", "slide_time",
             "status", "x_final", "steps", "chunk_start", "chunk_rerun"]
    if settings["section"] != "stroboscopic":
        names.append("phase")
    if lyapunov:
        names.append("lyapunov")
    data = {k: (dims + layout.get(k, ()), arr[k], va[k]) for k in names}
    coords = {"direction": ("direction", list(dirs),
                            {"long_name": "direction of the sweep (up: increasing values)"}),
              vdim: (vdim, vals, {**quantity_attrs(model, pname),
                                  "comment": "the swept parameter"}),
              "sample": ("sample", np.arange(maxp), {"long_name": "index of the section point"}),
              **state_coords(model)}
    if lyapunov:
        coords["exponent"] = ("exponent", np.arange(n),
                              {"long_name": "index of the Lyapunov exponent"})
    what = "map" if is_map else "flow"
    attrs = {**cf_global_attrs(model, "sweep",
                               f"pwsdyn bifurcation diagram of model {model.name} in {pname}",
                               f"brute-force parameter sweep of a {what} with continuation "
                               f"(pwsdyn.sweep)"),
             "kind": "sweep", "parameter": pname,
             "section": settings["section"],
             "settings": json.dumps(settings, sort_keys=True),
             # the stitching of the chunks into one sequence per direction (see the module
             # docstring): borders checked, chunks rerun, and the values integrated for it
             # (one per border checked, the values rerun; the guesses not counted)
             "stitch_borders": int(checks), "stitch_reruns": int(reran),
             "stitch_values": int(cost)}
    return xr.Dataset(data, coords=coords, attrs=attrs)
