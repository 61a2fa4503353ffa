"""Closed forms and shared orbits for the stability and orbit tests (issue 4).

One-impact periodic orbits of the impact oscillator (zoo ``impact-oscillator``)

    x'' + eps x' + x = sin(omega t),  x <= sigma,  at x = sigma: v -> -r v,

derived here from the linear flow between impacts, independently of pwsdyn.

With z = (x, v), z' = A z + (0, sin(omega t)), A = [[0, 1], [-1, -eps]], the forced
periodic solution is z_p(t) = (X sin(omega t) + Y cos(omega t), omega (X cos - Y sin)) with
(1 - omega^2) X - eps omega Y = 1, (1 - omega^2) Y + eps omega X = 0. An orbit with one impact
per period T = 2 pi / omega, impacting at time t0 with velocity v > 0, leaves the wall at
(sigma, -r v) and returns to (sigma, v) after T:

    (sigma, v) - z_p(t0) = E ((sigma, -r v) - z_p(t0)),   E = expm(A T),

(z_p is T-periodic). Hence z_p(t0) = (sigma, 0) + v b with b = (I - E)^{-1} (I + r E) e_2, and
since x_p^2 + (v_p / omega)^2 = X^2 + Y^2 = R^2 for every t0,

    (sigma + v b_1)^2 + (v b_2 / omega)^2 = R^2,

a quadratic for v; (sin, cos)(omega t0) then follow from the 2x2 linear system. Two roots
give two orbits (a saddle-node pair): for eps = 0.1, sigma = -0.5, omega = 2.8, r = 0.8 a
stable one (complex multipliers of modulus 0.715) and a saddle (multipliers 2.95 and 0.173)
that direct simulation cannot reach.

Multipliers: the one-period map from just after an impact is M = S E with the impact's
saltation matrix written out by hand, S = g_x + (f_out - g_x f_in) h_x / (h_x f_in) with
g_x = diag(1, -r), h_x = (-1, 0), f_in = (v, F - sigma - eps v), f_out = (-r v,
F - sigma + eps r v), F = sin(omega t0).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.linalg import expm

IO = dict(eps=0.1, sigma=-0.5, omega=2.8, r=0.8)


def linear_impact_closed_form(c, kappa, P, Q, omega, sigma, r) -> dict:
    """One-impact orbits of x'' + c x' + kappa x = P sin(omega t) + Q cos(omega t), x <= sigma,
    v -> -r v at x = sigma (the derivation of the module docstring with the general linear
    oscillator: (kappa - omega^2) X - c omega Y = P, (kappa - omega^2) Y + c omega X = Q).

    Returns ``{'stable': {...}, 'unstable': {...}}`` with impact velocity ``v``, impact time
    ``t0`` in [0, T), multipliers ``mu`` and the admissibility check (no other contact).
    """
    T = 2 * np.pi / omega
    A = np.array([[0.0, 1.0], [-kappa, -c]])
    E = expm(A * T)
    I2 = np.eye(2)
    X, Y = np.linalg.solve(np.array([[kappa - omega**2, -c * omega],
                                     [c * omega, kappa - omega**2]]), [P, Q])
    R2 = X * X + Y * Y
    b = np.linalg.solve(I2 - E, (I2 + r * E) @ np.array([0.0, 1.0]))
    qa, qb, qc = b[0] ** 2 + (b[1] / omega) ** 2, 2 * sigma * b[0], sigma**2 - R2
    disc = qb * qb - 4 * qa * qc
    out = []
    for v in ((-qb - np.sqrt(disc)) / (2 * qa), (-qb + np.sqrt(disc)) / (2 * qa)):
        a1, a2 = sigma + v * b[0], v * b[1] / omega
        s, co = (X * a1 - Y * a2) / R2, (Y * a1 + X * a2) / R2
        t0 = (np.arctan2(s, co) % (2 * np.pi)) / omega
        F = P * np.sin(omega * t0) + Q * np.cos(omega * t0)
        f_in = np.array([v, F - kappa * sigma - c * v])
        f_out = np.array([-r * v, F - kappa * sigma + c * r * v])
        gx, hx = np.diag([1.0, -r]), np.array([-1.0, 0.0])
        S = gx + np.outer(f_out - gx @ f_in, hx) / (hx @ f_in)
        mu = np.linalg.eigvals(S @ E)
        # admissibility: x < sigma strictly between impacts (closed-form flow on a grid)
        z = np.array([sigma, -r * v]) - _zp(t0, X, Y, omega)
        step = expm(A * T / 2000)
        xs = []
        for k in range(1, 2000):
            z = step @ z
            xs.append(z[0] + _zp(t0 + k * T / 2000, X, Y, omega)[0])
        out.append(dict(v=float(v), t0=float(t0), mu=mu, admissible=bool(max(xs) < sigma),
                        T=T, X=X, Y=Y, A=A))
    stable = [o for o in out if np.all(np.abs(o["mu"]) < 1)]
    unstable = [o for o in out if np.any(np.abs(o["mu"]) > 1)]
    return {"stable": stable[0], "unstable": unstable[0]}


def io_closed_form(eps=IO["eps"], sigma=IO["sigma"], omega=IO["omega"], r=IO["r"]) -> dict:
    """Zoo ``impact-oscillator``: c = eps, kappa = 1, forcing sin(omega t)."""
    return linear_impact_closed_form(eps, 1.0, 1.0, 0.0, omega, sigma, r)


#: Zoo ``impact-oscillator-base`` (m x'' = -k (x - a sin) - d (x' - a omega cos), wall at
#: x = delta, restitution e) at omega = 1.4: a stable and a saddle one-impact orbit.
BASE = dict(m=1.0, k=1.0, d=0.1, a=0.5, omega=1.4, delta=1.0, e=0.8)


def base_closed_form() -> dict:
    m, k, d, a, w = BASE["m"], BASE["k"], BASE["d"], BASE["a"], BASE["omega"]
    return linear_impact_closed_form(d / m, k / m, a * k / m, a * d * w / m, w, BASE["delta"],
                                     BASE["e"])


def _zp(t, X, Y, omega):
    return np.array([X * np.sin(omega * t) + Y * np.cos(omega * t),
                     omega * (X * np.cos(omega * t) - Y * np.sin(omega * t))])


def closed_form_state(cf, sigma, r, t):
    """The closed-form orbit's state at time ``t`` in [t0, t0 + T)."""
    z0 = np.array([sigma, -r * cf["v"]]) - _zp(cf["t0"], cf["X"], cf["Y"], 2 * np.pi / cf["T"])
    return expm(cf["A"] * (t - cf["t0"])) @ z0 + _zp(t, cf["X"], cf["Y"], 2 * np.pi / cf["T"])


