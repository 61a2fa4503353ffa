"""Admissibility: whether a solution of an orbit problem (:class:`~pwsdyn.orbits.OrbitProblem`)
is an orbit of the hybrid model. On a fixed signature nothing stops a segment at a surface it
is not meant to end at, so a solution past a grazing is checked here along its segments and
at its boundaries."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._base import ADMISSIBILITY_RTOL
from ._sampling import lowest_point
from .surfaces import (ScalarFunction, guard_holds, normal_acceleration, normal_velocity,
                       state_field, surface)


@dataclass(frozen=True)
class Admissibility:
    """Whether a solution of an orbit problem is an orbit of the hybrid model.

    Attributes
    ----------
    admissible : bool
    reason : str or None
        The first violation, in words (``None`` when admissible).
    violations : tuple of str
        Every violation found.
    """

    admissible: bool
    reason: str | None = None
    violations: tuple = ()

    def __bool__(self):
        return self.admissible


def admissibility(prob, u, p=None, evaluation=None
                  ) -> Admissibility:
    """Whether ``(u, p)`` is an orbit of the hybrid model (see the module docstring).

    Checked, for each segment: a positive duration; no event of its discrete state fires
    inside it (an impact surface stays on its admissible side ``h >= 0``, a transition's
    surface is not crossed in its direction where its guard holds), a mode stays on its
    side of every switching surface, sticking keeps a pressing contact (the free normal
    acceleration is not positive), sliding stays in the sliding region (the fields on both
    sides point into the surface). At each boundary: the flow meets the surface in the
    event's direction (an impact with the flow arriving, ``h_t + h_x f <= 0``), its guard
    holds, a crossing has both fields on the same side and a sliding entry both fields
    pointing into the surface, and a chattering sequence starts with an arriving flow and a
    pressing acceleration. "Zero" is within ``ADMISSIBILITY_RTOL (1 + |x|)`` (times the
    gradient's size; durations within ``ADMISSIBILITY_RTOL`` times the period): an orbit
    exactly at a grazing is admissible. Segments are checked on
    their dense output (8 points per step and the refined minima between them).
    """
    p = prob._p(p)
    ev = evaluation if evaluation is not None else prob.evaluate(u, p, jacobian=False)
    ctx = prob._context_at(p)
    out = []
    # a segment that vanishes at a graze (a sliding segment shrinking to nothing) has a
    # duration of round-off size, of either sign, at the located point
    t_band = ADMISSIBILITY_RTOL * max(1.0, sum(abs(float(s.T)) for s in ev.segs))
    for i, s in enumerate(ev.segs):
        name = prob.state_names[i]
        if s.T < -t_band:
            out.append(f"segment {i} ({name}) has a negative duration {s.T:.3e}: the "
                       f"event that should end it comes before its start")
            continue
        if s.T > 0:
            out += _interior(prob, i, s, ctx, p)
        if i < len(prob.bounds):
            out += _at_boundary(prob, i, s, ctx)
    return Admissibility(not out, out[0] if out else None, tuple(out))


def _interior(prob, i, s, ctx, p):
    n = prob.n
    tr, ts, Y = prob._dense_samples(i, s, p)
    if tr is None or not len(ts):
        return []
    scale = 1.0 + float(np.max(np.abs(Y)))
    fk = prob.fields[i]
    m = prob.model
    checks = []   # ("side", label, fn, sign): sign * fn >= -band; ("event", label, fn, j)
    if fk.kind in ("mode", "stick"):
        mode = fk.index if fk.kind == "mode" else fk.mode
        for j, e in enumerate(m.events):
            if mode not in e.modes:
                continue
            if fk.kind == "stick" and e.surface == m.events[fk.index].surface:
                continue
            checks.append(("event", f"{e.kind} event {e.name!r}", surface(ctx, e.surface), j))
        for sw in m.switches:
            if sw.above == mode:
                checks.append(("side", f"side of switching surface {sw.name!r} (mode "
                               f"{m.modes[mode].name!r} holds above it)",
                               surface(ctx, sw.surface), +1))
            elif sw.below == mode:
                checks.append(("side", f"side of switching surface {sw.name!r} (mode "
                               f"{m.modes[mode].name!r} holds below it)",
                               surface(ctx, sw.surface), -1))
        if fk.kind == "stick":
            k = m.events[fk.index].surface
            checks.append(("side", f"contact of sticking on {m.events[fk.index].name!r} "
                           f"(the free normal acceleration must press into the surface)",
                           normal_acceleration(ctx, k, fk.mode), -1))
    elif fk.kind == "slide_multi":
        # the weights of the multilinear field stay in [0, 1] (each surface's corner fields
        # keep pointing into it): a weight below 0 or above 1 is a surface the motion has
        # left to the side above or below without its slide_end
        names = [m.surfaces[k].name for k in range(len(m.surfaces)) if (fk.index >> k) & 1]
        for j, nm in enumerate(names):
            lam = _weight(prob, i, j, p)
            checks.append(("side", f"sliding region of {nm!r} on the intersection (its weight "
                           f"must stay >= 0)", lam, +1))
            checks.append(("side", f"sliding region of {nm!r} on the intersection (its weight "
                           f"must stay <= 1)", ScalarFunction(lambda t, x, f=lam: f(t, x) - 1.0),
                           -1))
        corners = {fk.mode}
        for k in range(len(m.surfaces)):
            if (fk.index >> k) & 1:
                corners |= {sw.below for sw in m.switches
                            if sw.surface == k and sw.above in corners}
        for j, e in enumerate(m.events):
            if corners & set(e.modes):
                checks.append(("event", f"{e.kind} event {e.name!r}", surface(ctx, e.surface),
                               j))
    else:
        sw = m.switches[fk.index]
        k = sw.surface
        checks.append(("side", f"sliding region of {sw.name!r} (the field above must point "
                       f"into the surface)", normal_velocity(ctx, k, sw.above), -1))
        checks.append(("side", f"sliding region of {sw.name!r} (the field below must point "
                       f"into the surface)", normal_velocity(ctx, k, sw.below), +1))
        for j, e in enumerate(m.events):
            if sw.above in e.modes or sw.below in e.modes:
                checks.append(("event", f"{e.kind} event {e.name!r}", surface(ctx, e.surface),
                               j))
    out = []
    for what, label, fn, rule in checks:
        # a surface's values on the samples: shared with the monitors of the point
        vals = (fn.rows(ts, Y) if fn.surface is None
                else prob._surface_samples(i, s, p, fn.surface, ctx))
        band = ADMISSIBILITY_RTOL * scale * fn.gscale
        if what == "side":
            worst = lowest_point(fn, tr, ts, vals, rule, n, limit=-band)
            if rule * worst[1] < -band:
                out.append(f"segment {i} ({prob.state_names[i]}) leaves the {label}: "
                           f"value {worst[1]:.3e} at t = {worst[0]:.10g}")
            continue
        # an event of the model: does it fire inside the segment?
        e = m.events[rule]
        if e.kind == "impact":
            worst = lowest_point(fn, tr, ts, vals, +1, n, limit=-band)
            if worst[1] < -band and guard_holds(ctx, rule, worst[0], tr(worst[0])[:n]):
                out.append(f"segment {i} ({prob.state_names[i]}) passes through the "
                           f"constraint of impact event {e.name!r}: h = {worst[1]:.3e} < 0 "
                           f"at t = {worst[0]:.10g} (the orbit is past a grazing)")
            continue
        for kk in range(1, len(vals)):
            a, bb = vals[kk - 1], vals[kk]
            crossed = ((e.direction <= 0 and a > band and bb < -band)
                       or (e.direction >= 0 and a < -band and bb > band))
            if crossed and guard_holds(ctx, rule, ts[kk], Y[kk]):
                out.append(f"segment {i} ({prob.state_names[i]}) crosses the surface of "
                           f"transition {e.name!r} near t = {ts[kk]:.10g} without the "
                           f"event")
                break
    return out


def _at_boundary(prob, i, s, ctx):
    b = prob.bounds[i]
    n, m = prob.n, prob.model
    te, y = s.te, s.y[:n]
    st = prob.state_names[i]
    scale = 1.0 + float(np.max(np.abs(y)))
    out = []
    if b.kind in ("impact", "transition", "chatter"):
        e = m.events[b.ref]
        rate, hx = boundary_normal_velocity(prob, i, s, ctx)
        band = ADMISSIBILITY_RTOL * scale * max(1.0, float(np.max(np.abs(hx))))
        d = -1 if b.kind == "chatter" else e.direction
        if d * rate < -band:
            what = ("the flow leaves the constraint there instead of hitting it (an impact "
                    "with the wrong sign of the normal velocity)" if e.kind == "impact"
                    else "the flow crosses the surface against the event's direction")
            out.append(f"{b.kind} {e.name!r} ending segment {i} ({st}) at t = {te:.10g}: "
                       f"h_t + h_x f = {rate:.3e}; {what}")
        if not guard_holds(ctx, b.ref, te, y):
            out.append(f"{b.kind} {e.name!r} ending segment {i} at t = {te:.10g}: its "
                       f"guard does not hold")
        if b.kind == "chatter":
            acc = normal_acceleration(ctx, b.surface, b.mode)(te, y)
            if acc > ADMISSIBILITY_RTOL * scale:
                out.append(f"chattering on {e.name!r} at t = {te:.10g}: the free normal "
                           f"acceleration {acc:.3e} pulls away from the surface")
            if s.tau < te:
                out.append(f"chattering on {e.name!r} at t = {te:.10g}: the accumulation "
                           f"time lies before the first impact")
    if b.kind == "slide_start" and prob.fields[(i + 1) % prob.m].kind == "slide_multi":
        # entry into sliding on an intersection: the weights of the multilinear field in
        # [0, 1] at the entry (the fields of every corner point into the intersection)
        lam = prob.multi_weights((i + 1) % prob.m, [te], [y])[0]
        band = ADMISSIBILITY_RTOL * scale
        if lam.min() < -band or lam.max() > 1 + band:
            out.append(f"sliding on {prob.state_names[(i + 1) % prob.m]!r} starts at "
                       f"t = {te:.10g} where its weights {np.round(lam, 12).tolist()} are not "
                       f"all in [0, 1] (the intersection does not attract the motion)")
    elif b.kind in ("crossing", "slide_start"):
        sw = m.switches[b.ref]
        ha = normal_velocity(ctx, b.surface, sw.above)(te, y)
        hb = normal_velocity(ctx, b.surface, sw.below)(te, y)
        band = ADMISSIBILITY_RTOL * scale * normal_velocity(ctx, b.surface, sw.above).gscale
        if b.kind == "slide_start":
            if ha > band or hb < -band:
                out.append(f"sliding on {sw.name!r} starts at t = {te:.10g} where the "
                           f"fields do not both point into the surface (h_t + h_x f = "
                           f"{ha:.3e} above, {hb:.3e} below)")
        else:
            if ha * hb < 0 and abs(ha) > band and abs(hb) > band:
                out.append(f"crossing of {sw.name!r} at t = {te:.10g} where the fields "
                           f"point to opposite sides (h_t + h_x f = {ha:.3e} above, "
                           f"{hb:.3e} below): the orbit should slide or cannot reach it")
    return out


def boundary_normal_velocity(prob, i, s, ctx):
    """``(h_t + h_x f, h_x)`` at the event ending segment ``i`` (``s``, of an evaluation at
    the parameter values of ``ctx``): the normal velocity of the segment's field on the
    boundary's surface and the surface's gradient there, computed once for the admissibility
    check and the monitors of a point (kept on ``s``)."""
    got = s.__dict__.get("_normal_velocity")
    if got is None or got[0] is not ctx:
        b = prob.bounds[i]
        te, y = s.te, s.y[:prob.n]
        f_in = state_field(ctx, prob.fields[i], te, y)
        hx = ctx.h_x(b.surface, te, y)
        got = (ctx, ctx.h_t(b.surface, te, y) + hx @ f_in, hx)
        s.__dict__["_normal_velocity"] = got
    return got[1], got[2]


def _weight(prob, i, j, p) -> ScalarFunction:
    """The weight ``lambda_j`` of segment ``i``'s sliding on an intersection, as a function
    of ``(t, x)``."""
    def fn(t, x):
        return float(prob.multi_weights(i, [t], [x], p)[0, j])
    return ScalarFunction(fn, rows=lambda ts, X: prob.multi_weights(i, ts, X, p)[:, j])
