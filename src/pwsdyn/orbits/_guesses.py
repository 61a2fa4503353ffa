"""Guesses that follow a signature: the unknowns ``u`` of an orbit problem
(:class:`~pwsdyn.orbits.OrbitProblem`) from a state at a time, each segment integrated in its
discrete state to the zero of its condition (:func:`follow`), or from a simulation of the
model whose events reproduce the signature (:func:`from_simulation`)."""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from .._codes import REGULAR, SLIDE, SLIDE_MULTI, STICK
from ..integrate.compiled import AfterEvents, KernelState, run_compiled
from ._base import ADMISSIBILITY_RTOL
from ._residual import _groups
from ._sampling import sample_times
from .signature import Signature
from .surfaces import model_context


def follow(prob, t0: float, x0, p=None, *, horizon: float | None = None) -> np.ndarray:
    """``u`` from a state ``x0`` at ``t0`` in segment 0 (the segment the signature's first
    event ends): each segment is integrated in its discrete state, whatever surfaces it
    meets, to the first zero of its condition, the event map applied, and so on around
    the signature and once more through segment 0.

    Raises :class:`~pwsdyn.ArgumentError` when a segment does not reach its condition within
    ``horizon`` (default: twice the period of a forced orbit; required for an autonomous
    one, whose ``t_ref`` is set to the start of segment 0 found).
    """
    p = prob._p(p)
    x0 = np.asarray(x0, dtype=float).reshape(prob.n)
    if not prob.m:
        T = prob.period_value(p) if prob.forced else float(horizon)
        return prob.pack(t0, [x0], [T])
    if horizon is None:
        horizon = 2.0 * prob.period_value(p) if prob.forced else None
    if horizon is None:
        raise ArgumentError("give `horizon` (a bound on a segment's duration) to follow the "
                            "signature of an autonomous orbit")
    # a first step far below the horizon: the kernel's steps then grow from it (at most
    # tenfold each), so a short segment (a bounce of a chattering sequence) is resolved
    opts = dict(prob._seg_opts(p, dense=True, variational=False),
                first_step=max(1e-10 * horizon, 1e-300))
    z = np.concatenate([x0, p])
    t = float(t0)
    starts, durs = [None] * prob.m, [None] * prob.m
    for step, i in enumerate(list(range(prob.m)) + [0]):
        start_t, start_x = t, z[:prob.n].copy()
        te, y = _first_zero(prob, i, t, z, horizon, opts)
        tau, X, *_ = prob._map(prob.bounds[i], te, y, prob.sys)
        if step:
            starts[i] = (start_t, start_x)
            durs[i] = te - start_t
        t = tau
        z = np.array(X, dtype=float)
        z[prob.n:] = p
    if not prob.forced:
        prob.t_ref = float(starts[0][0])
    return prob.pack(starts[0][0], [s[1] for s in starts], durs)


def from_simulation(prob, t0: float, x0, p=None, *, horizon: float | None = None):
    """``u`` from a simulation of the model from ``x0`` at ``t0`` (in the state of segment
    0), when its events reproduce the signature (from its first event on, and the first
    event once more); ``None`` otherwise. The simulator resolves what :func:`follow`
    cannot: the bounces at the end of a chattering sequence rise less than the
    integration error."""
    p = prob._p(p)
    if not prob.m:
        return None
    if horizon is None:
        horizon = 2.5 * prob.period_value(p) if prob.forced else None
    if horizon is None:
        return None
    ctx = model_context(prob.model, prob.param_dict(p), prob.sliding)
    fk = prob.fields[0]

    if fk.kind == "mode":
        st = KernelState(REGULAR, -1, fk.index)
    elif fk.kind == "stick":
        st = KernelState(STICK, fk.index, fk.mode)
    elif fk.kind == "slide_multi":
        st = KernelState(SLIDE_MULTI, fk.index, fk.mode)
    else:
        st = KernelState(SLIDE, fk.index, int(ctx.stab[fk.index]["above"]))
    opts = dict(prob.opts, variational=False, dense=False, throw=False, mode=None)
    nev = len(prob.signature)
    try:
        run = ctx.run(np.asarray(x0, dtype=float), st, float(t0), float(t0) + horizon, opts,
                      stop=AfterEvents(nev + 1), admit=False)
    except (ValueError, FloatingPointError):
        return None
    evs = list(run.event_log(ctx.model))
    if len(evs) < nev + 1 or Signature(evs[:nev]) != prob.signature or \
            (evs[nev].kind, evs[nev].name) != (prob.signature[0].kind,
                                               prob.signature[0].name):
        return None
    groups = _groups(prob.signature)
    te = [float(evs[g[0]].t) for g in groups]
    tau = [float(evs[g[-1]].t_after) for g in groups]
    X = [np.asarray(evs[g[-1]].x_after, dtype=float) for g in groups]
    t_s = tau[-1]
    xs = [X[-1]] + X[:-1]
    durs = [float(evs[nev].t) - t_s] + [te[i] - tau[i - 1] for i in range(1, prob.m)]
    if not prob.forced:
        prob.t_ref = float(t_s)
    return prob.pack(t_s, xs, durs)