@functools.lru_cache(maxsize=None)
def io_orbit(which: str, model: str = "impact-oscillator"):
    """The pwsdyn orbit (``find_periodic_orbit``) near the closed-form one, from a guess 0.3
    of a period after the impact, off by 1e-2 in both states."""
    import pwsdyn

    if model == "impact-oscillator":
        cf, params, sigma, r = io_closed_form()[which], IO, IO["sigma"], IO["r"]
    else:
        cf, params, sigma, r = base_closed_form()[which], BASE, BASE["delta"], BASE["e"]
    t_guess = cf["t0"] + 0.3 * cf["T"]
    guess = closed_form_state(cf, sigma, r, t_guess) + np.array([0.01, -0.01])
    return pwsdyn.find_periodic_orbit(model, guess, params=params, t0=t_guess)


def io_one_impact(omega, root, eps=IO["eps"], sigma=IO["sigma"], r=IO["r"]):
    """The one-impact orbit of the zoo impact oscillator on one root of the quadratic of the
    module docstring (``root = +1``: the larger impact velocity -- the stable orbit of ``IO``
    -- ``-1``: the smaller, the saddle), continuous in the parameters up to the fold where the
    discriminant vanishes. Returns ``(v, t0, M, disc)``: impact velocity, impact time in
    ``[0, T)``, the one-period matrix ``M = S E`` from just after the impact, and the
    discriminant (its zero is the fold)."""
    T = 2 * np.pi / omega
    A = np.array([[0.0, 1.0], [-1.0, -eps]])
    E = expm(A * T)
    I2 = np.eye(2)
    X, Y = np.linalg.solve(np.array([[1 - omega**2, -eps * omega],
                                     [eps * omega, 1 - omega**2]]), [1.0, 0.0])
    R2 = X * X + Y * Y
    b = np.linalg.solve(I2 - E, (I2 + r * E) @ np.array([0.0, 1.0]))
    qa, qb, qc = b[0] ** 2 + (b[1] / omega) ** 2, 2 * sigma * b[0], sigma**2 - R2
    disc = qb * qb - 4 * qa * qc
    v = (-qb + root * np.sqrt(max(disc, 0.0))) / (2 * qa)
    a1, a2 = sigma + v * b[0], v * b[1] / omega
    s, co = (X * a1 - Y * a2) / R2, (Y * a1 + X * a2) / R2
    t0 = (np.arctan2(s, co) % (2 * np.pi)) / omega
    F = np.sin(omega * t0)
    f_in = np.array([v, F - sigma - eps * v])
    f_out = np.array([-r * v, F - sigma + eps * r * v])
    gx, hx = np.diag([1.0, -r]), np.array([-1.0, 0.0])
    S = gx + np.outer(f_out - gx @ f_in, hx) / (hx @ f_in)
    return float(v), float(t0), S @ E, float(disc)


