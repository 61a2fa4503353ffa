"""Watch functions and event location: the scalar functions watched in each discrete state,
their values and slopes on a step's dense output, the bounded search of extrema towards zero
(grazes, short release and exit windows), and the contact tests.
"""

from __future__ import annotations

import numpy as np

from ...model.codegen import W_F, W_H, W_HD, W_HDT, W_HDX, W_HHD, W_HT, W_HX
from .._codes import REGULAR, WF_HDOT, WF_LAMBDA, WF_SURFACE
from ._base import _EPS, _FD_STEP, _dot, _hot, _ulp
from .fields import _cached_lambda, _field, _multi_offsets, _rate_band
from .steppers import _dense_eval

# --------------------------------------------------------------------------------------
# watch functions
# --------------------------------------------------------------------------------------

@_hot
def _watch_value(ev, p, wtype, widx, wmode, nm, t, x, n, buf, fbuf, hdx):
    if wtype == WF_SURFACE:
        ev(W_H, widx, t, x, p, buf)
        return buf[0]
    if wtype == WF_HDOT:
        ev(W_HD, widx * nm + wmode, t, x, p, buf)
        return buf[0]
    if wtype == WF_LAMBDA:
        # exit from sliding on an intersection: min(lambda_i, 1 - lambda_i), i = widx, of the
        # multilinear field on the surfaces of the mask wmode (zero where lambda_i reaches 0 or
        # 1; its kink at 1/2 is far from the zero), whose corner modes the kernel keeps in buf
        # (set when the watch list is built)
        if _cached_lambda(ev, p, wmode, t, x, n, fbuf, buf) < 0:
            return np.nan
        lam = buf[_multi_offsets(n)[2] + widx]
        return min(lam, 1.0 - lam)
    # WF_HDDOT: free normal acceleration hdot_t + hdot_x f
    ev(W_F, wmode, t, x, p, fbuf)
    ev(W_HDX, widx * nm + wmode, t, x, p, hdx)
    ev(W_HDT, widx * nm + wmode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n)


@_hot
def _surface_rate(ev, p, dkind, k, mode, nm, t, x, f, n, buf, hdx):
    """dh/dt along the current field f: one call of the compiled hdot in a regular mode."""
    if dkind == REGULAR:
        ev(W_HD, k * nm + mode, t, x, p, buf)
        return buf[0]
    ev(W_HX, k, t, x, p, hdx)
    ev(W_HT, k, t, x, p, buf)
    return buf[0] + _dot(hdx, f, n)


@_hot
def _hdot_rate(ev, p, k, wm, nm, t, x, f, n, buf, hdx):
    """d/dt of ``hdot`` of mode ``wm`` on surface ``k`` along the current field ``f``:
    ``hdot_t + hdot_x f`` (to polish a sliding exit, where that ``hdot`` reaches zero)."""
    ev(W_HDX, k * nm + wm, t, x, p, hdx)
    ev(W_HDT, k * nm + wm, t, x, p, buf)
    return buf[0] + _dot(hdx, f, n)


@_hot
def _crosses(v0, v1, direction):
    """A zero crossing from v0 to v1 in ``direction``. A function that starts exactly at zero
    and moves in the event direction crosses (a start on an impact surface with approaching
    velocity is an impact at the initial time)."""
    if direction < 0:
        return (v0 > 0.0 and v1 <= 0.0) or (v0 == 0.0 and v1 < 0.0)
    if direction > 0:
        return (v0 < 0.0 and v1 >= 0.0) or (v0 == 0.0 and v1 > 0.0)
    return (v0 > 0.0 and v1 <= 0.0) or (v0 < 0.0 and v1 >= 0.0)


