"""The event actions, one function per kind (impact with the chattering map, transition,
release, switch, sliding exit, intersection), each returning the new discrete state, and the
saltation matrices they apply to the variational equations.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...model.codegen import W_F, W_G, W_GX, W_GT, W_H, W_HD, W_HDT, W_HDX, W_HT, W_HX
from .._codes import (ACT_EVENT, ACT_INTERSECTION, ACT_SWITCH, IX_ATTRACTING, IX_NO_CORNER,
                      IX_NO_WEIGHTS, IX_NOT_ATTRACTING, IX_TOO_MANY, K_CHATTER, K_CROSSING,
                      K_IMPACT, K_RELEASE, K_SLIDE_END, K_SLIDE_START, MULTI_MAX, REGULAR, SLIDE,
                      SLIDE_MULTI, STICK, ST_INTERSECTION, ST_SUCCESS, SW_FILIPPOV)
from ._base import (EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE, _FD_STEP, _dot, _hot, _hot_inline,
                    compiled_on_first_use)
from .fields import (_field, _find_switch, _impact_direction_hdx, _lambda_core, _multi_corners,
                     _multi_count, _multi_field, _multi_offsets, _multi_reference,
                     _multi_set_corners, _multi_surface, _on_surfaces, _partner, _project_multi,
                     _project_surface, _resolve, _settle_multi, _solve_lambda, multi_work_size)
from .watch import _free_normal_acc, _grazing, _project_stick, _stays_in_contact, _surface_rate

@njit(cache=True)
def _event_saltation(ev, p, j, k, mode_in, mode_out, nm, t, x_in, x_out, n, S, gx, hx, buf,
                     f_in, f_out, gt, etab, stab, slide_c, old_kind, old_idx, tmp, new_kind,
                     new_idx):
    """S = g_x + (f_out - g_x f_in - g_t) h_x / (h_t + h_x f_in)  (slides, "Saltation
    matrices", with the time derivatives of time-dependent surfaces and resets): the full
    saltation matrix, ``Phi+ = S Phi-``. ``f_in`` is the field of the discrete state before the
    event at ``x_in``, ``f_out`` the field of the state after it at ``x_out = g(x_in)``.

    At a grazing event (``h_t + h_x f_in`` zero within :func:`_grazing`) the saltation matrix
    is unbounded: S is all NaN, so the variational result (the event's transfer matrix, the
    Jacobian through it) is marked singular instead of silently losing its singular term;
    :func:`pwsdyn.stability.saltation_matrix` raises there by the same test."""
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    hdx = np.zeros(n)
    _field(ev, p, old_kind, old_idx, mode_in, nm, t, x_in, n, f_in, etab, stab, slide_c,
           w1, w2, gx, hdx)
    _field(ev, p, new_kind, new_idx, mode_out, nm, t, x_out, n, f_out, etab, stab, slide_c,
           w1, w2, gx, hdx)
    ev(W_GX, j, t, x_in, p, gx)
    ev(W_GT, j, t, x_in, p, gt)
    ev(W_HX, k, t, x_in, p, hx)
    ev(W_HT, k, t, x_in, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    if _grazing(den, hx, f_in, n):
        S[:, :] = np.nan
        return
    for i in range(n):
        gf = 0.0
        for c in range(n):
            gf += gx[i * n + c] * f_in[c]
        v = f_out[i] - gf - gt[i]
        for c in range(n):
            S[i, c] = gx[i * n + c] + (v * hx[c] / den if den != 0.0 else 0.0)


@njit(cache=True)
def _switch_saltation(ev, p, dkind, didx, mode_in, mode_out, nm, k, t, x, n, S, hx, buf,
                      f_in, w1, w2, gx, etab, stab, slide_c, old_kind, old_idx):
    """Crossing or sliding entry: S = I + (f_out - f_in) h_x / (h_t + h_x f_in), with f_in
    the field of the discrete state before (``old_kind``, ``old_idx``, ``mode_in``) and f_out
    that of the state after (the sliding field at sliding entry). At sliding entry
    ``h_x S = 0``: the normal perturbation is lost (a zero multiplier). Grazing (see
    :func:`_grazing`): S is all NaN, as in :func:`_event_saltation`."""
    f_out = np.zeros(n)
    hdx = np.zeros(n)
    _field(ev, p, old_kind, old_idx, mode_in, nm, t, x, n, f_in, etab, stab, slide_c, w1, w2, gx,
           hdx)
    _field(ev, p, dkind, didx, mode_out, nm, t, x, n, f_out, etab, stab, slide_c, w1, w2, gx, hdx)
    ev(W_HX, k, t, x, p, hx)
    ev(W_HT, k, t, x, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    if _grazing(den, hx, f_in, n):
        S[:, :] = np.nan
        return
    for i in range(n):
        for c in range(n):
            S[i, c] = (1.0 if i == c else 0.0) + ((f_out[i] - f_in[i]) * hx[c] / den
                                                  if den != 0.0 else 0.0)


@_hot
def _impact_law(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx, f, buf):
    """``(a, r)`` of impact event ``j`` on surface ``k`` at ``(t, x)``: the free normal
    acceleration ``a = hdot_t + hdot_x f`` and the restitution ``r = -(1 + hdot_x W)`` of the
    impact law ``x+ = x- + W hdot`` (writes ``f``, ``hdot_x`` and ``W``). What the
    complete-chattering map, its coefficients and the impact action all start from."""
    ev(W_F, mode, t, x, p, f)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    acc = buf[0] + _dot(hdx, f, n)
    hw = _impact_direction_hdx(ev, p, j, t, x, n, W, gx, hdx)
    return acc, -(1.0 + hw)


@_hot
def _chatter_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf):
    """Complete-chattering map Q and time q at x (slides; Nordmark & Piiroinen 2009).
    Returns the duration q(x) - t; writes Q(x) into out."""
    ev(W_HD, k * nm + mode, t, x, p, buf)
    vin = buf[0]
    acc, r = _impact_law(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx, f, buf)
    for i in range(n):
        out[i] = x[i] + (2.0 * r * f[i] / acc + W[i]) * vin / (1.0 - r)
    return 2.0 * r * vin / ((1.0 - r) * acc)


@_hot
def _chatter_event_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf, hx):
    """The complete-chattering event map as the kernel applies it: ``(t_in, x_in) -> (t_out,
    x_out)`` with ``t_out = q(t_in, x_in)`` and ``x_out`` the map ``Q(t_in, x_in)`` (slides,
    "Local mapping at complete chattering") projected onto the sticking manifold
    ``{h = 0, hdot = 0}`` at ``t_out``. Returns ``t_out``; writes ``x_out`` into ``out``."""
    dur = _chatter_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf)
    t_out = t + dur
    _project_stick(ev, p, k, mode, nm, t_out, out, n, hdx, hx, buf)
    return t_out


@_hot
def _chatter_coef(ev, p, j, k, mode, nm, t, x, n, c, W, gx, hdx, f, buf):
    """The coefficients of the complete-chattering map, smooth functions of ``(t, x)``:
    ``Q = x + c hdot``, ``q = b hdot`` with ``b = 2 r / ((1 - r) a)`` and
    ``c = (2 r f / a + W) / (1 - r)`` (:func:`_chatter_map`). Writes c; returns b."""
    acc, r = _impact_law(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx, f, buf)
    for i in range(n):
        c[i] = (2.0 * r * f[i] / acc + W[i]) / (1.0 - r)
    return 2.0 * r / ((1.0 - r) * acc)


@_hot
def _stick_gradients(ev, p, k, mode, nm, t, x, n, mu0, mu1, out, hdx):
    """``G = mu0 h_x + mu1 hdot_x`` at ``(t, x)`` into out (the normal displacement of the
    projection onto the sticking manifold, as a function of the point)."""
    ev(W_HX, k, t, x, p, out)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    for i in range(n):
        out[i] = mu0 * out[i] + mu1 * hdx[i]


@njit(cache=True)
def _chatter_saltation(ev, p, j, k, mode, nm, t, x_in, n, S, etab, stab, slide_c):
    """Saltation matrix of a complete chattering sequence (the full form, ``Phi+ = S Phi-``).

    For an event map ``(t_in, x_in) -> (tau, X)`` applied where the flow reaches
    ``h(t, x) = 0``, a perturbation ``dx`` before the event reaches the surface ``dt = -h_x dx /
    (h_t + h_x f_in)`` later, at ``x_in + dx + f_in dt``; comparing the two solutions at a common
    time after the event gives

        S = C - (X_t + C f_in - F tau_t) h_x / (h_t + h_x f_in),   C = X_x - F tau_x,

    with ``F`` the sticking field at ``(tau, X)``. For a time-independent map ``tau = t + q``,
    ``X = Q`` this is the slides' chattering saltation ``G = C + (f_out - C f_in) h_x / (h_x
    f_in)``, ``C = Q_x - f_out q_x`` (Nordmark & Piiroinen 2009); for ``tau = t``, ``X = g`` it
    is the impact saltation of :func:`_event_saltation`. ``(tau, X)`` is the map the kernel
    applies, :func:`_chatter_event_map`: ``tau = t + b v``, ``Z = x + c v`` (``v = hdot``,
    ``b``, ``c`` of :func:`_chatter_coef`), ``X`` = Z projected onto ``{h = 0, hdot = 0}`` at
    ``tau`` along ``N = (h_x, hdot_x)``: ``X = Z + N mu``.

    The derivatives are analytic in ``v`` (the entry speed):

        tau_x = b v_x + v b_x,  Z_x = I + c v_x^T + v c_x,  D = d/dt + f_in . d/dx,
        D v = a,  D tau = 1 + a b + v D b,  D Z = f + a c + v D c = (1 + a b) F0 + v D c,

    ``F0`` the sticking field at ``(t, x_in)`` (``f + a c = (1 + a b)(f + a W / (1 + r))``
    identically). The projection's derivative is ``dX = L(dZ, dtau)``: ``(I - G_y) dX - N dmu
    = dZ + G_t dtau``, ``B dX = -Phi_t dtau`` (``B = N^T``, ``Phi = (h, hdot)`` at (tau, X),
    ``G = N mu`` with mu held, ``(I - G_y)^-1 ~ I + G_y``: ``G`` is O(v^2)). Since ``F`` is
    tangent to the manifold, ``L((I - G_y) F - G_t, 1) = F``, so with ``Fs = (I - G_y) F - G_t``

        C = L(Z_x - Fs tau_x^T, 0),
        (X_t + C f_in - F tau_t) / v = L(R / v, 0),
        R / v = -(1 + a b) (F - F0) / v + D c - D b F + D tau (G_y F + G_t) / v,

    so the 1/v of the formula multiplies no difference of O(1) numbers: ``(F - F0) / v`` is the
    divided difference of the sticking field over the jump, taken at the jump's ends or, when
    they are closer than a difference step, as a central difference along the jump about its
    midpoint (step relative to max(1, |t|)^(1/3) in time and max(1, |x_i|) in state); ``b_x, c_x,
    b_t, c_t`` and ``G_y, G_t`` are central differences of first derivatives of the model,
    multiplied by v or by ``mu = O(v^2)``. The result does not lose accuracy as the entry speed
    goes to 0 or as |t| grows (issue "events", item 5: the earlier central difference of the
    whole map divided its error, growing with |t|, by v).
    """
    W = np.zeros(n)
    n_work = multi_work_size(n, stab)
    gx = np.zeros(max(n * n, n_work))
    hdx = np.zeros(n)
    f = np.zeros(n)
    buf = np.zeros(max(n, 2, n_work))
    hx = np.zeros(n)
    hx1 = np.zeros(n)
    hd1 = np.zeros(n)
    vx = np.zeros(n)
    fi = np.zeros(n)
    xo = np.zeros(n)
    z = np.zeros(n)
    xt = np.zeros(n)
    cc = np.zeros(n)
    cp = np.zeros(n)
    cm = np.zeros(n)
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    F0 = np.zeros(n)
    F1 = np.zeros(n)
    Fp = np.zeros(n)
    Fm = np.zeros(n)
    bx = np.zeros(n)
    cx = np.zeros((n, n))
    ct = np.zeros(n)
    Gy = np.zeros((n, n))
    Gt = np.zeros(n)
    Rv = np.zeros(n)
    RC = np.zeros((n, n))
    Nt = np.zeros((n, 2))
    tmp = np.zeros(n)
    # input point: v = hdot, its derivatives, the field and the surface gradient
    ev(W_HD, k * nm + mode, t, x_in, p, buf)
    v = buf[0]
    ev(W_HDT, k * nm + mode, t, x_in, p, buf)
    vt = buf[0]
    ev(W_HDX, k * nm + mode, t, x_in, p, vx)
    ev(W_F, mode, t, x_in, p, fi)
    ev(W_HX, k, t, x_in, p, hx)
    a = vt + _dot(vx, fi, n)
    for i in range(n):
        xt[i] = x_in[i]
    b = _chatter_coef(ev, p, j, k, mode, nm, t, xt, n, cc, W, gx, hdx, f, buf)
    # the map as applied: Z = Q(x_in) and X, tau = the projected one
    _chatter_map(ev, p, j, k, mode, nm, t, xt, n, z, W, gx, hdx, f, buf)
    t_out = _chatter_event_map(ev, p, j, k, mode, nm, t, xt, n, xo, W, gx, hdx, f, buf, hx1)
    # derivatives of the coefficients b, c (O(1), multiplied by v below); actual steps
    for col in range(n):
        dx = _FD_STEP * max(1.0, abs(x_in[col]))
        xt[col] = x_in[col] + dx
        hp = xt[col]
        bp = _chatter_coef(ev, p, j, k, mode, nm, t, xt, n, cp, W, gx, hdx, f, buf)
        xt[col] = x_in[col] - dx
        hm = xt[col]
        bm = _chatter_coef(ev, p, j, k, mode, nm, t, xt, n, cm, W, gx, hdx, f, buf)
        xt[col] = x_in[col]
        bx[col] = (bp - bm) / (hp - hm)
        for i in range(n):
            cx[i, col] = (cp[i] - cm[i]) / (hp - hm)
    dt = _FD_STEP * max(1.0, abs(t)) ** (1.0 / 3.0)
    tp = t + dt
    tm = t - dt
    bp = _chatter_coef(ev, p, j, k, mode, nm, tp, xt, n, cp, W, gx, hdx, f, buf)
    bm = _chatter_coef(ev, p, j, k, mode, nm, tm, xt, n, cm, W, gx, hdx, f, buf)
    bt = (bp - bm) / (tp - tm)
    for i in range(n):
        ct[i] = (cp[i] - cm[i]) / (tp - tm)
    Db = bt + _dot(bx, fi, n)
    Dtau = 1.0 + a * b + v * Db
    # sticking fields at both ends of the jump
    _field(ev, p, STICK, j, mode, nm, t_out, xo, n, F1, etab, stab, slide_c, w1, w2, gx, hdx)
    _field(ev, p, STICK, j, mode, nm, t, x_in, n, F0, etab, stab, slide_c, w1, w2, gx, hdx)
    # projection geometry at (tau, X): N = (h_x, hdot_x), X - Z = N mu
    ev(W_HX, k, t_out, xo, p, hx1)
    ev(W_HDX, k * nm + mode, t_out, xo, p, hd1)
    aa = _dot(hx1, hx1, n)
    ab = _dot(hx1, hd1, n)
    bb = _dot(hd1, hd1, n)
    det = aa * bb - ab * ab
    proj = det != 0.0 and np.isfinite(det)
    if proj:
        for i in range(n):
            tmp[i] = xo[i] - z[i]
        r1 = _dot(hx1, tmp, n)
        r2 = _dot(hd1, tmp, n)
        mu0 = (bb * r1 - ab * r2) / det
        mu1 = (aa * r2 - ab * r1) / det
        if mu0 != 0.0 or mu1 != 0.0:
            for col in range(n):
                for i in range(n):
                    xt[i] = xo[i]
                dx = _FD_STEP * max(1.0, abs(xo[col]))
                xt[col] = xo[col] + dx
                hp = xt[col]
                _stick_gradients(ev, p, k, mode, nm, t_out, xt, n, mu0, mu1, cp, hdx)
                xt[col] = xo[col] - dx
                hm = xt[col]
                _stick_gradients(ev, p, k, mode, nm, t_out, xt, n, mu0, mu1, cm, hdx)
                for i in range(n):
                    Gy[i, col] = (cp[i] - cm[i]) / (hp - hm)
            for i in range(n):
                xt[i] = xo[i]
            dt = _FD_STEP * max(1.0, abs(t_out)) ** (1.0 / 3.0)
            tp = t_out + dt
            tm = t_out - dt
            _stick_gradients(ev, p, k, mode, nm, tp, xt, n, mu0, mu1, cp, hdx)
            _stick_gradients(ev, p, k, mode, nm, tm, xt, n, mu0, mu1, cm, hdx)
            for i in range(n):
                Gt[i] = (cp[i] - cm[i]) / (tp - tm)
    # (F - F0) / v over the jump from (t, x_in) to (t_out, xo), direction e = (b, (X - x) / v)
    if v != 0.0:
        et = (t_out - t) / v
        scl = abs(et) / max(1.0, abs(t)) ** (1.0 / 3.0)
        for i in range(n):
            tmp[i] = (xo[i] - x_in[i]) / v
            scl = max(scl, abs(tmp[i]) / max(1.0, abs(x_in[i])))
        smin = _FD_STEP / scl if scl > 0.0 else 0.0
        if scl == 0.0:
            for i in range(n):
                Rv[i] = 0.0
        elif 0.5 * abs(v) >= smin:
            for i in range(n):
                Rv[i] = (F1[i] - F0[i]) / v
        else:
            # central difference along the jump about its midpoint, the time steps as taken
            tmid = t + 0.5 * (t_out - t)
            tp = tmid + smin * et
            tm = tmid - smin * et
            s2 = (tp - tm) / et if et != 0.0 else 2.0 * smin
            for i in range(n):
                xt[i] = 0.5 * (x_in[i] + xo[i]) + 0.5 * s2 * tmp[i]
            _field(ev, p, STICK, j, mode, nm, tp, xt, n, Fp, etab, stab, slide_c, w1, w2, gx,
                   hdx)
            for i in range(n):
                xt[i] = 0.5 * (x_in[i] + xo[i]) - 0.5 * s2 * tmp[i]
            _field(ev, p, STICK, j, mode, nm, tm, xt, n, Fm, etab, stab, slide_c, w1, w2, gx,
                   hdx)
            for i in range(n):
                Rv[i] = (Fp[i] - Fm[i]) / s2
        # R / v = -(1 + a b) (F - F0) / v + D c - D b F + D tau (G_y F + G_t) / v
        for i in range(n):
            gf = Gt[i]
            dc = ct[i]
            for c in range(n):
                gf += Gy[i, c] * F1[c]
                dc += cx[i, c] * fi[c]
            Rv[i] = -(1.0 + a * b) * Rv[i] + dc - Db * F1[i] + Dtau * gf / v
    # C = L(Z_x - Fs tau_x^T, 0), Fs = (I - G_y) F - G_t
    for i in range(n):
        fs = F1[i] - Gt[i]
        for c in range(n):
            fs -= Gy[i, c] * F1[c]
        for c in range(n):
            RC[i, c] = ((1.0 if i == c else 0.0) + cc[i] * vx[c] + v * cx[i, c]
                        - fs * (b * vx[c] + v * bx[c]))
    # L(R, 0): dX = (I + G_y)(R + N dmu) with B dX = 0, B = N^T at (tau, X)
    if proj:
        for i in range(n):
            Nt[i, 0] = hx1[i]
            Nt[i, 1] = hd1[i]
            for c in range(n):
                Nt[i, 0] += Gy[i, c] * hx1[c]
                Nt[i, 1] += Gy[i, c] * hd1[c]
        m00 = _dot(hx1, Nt[:, 0], n)
        m01 = _dot(hx1, Nt[:, 1], n)
        m10 = _dot(hd1, Nt[:, 0], n)
        m11 = _dot(hd1, Nt[:, 1], n)
        dm = m00 * m11 - m01 * m10
        proj = dm != 0.0 and np.isfinite(dm)
    else:
        m00 = m01 = m10 = m11 = dm = 1.0
    for col in range(n + 1):
        # columns of C, then R / v
        for i in range(n):
            w1[i] = RC[i, col] if col < n else Rv[i]
        for i in range(n):
            s = w1[i]
            for c in range(n):
                s += Gy[i, c] * w1[c]
            w2[i] = s
        if proj:
            q0 = _dot(hx1, w2, n)
            q1 = _dot(hd1, w2, n)
            d0 = -(m11 * q0 - m01 * q1) / dm
            d1 = -(m00 * q1 - m10 * q0) / dm
            for i in range(n):
                w2[i] += Nt[i, 0] * d0 + Nt[i, 1] * d1
        if col < n:
            for i in range(n):
                S[i, col] = w2[i]
        else:
            for i in range(n):
                tmp[i] = w2[i]
    if v != 0.0:
        for i in range(n):
            for c in range(n):
                S[i, c] -= tmp[i] * hx[c]


def _chatter_saltation_signature():
    from numba import types as nt

    from ...model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    return nt.void(EVALUATE_TYPE, f1, nt.int64, nt.int64, nt.int64, nt.float64, f1,
                   EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE, nt.float64, nt.float64[:, ::1])


@njit(_chatter_saltation_signature(), cache=True)
def chatter_saltation(ev, p, j, mode, nm, t, x, etab, stab, slide_c, S):
    """The saltation matrix :func:`_chatter_saltation` of the complete-chattering map of
    impact event ``j`` entered from mode ``mode`` at ``(t, x)`` into ``S`` (n x n): the matrix
    the kernel applies, for Python callers (:func:`pwsdyn.stability.saltation_matrix`)."""
    _chatter_saltation(ev, p, j, etab[j].surface, mode, nm, t, x, x.shape[0], S, etab, stab,
                       slide_c)


# --------------------------------------------------------------------------------------
# event actions: one function per action, called from the one dispatch in run_kernel
# --------------------------------------------------------------------------------------
# Each takes the state at the event (``t``, ``y``; ``xs`` the copy before it), updates ``y``
# in place and returns the new discrete state ``(dkind, didx, mode)`` and the kind of the log
# record (``K_*``; -1: none). At most 30 arguments each (see the steppers above). The
# saltation matrix of every action is made by :func:`_action_saltation`, called after the
# action where the variational equations are on: the saltation helpers allocate, so they keep
# numba's reference counting, which the actions (like every other per-step or per-event
# helper) are compiled without (with it, measured 5-10% of an event-dominated run).

@_hot_inline
def _act_impact(ev, p, j, dkind, didx, mode, nm, t, y, xs, n, etab, t_end, rtol, atol, chat_rel,
                chat_abs, chatter_on, chain_event, chain_vmax, vin, buf, fbuf, ytmp, wk):
    """Impact on event ``j``: the reset ``g``, or the complete-chattering map where the
    sequence of impacts accumulates (:func:`_act_chatter`), or, where the accumulation point
    lies past ``t_end`` and the bounces are below the velocity floor, the end of the run on
    the chord of the chattering gap. ``chain_event``/``chain_vmax``: the impacts of the
    current sequence and its largest normal speed (the relative chattering threshold).
    ``vin``: the normal velocity ``hdot`` of the mode at ``(t, y)`` where the caller has it,
    else NaN. Returns ``(dkind, didx, mode, log_kind, t_after, chatter_tail, chain_event,
    chain_vmax, chattered)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    # a negative ratio is the default one, applied only where the chattering map is accurate
    chat_gated = chat_rel < 0.0
    chat_rel = abs(chat_rel)
    k = etab[j].surface
    # normal velocity and acceleration at impact, impact direction W, restitution r
    if vin != vin:
        ev(W_HD, k * nm + mode, t, y, p, buf)
        vin = buf[0]
    acc, r = _impact_law(ev, p, j, k, mode, nm, t, y, n, w1, gx, hdx, fbuf, buf)
    if chain_event != j:
        chain_event = j
        chain_vmax = 0.0
    chain_vmax = max(chain_vmax, abs(vin))
    # velocity floor: a bounce of speed v rises v^2 / (2|a|); below the position tolerance it
    # cannot be told from sticking (default when chat_abs < 0)
    vfloor = chat_abs
    if vfloor < 0.0:
        xmax = 0.0
        for i in range(n):
            xmax = max(xmax, abs(y[i]))
        vfloor = np.sqrt(2.0 * abs(acc) * (atol + rtol * xmax))
    do_chatter = (chatter_on == 1 and acc < 0.0 and r >= 0.0 and r < 1.0
                  and (abs(vin) <= vfloor or r == 0.0))
    if (chatter_on == 1 and not do_chatter and acc < 0.0 and 0.0 <= r < 1.0
            and abs(vin) <= chat_rel * chain_vmax and not chat_gated):
        do_chatter = True
    elif (chatter_on == 1 and not do_chatter and acc < 0.0 and 0.0 <= r < 1.0
            and abs(vin) <= chat_rel * chain_vmax):
        # the map takes the normal acceleration as constant over the sequence: jump only
        # where its change over the sequence's duration moves the state by less than the
        # position tolerance, dt^2 |a(t + dt) - a(t)| (a table whose acceleration varies put
        # the accumulation point 3e-6 off when entered at 1e-4 of the first impact's speed;
        # below the floor the bounces are unresolvable anyway)
        dtq = 2.0 * r * vin / ((1.0 - r) * acc)
        for i in range(n):
            xt[i] = y[i] + dtq * fbuf[i]
        acc2 = _free_normal_acc(ev, p, k, mode, nm, t + dtq, xt, n, buf, ft, w2)
        xmax = 0.0
        for i in range(n):
            xmax = max(xmax, abs(y[i]))
        do_chatter = dtq * dtq * abs(acc2 - acc) <= atol + rtol * xmax
    # complete-chattering map (Nordmark & Piiroinen 2009; slides):
    # x_out = x_in + (2 r f_in / a + W) hdot_in / (1 - r),
    # t_out = t_in + 2 r hdot_in / ((1 - r) a)
    dtc = 2.0 * r * vin / ((1.0 - r) * acc) if do_chatter else 0.0
    chatter_tail = False
    if do_chatter and not (t + dtc <= t_end):
        # the accumulation point lies beyond t_end: up to t_end the motion is a finite number
        # of ordinary impacts, so take this one (and the next ones) as an impact and
        # integrate on; jumping would end the run past t_end with the state of a time not
        # asked for
        do_chatter = False
        # ... unless the bounces are below the velocity floor: they rise less than the
        # position tolerance, so the event search cannot resolve them (their crossings drown
        # in the round-off band of the re-trigger guard and the state would fall through the
        # surface). Up to t_end the motion then is the start of the chattering sequence,
        # within the resolution of the run: end at t_end on the chord from x_in to the
        # accumulation state (Q(x_in) projected onto the sticking manifold, as below) that a
        # chattering gap is drawn with (error O(floor) in hdot, O(tolerance) in h)
        chatter_tail = abs(vin) <= vfloor and dtc > 0.0
    log_kind = -1
    t_after = t
    chattered = 0
    if chatter_tail:
        _chatter_jump(ev, p, k, mode, nm, t + dtc, xs, ytmp, n, r, vin, acc, fbuf, w1, hdx, w2,
                      buf)
        th = (t_end - t) / dtc
        for i in range(n):
            y[i] = (1.0 - th) * xs[i] + th * ytmp[i]
    elif do_chatter:
        t_after = t + dtc
        _chatter_jump(ev, p, k, mode, nm, t_after, xs, y, n, r, vin, acc, fbuf, w1, hdx, w2, buf)
        log_kind = K_CHATTER
        dkind = STICK
        didx = j
        chattered = 1
        chain_event = -1
    else:
        # the impact law x+ = g_j(t, x-) (written out: a call per event is measurable)
        ev(W_G, j, t, xs, p, ytmp)
        for i in range(n):
            y[i] = ytmp[i]
        if etab[j].target >= 0:
            mode = etab[j].target
        log_kind = K_IMPACT
    return dkind, didx, mode, log_kind, t_after, chatter_tail, chain_event, chain_vmax, chattered


