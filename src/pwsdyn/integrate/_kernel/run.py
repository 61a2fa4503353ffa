"""The runner: :func:`run_kernel` (the stepping loop that calls the parts) and
:func:`dense_coefficients` (a step's dense output rebuilt on demand).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...model.codegen import W_F, W_GUARD, W_H, W_HD, W_HHD
from .._codes import (ACT_EVENT, ACT_EXIT_ABOVE, ACT_EXIT_BELOW, ACT_EXIT_MULTI, ACT_INTERSECTION,
                      ACT_RELEASE, ACT_SWITCH, EV_IMPACT, IV_CHATTER, IV_JUMP,
                      IV_STEP, K_CHATTER, K_STICK, K_TRANSITION, REGULAR, SAVE_DENSE, SAVE_EVENTS,
                      SLIDE, SLIDE_MULTI, STICK, ST_INTERSECTION, ST_MAX_EVENTS, ST_MAX_STEPS,
                      ST_NONFINITE,
                      ST_STEP_TOO_SMALL, ST_SUCCESS, ST_TERMINAL, ST_ZENO, SW_CONTINUOUS,
                      VAR_NONE, VAR_SEGMENTS,
                      WF_HDDOT, WF_HDOT, WF_LAMBDA, WF_SURFACE)
from ._base import (EVENT_TABLE_TYPE, OPTIONS_TYPE, SWITCH_TABLE_TYPE, _COINCIDENT_ULPS, _EPS,
                    _EXACT_TERMS, _MAXW, _grow1, _grow2, _grow3,
                    _log_event, _ulp, compiled_on_first_use)
from .fields import (_block_row, _clear_lambda_cache, _field, _multi_corners, _multi_count,
                     _multi_offsets, _multi_surface, _next_touching, _project_multi,
                     _project_surface, _rate_band, _resolve, _rhs, _start_on_surface,
                     multi_work_size)
from .steppers import (_affine_setup, _dense_eval, _error_norm, _exact_stepper, _step_dense,
                       _step_stages, _take_samples)
from .watch import (_crosses, _graze_samples, _hdot_rate, _hermite_extrema, _locate_exact,
                    _merge_samples, _surface_rate, _watch_pair, _watch_slope, _watch_value)
from .actions import (_act_impact, _act_intersection, _act_multi_exit, _act_multi_intersection,
                      _act_release, _act_slide_exit, _act_switch, _act_transition,
                      _action_saltation, _after_reset, _apply_saltation, _stick_meets_slide)

# --------------------------------------------------------------------------------------
# dense output on demand
# --------------------------------------------------------------------------------------

def _dense_coefficients(ev, p, etab, stab, options, A, C, P, s_fsal, t0, x0, nodes_t,
                        nodes_y, nodes_s, hstep, which, deg):
    """Power-form dense output (as stored with ``SAVE_DENSE``) of the step intervals
    ``which`` of a run made with ``SAVE_NODES``, rebuilt from their start nodes: the step from
    ``(nodes_t[i], nodes_y[i])`` of length ``hstep[i]`` in the discrete state ``nodes_s[i]``
    is taken again -- the Runge-Kutta stages and the dense-output stages, or the Taylor terms
    of the exact flow -- with the run's options (``options``, the tableau). The
    stages are computed as in the kernel from the same numbers, so the coefficients are the
    ones it would have stored (to rounding: after a projected sliding step the kernel's first
    stage is the field before the projection). Rows of intervals with ``hstep <= 0`` (jumps,
    chattering gaps) are zero. Not for variational runs, whose nodes are transformed after
    the run (they store their dense output: ``SAVE_DENSE``)."""
    n = x0.shape[0]
    opts = options[0]
    nm = opts.n_modes
    nvar = 1 if opts.variational != VAR_NONE else 0
    nY = nodes_y.shape[1]
    slide_c = opts.sliding_gain
    nz, aff_ok, aff_M, aff_h, aff_s, aff_w = _affine_setup(ev, t0, x0, p, n, nm, opts.exact != 0)
    s_ext = A.shape[0]
    K = np.zeros((s_ext, nY))
    ytmp = np.zeros(nY)
    y = np.zeros(nY)
    Q = np.zeros((nY, max(deg, P.shape[1], _EXACT_TERMS if nz > 0 else 1)))
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(max(n * n, multi_work_size(n, stab)))
    hdx = np.zeros(n)
    jac = np.zeros(n * n)
    xt = np.zeros(n)
    ft = np.zeros(n)
    zv = np.zeros(max(nz, 1))
    zv1 = np.zeros(max(nz, 1))
    out = np.zeros((which.shape[0], nY, deg))
    wk = (w1, w2, gx, hdx, jac, xt, ft)
    aff = (aff_M, aff_s, aff_w, zv, zv1)
    for r in range(which.shape[0]):
        i = which[r]
        h = hstep[i]
        if not h > 0.0:
            continue
        dkind = nodes_s[i, 0]
        didx = nodes_s[i, 1]
        mode = nodes_s[i, 2]
        t = nodes_t[i]
        for c in range(nY):
            y[c] = nodes_y[i, c]
        exact = nz > 0 and dkind == REGULAR and nvar == 0 and aff_ok[mode] == 1
        if not exact:
            _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, K[0], etab, stab, slide_c,
                 w1, w2, gx, hdx, jac, xt, ft)
            _step_stages(ev, p, exact, dkind, didx, mode, nm, t, y, h, h, K, A, C, s_fsal, Q, ytmp,
                         etab, stab, slide_c, wk)
        _step_dense(ev, p, exact, dkind, didx, mode, nm, t, y, h, h, K, A, C, s_fsal, P, Q, ytmp,
                    etab, stab, slide_c, wk, nz, aff)
        for c in range(nY):
            for k in range(deg):
                out[r, c, k] = Q[c, k]
    return out


def _dense_coefficients_signature():
    from numba import types as nt

    from ...model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    f2 = nt.float64[:, ::1]
    i1 = nt.int64[::1]
    i2 = nt.int64[:, ::1]
    return nt.float64[:, :, ::1](EVALUATE_TYPE, f1, EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE,
                                 OPTIONS_TYPE, f2, f1, f2, nt.int64, nt.float64, f1, f1, f2, i2,
                                 f1, i1, nt.int64)


#: :func:`_dense_coefficients`, compiled on first use: runs that never evaluate their dense
#: output do not wait for it.
dense_coefficients = compiled_on_first_use(_dense_coefficients, _dense_coefficients_signature,
                                           nogil=True)


# --------------------------------------------------------------------------------------
# the kernel
# --------------------------------------------------------------------------------------

def _kernel_signature():
    from numba import types as nt

    from ...model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    f2 = nt.float64[:, ::1]
    i1 = nt.int64[::1]
    i2 = nt.int64[:, ::1]
    ret = nt.Tuple((nt.int64, nt.float64, f1, i1, f1, f2, i2, nt.float64[:, :, ::1], i1, f1, f1,
                    i2, f2, f2, i1, f2, f1))
    return ret(EVALUATE_TYPE, nt.float64, nt.float64, f1, f1, EVENT_TABLE_TYPE, i2,
               SWITCH_TABLE_TYPE, OPTIONS_TYPE, f2, f1, f2, f2, nt.int64)


# nogil: a run holds no Python object, so a Dask worker's event loop (heartbeats, transfers)
# and other threads go on while it integrates
@njit(_kernel_signature(), cache=True, nogil=True)
def run_kernel(ev, t0, t_end, x0, p, etab, eactive, stab, options, A, C, E, P, s_fsal):
    """Integrate from ``t0`` to ``t_end``. See the module docstring.

    Tables
    ------
    etab : (n_events,) records of ``EVENT_TABLE`` -- surface, direction, kind, target,
        terminal, has_reset, time_dependent (:mod:`pwsdyn._codes`)
    eactive : (n_events, n_modes) int64, 1 where the event is watched in the mode
    stab : (n_switches,) records of ``SWITCH_TABLE`` -- surface, above, below, kind
        (SW_FILIPPOV / SW_CONTINUOUS), sliding (SLIDE_CONVEX / SLIDE_UTKIN), time_dependent
    options : one record of ``KERNEL_OPTIONS``, the run's options by name
        (:func:`pwsdyn._codes.kernel_options`)

    Returns
    -------
    status, t, y, final discrete state, nodes_t, nodes_y, nodes_state (kind, idx, mode), dense
    (per interval; ``SAVE_DENSE`` only, else no rows), interval kind (0 step, 1 jump, 2
    chatter gap), event log (t, t_after, info, x_before, x_after), stats, samples, and the
    length of the step of each interval (0 for jumps; with ``SAVE_NODES`` the dense output is
    rebuilt from it, :func:`dense_coefficients`)
    """
    n = x0.shape[0]
    opts = options[0]
    nm = opts.n_modes
    nvar = 1 if opts.variational != VAR_NONE else 0
    seg_var = opts.variational == VAR_SEGMENTS
    stop_mask = opts.stop_mask
    stop_ref = opts.stop_ref
    stop_count = opts.stop_count
    n_stop = 0
    nY = n + nvar * n * n
    method = opts.method
    max_steps = opts.max_steps
    max_events = opts.max_events
    chatter_on = opts.chatter
    save_all = opts.save != SAVE_EVENTS
    store_q = opts.save == SAVE_DENSE
    rtol = opts.rtol
    atol = opts.atol
    hmax = opts.max_step
    slide_c = opts.sliding_gain
    chat_rel = opts.chatter_ratio
    chat_abs = opts.chatter_velocity
    s_ext = A.shape[0]
    deg = P.shape[1]
    n_events = etab.shape[0]
    # exact propagation of affine modes: their augmented matrices, balancing weights and the
    # largest step (see _affine_setup)
    nz, aff_ok, aff_M, aff_h, aff_s, aff_w = _affine_setup(ev, t0, x0, p, n, nm, opts.exact != 0)
    if nz > 0:
        deg = max(deg, _EXACT_TERMS)
    zv = np.zeros(max(nz, 1))
    zv1 = np.zeros(max(nz, 1))
    # propagator exp(h M) per mode for the step length aff_ph (most steps have the same one)
    aff_P = np.zeros((nm, max(nz, 1), max(nz, 1)))
    aff_ph = np.full(nm, -1.0)
    T1 = np.zeros((max(nz, 1), max(nz, 1)))
    T2 = np.zeros((max(nz, 1), max(nz, 1)))
    n_sw = stab.shape[0]
    # the order of the propagated solution: the exponent of the step-size control (Hairer,
    # Norsett & Wanner I, II.4)
    order = 5.0 if method == 0 else 8.0
    if opts.order > 0:
        order = float(opts.order)

    # work arrays
    # K[0]: the field at (t, y), made at every restart and carried by Runge-Kutta steps
    # (FSAL). Exact steps leave it behind: nothing on their path reads it (their surface
    # rates are the model's hdot, their landing is the dense output), and a mode turns
    # exact or stops being so only at a restart, which makes it again.
    K = np.zeros((s_ext, nY))
    kst = np.zeros(nY)
    ytmp = np.zeros(nY)
    ynew = np.zeros(nY)
    y = np.zeros(nY)
    Q = np.zeros((nY, deg))
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    n_work = multi_work_size(n, stab)
    gx = np.zeros(max(n * n, n_work))
    hdx = np.zeros(n)
    jac = np.zeros(n * n)
    xt = np.zeros(n)
    ft = np.zeros(n)
    buf = np.zeros(max(n, 2, n_work))
    o_corners = _multi_offsets(n)[8]
    fbuf = np.zeros(n)
    xs = np.zeros(nY)
    Kland = np.zeros((s_ext, nY))
    S = np.zeros((n, n))
    Phi = np.zeros((n, n))
    # the vector fields' work vectors and the affine tables, passed as one argument each
    wk = (w1, w2, gx, hdx, jac, xt, ft)
    aff = (aff_M, aff_s, aff_w, zv, zv1)

    # outputs
    cap = 256
    nodes_t = np.empty(cap)
    nodes_y = np.empty((cap, nY))
    nodes_s = np.empty((cap, 3), dtype=np.int64)
    # power-form dense output per interval (SAVE_DENSE only) and the length of each step
    dense = np.empty((cap if store_q else 0, nY, deg))
    hstep = np.empty(cap)
    ikind = np.empty(cap, dtype=np.int64)
    ecap = 16
    ev_t = np.empty(ecap)
    ev_t2 = np.empty(ecap)
    # columns: kind, ref, kind/idx/mode before, kind/idx/mode after, index of the post-event node
    ev_info = np.empty((ecap, 9), dtype=np.int64)
    ev_xb = np.empty((ecap, nY))
    ev_xa = np.empty((ecap, nY))
    rec = np.zeros(9, dtype=np.int64)   # one event record's integer columns
    stats = np.zeros(6, dtype=np.int64)  # steps, rejected, nfev, events, chatter, landing steps
    n_nodes = 0
    n_ev = 0

    # state
    t = t0
    for i in range(n):
        y[i] = x0[i]
    if nvar:
        for i in range(n):
            for c in range(n):
                y[n + i * n + c] = 1.0 if i == c else 0.0
    dkind = REGULAR
    didx = -1
    mode = opts.mode0
    dkind = opts.dkind0
    didx = opts.didx0
    status = ST_SUCCESS
    # Non-finite input ends the run at once, before any work: a NaN compares false with
    # everything, so a NaN time or step size would never reach t_end nor fall below the
    # smallest step, and the stepping loop would spin (rejected steps do not count against
    # max_steps). Infinite ones are refused too: t_end = inf never ends, and x0 or
    # first_step = inf make the first step NaN. max_step = inf is fine (no limit).
    h0 = opts.first_step
    if not (np.isfinite(t0) and np.isfinite(t_end) and np.isfinite(h0) and not np.isnan(hmax)
            and np.isfinite(rtol) and np.isfinite(atol)):
        status = ST_NONFINITE
    for i in range(n):
        if not np.isfinite(x0[i]):
            status = ST_NONFINITE
    # sampling: off for dt <= 0; a NaN or infinite dt (a NaN forcing period or phase of a
    # sweep) or a non-finite first sample time is non-finite input
    sdt_in = opts.sample_dt
    if np.isnan(sdt_in) or (sdt_in > 0.0 and not (np.isfinite(sdt_in)
                                                   and np.isfinite(opts.sample_t0))):
        status = ST_NONFINITE
    if status == ST_SUCCESS and dkind == REGULAR and n_sw > 0:
        # the mode on the right side of every switching surface; sliding from a start on one
        dkind, didx, mode = _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx)

    # watch list. Sized from the model's tables, never a fixed capacity: in any discrete
    # state an event or a switch is watched at most once (the loops below add one entry per
    # event or switch at most), plus the release (sticking) or the two exits (sliding); the
    # _MAXW spare entries leave room for more functions per state
    wcap = n_events + n_sw + _MAXW
    wtype = np.zeros(wcap, dtype=np.int64)
    widx = np.zeros(wcap, dtype=np.int64)
    wmode = np.zeros(wcap, dtype=np.int64)
    wdir = np.zeros(wcap, dtype=np.int64)
    wact = np.zeros(wcap, dtype=np.int64)
    wref = np.zeros(wcap, dtype=np.int64)
    wforce = np.zeros(wcap)      # forced sign at the start of the next step (re-trigger guard)
    wv = np.zeros(wcap)          # watch values at the end of the last accepted step ...
    wd = np.zeros(wcap)          # ... and their time derivatives (surfaces), reused next step
    wvalid = np.zeros(wcap, dtype=np.int64)
    wtdep = np.zeros(wcap, dtype=np.int64)  # surface depends on t explicitly (moving wall)
    nw = 0
    # the surface/function that just fired, to suppress an immediate re-trigger
    last_type = -1
    last_idx = -1
    last_mode = -1
    last_sign = 0.0
    last_t = np.nan
    # events at one instant: the guards of functions that fired earlier at last_t (kept with
    # the last one's), and crossings that coincide with the event being handled (found
    # between the bracketed and the polished event time) still to fire at pend_t
    co_type = np.zeros(wcap, dtype=np.int64)
    co_idx = np.zeros(wcap, dtype=np.int64)
    co_mode = np.zeros(wcap, dtype=np.int64)
    co_sign = np.zeros(wcap)
    co_t = np.zeros(wcap)
    n_co = 0
    pend_type = np.zeros(wcap, dtype=np.int64)
    pend_idx = np.zeros(wcap, dtype=np.int64)
    pend_mode = np.zeros(wcap, dtype=np.int64)
    pend_act = np.zeros(wcap, dtype=np.int64)
    pend_ref = np.zeros(wcap, dtype=np.int64)
    n_pend = 0
    pend_t = np.nan
    wpend = np.zeros(wcap, dtype=np.int64)
    # chattering chain bookkeeping
    chain_event = -1
    chain_vmax = 0.0
    zeno = 0
    last_depth = 0.0

    noise = 0.0
    vals = np.zeros((wcap, 8))
    thetas = np.zeros(8)
    rates = np.zeros(8)           # time derivatives of a watch function at the samples
    ex_th = np.zeros(8)           # samples of the release watch's extremum search
    ex_g = np.zeros(8)

    # first node
    nodes_t[0] = t
    nodes_y[0, :] = y
    nodes_s[0, 0] = dkind
    nodes_s[0, 1] = didx
    nodes_s[0, 2] = mode
    n_nodes = 1

    # stroboscopic sampling on the dense output (no event, no landing step)
    n_samp = 0
    n_need = 0
    s0 = 0.0
    sdt = 0.0
    sk = 0
    # the samples are bounded by the step budget (each costs about what a stored step does):
    # a run that would record more than max_steps of them ends at once with ST_MAX_STEPS
    # instead of looping ~(t_end - t0) / dt times (dt = 1e-300); max_samp caps the sampling
    # loops as a backstop (one more for the rounding of the count)
    max_samp = max_steps + 2
    if status == ST_SUCCESS and opts.sample_dt > 0.0:
        s0 = opts.sample_t0
        sdt = opts.sample_dt
        kf = max(0.0, np.ceil((t - s0) / sdt))
        # index of the first sample; beyond 2^53 (an s0 that far before t0) neither it nor
        # s0 + k sdt is exact, and int() of it would overflow
        if kf > 2.0 ** 53 or (t_end - s0) / sdt - kf + 1.0 > max_steps:
            status = ST_MAX_STEPS
            sdt = 0.0
        sk = int(kf) if status == ST_SUCCESS else 0
        if sdt > 0.0:
            # room for every sample (at most max_steps + 2, checked above): the array is not
            # grown inside the stepping loop (see the outer loop below)
            n_need = int(max(0.0, min((t_end - s0) / sdt - kf, float(max_steps)))) + 3
    samp = np.empty((max(n_need, 1), 1 + n))
    max_samp = min(max_samp, samp.shape[0])
    if sdt > 0.0:
        if s0 + sk * sdt == t:
            samp[0, 0] = t
            for i in range(n):
                samp[0, 1 + i] = y[i]
            n_samp = 1
            sk += 1

    restart = True
    h = h0
    # Every iteration of this loop either accepts a step (counted in stats[0], bounded by
    # max_steps; event handling, also without an event, follows an accepted step) or rejects
    # one (error, non-finite stage, unresolved moving surface). A rejection shrinks h by a
    # factor <= 0.9, a step grows it by <= 10, and h below 4 ulp(t) ends the run, so the
    # rejections are bounded too -- provided t and h stay finite, which the checks at each
    # restart (t, y, field) and before each step (h) guarantee.
    # The stepping loop never reassigns an array: numba keeps a reassigned array in a phi
    # variable and updates its reference count (two atomic operations) at every pass of the
    # loop, ~15% of a step for the seven output arrays. Room for the next iteration's nodes
    # (at most two) and event records (at most two) is made here, in an outer loop that the
    # stepping loop leaves only to grow them.
    finished = False
    while not finished:
        if n_nodes + 4 > nodes_t.shape[0]:
            need = 2 * nodes_t.shape[0] + 4
            nodes_t = _grow1(nodes_t, need)
            nodes_y = _grow2(nodes_y, need)
            nodes_s = _grow2(nodes_s, need)
            ikind = _grow1(ikind, need)
            hstep = _grow1(hstep, need)
            if store_q:
                dense = _grow3(dense, need)
        if n_ev + 4 > ev_t.shape[0]:
            need = 2 * ev_t.shape[0] + 4
            ev_t = _grow1(ev_t, need)
            ev_t2 = _grow1(ev_t2, need)
            ev_info = _grow2(ev_info, need)
            ev_xb = _grow2(ev_xb, need)
            ev_xa = _grow2(ev_xa, need)
        finished = True
        while True:
            if n_nodes + 4 > nodes_t.shape[0] or n_ev + 4 > ev_t.shape[0]:
                finished = False
                break
            if restart:
                if status != ST_SUCCESS:
                    # refused input (above); tested here, not in the loop condition, which
                    # measured ~40% slower on every step
                    break
                # (re)build the watch list for the current discrete state
                nw = 0
                if dkind == SLIDE_MULTI:
                    _clear_lambda_cache(buf, n)
                    # the corner modes of the intersection, kept in buf for the watches of
                    # the weights (_watch_value) and read below (-1: a corner is missing)
                    _multi_corners(stab, didx, mode, buf, o_corners)
                for j in range(n_events):
                    if eactive[j, mode] == 0:
                        continue
                    if dkind == STICK and etab[j].surface == etab[didx].surface:
                        continue
                    if dkind == SLIDE or dkind == SLIDE_MULTI:
                        continue
                    wtype[nw] = WF_SURFACE; widx[nw] = etab[j].surface; wmode[nw] = mode
                    wdir[nw] = etab[j].direction; wact[nw] = ACT_EVENT; wref[nw] = j
                    nw += 1
                # the switches in table order; those of a sign family's block (all on one
                # surface) by arithmetic, not one by one (_next_touching, _block_row)
                s = 0
                while s < n_sw:
                    if dkind == SLIDE_MULTI or dkind == SLIDE:
                        # a further surface bounding the modes slid between: crossed while
                        # sliding, or reaching (joining) the intersection with it; one watch
                        # per surface, from its first switch that touches one of those modes
                        r = -1
                        if dkind == SLIDE_MULTI:
                            # the corners of the intersection
                            b0 = stab[s].block
                            nxt = s + 1 if b0 < 0 else stab[s].block_end
                            if not (didx >> stab[s].surface) & 1:
                                for c in range(1 << _multi_count(didx)):
                                    mc = int(buf[o_corners + c])
                                    if b0 >= 0:
                                        rc = _block_row(stab, b0, mc)
                                        if rc >= s and (r < 0 or rc < r):
                                            r = rc
                                    elif stab[s].above == mc or stab[s].below == mc:
                                        r = s
                                        break
                        else:
                            # the sliding pair's two modes
                            s = min(_next_touching(stab, s, stab[didx].above),
                                    _next_touching(stab, s, stab[didx].below))
                            if s >= n_sw:
                                break
                            nxt = s + 1
                            if stab[s].surface != stab[didx].surface:
                                r = s
                        if r >= 0:
                            dup = False
                            for ww in range(nw):
                                if wact[ww] == ACT_INTERSECTION and widx[ww] == stab[r].surface:
                                    dup = True
                            if not dup:
                                wtype[nw] = WF_SURFACE; widx[nw] = stab[r].surface
                                wmode[nw] = mode; wdir[nw] = 0; wact[nw] = ACT_INTERSECTION
                                wref[nw] = r
                                nw += 1
                        s = nxt
                        continue
                    s = _next_touching(stab, s, mode)
                    if s >= n_sw:
                        break
                    watched = True
                    if dkind == STICK and stab[s].kind == SW_CONTINUOUS:
                        # a kink surface that the sticking motion lies in (bilinear damping of
                        # a relative velocity held at zero against a stop): the two variants
                        # agree there, and its sign is round-off
                        ev(W_H, stab[s].surface, t, y, p, buf)
                        xmax = 1.0
                        for i in range(n):
                            xmax = max(xmax, abs(y[i]))
                        if abs(buf[0]) <= 1e3 * _EPS * xmax:
                            watched = False
                    if watched:
                        wtype[nw] = WF_SURFACE; widx[nw] = stab[s].surface; wmode[nw] = mode
                        wdir[nw] = -1 if stab[s].above == mode else 1
                        wact[nw] = ACT_SWITCH; wref[nw] = s
                        nw += 1
                    s += 1
                if dkind == STICK:
                    k = etab[didx].surface
                    wtype[nw] = WF_HDDOT; widx[nw] = k; wmode[nw] = mode
                    wdir[nw] = 1; wact[nw] = ACT_RELEASE; wref[nw] = didx
                    nw += 1
                if dkind == SLIDE:
                    k = stab[didx].surface
                    # leave above when hdot of the above field turns positive (alpha -> 0),
                    # below when hdot of the below field turns negative (alpha -> 1)
                    wtype[nw] = WF_HDOT; widx[nw] = k; wmode[nw] = stab[didx].above
                    wdir[nw] = 1; wact[nw] = ACT_EXIT_ABOVE; wref[nw] = didx
                    nw += 1
                    wtype[nw] = WF_HDOT; widx[nw] = k; wmode[nw] = stab[didx].below
                    wdir[nw] = -1; wact[nw] = ACT_EXIT_BELOW; wref[nw] = didx
                    nw += 1
                    for j in range(n_events):
                        if eactive[j, stab[didx].above] == 0 and eactive[j, stab[didx].below] == 0:
                            continue
                        wtype[nw] = WF_SURFACE; widx[nw] = etab[j].surface; wmode[nw] = mode
                        wdir[nw] = etab[j].direction; wact[nw] = ACT_EVENT; wref[nw] = j
                        nw += 1
                if dkind == SLIDE_MULTI:
                    # leave surface i of the intersection where its weight lambda_i reaches 0
                    # (to the side above) or 1 (below): one watch per surface,
                    # min(lambda_i, 1 - lambda_i) (each watch costs a Newton solve per sample,
                    # on the sign family's field where it applies, else over all corner
                    # fields), whose corner modes are kept in buf (set above; _watch_value)
                    for i in range(_multi_count(didx)):
                        wtype[nw] = WF_LAMBDA; widx[nw] = i; wmode[nw] = didx
                        wdir[nw] = -1; wact[nw] = ACT_EXIT_MULTI; wref[nw] = i
                        nw += 1
                    for j in range(n_events):
                        active = False
                        for c in range(1 << _multi_count(didx)):
                            mc = int(buf[o_corners + c])
                            if mc >= 0 and eactive[j, mc] != 0:
                                active = True
                        if not active:
                            continue
                        wtype[nw] = WF_SURFACE; widx[nw] = etab[j].surface; wmode[nw] = mode
                        wdir[nw] = etab[j].direction; wact[nw] = ACT_EVENT; wref[nw] = j
                        nw += 1
                for w in range(nw):
                    wvalid[w] = 0
                    wtdep[w] = 0
                    if wtype[w] == WF_SURFACE:
                        if wact[w] == ACT_EVENT:
                            wtdep[w] = etab[wref[w]].time_dependent
                        else:
                            wtdep[w] = stab[wref[w]].time_dependent
                    wforce[w] = 0.0
                    if (t == last_t and wtype[w] == last_type and widx[w] == last_idx
                            and (wtype[w] == WF_SURFACE or wmode[w] == last_mode)):
                        wforce[w] = last_sign
                    else:
                        for c in range(n_co):
                            if (wtype[w] == co_type[c] and widx[w] == co_idx[c]
                                    and (wtype[w] == WF_SURFACE or wmode[w] == co_mode[c])
                                    and abs(t - co_t[c]) <= _COINCIDENT_ULPS * _ulp(t)):
                                wforce[w] = co_sign[c]
                    wpend[w] = 0
                    if t == pend_t and wforce[w] == 0.0:
                        for c in range(n_pend):
                            if (pend_type[c] == wtype[w] and pend_idx[c] == widx[w]
                                    and pend_mode[c] == wmode[w] and pend_act[c] == wact[w]
                                    and pend_ref[c] == wref[w]):
                                wpend[w] = 1
                _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, kst, etab, stab, slide_c,
                     w1, w2, gx, hdx, jac, xt, ft)
                for i in range(nY):
                    K[0, i] = kst[i]
                stats[2] += 1
                # at the start and after every event (a reset, a chattering jump in time, a new
                # mode): time, state and field must be finite. A NaN field here would make the
                # first step size NaN (a step then neither accepted nor rejected for good).
                ok = np.isfinite(t)
                for i in range(nY):
                    if not (np.isfinite(y[i]) and np.isfinite(K[0, i])):
                        ok = False
                if not ok:
                    status = ST_NONFINITE
                    break
                if h <= 0.0:
                    # initial step (Hairer, Norsett & Wanner I, II.4): from the scales of y and f
                    d0 = 0.0
                    d1 = 0.0
                    for i in range(n):
                        sc = atol + rtol * abs(y[i])
                        d0 += (y[i] / sc) ** 2
                        d1 += (K[0, i] / sc) ** 2
                    d0 = np.sqrt(d0 / n)
                    d1 = np.sqrt(d1 / n)
                    h = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
                    # a state within atol of zero but not zero (a mass at rest a few 1e-14
                    # from the corner of an incline, with atol = 1e-13) has d0 ~ 1 and, with
                    # a field of order one, d1 ~ 1/atol: the estimate falls below the
                    # resolution of t, and the run would stop at once with STEP_TOO_SMALL.
                    # A first step too large is only rejected and shortened by the error
                    # control; one too small is fatal, so it is kept well above that limit.
                    h = max(h, 100.0 * _ulp(t))
                    h = min(h, abs(t_end - t))
                restart = False

            if t >= t_end:
                break
            if stats[0] >= max_steps:
                status = ST_MAX_STEPS
                break
            if not np.isfinite(h):
                # NaN from the error control (an error norm 0/0) or the initial-step estimate;
                # compared with anything it is false, so it must not reach the clipping below
                status = ST_NONFINITE
                break
            exact_now = nz > 0 and dkind == REGULAR and nvar == 0 and aff_ok[mode] == 1
            if exact_now:
                h = min(h, aff_h[mode])
            h = min(h, hmax, t_end - t)
            if h < 4.0 * _ulp(t):
                if t_end - t <= 4.0 * _ulp(t):
                    t = t_end
                    break
                status = ST_STEP_TOO_SMALL
                break

            # ---- one step: the exact flow of an affine mode or the Runge-Kutta pair
            if exact_now:
                err, finite, q_made, nf = _exact_stepper(mode, t, y, h, ynew, Q, aff, aff_P,
                                                         aff_ph, min(aff_h[mode], hmax), nz, T1,
                                                         T2)
            else:
                # the Runge-Kutta step, written out here: as a call it would pass ~20 arrays
                # per step, measured 10-15% of an RK45 step on a two-state model
                q_made = False
                nf = s_fsal
                fast = dkind == REGULAR and nvar == 0
                for st in range(1, s_fsal + 1):
                    cst = t + C[st] * h
                    for i in range(nY):
                        acc = 0.0
                        for m in range(st):
                            acc += A[st, m] * K[m, i]
                        ytmp[i] = y[i] + h * acc
                    # into a scratch vector: passing the row K[st] makes an array view, whose
                    # reference counting (two atomic updates) measured 30% of a step
                    if fast:
                        ev(W_F, mode, cst, ytmp, p, kst)
                    else:
                        _rhs(ev, p, dkind, didx, mode, nm, cst, ytmp, n, nvar, kst, etab, stab,
                             slide_c, w1, w2, gx, hdx, jac, xt, ft)
                    for i in range(nY):
                        K[st, i] = kst[i]
                # the FSAL stage was evaluated at y + h sum B K = the new solution
                finite = True
                for i in range(nY):
                    ynew[i] = ytmp[i]
                    if not (np.isfinite(K[s_fsal, i]) and np.isfinite(ynew[i])):
                        finite = False
                err = (_error_norm(K, E, method, s_fsal, y, ynew, h, 0, n, rtol, atol) if finite
                       else np.inf)
                if nvar and finite:
                    err = max(err, _error_norm(K, E, method, s_fsal, y, ynew, h, n, nY, rtol,
                              atol))
            stats[2] += nf
            if not (err <= 1.0):
                stats[1] += 1
                if not finite or err != err:
                    h *= 0.25
                    if h < 4.0 * _ulp(t):
                        status = ST_NONFINITE
                        break
                else:
                    h *= max(0.2, 0.9 * err ** (-1.0 / order))
                continue
            stats[0] += 1
            # dense output coefficients are made only when needed (stored steps, interior samples)
            q_ready = q_made
            if store_q and not q_ready:
                stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h, h, K, A,
                        C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                q_ready = True
            t_new = t + h
            if t_new > t_end or h >= t_end - t:
                # the last step, clipped to t_end - t: t + (t_end - t) can round one ulp past (or
                # short of) t_end; the run ends exactly at t_end
                t_new = t_end

            # ---- event detection on [t, t_new]
            best = -1
            best_th = 2.0
            best_sign = 0.0
            unresolved = False
            bad_watch = False  # a watch function (surface, hdot, hddot) NaN or inf at a step end
            tratio = 0.0   # largest midpoint mismatch / tolerance of time-dependent surfaces
            for w in range(nw):
                # Samples in increasing theta. Surfaces: the ends and the interior extrema of the
                # cubic Hermite fit built from h and hdot at the ends (where a graze hides);
                # other watch functions: the ends and the midpoint.
                if wtype[w] == WF_SURFACE:
                    if wvalid[w] == 1:
                        v0 = wv[w]
                        r0 = wd[w]
                    else:
                        v0 = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t, y, n, buf,
                                          fbuf, hdx)
                        r0 = _surface_rate(ev, p, dkind, widx[w], mode, nm, t, y, K[0], n, buf,
                                           hdx)
                        if ((wact[w] == ACT_EVENT or wact[w] == ACT_SWITCH)
                                and not (wforce[w] != 0.0 and t == last_t)):
                            # first step after a restart (start of the run, any event): on the
                            # surface within round-off is on it (the surface that just fired
                            # keeps its guard)
                            v0, r0 = _start_on_surface(ev, p, widx[w], dkind, mode, nm, t, y, n,
                                                       v0, r0, buf, hdx)
                            if wpend[w] == 1:
                                # crossed at the instant of the event just handled (see below):
                                # on the surface now, it fires here if the flow still goes on
                                v0 = 0.0
                    if dkind == REGULAR:
                        ev(W_HHD, widx[w] * nm + mode, t_new, ynew, p, buf)
                        v1 = buf[0]
                        r1 = buf[1]
                    else:
                        v1 = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t_new, ynew, n,
                                          buf, fbuf, hdx)
                        # (kst holds the last stage, K[s_fsal]: no array view per step)
                        r1 = _surface_rate(ev, p, dkind, widx[w], mode, nm, t_new, ynew, kst, n,
                                           buf, hdx)
                    if not (np.isfinite(v0) and np.isfinite(v1)):
                        bad_watch = True
                        break
                    wv[w] = v1
                    wd[w] = r1
                    d0 = r0 * h
                    d1 = r1 * h
                    if wtdep[w] == 1:
                        # a surface that moves in time (an oscillating constraint) while the state
                        # barely does (a mass at rest, free flight): the error control does not see
                        # the surface, so a step may span several of its oscillations. The cubic
                        # Hermite fit must reproduce h at the midpoint, or the step is retaken
                        # shorter.
                        if not q_ready:
                            stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y,
                                    h, h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz,
                                    aff)
                            q_ready = True
                        _dense_eval(y, Q, 0.5, nY, deg, xs)
                        hm = _watch_value(ev, p, WF_SURFACE, widx[w], wmode[w], nm, t + 0.5 * h,
                                          xs, n, buf, fbuf, hdx)
                        hh = 0.5 * (v0 + v1) + 0.125 * (d0 - d1)
                        hsc = max(abs(v0), abs(v1), abs(hm))
                        ratio = abs(hm - hh) / (0.01 * hsc + 64.0 * _EPS * (1.0 + hsc))
                        tratio = max(tratio, ratio)
                        if ratio > 1.0:
                            unresolved = True
                            break
                    ns = 1
                    thetas[0] = 0.0
                    vals[w, 0] = v0
                    # the interior extrema of the cubic Hermite fit (2.0: none)
                    ra, rb = _hermite_extrema(v0, v1, d0, d1)
                    if (exact_now and rb > 1.0 and ra < 1.0 and v0 * v1 > 0.0 and v0 * d0 > 0.0
                            and v1 * d1 < 0.0 and wtdep[w] == 0
                            and not (wforce[w] != 0.0 and t == last_t)):
                        # the one extremum of the fit lies beyond both ends, on the far side of
                        # zero (the exact flow moves away from the surface and back: the lowest
                        # point of a flight below a wall). Within the exact step's bound no
                        # crossing or graze hides there, and its sample (the step's Taylor
                        # series, a dense evaluation, the surface) would not change a decision
                        # below: it is not taken
                        ra = 2.0
                    if ra < 1.0:
                        thetas[ns] = ra
                        ns += 1
                    if rb < 1.0:
                        thetas[ns] = rb
                        ns += 1
                    if ns > 1 and not q_ready:
                        stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h,
                                h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                        q_ready = True
                    rates[0] = r0
                    for q in range(1, ns):
                        if dkind == REGULAR:
                            _dense_eval(y, Q, thetas[q], n, deg, xs)
                            ev(W_HHD, widx[w] * nm + mode, t + thetas[q] * h, xs, p, buf)
                            vals[w, q] = buf[0]
                            rates[q] = buf[1]
                        else:
                            vq, rq = _watch_pair(ev, p, wtype[w], widx[w], wmode[w], dkind, didx,
                                                 mode, nm, t, h, y, Q, n, deg, thetas[q], xs, buf,
                                                 fbuf, hdx, ft, etab, stab, slide_c, w1, w2, gx)
                            vals[w, q] = vq
                            rates[q] = rq
                    thetas[ns] = 1.0
                    vals[w, ns] = v1
                    rates[ns] = r1
                    ns += 1
                    # an extremum of h towards zero between two samples (near grazing): bounded
                    # search on the dense output instead of trusting the fit's extremum
                    search = False
                    for q in range(ns - 1):
                        if vals[w, q] * vals[w, q + 1] > 0.0:
                            sg = 1.0 if vals[w, q] > 0.0 else -1.0
                            if sg * wdir[w] <= 0 and sg * rates[q] < 0.0 < sg * rates[q + 1]:
                                search = True
                    if search:
                        ns = _graze_samples(ev, p, wtype[w], widx[w], wmode[w], wdir[w], dkind,
                                            didx, mode, nm, t, h, y, Q, n, deg, thetas, vals[w],
                                            rates, ns, xs, buf, fbuf, hdx, ft, etab, stab, slide_c,
                                            w1, w2, gx)
                else:
                    thetas[0] = 0.0
                    thetas[1] = 0.5
                    thetas[2] = 1.0
                    ns = 3
                    if wvalid[w] == 1:
                        vals[w, 0] = wv[w]
                    else:
                        vals[w, 0] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t, y, n,
                                                  buf, fbuf, hdx)
                        if wpend[w] == 1:
                            # changed sign at the instant of the event just handled (see below)
                            vals[w, 0] = 0.0
                    if not q_ready:
                        stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h,
                                h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                        q_ready = True
                    _dense_eval(y, Q, 0.5, nY, deg, xs)
                    vals[w, 1] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + 0.5 * h,
                                              xs, n, buf, fbuf, hdx)
                    vals[w, 2] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t_new, ynew,
                                              n, buf, fbuf, hdx)
                    if not (np.isfinite(vals[w, 0]) and np.isfinite(vals[w, 2])):
                        bad_watch = True
                        break
                    wv[w] = vals[w, 2]
                    if wtype[w] == WF_HDDOT or wtype[w] == WF_HDOT or wtype[w] == WF_LAMBDA:
                        # release from sticking, exit from sliding: the free normal
                        # acceleration, or the normal velocity of the field beyond, may change
                        # sign only in a short window around its extremum inside the step (the
                        # sliding flow touching the boundary of the sliding region, near an
                        # adding-sliding). Its slopes at the ends (central differences on the
                        # dense output; the end one is kept for the next step), the extrema of
                        # the Hermite fit and the bounded search of surfaces add samples there
                        if wvalid[w] == 1:
                            sd0 = wd[w]
                        else:
                            sd0 = _watch_slope(ev, p, wtype[w], widx[w], wmode[w], nm, t, h, y, Q,
                                               n, deg, 0.0, xs, buf, fbuf, hdx)
                        sd1 = _watch_slope(ev, p, wtype[w], widx[w], wmode[w], nm, t, h, y, Q, n,
                                           deg, 1.0, xs, buf, fbuf, hdx)
                        wd[w] = sd1
                        ra, rb = _hermite_extrema(vals[w, 0], vals[w, 2], sd0 * h, sd1 * h)
                        ex_th[0] = 0.0
                        ex_g[0] = vals[w, 0]
                        rates[0] = sd0
                        ne = 1
                        for rr in (ra, rb):
                            if 0.0 < rr < 1.0:
                                vq, rq = _watch_pair(ev, p, wtype[w], widx[w], wmode[w], dkind,
                                                     didx, mode, nm, t, h, y, Q, n, deg, rr, xs,
                                                     buf, fbuf, hdx, ft, etab, stab, slide_c, w1,
                                                     w2, gx)
                                ex_th[ne] = rr
                                ex_g[ne] = vq
                                rates[ne] = rq
                                ne += 1
                        ex_th[ne] = 1.0
                        ex_g[ne] = vals[w, 2]
                        rates[ne] = sd1
                        ne += 1
                        if ne > 2:
                            ne = _graze_samples(ev, p, wtype[w], widx[w], wmode[w], wdir[w], dkind,
                                                didx, mode, nm, t, h, y, Q, n, deg, ex_th, ex_g,
                                                rates, ne, xs, buf, fbuf, hdx, ft, etab, stab,
                                                slide_c, w1, w2, gx)
                            ns = _merge_samples(thetas, vals[w], ns, ex_th, ex_g, ne)
                forced = wforce[w] != 0.0 and t == last_t
                if forced:
                    vals[w, 0] = wforce[w] * max(abs(vals[w, 0]), 1e-300)
                    # right after an event on this function, values at round-off level are noise
                    noise = 0.0
                    for i in range(n):
                        noise = max(noise, abs(y[i]))
                    noise = max(1e3 * _EPS * (1.0 + noise), last_depth)
                # the first crossing in the event direction between consecutive samples
                prev_th = thetas[0]
                prev_v = vals[w, 0]
                for q in range(1, ns):
                    th = thetas[q]
                    vq = vals[w, q]
                    # a bracket that starts before the earliest crossing found so far may hold
                    # an earlier one (two surfaces crossed in one step: the later sample end is
                    # no bound)
                    if prev_th >= best_th:
                        break
                    if forced and abs(vq) <= noise:
                        prev_th = th
                        continue
                    if _crosses(prev_v, vq, wdir[w]):
                        if not q_ready:
                            stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y,
                                    h, h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz,
                                    aff)
                            q_ready = True
                        # locate by Illinois on the dense output within [prev_th, th]
                        a_th = prev_th
                        b_th = th
                        fa = prev_v
                        fb = vq
                        side = 0
                        width_check = b_th - a_th
                        if fa == 0.0:
                            # the function is exactly zero at the left sample and moves into the
                            # event direction from there (a start on the surface, or one within
                            # its round-off band, see above): the crossing is at that sample. The
                            # sign test below would take a zero end for the far side and slide
                            # the bracket to the step's end
                            b_th = a_th
                        elif (exact_now and dkind == REGULAR and wtype[w] == WF_SURFACE
                              and not forced):
                            # the exact flow: Newton with the surface's rate, where the crossing
                            # is resolved above round-off (else -1: Illinois below)
                            got = _locate_exact(ev, p, widx[w] * nm + mode, t, h, y, Q, nY, deg,
                                                a_th, b_th, fa, fb, xs, buf)
                            if got >= 0.0:
                                a_th = b_th = got
                        for it in range(400):
                            if (b_th - a_th) * h <= 2.0 * _ulp(t + b_th * h):
                                break
                            m_th = ((a_th * fb - b_th * fa) / (fb - fa) if fb != fa
                                    else 0.5 * (a_th + b_th))
                            # safeguard: bisect when two secant steps did not halve the bracket
                            # (Illinois stalls when one end value is tiny, e.g. right after an
                            # event)
                            if it % 2 == 1:
                                if b_th - a_th > 0.5 * width_check:
                                    m_th = 0.5 * (a_th + b_th)
                                width_check = b_th - a_th
                            if not (a_th < m_th < b_th):
                                m_th = 0.5 * (a_th + b_th)
                            _dense_eval(y, Q, m_th, nY, deg, xs)
                            fm = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + m_th * h,
                                              xs, n, buf, fbuf, hdx)
                            if forced and abs(fm) <= noise:
                                # still on the side just left: round-off around the last event
                                fm = wforce[w] * max(abs(fm), 1e-300)
                            if (fm > 0.0) == (fa > 0.0) and fm != 0.0:
                                a_th = m_th
                                fa = fm
                                if side == -1:
                                    fb *= 0.5
                                side = -1
                            else:
                                b_th = m_th
                                fb = fm
                                if side == 1:
                                    fa *= 0.5
                                side = 1
                        if b_th < best_th:
                            best_th = b_th
                            best = w
                            best_sign = -1.0 if prev_v > 0.0 else 1.0
                        break
                    prev_th = th
                    prev_v = vq

            if bad_watch:
                # a crossing of a NaN surface can never be seen: events would be missed silently.
                # Treated like a non-finite stage: retake the step shorter, down to the point
                # where the function turns non-finite (or at once, if it is at the start)
                stats[1] += 1
                for ww in range(nw):
                    wvalid[ww] = 0
                h *= 0.25
                if h < 4.0 * _ulp(t):
                    status = ST_NONFINITE
                    break
                continue

            if unresolved:
                # retake the step shorter (the surface was not resolved); cached watch values
                # belong to the rejected step
                stats[1] += 1
                # the Hermite midpoint error is O(h^4)
                h *= max(0.2, 0.9 * tratio ** -0.25)
                for ww in range(nw):
                    wvalid[ww] = 0
                continue

            if best < 0:
                # accept the whole step
                if dkind == SLIDE:
                    # keep the sliding state on its surface: the Runge-Kutta step conserves a
                    # linear h exactly but drifts off a curved or moving one by the local error;
                    # one Newton step along h_x removes that (projection; it leaves the sliding
                    # field non-stiff, unlike a large gain C of the -C h grad h term)
                    _project_surface(ev, p, stab[didx].surface, t_new, ynew, n, hdx, buf)
                elif dkind == SLIDE_MULTI:
                    # the same onto every surface of the intersection
                    _project_multi(ev, p, didx, t_new, ynew, n, hdx, buf)
                if save_all:
                    if store_q:
                        for i in range(nY):
                            for k in range(deg):
                                dense[n_nodes - 1, i, k] = Q[i, k]
                    for i in range(nY):
                        nodes_y[n_nodes, i] = ynew[i]
                    ikind[n_nodes - 1] = IV_STEP
                    hstep[n_nodes - 1] = h
                    nodes_t[n_nodes] = t_new
                    nodes_s[n_nodes, 0] = dkind
                    nodes_s[n_nodes, 1] = didx
                    nodes_s[n_nodes, 2] = mode
                    n_nodes += 1
                if sdt > 0.0 and s0 + sk * sdt <= t_new:
                    if not q_ready:
                        stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h,
                                h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                        q_ready = True
                    n_samp, sk = _take_samples(t, h, y, Q, nY, n, deg, s0, sdt, sk, t_end,
                                                     samp, n_samp, xs, max_samp)
                if t == last_t:
                    # the re-trigger guard holds while its function stays within the round-off
                    # band on the far side: a step ending there must not start the next one on the
                    # far side unguarded (a release whose flight rises less than the band would
                    # have its landing stepped over)
                    for ww in range(nw):
                        if wforce[ww] * wv[ww] < 0.0 and abs(wv[ww]) <= noise:
                            last_t = t_new
                t = t_new
                for i in range(nY):
                    y[i] = ynew[i]
                if not exact_now:
                    # (an exact step makes no field at its end: see K above)
                    for i in range(nY):
                        K[0, i] = K[s_fsal, i]
                for ww in range(nw):
                    wvalid[ww] = 1
                fac = 10.0 if err == 0.0 else min(10.0, max(0.2, 0.9 * err ** (-1.0 / order)))
                if tratio > 0.0:
                    # nor grow past the resolution of a moving surface
                    fac = min(fac, max(0.2, 0.9 * tratio ** -0.25))
                h = h * fac
                continue

            # ---- an event inside the step: land exactly on it with a shortened step, then
            # polish the time with Newton on the watch function (h / hdot) for surfaces. The
            # dense output of an exact step is the exact flow: there the landing "step" is its
            # evaluation, and the step's Taylor terms are rescaled to the shorter interval.
            w = best
            h_ev = best_th * h
            if not exact_now:
                # (an exact landing step is the dense output: it reads no stage)
                for i in range(nY):
                    Kland[0, i] = K[0, i]
            for polish in range(8):
                stats[2] += _step_stages(ev, p, exact_now, dkind, didx, mode, nm, t, y, h_ev, h,
                        Kland, A, C, s_fsal, Q, ytmp, etab, stab, slide_c, wk)
                stats[5] += 1
                for i in range(nY):
                    ynew[i] = ytmp[i]
                if (wtype[w] != WF_SURFACE and wtype[w] != WF_HDOT) or polish == 7:
                    break
                if best_th == 0.0:
                    # the function was zero at the step's start (on the surface, see the bracket
                    # above): the event is at t, where the state is given; Newton on round-off
                    # values (tangency: hv / hd ~ 1e-16 / 1e-16) would move it anywhere
                    break
                # Newton on h(t + h_ev) (or on hdot of a mode, for a sliding exit) with the
                # landing step as the flow: quadratic, so a few iterations bring the watch function
                # to round-off even for slow (near-grazing, tangential-exit) arrivals
                hv = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + h_ev, ynew, n, buf,
                                  fbuf, hdx)
                if wtype[w] == WF_SURFACE:
                    hd = _surface_rate(ev, p, dkind, widx[w], mode, nm, t + h_ev, ynew,
                                       Kland[s_fsal], n, buf, hdx)
                else:
                    hd = _hdot_rate(ev, p, widx[w], wmode[w], nm, t + h_ev, ynew, Kland[s_fsal], n,
                                    buf, hdx)
                if hd == 0.0 or hv == 0.0:
                    break
                dt = -hv / hd
                # (a NaN correction, from a NaN watch function, keeps the bracketed time)
                if (not np.isfinite(dt) or abs(dt) <= 2.0 * _ulp(t + h_ev) or h_ev + dt <= 0.0
                        or h_ev + dt > h):
                    break
                h_ev += dt
            # landing-step dense output (extra stages for DOP853; Taylor terms rescaled), where it
            # is stored or a sample falls in the landing step (most events of a sweep have none)
            if store_q or (sdt > 0.0 and s0 + sk * sdt <= t + h_ev):
                stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h_ev, h,
                        Kland, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
            t_ev = min(t + h_ev, t_end)
            # Events at one instant: another watched function (an event surface, a release or a
            # sliding exit) that changed sign between the step's start and the polished event
            # time crossed within the location error of this event (this one was bracketed
            # first; polishing moved its time past the other crossing). It fires at the same
            # time, right after this one (unless the new motion leaves it), instead of being
            # found on its far side after the restart and lost (a release lost that way left a
            # ball stuck to a table that pulls it).
            n_pend = 0
            pend_t = t_ev
            for ww in range(nw):
                if ww == w or (wtype[ww] == WF_SURFACE and widx[ww] == widx[w]):
                    continue
                vw = _watch_value(ev, p, wtype[ww], widx[ww], wmode[ww], nm, t_ev, ynew, n, buf,
                                  fbuf, hdx)
                if vals[ww, 0] != 0.0 and _crosses(vals[ww, 0], vw, wdir[ww]):
                    pend_type[n_pend] = wtype[ww]
                    pend_idx[n_pend] = widx[ww]
                    pend_mode[n_pend] = wmode[ww]
                    pend_act[n_pend] = wact[ww]
                    pend_ref[n_pend] = wref[ww]
                    n_pend += 1
            if sdt > 0.0 and s0 + sk * sdt <= t + h_ev:
                # samples up to the event (one at the event time takes the state before it)
                n_samp, sk = _take_samples(t, h_ev, y, Q, nY, n, deg, s0, sdt, sk, t_end,
                                                 samp, n_samp, xs, max_samp)
            # store the node just before the event (always, also when not saving all steps)
            if store_q:
                for i in range(nY):
                    for k in range(deg):
                        dense[n_nodes - 1, i, k] = Q[i, k]
            ikind[n_nodes - 1] = IV_STEP if save_all else IV_JUMP
            hstep[n_nodes - 1] = h_ev
            nodes_t[n_nodes] = t_ev
            for i in range(nY):
                nodes_y[n_nodes, i] = ynew[i]
            nodes_s[n_nodes, 0] = dkind
            nodes_s[n_nodes, 1] = didx
            nodes_s[n_nodes, 2] = mode
            n_nodes += 1

            # ---- handle the event: one action per kind of watch function
            n_ev0 = n_ev
            for i in range(nY):
                y[i] = ynew[i]
                xs[i] = ynew[i]
            t = t_ev
            old_kind = dkind
            old_idx = didx
            old_mode = mode
            log_kind = -1
            t_after = t
            act = wact[w]
            new_sign = best_sign
            chatter_tail = False
            contact_stick = False
            exit_below = False
            if act == ACT_EVENT:
                # Is the crossing an event? (Written out here, as the re-trigger guard below: a
                # call passing the watch arrays measured a few % of an event-dominated run.)
                # Events on one surface with complementary guards (stick or reverse at v = 0,
                # thesis eq. 5.4): the crossing belongs to the one whose guard holds.
                j = wref[w]
                ev(W_GUARD, j, t, y, p, buf)
                guard_ok = buf[0] != 0.0
                if not guard_ok:
                    for ww in range(nw):
                        if (ww != w and wact[ww] == ACT_EVENT and wtype[ww] == WF_SURFACE
                                and widx[ww] == widx[w]
                                and (wdir[ww] == 0 or wdir[ww] * new_sign > 0.0)):
                            ev(W_GUARD, wref[ww], t, y, p, buf)
                            if buf[0] != 0.0:
                                w = ww
                                j = wref[ww]
                                guard_ok = True
                                break
                # a crossing whose normal velocity points against the event direction is
                # round-off around a previous event (the state is already leaving): not an
                # event, unless that velocity is round-off itself (a state on the surface and
                # tangent to it is not leaving; the sign of the round-off must not decide)
                if dkind == REGULAR:
                    ev(W_HD, widx[w] * nm + mode, t, y, p, buf)
                    vn = buf[0]
                else:
                    _field(ev, p, dkind, didx, mode, nm, t, y, n, fbuf, etab, stab, slide_c, w1,
                           w2, gx, hdx)
                    vn = _surface_rate(ev, p, dkind, widx[w], mode, nm, t, y, fbuf, n, buf, hdx)
                moving_away = etab[j].direction != 0 and vn * etab[j].direction < 0.0
                if moving_away and abs(vn) <= _rate_band(ev, p, widx[w], mode, nm, t, y, n, hdx):
                    moving_away = False
                if not guard_ok or moving_away:
                    # no event: continue past this crossing
                    last_type = wtype[w]
                    last_idx = widx[w]
                    last_mode = wmode[w]
                    last_sign = new_sign
                    if moving_away:
                        last_sign = 1.0 if vn > 0.0 else -1.0
                        # the state sits a little on the far side (round-off of an earlier
                        # event) and is moving back: values within that depth are not a new
                        # crossing
                        ev(W_H, widx[w], t, y, p, buf)
                        last_depth = 4.0 * abs(buf[0])
                    last_t = t
                    # the interval [t_ev, ...] continues smoothly: the stored one is a step
                    ikind[n_nodes - 2] = IV_STEP if save_all else IV_JUMP
                    restart = True
                    continue
                j = wref[w]
                if etab[j].kind == EV_IMPACT:
                    (dkind, didx, mode, log_kind, t_after, chatter_tail, chain_event, chain_vmax,
                     chattered) = _act_impact(ev, p, j, dkind, didx, mode, nm, t, y, xs, n, etab,
                                              t_end, rtol, atol, chat_rel, chat_abs, chatter_on,
                                              chain_event, chain_vmax,
                                              vn if dkind == REGULAR else np.nan,
                                              buf, fbuf, ytmp, wk)
                    stats[4] += chattered
                else:
                    mode = _act_transition(ev, p, j, mode, t, y, xs, n, etab, ytmp)
                    log_kind = K_TRANSITION
                    chain_event = -1
                dkind, didx, mode, contact_stick = _after_reset(
                    ev, p, j, log_kind, chatter_tail, dkind, didx, mode, nm, t, y, n, etab, stab,
                    buf, fbuf, wk)
            elif act == ACT_RELEASE:
                dkind, didx, mode, log_kind = _act_release(ev, p, etab[old_idx].surface, mode,
                                                           nm, t, y, n, stab, buf, wk)
            elif act == ACT_SWITCH:
                dkind, didx, mode, log_kind, graze = _act_switch(ev, p, wref[w], old_kind,
                                                                 old_idx, old_mode, nm, t, y, n,
                                                                 stab, buf, hdx)
                if graze:
                    last_type = wtype[w]
                    last_idx = widx[w]
                    last_mode = wmode[w]
                    last_sign = new_sign
                    last_t = t
                    ikind[n_nodes - 2] = IV_STEP if save_all else IV_JUMP
                    restart = True
                    continue
            elif act == ACT_EXIT_ABOVE or act == ACT_EXIT_BELOW:
                dkind, didx, mode, log_kind = _act_slide_exit(wref[w], act == ACT_EXIT_ABOVE,
                                                              stab)
            elif act == ACT_EXIT_MULTI:
                dkind, didx, mode, log_kind, log_ref, exit_below = _act_multi_exit(
                    ev, p, wref[w], old_idx, old_mode, nm, t, y, n, stab, buf, wk)
            elif old_kind == SLIDE_MULTI:
                status, dkind, didx, mode, log_kind, log_ref = _act_multi_intersection(
                    ev, p, widx[w], new_sign, wref[w], old_idx, old_mode, nm, t, y, n, etab,
                    stab, slide_c, buf, fbuf, wk)
            else:
                status, dkind, didx, mode, log_kind, log_ref = _act_intersection(
                    ev, p, widx[w], new_sign, wref[w], old_kind, old_idx, old_mode, nm, t, y, n,
                    etab, stab, slide_c, buf, fbuf, wk)
            if act == ACT_INTERSECTION and status == ST_SUCCESS and log_kind < 0:
                # the sliding motion touched the surface tangentially (a graze): no event; it
                # goes on in its state, guarded on its own side of the surface, to a depth of
                # the touch's integration error across it
                last_type = wtype[w]
                last_idx = widx[w]
                last_mode = wmode[w]
                last_sign = -new_sign
                ev(W_H, widx[w], t, y, p, buf)
                last_depth = 4.0 * abs(buf[0])
                last_t = t
                ikind[n_nodes - 2] = IV_STEP if save_all else IV_JUMP
                restart = True
                continue
            if _stick_meets_slide(act, old_kind, dkind):
                # sticking on a contact and sliding on a switching surface at once: no discrete
                # state holds both constraints; the run ends at the event, before it
                status = ST_INTERSECTION
                dkind = old_kind
                didx = old_idx
                mode = old_mode
                for i in range(nY):
                    y[i] = xs[i]
                break
            if act != ACT_INTERSECTION and act != ACT_EXIT_MULTI:
                log_ref = wref[w]

            if log_kind >= 0:
                if nvar:
                    # the saltation matrix of the action, then Phi+ = S Phi-
                    _action_saltation(ev, p, act, log_kind, chatter_tail, log_ref,
                                      widx[w] if act != ACT_SWITCH else stab[wref[w]].surface,
                                      old_kind, old_idx, old_mode, dkind, didx, mode, nm, t, xs,
                                      y, n, S, etab, stab, slide_c, buf, fbuf, ytmp, wk)
                    _apply_saltation(y, S, Phi, n, seg_var)
                rec[0] = log_kind
                rec[1] = log_ref
                rec[2] = old_kind
                rec[3] = old_idx
                rec[4] = old_mode
                # the chatter record is the jump x_in -> Q(x_in); the change of discrete state
                # to sticking is the `stick` record that follows it
                rec[5] = (old_kind if log_kind == K_CHATTER
                          else (REGULAR if contact_stick else dkind))
                rec[6] = old_idx if log_kind == K_CHATTER else (-1 if contact_stick else didx)
                rec[7] = old_mode if log_kind == K_CHATTER else mode
                rec[8] = n_nodes
                _log_event(ev_t, ev_t2, ev_info, ev_xb, ev_xa, n_ev, t, t_after, rec, xs, y)
                n_ev += 1
                stats[3] += 1
                if nvar and seg_var:
                    # the next segment's Phi starts at the identity
                    for i in range(n):
                        for c in range(n):
                            y[n + i * n + c] = 1.0 if i == c else 0.0
                # jump (or chatter gap) interval to the post-event node
                nodes_t[n_nodes] = t_after
                for i in range(nY):
                    nodes_y[n_nodes, i] = y[i]
                nodes_s[n_nodes, 0] = dkind
                nodes_s[n_nodes, 1] = didx
                nodes_s[n_nodes, 2] = mode
                ikind[n_nodes - 1] = IV_CHATTER if log_kind == K_CHATTER else IV_JUMP
                hstep[n_nodes - 1] = 0.0
                if store_q:
                    for i in range(nY):
                        for k in range(deg):
                            dense[n_nodes - 1, i, k] = 0.0
                n_nodes += 1
                if contact_stick or log_kind == K_CHATTER:
                    # sticking starts here (after an impact that left the state in contact, or
                    # at the accumulation point of a chattering sequence): its own record, from
                    # the mode the reset gave
                    rec[0] = K_STICK
                    if contact_stick:
                        rec[2] = REGULAR
                        rec[3] = -1
                        rec[4] = mode
                    rec[5] = dkind
                    rec[6] = didx
                    rec[7] = mode
                    rec[8] = n_nodes - 1
                    _log_event(ev_t, ev_t2, ev_info, ev_xb, ev_xa, n_ev, t_after, t_after, rec, y,
                               y)
                    n_ev += 1
                if log_kind == K_CHATTER:
                    # samples across the chattering gap on its chord
                    while (sdt > 0.0 and s0 + sk * sdt < t_after and s0 + sk * sdt <= t_end
                           and n_samp < max_samp):
                        ts = s0 + sk * sdt
                        th = (ts - t) / (t_after - t)
                        samp[n_samp, 0] = ts
                        for i in range(n):
                            samp[n_samp, 1 + i] = (1.0 - th) * xs[i] + th * y[i]
                        n_samp += 1
                        sk += 1
                t = t_after
            if chatter_tail:
                # the run ends at t_end inside the unresolvable tail of a chattering sequence
                # (see the impact above); samples on the same chord
                while (sdt > 0.0 and s0 + sk * sdt <= t_end and n_samp < max_samp):
                    ts = s0 + sk * sdt
                    th = (ts - t) / (t_end - t) if t_end > t else 1.0
                    samp[n_samp, 0] = ts
                    for i in range(n):
                        samp[n_samp, 1 + i] = (1.0 - th) * xs[i] + th * y[i]
                    n_samp += 1
                    sk += 1
                t = t_end
                break
            if stop_mask != 0:
                # stop at the stop_count-th logged event of the requested kinds and index
                for r in range(n_ev0, n_ev):
                    if ((stop_mask >> ev_info[r, 0]) & 1) == 1 and (stop_ref < 0
                                                                    or ev_info[r, 1] == stop_ref):
                        n_stop += 1
                if n_stop >= stop_count and status == ST_SUCCESS:
                    status = ST_TERMINAL
                    break
            if status != ST_SUCCESS:
                break
            if act == ACT_EVENT and etab[wref[w]].terminal == 1:
                status = ST_TERMINAL
                break
            if stats[3] >= max_events:
                status = ST_MAX_EVENTS
                break
            # Zeno: events on the same function closer than the resolution of t, repeatedly
            if (last_type == wtype[w] and last_idx == widx[w]
                    and t - last_t <= 64.0 * _ulp(t)):
                zeno += 1
                if zeno >= 3:
                    status = ST_ZENO
                    break
            else:
                zeno = 0
            # re-trigger guard: the side of the function after the event; the guards of
            # functions that fired earlier at this same instant are kept
            if abs(t - last_t) <= _COINCIDENT_ULPS * _ulp(t) and last_type >= 0:
                if n_co < wcap:
                    co_type[n_co] = last_type
                    co_idx[n_co] = last_idx
                    co_mode[n_co] = last_mode
                    co_sign[n_co] = last_sign
                    co_t[n_co] = last_t
                    n_co += 1
            else:
                n_co = 0
            last_depth = 0.0
            last_mode = wmode[w]
            last_t = t
            last_type = wtype[w]
            last_idx = widx[w]
            # re-trigger guard: the function that fired and the side of it the state is on now
            if act == ACT_EVENT:
                # after a reset the surface value is ~0; its new side is hdot after the reset
                if dkind == REGULAR:
                    ev(W_HD, widx[w] * nm + mode, t, y, p, buf)
                    last_sign = 1.0 if buf[0] > 0.0 else -1.0
                    vout = buf[0]
                    if etab[wref[w]].kind == EV_IMPACT and vout != 0.0:
                        # hdot after an impact within round-off (a plastic impact that does not
                        # stick: the free motion leaves tangentially): its sign is noise, the
                        # state is on the allowed side
                        if abs(vout) <= _rate_band(ev, p, widx[w], mode, nm, t, y, n, hdx):
                            vout = 0.0
                    if vout == 0.0:
                        # tangent after the event: an impact leaves the state on the admissible
                        # side, a transition has crossed into the event direction
                        if etab[wref[w]].kind == EV_IMPACT or etab[wref[w]].direction == 0:
                            last_sign = 1.0 if etab[wref[w]].direction <= 0 else -1.0
                        else:
                            last_sign = 1.0 if etab[wref[w]].direction > 0 else -1.0
                else:
                    last_sign = 1.0
            elif act == ACT_RELEASE:
                last_sign = 1.0
                last_type = WF_SURFACE
                last_idx = etab[wref[w]].surface
            elif act == ACT_SWITCH:
                if dkind == SLIDE:
                    last_type = -1
                else:
                    last_sign = 1.0 if mode == stab[wref[w]].above else -1.0
            elif act == ACT_INTERSECTION:
                # crossed surface widx[w] while sliding: we are on the new side of it
                last_type = WF_SURFACE
                last_sign = new_sign
            elif act == ACT_EXIT_MULTI:
                # left one surface of the intersection, to the side above (lambda_i = 0) or
                # below (lambda_i = 1)
                last_type = WF_SURFACE
                last_idx = _multi_surface(old_idx, wref[w])
                last_sign = -1.0 if exit_below else 1.0
            else:
                # sliding exit: we leave into the mode's side of the surface
                last_type = WF_SURFACE
                last_idx = stab[wref[w]].surface
                last_sign = 1.0 if act == ACT_EXIT_ABOVE else -1.0
            restart = True

    # final node (when only events are saved, the end state still is)
    if nodes_t[n_nodes - 1] != t:
        nodes_t = _grow1(nodes_t, n_nodes + 1)
        nodes_y = _grow2(nodes_y, n_nodes + 1)
        nodes_s = _grow2(nodes_s, n_nodes + 1)
        ikind = _grow1(ikind, n_nodes + 1)
        hstep = _grow1(hstep, n_nodes + 1)
        ikind[n_nodes - 1] = IV_JUMP
        hstep[n_nodes - 1] = 0.0
        if store_q:
            dense = _grow3(dense, n_nodes + 1)
            dense[n_nodes - 1, :, :] = 0.0
        nodes_t[n_nodes] = t
        nodes_y[n_nodes, :] = y
        nodes_s[n_nodes, 0] = dkind
        nodes_s[n_nodes, 1] = didx
        nodes_s[n_nodes, 2] = mode
        n_nodes += 1
    # the node arrays are returned as they are (views of their first rows): a copy is another
    # pass over memory (~10% of a run storing every step); the spare rows (the arrays grow
    # by doubling) are at most as many as the used ones
    return (status, t, y.copy(), np.array([dkind, didx, mode], dtype=np.int64),
            nodes_t[:n_nodes], nodes_y[:n_nodes], nodes_s[:n_nodes],
            dense[: max(n_nodes - 1, 0) if store_q else 0],
            ikind[: max(n_nodes - 1, 0)],
            ev_t[:n_ev].copy(), ev_t2[:n_ev].copy(), ev_info[:n_ev].copy(),
            ev_xb[:n_ev].copy(), ev_xa[:n_ev].copy(), stats, samp[:n_samp].copy(),
            hstep[: max(n_nodes - 1, 0)])
