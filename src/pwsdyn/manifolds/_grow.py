"""Growing one branch of a one-dimensional manifold of a map by arclength.

The method is the one of Krauskopf and Osinga (J. Comput. Phys. 146, 1998) for maps, with the
point-by-point mesh of Hobson (J. Comput. Phys. 104, 1993): the branch starts as the
fundamental domain ``[q, H(q)]`` with ``q = p + delta v`` on the eigendirection ``v`` of the
saddle ``p``; every further point is the image under ``H`` of a point of the branch computed so
far, found by moving a cursor along that polyline (a preimage parameter ``s``: mesh index plus
the fraction of the next segment). A candidate image is accepted when the distance ``d`` from
the last point is at most ``max_step`` and the angle ``alpha`` between the last two chords is
at most ``alpha_max`` with ``d * alpha`` at most ``8 tol`` (unless ``d`` is below ``min_dist``,
the scale of the evaluation's own error; the deviation of the chord from an
arc of length ``d`` turning by ``alpha`` is about ``d alpha / 8``); otherwise the cursor's step
is halved, and it is doubled after a step well inside the criteria.

What is new for piecewise-smooth maps: each evaluation returns the signature of the point (the
pieces applied, or the events of a Poincaré map's orbit). Where the signature changes between
the cursor and the candidate, the border is located by bisection on the preimage polyline, the
images of its two sides are computed, and the branch gets a *node* there: a kink (the two images
agree: a continuous map, or the square-root map of grazing) or the end of one piece and the
start of the next (they do not: a jump). A node is never stepped over by the cursor, so the
images of kinks and piece ends are computed exactly rather than interpolated, and no segment is
ever drawn across a jump. The angle criterion is not applied across a node. Near a
square-root border the step halving refines by itself: the image of a cursor step ``h`` has
length of order ``sqrt(h)``.

For a stable manifold ``H`` is the inverse map; the model provides none, so each "image" is a
preimage found by Newton on the forward map with its Jacobian, started from the previous
preimage (:func:`preimage`).
"""

from __future__ import annotations

import math

import numpy as np

EPS = np.finfo(float).eps


def preimage(sec, y, guess, tol: float = 1e-13, max_iter: int = 40):
    """``z`` with ``H(z) = y`` by Newton from ``guess`` (each step with the Jacobian of the
    pieces applied at the iterate), and the signature at ``z``; ``(guess, None)`` when it
    fails."""
    z = np.array(guess, dtype=float)
    scale = 1.0 + float(np.max(np.abs(y)))
    for _ in range(max_iter):
        Hz, sig, J = sec.evaluate(z, jacobian=True)
        if sig is None:
            return z, None
        r = Hz - y
        if float(np.max(np.abs(r))) <= tol * scale:
            return z, sig
        try:
            dz = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError:
            return z, None
        if not np.all(np.isfinite(dz)):
            return z, None
        z = z + dz
    return z, None


def preimage_guarded(sec, y, guess, tol: float = 1e-13, max_iter: int = 60,
                     max_halvings: int = 30):
    """``preimage`` with a line search: a Newton step is halved until the residual
    ``max|H(z) - y|`` decreases and ``H`` is defined at the new iterate. For a strongly
    contracting stable direction (a preimage map that expands by ``1 / |lambda_s|``, thousands
    for the impact oscillator's saddles) a full Newton step from a guess a little off lands
    where the map applies other pieces (an impact more or fewer) and the Jacobian of those
    pieces sends the iterate away; the line search keeps the iterates where the residual
    shrinks. Used only where :func:`preimage` has failed, so that every preimage it finds is
    unchanged. ``(guess, None)`` when it fails."""
    z = np.array(guess, dtype=float)
    scale = 1.0 + float(np.max(np.abs(y)))
    Hz, sig, J = sec.evaluate(z, jacobian=True)
    if sig is None:
        return z, None
    res = float(np.max(np.abs(Hz - y)))
    for _ in range(max_iter):
        if res <= tol * scale:
            return z, sig
        try:
            dz = np.linalg.solve(J, -(Hz - y))
        except np.linalg.LinAlgError:
            return z, None
        if not np.all(np.isfinite(dz)):
            return z, None
        u = 1.0
        for _ in range(max_halvings):
            zt = z + u * dz
            Ht, sigt, Jt = sec.evaluate(zt, jacobian=True)
            if sigt is not None:
                rt = float(np.max(np.abs(Ht - y)))
                if rt < (1.0 - 1e-4 * u) * res:
                    break
            u *= 0.5
        else:
            return z, None
        z, Hz, sig, J, res = zt, Ht, sigt, Jt, rt
    return z, sig if res <= tol * scale else None