@_hot
def _chatter_jump(ev, p, k, mode, nm, t_out, xs, out, n, r, vin, acc, f, W, hdx, w2, buf):
    """The complete-chattering map ``Q(x_in) = x_in + (2 r f_in / a + W) hdot_in / (1 - r)``
    (Nordmark & Piiroinen 2009) into ``out``. Q is first order in hdot; the accumulation point
    lies on the sticking manifold {h = 0, hdot = 0} by definition, so it is projected onto
    it at ``t_out``."""
    for i in range(n):
        out[i] = xs[i] + (2.0 * r * f[i] / acc + W[i]) * vin / (1.0 - r)
    _project_stick(ev, p, k, mode, nm, t_out, out, n, hdx, w2, buf)


@_hot
def _act_transition(ev, p, j, mode, t, y, xs, n, etab, ytmp):
    """Transition on event ``j``: the reset ``x+ = g_j(t, x-)`` into ``y`` (the identity where
    the event has none) and its target mode (unchanged where it has none). Returns the
    mode."""
    ev(W_G, j, t, xs, p, ytmp)
    for i in range(n):
        y[i] = ytmp[i]
    if etab[j].target >= 0:
        return etab[j].target
    return mode


@_hot_inline
def _after_reset(ev, p, j, log_kind, chatter_tail, dkind, didx, mode, nm, t, y, n, etab, stab,
                 buf, fbuf, wk):
    """After an impact or a transition: the switching variant the new state lies in (a reset
    or a new mode may put the state on the other side of a switching surface, or on one: take
    the variant on the right side, or slide; an event without reset or target while sliding,
    a section or a terminal event, leaves the sliding motion alone); sticking where an impact
    left the normal velocity at round-off while the free motion presses into the surface (a
    plastic impact on an oblique or curved surface, an impact at rest: constrained motion
    along the surface, released where the constraint force vanishes; the impact's saltation
    matrix then maps into the sticking field). Returns ``(dkind, didx, mode,
    contact_stick)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    k = etab[j].surface
    contact_stick = False
    if (log_kind != K_CHATTER and not chatter_tail and stab.shape[0] > 0
            and (dkind == REGULAR or etab[j].has_reset == 1 or etab[j].target >= 0)):
        dkind, didx, mode = _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx)
    if (log_kind == K_IMPACT and dkind == REGULAR
            and _stays_in_contact(ev, p, k, mode, nm, t, y, n, buf, fbuf, hdx)):
        contact_stick = True
        dkind = STICK
        didx = j
        _project_stick(ev, p, k, mode, nm, t, y, n, hdx, w2, buf)
    elif (log_kind == K_IMPACT and (dkind == SLIDE or dkind == SLIDE_MULTI)
            and _stays_in_contact(ev, p, k, mode, nm, t, y, n, buf, fbuf, hdx)):
        # the impact leaves the state in contact while it slides on a switching surface: no
        # discrete state holds both constraints (:func:`_stick_meets_slide`)
        dkind = -1
    return dkind, didx, mode, contact_stick


@_hot
def _stick_meets_slide(act, old_kind, dkind):
    """Whether the action just taken would trade one constraint for another that should
    hold with it: sticking on an impact surface (``STICK``) for Filippov sliding
    (``SLIDE``, ``SLIDE_MULTI``) at the arrival on a switching surface, or sliding for
    sticking at an impact (a complete chattering sequence, or an impact that leaves the state
    in contact: :func:`_after_reset` returns ``dkind`` -1). A contact that sticks while a
    switching surface is slid on (a block held against a wall by the belt's friction while
    another block sticks to the belt) has no discrete state in the kernel: the run ends
    there with ``ST_INTERSECTION``, in the state before the event (the kernel's loop; the
    message names both surfaces)."""
    if dkind < 0:
        return True
    slide_new = dkind == SLIDE or dkind == SLIDE_MULTI
    slide_old = old_kind == SLIDE or old_kind == SLIDE_MULTI
    return ((act == ACT_SWITCH and old_kind == STICK and slide_new)
            or (act == ACT_EVENT and slide_old and dkind == STICK))


@_hot
def _act_release(ev, p, k, mode, nm, t, y, n, stab, buf, wk):
    """Release from sticking on surface ``k``: the flight starts on the sticking manifold
    {h = 0, hdot = 0} (the sticking steps drift off it by their local error, and a drift to
    the far side, deeper than the re-trigger guard's round-off band, would hide a short
    flight's landing), in the switching variant on the side the released motion takes (a
    kink surface held at zero while sticking, e.g. the relative velocity of bilinear damping).
    Returns ``(dkind, didx, mode, log_kind)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    _project_stick(ev, p, k, mode, nm, t, y, n, hdx, w2, buf)
    dkind = REGULAR
    didx = -1
    if stab.shape[0] > 0:
        dkind, didx, mode = _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx)
    return dkind, didx, mode, K_RELEASE


