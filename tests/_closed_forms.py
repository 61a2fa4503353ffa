"""Closed forms shared by the event tests. None of them calls pwsdyn.

* ``x'' = a - x`` against the wall ``1 - x >= 0`` with ``v -> -e v``: harmonic arcs about
  ``x = a`` between impacts (:func:`harmonic_arc`, :func:`wall_impacts`);
* the ball ``y'' = -g`` on a table ``s(t) = A sin(omega t)``: the release of a ball resting on
  the table where the table's acceleration falls to ``-g`` (:func:`release_time`) and the next
  contact of a parabola with the table (:func:`parabola_hits_table`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

G = 9.81


def harmonic_arc(u, a):
    """Time from the wall back to the wall of ``x'' = a - x`` leaving ``x = 1`` with speed
    ``u > 0``: ``x - 1 = (1 - a)(cos s - 1) - u sin s`` vanishes again where
    ``tan(s/2) = -u / (1 - a)``."""
    if a > 1.0:
        return 2.0 * math.atan(u / (a - 1.0))
    if a < 1.0:
        return 2.0 * (math.pi - math.atan(u / (1.0 - a)))
    return math.pi


def wall_impacts(t_first, v_first, a, e, t_end):
    """Impact times and incoming speeds from an impact at ``t_first`` with incoming speed
    ``v_first`` (the speed is kept along each harmonic arc), up to ``t_end``."""
    times, speeds = [t_first], [v_first]
    while len(times) < 500:
        u = e * speeds[-1]
        if u <= 1e-12 * v_first:
            break  # (a > 1: the arcs shrink geometrically and accumulate before t_end)
        t = times[-1] + harmonic_arc(u, a)
        if t > t_end:
            break
        times.append(t)
        speeds.append(u)
    return np.array(times), np.array(speeds)


def release_time(A, w, t0, g=G):
    """The first time after ``t0`` at which a ball resting on the table leaves it: where the
    table's acceleration ``-A w^2 sin(w t)`` falls to ``-g`` with ``sin`` increasing."""
    phi = math.asin(g / (A * w * w))
    k = math.ceil((w * t0 - phi) / (2 * math.pi))
    return (phi + 2 * math.pi * k) / w


def parabola_hits_table(t0, y0, v0, A, w, t_max, g=G, grid=20_000):
    """First time in ``(t0, t_max]`` at which the parabola ``y0 + v0 (t - t0) - g (t - t0)^2 / 2``
    comes back down through the table ``A sin(w t)``, or None. The gap is sampled on a fine
    grid (it starts at zero at ``t0`` and must be positive just after) and the sign change
    refined by brentq to round-off."""
    def gap(t):
        s = t - t0
        return y0 + v0 * s - 0.5 * g * s * s - A * math.sin(w * t)
    ts = np.linspace(t0, t_max, grid + 1)[1:]
    gs = np.array([gap(t) for t in ts])
    neg = np.nonzero(gs < 0.0)[0]
    if neg.size == 0:
        return None
    i = neg[0]
    if i == 0:
        return None  # not positive just after the start: no flight to speak of
    return brentq(gap, ts[i - 1], ts[i], xtol=1e-15, rtol=4 * np.finfo(float).eps)