@_hot
def _locate_exact(ev, p, km, t, h, y, Q, nY, deg, a_th, b_th, fa, fb, xs, buf):
    """Newton's method for the crossing of surface ``k`` (``km = k * nm + mode``, a regular
    mode) in the bracket ``[a_th, b_th]`` of an exact step's dense output, ``fa`` and ``fb``
    the surface's values at the ends (``fa`` on the side not crossed). Returns the crossed
    end of the final bracket, closed as far as the Illinois search closes it (``(b - a) h
    <= 2 ulp(t)``), or ``-1.0`` where Newton is not used and Illinois goes on.

    The dense output of an exact step is the exact flow (Taylor terms to 1e-18), so the
    derivative of ``h_k`` in ``theta`` is ``h hdot_k``, which the compiled model gives with
    ``h_k`` in one call (``W_HHD``). Safeguarded as Numerical Recipes' ``rtsafe`` (a bisection
    where the Newton point leaves the bracket or the step does not halve), it takes ~5
    evaluations where Illinois takes ~16 (impact oscillator). A Newton point within an ulp
    of ``t`` is moved an ulp past the root it predicts, so the next value lies across it and
    the bracket closes.

    Only where the crossing is resolved above round-off: the surface must move, across an
    ulp of ``t``, by more than four rounding errors of its value (``hdot`` at the crossed end
    large enough, in the crossing's direction). Near a graze the computed surface changes
    sign several times within the last ulps, and which of those sign changes a search closes
    on depends on its trial points: there Illinois keeps its own (the results of the
    analyses built on them, a grazing classified as such, do not depend on the locator)."""
    _dense_eval(y, Q, b_th, nY, deg, xs)
    tb = t + b_th * h
    ev(W_HHD, km, tb, xs, p, buf)
    big = 0.0
    for i in range(nY):
        big = max(big, abs(xs[i]))
    rate = buf[1]
    if not (np.isfinite(rate) and rate * (fb - fa) > 0.0
            and abs(rate) * _ulp(tb) > 4.0 * _EPS * (1.0 + big)):
        return -1.0
    th = (a_th * fb - b_th * fa) / (fb - fa) if fb != fa else 0.5 * (a_th + b_th)
    if not a_th < th < b_th:
        th = 0.5 * (a_th + b_th)
    step_before = b_th - a_th
    step = step_before
    for _ in range(200):
        if (b_th - a_th) * h <= 2.0 * _ulp(t + b_th * h):
            break
        _dense_eval(y, Q, th, nY, deg, xs)
        ev(W_HHD, km, t + th * h, xs, p, buf)
        g = buf[0]
        dg = buf[1] * h
        if g != 0.0 and (g > 0.0) == (fa > 0.0):
            a_th = th
        else:
            b_th = th
        if (b_th - a_th) * h <= 2.0 * _ulp(t + b_th * h):
            break
        tiny = _ulp(t + th * h) / h
        if g == 0.0:
            # on the surface: close the bracket from the side not crossed
            nxt = th - tiny
        elif (not np.isfinite(dg) or dg == 0.0
              or ((th - b_th) * dg - g) * ((th - a_th) * dg - g) > 0.0
              or abs(2.0 * g) > abs(step_before * dg)):
            # the Newton point is outside the bracket, or Newton is not halving the step
            step_before = step
            step = 0.5 * (b_th - a_th)
            nxt = a_th + step
        else:
            step_before = step
            step = g / dg
            nxt = th - step
            if abs(step) < tiny:
                nxt = th - step - (tiny if step > 0.0 else -tiny)
        if not a_th < nxt < b_th:
            nxt = 0.5 * (a_th + b_th)
        th = nxt
    return b_th


@_hot
def _watch_slope(ev, p, wtype, widx, wmode, nm, t, h, y, Q, n, deg, th, xs, buf, fbuf, hdx):
    """d/dt of a watch function along the step's dense output at ``theta``: a central
    difference (relative step ``_FD_STEP`` of the step; the dense output is a polynomial, so
    ``theta +- step`` may lie just outside ``[0, 1]``). For the normal acceleration of a
    sticking motion, whose time derivative the generated code does not carry."""
    ta = t + (th - _FD_STEP) * h
    tb = t + (th + _FD_STEP) * h
    if not tb > ta:
        return 0.0
    _dense_eval(y, Q, th - _FD_STEP, n, deg, xs)
    ga = _watch_value(ev, p, wtype, widx, wmode, nm, ta, xs, n, buf, fbuf, hdx)
    _dense_eval(y, Q, th + _FD_STEP, n, deg, xs)
    gb = _watch_value(ev, p, wtype, widx, wmode, nm, tb, xs, n, buf, fbuf, hdx)
    return (gb - ga) / (tb - ta)


@_hot
def _watch_pair(ev, p, wtype, widx, wmode, dkind, didx, mode, nm, t, h, y, Q, n, deg, th, xs,
                buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2, gx):
    """Value and time derivative of a watch function at ``theta`` on the step's dense output
    (the exact flow on an exact step). Surfaces: ``h`` and ``hdot`` from the model at the
    interpolated state (one call in a regular mode; along the sticking or sliding field
    otherwise); other watch functions: :func:`_watch_slope`."""
    tt = t + th * h
    _dense_eval(y, Q, th, n, deg, xs)
    if wtype == WF_SURFACE:
        if dkind == REGULAR:
            ev(W_HHD, widx * nm + mode, tt, xs, p, buf)
            return buf[0], buf[1]
        ev(W_H, widx, tt, xs, p, buf)
        g = buf[0]
        _field(ev, p, dkind, didx, mode, nm, tt, xs, n, f, etab, stab, slide_c, w1, w2, gx, hdx)
        return g, _surface_rate(ev, p, dkind, widx, mode, nm, tt, xs, f, n, buf, hdx)
    g = _watch_value(ev, p, wtype, widx, wmode, nm, tt, xs, n, buf, fbuf, hdx)
    return g, _watch_slope(ev, p, wtype, widx, wmode, nm, t, h, y, Q, n, deg, th, xs, buf, fbuf,
                           hdx)