@_hot
def _act_switch(ev, p, s, old_kind, old_idx, old_mode, nm, t, y, n, stab, buf, hdx):
    """Arrival at switching surface ``s``: sliding starts where both fields point into the
    surface (h_t + h_x f_above < 0 < h_t + h_x f_below), otherwise the flow crosses (thesis
    eq. 2.6-2.8); kink surfaces (SW_CONTINUOUS) always cross. Arriving with the own field
    tangent (hdot = 0) while the other one points back is a graze: no event. Returns
    ``(dkind, didx, mode, log_kind, graze)``."""
    k = stab[s].surface
    a_m = stab[s].above
    b_m = stab[s].below
    ev(W_HD, k * nm + a_m, t, y, p, buf)
    sa = buf[0]
    ev(W_HD, k * nm + b_m, t, y, p, buf)
    sb = buf[0]
    filippov = stab[s].kind == SW_FILIPPOV
    graze = filippov and ((old_mode == a_m and sa >= 0.0 and sb > 0.0)
                          or (old_mode == b_m and sb <= 0.0 and sa < 0.0))
    if graze:
        return old_kind, old_idx, old_mode, -1, True
    dkind = old_kind
    didx = old_idx
    if filippov and sa < 0.0 and sb > 0.0:
        dkind = SLIDE
        didx = s
        mode = a_m
        log_kind = K_SLIDE_START
        # arriving on further Filippov surfaces at the same instant (an arrival at their
        # intersection, non-generic): the multilinear weights decide which of them it slides
        # on (buf, at least multi_work_size long, is the work vector)
        xmax = 1.0
        for i in range(n):
            xmax = max(xmax, abs(y[i]))
        mask = _on_surfaces(ev, p, t, y, n, xmax, k, a_m, stab, buf, hdx)
        if mask != 0:
            mask |= 1 << k
            ref = _multi_reference(stab, mask, a_m)
            if ref >= 0:
                dk, di, dm = _settle_multi(ev, p, t, y, n, nm, mask, ref, stab, buf, hdx, hdx,
                                           buf)
                if dk >= 0:
                    if dk == REGULAR:
                        log_kind = K_CROSSING
                    return dk, di, dm, log_kind, False
        _project_surface(ev, p, k, t, y, n, hdx, buf)
    else:
        log_kind = K_CROSSING
        mode = b_m if old_mode == a_m else a_m
    return dkind, didx, mode, log_kind, False


