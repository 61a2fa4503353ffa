"""The vector field of every discrete state: a mode, sticking on a surface (constrained motion),
Filippov sliding (convex combination or Utkin's equivalent control); the discrete state
resolved against the switching surfaces; the right-hand side with the variational equations.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...model.codegen import (W_F, W_FU, W_FX, W_GX, W_H, W_HD, W_HDT, W_HDU, W_HDUD, W_HDX, W_HT,
                              W_HX)
from .._codes import REGULAR, SLIDE, SLIDE_UTKIN, STICK, SW_FILIPPOV
from ._base import EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE, _EPS, _FD_STEP, _dot, _hot, _hot_inline

# --------------------------------------------------------------------------------------
# vector fields of the discrete states
# --------------------------------------------------------------------------------------

@_hot
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


@_hot
def _field(ev, p, dkind, didx, mode, nm, t, x, n, out, etab, stab, slide_c, w1, w2, gx, hdx):
    """Vector field of the current discrete state at (t, x) into out[:n]."""
    if dkind == REGULAR:
        ev(W_F, mode, t, x, p, out)
        return
    if dkind == STICK:
        # constrained motion f - lambda W with lambda from hddot = 0 (slides):
        # lambda = (hdot_t + hdot_x f) / (hdot_x W)
        j = didx
        k = etab[j].surface
        ev(W_F, mode, t, x, p, out)
        hw = _impact_direction(ev, p, j, k, mode, nm, t, x, n, w1, gx, hdx)
        ev(W_HDT, k * nm + mode, t, x, p, w2)
        acc = w2[0] + _dot(hdx, out, n)
        lam = acc / hw if hw != 0.0 else 0.0
        for i in range(n):
            out[i] -= lam * w1[i]
        return
    # SLIDE on switch didx: Filippov's convex combination (thesis eq. 2.7-2.8)
    #     f12 = (1 - alpha) f_above + alpha f_below,
    #     alpha = (h_t + h_x f_above) / (h_x (f_above - f_below)),
    # (eq. 2.8 with the h_t of a time-dependent surface) or Utkin's equivalent control
    # f(t, x, u_eq) with h_t + h_x f(t, x, u_eq) = 0 (slides, "Simulation: Filippov systems"),
    # plus the stabilising term of the slides, -C h h_x^T, scaled by 1/|h_x|^2 so that the
    # drift obeys hdot = -C h whatever the scale of h (C is a rate, 1/time; default 0: the
    # kernel projects each accepted sliding step back onto h = 0 instead)
    s = didx
    k = stab[s].surface
    ev(W_HX, k, t, x, p, hdx)
    ev(W_H, k, t, x, p, out)
    hval = out[0]
    if stab[s].sliding == SLIDE_UTKIN:
        u = _equivalent_control(ev, p, s, t, x, out)
        out[0] = u
        ev(W_FU, s, t, x, p, out)
    else:
        ev(W_F, stab[s].above, t, x, p, w1)
        ev(W_F, stab[s].below, t, x, p, w2)
        ev(W_HT, k, t, x, p, out)
        ha = out[0] + _dot(hdx, w1, n)
        den = _dot(hdx, w1, n) - _dot(hdx, w2, n)
        alpha = ha / den if den != 0.0 else 0.5
        for i in range(n):
            out[i] = (1.0 - alpha) * w1[i] + alpha * w2[i]
    # h_t + h_x f12 = 0 holds by construction up to round-off; remove that round-off along h_x
    # (a linear surface, e.g. v = V, is then conserved exactly by the Runge-Kutta stages even
    # over very long sliding steps)
    nrm2 = _dot(hdx, hdx, n)
    if nrm2 > 0.0:
        ev(W_HT, k, t, x, p, w2)
        res = (w2[0] + _dot(hdx, out, n)) / nrm2
        for i in range(n):
            out[i] -= res * hdx[i]
    if slide_c != 0.0 and hval != 0.0:
        nrm2 = _dot(hdx, hdx, n)
        if nrm2 > 0.0:
            g = slide_c * hval / nrm2
            for i in range(n):
                out[i] -= g * hdx[i]


@_hot
def _equivalent_control(ev, p, s, t, x, buf):
    """Utkin's equivalent control on switch ``s``: the root ``u`` of
    ``g(u) = h_t + h_x f(t, x, u)`` in ``[-1, 1]`` (``u = +1`` is the field above the surface,
    ``-1`` below), by Newton's method safeguarded by bisection on the bracket
    ``g(-1) > 0 > g(+1)`` that holds while sliding. The first guess is the root of the line
    through ``g(-1)`` and ``g(+1)``: exact (the convex method) when ``f`` is affine in ``u``.
    Outside the sliding region (stage values of a step that overshoots an exit) plain Newton
    continues the root smoothly; ``buf[0]`` is overwritten."""
    buf[0] = 1.0
    ev(W_HDU, s, t, x, p, buf)
    ga = buf[0]
    buf[0] = -1.0
    ev(W_HDU, s, t, x, p, buf)
    gb = buf[0]
    u = (ga + gb) / (gb - ga) if gb != ga else 0.0
    lo = -1.0
    hi = 1.0
    bracket = ga < 0.0 < gb
    if bracket:
        u = min(max(u, lo), hi)
    for it in range(60):
        buf[0] = u
        ev(W_HDU, s, t, x, p, buf)
        g = buf[0]
        if g == 0.0:
            break
        if bracket:
            if g > 0.0:
                lo = u
            else:
                hi = u
        buf[0] = u
        ev(W_HDUD, s, t, x, p, buf)
        d = buf[0]
        un = u - g / d if d != 0.0 else np.nan
        if bracket and not (lo < un < hi):
            un = 0.5 * (lo + hi)
        if not np.isfinite(un):
            break
        if abs(un - u) <= 4.0 * _EPS * max(1.0, abs(u)):
            u = un
            break
        u = un
    return u


@_hot
def _project_surface(ev, p, k, t, y, n, hdx, buf):
    """One Newton step onto ``h = 0`` along ``h_x``: at sliding entry the state is a few ulps
    off the surface; this removes them, so a linear ``h`` is then held to round-off."""
    ev(W_H, k, t, y, p, buf)
    hv = buf[0]
    ev(W_HX, k, t, y, p, hdx)
    nrm2 = _dot(hdx, hdx, n)
    if nrm2 > 0.0 and hv != 0.0:
        for i in range(n):
            y[i] -= hv * hdx[i] / nrm2


@_hot
def _partner(stab, k, m):
    """The mode across surface ``k`` from mode ``m`` (-1 if no switch joins them)."""
    for s in range(stab.shape[0]):
        if stab[s].surface == k:
            if stab[s].above == m:
                return stab[s].below
            if stab[s].below == m:
                return stab[s].above
    return -1


@_hot
def _find_switch(stab, k, a, b):
    """The switch on surface ``k`` with mode ``a`` above and ``b`` below (-1 if none)."""
    for s in range(stab.shape[0]):
        if stab[s].surface == k and stab[s].above == a and stab[s].below == b:
            return s
    return -1


@_hot
def _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx):
    """h of surface ``k`` at (t, y) and the round-off band around zero it is judged with
    (64 ulps of the state and gradient scales)."""
    ev(W_H, k, t, y, p, buf)
    hv = buf[0]
    ev(W_HX, k, t, y, p, hdx)
    gmax = 1.0
    for i in range(n):
        gmax = max(gmax, abs(hdx[i]))
    return hv, 64.0 * _EPS * xmax * gmax


@_hot_inline
def _start_on_surface(ev, p, k, dkind, mode, nm, t, y, n, v0, r0, buf, hdx):
    """``(h, hdot)`` of surface ``k`` at the start of the first step after a restart, with
    round-off taken as zero: a surface within its band (:func:`_surface_offset`) is ON it,
    whatever the sign of that round-off (a slide exit or release that ends on a wall, a state
    given on a constraint). Taken as exactly zero, the crossing test fires at ``t`` if the
    flow goes into the event direction and never if it leaves. A rate within its own band
    (:func:`_rate_band`) is tangency, zero too: a start tangent to the surface and curving
    into it fires at ``t``, not where ``-c (t - t0)^2`` outgrows the round-off (~sqrt(eps)
    later)."""
    xmax = 1.0
    for i in range(n):
        xmax = max(xmax, abs(y[i]))
    hv, tolb = _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx)
    if abs(v0) <= tolb:
        v0 = 0.0
        if dkind == REGULAR and abs(r0) <= _rate_band(ev, p, k, mode, nm, t, y, n, hdx):
            r0 = 0.0
    return v0, r0


@_hot
def _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx):
    """The discrete state that the switches impose at ``(t, y)`` starting from ``mode``.

    Off every surface the mode must be the one on the side of ``h`` (a model written with
    ``sign``, or a state given or reset by the user, may name a mode on the other side).
    On a Filippov surface (``|h|`` within round-off of the state) the signs of
    ``hdot`` of the two modes decide, as at an arrival (thesis eq. 2.6-2.8): both pointing
    into the surface, sliding (the state is projected onto it); both pointing to one side,
    that side's mode. Returns ``(dkind, didx, mode)``.
    """
    n_sw = stab.shape[0]
    xmax = 1.0
    for i in range(n):
        xmax = max(xmax, abs(y[i]))
    # 1. the side of every surface the state is off
    for sweep in range(n_sw + 1):
        changed = False
        for s in range(n_sw):
            a = stab[s].above
            b = stab[s].below
            if mode != a and mode != b:
                continue
            hv, tol = _surface_offset(ev, p, stab[s].surface, t, y, n, xmax, buf, hdx)
            new = mode
            if hv > tol:
                new = a
            elif hv < -tol:
                new = b
            if new != mode:
                mode = new
                changed = True
        if not changed:
            break
    # 2. on a surface: slide, or take the side the flow leaves to
    for s in range(n_sw):
        a = stab[s].above
        b = stab[s].below
        if mode != a and mode != b:
            continue
        k = stab[s].surface
        hv, tol = _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx)
        if abs(hv) > tol:
            continue
        ev(W_HD, k * nm + a, t, y, p, buf)
        sa = buf[0]
        ev(W_HD, k * nm + b, t, y, p, buf)
        sb = buf[0]
        filippov = stab[s].kind == SW_FILIPPOV
        if filippov and sa < 0.0 and sb > 0.0:
            _project_surface(ev, p, k, t, y, n, hdx, buf)
            return SLIDE, s, a
        if sa >= 0.0 and sb > 0.0 or sa > 0.0 and sb >= 0.0:
            mode = a
        elif sa <= 0.0 and sb < 0.0 or sa < 0.0 and sb <= 0.0:
            mode = b
    return REGULAR, -1, mode


@_hot
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


@_hot
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
        # step ~ eps^(1/3): truncation (dx^2) and rounding (eps/dx) errors balance near 1e-11
        dx = _FD_STEP * max(1.0, abs(y[c]))
        xt[c] = y[c] + dx
        _field(ev, p, dkind, didx, mode, nm, t, xt, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
        for i in range(n):
            jac[i * n + c] = ft[i]
        xt[c] = y[c] - dx
        _field(ev, p, dkind, didx, mode, nm, t, xt, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
        for i in range(n):
            jac[i * n + c] = (jac[i * n + c] - ft[i]) / (2.0 * dx)


@_hot
def _rate_band(ev, p, k, mode, nm, t, x, n, hdx):
    """The round-off band around zero of ``hdot`` of surface ``k`` in ``mode`` at (t, x): 64
    ulps of the state and gradient scales, as :func:`_surface_offset` for ``h``. A normal
    velocity within it is tangency; its sign is noise (after a plastic impact on an oblique
    or curved surface ``hdot`` is +-1e-16)."""
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    xmax = 1.0
    gmax = 1.0
    for i in range(n):
        xmax = max(xmax, abs(x[i]))
        gmax = max(gmax, abs(hdx[i]))
    return 64.0 * _EPS * xmax * gmax


def _state_field_signature():
    from numba import types as nt

    from ...model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    return nt.void(EVALUATE_TYPE, f1, nt.int64, nt.int64, nt.int64, nt.int64, nt.float64, f1,
                   EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE, nt.float64, f1)


@njit(_state_field_signature(), cache=True)
def state_field(ev, p, dkind, didx, mode, nm, t, x, etab, stab, slide_c, out):
    """The vector field of a discrete state (``dkind``: REGULAR, STICK, SLIDE; ``didx``; mode)
    at ``(t, x)`` into ``out``: the same function the kernel integrates, for Python callers
    (Poincaré-map projections, shooting, projected saltation matrices)."""
    n = x.shape[0]
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(n * n)
    hdx = np.zeros(n)
    _field(ev, p, dkind, didx, mode, nm, t, x, n, out, etab, stab, slide_c, w1, w2, gx, hdx)