@_hot
def _extremum_search(ev, p, wtype, widx, wmode, dkind, didx, mode, nm, t, h, y, Q, n, deg,
                     a, ga, da, b, gb, db, xs, buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2,
                     gx):
    """Bounded search for a crossing hidden at an extremum of a watch function ``g`` between
    two samples ``a < b`` (in theta) of one sign ``s`` where ``s g`` decreases at ``a``
    (``s da < 0``) and increases at ``b`` (``s db > 0``; ``da``, ``db`` are time derivatives).

    With ``G = s g`` convex on the bracket, the tangents at its ends bound ``G`` from below;
    their intersection gives the bound ``LB`` on its minimum. While ``LB <= 0`` the bracket
    is shrunk by the zero of the secant of ``G'`` (Illinois, safeguarded by bisection), ``g``
    and ``g'`` evaluated on the dense output, until a sample with ``G <= 0`` is found (the
    crossing), ``LB > 0`` (no crossing) or the bound is tight to rounding. The bound is
    second order in the bracket, so the error of one sample at an estimated extremum (the
    Hermite fit's, which grows like ``h^3``) no longer decides whether a graze is seen: a
    graze deeper than the dense output's error is found. Returns the sample with the smallest
    ``G``: ``(theta, g, g')``."""
    s = 1.0 if ga > 0.0 else -1.0
    Ga = s * ga
    Gb = s * gb
    Da = s * da * h     # derivatives in theta units
    Db = s * db * h
    best_th = a
    best_g = ga
    best_d = da
    if Gb < Ga:
        best_th = b
        best_g = gb
        best_d = db
    gnoise = 64.0 * _EPS * (Ga + Gb) + 1e-300
    Sa = Da             # the Illinois-weighted end derivatives of the secant
    Sb = Db
    side = 0
    width_check = b - a
    for it in range(48):
        W = b - a
        if W * h <= 4.0 * _ulp(t + b * h):
            break
        u = (Gb - Ga - Db * W) / (Da - Db)
        u = min(max(u, 0.0), W)
        LB = max(Ga + Da * u, Gb + Db * (u - W))
        if LB > 0.0 or s * best_g - LB <= gnoise:
            break
        m = a + W * Sa / (Sa - Sb)
        if it % 2 == 1:
            if W > 0.5 * width_check:
                m = 0.5 * (a + b)
            width_check = W
        if not (a < m < b):
            m = 0.5 * (a + b)
        gm, dm = _watch_pair(ev, p, wtype, widx, wmode, dkind, didx, mode, nm, t, h, y, Q, n,
                             deg, m, xs, buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2, gx)
        if not (np.isfinite(gm) and np.isfinite(dm)):
            break
        Gm = s * gm
        Dm = s * dm * h
        if Gm < s * best_g:
            best_th = m
            best_g = gm
            best_d = dm
        if Gm <= 0.0:
            break
        if Dm < 0.0:
            a = m
            Ga = Gm
            Da = Dm
            Sa = Dm
            if side == -1:
                Sb *= 0.5
            side = -1
        elif Dm > 0.0:
            b = m
            Gb = Gm
            Db = Dm
            Sb = Dm
            if side == 1:
                Sa *= 0.5
            side = 1
        else:
            break
    return best_th, best_g, best_d


@_hot
def _graze_samples(ev, p, wtype, widx, wmode, wdir, dkind, didx, mode, nm, t, h, y, Q, n, deg,
                   th, g, gd, ns, xs, buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2, gx):
    """Samples ``th[:ns]`` (increasing theta) of a watch function with values ``g`` and time
    derivatives ``gd``: between consecutive samples of one sign where it moves towards zero
    and then away (an extremum towards zero, in a direction the watch reacts to) run
    :func:`_extremum_search` and insert the sample it returns. Stops at the first pair that
    brackets a crossing. Returns the new number of samples."""
    q = 0
    while q < ns - 1 and ns < th.shape[0]:
        ga = g[q]
        gb = g[q + 1]
        if _crosses(ga, gb, wdir):
            break
        if ga != 0.0 and gb != 0.0 and (ga > 0.0) == (gb > 0.0):
            s = 1.0 if ga > 0.0 else -1.0
            if s * wdir <= 0 and s * gd[q] < 0.0 and s * gd[q + 1] > 0.0:
                tm, gm, dm = _extremum_search(ev, p, wtype, widx, wmode, dkind, didx, mode, nm,
                                              t, h, y, Q, n, deg, th[q], ga, gd[q], th[q + 1],
                                              gb, gd[q + 1], xs, buf, fbuf, hdx, f, etab, stab,
                                              slide_c, w1, w2, gx)
                if th[q] < tm < th[q + 1]:
                    for r in range(ns, q + 1, -1):
                        th[r] = th[r - 1]
                        g[r] = g[r - 1]
                        gd[r] = gd[r - 1]
                    th[q + 1] = tm
                    g[q + 1] = gm
                    gd[q + 1] = dm
                    ns += 1
                    if _crosses(ga, gm, wdir):
                        break
                    q += 1
        q += 1
    return ns