@_hot
def _act_slide_exit(s, above, stab):
    """End of sliding on switch ``s`` into the mode above (``alpha -> 0``) or below
    (``alpha -> 1``). Returns ``(dkind, didx, mode, log_kind)``."""
    return REGULAR, -1, (stab[s].above if above else stab[s].below), K_SLIDE_END


@_hot
def _act_intersection(ev, p, k2, new_sign, log_ref, old_kind, old_idx, old_mode, nm, t, y, n,
                      etab, stab, slide_c, buf, fbuf, wk):
    """Sliding on switch ``old_idx`` reached surface ``k2`` of another switch. Across ``k2``
    the sliding pair (a, b) becomes (a2, b2): if the flow slides on the first surface there
    too and its sliding field carries the state away from k2, it crosses k2 while sliding; if
    both pairs leave the first surface to one side, the sliding ends; otherwise the motion
    slides on the intersection of the two surfaces where the multilinear weights allow it
    (:func:`_enter_multi`), and the run ends with ``ST_INTERSECTION`` where they do not.

    First, a tangential return (:func:`_returns_tangentially`): where the sliding motion
    itself does not move across ``k2`` in the direction of the crossing, it only touches the
    surface (a graze, located a little across it by the integration error) and stays on its
    side: no event, returned as ``ST_SUCCESS`` with log kind -1 (an undamped Coulomb
    oscillator slips back to the belt speed exactly at its static bound, tangentially, while
    another contact sticks). Returns ``(status, dkind, didx, mode, log_kind, log_ref)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    if _returns_tangentially(ev, p, k2, new_sign, old_kind, old_idx, old_mode, nm, t, y, n,
                             etab, stab, slide_c, buf, fbuf, wk):
        return ST_SUCCESS, old_kind, old_idx, old_mode, -1, log_ref
    dkind = old_kind
    didx = old_idx
    mode = old_mode
    log_kind = -1
    k1 = stab[old_idx].surface
    a2 = _partner(stab, k2, stab[old_idx].above)
    b2 = _partner(stab, k2, stab[old_idx].below)
    s_new = _find_switch(stab, k1, a2, b2) if a2 >= 0 and b2 >= 0 else -1
    if s_new >= 0:
        ev(W_HD, k1 * nm + a2, t, y, p, buf)
        sa = buf[0]
        ev(W_HD, k1 * nm + b2, t, y, p, buf)
        sb = buf[0]
        if sa < 0.0 and sb > 0.0:
            _field(ev, p, SLIDE, s_new, a2, nm, t, y, n, fbuf, etab, stab, slide_c, w1, w2, gx,
                   hdx)
            rate = _surface_rate(ev, p, SLIDE, k2, a2, nm, t, y, fbuf, n, buf, hdx)
            if rate * new_sign > 0.0:
                dkind = SLIDE
                didx = s_new
                mode = a2
                log_kind = K_CROSSING
        elif sa >= 0.0 and sb > 0.0:
            dkind = REGULAR
            didx = -1
            mode = a2
            log_kind = K_SLIDE_END
            log_ref = old_idx
        elif sa < 0.0 and sb <= 0.0:
            dkind = REGULAR
            didx = -1
            mode = b2
            log_kind = K_SLIDE_END
            log_ref = old_idx
    if log_kind < 0:
        # the sliding motion can neither cross k2 nor leave k1 there: it slides on the
        # intersection if the multilinear weights lie in [0, 1]^2 (an attracting intersection)
        return _enter_multi(ev, p, (1 << k1) | (1 << k2), stab[old_idx].above, k2, nm, t, y, n,
                            stab, buf, wk, dkind, didx, mode, log_ref)
    return ST_SUCCESS, dkind, didx, mode, log_kind, log_ref


@_hot
def _returns_tangentially(ev, p, k, new_sign, old_kind, old_idx, old_mode, nm, t, y, n, etab,
                          stab, slide_c, buf, fbuf, wk):
    """Whether a sliding motion (on a switch or an intersection) that reached surface ``k``
    crossing it with sign ``new_sign`` (the side of ``k`` it was found on) only touches it:
    the rate ``h_t + h_x f`` of ``k`` along the motion's own field does not point to that
    side. A crossing located by the sign of ``h`` has that rate's sign up to the integration
    error of ``h``; the opposite sign (or zero) is a tangency -- the motion grazes ``k`` --
    which that error moved across the surface (the same rule as a regular motion's graze in
    :func:`_act_switch`)."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    _field(ev, p, old_kind, old_idx, old_mode, nm, t, y, n, fbuf, etab, stab, slide_c, w1, w2,
           gx, hdx)
    rate = _surface_rate(ev, p, old_kind, k, old_mode, nm, t, y, fbuf, n, buf, hdx)
    return rate * new_sign <= 0.0