def _first_zero(prob, i, t, z, horizon, opts):
    """The first zero of segment ``i``'s condition from ``(t, z)`` within ``horizon``,
    searched in eight pieces of the horizon (a mode's field continued far beyond its
    surfaces may blow up: the search stops at the zero, or where integration fails)."""
    from scipy.optimize import brentq

    sysm = prob.sys
    ci = prob._cidx[i]
    side = None
    t_a, z_a = t, z
    for piece in range(8):
        t_b = t_a + horizon / 8.0
        tr = run_compiled(prob.sys.cm, z_a, t_a, t_b, prob._pv, opts, mode0=prob._fidx[i],
                          admit=False).trajectory(prob.sys.cm.model, opts, t_a, t_b)
        ts = sample_times(tr)
        if len(ts) < 2:
            break
        Y = tr(ts)
        vals = np.array([sysm.scalar(ci, tt, yy, prob._pv, grad=False)
                         for tt, yy in zip(ts, Y)])
        if side is None:
            # the condition may vanish at the start (an impact surface just after the
            # impact, a bounce of a chattering sequence): its side is then the one its
            # rate points to
            scale = 1.0 + float(np.max(np.abs(Y[:, :prob.n])))
            band = ADMISSIBILITY_RTOL * scale
            c0, cz0, ct0 = sysm.scalar(ci, ts[0], Y[0], prob._pv)
            side = np.sign(vals[0])
            # a start tangent to the condition (a sliding exit on the surface the next
            # sliding entry is on) cannot tell its side from round-off: a crossing must
            # then leave the band
            need = 0.0
            if abs(vals[0]) <= band:
                f0 = sysm.field(prob._fidx[i], ts[0], Y[0], prob._pv)
                rate = ct0 + cz0 @ f0
                side = np.sign(rate)
                rband = band * max(1.0, float(np.max(np.abs(cz0))) * float(
                    np.max(np.abs(f0))))
                if abs(rate) <= rband:
                    need = band
                    nz = vals[np.abs(vals) > band]
                    side = np.sign(nz[0]) if len(nz) else 1.0

        def g(tt):
            return sysm.scalar(ci, tt, tr(tt), prob._pv, grad=False)

        for k in range(1, len(vals)):
            if vals[k] * side < -need and np.isfinite(vals[k]):
                a, b = ts[k - 1], ts[k]
                if g(a) * side <= 0:
                    # the start's own zero (round-off on the wrong side): the last point
                    # on the condition's side before b
                    grid = np.linspace(a, b, 65)[1:-1]
                    on = [tt for tt in grid if g(tt) * side > 0]
                    if not on:
                        continue
                    a = on[-1]
                tz = brentq(g, a, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)
                return tz, np.array(tr(tz), dtype=float)
        if tr.status.failed or not np.all(np.isfinite(tr.x_final)):
            break
        t_a, z_a = float(tr.t_final), np.array(tr.x_final, dtype=float)
    raise ArgumentError(f"cannot follow the signature from t = {t:.10g}: segment {i} "
                        f"({prob.state_names[i]}) does not reach its "
                        f"{prob.bounds[i].kind} condition within {horizon:.6g}; the guess "
                        f"is not near an orbit of signature {prob.signature}")
