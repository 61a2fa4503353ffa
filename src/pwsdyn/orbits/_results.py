"""What is computed from a solution of an orbit problem (:class:`~pwsdyn.orbits.OrbitProblem`):
the monodromy matrix (the segments' flow Jacobians and the boundaries' full saltation
matrices), the Floquet multipliers, the reported :class:`~pwsdyn.PeriodicOrbit` with its
one-period trajectory, and the derivatives of the orbit along its branch
(:class:`OrbitSensitivity`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError, Status
from ..integrate.trajectory import EventRecord, Trajectory
from ..integrate import compiled
from ..stability import floquet_multipliers
from ._admissibility import admissibility
from ._base import STABILITY_MARGIN
from ._orbit import PeriodicOrbit
from ._sampling import sample_times
from .surfaces import model_context, state_field


def monodromy(prob, ev) -> np.ndarray:
    """The one-period Jacobian (full saltation matrices) at the start of segment 0."""
    M = np.eye(prob.n)
    for i, s in enumerate(ev.segs):
        M = s.Phi[:prob.n, :prob.n] @ M
        if i < len(prob.bounds):
            M = boundary_saltation(prob, i, s) @ M
    return M


def boundary_saltation(prob, i, s) -> np.ndarray:
    """Full saltation matrix of boundary ``i`` (model states), of its event map
    ``(t, x) -> (tau, X)`` (``event_map_saltation``, the one formula, in the compiled-model
    layer :mod:`pwsdyn.integrate.compiled`)."""
    n = prob.n
    k = (i + 1) % prob.m
    zX = np.array(s.X, dtype=float)
    Fo = prob.sys.field(prob._fidx[k], s.tau, zX, prob._pv)[:n]
    fi = s.f_end[:n]
    cx = s.c_z[:n]
    den = s.c_t + cx @ fi
    # den = 0 at an event with zero normal velocity (a graze): the matrix is infinite,
    # left to the callers to see (multipliers NaN)
    with np.errstate(divide="ignore", invalid="ignore"):
        return compiled.event_map_saltation(s.X_y[:n, :n], s.X_t[:n], fi, Fo, cx, den,
                                            tau_x=s.tau_y[:n], tau_t=s.tau_t)


def multipliers(prob, ev) -> np.ndarray:
    """Floquet multipliers of the orbit at ``ev`` (nontrivial ones, autonomous)."""
    M = monodromy(prob, ev)
    if prob.forced:
        return floquet_multipliers(M)
    f0 = ev.segs[0].f_start[:prob.n]
    return floquet_multipliers(M, flow_direction=f0)

# ---- the base point of a reported orbit ------------------------------------------------

def _base_point(prob, ev, t0=None, x_ref=None, normal=None):
    """``(k, s, shift)``: the base point lies in segment ``k``, ``s`` after its start, and
    its time is ``t_k + s + shift`` (``shift`` a multiple of the period).

    Forced: the segment containing ``t0`` modulo the period. Autonomous with a section
    (``x_ref``, ``normal``): where the orbit crosses ``normal . (x - x_ref) = 0`` with
    ``normal . f > 0``, nearest ``x_ref``. Otherwise the middle of the longest segment in
    a mode (the longest segment)."""
    segs = ev.segs
    P = ev.period
    if not prob.m:
        if t0 is not None and prob.forced:
            k = math.floor((t0 - segs[0].t) / P)
            return 0, t0 - segs[0].t - k * P, k * P
        return 0, 0.0, 0.0
    if prob.forced and t0 is not None:
        kshift = math.floor((t0 - segs[0].t) / P)
        tt = t0 - kshift * P
        for i, sg in enumerate(segs):
            if sg.T > 0 and sg.t <= tt < sg.te:
                return i, tt - sg.t, kshift * P
    if not prob.forced and x_ref is not None and normal is not None:
        best = None
        opts = prob._seg_opts(ev.p, dense=True, variational=False)
        x_ref = np.asarray(x_ref, dtype=float)
        normal = np.asarray(normal, dtype=float)
        for i, sg in enumerate(segs):
            if sg.T <= 0:
                continue
            _, _, tr = prob._flow(i, sg.t, sg.z, sg.T, opts)
            ts = sample_times(tr)
            g = np.asarray(tr(ts))[:, :prob.n] @ normal - normal @ x_ref
            for kk in range(1, len(ts)):
                if g[kk - 1] < 0 <= g[kk]:
                    from scipy.optimize import brentq

                    tz = brentq(lambda tt: normal @ (tr(tt)[:prob.n] - x_ref), ts[kk - 1],
                                ts[kk], xtol=1e-15, rtol=4 * np.finfo(float).eps)
                    d = float(np.linalg.norm(tr(tz)[:prob.n] - x_ref))
                    if (0.0 < tz - sg.t < sg.T) and (best is None or d < best[0]):
                        best = (d, i, tz - sg.t)
        if best is not None:
            shift = 0.0
            if t0 is not None and P > 0:
                tb = segs[best[1]].t + best[2]
                shift = round((t0 - tb) / P) * P
            return best[1], best[2], shift
    cands = [i for i, f in enumerate(prob.fields) if f.kind == "mode"] or list(
        range(prob.m))
    k = max(cands, key=lambda i: segs[i].T)
    return k, 0.5 * segs[k].T, 0.0


def _order(prob, k):
    return list(range(k, prob.m)) + list(range(k))

# ---- the reported orbit ----------------------------------------------------------------

def orbit(prob, u, p=None, *, t0=None, x_ref=None, phase_normal=None, history=None,
          converged: bool = True):
    """The :class:`~pwsdyn.PeriodicOrbit` at ``(u, p)``.

    Its base point: forced orbits at time ``t0`` (default: the middle of the longest
    segment in a mode); autonomous orbits where they cross the hyperplane through
    ``x_ref`` with normal ``phase_normal`` (the section of
    :func:`pwsdyn.find_periodic_orbit`), else the middle of the longest segment. The
    trajectory (one period, dense, with the variational solution) is assembled from the
    segments integrated in their discrete states and the events from the signature, so
    an orbit that is not admissible is reported as it is, with ``admissible = False`` and
    the reason. Monodromy: the segments' flow Jacobians and the boundaries' full
    saltation matrices (:func:`boundary_saltation`).
    """

    p = prob._p(p)
    ev = prob.evaluate(u, p, jacobian=False)
    adm = admissibility(prob, u, p, ev)
    n = prob.n
    k, s_off, shift = _base_point(prob, ev, t0, x_ref, phase_normal)
    P = ev.period
    opts = prob._seg_opts(p, dense=True, variational=True)
    segs = ev.segs
    sk = segs[k]
    t_base = sk.t + s_off + shift
    zb, _, _ = prob._flow(k, sk.t, sk.z, s_off, opts)
    # pieces: (run or None for no time, state name, start time, start state)
    first = P if not prob.m else sk.T - s_off
    pieces = [(prob._flow(k, t_base, zb, first, opts)[2], prob.state_names[k], t_base, zb)]
    records, salts = [], []
    order = _order(prob, k) if prob.m else []
    for pos, i in enumerate(order):
        sg = segs[i]
        off = shift + (P if i < k else 0.0)
        b = prob.bounds[i] if prob.m else None
        if b is not None:
            S = boundary_saltation(prob, i, sg)
            e0 = b.events[0]
            records.append(EventRecord(sg.te + off, e0.name, e0.kind, sg.y[:n].copy(),
                                       np.array(sg.X[:n]), e0.mode_before, e0.mode_after,
                                       sg.tau + off))
            salts.append(S)
            for e in b.events[1:]:
                records.append(EventRecord(sg.tau + off, e.name, e.kind,
                                           np.array(sg.X[:n]), np.array(sg.X[:n]),
                                           e.mode_before, e.mode_after, sg.tau + off))
                salts.append(np.eye(n))
        nxt = order[pos + 1] if pos + 1 < len(order) else None
        if nxt is not None:
            sn = segs[nxt]
            offn = shift + (P if nxt < k else 0.0)
            pieces.append((prob._flow(nxt, sn.t + offn, sn.z, sn.T, opts)[2],
                           prob.state_names[nxt], sn.t + offn, sn.z))
    if prob.m:
        pieces.append((prob._flow(k, sk.t + shift + P, sk.z, s_off, opts)[2],
                       prob.state_names[k], sk.t + shift + P, sk.z))
    traj, transfer, M = _assemble(prob, pieces, records, salts, p, t_base, t_base + P)
    x0 = np.array(zb[:n], dtype=float)
    state0 = prob.state_names[k]
    autonomous = not prob.forced
    ctx = model_context(prob.model, prob.param_dict(p), prob.sliding)
    trivial = pj = nv = None
    if not np.all(np.isfinite(M)):
        # an event at zero normal velocity (the orbit at a graze of its own impact): the
        # saltation matrix is infinite there and the orbit has no multipliers
        mult = np.full(n - (1 if autonomous else 0), np.nan + 0j)
    elif autonomous:
        f0 = state_field(ctx, prob.fields[k], t_base, x0)
        nv = f0 if phase_normal is None else np.asarray(phase_normal, dtype=float)
        mult = floquet_multipliers(M, flow_direction=f0, section_normal=nv)
        pj = M - np.outer(f0, nv @ M) / (nv @ f0)
        eg = np.linalg.eigvals(M)
        trivial = complex(eg[np.argmin(np.abs(eg - 1.0))])
    else:
        mult = floquet_multipliers(M)
    hist = list(history) if history is not None else [prob.norm(ev.F, u)]
    nodes = np.array([t_base] + [segs[i].t + shift + (P if i < k else 0.0)
                                 for i in order[1:]])
    if not prob.m:
        nodes = np.array([t_base])
    orbit = PeriodicOrbit(
        model=prob.model, params=prob.param_dict(p), t0=float(t_base), x0=x0,
        state0=state0, period=float(P), events=records, trajectory=traj, monodromy=M,
        multipliers=mult, stable=bool(np.all(np.abs(mult) < 1.0 - STABILITY_MARGIN)),
        history=hist, converged=converged, autonomous=autonomous,
        trivial_multiplier=trivial, poincare_jacobian=pj,
        phase_normal=None if nv is None else np.asarray(nv, dtype=float).copy(),
        nodes=nodes, residual=float(hist[-1]),
        closure=float(np.max(np.abs(traj.x[-1] - x0))),
        options={k2: v for k2, v in prob.opts.items() if k2 != "throw"},
        admissible=adm.admissible, reason=adm.reason, locked=True)
    orbit._source = (prob, np.asarray(u, dtype=float).copy(), p.copy())
    return orbit


def _assemble(prob, pieces, records, salts, p, t_start, t_end):
    """One period as a :class:`Trajectory` of the model from the segments' runs (their
    model states and Jacobian block), the event records and the saltation matrices
    between them; returns it, its transfer matrices ``[Phi, S, Phi, ..., S, Phi]`` (an
    event followed by the start of sticking: ``S, I, I``) and the monodromy."""
    n, na = prob.n, prob.sys.naug
    cols = list(range(n)) + [na + i * na + c for i in range(n) for c in range(n)]
    eye = np.eye(n)
    phis = [tr.jacobian[:n, :n].copy() if tr is not None else eye for tr, *_ in pieces]
    transfer = [phis[0]]
    Pstart = [eye]
    Pm = phis[0].copy()
    r = 0
    for idx in range(1, len(pieces)):
        transfer.append(salts[r])
        Pm = salts[r] @ Pm
        r += 1
        while r < len(records) and records[r].kind == "stick":
            transfer += [eye, salts[r]]
            Pm = salts[r] @ Pm
            r += 1
        Pstart.append(Pm.copy())
        transfer.append(phis[idx])
        Pm = phis[idx] @ Pm
    return _build_traj(prob, pieces, cols, Pstart, p, t_start, t_end, records, transfer, Pm)


def _build_traj(prob, pieces, cols, Pstart, p, t_start, t_end, records, transfer, M):
    n = prob.n
    ts, ys, states, dense, ikind = [], [], [], [], []
    deg = None
    for tr, *_ in pieces:
        if tr is not None:
            deg = np.asarray(tr.dense).shape[2]
            break
    for idx, ((tr, name, ta, za), P0) in enumerate(zip(pieces, Pstart)):
        if tr is None:
            y = np.concatenate([za[:n], P0.reshape(-1)])[None, :]
            t = np.array([float(ta)])
            d = np.zeros((0, n + n * n, deg or 1))
            ik = np.zeros(0, dtype=np.int64)
        else:
            y = np.asarray(tr.y, dtype=float)[:, cols].copy()
            t = np.asarray(tr.t, dtype=float)
            d = np.asarray(tr.dense, dtype=float)[:, cols, :].copy()
            ik = np.asarray(tr.interval_kind, dtype=np.int64)
            N = len(y)
            y[:, n:] = np.matmul(y[:, n:].reshape(N, n, n), P0).reshape(N, n * n)
            if len(d):
                d[:, n:, :] = np.einsum("iabk,bc->iack",
                                        d[:, n:, :].reshape(len(d), n, n, -1),
                                        P0).reshape(len(d), n * n, -1)
        if idx:
            ikind.append(np.array([2 if t[0] > ts[-1][-1] else 1], dtype=np.int64))
            dense.append(np.zeros((1, n + n * n, deg or 1)))
        ts.append(t)
        ys.append(y)
        states.append(np.array([name] * len(t)))
        ikind.append(ik)
        dense.append(d)
    Y = np.concatenate(ys)
    traj = Trajectory.from_parts(
        t=np.concatenate(ts), x=Y[:, :n].copy(), state=np.concatenate(states),
        events=list(records), status=Status.SUCCESS, message=Status.SUCCESS.message,
        stats={}, model=prob.model, params=prob.param_dict(p),
        options={k: v for k, v in prob.opts.items() if k != "throw"}, t0=float(t_start),
        t_end=float(t_end), jacobian=M, transfer_matrices=transfer,
        dense=np.concatenate(dense) if deg else None, interval_kind=np.concatenate(ikind),
        y=Y, provenance={"model": prob.model.name, "model_hash": prob.model.hash,
                          "pwsdyn_version": _version()})
    return traj, transfer, M

# ---- sensitivity -------------------------------------------------------------------------

def sensitivity(prob, u, p, name, *, t0=None, x_ref=None, phase_normal=None,
                rel_step: float = 1e-4):
    """Derivatives of a solution ``(u, p)`` along its branch in parameter ``name``.

    ``du/dp = -F_u^-1 F_p`` (the implicit function theorem), carried to the base point of
    :func:`orbit` (forced: the state at the fixed time ``t0``; autonomous: the crossing of
    the fixed section ``(x_ref, phase_normal)``, or the middle of the segment), the period,
    the events' times and states (exact, from the same chain rule as ``F_u``), and the
    Floquet multipliers: ``d mu_i = (V^-1 dM V)_ii`` (first-order perturbation of a simple
    eigenvalue of the monodromy ``M = V diag(mu) V^-1``), with ``dM`` the fourth-order
    central difference of the monodromy of the orbits at ``p +- h``, ``p +- 2h`` (solved by
    Newton from the tangent predictor), ``h = rel_step * max(1, |p|)``: error ``O(h^4)``
    plus the integration error over ``h``, about ``1e-8`` with the default tolerances.
    """
    if name not in prob.parameters:
        raise ArgumentError(f"`name` must be a parameter of the problem "
                            f"{list(prob.parameters)}, got {name!r}")
    p = prob._p(p)
    j = prob.parameters.index(name)
    ev = prob.evaluate(u, p)
    N, n = prob.size, prob.n
    up = np.linalg.solve(ev.F_u, -ev.F_p[:, j])
    dw = np.zeros(N + prob.q)
    dw[:N] = up
    dw[N + j] = 1.0
    k, s_off, shift = _base_point(prob, ev, t0, x_ref, phase_normal)
    sg = ev.segs[k]
    opts = prob._seg_opts(p)
    yb, Phib, _ = prob._flow(k, sg.t, sg.z, s_off, opts)
    fb = prob.sys.field(prob._fidx[k], sg.t + s_off, yb, prob._pv)
    D = Phib @ sg.Dz - np.outer(Phib @ sg.f_start, sg.Dt)
    if prob.forced and t0 is not None:
        pass   # the base time is fixed
    elif not prob.forced and x_ref is not None and phase_normal is not None and prob.m:
        nv = np.asarray(phase_normal, dtype=float)
        Dsec = D + np.outer(fb, sg.Dt)
        Ds = -(nv @ Dsec[:n]) / (nv @ fb[:n])
        D = Dsec + np.outer(fb, Ds)
    elif prob.m:
        # the middle of segment k: s = T_k / 2
        Ds = 0.5 * (sg.Dte - sg.Dt)
        D = D + np.outer(fb, sg.Dt + Ds)
    dx0 = (D @ dw)[:n]
    if prob.forced:
        dP = float(prob._period_grad(p)[j])
    else:
        dP = float(ev.Dperiod @ dw)
    times, before, after = [], [], []
    for i in _order(prob, k) if prob.m else []:
        s = ev.segs[i]
        b = prob.bounds[i]
        times.append(float(s.Dte @ dw))
        before.append((s.Dy @ dw)[:n])
        after.append((s.DX @ dw)[:n])
        for _ in b.events[1:]:
            times.append(float(s.Dtau @ dw))
            before.append((s.DX @ dw)[:n])
            after.append((s.DX @ dw)[:n])
    # d mu: first-order perturbation of the eigenvalues of the monodromy matrix M(u, p)
    # (Wilkinson: d lambda_i = (V^-1 dM V)_ii for a simple eigenvalue, V its right
    # eigenvectors), dM the central difference of M along the branch tangent; an
    # autonomous orbit's nontrivial multipliers are the eigenvalues of M other than 1
    h = rel_step * max(1.0, abs(p[j]))
    mu0 = np.atleast_1d(multipliers(prob, ev))
    e = np.zeros(prob.q)
    e[j] = h

    def M_at(s):
        # the orbit at p + s h: Newton from the tangent predictor (off the branch, M has
        # large higher derivatives: an open cycle's trivial multiplier drifts from 1)
        ut = u + s * h * up
        res = prob.solve(ut, p + s * e, tol=1e-13, max_iter=8)
        if res.converged or res.history[-1] < 1e-11:
            ut = res.x
        return monodromy(prob, prob.evaluate(ut, p + s * e, jacobian=False))

    # fourth-order central difference (Richardson): error O(h^4) + noise / h
    dM = (8.0 * (M_at(1.0) - M_at(-1.0)) - (M_at(2.0) - M_at(-2.0))) / (12.0 * h)
    M0 = monodromy(prob, ev)
    lam, Vr = np.linalg.eig(M0)
    if np.linalg.cond(Vr) < 1e8:
        dlam = np.diag(np.linalg.solve(Vr, dM @ Vr))
        dmu = np.array([dlam[int(np.argmin(np.abs(lam - m0)))] for m0 in mu0])
    else:
        # repeated eigenvalues (two zero multipliers of sticking): differences of the
        # eigenvalues themselves, matched to the nearest
        lp = np.linalg.eigvals(M0 + h * dM)
        lm = np.linalg.eigvals(M0 - h * dM)
        dmu = np.array([(_nearest(lp, m0) - _nearest(lm, m0)) / (2 * h) for m0 in mu0])
    if np.all(np.isreal(mu0)) and np.all(np.abs(np.imag(dmu)) <= 1e-12 * (
            1 + np.abs(dmu))):
        dmu = np.real(dmu)
    return OrbitSensitivity(parameter=name, x0=dx0, period=dP, multipliers=dmu,
                            event_times=np.array(times), x_before=np.array(before),
                            x_after=np.array(after), u=up)


@dataclass(frozen=True)
class OrbitSensitivity:
    """Derivatives of a periodic orbit with respect to a parameter along its branch
    (:meth:`~pwsdyn.PeriodicOrbit.sensitivity`).

    Attributes
    ----------
    parameter : str
    x0 : numpy.ndarray
        ``d x0 / d p``: forced orbits at the fixed time ``t0``; autonomous orbits in the fixed
        section through ``x0`` with normal ``phase_normal``.
    period : float
        ``d period / d p`` (forced: ``periods * d forcing_period / d p``).
    multipliers : numpy.ndarray
        ``d mu / d p`` of each of ``orbit.multipliers`` (same order).
    event_times, x_before, x_after : numpy.ndarray
        Derivatives of each event's time and states (order of ``orbit.events``).
    u : numpy.ndarray
        ``d u / d p`` of the orbit problem's unknowns.
    """

    parameter: str
    x0: np.ndarray
    period: float
    multipliers: np.ndarray
    event_times: np.ndarray
    x_before: np.ndarray
    x_after: np.ndarray
    u: np.ndarray


def _nearest(values, target):
    values = np.atleast_1d(values)
    return values[int(np.argmin(np.abs(values - target)))]


def _version():
    from .._version import __version__

    return __version__
