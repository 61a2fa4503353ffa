"""Lyapunov spectra of piecewise-smooth flows and maps.

Flows: the variational equations ``Phi' = f_x Phi`` are integrated with the state and, at
every event, ``Phi`` is multiplied by the event's saltation matrix (impacts, crossings,
sliding entry and exit, the complete-chattering map; slides "Saltation matrices"). Tangent
dynamics that ignore these jumps give wrong exponents (DESIGN.md; ChaosTools.jl issue 324).
The run is cut into segments (default one forcing period): each segment starts from the end
state of the previous one with ``Phi = I``, so the kernel returns the segment's Jacobian
``J_k`` (saltations included); the tangent basis is updated by ``J_k Q = Q' R`` (QR
re-orthonormalisation, Benettin et al. 1980) and ``lambda_i = sum_k log|R_ii| / total time``.

The sum of the exponents is then ``log|det prod J_k| / time``, which by Liouville's formula
and ``det(S Phi) = det S det Phi`` equals the mean divergence ``tr f_x`` along the orbit plus
the mean of ``log|det S|`` over the events per unit time -- the sum rule that
tests/test_explore.py checks against closed forms of ``tr f_x`` and ``det S``.

Maps: the same QR iteration with the Jacobian of the applied piece at every iterate
(:func:`pwsdyn.model.maps.lyapunov_kernel`), per iteration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from .. import __version__
from .. import _validate as V
from ..errors import ArgumentError
from ..integrate.simulate import check_mode, integrator_options, _simulate_compiled, state_vector
from ..stability._context import forcing_period
from ._common import ModelContext, check_bound, failed_status, readmit


@dataclass
class LyapunovSpectrum:
    """The result of :func:`lyapunov_spectrum`.

    Attributes
    ----------
    exponents : numpy.ndarray, shape (n,)
        Lyapunov exponents in decreasing order, per unit time (flows) or per iteration (maps).
        ``-inf`` where the tangent dynamics collapse a direction exactly (Filippov sliding:
        the saltation matrix of sliding entry has rank n - 1).
    time : float
        Averaging time (flows: time units; maps: iterations).
    convergence : numpy.ndarray, shape (n_segments, n)
        Running estimates after each segment (Gram-Schmidt order), to judge convergence.
    events : dict
        Number of events of each kind in the averaging window (flows).
    status : int
        0, or the :class:`pwsdyn.Status` of a failed simulation (-1: diverged).
    x_final : numpy.ndarray
    provenance : dict
    """

    exponents: np.ndarray
    time: float
    convergence: np.ndarray
    events: dict = field(default_factory=dict)
    status: int = 0
    x_final: np.ndarray | None = None
    provenance: dict = field(default_factory=dict)

    @property
    def sum(self) -> float:
        return float(np.sum(self.exponents))


def _sticking_projector(ctx: ModelContext, t: float, x, p, kind: int, event: int, mode: int):
    """Projector onto the tangent space of the sticking manifold {h = 0, hdot = 0} of impact
    event ``event``, along span(h_x, hdot_x) -- the derivative of the projection the kernel
    applies at the end of a chattering sequence."""
    from ..model.codegen import W_HDX, W_HX

    n = ctx.model.n_states
    k = ctx.model.events[event].surface
    nm = len(ctx.model.modes)
    pv = p if len(p) else np.zeros(1)
    buf = np.zeros(max(n, 2))
    ctx.cm.evaluate(W_HX, k, float(t), np.asarray(x, float), pv, buf)
    a = buf[:n].copy()
    ctx.cm.evaluate(W_HDX, k * nm + mode, float(t), np.asarray(x, float), pv, buf)
    b = buf[:n].copy()
    A = np.vstack([a, b])
    return np.eye(n) - A.T @ np.linalg.solve(A @ A.T, A)


def flow_segments(ctx: ModelContext, x, t0: float, seg: float, n_seg: int, p, opts,
                  bound: float, keep_events: bool = False):
    """Integrate ``n_seg`` segments of length ``seg`` with the variational equations and QR.

    Returns (sums of log|R_ii| (n,), segments done, x_end, status, starts (n_seg, n) -- the
    state at the start of each segment, events (list, if ``keep_events``), running estimates).
    """
    n = ctx.model.n_states
    Q = np.eye(n)
    sums = np.zeros(n)
    starts = np.full((n_seg, n), np.nan)
    running = np.full((n_seg, n), np.nan)
    events = []
    vopts = {**opts, "variational": True, "dense": False, "throw": False}
    status = 0
    done = 0
    x = np.array(x, dtype=float)
    discrete = None   # the discrete state the previous segment ended in
    for k in range(n_seg):
        ta = t0 + k * seg
        P0 = None
        if discrete is not None and discrete[0] == 1:
            # still sticking: continue in the sticking state (a restart in free flight would
            # register the contact again with a chattering saltation each segment), and
            # start Phi on the tangent space of the sticking manifold {h = 0, hdot = 0}:
            # perturbations off it return to it in finite time (superstable directions)
            P0 = _sticking_projector(ctx, ta, x, p, *discrete)
            traj = _simulate_compiled(ctx.cm, x, ta, ta + seg, p, vopts, mode0=discrete[2],
                                      dkind0=1, didx0=discrete[1])
        else:
            x = readmit(ctx, ta, x, p)
            traj = _simulate_compiled(ctx.cm, x, ta, ta + seg, p, vopts)
        starts[k] = x
        status = failed_status(traj)
        if status:
            break
        if keep_events:
            events.extend(traj.events)
        x = traj.x_final.copy()
        discrete = traj.final_discrete_state
        if not check_bound(x, bound):
            status = -1
            break
        J = traj.jacobian if P0 is None else traj.jacobian @ P0
        Qn, R = np.linalg.qr(J @ Q)
        d = np.abs(np.diag(R))
        if not np.all(np.isfinite(d)):
            status = -1
            break
        # R_ii = 0: the segment maps a direction to zero (sliding collapses the normal
        # direction onto the switching surface): that exponent is -inf
        with np.errstate(divide="ignore"):
            sums += np.log(d)
        Q = Qn
        done = k + 1
        running[k] = sums / (done * seg)
    return sums, done, x, status, starts, events, running


def lyapunov_spectrum(model, x0, params: Mapping[str, float] | None = None, *,
                      transient: int = 100, duration: int = 1000, segment: float | None = None,
                      t0: float = 0.0, bound: float = 1e8, **options) -> LyapunovSpectrum:
    """The full Lyapunov spectrum of a piecewise-smooth flow (with saltation matrices at every
    event) or map, by QR re-orthonormalisation.

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
    x0 : sequence or dict
        Initial state.
    params : dict, optional
        Parameter values overriding the model's defaults.
    transient : int
        Segments (flows) or iterations (maps) discarded before averaging (default 100).
    duration : int
        Segments (flows) or iterations (maps) averaged over (default 1000).
    segment : float, optional
        Length of a segment (flows): default the forcing period; required for autonomous
        flows. The basis is re-orthonormalised once per segment.
    t0 : float
        Start time (flows).
    bound : float
        A state component beyond this magnitude counts as divergence (status -1).
    **options
        Integrator options of :func:`pwsdyn.simulate` (``rtol``, ``atol``, ``method``, ...).

    Returns
    -------
    LyapunovSpectrum

    Raises
    ------
    ArgumentError
        (a ``ValueError``) Before any work: a non-positive duration, an autonomous flow
        without ``segment``, a non-finite ``t0``, a run not resolved in double-precision time
        from ``t0`` (see :mod:`pwsdyn._validate`), a ``duration`` whose per-segment records
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
    t0 = V.number("t0", t0)
    bound = V.positive("bound", bound, allow_inf=True)
    model = V.model(model, caller="lyapunov_spectrum()")
    p = model.parameter_vector(params)
    x = state_vector(model, x0)
    n = model.n_states
    prov = {"model": model.name, "model_hash": model.hash, "pwsdyn_version": __version__,
            "params": dict(zip(model.parameters, map(float, p)))}
    if getattr(model, "is_map", False):
        if options or segment is not None:
            raise ArgumentError("integrator options and `segment` apply to flows only, not to "
                                f"map {model.name!r}")
        ctx = ModelContext.get(model)
        from ..model.maps import MAP_DIVERGED, MAP_OK, lyapunov_kernel

        st, ex, xe, done = lyapunov_kernel(ctx.cm.step, x, p if p.size else np.zeros(1),
                                           int(transient), int(duration), float(bound))
        status = 0 if st == MAP_OK else (-1 if st == MAP_DIVERGED else int(st))
        return LyapunovSpectrum(np.sort(ex)[::-1], float(done), ex[None, :], {}, status, xe,
                                prov)
    opts = {**integrator_options(options, "lyapunov_spectrum()"), "dense": False,
            "throw": False}
    check_mode(model, opts)
    if segment is None:
        segment = forcing_period(model, p)       # checked: positive and finite
        if segment is not None:
            segment = model.forcing_period_value(params)
        else:
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
    status = 0
    if transient:
        x = readmit(ctx, t, x, p)
        tr = _simulate_compiled(ctx.cm, x, t, t + transient * segment, p, opts)
        status = failed_status(tr)
        x = tr.x_final.copy()
        t += transient * segment
    if status:
        n = model.n_states
        return LyapunovSpectrum(np.full(n, np.nan), 0.0, np.zeros((0, n)), {}, status, x, prov)
    sums, done, xe, status, _, events, running = flow_segments(
        ctx, x, t, segment, int(duration), p, opts, bound, keep_events=True)
    counts: dict = {}
    for e in events:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    ex = sums / (done * segment) if done else np.full(model.n_states, np.nan)
    prov.update(segment=segment, transient=int(transient), duration=int(duration),
                options={k: v for k, v in opts.items() if k not in ("throw",)})
    return LyapunovSpectrum(np.sort(ex)[::-1], done * segment, running[:done], counts, status,
                            xe, prov)