#: Zoo ``bouncing-ball`` at the table frequency of its defaults.
BALL = dict(g=9.81, e=0.8, omega=2 * np.pi)


def ball_period_one(A, g=BALL["g"], e=BALL["e"], omega=BALL["omega"]):
    """The period-one orbit of a ball on a table ``s = A sin(omega t)`` (one impact per table
    period ``T``, restitution ``v -> sdot - e (v - sdot)``) and the Jacobian of its
    impact-to-impact map, in closed form.

    The ball leaves the table with velocity ``u`` and meets it again after ``T`` at the same
    phase: ``u T - g T^2 / 2 = 0``, ``u = g T / 2``, arriving with ``u - g T = -u``; the reset
    gives ``u = (1 + e) sdot + e u``, so ``sdot = A omega cos(omega t) = g T (1 - e) /
    (2 (1 + e))`` at impact -- the root with ``sin(omega t) > 0`` (the table above its mean
    position, decelerating) is the one stable at small ``A``.

    The map ``(t, u) -> (t', u')`` after one impact: ``t'`` the next zero of
    ``A sin(omega t) + u (t' - t) - g (t' - t)^2 / 2 - A sin(omega t')``, ``u' = (1 + e)
    sdot(t') - e (u - g (t' - t))``; its Jacobian by implicit differentiation. Returns
    ``(t, u, J)``.
    """
    T = 2 * np.pi / omega
    t = np.arccos(g * T * (1 - e) / (2 * (1 + e) * A * omega)) / omega
    u = g * T / 2
    tp, D = t + T, T
    sd = lambda s: A * omega * np.cos(omega * s)          # noqa: E731
    sdd = lambda s: -A * omega**2 * np.sin(omega * s)     # noqa: E731
    G_tp = (u - g * D) - sd(tp)
    G_t = sd(t) - u + g * D
    dtp_dt, dtp_du = -G_t / G_tp, -D / G_tp
    du_dt = (1 + e) * sdd(tp) * dtp_dt + e * g * (dtp_dt - 1)
    du_du = (1 + e) * sdd(tp) * dtp_du - e * (1 - g * dtp_du)
    return float(t), float(u), np.array([[dtp_dt, dtp_du], [du_dt, du_du]])