@_hot
def _multi_entry(ev, p, mask, m, k2, nm, t, y, n, stab, w1, work):
    """Whether sliding can start on the intersection of the surfaces of ``mask`` (``k2``, the
    surface just reached, among them; ``m`` a mode of one of its corners): the weights of the
    multilinear rule, solved into ``work`` (:func:`_solve_lambda`), must lie in ``[0, 1]^k``
    (the fields of all corners press the state into the intersection). Returns ``(cause,
    ref, k)``: ``cause`` ``IX_ATTRACTING`` where it can start, otherwise why not (the
    ``IX_*`` codes: too many surfaces, a corner mode missing, no weights, weights outside the
    cube); ``ref`` the reference corner, ``k`` the number of surfaces (0 where unknown)."""
    if _multi_count(mask) > MULTI_MAX or k2 >= 63:
        return IX_TOO_MANY, -1, 0
    ref = _multi_reference(stab, mask, m)
    if ref < 0 or not _multi_set_corners(stab, mask, ref, n, work):
        return IX_NO_CORNER, ref, 0
    k = _lambda_core(ev, p, mask, t, y, n, w1, work)
    if k < 0:
        return IX_NO_WEIGHTS, ref, 0
    o_lam = _multi_offsets(n)[2]
    tol = 64.0 * 2.220446049250313e-16
    for i in range(k):
        lam = work[o_lam + i]
        if not (-tol <= lam <= 1.0 + tol):
            return IX_NOT_ATTRACTING, ref, k
    return IX_ATTRACTING, ref, k


