"""The vector field of every discrete state: a mode, sticking on a surface (constrained motion),
Filippov sliding (convex combination or Utkin's equivalent control), sliding on the
intersection of several switching surfaces (the multilinear extension); the discrete state
resolved against the switching surfaces; the right-hand side with the variational equations.

Sliding on an intersection
--------------------------
On the intersection of ``k >= 2`` Filippov surfaces Filippov's convex set holds the ``2^k``
fields of the corner modes (the product variants that differ only in the sides of the ``k``
surfaces) and a tangent convex combination is not unique. The kernel takes the multilinear
(for ``k = 2`` bilinear) extension of L. Dieci and L. Lopez, "Sliding motion on discontinuity
surfaces of high co-dimension. A construction for selecting a Filippov vector field",
Numer. Math. 117 (2011) 779-811:

    f = sum_c prod_i w_i(c) f_c,   w_i(c) = lambda_i (c below surface i), 1 - lambda_i (above),

with ``lambda`` in ``[0, 1]^k`` the root of the ``k`` tangency conditions
``h_i,t + h_i,x f = 0`` (:func:`_solve_lambda`). Why this rule: a field that is affine in each
switching term (dry friction written with ``sign``, relays) is multilinear in the signs, and
the corner fields are its values at ``u_i = +-1``; the multilinear extension at
``lambda`` IS that field at ``u_i = 1 - 2 lambda_i``. So it is Utkin's equivalent control
with a vector ``u``, and in mechanics the stuck contacts' forces solved jointly from their
stick conditions (each within its static bound while ``lambda_i`` is in ``[0, 1]``); for
contacts that do not interact the conditions decouple and each contact slides exactly as it
does alone. For ``k = 1`` it is the convex combination (thesis eq. 2.8), which the kernel keeps
in its own code path (``SLIDE``).

Where the corners are the variants of one sign family whose field is multilinear in its sides
on the surfaces (:class:`pwsdyn.model.elements.SignFamily`, ``multilinear``), that field IS
the multilinear extension: the kernel then solves the tangency conditions for the sides
``u_i = 1 - 2 lambda_i`` by Newton's method on the family's field and its side derivatives
(one evaluation of each per iteration, one or two iterations for friction) instead of
evaluating the ``2^k`` corner fields (:func:`_lambda_family`); where that Newton iteration
fails it falls back to the corners. Deciding which surface to leave (:func:`_settle_multi`)
looks at the corners either way.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...model.codegen import (W_F, W_FAMILY, W_FS, W_FSD, W_FU, W_FX, W_GX, W_H, W_HD, W_HDT,
                              W_HDU, W_HDUD, W_HDX, W_HT, W_HX)
from .._codes import (FAMILY_MAX, MULTI_MAX, REGULAR, SLIDE, SLIDE_MULTI, SLIDE_UTKIN, STICK,
                      SW_FILIPPOV)
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
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    return _impact_direction_hdx(ev, p, j, t, x, n, W, gx, hdx)


@_hot
def _impact_direction_hdx(ev, p, j, t, x, n, W, gx, hdx):
    """:func:`_impact_direction` where ``hdx`` already holds ``hdot_x`` at ``(t, x)``."""
    ev(W_GX, j, t, x, p, gx)
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
    if dkind == SLIDE_MULTI:
        # sliding on the intersection of the surfaces of the bit mask didx, mode the corner
        # above all of them: the multilinear extension (module docstring); gx is its work
        # vector (the kernel sizes it by multi_work_size)
        _multi_field(ev, p, didx, mode, nm, t, x, n, out, stab, slide_c, w1, gx)
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


@_hot_inline
def _block_row(stab, b0, m):
    """The record of the block starting at record ``b0`` (a sign family's switches on one
    surface: ``SWITCH_TABLE``) that mode ``m`` is above or below, or -1 where ``m`` is not a
    variant of the family. Its index ``c`` in the family with bit ``bit`` cleared is the
    variant above the switch; the record is that index's rank among those with the bit
    clear: ``c`` with the bit removed."""
    c = m - stab[b0].first
    if c < 0 or c >= 2 * (stab[b0].block_end - b0):
        return -1
    bit = stab[b0].bit
    a = c & ~(1 << bit)
    return b0 + (((a >> (bit + 1)) << bit) | (a & ((1 << bit) - 1)))


@_hot
def _next_touching(stab, s, m):
    """The first switch at or after record ``s`` that has mode ``m`` above or below it, in
    table order (the table's length where none): a search of the table that passes over a
    sign family's block at once, computing the one record of it that touches ``m``
    (:func:`_block_row`)."""
    n_sw = stab.shape[0]
    while s < n_sw:
        b0 = stab[s].block
        if b0 >= 0:
            r = _block_row(stab, b0, m)
            if r >= s:
                return r
            s = stab[s].block_end
            continue
        if stab[s].above == m or stab[s].below == m:
            return s
        s += 1
    return n_sw


@_hot
def _switch_on(stab, k, m):
    """The first switch on surface ``k`` that has mode ``m`` above or below it (-1 if
    none)."""
    n_sw = stab.shape[0]
    s = _next_touching(stab, 0, m)
    while s < n_sw:
        if stab[s].surface == k:
            return s
        s = _next_touching(stab, s + 1, m)
    return -1


@_hot
def _partner(stab, k, m):
    """The mode across surface ``k`` from mode ``m`` (-1 if no switch joins them): of the
    first switch on ``k`` that touches ``m``."""
    s = _switch_on(stab, k, m)
    if s < 0:
        return -1
    return stab[s].below if stab[s].above == m else stab[s].above


@_hot
def _find_switch(stab, k, a, b):
    """The switch on surface ``k`` with mode ``a`` above and ``b`` below (-1 if none)."""
    n_sw = stab.shape[0]
    s = _next_touching(stab, 0, a)
    while s < n_sw:
        if stab[s].surface == k and stab[s].above == a and stab[s].below == b:
            return s
        s = _next_touching(stab, s + 1, a)
    return -1


@_hot
def _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx):
    """h of surface ``k`` at (t, y) and the round-off band around zero it is judged with
    (64 ulps of the state and gradient scales)."""
    ev(W_H, k, t, y, p, buf)
    return buf[0], _surface_band(ev, p, k, t, y, n, xmax, hdx)


@_hot
def _surface_band(ev, p, k, t, y, n, xmax, hdx):
    """The round-off band of :func:`_surface_offset` alone (``h`` itself known)."""
    ev(W_HX, k, t, y, p, hdx)
    gmax = 1.0
    for i in range(n):
        gmax = max(gmax, abs(hdx[i]))
    return 64.0 * _EPS * xmax * gmax


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
    tolb = _surface_band(ev, p, k, t, y, n, xmax, hdx)
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
    # 1. the side of every surface the state is off (the switches touching the mode, in
    # table order; after a change those touching the new one)
    for sweep in range(n_sw + 1):
        changed = False
        s = _next_touching(stab, 0, mode)
        while s < n_sw:
            a = stab[s].above
            b = stab[s].below
            hv, tol = _surface_offset(ev, p, stab[s].surface, t, y, n, xmax, buf, hdx)
            new = mode
            if hv > tol:
                new = a
            elif hv < -tol:
                new = b
            if new != mode:
                mode = new
                changed = True
            s = _next_touching(stab, s + 1, mode)
        if not changed:
            break
    # 2. on a surface: slide, or take the side the flow leaves to
    s = _next_touching(stab, 0, mode)
    while s < n_sw:
        a = stab[s].above
        b = stab[s].below
        k = stab[s].surface
        hv, tol = _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx)
        if abs(hv) <= tol:
            ev(W_HD, k * nm + a, t, y, p, buf)
            sa = buf[0]
            ev(W_HD, k * nm + b, t, y, p, buf)
            sb = buf[0]
            filippov = stab[s].kind == SW_FILIPPOV
            if filippov and sa < 0.0 and sb > 0.0:
                # on further Filippov surfaces of the corner modes too (a start on an
                # intersection): sliding on the intersection or on some of its surfaces, as
                # the multilinear weights decide (_settle_multi; buf, at least
                # multi_work_size long, is its work vector)
                mask = _on_surfaces(ev, p, t, y, n, xmax, k, a, stab, buf, hdx)
                if mask != 0:
                    mask |= 1 << k
                    ref = _multi_reference(stab, mask, a)
                    if ref >= 0:
                        dk, di, dm = _settle_multi(ev, p, t, y, n, nm, mask, ref, stab, buf,
                                                   hdx, hdx, buf)
                        if dk >= 0:
                            return dk, di, dm
                _project_surface(ev, p, k, t, y, n, hdx, buf)
                return SLIDE, s, a
            if sa >= 0.0 and sb > 0.0 or sa > 0.0 and sb >= 0.0:
                mode = a
            elif sa <= 0.0 and sb < 0.0 or sa < 0.0 and sb <= 0.0:
                mode = b
        s = _next_touching(stab, s + 1, mode)
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


# --------------------------------------------------------------------------------------
# sliding on the intersection of several switching surfaces (multilinear extension)
# --------------------------------------------------------------------------------------

@_hot
def multi_work_size(n, stab):
    """Length of the work vector of :func:`_solve_lambda` for ``n`` states and the switch
    table ``stab`` (the kernel's ``gx`` and ``buf`` are at least this long;
    :func:`_multi_offsets`): its corner region holds the ``2**k`` corners of the largest
    intersection the table allows (:func:`_multi_kmax`), so a model without switches does
    not carry room for ``2**MULTI_MAX`` of them; the last :func:`lambda_cache_size` entries
    are the cache of the weights of the watch functions (:func:`_cached_lambda`)."""
    k = _multi_kmax(stab)
    return _multi_offsets(n)[8] + ((1 + n + k) << k) + 4 + lambda_cache_size(n)


#: Entries of the cache of the weights of sliding on an intersection (:func:`_cached_lambda`):
#: one per distinct sample of a step (start, midpoint, end, the central differences of the
#: slopes at the ends), with room to spare.
_LAM_SLOTS = 8


@_hot
def lambda_cache_size(n):
    """Length of the cache of :func:`_cached_lambda` at the end of the work vector ``buf``: a
    counter (the entry to write next), then ``_LAM_SLOTS`` entries of ``[valid, t, mask,
    x (n), lambda (MULTI_MAX)]``."""
    return 1 + _LAM_SLOTS * (3 + n + MULTI_MAX)


@_hot
def _clear_lambda_cache(buf, n):
    """Empty the cache (when the watch list is rebuilt: a new discrete state, new corners)."""
    o_c = buf.shape[0] - lambda_cache_size(n)
    buf[o_c] = 0.0
    for j in range(_LAM_SLOTS):
        buf[o_c + 1 + j * (3 + n + MULTI_MAX)] = 0.0


@_hot
def _cached_lambda(ev, p, mask, t, x, n, fbuf, buf):
    """The weights of sliding on the surfaces of ``mask`` at ``(t, x)`` (:func:`_lambda_core`
    with the corners the kernel keeps in ``buf``), into ``buf``'s weight region
    (:func:`_multi_offsets`). Each of the ``k`` watch functions of the state (one per
    surface, ``min(lambda_i, 1 - lambda_i)``) samples the step at the same times and states,
    so the weights of one sample are solved once, not ``k`` times: a solve at ``(t, x)`` equal
    to a cached one in every bit is copied from the cache (the same arithmetic, the same
    numbers). Returns ``k``, or -1 where the weights have no solution (not cached)."""
    o_lam = _multi_offsets(n)[2]
    o_c = buf.shape[0] - lambda_cache_size(n)
    width = 3 + n + MULTI_MAX
    fm = float(mask)
    for j in range(_LAM_SLOTS):
        o = o_c + 1 + j * width
        if buf[o] == 1.0 and buf[o + 1] == t and buf[o + 2] == fm:
            same = True
            for i in range(n):
                if buf[o + 3 + i] != x[i]:
                    same = False
                    break
            if same:
                k = _multi_count(mask)
                for i in range(k):
                    buf[o_lam + i] = buf[o + 3 + n + i]
                return k
    k = _lambda_core(ev, p, mask, t, x, n, fbuf, buf)
    if k < 0 or mask >= (1 << 52):
        # (a mask beyond 2**52 would not survive the cache's float)
        return k
    j = int(buf[o_c])
    buf[o_c] = float((j + 1) % _LAM_SLOTS)
    o = o_c + 1 + j * width
    buf[o] = 1.0
    buf[o + 1] = t
    buf[o + 2] = fm
    for i in range(n):
        buf[o + 3 + i] = x[i]
    for i in range(k):
        buf[o + 3 + n + i] = buf[o_lam + i]
    return k


@_hot
def _multi_kmax(stab):
    """The most surfaces an intersection of this switch table can have: its distinct
    surfaces (every mask the kernel slides on is made of them), at most ``MULTI_MAX``."""
    mask = 0
    for s in range(stab.shape[0]):
        ks = stab[s].surface
        if ks < 63:
            mask |= 1 << ks
    return min(_multi_count(mask), MULTI_MAX)


@_hot
def _corner_offsets(n, k):
    """Offsets into the work vector of the corner fields (``2**k`` rows of ``n``) and the
    tangency values ``a_ic`` (``k`` rows of ``2**k``) of an intersection of ``k`` surfaces:
    after its ``2**k`` corner modes, at the end of the vector (:func:`_multi_offsets`)."""
    o_m = _multi_offsets(n)[8]
    o_fc = o_m + (1 << k)
    return o_fc, o_fc + (n << k)


@_hot
def _multi_count(mask):
    """The number of surfaces in the bit mask ``mask``."""
    c = 0
    m = mask
    while m != 0:
        c += m & 1
        m >>= 1
    return c


@_hot
def _multi_surface(mask, i):
    """The ``i``-th surface (in increasing index) of the bit mask ``mask``."""
    c = 0
    k = 0
    m = mask
    while m != 0:
        if m & 1:
            if c == i:
                return k
            c += 1
        m >>= 1
        k += 1
    return -1


@_hot
def _multi_corners(stab, mask, ref, out, o):
    """The ``2**k`` corner modes of sliding on the surfaces of ``mask`` with reference ``ref``
    (the corner above all of them) into ``out[o:o + 2**k]``: corner ``c`` lies below the
    ``i``-th surface where bit ``i`` of ``c`` is set, and is reached from ``ref`` across one
    surface at a time, in increasing order (the product variants are joined pairwise:
    :mod:`pwsdyn.model.discontinuities`); -1 where a switch is missing. Each corner is one
    switch-table search from the corner without its highest bit."""
    out[o] = ref
    for c in range(1, 1 << _multi_count(mask)):
        i = 0
        while c >> (i + 1):
            i += 1
        prev = int(out[o + (c ^ (1 << i))])
        out[o + c] = -1 if prev < 0 else _partner(stab, _multi_surface(mask, i), prev)


@_hot
def _small_solve(a, oa, b, ob, k):
    """Solve the ``k x k`` system stored row-major in ``a[oa:]`` for the right-hand side
    ``b[ob:ob + k]`` in place (Gaussian elimination with partial pivoting; ``k <=
    MULTI_MAX``). Returns False where it is singular."""
    for c in range(k):
        piv = c
        for r in range(c + 1, k):
            if abs(a[oa + r * k + c]) > abs(a[oa + piv * k + c]):
                piv = r
        if a[oa + piv * k + c] == 0.0 or not np.isfinite(a[oa + piv * k + c]):
            return False
        if piv != c:
            for q in range(k):
                tmp = a[oa + c * k + q]
                a[oa + c * k + q] = a[oa + piv * k + q]
                a[oa + piv * k + q] = tmp
            tmp = b[ob + c]
            b[ob + c] = b[ob + piv]
            b[ob + piv] = tmp
        for r in range(c + 1, k):
            fac = a[oa + r * k + c] / a[oa + c * k + c]
            for q in range(c, k):
                a[oa + r * k + q] -= fac * a[oa + c * k + q]
            b[ob + r] -= fac * b[ob + c]
    for c in range(k - 1, -1, -1):
        acc = b[ob + c]
        for q in range(c + 1, k):
            acc -= a[oa + c * k + q] * b[ob + q]
        b[ob + c] = acc / a[oa + c * k + c]
    return True


@_hot
def _multi_weight(c, lam, ol, k, skip):
    """``prod_i w_i(c)`` of corner ``c`` (``lambda_i`` below surface ``i``, ``1 - lambda_i``
    above), leaving out factor ``skip`` (-1: none)."""
    w = 1.0
    for i in range(k):
        if i == skip:
            continue
        w *= lam[ol + i] if (c >> i) & 1 else 1.0 - lam[ol + i]
    return w


@_hot
def _solve_lambda(ev, p, mask, ref, nm, t, x, n, stab, w1, work, family=True):
    """The weights ``lambda`` of the multilinear sliding field on the surfaces of ``mask``
    (Dieci & Lopez 2011; the module docstring) at ``(t, x)``, into ``work`` (layout:
    :func:`_multi_offsets`), with the corner fields, gradients and ``h_t`` the field needs.

    ``lambda`` solves ``g_i = h_i,t + h_i,x f(lambda) = sum_c W_c(lambda) a_ic = 0`` with
    ``a_ic = h_i,t + h_i,x f_c`` (the weights sum to one), by Newton's method with the exact
    Jacobian of the multilinear form, ``dg_i/dlambda_j = sum_c dW_c/dlambda_j a_ic``, from the
    centre ``lambda = 1/2`` (the same start at every call: the field is a function of
    ``(t, x)`` alone, so a step taken again gives the same numbers), at most 30 iterations;
    where that fails, from the further fixed starts of :func:`_lambda_core`.
    For a field affine in the signs of uncoupled contacts the system is triangular in each
    ``lambda_i`` and one or two iterations are exact. Returns ``k`` (the number of surfaces),
    or -1 where a corner mode is missing or Newton fails from every start (the rule has no
    solution there, e.g. tangency conditions with complex roots only). With ``family`` the
    weights of the corners of a multilinear sign family come from its field
    (:func:`_lambda_family`; the module docstring)."""
    if family:
        # the family needs the reference corner only: the other 2^k - 1, each a walk through
        # the switch table, are found only where it does not apply
        work[_multi_offsets(n)[8]] = ref
        k = _multi_count(mask)
        _multi_gradients(ev, p, mask, k, t, x, n, w1, work)
        if _lambda_family(ev, p, mask, k, t, x, n, work):
            work[_multi_offsets(n)[6]] = 1.0
            return k
    if not _multi_set_corners(stab, mask, ref, n, work):
        return -1
    return _lambda_core(ev, p, mask, t, x, n, w1, work, False)


@_hot
def _multi_set_corners(stab, mask, ref, n, work):
    """The corner modes of sliding on ``mask`` with reference ``ref`` into ``work`` (read by
    :func:`_lambda_core`; the kernel sets them once per sliding state in its ``buf``, whose
    watch functions have no switch table). False if a corner is missing."""
    o_m = _multi_offsets(n)[8]
    _multi_corners(stab, mask, ref, work, o_m)
    for c in range(1 << _multi_count(mask)):
        if work[o_m + c] < 0.0:
            return False
    return True


@_hot
def _lambda_core(ev, p, mask, t, x, n, w1, work, family=True):
    """:func:`_solve_lambda` with the corner modes already in ``work``."""
    k = _multi_count(mask)
    nc = 1 << k
    o_hx, o_ht, o_lam, o_g, o_jac, o_dl, o_fi, o_fu, o_m = _multi_offsets(n)
    o_fc, o_a = _corner_offsets(n, k)
    _multi_gradients(ev, p, mask, k, t, x, n, w1, work)
    work[o_fi] = 0.0
    if family and _lambda_family(ev, p, mask, k, t, x, n, work):
        work[o_fi] = 1.0
        return k
    for c in range(nc):
        m = int(work[o_m + c])
        ev(W_F, m, t, x, p, w1)
        for q in range(n):
            work[o_fc + c * n + q] = w1[q]
        for i in range(k):
            acc = work[o_ht + i]
            for q in range(n):
                acc += work[o_hx + i * n + q] * w1[q]
            work[o_a + i * nc + c] = acc
    # from the centre; where Newton fails from there (a singular matrix: a condition whose
    # gradient vanishes at lambda = 1/2, as for x' = -sign(x) sign(y), or an iteration that
    # runs away or does not settle), from the points lambda_i = 1/4 or 3/4, in a fixed order
    # (the weights stay a function of (t, x) alone)
    for start in range(1 + nc):
        for i in range(k):
            work[o_lam + i] = 0.5 if start == 0 else (0.75 if ((start - 1) >> i) & 1 else 0.25)
        if _lambda_newton(work, k, nc, o_a, o_lam, o_g, o_jac):
            return k
    return -1


@_hot
def _multi_gradients(ev, p, mask, k, t, x, n, w1, work):
    """The gradients ``h_i,x`` and rates ``h_i,t`` of the surfaces of ``mask`` into
    ``work``."""
    o_hx, o_ht = _multi_offsets(n)[:2]
    for i in range(k):
        ks = _multi_surface(mask, i)
        ev(W_HX, ks, t, x, p, w1)
        for q in range(n):
            work[o_hx + i * n + q] = w1[q]
        ev(W_HT, ks, t, x, p, w1)
        work[o_ht + i] = w1[0]


@_hot
def _lambda_newton(work, k, nc, o_a, o_lam, o_g, o_jac):
    """Newton's method for the weights of :func:`_lambda_core` from the ``lambda`` in
    ``work``, at most 30 iterations. True where it converged (a step below 4 eps, or after
    the 30 iterations a residual ``max_i |g_i|`` within sqrt(eps) of the scale of the
    ``a_ic``: steps that stall at round-off of an ill-conditioned matrix); False where the
    matrix was singular, the iteration ran away or did not converge."""
    for it in range(30):
        for i in range(k):
            g = 0.0
            for c in range(nc):
                g += _multi_weight(c, work, o_lam, k, -1) * work[o_a + i * nc + c]
            work[o_g + i] = -g
            for j in range(k):
                d = 0.0
                for c in range(nc):
                    sgn = 1.0 if (c >> j) & 1 else -1.0
                    d += sgn * _multi_weight(c, work, o_lam, k, j) * work[o_a + i * nc + c]
                work[o_jac + i * k + j] = d
        if not _small_solve(work, o_jac, work, o_g, k):
            return False
        step = 0.0
        for i in range(k):
            work[o_lam + i] += work[o_g + i]
            step = max(step, abs(work[o_g + i]))
        if not step <= 1e30:
            return False
        if step <= 4.0 * _EPS:
            return True
    res = 0.0
    scale = 0.0
    for i in range(k):
        g = 0.0
        for c in range(nc):
            g += _multi_weight(c, work, o_lam, k, -1) * work[o_a + i * nc + c]
            scale = max(scale, abs(work[o_a + i * nc + c]))
        res = max(res, abs(g))
    return res <= 1.4901161193847656e-08 * scale


@_hot
def _lambda_family(ev, p, mask, k, t, x, n, work):
    """The weights of sliding on the surfaces of ``mask`` (``k`` of them) from the field of
    the sign family of the reference corner (``work``'s first corner mode), where it is
    multilinear and holds every surface of the mask: Newton's method for the sides ``u_S``
    of those surfaces (the other sides fixed at the reference's, +-1) on
    ``g_i(u) = h_i,t + h_i,x f(t, x, u) = 0`` with ``dg_i/du_j = h_i,x df/du_j``, from
    ``u_S = 0`` (``lambda = 1/2``, the same start at every call), at most 30 iterations;
    then ``lambda_i = (1 - u_i)/2``. The gradients and ``h_t`` are in ``work`` already.
    False where the corners are no such family or Newton does not converge (the caller sums
    the corners instead). The family's info, sides and side derivatives stay in ``work``
    (:func:`_multi_offsets`) for :func:`_multi_field`; entries ``0 .. n * FAMILY_MAX`` are
    the compiled model's scratch."""
    o_hx, o_ht, o_lam, o_g, o_jac, o_dl, o_fi, o_fu, o_m = _multi_offsets(n)
    o_sf = o_fi + 3                    # the family's surfaces
    o_pos = o_sf + FAMILY_MAX          # the side of each surface of the mask
    o_u = o_pos + MULTI_MAX            # the sides
    ref = int(work[o_m])
    ev(W_FAMILY, ref, t, x, p, work)
    kf = int(work[0])
    if kf == 0 or kf > FAMILY_MAX:
        return False
    first = int(work[1])
    for j in range(kf):
        work[o_sf + j] = work[2 + j]
    work[o_fi + 1] = kf
    work[o_fi + 2] = first
    c = ref - first
    for j in range(kf):
        work[o_u + j] = -1.0 if (c >> (kf - 1 - j)) & 1 else 1.0
    for i in range(k):
        ks = _multi_surface(mask, i)
        pos = -1
        for j in range(kf):
            if int(work[o_sf + j]) == ks:
                pos = j
        if pos < 0:
            return False
        work[o_pos + i] = pos
        work[o_u + pos] = 0.0
    for it in range(30):
        for j in range(kf):
            work[j] = work[o_u + j]
        ev(W_FSD, first, t, x, p, work)
        for q in range(n * kf):
            work[o_fu + q] = work[q]
        for j in range(kf):
            work[j] = work[o_u + j]
        ev(W_FS, first, t, x, p, work)
        for i in range(k):
            g = work[o_ht + i]
            for q in range(n):
                g += work[o_hx + i * n + q] * work[q]
            work[o_g + i] = -g
            for l in range(k):
                pos = int(work[o_pos + l])
                d = 0.0
                for q in range(n):
                    d += work[o_hx + i * n + q] * work[o_fu + q * kf + pos]
                work[o_jac + i * k + l] = d
        if not _small_solve(work, o_jac, work, o_g, k):
            return False
        step = 0.0
        for i in range(k):
            pos = int(work[o_pos + i])
            work[o_u + pos] += work[o_g + i]
            step = max(step, abs(work[o_g + i]))
        if not step <= 1e30:
            return False
        if step <= 8.0 * _EPS:
            for i in range(k):
                work[o_lam + i] = 0.5 * (1.0 - work[o_u + int(work[o_pos + i])])
            return True
    return False


@_hot
def _family_field(ev, p, t, x, n, out, work):
    """The field of the sign family at the sides :func:`_lambda_family` solved, into
    ``out``."""
    o_fi = _multi_offsets(n)[6]
    kf = int(work[o_fi + 1])
    o_u = o_fi + 3 + FAMILY_MAX + MULTI_MAX
    for j in range(kf):
        work[j] = work[o_u + j]
    ev(W_FS, int(work[o_fi + 2]), t, x, p, work)
    for q in range(n):
        out[q] = work[q]


@_hot
def _multi_offsets(n):
    """Offsets into the work vector of :func:`_solve_lambda`: gradients ``h_i,x`` (k rows of
    n), ``h_i,t``, ``lambda``, the Newton residual, its matrix, a spare vector, a sign
    family's info (:func:`_lambda_family`: a flag, its number of surfaces, first variant,
    surfaces, the sides of the mask's surfaces, the sides) and side derivatives, then the
    corner region, whose length depends on the number ``k`` of surfaces: the corner modes
    (``2**k``), the corner fields and the tangency values (:func:`_corner_offsets`), sized
    by :func:`multi_work_size`. Entries ``0 .. max(4, n * FAMILY_MAX)`` stay free for the
    outputs of the compiled model."""
    o_hx = max(4, n * FAMILY_MAX, FAMILY_MAX + 2)
    o_ht = o_hx + MULTI_MAX * n
    o_lam = o_ht + MULTI_MAX
    o_g = o_lam + MULTI_MAX
    o_jac = o_g + MULTI_MAX
    o_dl = o_jac + MULTI_MAX * MULTI_MAX
    o_fi = o_dl + 2 * MULTI_MAX
    o_fu = o_fi + 3 + 2 * FAMILY_MAX + MULTI_MAX
    o_m = o_fu + n * FAMILY_MAX
    return o_hx, o_ht, o_lam, o_g, o_jac, o_dl, o_fi, o_fu, o_m


@_hot
def _multi_field(ev, p, mask, ref, nm, t, x, n, out, stab, slide_c, w1, work):
    """The multilinear sliding field on the surfaces of ``mask`` (module docstring) into
    ``out``, its tangency round-off removed along the gradients (as the ``k = 1`` field does:
    ``h_i,t + h_i,x f = 0`` to round-off for every surface, so linear surfaces are conserved
    exactly by the Runge-Kutta stages), with the stabilising term ``-C h_i h_i,x / |h_i,x|^2``
    of each surface. NaN where the weights have no solution."""
    k = _solve_lambda(ev, p, mask, ref, nm, t, x, n, stab, w1, work)
    if k < 0:
        for q in range(n):
            out[q] = np.nan
        return
    nc = 1 << k
    o_hx, o_ht, o_lam, o_g, o_jac, o_dl, o_fi, o_fu, o_m = _multi_offsets(n)
    o_fc = _corner_offsets(n, k)[0]
    if work[o_fi] == 1.0:
        _family_field(ev, p, t, x, n, out, work)
    else:
        for q in range(n):
            out[q] = 0.0
        for c in range(nc):
            wc = _multi_weight(c, work, o_lam, k, -1)
            for q in range(n):
                out[q] += wc * work[o_fc + c * n + q]
    # remove the residual of the k tangency conditions along the gradients: the Gram system
    # (h_i,x . h_j,x) r = h_i,t + h_i,x f, then f -= sum_j r_j h_j,x
    for i in range(k):
        acc = work[o_ht + i]
        for q in range(n):
            acc += work[o_hx + i * n + q] * out[q]
        work[o_g + i] = acc
        for j in range(k):
            d = 0.0
            for q in range(n):
                d += work[o_hx + i * n + q] * work[o_hx + j * n + q]
            work[o_jac + i * k + j] = d
    if _small_solve(work, o_jac, work, o_g, k):
        for j in range(k):
            for q in range(n):
                out[q] -= work[o_g + j] * work[o_hx + j * n + q]
    if slide_c != 0.0:
        for i in range(k):
            ev(W_H, _multi_surface(mask, i), t, x, p, w1)
            hval = w1[0]
            nrm2 = 0.0
            for q in range(n):
                nrm2 += work[o_hx + i * n + q] ** 2
            if hval != 0.0 and nrm2 > 0.0:
                g = slide_c * hval / nrm2
                for q in range(n):
                    out[q] -= g * work[o_hx + i * n + q]


@_hot
def _project_multi(ev, p, mask, t, y, n, hdx, buf):
    """Bring a state back onto all surfaces of ``mask``: sweeps of the one-surface Newton
    projection (:func:`_project_surface`), exact after one sweep for orthogonal linear
    surfaces (independent contacts), a few for oblique ones."""
    k = _multi_count(mask)
    for sweep in range(4):
        for i in range(k):
            _project_surface(ev, p, _multi_surface(mask, i), t, y, n, hdx, buf)


@_hot
def _multi_reference(stab, mask, m):
    """The corner of mode ``m`` above every surface of ``mask`` (-1 if a switch is missing)."""
    k = _multi_count(mask)
    for i in range(k):
        s = _switch_on(stab, _multi_surface(mask, i), m)
        if s < 0:
            return -1
        m = stab[s].above
    return m


@_hot
def _settle_multi(ev, p, t, y, n, nm, mask, ref, stab, buf, hdx, w1, work):
    """The discrete state of a state on the intersection of the surfaces of ``mask`` (corner
    ``ref`` above all of them): sliding on all of them where the weights of the multilinear
    field lie in ``[0, 1]^k`` (an attracting intersection); otherwise the surface whose weight
    lies farthest outside is left to the side its weight points to (``lambda_i < 0``: above,
    ``> 1``: below) and the rest is settled again, down to sliding on one surface (the signs
    of ``hdot`` on its two sides, thesis eq. 2.6-2.8) or a regular mode. The state is
    projected onto the surfaces it slides on. Returns ``(dkind, didx, mode)``."""
    o_lam = _multi_offsets(n)[2]
    o_fi = _multi_offsets(n)[6]
    tol = 64.0 * _EPS
    for rnd in range(MULTI_MAX + 1):
        k = _multi_count(mask)
        if k >= 2:
            # the weights from the sign family's field where it applies (its Newton iterates
            # are the corner sum's, an affine change of variables apart): where they all lie
            # in [0, 1] the motion slides on the whole intersection, and the 2**k corner
            # fields are not needed
            kk = _solve_lambda(ev, p, mask, ref, nm, t, y, n, stab, w1, work)
            if kk >= 0 and work[o_fi] == 1.0:
                inside = True
                for i in range(k):
                    lam = work[o_lam + i]
                    if max(-lam, lam - 1.0) > tol:
                        inside = False
                if inside:
                    _project_multi(ev, p, mask, t, y, n, hdx, buf)
                    return SLIDE_MULTI, mask, ref
                # the corners' tangency values decide which surface is left
                kk = _solve_lambda(ev, p, mask, ref, nm, t, y, n, stab, w1, work, False)
            if kk < 0:
                return -1, mask, ref
            worst = -1
            dev = tol
            for i in range(k):
                lam = work[o_lam + i]
                d = max(-lam, lam - 1.0)
                if d > dev:
                    dev = d
                    worst = i
            if worst < 0:
                _project_multi(ev, p, mask, t, y, n, hdx, buf)
                return SLIDE_MULTI, mask, ref
            ks = _multi_surface(mask, worst)
            # the side it leaves to: where every corner field moves the state one way across
            # it (a crossing), that way; otherwise (some corner fields point into it) the side
            # its weight points to
            amin = np.inf
            amax = -np.inf
            o_a = _corner_offsets(n, k)[1]
            for c in range(1 << k):
                amin = min(amin, work[o_a + worst * (1 << k) + c])
                amax = max(amax, work[o_a + worst * (1 << k) + c])
            below = work[o_lam + worst] > 1.0
            if amin >= 0.0:
                below = False
            elif amax <= 0.0:
                below = True
            if below:
                ref = _partner(stab, ks, ref)
            mask &= ~(1 << ks)
            ref = _multi_reference(stab, mask, ref)
            if ref < 0:
                return -1, mask, ref
            if not _multi_set_corners(stab, mask, ref, n, work):
                return -1, mask, ref
            continue
        if k == 1:
            ks = _multi_surface(mask, 0)
            b = _partner(stab, ks, ref)
            s = _find_switch(stab, ks, ref, b)
            if s < 0:
                return REGULAR, -1, ref
            ev(W_HD, ks * nm + ref, t, y, p, buf)
            sa = buf[0]
            ev(W_HD, ks * nm + b, t, y, p, buf)
            sb = buf[0]
            if stab[s].kind == SW_FILIPPOV and sa < 0.0 and sb > 0.0:
                _project_surface(ev, p, ks, t, y, n, hdx, buf)
                return SLIDE, s, ref
            if sa >= 0.0 and sb > 0.0 or sa > 0.0 and sb >= 0.0:
                return REGULAR, -1, ref
            return REGULAR, -1, b
        return REGULAR, -1, ref
    return -1, mask, ref


@_hot
def _on_surfaces(ev, p, t, y, n, xmax, k, a, stab, buf, hdx):
    """The bit mask of the Filippov surfaces other than ``k`` that bound mode ``a`` or its
    partners across them and that the state lies on (within round-off,
    :func:`_surface_offset`), at most ``MULTI_MAX - 1`` of them (0: none)."""
    mask = 0
    cnt = 0
    n_sw = stab.shape[0]
    s = _next_touching(stab, 0, a)
    while s < n_sw:
        ks = stab[s].surface
        if ks != k and stab[s].kind == SW_FILIPPOV and not (mask >> ks) & 1:
            hv, tol = _surface_offset(ev, p, ks, t, y, n, xmax, buf, hdx)
            if abs(hv) <= tol and cnt < MULTI_MAX - 1 and ks < 63:
                mask |= 1 << ks
                cnt += 1
        s = _next_touching(stab, s + 1, a)
    return mask


def _state_field_signature():
    from numba import types as nt

    from ...model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    return nt.void(EVALUATE_TYPE, f1, nt.int64, nt.int64, nt.int64, nt.int64, nt.float64, f1,
                   EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE, nt.float64, f1)


@njit(_state_field_signature(), cache=True)
def state_field(ev, p, dkind, didx, mode, nm, t, x, etab, stab, slide_c, out):
    """The vector field of a discrete state (``dkind``: REGULAR, STICK, SLIDE, SLIDE_MULTI;
    ``didx``; mode)
    at ``(t, x)`` into ``out``: the same function the kernel integrates, for Python callers
    (Poincaré-map projections, shooting, projected saltation matrices)."""
    n = x.shape[0]
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(max(n * n, multi_work_size(n, stab)))
    hdx = np.zeros(n)
    _field(ev, p, dkind, didx, mode, nm, t, x, n, out, etab, stab, slide_c, w1, w2, gx, hdx)
