"""The compiled event-driven integrator (numba).

One function, :func:`run_kernel`, integrates a hybrid model from ``t0`` to ``t_end`` with an
embedded explicit Runge-Kutta pair and handles every discontinuity in the same compiled loop:
no Python call is made per step or per event. The model enters as one first-class function
``evaluate(which, idx, t, x, p, out)`` (see :mod:`pwsdyn.model.codegen`), so this kernel is
compiled once for all models and cached on disk.

Discrete state
--------------
``dkind`` is what governs the motion now:

* ``REGULAR``: the vector field of mode ``mode``;
* ``STICK``: sticking on the surface of impact event ``didx`` after a complete chattering
  sequence: constrained motion ``f - lambda W`` (slides "Simulation: Chattering");
* ``SLIDE``: Filippov sliding on switch ``didx`` with the convex field
  ``f12 = (1 - alpha) f_above + alpha f_below - C h h_x^T`` (thesis eq. 2.7-2.8 with the
  stabilising term of the slides).

Watch functions
---------------
In each discrete state the kernel watches a small list of scalar functions of ``(t, x)`` for
zero crossings: surfaces ``h`` (events, switches), normal velocities ``hdot`` (sliding exit)
and normal accelerations ``hddot`` (release from sticking). On every accepted step each is
sampled on the dense output (ends, midpoint and, for surfaces, the extremum of the cubic
Hermite fit from ``h`` and ``hdot`` at the ends) so a crossing and re-crossing inside one step
(near grazing) is still found. The earliest crossing is bracketed and located by the Illinois
method on the dense output to a few ulps, then the step is re-taken exactly to that time
("landing step") and the time is polished with Newton steps on ``h`` so the event state comes
from the integrator itself, not from the interpolant.

Variational equations
---------------------
With ``variational`` the state is augmented by the n x n matrix ``Phi`` (row-major), integrated
with ``Phi' = J Phi`` and updated at every event by the saltation matrix (slides, "Saltation
matrices"; Adolfsson et al. 2001) with the ``h_t`` terms of time-dependent surfaces.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model.codegen import (W_F, W_FX, W_G, W_GUARD, W_GX, W_GT, W_H, W_HD, W_HDT, W_HDX,
                             W_HHD, W_HT, W_HX)

# discrete states
REGULAR, STICK, SLIDE = 0, 1, 2
# watch function types
WF_SURFACE, WF_HDOT, WF_HDDOT = 0, 1, 2
# actions of watch functions
ACT_EVENT, ACT_SWITCH, ACT_RELEASE, ACT_EXIT_ABOVE, ACT_EXIT_BELOW, ACT_INTERSECTION = 0, 1, 2, 3, 4, 5
# event log kinds (kept in sync with trajectory.EVENT_KINDS)
K_IMPACT, K_TRANSITION, K_CHATTER, K_STICK, K_RELEASE, K_CROSSING, K_SLIDE_START, K_SLIDE_END = (
    0, 1, 2, 3, 4, 5, 6, 7)
# event kinds in the model tables
EV_IMPACT, EV_TRANSITION = 0, 1
# status codes (errors.Status)
ST_SUCCESS, ST_TERMINAL, ST_MAX_STEPS, ST_MAX_EVENTS, ST_STEP_TOO_SMALL, ST_NONFINITE = 0, 1, 2, 3, 4, 5
ST_INTERSECTION = 6
ST_ZENO = 7
# integer options
IO_MODE0, IO_NMODES, IO_MAXSTEPS, IO_MAXEVENTS, IO_METHOD, IO_VAR, IO_CHATTER, IO_SAVE = range(8)
IO_N = 8
# float options
FO_RTOL, FO_ATOL, FO_H0, FO_HMAX, FO_CHAT_REL, FO_CHAT_ABS, FO_SLIDE_C = range(7)
FO_N = 7

_EPS = np.finfo(np.float64).eps
_MAXW = 64


# --------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------

@njit(cache=True)
def _grow2(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty((max(need, 2 * a.shape[0]),) + a.shape[1:], dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow3(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty((max(need, 2 * a.shape[0]), a.shape[1], a.shape[2]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow1(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _dot(a, b, n):
    s = 0.0
    for i in range(n):
        s += a[i] * b[i]
    return s


@njit(cache=True)
def _ulp(t):
    return max(abs(t), 1.0) * _EPS


# --------------------------------------------------------------------------------------
# vector fields of the discrete states
# --------------------------------------------------------------------------------------

@njit(cache=True)
def _impact_direction(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx):
    """W of the impact law ``x+ = x- + W hdot`` (slides, "Simulation: Chattering").

    For a reset ``g`` that is the identity at zero normal velocity ``hdot``, differentiating
    ``g(x) - x = W(x) hdot(x)`` on ``hdot = 0`` gives ``g_x - I = W hdot_x``, hence
    ``W = (g_x - I) hdot_x^T / |hdot_x|^2`` -- computed from the compiled derivatives.
    Returns ``hdot_x . W`` (so the restitution coefficient is ``r = -(1 + hdot_x W)``).
    """
    ev(W_GX, j, t, x, p, gx)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    nrm2 = _dot(hdx, hdx, n)
    for i in range(n):
        s = -hdx[i]
        for c in range(n):
            s += gx[i * n + c] * hdx[c]
        W[i] = s / nrm2 if nrm2 > 0.0 else 0.0
    return _dot(hdx, W, n)


@njit(cache=True)
def _field(ev, p, dkind, didx, mode, nm, t, x, n, out, etab, stab, slide_c, w1, w2, gx, hdx):
    """Vector field of the current discrete state at (t, x) into out[:n]."""
    if dkind == REGULAR:
        ev(W_F, mode, t, x, p, out)
        return
    if dkind == STICK:
        # constrained motion f - lambda W with lambda from hddot = 0 (slides):
        # lambda = (hdot_t + hdot_x f) / (hdot_x W)
        j = didx
        k = etab[j, 0]
        ev(W_F, mode, t, x, p, out)
        hw = _impact_direction(ev, p, j, k, mode, nm, t, x, n, w1, gx, hdx)
        ev(W_HDT, k * nm + mode, t, x, p, w2)
        acc = w2[0] + _dot(hdx, out, n)
        lam = acc / hw if hw != 0.0 else 0.0
        for i in range(n):
            out[i] -= lam * w1[i]
        return
    # SLIDE: Filippov convex combination (thesis eq. 2.7-2.8) + stabilisation -C h grad h
    s = didx
    k = stab[s, 0]
    a = stab[s, 1]
    b = stab[s, 2]
    ev(W_F, a, t, x, p, w1)
    ev(W_F, b, t, x, p, w2)
    ev(W_HX, k, t, x, p, hdx)
    ev(W_HT, k, t, x, p, out)
    ht = out[0]
    ev(W_H, k, t, x, p, out)
    hval = out[0]
    num = ht + _dot(hdx, w1, n)
    den = _dot(hdx, w1, n) - _dot(hdx, w2, n)
    alpha = num / den if den != 0.0 else 0.5
    for i in range(n):
        out[i] = (1.0 - alpha) * w1[i] + alpha * w2[i] - slide_c * hval * hdx[i]


@njit(cache=True)
def _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, out, etab, stab, slide_c,
         w1, w2, gx, hdx, jac, xt, ft):
    """Right-hand side of the (optionally variational) system."""
    _field(ev, p, dkind, didx, mode, nm, t, y, n, out, etab, stab, slide_c, w1, w2, gx, hdx)
    if nvar == 0:
        return
    _jacobian(ev, p, dkind, didx, mode, nm, t, y, n, out, etab, stab, slide_c,
              w1, w2, gx, hdx, jac, xt, ft)
    # Phi' = J Phi, Phi stored row-major after the state
    for i in range(n):
        for c in range(n):
            s = 0.0
            for m in range(n):
                s += jac[i * n + m] * y[n + m * n + c]
            out[n + i * n + c] = s


@njit(cache=True)
def _jacobian(ev, p, dkind, didx, mode, nm, t, y, n, f0, etab, stab, slide_c,
              w1, w2, gx, hdx, jac, xt, ft):
    """Jacobian of the current field: symbolic in a regular mode, central differences of the
    constrained (sticking) or sliding field otherwise (those involve second derivatives of
    h and g that the generated code does not carry)."""
    if dkind == REGULAR:
        ev(W_FX, mode, t, y, p, jac)
        return
    for c in range(n):
        for i in range(n):
            xt[i] = y[i]
        dx = 1e-7 * max(1.0, abs(y[c]))
        xt[c] = y[c] + dx
        _field(ev, p, dkind, didx, mode, nm, t, xt, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
        for i in range(n):
            jac[i * n + c] = ft[i]
        xt[c] = y[c] - dx
        _field(ev, p, dkind, didx, mode, nm, t, xt, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
        for i in range(n):
            jac[i * n + c] = (jac[i * n + c] - ft[i]) / (2.0 * dx)


# --------------------------------------------------------------------------------------
# Runge-Kutta step and dense output
# --------------------------------------------------------------------------------------

@njit(cache=True)
def _rk_stages(ev, p, dkind, didx, mode, nm, t, y, h, nY, n, nvar, K, A, C, s_last, ytmp,
               etab, stab, slide_c, w1, w2, gx, hdx, jac, xt, ft):
    """Stages 1..s_last of an explicit RK step (stage 0 = K[0] is given)."""
    for st in range(1, s_last + 1):
        for i in range(nY):
            acc = 0.0
            for m in range(st):
                a = A[st, m]
                if a != 0.0:
                    acc += a * K[m, i]
            ytmp[i] = y[i] + h * acc
        if dkind == REGULAR and nvar == 0:
            ev(W_F, mode, t + C[st] * h, ytmp, p, K[st])
        else:
            _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h, ytmp, n, nvar, K[st], etab, stab,
                 slide_c, w1, w2, gx, hdx, jac, xt, ft)


@njit(cache=True)
def _error_norm(K, E, method, s, y, ynew, h, n, rtol, atol):
    """Scaled RMS error over the state components (not the variational ones)."""
    if method == 0:
        acc = 0.0
        for i in range(n):
            e = 0.0
            for m in range(s + 1):
                e += E[0, m] * K[m, i]
            sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
            acc += (h * e / sc) ** 2
        return np.sqrt(acc / n)
    # DOP853 (Hairer et al. II.10): combined 5th and 3rd order estimates
    e5 = 0.0
    e3 = 0.0
    for i in range(n):
        a5 = 0.0
        a3 = 0.0
        for m in range(s + 1):
            a5 += E[0, m] * K[m, i]
            a3 += E[1, m] * K[m, i]
        sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
        e5 += (a5 / sc) ** 2
        e3 += (a3 / sc) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * n)


@njit(cache=True)
def _dense_coeffs(K, P, h, nY, s_ext, deg, out):
    """out[i, k] = h * sum_j K[j, i] P[j, k]  (power form, theta^(k+1))."""
    for i in range(nY):
        for k in range(deg):
            acc = 0.0
            for j in range(s_ext):
                pj = P[j, k]
                if pj != 0.0:
                    acc += K[j, i] * pj
            out[i, k] = h * acc


@njit(cache=True)
def _make_dense(ev, p, dkind, didx, mode, nm, t, y, h, nY, n, nvar, K, A, C, s_fsal, P, Q, ytmp,
                etab, stab, slide_c, w1, w2, gx, hdx, jac, xt, ft):
    """Dense output of the step just taken: extra stages (DOP853) and power-form
    coefficients. Returns the number of extra function evaluations."""
    s_ext = A.shape[0]
    for st in range(s_fsal + 1, s_ext):
        for i in range(nY):
            acc = 0.0
            for m in range(st):
                acc += A[st, m] * K[m, i]
            ytmp[i] = y[i] + h * acc
        _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h, ytmp, n, nvar, K[st], etab, stab,
             slide_c, w1, w2, gx, hdx, jac, xt, ft)
    _dense_coeffs(K, P, h, nY, s_ext, P.shape[1], Q)
    return s_ext - s_fsal - 1


@njit(cache=True)
def _dense_eval(y0, Q, theta, nY, deg, out):
    for i in range(nY):
        acc = 0.0
        for k in range(deg - 1, -1, -1):
            acc = (acc + Q[i, k]) * theta
        out[i] = y0[i] + acc


# --------------------------------------------------------------------------------------
# watch functions
# --------------------------------------------------------------------------------------

@njit(cache=True)
def _watch_value(ev, p, wtype, widx, wmode, nm, t, x, n, buf, fbuf, hdx):
    if wtype == WF_SURFACE:
        ev(W_H, widx, t, x, p, buf)
        return buf[0]
    if wtype == WF_HDOT:
        ev(W_HD, widx * nm + wmode, t, x, p, buf)
        return buf[0]
    # WF_HDDOT: free normal acceleration hdot_t + hdot_x f
    ev(W_F, wmode, t, x, p, fbuf)
    ev(W_HDX, widx * nm + wmode, t, x, p, hdx)
    ev(W_HDT, widx * nm + wmode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n)


@njit(cache=True)
def _surface_rate(ev, p, dkind, k, mode, nm, t, x, f, n, buf, hdx):
    """dh/dt along the current field f: one call of the compiled hdot in a regular mode."""
    if dkind == REGULAR:
        ev(W_HD, k * nm + mode, t, x, p, buf)
        return buf[0]
    ev(W_HX, k, t, x, p, hdx)
    ev(W_HT, k, t, x, p, buf)
    return buf[0] + _dot(hdx, f, n)


@njit(cache=True)
def _crosses(v0, v1, direction):
    """A zero crossing from v0 to v1 in ``direction``. A function that starts exactly at zero
    and moves in the event direction crosses (a start on an impact surface with approaching
    velocity is an impact at the initial time)."""
    if direction < 0:
        return (v0 > 0.0 and v1 <= 0.0) or (v0 == 0.0 and v1 < 0.0)
    if direction > 0:
        return (v0 < 0.0 and v1 >= 0.0) or (v0 == 0.0 and v1 > 0.0)
    return (v0 > 0.0 and v1 <= 0.0) or (v0 < 0.0 and v1 >= 0.0)


# --------------------------------------------------------------------------------------
# event maps and saltation matrices
# --------------------------------------------------------------------------------------

@njit(cache=True)
def _project_stick(ev, p, k, mode, nm, t, x, n, hdx, w2, buf):
    """Project x onto {h = 0, hdot = 0} along span(h_x, hdot_x) (two Newton iterations)."""
    for it in range(3):
        ev(W_H, k, t, x, p, buf)
        r1 = buf[0]
        ev(W_HD, k * nm + mode, t, x, p, buf)
        r2 = buf[0]
        ev(W_HX, k, t, x, p, w2)
        ev(W_HDX, k * nm + mode, t, x, p, hdx)
        # solve [a.a a.b; b.a b.b] c = -r for x += c0 a + c1 b with a = h_x, b = hdot_x
        aa = _dot(w2, w2, n)
        ab = _dot(w2, hdx, n)
        bb = _dot(hdx, hdx, n)
        det = aa * bb - ab * ab
        if det == 0.0 or not np.isfinite(det):
            return
        # rows: h_x.(c0 a + c1 b) = -r1, hdot_x.(c0 a + c1 b) = -r2
        c0 = (-r1 * bb + r2 * ab) / det
        c1 = (-r2 * aa + r1 * ab) / det
        for i in range(n):
            x[i] += c0 * w2[i] + c1 * hdx[i]


@njit(cache=True)
def _event_saltation(ev, p, j, k, mode_in, mode_out, nm, t, x_in, x_out, n, S, gx, hx, buf,
                     f_in, f_out, gt, etab, stab, slide_c, old_kind, old_idx, tmp):
    """S = g_x + (f_out - g_x f_in - g_t) h_x / (h_t + h_x f_in)  (slides, "Saltation
    matrices", with the time derivatives of time-dependent surfaces and resets)."""
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    hdx = np.zeros(n)
    _field(ev, p, old_kind, old_idx, mode_in, nm, t, x_in, n, f_in, etab, stab, slide_c,
           w1, w2, gx, hdx)
    ev(W_F, mode_out, t, x_out, p, f_out)
    ev(W_GX, j, t, x_in, p, gx)
    ev(W_GT, j, t, x_in, p, gt)
    ev(W_HX, k, t, x_in, p, hx)
    ev(W_HT, k, t, x_in, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    for i in range(n):
        gf = 0.0
        for c in range(n):
            gf += gx[i * n + c] * f_in[c]
        v = f_out[i] - gf - gt[i]
        for c in range(n):
            S[i, c] = gx[i * n + c] + (v * hx[c] / den if den != 0.0 else 0.0)


@njit(cache=True)
def _switch_saltation(ev, p, dkind, didx, mode_in, mode_out, nm, k, t, x, n, S, hx, buf,
                      f_in, w1, w2, gx, etab, stab, slide_c):
    """Crossing or sliding entry: S = I + (f_out - f_in) h_x / (h_t + h_x f_in)."""
    f_out = np.zeros(n)
    hdx = np.zeros(n)
    ev(W_F, mode_in, t, x, p, f_in)
    _field(ev, p, dkind, didx, mode_out, nm, t, x, n, f_out, etab, stab, slide_c, w1, w2, gx, hdx)
    ev(W_HX, k, t, x, p, hx)
    ev(W_HT, k, t, x, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    for i in range(n):
        for c in range(n):
            S[i, c] = (1.0 if i == c else 0.0) + ((f_out[i] - f_in[i]) * hx[c] / den
                                                  if den != 0.0 else 0.0)


@njit(cache=True)
def _chatter_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf):
    """Complete-chattering map Q and time q at x (slides; Nordmark & Piiroinen 2009).
    Returns the duration q(x) - t; writes Q(x) into out."""
    ev(W_HD, k * nm + mode, t, x, p, buf)
    vin = buf[0]
    ev(W_F, mode, t, x, p, f)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    acc = buf[0] + _dot(hdx, f, n)
    hw = _impact_direction(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx)
    r = -(1.0 + hw)
    for i in range(n):
        out[i] = x[i] + (2.0 * r * f[i] / acc + W[i]) * vin / (1.0 - r)
    return 2.0 * r * vin / ((1.0 - r) * acc)


@njit(cache=True)
def _chatter_saltation(ev, p, j, k, mode, nm, t, x_in, n, S, W, w2, gx, hdx, f_in, xt, ft, buf,
                       etab, stab, slide_c, jac):
    """G = C + (f_out - C f_in) h_x / (h_x f_in),  C = Q_x - f_out q_x  (slides, "Saltation
    matrices", chattering). Q_x and q_x by central differences of the closed-form map."""
    qo = np.zeros(n)
    qp = np.zeros(n)
    qm = np.zeros(n)
    f = np.zeros(n)
    hx = np.zeros(n)
    dq = np.zeros(n)
    _chatter_map(ev, p, j, k, mode, nm, t, x_in, n, qo, W, gx, hdx, f, buf)
    Cm = np.zeros((n, n))
    for c in range(n):
        for i in range(n):
            xt[i] = x_in[i]
        dx = 1e-7 * max(1.0, abs(x_in[c]))
        xt[c] = x_in[c] + dx
        tp = _chatter_map(ev, p, j, k, mode, nm, t, xt, n, qp, W, gx, hdx, f, buf)
        xt[c] = x_in[c] - dx
        tm = _chatter_map(ev, p, j, k, mode, nm, t, xt, n, qm, W, gx, hdx, f, buf)
        for i in range(n):
            Cm[i, c] = (qp[i] - qm[i]) / (2.0 * dx)
        dq[c] = (tp - tm) / (2.0 * dx)
    # f_out: the sticking field at Q(x_in)
    w1 = np.zeros(n)
    _field(ev, p, STICK, j, mode, nm, t, qo, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
    for i in range(n):
        for c in range(n):
            Cm[i, c] -= ft[i] * dq[c]
    ev(W_F, mode, t, x_in, p, f_in)
    ev(W_HX, k, t, x_in, p, hx)
    ev(W_HT, k, t, x_in, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    for i in range(n):
        cf = 0.0
        for c in range(n):
            cf += Cm[i, c] * f_in[c]
        v = ft[i] - cf
        for c in range(n):
            S[i, c] = Cm[i, c] + (v * hx[c] / den if den != 0.0 else 0.0)


# --------------------------------------------------------------------------------------
# the kernel
# --------------------------------------------------------------------------------------

def _kernel_signature():
    from numba import types as nt

    from ..model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    f2 = nt.float64[:, ::1]
    i1 = nt.int64[::1]
    i2 = nt.int64[:, ::1]
    ret = nt.Tuple((nt.int64, nt.float64, f1, i1, f1, f2, i2, nt.float64[:, :, ::1], i1, f1, f1,
                    i2, f2, f2, i1))
    return ret(EVALUATE_TYPE, nt.float64, nt.float64, f1, f1, i2, i2, i2, i1, f1, f2, f1, f2, f2,
               nt.int64)


@njit(_kernel_signature(), cache=True)
def run_kernel(ev, t0, t_end, x0, p, etab, eactive, stab, iopt, fopt, A, C, E, P, s_fsal):
    """Integrate from ``t0`` to ``t_end``. See the module docstring.

    Tables
    ------
    etab : (n_events, 6) int64 -- surface, direction, kind, target, terminal, has_reset
    eactive : (n_events, n_modes) int8
    stab : (n_switches, 3) int64 -- surface, above, below
    iopt, fopt : options, indexed by the IO_* / FO_* constants

    Returns
    -------
    status, nodes_t, nodes_y, nodes_state (kind, idx, mode), dense (per interval), interval kind
    (0 step, 1 jump, 2 chatter gap), event log (t, t_after, info, x_before, x_after), stats
    """
    n = x0.shape[0]
    nm = iopt[IO_NMODES]
    nvar = iopt[IO_VAR]
    nY = n + nvar * n * n
    method = iopt[IO_METHOD]
    max_steps = iopt[IO_MAXSTEPS]
    max_events = iopt[IO_MAXEVENTS]
    chatter_on = iopt[IO_CHATTER]
    save_all = iopt[IO_SAVE]
    rtol = fopt[FO_RTOL]
    atol = fopt[FO_ATOL]
    hmax = fopt[FO_HMAX]
    chat_rel = fopt[FO_CHAT_REL]
    chat_abs = fopt[FO_CHAT_ABS]
    slide_c = fopt[FO_SLIDE_C]
    s_ext = A.shape[0]
    deg = P.shape[1]
    n_events = etab.shape[0]
    n_sw = stab.shape[0]
    order = 5.0 if method == 0 else 8.0

    # work arrays
    K = np.zeros((s_ext, nY))
    ytmp = np.zeros(nY)
    ynew = np.zeros(nY)
    y = np.zeros(nY)
    Q = np.zeros((nY, deg))
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(n * n)
    hdx = np.zeros(n)
    jac = np.zeros(n * n)
    xt = np.zeros(n)
    ft = np.zeros(n)
    buf = np.zeros(max(n, 2))
    fbuf = np.zeros(n)
    xs = np.zeros(nY)
    Kland = np.zeros((s_ext, nY))
    S = np.zeros((n, n))
    Phi = np.zeros((n, n))

    # outputs
    cap = 256
    nodes_t = np.empty(cap)
    nodes_y = np.empty((cap, nY))
    nodes_s = np.empty((cap, 3), dtype=np.int64)
    dense = np.empty((cap, nY, deg))
    ikind = np.empty(cap, dtype=np.int64)
    ecap = 16
    ev_t = np.empty(ecap)
    ev_t2 = np.empty(ecap)
    ev_info = np.empty((ecap, 8), dtype=np.int64)
    ev_xb = np.empty((ecap, nY))
    ev_xa = np.empty((ecap, nY))
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
    mode = iopt[IO_MODE0]
    status = ST_SUCCESS

    # watch list
    wtype = np.zeros(_MAXW, dtype=np.int64)
    widx = np.zeros(_MAXW, dtype=np.int64)
    wmode = np.zeros(_MAXW, dtype=np.int64)
    wdir = np.zeros(_MAXW, dtype=np.int64)
    wact = np.zeros(_MAXW, dtype=np.int64)
    wref = np.zeros(_MAXW, dtype=np.int64)
    wforce = np.zeros(_MAXW)      # forced sign at the start of the next step (re-trigger guard)
    wv = np.zeros(_MAXW)          # watch values at the end of the last accepted step ...
    wd = np.zeros(_MAXW)          # ... and their time derivatives (surfaces), reused next step
    wvalid = np.zeros(_MAXW, dtype=np.int64)
    nw = 0
    # the surface/function that just fired, to suppress an immediate re-trigger
    last_type = -1
    last_idx = -1
    last_mode = -1
    last_sign = 0.0
    last_t = np.nan
    # chattering chain bookkeeping
    chain_event = -1
    chain_vmax = 0.0
    zeno = 0
    last_depth = 0.0

    noise = 0.0
    vals = np.zeros((_MAXW, 8))
    thetas = np.zeros(8)

    # first node
    nodes_t[0] = t
    nodes_y[0, :] = y
    nodes_s[0, 0] = dkind
    nodes_s[0, 1] = didx
    nodes_s[0, 2] = mode
    n_nodes = 1

    restart = True
    h = fopt[FO_H0]
    f_ok = False
    while True:
        if restart:
            # (re)build the watch list for the current discrete state
            nw = 0
            for j in range(n_events):
                if eactive[j, mode] == 0:
                    continue
                if dkind == STICK and etab[j, 0] == etab[didx, 0]:
                    continue
                if dkind == SLIDE:
                    continue
                wtype[nw] = WF_SURFACE; widx[nw] = etab[j, 0]; wmode[nw] = mode
                wdir[nw] = etab[j, 1]; wact[nw] = ACT_EVENT; wref[nw] = j
                nw += 1
            for s in range(n_sw):
                if dkind == SLIDE:
                    if s == didx:
                        continue
                    wtype[nw] = WF_SURFACE; widx[nw] = stab[s, 0]; wmode[nw] = mode
                    wdir[nw] = 0; wact[nw] = ACT_INTERSECTION; wref[nw] = s
                    nw += 1
                    continue
                if stab[s, 1] == mode or stab[s, 2] == mode:
                    wtype[nw] = WF_SURFACE; widx[nw] = stab[s, 0]; wmode[nw] = mode
                    wdir[nw] = -1 if stab[s, 1] == mode else 1
                    wact[nw] = ACT_SWITCH; wref[nw] = s
                    nw += 1
            if dkind == STICK:
                k = etab[didx, 0]
                wtype[nw] = WF_HDDOT; widx[nw] = k; wmode[nw] = mode
                wdir[nw] = 1; wact[nw] = ACT_RELEASE; wref[nw] = didx
                nw += 1
            if dkind == SLIDE:
                k = stab[didx, 0]
                # leave above when hdot of the above field turns positive (alpha -> 0),
                # below when hdot of the below field turns negative (alpha -> 1)
                wtype[nw] = WF_HDOT; widx[nw] = k; wmode[nw] = stab[didx, 1]
                wdir[nw] = 1; wact[nw] = ACT_EXIT_ABOVE; wref[nw] = didx
                nw += 1
                wtype[nw] = WF_HDOT; widx[nw] = k; wmode[nw] = stab[didx, 2]
                wdir[nw] = -1; wact[nw] = ACT_EXIT_BELOW; wref[nw] = didx
                nw += 1
                for j in range(n_events):
                    if eactive[j, stab[didx, 1]] == 0 and eactive[j, stab[didx, 2]] == 0:
                        continue
                    wtype[nw] = WF_SURFACE; widx[nw] = etab[j, 0]; wmode[nw] = mode
                    wdir[nw] = etab[j, 1]; wact[nw] = ACT_EVENT; wref[nw] = j
                    nw += 1
            for w in range(nw):
                wvalid[w] = 0
                wforce[w] = 0.0
                if (t == last_t and wtype[w] == last_type and widx[w] == last_idx
                        and (wtype[w] == WF_SURFACE or wmode[w] == last_mode)):
                    wforce[w] = last_sign
            _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, K[0], etab, stab, slide_c,
                 w1, w2, gx, hdx, jac, xt, ft)
            stats[2] += 1
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
                h = min(h, abs(t_end - t))
            restart = False

        if t >= t_end:
            break
        if stats[0] >= max_steps:
            status = ST_MAX_STEPS
            break
        h = min(h, hmax, t_end - t)
        if h < 4.0 * _ulp(t):
            if t_end - t <= 4.0 * _ulp(t):
                t = t_end
                break
            status = ST_STEP_TOO_SMALL
            break

        # ---- one RK step (stages written out here: this is the hot loop)
        fast = dkind == REGULAR and nvar == 0
        for st in range(1, s_fsal + 1):
            cst = t + C[st] * h
            for i in range(nY):
                acc = 0.0
                for m in range(st):
                    acc += A[st, m] * K[m, i]
                ytmp[i] = y[i] + h * acc
            if fast:
                ev(W_F, mode, cst, ytmp, p, K[st])
            else:
                _rhs(ev, p, dkind, didx, mode, nm, cst, ytmp, n, nvar, K[st], etab, stab,
                     slide_c, w1, w2, gx, hdx, jac, xt, ft)
        stats[2] += s_fsal
        # the FSAL stage was evaluated at y + h sum B K = the new solution
        finite = True
        for i in range(nY):
            ynew[i] = ytmp[i]
            if not (np.isfinite(K[s_fsal, i]) and np.isfinite(ynew[i])):
                finite = False
        if not finite:
            err = np.inf
        elif method == 0:
            err = 0.0
            for i in range(n):
                e = 0.0
                for m in range(s_fsal + 1):
                    e += E[0, m] * K[m, i]
                sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
                err += (h * e / sc) ** 2
            err = np.sqrt(err / n)
        else:
            err = _error_norm(K, E, method, s_fsal, y, ynew, h, n, rtol, atol)
        if not (err <= 1.0):
            stats[1] += 1
            if not finite:
                h *= 0.25
                if h < 4.0 * _ulp(t):
                    status = ST_NONFINITE
                    break
            else:
                h *= max(0.2, 0.9 * err ** (-1.0 / order))
            continue
        stats[0] += 1
        # dense output coefficients are made only when needed (stored steps, interior samples)
        q_ready = False
        if save_all:
            stats[2] += _make_dense(ev, p, dkind, didx, mode, nm, t, y, h, nY, n, nvar, K, A, C,
                                    s_fsal, P, Q, ytmp, etab, stab, slide_c, w1, w2, gx, hdx,
                                    jac, xt, ft)
            q_ready = True
        t_new = t + h

        # ---- event detection on [t, t_new]
        best = -1
        best_th = 2.0
        best_sign = 0.0
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
                    r0 = _surface_rate(ev, p, dkind, widx[w], mode, nm, t, y, K[0], n, buf, hdx)
                if dkind == REGULAR:
                    ev(W_HHD, widx[w] * nm + mode, t_new, ynew, p, buf)
                    v1 = buf[0]
                    r1 = buf[1]
                else:
                    v1 = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t_new, ynew, n,
                                      buf, fbuf, hdx)
                    r1 = _surface_rate(ev, p, dkind, widx[w], mode, nm, t_new, ynew, K[s_fsal],
                                       n, buf, hdx)
                wv[w] = v1
                wd[w] = r1
                d0 = r0 * h
                d1 = r1 * h
                # H(th) = ca th^3 + cb th^2 + d0 th + v0;  H'(th) = 3 ca th^2 + 2 cb th + d0
                ca = 2.0 * v0 - 2.0 * v1 + d0 + d1
                cb = -3.0 * v0 + 3.0 * v1 - 2.0 * d0 - d1
                qa = 3.0 * ca
                qb = 2.0 * cb
                ns = 1
                thetas[0] = 0.0
                vals[w, 0] = v0
                if abs(qa) > 1e-300:
                    disc = qb * qb - 4.0 * qa * d0
                    if disc >= 0.0:
                        sq = np.sqrt(disc)
                        ra = (-qb - sq) / (2.0 * qa)
                        rb = (-qb + sq) / (2.0 * qa)
                        if ra > rb:
                            ra, rb = rb, ra
                        if 0.0 < ra < 1.0:
                            thetas[ns] = ra
                            ns += 1
                        if 0.0 < rb < 1.0 and rb > ra:
                            thetas[ns] = rb
                            ns += 1
                elif abs(qb) > 1e-300:
                    ra = -d0 / qb
                    if 0.0 < ra < 1.0:
                        thetas[ns] = ra
                        ns += 1
                if ns > 1 and not q_ready:
                    stats[2] += _make_dense(ev, p, dkind, didx, mode, nm, t, y, h, nY, n, nvar, K,
                                            A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, w1, w2,
                                            gx, hdx, jac, xt, ft)
                    q_ready = True
                for q in range(1, ns):
                    _dense_eval(y, Q, thetas[q], nY, deg, xs)
                    vals[w, q] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm,
                                              t + thetas[q] * h, xs, n, buf, fbuf, hdx)
                thetas[ns] = 1.0
                vals[w, ns] = v1
                ns += 1
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
                if not q_ready:
                    stats[2] += _make_dense(ev, p, dkind, didx, mode, nm, t, y, h, nY, n, nvar, K,
                                            A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, w1, w2,
                                            gx, hdx, jac, xt, ft)
                    q_ready = True
                _dense_eval(y, Q, 0.5, nY, deg, xs)
                vals[w, 1] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + 0.5 * h,
                                          xs, n, buf, fbuf, hdx)
                vals[w, 2] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t_new, ynew,
                                          n, buf, fbuf, hdx)
                wv[w] = vals[w, 2]
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
                if th >= best_th:
                    break
                if forced and abs(vq) <= noise:
                    prev_th = th
                    continue
                if _crosses(prev_v, vq, wdir[w]):
                    if not q_ready:
                        stats[2] += _make_dense(ev, p, dkind, didx, mode, nm, t, y, h, nY, n,
                                                nvar, K, A, C, s_fsal, P, Q, ytmp, etab, stab,
                                                slide_c, w1, w2, gx, hdx, jac, xt, ft)
                        q_ready = True
                    # locate by Illinois on the dense output within [prev_th, th]
                    a_th = prev_th
                    b_th = th
                    fa = prev_v
                    fb = vq
                    side = 0
                    width_check = b_th - a_th
                    for it in range(400):
                        if (b_th - a_th) * h <= 2.0 * _ulp(t + b_th * h):
                            break
                        m_th = (a_th * fb - b_th * fa) / (fb - fa) if fb != fa else 0.5 * (a_th + b_th)
                        # safeguard: bisect when two secant steps did not halve the bracket
                        # (Illinois stalls when one end value is tiny, e.g. right after an event)
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

        if best < 0:
            # accept the whole step
            if save_all:
                if n_nodes + 1 > nodes_t.shape[0]:
                    nodes_t = _grow1(nodes_t, n_nodes + 1)
                    nodes_y = _grow2(nodes_y, n_nodes + 1)
                    nodes_s = _grow2(nodes_s, n_nodes + 1)
                    dense = _grow3(dense, n_nodes + 1)
                    ikind = _grow1(ikind, n_nodes + 1)
                for i in range(nY):
                    for k in range(deg):
                        dense[n_nodes - 1, i, k] = Q[i, k]
                    nodes_y[n_nodes, i] = ynew[i]
                ikind[n_nodes - 1] = 0
                nodes_t[n_nodes] = t_new
                nodes_s[n_nodes, 0] = dkind
                nodes_s[n_nodes, 1] = didx
                nodes_s[n_nodes, 2] = mode
                n_nodes += 1
            t = t_new
            for i in range(nY):
                y[i] = ynew[i]
                K[0, i] = K[s_fsal, i]
            for ww in range(nw):
                wvalid[ww] = 1
            fac = 10.0 if err == 0.0 else min(10.0, max(0.2, 0.9 * err ** (-1.0 / order)))
            h = h * fac
            continue

        # ---- an event inside the step: land exactly on it with a shortened step, then
        # polish the time with Newton on the watch function (h / hdot) for surfaces
        w = best
        h_ev = best_th * h
        for i in range(nY):
            Kland[0, i] = K[0, i]
        for polish in range(8):
            _rk_stages(ev, p, dkind, didx, mode, nm, t, y, h_ev, nY, n, nvar, Kland, A, C, s_fsal,
                       ytmp, etab, stab, slide_c, w1, w2, gx, hdx, jac, xt, ft)
            stats[2] += s_fsal
            stats[5] += 1
            for i in range(nY):
                ynew[i] = ytmp[i]
            if wtype[w] != WF_SURFACE or polish == 7:
                break
            # Newton on h(t + h_ev) with the landing step as the flow: quadratic, so a few
            # iterations bring h to round-off even for slow (near-grazing) arrivals
            hv = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + h_ev, ynew, n, buf,
                              fbuf, hdx)
            hd = _surface_rate(ev, p, dkind, widx[w], mode, nm, t + h_ev, ynew, Kland[s_fsal], n,
                               buf, hdx)
            if hd == 0.0 or hv == 0.0:
                break
            dt = -hv / hd
            if abs(dt) <= 2.0 * _ulp(t + h_ev) or h_ev + dt <= 0.0 or h_ev + dt > h:
                break
            h_ev += dt
        # landing-step dense output (extra stages for DOP853)
        if s_ext > s_fsal + 1:
            for st in range(s_fsal + 1, s_ext):
                for i in range(nY):
                    acc = 0.0
                    for m in range(st):
                        acc += A[st, m] * Kland[m, i]
                    ytmp[i] = y[i] + h_ev * acc
                _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h_ev, ytmp, n, nvar, Kland[st],
                     etab, stab, slide_c, w1, w2, gx, hdx, jac, xt, ft)
        _dense_coeffs(Kland, P, h_ev, nY, s_ext, deg, Q)
        t_ev = t + h_ev
        # store the node just before the event (always, also when not saving all steps)
        nodes_t = _grow1(nodes_t, n_nodes + 3)
        nodes_y = _grow2(nodes_y, n_nodes + 3)
        nodes_s = _grow2(nodes_s, n_nodes + 3)
        dense = _grow3(dense, n_nodes + 3)
        ikind = _grow1(ikind, n_nodes + 3)
        dense[n_nodes - 1, :, :] = Q
        ikind[n_nodes - 1] = 0 if save_all else 1
        nodes_t[n_nodes] = t_ev
        nodes_y[n_nodes, :] = ynew
        nodes_s[n_nodes, 0] = dkind
        nodes_s[n_nodes, 1] = didx
        nodes_s[n_nodes, 2] = mode
        n_nodes += 1

        # ---- handle the event
        for i in range(nY):
            y[i] = ynew[i]
        t = t_ev
        old_kind = dkind
        old_idx = didx
        old_mode = mode
        log_kind = -1
        log_ref = wref[w]
        t_after = t
        act = wact[w]
        new_sign = best_sign
        for i in range(nY):
            xs[i] = y[i]
        if act == ACT_EVENT:
            j = wref[w]
            ev(W_GUARD, j, t, y, p, buf)
            guard_ok = buf[0] != 0.0
            # a crossing whose normal velocity points against the event direction is
            # round-off around a previous event (the state is already leaving): not an event
            ev(W_HD, widx[w] * nm + mode, t, y, p, buf)
            vn = buf[0]
            moving_away = etab[j, 1] != 0 and vn * etab[j, 1] < 0.0
            if not guard_ok or moving_away:
                # no event: continue past this crossing
                last_type = wtype[w]; last_idx = widx[w]; last_mode = wmode[w]
                last_sign = new_sign
                if moving_away:
                    last_sign = 1.0 if vn > 0.0 else -1.0
                    # the state sits a little on the far side (round-off of an earlier event)
                    # and is moving back: values within that depth are not a new crossing
                    ev(W_H, widx[w], t, y, p, buf)
                    last_depth = 4.0 * abs(buf[0])
                last_t = t
                # the interval [t_ev, ...] continues smoothly: mark the stored interval as step
                ikind[n_nodes - 2] = 0 if save_all else 1
                restart = True
                continue
            k = etab[j, 0]
            if etab[j, 2] == EV_IMPACT:
                # normal velocity and acceleration at impact, impact direction W, restitution r
                ev(W_HD, k * nm + mode, t, y, p, buf)
                vin = buf[0]
                ev(W_F, mode, t, y, p, fbuf)
                ev(W_HDX, k * nm + mode, t, y, p, hdx)
                ev(W_HDT, k * nm + mode, t, y, p, buf)
                acc = buf[0] + _dot(hdx, fbuf, n)
                hw = _impact_direction(ev, p, j, k, mode, nm, t, y, n, w1, gx, hdx)
                r = -(1.0 + hw)
                if chain_event != j:
                    chain_event = j
                    chain_vmax = 0.0
                chain_vmax = max(chain_vmax, abs(vin))
                do_chatter = (chatter_on == 1 and acc < 0.0 and r >= 0.0 and r < 1.0
                              and (abs(vin) <= chat_rel * chain_vmax or abs(vin) <= chat_abs
                                   or r == 0.0))
                if do_chatter:
                    # complete-chattering map (Nordmark & Piiroinen 2009; slides):
                    # x_out = x_in + (2 r f_in / a + W) hdot_in / (1 - r),
                    # t_out = t_in + 2 r hdot_in / ((1 - r) a)
                    dtc = 2.0 * r * vin / ((1.0 - r) * acc)
                    for i in range(n):
                        y[i] = xs[i] + (2.0 * r * fbuf[i] / acc + w1[i]) * vin / (1.0 - r)
                    if nvar:
                        _chatter_saltation(ev, p, j, k, mode, nm, t, xs, n, S, w1, w2, gx, hdx,
                                           fbuf, xt, ft, buf, etab, stab, slide_c, jac)
                    t_after = t + dtc
                    # Q is first order in hdot; the accumulation point lies on the sticking
                    # manifold {h = 0, hdot = 0} by definition, so we project onto it
                    _project_stick(ev, p, k, mode, nm, t_after, y, n, hdx, w2, buf)
                    log_kind = K_CHATTER
                    dkind = STICK
                    didx = j
                    stats[4] += 1
                    chain_event = -1
                else:
                    ev(W_G, j, t, xs, p, ytmp)
                    for i in range(n):
                        y[i] = ytmp[i]
                    log_kind = K_IMPACT
                    if etab[j, 3] >= 0:
                        mode = etab[j, 3]
            else:
                ev(W_G, j, t, xs, p, ytmp)
                for i in range(n):
                    y[i] = ytmp[i]
                log_kind = K_TRANSITION
                if etab[j, 3] >= 0:
                    mode = etab[j, 3]
                chain_event = -1
            if nvar and log_kind != K_CHATTER:
                _event_saltation(ev, p, j, k, old_mode, mode, nm, t, xs, y, n, S, gx, hdx, buf,
                                 fbuf, w1, w2, etab, stab, slide_c, old_kind, old_idx, ytmp)
        elif act == ACT_RELEASE:
            dkind = REGULAR
            didx = -1
            log_kind = K_RELEASE
            if nvar:
                for i in range(n):
                    for c in range(n):
                        S[i, c] = 1.0 if i == c else 0.0
        elif act == ACT_SWITCH:
            s = wref[w]
            k = stab[s, 0]
            a_m = stab[s, 1]
            b_m = stab[s, 2]
            ev(W_HD, k * nm + a_m, t, y, p, buf)
            sa = buf[0]
            ev(W_HD, k * nm + b_m, t, y, p, buf)
            sb = buf[0]
            if sa < 0.0 and sb > 0.0:
                dkind = SLIDE
                didx = s
                mode = a_m
                log_kind = K_SLIDE_START
            else:
                log_kind = K_CROSSING
                mode = b_m if old_mode == a_m else a_m
            if nvar:
                _switch_saltation(ev, p, dkind, didx, old_mode, mode, nm, k, t, y, n, S, hdx,
                                  buf, fbuf, w1, w2, gx, etab, stab, slide_c)
        elif act == ACT_EXIT_ABOVE or act == ACT_EXIT_BELOW:
            s = wref[w]
            mode = stab[s, 1] if act == ACT_EXIT_ABOVE else stab[s, 2]
            dkind = REGULAR
            didx = -1
            log_kind = K_SLIDE_END
            if nvar:
                for i in range(n):
                    for c in range(n):
                        S[i, c] = 1.0 if i == c else 0.0
        else:
            status = ST_INTERSECTION
            log_kind = -1

        if log_kind >= 0:
            if nvar:
                # Phi+ = S Phi-
                for i in range(n):
                    for c in range(n):
                        Phi[i, c] = y[n + i * n + c]
                for i in range(n):
                    for c in range(n):
                        acc = 0.0
                        for m in range(n):
                            acc += S[i, m] * Phi[m, c]
                        y[n + i * n + c] = acc
            ev_t = _grow1(ev_t, n_ev + 1)
            ev_t2 = _grow1(ev_t2, n_ev + 1)
            ev_info = _grow2(ev_info, n_ev + 1)
            ev_xb = _grow2(ev_xb, n_ev + 1)
            ev_xa = _grow2(ev_xa, n_ev + 1)
            ev_t[n_ev] = t
            ev_t2[n_ev] = t_after
            ev_info[n_ev, 0] = log_kind
            ev_info[n_ev, 1] = log_ref
            ev_info[n_ev, 2] = old_kind
            ev_info[n_ev, 3] = old_idx
            ev_info[n_ev, 4] = old_mode
            ev_info[n_ev, 5] = dkind
            ev_info[n_ev, 6] = didx
            ev_info[n_ev, 7] = mode
            ev_xb[n_ev, :] = xs
            ev_xa[n_ev, :] = y
            n_ev += 1
            stats[3] += 1
            # jump (or chatter gap) interval to the post-event node
            nodes_t[n_nodes] = t_after
            nodes_y[n_nodes, :] = y
            nodes_s[n_nodes, 0] = dkind
            nodes_s[n_nodes, 1] = didx
            nodes_s[n_nodes, 2] = mode
            ikind[n_nodes - 1] = 2 if log_kind == K_CHATTER else 1
            dense[n_nodes - 1, :, :] = 0.0
            n_nodes += 1
            if log_kind == K_CHATTER:
                # the accumulation is followed by sticking: log it as its own event
                ev_t = _grow1(ev_t, n_ev + 1)
                ev_t2 = _grow1(ev_t2, n_ev + 1)
                ev_info = _grow2(ev_info, n_ev + 1)
                ev_xb = _grow2(ev_xb, n_ev + 1)
                ev_xa = _grow2(ev_xa, n_ev + 1)
                ev_t[n_ev] = t_after
                ev_t2[n_ev] = t_after
                ev_info[n_ev, 0] = K_STICK
                ev_info[n_ev, 1] = log_ref
                ev_info[n_ev, 2] = old_kind
                ev_info[n_ev, 3] = old_idx
                ev_info[n_ev, 4] = old_mode
                ev_info[n_ev, 5] = dkind
                ev_info[n_ev, 6] = didx
                ev_info[n_ev, 7] = mode
                ev_xb[n_ev, :] = y
                ev_xa[n_ev, :] = y
                n_ev += 1
            t = t_after
        if status != ST_SUCCESS:
            break
        if act == ACT_EVENT and etab[wref[w], 4] == 1:
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
        # re-trigger guard: the side of the function after the event
        last_depth = 0.0
        last_type = wtype[w]
        last_idx = widx[w]
        last_mode = wmode[w]
        last_t = t
        if act == ACT_EVENT:
            # after a reset the surface value is ~0; its new side is given by hdot after reset
            if dkind == REGULAR:
                ev(W_HD, widx[w] * nm + mode, t, y, p, buf)
                last_sign = 1.0 if buf[0] > 0.0 else -1.0
                if buf[0] == 0.0:
                    last_sign = 1.0 if etab[wref[w], 1] <= 0 else -1.0
            else:
                last_sign = 1.0
        elif act == ACT_RELEASE:
            last_sign = 1.0
            last_type = WF_SURFACE
            last_idx = etab[wref[w], 0]
        elif act == ACT_SWITCH:
            if dkind == SLIDE:
                last_type = -1
            else:
                last_sign = 1.0 if mode == stab[wref[w], 1] else -1.0
        else:
            # sliding exit: we leave into the mode's side of the surface
            last_type = WF_SURFACE
            last_idx = stab[wref[w], 0]
            last_sign = 1.0 if act == ACT_EXIT_ABOVE else -1.0
        restart = True

    # final node (when only events are saved, the end state still is)
    if nodes_t[n_nodes - 1] != t:
        nodes_t = _grow1(nodes_t, n_nodes + 1)
        nodes_y = _grow2(nodes_y, n_nodes + 1)
        nodes_s = _grow2(nodes_s, n_nodes + 1)
        dense = _grow3(dense, n_nodes + 1)
        ikind = _grow1(ikind, n_nodes + 1)
        ikind[n_nodes - 1] = 1
        dense[n_nodes - 1, :, :] = 0.0
        nodes_t[n_nodes] = t
        nodes_y[n_nodes, :] = y
        nodes_s[n_nodes, 0] = dkind
        nodes_s[n_nodes, 1] = didx
        nodes_s[n_nodes, 2] = mode
        n_nodes += 1
    return (status, t, y.copy(), np.array([dkind, didx, mode], dtype=np.int64),
            nodes_t[:n_nodes].copy(), nodes_y[:n_nodes].copy(), nodes_s[:n_nodes].copy(),
            dense[: max(n_nodes - 1, 0)].copy(), ikind[: max(n_nodes - 1, 0)].copy(),
            ev_t[:n_ev].copy(), ev_t2[:n_ev].copy(), ev_info[:n_ev].copy(),
            ev_xb[:n_ev].copy(), ev_xa[:n_ev].copy(), stats)