@_hot
def _hermite_extrema(v0, v1, d0, d1):
    """Interior extrema ``ra <= rb`` in ``(0, 1)`` of the cubic Hermite fit with values ``v0``,
    ``v1`` and theta-derivatives ``d0``, ``d1`` at the ends (2.0: none). With
    ``H(th) = ca th^3 + cb th^2 + d0 th + v0``, the roots of ``H'`` by the cancellation-free
    form of the quadratic formula (Numerical Recipes 5.6): the cubic term vanishes for a
    parabolic ``h``, where the textbook formula loses all digits."""
    qa = 3.0 * (2.0 * v0 - 2.0 * v1 + d0 + d1)
    qb = 2.0 * (-3.0 * v0 + 3.0 * v1 - 2.0 * d0 - d1)
    ra = 2.0
    rb = 2.0
    if d0 * d1 > 0.0 and not (0.0 < -qb < 2.0 * qa or 2.0 * qa < -qb < 0.0):
        # H' has one sign at both ends and its vertex -qb / (2 qa) is not inside: no root in
        # (0, 1), known without the square root and the divisions (most steps)
        return ra, rb
    disc = qb * qb - 4.0 * qa * d0
    if disc >= 0.0:
        qq = -0.5 * (qb + (np.sqrt(disc) if qb >= 0.0 else -np.sqrt(disc)))
        if qa != 0.0:
            ra = qq / qa
        if qq != 0.0:
            rb = d0 / qq
        if ra > rb:
            ra, rb = rb, ra
    if not (0.0 < ra < 1.0):
        ra = 2.0
    if not (0.0 < rb < 1.0) or rb == ra:
        rb = 2.0
    if rb < ra:
        ra, rb = rb, ra
    return ra, rb


@_hot
def _merge_samples(th, g, ns, th2, g2, ns2):
    """Insert the interior samples ``th2[1:ns2-1]`` into the increasing samples ``th[:ns]``
    (same ends), as room allows. Returns the new number of samples."""
    for q2 in range(1, ns2 - 1):
        if ns >= th.shape[0]:
            break
        tq = th2[q2]
        r = ns
        while r > 0 and th[r - 1] > tq:
            th[r] = th[r - 1]
            g[r] = g[r - 1]
            r -= 1
        if r > 0 and th[r - 1] == tq:
            # already sampled there: undo the shift
            for r2 in range(r, ns):
                th[r2] = th[r2 + 1]
                g[r2] = g[r2 + 1]
            continue
        th[r] = tq
        g[r] = g2[q2]
        ns += 1
    return ns


# --------------------------------------------------------------------------------------
# event maps and saltation matrices
# --------------------------------------------------------------------------------------

@_hot
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


#: Relative size of ``h_t + h_x f`` below which an event is grazing and its saltation matrix
#: singular (the same test as :func:`pwsdyn.stability.saltation_matrix`).
GRAZING_RTOL = 1e-13


@_hot
def _grazing(den, hx, f, n):
    """``den = h_t + h_x f`` is zero within ``GRAZING_RTOL |h_x| |f|`` (or not finite): the
    flow is tangent to the surface and the saltation matrix, with ``den`` as its
    denominator, is unbounded."""
    return not (abs(den) > GRAZING_RTOL * np.sqrt(_dot(hx, hx, n)) * np.sqrt(_dot(f, f, n)))


@_hot
def _free_normal_acc(ev, p, k, mode, nm, t, x, n, buf, fbuf, hdx):
    """The free normal acceleration ``hdot_t + hdot_x f`` of surface ``k`` in ``mode``."""
    ev(W_F, mode, t, x, p, fbuf)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n)


@_hot
def _stays_in_contact(ev, p, k, mode, nm, t, x, n, buf, fbuf, hdx):
    """A state on impact surface ``k`` whose normal velocity ``hdot`` is round-off
    (:func:`_rate_band`) while the free normal acceleration ``hdot_t + hdot_x f`` points into
    the surface: contact (sticking, i.e. constrained motion along the surface), never free
    flight through it."""
    ev(W_HD, k * nm + mode, t, x, p, buf)
    vn = buf[0]
    if not abs(vn) <= _rate_band(ev, p, k, mode, nm, t, x, n, hdx):
        return False
    ev(W_F, mode, t, x, p, fbuf)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n) < 0.0