@_hot
def _enter_multi(ev, p, mask, m, k2, nm, t, y, n, stab, buf, wk, dkind, didx, mode, log_ref):
    """Sliding that reaches surface ``k2`` starts sliding on the intersection of the surfaces
    of ``mask`` (``k2`` among them; ``m`` a mode of one of the corners) where the multilinear
    weights solve the tangency conditions inside ``[0, 1]^k`` (:func:`_multi_entry`):
    ``slide_start`` on the switch of ``k2`` at the reference corner. Otherwise the
    intersection is not attracting, or the rule has no solution, and the run ends with
    ``ST_INTERSECTION`` in the old state (:func:`intersection_cause` tells why, for the
    message). Returns ``(status, dkind, didx, mode, log_kind, log_ref)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    cause, ref, k = _multi_entry(ev, p, mask, m, k2, nm, t, y, n, stab, w1, gx)
    if cause != IX_ATTRACTING:
        return ST_INTERSECTION, dkind, didx, mode, -1, log_ref
    _project_multi(ev, p, mask, t, y, n, hdx, buf)
    s2 = _find_switch(stab, k2, ref, _partner(stab, k2, ref))
    return ST_SUCCESS, SLIDE_MULTI, mask, ref, K_SLIDE_START, s2


@_hot
def _act_multi_intersection(ev, p, k3, new_sign, log_ref, old_idx, old_mode, nm, t, y, n,
                            etab, stab, slide_c, buf, fbuf, wk):
    """Sliding on the intersection of the surfaces of ``old_idx`` reached surface ``k3``:
    a tangential return (:func:`_returns_tangentially`) is no event (``ST_SUCCESS`` with log
    kind -1, as in :func:`_act_intersection`); otherwise it crosses ``k3`` where the
    multilinear field of the corners beyond it is defined (weights in ``[0, 1]^k``) and
    carries the state away from ``k3``; otherwise it slides on the intersection with ``k3``
    too (:func:`_enter_multi`), or the run ends with ``ST_INTERSECTION``. Returns
    ``(status, dkind, didx, mode, log_kind, log_ref)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    mask = old_idx
    if _returns_tangentially(ev, p, k3, new_sign, SLIDE_MULTI, mask, old_mode, nm, t, y, n,
                             etab, stab, slide_c, buf, fbuf, wk):
        return ST_SUCCESS, SLIDE_MULTI, mask, old_mode, -1, log_ref
    ref2 = _partner(stab, k3, old_mode)
    if ref2 >= 0:
        k = _solve_lambda(ev, p, mask, ref2, nm, t, y, n, stab, w1, gx)
        if k > 0:
            o_lam = _multi_offsets(n)[2]
            inside = True
            for i in range(k):
                if not (0.0 <= gx[o_lam + i] <= 1.0):
                    inside = False
            if inside:
                _multi_field(ev, p, mask, ref2, nm, t, y, n, fbuf, stab, slide_c, w1, gx)
                ev(W_HX, k3, t, y, p, hdx)
                ev(W_HT, k3, t, y, p, buf)
                rate = buf[0] + _dot(hdx, fbuf, n)
                if rate * new_sign > 0.0:
                    s3 = _find_switch(stab, k3, ref2, old_mode)
                    if s3 < 0:
                        s3 = _find_switch(stab, k3, old_mode, ref2)
                    return ST_SUCCESS, SLIDE_MULTI, mask, ref2, K_CROSSING, s3
    return _enter_multi(ev, p, mask | (1 << k3), old_mode, k3, nm, t, y, n, stab, buf, wk,
                        SLIDE_MULTI, old_idx, old_mode, log_ref)


