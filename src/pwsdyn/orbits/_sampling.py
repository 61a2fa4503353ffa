"""Sampling of a segment's dense output: the sample times and the refined minima of a function
along them, for the admissibility checks, the monitors and the search of a condition."""

from __future__ import annotations

import numpy as np

#: Dense-output samples per step in the admissibility checks and the search of a condition.
SAMPLES = 8

# the fractions of a step that are sampled, made once (keyed by SAMPLES, a module setting)
_THETA: dict = {}


def sample_times(tr) -> np.ndarray:
    """Nodes of a run and ``SAMPLES - 1`` points inside each step."""
    t = np.asarray(tr.t, dtype=float)
    if len(t) < 2:
        return t
    th = _THETA.get(SAMPLES)
    if th is None:
        th = _THETA[SAMPLES] = np.arange(SAMPLES) / SAMPLES
    # (numpy.append and numpy.diff's own operations, without their wrappers)
    inner = np.concatenate(((t[:-1, None] + (t[1:] - t[:-1])[:, None] * th[None, :]
                             ).reshape(-1), t[-1:]))
    # sorted and distinct already unless a step is of no length (a jump's two nodes) or of
    # round-off size: numpy.unique (a sort) only then, with the same result
    if bool((inner[1:] > inner[:-1]).all()):
        return inner
    return np.unique(inner)


def _local_minima(g) -> list:
    """Indices ``i`` (``0 < i < len(g) - 1``) with ``g[i] <= g[i - 1]`` and ``g[i] <= g[i +
    1]``, in order (compared as arrays: a Python loop over the samples cost more than the
    rest of a check)."""
    g = np.asarray(g)
    if len(g) < 3:
        return []
    mid = g[1:-1]
    return (np.flatnonzero((mid <= g[:-2]) & (mid <= g[2:])) + 1).tolist()


def interior_minimum(val, ts, g):
    """``(t, value)`` of the smallest local minimum of the samples ``g`` at ``ts`` strictly
    inside the range (not at its ends), refined by minimizing ``val`` between the
    neighbouring samples; ``None`` when the samples have no interior local minimum."""
    cands = _local_minima(g)
    if not cands:
        return None
    best = None
    for i in sorted(cands, key=lambda k: g[k])[:8]:
        tm, fm = _refine_min(val, ts[i - 1], ts[i + 1], 4e-16 * max(1.0, abs(ts[i + 1])))
        fm = min(fm, g[i])
        if best is None or fm < best[1]:
            best = (float(tm), float(fm))
    return best


def _refine_min(val, a, b, xatol):
    """``(t, val(t))`` of the minimum of ``val`` on ``[a, b]`` (Brent's bounded method)."""
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(val, bounds=(float(a), float(b)), method="bounded",
                          options={"xatol": max(float(xatol), 1e-300), "maxiter": 200})
    return float(res.x), float(res.fun)


def _parabola_min(t3, g3, a, b) -> float:
    """Minimum over ``[a, b]`` of the parabola through three samples ``(t3, g3)``."""
    t0, t1, t2 = t3.tolist()
    g0, g1, g2 = g3.tolist()
    d1 = (g1 - g0) / (t1 - t0)
    d2 = (g2 - g1) / (t2 - t1)
    c = (d2 - d1) / (t2 - t0)                      # p(t) = g1 + m (t - t1) + c (t - t1)^2
    m = d1 + c * (t1 - t0)

    def p(t):
        return g1 + m * (t - t1) + c * (t - t1) ** 2
    vals = [p(a), p(b)]
    if c > 0:
        tv = t1 - m / (2 * c)
        if a < tv < b:
            vals.append(p(tv))
    return min(vals)


def lowest_point(fn, tr, ts, vals, sign, n, limit=None):
    """``(t, value)`` of the most negative ``sign * fn`` over the samples, each sampled local
    minimum refined by minimizing on the dense output.

    With ``limit``, only minima that could reach below it are refined: the parabola through
    a sampled minimum and its neighbours predicts the minimum between them, and a minimum
    whose prediction stays above ``limit`` by four times its own correction is left (the
    refinement, tens of evaluations of the dense output, costs more than the rest of a
    check)."""
    g = sign * vals
    k = int(np.argmin(g))
    best = (float(ts[k]), float(vals[k]))
    cands = [k] + _local_minima(g)
    for i in sorted(set(cands))[:50]:
        a = ts[max(i - 1, 0)]
        b = ts[min(i + 1, len(ts) - 1)]
        if b <= a:
            continue
        if limit is not None and len(g) >= 3:
            j = min(max(i, 1), len(g) - 2)
            pred = _parabola_min(ts[j - 1:j + 2], g[j - 1:j + 2], a, b)
            corr = abs(g[i] - pred)
            if pred - 4.0 * corr - 1e-3 * (abs(g[i]) + corr) > limit:
                continue
        def val(tt):
            return sign * fn(tt, tr(tt)[:n])
        tm, fm = _refine_min(val, a, b, 1e-9 * (b - a))
        if fm < sign * best[1]:
            best = (float(tm), float(sign * fm))
    return best