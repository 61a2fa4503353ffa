"""Independent references for the stability and orbit tests (issue 4).

Event-driven flows written the way a user writes them with scipy (``solve_ivp`` with event
functions, restarted at each event, DOP853 at rtol 1e-12) and central finite differences of
those flows. They share no code with pwsdyn's kernel: vector fields, surfaces, resets, the
chattering map and the sliding motion are written out here from the equations of the models.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

RTOL = 1e-12
ATOL = 1e-13


def _solve(rhs, t0, t1, y, events=None):
    return solve_ivp(rhs, (t0, t1), np.asarray(y, float), method="DOP853", rtol=RTOL,
                     atol=ATOL, events=events)


def impacting_flow(rhs, surface, reset, x0, t0, t1, max_events=1000):
    """x(t1) of a flow with one impact surface (``surface`` decreasing through 0 fires,
    ``reset(t, x)`` applied). Returns the end state and the event times."""
    def ev(t, y):
        return surface(t, y)
    ev.terminal = True
    ev.direction = -1
    t, y, times = float(t0), np.asarray(x0, float), []
    while t < t1 and len(times) < max_events:
        sol = _solve(rhs, t, t1, y, [ev])
        if sol.status == 1:
            te, ye = sol.t_events[0][0], sol.y_events[0][0]
            times.append(te)
            t, y = te, reset(te, ye)
        else:
            return sol.y[:, -1], times
    return y, times


def central_fd(fun, x0, h):
    """Central finite differences of ``fun`` at ``x0`` with relative steps ``h``."""
    x0 = np.asarray(x0, float)
    cols = []
    for c in range(len(x0)):
        e = np.zeros_like(x0)
        e[c] = h * max(1.0, abs(x0[c]))
        cols.append((np.asarray(fun(x0 + e)) - np.asarray(fun(x0 - e))) / (2 * e[c]))
    return np.column_stack(cols)


def rel_err(a, b) -> float:
    """max |a - b| / max |b|."""
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


# --------------------------------------------------------------------------------------
# Filippov: mass on a belt (velocity vb) with Coulomb friction and harmonic forcing
#   x' = v,  v' = -k x - c v - mu sign(v - vb) + A cos(w t)
# switch h = v - vb (above: v > vb). Sliding on h = 0 (sticking to the belt): x' = vb, v = vb,
# while -mu < k x + c vb - A cos(w t) < mu; it ends when the below field's normal velocity
# -k x - c vb + mu + A cos(w t) reaches 0 (leaving below) or the above field's
# -k x - c vb - mu + A cos(w t) reaches 0 (leaving above).
# --------------------------------------------------------------------------------------

def belt_flow(p, x0, t0, t1, max_events=100):
    """x(t1) and the event kinds of the forced belt oscillator (Filippov, by hand)."""
    k, c, mu, vb, A, w = (p[s] for s in ("k", "c", "mu", "vb", "A", "w"))

    def force(t):
        return A * np.cos(w * t)

    def field(sgn):
        return lambda t, y: [y[1], -k * y[0] - c * y[1] - sgn * mu + force(t)]

    def hd(sgn, t, x):
        # normal velocity of h = v - vb in the mode with friction -sgn*mu, at v = vb
        return -k * x - c * vb - sgn * mu + force(t)

    def hit(t, y):
        return y[1] - vb
    hit.terminal = True
    t, y = float(t0), np.asarray(x0, float)
    sgn = 1.0 if y[1] > vb else -1.0
    kinds = []
    while t < t1 and len(kinds) < max_events:
        # leave above through h decreasing, below through h increasing (a restart on the
        # surface moving away from it is not a crossing)
        hit.direction = -sgn
        sol = _solve(field(sgn), t, t1, y, [hit])
        if sol.status != 1:
            return sol.y[:, -1], kinds
        te = sol.t_events[0][0]
        ye = sol.y_events[0][0].copy()
        ye[1] = vb
        t, y = te, ye
        if hd(+1.0, t, y[0]) < 0 < hd(-1.0, t, y[0]):
            kinds.append("slide_start")

            def leave_below(tt, yy):
                return hd(-1.0, tt, yy[0])
            leave_below.terminal = True
            leave_below.direction = -1

            def leave_above(tt, yy):
                return hd(+1.0, tt, yy[0])
            leave_above.terminal = True
            leave_above.direction = 1
            sl = _solve(lambda tt, yy: [vb], t, t1, y[:1], [leave_below, leave_above])
            if sl.status != 1:
                return np.array([sl.y[0, -1], vb]), kinds
            which = 0 if sl.t_events[0].size else 1
            t = sl.t_events[which][0]
            y = np.array([sl.y_events[which][0][0], vb])
            sgn = -1.0 if which == 0 else 1.0
            kinds.append("slide_end")
        else:
            kinds.append("crossing")
            sgn = -sgn
    return y, kinds


# --------------------------------------------------------------------------------------
# one-legged jumper (zoo model) with chattering mapped at the first impact of a landing:
# flight, impact (Newton restitution relative to the ground), the complete-chattering map
# Q, q of the slides (Nordmark & Piiroinen 2009) with the foot then put on the ground,
# sticking (foot on the ground, body on the spring), release when the foot's free
# acceleration relative to the ground turns positive, flight.
# --------------------------------------------------------------------------------------

def jumper_flow(p, x0, t0, t1):
    m, k, d0, g, w, r, L, A = (p[s] for s in ("m", "k", "d0", "g", "omega", "r", "L", "A"))

    def G(t):
        return L + A * (np.sin(w * t) + np.cos(w * t))

    def Gd(t):
        return A * w * (np.cos(w * t) - np.sin(w * t))

    def Gdd(t):
        return -A * w * w * (np.sin(w * t) + np.cos(w * t))

    def flight(t, y):
        s = k * (y[2] - y[0] - d0)
        return [y[1], s / m - g, y[3], -s / m - g]

    def foot(t, y):
        return y[0] - G(t)
    foot.terminal = True
    foot.direction = -1

    def rel_acc(t, y):
        # free normal acceleration of the foot relative to the ground
        return k * (y[2] - y[0] - d0) / m - g - Gdd(t)

    t, y = float(t0), np.asarray(x0, float)
    kinds = []
    sticking = False
    while t < t1 and len(kinds) < 50:
        if not sticking:
            sol = _solve(flight, t, t1, y, [foot])
            if sol.status != 1:
                return sol.y[:, -1], kinds
            t, y = sol.t_events[0][0], sol.y_events[0][0].copy()
            vin = y[1] - Gd(t)                        # hdot at impact (< 0)
            a = rel_acc(t, y)                          # hddot = (hdot)_x f + hdot_t
            if a < 0:
                # complete chattering (slides): W = (0, -(1+r), 0, 0) so that
                # x+ = x- + W hdot for the restitution law; hdot_x W = -(1 + r)
                W = np.array([0.0, -(1 + r), 0.0, 0.0])
                f = np.array(flight(t, y))
                q = 2 * r * vin / ((1 - r) * a)
                y = y + (2 * r * f / a + W) * vin / (1 - r)
                t = t + q
                # on the sticking manifold h = 0, hdot = 0 (the kernel's projection)
                y[0], y[1] = G(t), Gd(t)
                kinds += ["chatter", "stick"]
                sticking = True
            else:
                y[1] = Gd(t) - r * (y[1] - Gd(t))
                kinds.append("impact")
        else:
            def stick(tt, z):
                s = k * (z[0] - G(tt) - d0)
                return [z[1], -s / m - g]

            def release(tt, z):
                return k * (z[0] - G(tt) - d0) / m - g - Gdd(tt)
            release.terminal = True
            release.direction = 1
            sol = _solve(stick, t, t1, y[2:], [release])
            tt = sol.t_events[0][0] if sol.status == 1 else sol.t[-1]
            z = sol.y_events[0][0] if sol.status == 1 else sol.y[:, -1]
            y = np.array([G(tt), Gd(tt), z[0], z[1]])
            t = tt
            if sol.status != 1:
                return y, kinds
            kinds.append("release")
            sticking = False
    return y, kinds