@_hot
def _act_multi_exit(ev, p, i, old_idx, old_mode, nm, t, y, n, stab, buf, wk):
    """Sliding on the intersection of the surfaces of ``old_idx`` (reference corner
    ``old_mode``) ends on its ``i``-th surface: its weight ``lambda_i`` reached 0 (the motion
    leaves it to the side above) or 1 (below; ``lambda_i > 1/2`` tells which). The other
    surfaces keep sliding as far as their own weights allow (:func:`_settle_multi`: on the
    intersection of the rest, on the one left, or none -- the released contact may make
    another one slip at once). Logged as ``slide_end`` on the switch of that surface at the
    reference corner. Returns ``(dkind, didx, mode, log_kind, log_ref, below)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    ks = _multi_surface(old_idx, i)
    below = False
    if _solve_lambda(ev, p, old_idx, old_mode, nm, t, y, n, stab, w1, gx) > 0:
        below = gx[_multi_offsets(n)[2] + i] > 0.5
    ref = old_mode
    if below:
        ref = _partner(stab, ks, ref)
    s_log = _find_switch(stab, ks, old_mode, _partner(stab, ks, old_mode))
    mask = old_idx & ~(1 << ks)
    ref = _multi_reference(stab, mask, ref)
    dkind, didx, mode = _settle_multi(ev, p, t, y, n, nm, mask, ref, stab, buf, hdx, w1, gx)
    if dkind < 0:
        dkind = REGULAR
        didx = -1
        mode = ref
    return dkind, didx, mode, K_SLIDE_END, s_log, below


@njit(cache=True)
def _action_saltation(ev, p, act, log_kind, chatter_tail, ref, k, old_kind, old_idx, old_mode,
                      dkind, didx, mode, nm, t, xs, y, n, S, etab, stab, slide_c, buf, fbuf,
                      ytmp, wk):
    """The saltation matrix ``S`` of the action just taken (slides, "Saltation matrices";
    Adolfsson et al. 2001): of the reset or transition (:func:`_event_saltation`), of the
    complete-chattering map (:func:`_chatter_saltation`), of a Filippov crossing or sliding
    entry on surface ``k`` (:func:`_switch_saltation`); release and sliding exit leave the
    field continuous (``S = I``). ``ref``: the event or switch index of the action; ``xs``
    the state before it, ``y`` after it."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    if act == ACT_EVENT:
        if log_kind == K_CHATTER:
            _chatter_saltation(ev, p, ref, k, old_mode, nm, t, xs, n, S, etab, stab, slide_c)
        elif not chatter_tail:
            _event_saltation(ev, p, ref, k, old_mode, mode, nm, t, xs, y, n, S, gx, hdx, buf, fbuf,
                             w1, w2, etab, stab, slide_c, old_kind, old_idx, ytmp, dkind, didx)
    elif act == ACT_SWITCH or act == ACT_INTERSECTION:
        _switch_saltation(ev, p, dkind, didx, old_mode, mode, nm, k, t, y, n, S, hdx, buf, fbuf,
                          w1, w2, gx, etab, stab, slide_c, old_kind, old_idx)
    else:
        _identity(S, n)


