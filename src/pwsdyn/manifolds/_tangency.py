"""Homoclinic and heteroclinic tangencies of a map's one-dimensional manifolds, located in a
parameter; the boundary crisis of a planar map's attractor is one (Grebogi, Ott & Yorke 1983).

A saddle ``P`` and a saddle ``S`` (the same one for a homoclinic tangency) of a planar map,
each with one unstable and one stable multiplier, have the curves ``W^u(P)`` and ``W^s(S)``
(grown with :func:`pwsdyn.manifold`). Where they do not meet near a point ``c``, the side of
``W^s(S)`` on which ``W^u(P)`` lies there is defined; the *contact function*

``g(p) = min(sigma_u min_{u} d(u, W^s), sigma_s min_{s} d(s, W^u))``

takes, over the vertices ``u`` of ``W^u(P)`` (and ``s`` of ``W^s(S)``) in a ball around ``c``,
the signed distance ``d`` to the other curve's polyline in the ball (the sign of the cross
product with the nearest segment, the sum of the two segments' normals at a vertex: the
curve's side, as for any curve that cuts the ball), oriented by ``sigma`` so that it is
positive at the first parameter. It is zero at the first contact: a vertex of one curve (a
fold of a piecewise-linear map's manifold is a vertex, computed as the image of the border
point, never interpolated) reaching the other's segment, and negative once they cross; taking
both terms makes either kind of contact exact, the other one changing sign later. Between
the vertices of a smooth contact the chords deviate from the curves by the manifold's ``tol``,
which bounds the located value's error. The root is found by ``scipy.optimize.brentq``;
the saddles are found again by Newton at every parameter from their previous position.

A boundary crisis of a chaotic attractor of a planar map is the first contact of the
attractor (the closure of a saddle's unstable manifold within it) with its basin's
boundary (the stable manifold of a saddle on it): the orbits on the attractor can then cross
into the other side and leave. :func:`pwsdyn.locate_crisis` brackets it by following the
attractor, finds the saddles around it, and locates the first contact of the pairs whose
contact changes sign in the bracket with the machinery here.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from ._manifold import manifold
from ._points import ManifoldError, PeriodicPoint, find_periodic_point, refind, section_point


def _saddle(pt) -> bool:
    """One real multiplier outside the unit circle and one inside: both manifolds are
    curves."""
    m = np.asarray(pt.multipliers)
    if m.size != 2 or not np.all(np.isfinite(m)) or np.any(np.abs(m.imag) > 1e-12):
        return False
    a = np.abs(m)
    return bool(a[0] > 1 + 1e-9 and a[1] < 1 - 1e-9)


def _runs(pieces, center, radius):
    """The parts of the polylines ``pieces`` with a vertex within ``radius`` of ``center``:
    a list of ``(m, 2)`` arrays (consecutive vertices, each run cut where the polyline leaves
    the ball)."""
    out = []
    for piece in pieces:
        if len(piece) < 2:
            continue
        near = np.linalg.norm(piece - center, axis=1) <= radius
        # a segment is kept when either end is in the ball
        seg = near[:-1] | near[1:]
        idx = np.flatnonzero(seg)
        if not len(idx):
            continue
        cuts = np.flatnonzero(np.diff(idx) > 1)
        for chunk in np.split(idx, cuts + 1):
            out.append(piece[chunk[0]:chunk[-1] + 2])
    return out


def _signed(points, runs):
    """Per point, the signed distance to the union of the polylines ``runs`` (the left side of
    their direction positive) and the nearest point on them; ``nan`` where the nearest point is
    an end of a run (the side is not defined beyond it)."""
    P = np.atleast_2d(points)
    best = np.full(len(P), np.inf)
    sd = np.full(len(P), np.nan)
    foot = np.full(P.shape, np.nan)
    for run in runs:
        A, B = run[:-1], run[1:]
        AB = B - A
        L2 = np.einsum("ij,ij->i", AB, AB)
        L = np.sqrt(L2)
        ok = L2 > 0
        if not ok.any():
            continue
        A, B, AB, L2, L = A[ok], B[ok], AB[ok], L2[ok], L[ok]
        D = P[:, None, :] - A[None, :, :]
        t = np.einsum("mkj,kj->mk", D, AB) / L2
        tc = np.clip(t, 0.0, 1.0)
        F = A[None] + tc[..., None] * AB[None]
        dist = np.linalg.norm(P[:, None, :] - F, axis=2)
        k = np.argmin(dist, axis=1)
        m = np.arange(len(P))
        dk = dist[m, k]
        better = dk < best
        if not better.any():
            continue
        n = len(A)
        cross = (AB[None, :, 0] * D[..., 1] - AB[None, :, 1] * D[..., 0]) / L[None]
        for i in np.flatnonzero(better):
            j = int(k[i])
            best[i] = dk[i]
            foot[i] = F[i, j]
            tj = tc[i, j]
            if 0.0 < tj < 1.0:
                sd[i] = np.sign(cross[i, j]) * dk[i]
                continue
            # at a vertex: the sum of the normals of the segments meeting there
            j2 = j - 1 if tj == 0.0 else j + 1
            if j2 < 0 or j2 >= n:
                sd[i] = np.nan          # an end of the run
                continue
            s = np.sign(cross[i, j] + cross[i, j2]) if dk[i] > 0 else 0.0
            sd[i] = s * dk[i]
    return sd, foot


class Contact:
    """The contact function of ``W^u(P)`` and ``W^s(S)`` in one parameter, continued from the
    nearest parameter evaluated (saddles by Newton from there)."""

    def __init__(self, model, param, params, unstable, stable, *, arclength, tol,
                 max_points, exclude, options=None):
        self.model, self.param, self.params = model, param, dict(params or {})
        # a flow's integrator options, for its saddles' and manifolds' runs
        self.options = dict(options or {})
        self.arclength, self.tol, self.max_points = arclength, tol, max_points
        self.exclude = exclude
        self.homoclinic = unstable is stable
        self.known = {}        # p -> (P, S)
        self.center = self.radius = None
        self.sigma = (1.0, 1.0)
        self.last = None       # (p, g, point, Wu, Ws, P, S) of the last evaluation

    def _at(self, p, guesses=None):
        if guesses is None:
            near = min(self.known, key=lambda q: abs(q - p))
            guesses = self.known[near]
        P0, S0 = guesses
        prm = {**self.params, self.param: float(p)}
        P = refind(self.model, P0, prm, self.options)
        S = P if self.homoclinic else refind(self.model, S0, prm, self.options)
        if not (_saddle(P) and _saddle(S)):
            raise ManifoldError(f"a saddle is no longer a saddle at {self.param} = {p}")
        Wu = manifold(self.model, P, "unstable", arclength=self.arclength, tol=self.tol,
                      max_points=self.max_points, **self.options)
        Ws = manifold(self.model, S, "stable", arclength=self.arclength, tol=self.tol,
                      max_points=self.max_points, **self.options)
        return P, S, Wu, Ws

    def start(self, p, P, S):
        """Find the manifolds' nearest approach at ``p`` (away from ``S`` itself for a
        homoclinic pair, where they cross) and orient the contact function positive there;
        its value."""
        P, S, Wu, Ws = self._at(p, (P, S))
        U = np.concatenate(Wu.pieces)
        Sp = np.concatenate(Ws.pieces)
        if self.homoclinic:
            keep_u = np.min(np.linalg.norm(U[:, None] - S.cycle[None], axis=2),
                            axis=1) > self.exclude
            keep_s = np.min(np.linalg.norm(Sp[:, None] - S.cycle[None], axis=2),
                            axis=1) > self.exclude
            U, Sp = U[keep_u], Sp[keep_s]
        if not len(U) or not len(Sp):
            raise ManifoldError("the manifolds have no points away from the saddle")
        du, ds = Ws.distance(U), Wu.distance(Sp)
        iu, is_ = int(np.argmin(du)), int(np.argmin(ds))
        if du[iu] <= ds[is_]:
            c, d0 = U[iu], float(du[iu])
        else:
            c, d0 = Sp[is_], float(ds[is_])
        step = max(Wu.options["max_step"], Ws.options["max_step"])
        radius = max(8.0 * d0, 4.0 * step)
        far = float(np.min(np.linalg.norm(S.cycle - c, axis=1)))
        if self.homoclinic:
            radius = min(radius, 0.9 * far)
        self.center = c
        # shrink the ball until the curves in it lie each on one side of the other (two folds
        # of one curve on either side of the other's would give both signs)
        while True:
            self.radius = radius
            su, ss = self._terms(Wu, Ws, c, radius)
            ok_u = su[np.isfinite(su)]
            ok_s = ss[np.isfinite(ss)]
            if (not len(ok_u) or np.all(ok_u > 0) or np.all(ok_u < 0)) and (
                    not len(ok_s) or np.all(ok_s > 0) or np.all(ok_s < 0)) and (
                    len(ok_u) or len(ok_s)):
                break
            radius *= 0.5
            # d0 may be zero (the curves already cross at a vertex): the halving must end
            if radius < 1.01 * d0 or radius < 1e-12 * (1.0 + float(np.max(np.abs(c)))):
                raise ManifoldError("the manifolds meet on both sides of each other near "
                                    "their nearest approach")
        self.sigma = (np.sign(ok_u[0]) if len(ok_u) else 1.0,
                      np.sign(ok_s[0]) if len(ok_s) else 1.0)
        self.known[p] = (P, S)
        g, point = self._value(Wu, Ws)
        self.last = (p, g, point, Wu, Ws, P, S)
        return g

    def _terms(self, Wu, Ws, c, radius):
        ru = _runs(Wu.pieces, c, radius)
        rs = _runs(Ws.pieces, c, radius)
        U = np.concatenate(ru) if ru else np.zeros((0, 2))
        Sp = np.concatenate(rs) if rs else np.zeros((0, 2))
        U = U[np.linalg.norm(U - c, axis=1) <= radius] if len(U) else U
        Sp = Sp[np.linalg.norm(Sp - c, axis=1) <= radius] if len(Sp) else Sp
        su = _signed(U, rs)[0] if len(U) and rs else np.zeros(0)
        ss = _signed(Sp, ru)[0] if len(Sp) and ru else np.zeros(0)
        self._pts = (U, Sp)
        return su, ss

    def _value(self, Wu, Ws):
        su, ss = self._terms(Wu, Ws, self.center, self.radius)
        U, Sp = self._pts
        best, point = np.inf, None
        for vals, pts, sg in ((su, U, self.sigma[0]), (ss, Sp, self.sigma[1])):
            v = sg * vals
            fin = np.isfinite(v)
            if fin.any():
                i = int(np.flatnonzero(fin)[np.argmin(v[fin])])
                if v[i] < best:
                    best, point = float(v[i]), pts[i]
        if point is None:
            return np.nan, None
        return best, point

    def __call__(self, p):
        try:
            P, S, Wu, Ws = self._at(p)
        except ManifoldError:
            return np.nan
        self.known[p] = (P, S)
        g, point = self._value(Wu, Ws)
        self.last = (p, g, point, Wu, Ws, P, S)
        return g


def as_point(model, pt, params, period, t0=0.0, options=None):
    if isinstance(pt, PeriodicPoint):
        return pt
    if getattr(model, "is_map", False):
        return find_periodic_point(model, pt, period, params=params)
    return section_point(model, pt, period, params=params, t0=t0, options=options)


def root(contact, a, b, tol, history):
    """``brentq`` on the contact function between ``a`` (where it was started) and ``b``;
    ``None`` when it does not change sign or cannot be evaluated."""
    def g(q):
        v = contact(q)
        history.append((float(q), float(v)))
        if not np.isfinite(v):
            raise ValueError("contact undefined")
        return v

    try:
        gb = g(b)
    except ValueError:
        return None
    if gb > 0:
        return None
    try:
        r = brentq(g, a, b, xtol=tol)
    except (ValueError, RuntimeError):
        return None
    return None if _jumps(history) else r


def _jumps(history, factor: float = 1e3) -> bool:
    """Whether Brent's method closed in on a jump of the contact function rather than a
    zero: the secant slope over its last sign change exceeds the one over the whole bracket
    (its first two evaluations) ``factor`` times. A contact moves with the parameter at a
    finite rate, so the two slopes are alike at a zero; they part at a jump, where the side
    or the ball's content changes at once (a manifold cut by an impact at the section's
    time, its continuation not grown), and no tangency is there."""
    if len(history) < 3:
        return False
    (q0, g0), (q1, g1) = history[0], history[1]
    if q0 == q1:
        return False
    outer = abs(g1 - g0) / abs(q1 - q0)
    pos = [(q, v) for q, v in history if v > 0]
    neg = [(q, v) for q, v in history if v <= 0]
    if not pos or not neg:
        return False
    # the last sign change: the positive and non-positive evaluations nearest each other
    qp, vp = min(pos, key=lambda t: min(abs(t[0] - q) for q, _ in neg))
    qn, vn = min(neg, key=lambda t: abs(t[0] - qp))
    if qp == qn:
        return False
    return abs(vp - vn) / abs(qp - qn) > factor * outer