class Branch:
    """One branch as it grows: points, which are nodes (kinks and piece ends: mapped exactly),
    which segments are jumps (``gap[i]``: from point ``i`` to ``i + 1``)."""

    def __init__(self, q0, q1):
        self.pts = [np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)]
        self.node = [True, False]
        self.gap = [False]
        self.length = float(np.linalg.norm(self.pts[1] - self.pts[0]))
        self.status = "arclength"
        self.unresolved = 0
        self.flickers = 0

    def append(self, y, *, node=False, gap=False):
        if not gap:
            self.length += float(np.linalg.norm(y - self.pts[-1]))
        self.pts.append(y)
        self.node.append(node)
        self.gap.append(gap)

    def pieces(self) -> list:
        """The polyline cut at its jumps: a list of ``(m, n)`` arrays."""
        out, start = [], 0
        for i, g in enumerate(self.gap):
            if g:
                out.append(np.array(self.pts[start:i + 1]))
                start = i + 1
        out.append(np.array(self.pts[start:]))
        return [p for p in out if len(p) >= 1]

    def nodes(self) -> np.ndarray:
        return np.array(self.node, dtype=bool)


def grow(evaluate, q0, q1, sig0, *, arclength: float, max_points: int, max_step: float,
         tol: float, alpha_max: float = 0.3, jump_tol: float, bound: float,
         min_dist: float = 0.0, min_step: float = 1e-14, predict: bool = False) -> Branch:
    """Grow one branch from the fundamental domain ``[q0, q1 = H(q0)]`` (``sig0`` the signature
    of ``H`` at ``q0``) until its arclength exceeds ``arclength`` or it has ``max_points``
    points. ``evaluate(x, guess) -> (H(x), signature)``; ``guess`` is the image of a nearby
    point (used by Newton preimages). With ``predict``, ``evaluate(x, guess, predicted)`` also
    gets a prediction of ``H(x)`` extrapolated from the last two points along the branch in the
    cursor's parameter (``None`` when there is none): where ``H``
    expands strongly (the preimages of a strongly contracting saddle) a cursor step ``h`` moves
    the image by ``h / |lambda_s|`` times a chord, far from the last point."""
    br = Branch(q0, q1)
    # (cursor, image) of the last points accepted along the current piece, for the predictor
    hist = [(0.0, br.pts[1])]
    last_pred = [None]
    h_done = [0.0]          # the cursor's last accepted step

    def call(x, guess, s_x):
        if not predict:
            return evaluate(x, guess)
        pred = last_pred[0] = None
        if len(hist) >= 2 and hist[-1][0] > hist[-2][0]:
            (sa_, ya_), (sb_, yb_) = hist[-2], hist[-1]
            pred = last_pred[0] = yb_ + (s_x - sb_) / (sb_ - sa_) * (yb_ - ya_)
        return evaluate(x, guess, pred)
    pts, node, gap = br.pts, br.node, br.gap
    dalpha_max = 8.0 * tol

    def x_at(s):
        i = int(math.floor(s))
        if i >= len(pts) - 1:
            return pts[-1]
        u = s - i
        if u == 0.0:
            return pts[i]
        return pts[i] + u * (pts[i + 1] - pts[i])

    def angle(a, b):
        na, nb = np.linalg.norm(a), np.linalg.norm(b)
        if na == 0.0 or nb == 0.0:
            return 0.0
        c = float(np.dot(a, b)) / (na * nb)
        return math.acos(max(-1.0, min(1.0, c)))

    def bisect(sa, sig_a, ya, sb, yb, sig_b):
        """The change of signature between cursor positions ``sa < sb``: the last position
        with ``sig_a`` and the first with another, with their images and signatures, and
        whether the map jumps there. A jump is a distance between the two sides' images that
        does not shrink as the bracket does: after the bracket shrank by ``2**20`` the
        distance of a continuous map (Lipschitz, or a square root at grazing) has shrunk by
        ``2**10`` at least, a jump's not at all."""
        gaps = []
        for _ in range(200):
            xa, xb = x_at(sa), x_at(sb)
            if float(np.max(np.abs(xb - xa))) <= 4 * EPS * (1.0 + float(np.max(np.abs(xa)))):
                break
            sm = 0.5 * (sa + sb)
            if not sa < sm < sb:
                break
            # no prediction in a bisection: its points are where plain Newton from the
            # bracket's end decides, so that a border (or the branch's end) is located as before
            ym, sigm = evaluate(x_at(sm), ya)
            if sigm == sig_a:
                sa, ya = sm, ym
            else:
                sb, yb, sig_b = sm, ym, sigm
            if yb is not None and sig_b is not None:
                gaps.append(float(np.linalg.norm(yb - ya)))
        jump = False
        if sig_b is not None and gaps:
            final = gaps[-1]
            earlier = gaps[-21] if len(gaps) > 20 else None
            if earlier is not None:
                jump = final > 0.5 * earlier and final > jump_tol * (1.0 + float(
                    np.max(np.abs(yb))))
            else:
                jump = final > jump_tol * (1.0 + float(np.max(np.abs(yb))))
        return sa, ya, sb, yb, sig_b, jump

    s = 0.0
    s_sig = sig0
    h = 1.0
    next_node = 1          # where the cursor must stop next (a forward scan: see below)
    scale_bound = bound
    while br.length < arclength and len(pts) < max_points:
        if s >= len(pts) - 1:
            # the cursor reached the end of the branch: the map does not expand along it
            br.status = "stalled"
            break
        # the cursor stops at the next node, or at the last point computed
        while next_node < len(pts) - 1 and (next_node <= s or not node[next_node]):
            next_node += 1
        s_lim = float(next_node)
        s1 = min(s + h, s_lim)
        y1, sig1 = call(x_at(s1), pts[-1], s1)
        border = None
        if predict and sig1 is None and s1 - s > 1e-6 and (
                last_pred[0] is None or s1 - s > h_done[0]
                or float(np.linalg.norm(last_pred[0] - pts[-1])) > max_step):
            # no preimage found, and none predicted (the first steps of a branch or piece) or
            # the predicted one farther than the distance criterion allows (the step would be
            # refused anyway): the step is halved (Newton from nearer) before a failure is
            # taken for the end of the branch (the preimage leaves the section, or none
            # exists) and located by bisection
            h = 0.5 * (s1 - s)
            continue
        if sig1 != s_sig:
            sa, ya, sb, yb, sig_b, jump = bisect(s, s_sig, pts[-1], s1, y1, sig1)
            if sa == s and sig1 is not None and not jump:
                # the signature changes at the cursor itself: the point the branch ends at is
                # (to rounding) on the border, where the event detection of a grazing orbit
                # may go either way; continuous there, so the new signature is taken and the
                # step goes on (bisecting again would advance by one ulp at a time)
                s_sig = sig1
                br.flickers += 1
            else:
                border = (sb, yb, sig_b, jump)
                s1, y1 = sa, ya
        d = float(np.linalg.norm(y1 - pts[-1]))
        a = 0.0
        if len(pts) >= 2 and not node[-1] and d > 0.0:
            a = angle(pts[-1] - pts[-2], y1 - pts[-1])
        # below min_dist the angle is not asked for: the direction of a very short chord is
        # that of the rounding (or integration) error of its ends
        ok = d <= max_step and (d < min_dist or (a <= alpha_max and d * a <= dalpha_max))
        if not ok:
            if (s1 - s) > min_step:
                h = 0.5 * (s1 - s)
                continue
            br.unresolved += 1
            h = max(h, 1e6 * min_step)
        if not np.all(np.isfinite(y1)) or float(np.max(np.abs(y1))) > scale_bound:
            br.status = "diverged"
            break
        at_node = border is None and s1 == s_lim and node[next_node]
        if d > 0.0:
            br.append(y1, node=bool(border is not None or at_node))
        else:
            node[-1] = node[-1] or border is not None or at_node
        h_done[0] = s1 - s
        s = s1
        if predict and (not hist or s1 > hist[-1][0]):
            hist.append((s1, y1))
            del hist[:-2]
        if ok and d < 0.25 * max_step and (d < min_dist or (
                a < 0.25 * alpha_max and d * a < 0.25 * dalpha_max)):
            h *= 2.0
        if border is not None:
            sb, yb, sig_b, jump = border
            if sig_b is None:
                br.status = "undefined"    # no piece applies beyond the border (or Newton fails)
                break
            node[-1] = True
            if jump:
                br.append(yb, node=True, gap=True)
            s, s_sig = sb, sig_b
            hist[:] = [(sb, yb)]
            continue
        if at_node and next_node < len(gap) and gap[next_node]:
            # the end of a piece of the preimage: the next piece's image starts a piece here
            y2, sig2 = call(pts[next_node + 1], pts[-1], float(next_node + 1))
            if sig2 is None:
                br.status = "undefined"
                break
            br.append(y2, node=True, gap=True)
            s, s_sig = float(next_node + 1), sig2
            hist[:] = [(s, y2)]
            continue
        s_sig = sig1
    else:
        br.status = "arclength" if br.length >= arclength else "max_points"
    return br