@_hot
def _identity(S, n):
    for i in range(n):
        for c in range(n):
            S[i, c] = 1.0 if i == c else 0.0


@_hot
def _apply_saltation(y, S, Phi, n, seg_var):
    """The variational part of ``y`` after an event: ``Phi+ = S Phi-`` (slides, "Saltation
    matrices"); per segment the record keeps ``S`` (the segment's ``Phi`` is in x_before)."""
    if seg_var:
        for i in range(n):
            for c in range(n):
                y[n + i * n + c] = S[i, c]
        return
    for i in range(n):
        for c in range(n):
            Phi[i, c] = y[n + i * n + c]
    for i in range(n):
        for c in range(n):
            acc = 0.0
            for m in range(n):
                acc += S[i, m] * Phi[m, c]
            y[n + i * n + c] = acc


# --------------------------------------------------------------------------------------
# why a run ended at an intersection (for its message; compiled on first use)
# --------------------------------------------------------------------------------------

def _intersection_cause(ev, p, dkind, didx, mode, nm, t, x, stab, out):
    """Why the sliding motion in the discrete state ``(dkind, didx, mode)`` (``SLIDE`` or
    ``SLIDE_MULTI``) at ``(t, x)`` -- where a run ended with ``ST_INTERSECTION`` -- cannot
    slide on the intersection with the surface it reached, by the test the kernel applied
    (:func:`_multi_entry`, on the surfaces :func:`_act_intersection` and
    :func:`_act_multi_intersection` pass it).

    The surface reached is not in the kernel's result: it is the surface of a switch that
    bounds a mode of the sliding motion, is not slid on, and lies nearest to ``(t, x)`` in
    ``|h| / |h_x|`` (the kernel ends the run on the located crossing, within the location
    error of it). Writes ``out[0]`` that surface (-1: none), ``out[1]`` the cause
    (``IX_*``), ``out[2]`` the number ``k`` of surfaces and ``out[3:3 + k]`` their weights
    where they were solved (``IX_NOT_ATTRACTING``), or ``out[3]``, ``out[4]`` the surface and
    the mode from which no switch leads across it (``IX_NO_CORNER``). Returns the cause (-1
    where no surface was found)."""
    n = x.shape[0]
    w1 = np.zeros(n)
    work = np.zeros(max(n * n, multi_work_size(n, stab)))
    hdx = np.zeros(n)
    buf = np.zeros(max(n, 2))
    if dkind == SLIDE:
        mask0 = 1 << stab[didx].surface
        m = stab[didx].above
    else:
        mask0 = didx
        m = mode
    k0 = _multi_count(mask0)
    # the modes of the sliding motion, found once for every row of the table below
    corners = np.full(1 << k0, -1.0)
    if dkind == SLIDE_MULTI:
        _multi_corners(stab, mask0, m, corners, 0)
    else:
        corners[0] = stab[didx].above
        corners[1] = stab[didx].below
    best = np.inf
    k2 = -1
    for s in range(stab.shape[0]):
        ks = stab[s].surface
        if ks >= 63 or (mask0 >> ks) & 1:
            continue
        adjacent = False
        for c in range(1 << k0):
            mc = int(corners[c])
            if mc >= 0 and (stab[s].above == mc or stab[s].below == mc):
                adjacent = True
        if not adjacent:
            continue
        ev(W_H, ks, t, x, p, buf)
        hv = abs(buf[0])
        ev(W_HX, ks, t, x, p, hdx)
        g = np.sqrt(_dot(hdx, hdx, n))
        dist = hv / g if g > 0.0 else hv
        if dist < best:
            best = dist
            k2 = ks
    out[0] = k2
    if k2 < 0:
        return -1
    mask = mask0 | (1 << k2)
    cause, ref, k = _multi_entry(ev, p, mask, m, k2, nm, t, x, n, stab, w1, work)
    out[1] = cause
    out[2] = k
    if cause == IX_NOT_ATTRACTING:
        o_lam = _multi_offsets(n)[2]
        for i in range(k):
            out[3 + i] = work[o_lam + i]
    elif cause == IX_NO_CORNER:
        kk = _multi_count(mask)
        out[2] = kk
        # the walk of _multi_reference (to the corner above all surfaces), then that of
        # _multi_corners (from it across the surfaces of each corner): the first step that
        # finds no switch
        for c in range(1 if ref < 0 else 1 << kk):
            mm = m if ref < 0 else ref
            for i in range(kk):
                if ref >= 0 and not (c >> i) & 1:
                    continue
                ks = _multi_surface(mask, i)
                nxt = -1
                for s in range(stab.shape[0]):
                    if stab[s].surface == ks:
                        if stab[s].above == mm:
                            nxt = stab[s].below if ref >= 0 else mm
                            break
                        if stab[s].below == mm:
                            nxt = stab[s].above
                            break
                if nxt < 0:
                    out[3] = ks
                    out[4] = mm
                    return cause
                mm = nxt
    return cause


def _intersection_cause_signature():
    from numba import types as nt

    from ...model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    return nt.int64(EVALUATE_TYPE, f1, nt.int64, nt.int64, nt.int64, nt.int64, nt.float64, f1,
                    SWITCH_TABLE_TYPE, f1)


#: :func:`_intersection_cause`, compiled on first use: only a run that ends at an
#: intersection needs it.
intersection_cause = compiled_on_first_use(_intersection_cause, _intersection_cause_signature)
