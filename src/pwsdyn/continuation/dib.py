"""Past a discontinuity-induced bifurcation: the orbit's new signature and a start on it.

At a graze located on an orbit branch (monitor ``GR`` of
:meth:`pwsdyn.orbits.OrbitProblem.dib_monitors`) the orbit's sequence of events changes:

* a segment touching an impact surface inside it (``GR/<surface>/<i>``): past the graze it
  hits the surface -- an impact is added, splitting segment ``i``;
* an impact whose normal velocity goes to zero (``GR/<event>@<i>``): past it the orbit no
  longer reaches the surface -- the impact is removed, joining segments ``i`` and ``i + 1``;
* a segment touching a Filippov surface where the field beyond points back
  (``GS/<surface>/<i>``, grazing-sliding): past it the orbit slides on the surface -- a
  sliding segment (``slide_start``, ``slide_end``) is added inside segment ``i``;
* a sliding entry reaching the other boundary of the sliding region (``SS/<switch>@<i>``,
  switching-sliding): past it the orbit crosses, runs a short arc in the other mode and
  comes back to slide -- the entry becomes a crossing and an entry from the other side;
  seen from the crossing side (``SS`` at a crossing followed by that arc) the arc goes;
* a crossing point reaching the boundary of the sliding region where the sliding flow leaves
  it (``CS/<switch>@<i>``, crossing-sliding): past it the orbit slides a short way there --
  the crossing becomes an entry, a sliding segment and an exit; seen from the sliding side
  (an entry whose sliding segment leaves into the mode beyond) the sliding segment goes;
* the sliding flow touching the boundary of the sliding region inside a sliding segment
  (``AS/<switch>:<side>/<i>``, adding-sliding): past it the orbit leaves there, runs an arc
  and slides again -- the segment is split; seen from the split side (``AS/<switch>@<i>``,
  an exit whose field no longer curves away) the two sliding segments join;
* an orbit arriving ever more tangentially at a sliding entry that leaves back into the same
  mode (``GS/<switch>@<i>``, grazing-sliding from its sliding side): the sliding segment goes;
* an arc between two crossings of one surface shrinking to nothing (``GR/<surface>/<i>/arc``):
  both crossings and the arc go;
* an event point reaching another surface (``CC``, a corner collision): the order of the
  events around the corner changes in ways the old sequence does not tell, so the new one is
  the sequence a direct simulation follows over one period from the old orbit, a short step
  past the corner.

Where the old signature has no solution past the bifurcation (a segment that shrank to
nothing: the locked branch folds back there), the new signature is built at the bifurcation
itself and solved past it.

The new problem is singular at the graze itself (its event condition's derivative
``h_x f`` vanishes there) and the new orbit lies a square root of the parameter distance
away (the new impact's velocity; thesis Paper A). So the start is taken a short step
``delta`` past the graze: the old signature is solved there (a regular problem: it only
crosses the surface), and its crossing of the surface gives the new signature's guess -- the
impact where the old orbit enters the constraint, or the old impact removed -- which Newton
on the new problem corrects (its Jacobian is regular there: the crossing is transversal).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from ..newton import TrialRejected


def _segment_mode(op, seg):
    """The mode of segment ``seg``, or ``None`` where re-segmenting it is not supported (a
    sticking or sliding segment, or boundaries made of several events)."""
    if len(op.bounds) != len(op.signature) or op.fields[seg].kind != "mode":
        return None
    return op.fields[seg].index


def _old_segment(op, u, lam, seg):
    """``(p, segment, dense trajectory, context)`` of segment ``seg`` of the old signature's
    solution ``u`` at ``lam``."""
    from ..orbits.surfaces import model_context

    p = np.array([lam])
    s = op.evaluate(u, p, jacobian=False).segs[seg]
    return (p, s, op.dense_segment(seg, s, p),
            model_context(op.model, op.param_dict(p), op.sliding))


def insert_impact(op, u, lam, seg: int, surface_name: str, touch: bool = False):
    """The problem with an impact on ``surface_name`` added inside segment ``seg`` and its
    ``u`` at ``lam`` from the old signature's solution there (which crosses the surface):
    ``(problem, u)`` or a reason string. With ``touch`` an orbit that only touches the
    surface (the graze itself) gets its impact at the point of tangency, where ``h`` is
    least: the new orbit on the side where the old one does not reach the surface (a
    non-smooth fold) starts there."""
    from ..orbits.signature import Signature, SignatureEvent

    m = op.model
    n = op.n
    mode = _segment_mode(op, seg)
    if mode is None:
        return "only segments in a mode ending in single events are re-segmented"
    events = [(j, e) for j, e in enumerate(m.events)
              if e.kind == "impact" and mode in e.modes
              and m.surfaces[e.surface].name == surface_name]
    if not events:
        return f"no impact event on surface {surface_name!r} in the segment's mode"
    j, e = events[0]
    p, s, tr, ctx = _old_segment(op, u, lam, seg)

    def h(t):
        return ctx.h(e.surface, t, tr(t)[:n])
    ts = np.linspace(s.t, s.t + s.T, 400)[1:-1]
    hv = np.array([h(t) for t in ts])
    k = np.flatnonzero((hv[:-1] > 0) & (hv[1:] <= 0))
    if k.size:
        ta = brentq(h, ts[k[0]], ts[k[0] + 1], xtol=1e-14)
    elif touch:
        i = int(np.argmin(hv))
        lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, ts.size - 1)]
        ta = float(minimize_scalar(h, bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-13}).x)
    else:
        return "the orbit past the graze does not cross the surface"
    xa = tr(ta)[:n]
    xr = ctx.g(j, ta, xa)
    t0, xs, Ts = op.unpack(u)
    xs, Ts = [np.asarray(x, dtype=float) for x in xs], list(Ts)
    mname = op.state_names[seg]
    new_ev = SignatureEvent("impact", e.name, mname, mname)
    if not op.m:
        prob = op.replace(signature=Signature([new_ev]))
        P = op.period_value(p)
        return prob, prob.pack(ta, [xr], [P])
    prob = op.replace(signature=list(op.signature[:seg]) + [new_ev] +
                      list(op.signature[seg:]))
    xs2 = xs[:seg + 1] + [xr] + xs[seg + 1:]
    Ts2 = Ts[:seg] + [ta - s.t, s.t + s.T - ta] + Ts[seg + 1:]
    return prob, prob.pack(t0, xs2, Ts2)


def remove_impact(op, u, lam, seg: int):
    """The problem with the impact ending segment ``seg`` removed (its velocity went to zero)
    and its ``u`` at ``lam`` from the old solution there: ``(problem, u)`` or a reason."""
    if len(op.bounds) != len(op.signature):
        return "only orbits whose boundaries are single events are re-segmented"
    p = np.array([lam])
    ev = op.evaluate(u, p, jacobian=False)
    t0, xs, Ts = op.unpack(u)
    xs, Ts = [np.asarray(x, dtype=float) for x in xs], list(Ts)
    mm = op.m
    if mm == 1:
        s = ev.segs[0]
        if op.fields[0].kind != "mode":
            return "the segment is not in a mode"
        prob = op.replace(signature=[], t_ref=float(s.te), state=str(op.state_names[0]))
        return prob, prob.pack(float(s.te), [np.asarray(s.y[:op.n], dtype=float)],
                               [op.period_value(p)])
    nxt = (seg + 1) % mm
    if op.fields[seg] != op.fields[nxt]:
        return "the segments on either side of the impact are in different states"
    sig = [e for k, e in enumerate(op.signature) if k != seg]
    if nxt == 0:
        # the removed impact ends the last segment: the first segment now starts where the
        # last one did
        t0 = t0 - Ts[-1]
        xs2 = [xs[-1]] + xs[1:-1]
        Ts2 = [Ts[-1] + Ts[0]] + Ts[1:-1]
    else:
        xs2 = xs[:nxt] + xs[nxt + 1:]
        Ts2 = Ts[:seg] + [Ts[seg] + Ts[nxt]] + Ts[nxt + 1:]
    prob = op.replace(signature=sig)
    return prob, prob.pack(t0, xs2, Ts2)


def insert_sliding(op, u, lam, seg: int, surface_name: str):
    """The problem with a sliding segment on the Filippov surface ``surface_name`` added
    inside segment ``seg`` (past a grazing-sliding) and its ``u`` at ``lam`` from the old
    signature's solution there, which crosses the surface and comes back: sliding from where
    it enters to where it returns (Newton moves the exit to where the sliding field leaves):
    ``(problem, u)`` or a reason string."""
    from ..orbits.signature import SignatureEvent

    m = op.model
    n = op.n
    mode = _segment_mode(op, seg)
    if mode is None:
        return "only segments in a mode ending in single events are re-segmented"
    sws = [sw for sw in m.switches if sw.kind == "filippov" and mode in (sw.above, sw.below)
           and m.surfaces[sw.surface].name == surface_name]
    if not sws:
        return f"no Filippov switch on surface {surface_name!r} bounds the segment's mode"
    sw = sws[0]
    sign = 1.0 if mode == sw.above else -1.0
    p, s, tr, ctx = _old_segment(op, u, lam, seg)

    def g(t):
        return sign * ctx.h(sw.surface, t, tr(t)[:n])
    ts = np.linspace(s.t, s.t + s.T, 400)[1:-1]
    gv = np.array([g(t) for t in ts])
    k_in = np.flatnonzero((gv[:-1] > 0) & (gv[1:] <= 0))
    if not k_in.size:
        return "the orbit past the graze does not reach the surface"
    k_out = np.flatnonzero((gv[:-1] <= 0) & (gv[1:] > 0))
    k_out = k_out[k_out > k_in[0]]
    if not k_out.size:
        return "the orbit past the graze does not come back across the surface"
    ta = brentq(g, ts[k_in[0]], ts[k_in[0] + 1], xtol=1e-14)
    tb = brentq(g, ts[k_out[0]], ts[k_out[0] + 1], xtol=1e-14)
    xa, xb = tr(ta)[:n], tr(tb)[:n]
    mname = op.state_names[seg]
    sname = f"slide:{sw.name}"
    start = SignatureEvent("slide_start", sw.name, mname, sname)
    end = SignatureEvent("slide_end", sw.name, sname, mname)
    t0, xs, Ts = op.unpack(u)
    xs, Ts = [np.asarray(x, dtype=float) for x in xs], list(Ts)
    if not op.m:
        P = op.period_value(p)
        prob = op.replace(signature=[start, end])
        return prob, prob.pack(tb, [xb, xa], [ta + P - tb, tb - ta])
    prob = op.replace(signature=list(op.signature[:seg]) + [start, end] +
                      list(op.signature[seg:]))
    xs2 = xs[:seg + 1] + [xa, xb] + xs[seg + 1:]
    Ts2 = Ts[:seg] + [ta - s.t, tb - ta, s.t + s.T - tb] + Ts[seg + 1:]
    return prob, prob.pack(t0, xs2, Ts2)


def _opts(op):
    from ..integrate.simulate import DEFAULTS

    drop = ("variational", "dense", "throw", "mode", "sliding")
    return {k: v for k, v in op.opts.items() if k in DEFAULTS and k not in drop}


def insert_crossing(op, u, lam, seg: int):
    """Past a switching-sliding at the sliding entry ending segment ``seg``: the orbit now
    reaches the surface where the field beyond it points away, crosses, runs a short arc in
    the other mode and comes back to slide. The entry is replaced by a crossing and an entry
    from the other side; the arc's guessed duration is the parabola's return time
    ``2 |hdot / hddot|`` of the other mode's normal velocity and acceleration there:
    ``(problem, u)`` or a reason string."""
    from ..orbits.signature import SignatureEvent
    from ..orbits.surfaces import model_context, normal_acceleration, normal_velocity

    m = op.model
    b = op.bounds[seg]
    fk = op.fields[seg]
    if b.kind != "slide_start" or fk.kind != "mode" or len(op.bounds) != len(op.signature):
        return "only a sliding entry from a mode is re-segmented"
    sw = m.switches[b.ref]
    other = sw.above if fk.index == sw.below else sw.below
    p = np.array([lam])
    ev = op.evaluate(u, p, jacobian=False)
    s = ev.segs[seg]
    te, y = float(s.te), np.asarray(s.y[:op.n], dtype=float)
    ctx = model_context(m, op.param_dict(p), op.sliding)
    hd = normal_velocity(ctx, b.surface, other)(te, y)
    acc = normal_acceleration(ctx, b.surface, other)(te, y)
    if hd * acc >= 0.0 or acc == 0.0:
        return "the other mode's arc does not come back to the surface"
    tau = 2.0 * abs(hd / acc)
    m1, m2 = op.state_names[seg], m.mode_names[other]
    old = op.signature[seg]
    new = [SignatureEvent("crossing", sw.name, m1, m2),
           SignatureEvent("slide_start", sw.name, m2, old.mode_after)]
    prob = op.replace(signature=list(op.signature[:seg]) + new + list(op.signature[seg + 1:]))
    t0, xs, Ts = op.unpack(u)
    xs, Ts = [np.asarray(x, dtype=float) for x in xs], list(Ts)
    nxt = (seg + 1) % len(Ts)
    xs2 = xs[:seg + 1] + [y] + xs[seg + 1:]
    Ts2 = Ts[:seg + 1] + [tau] + Ts[seg + 1:]
    # the segment after the entry (the sliding one) starts tau later
    if nxt == 0:
        t0 += tau
        Ts2[0] -= tau
    else:
        Ts2[nxt + 1] -= tau
    return prob, prob.pack(t0, xs2, Ts2)


def _segments(op, u):
    """The solution ``u`` as a list of ``[start time, start state, duration]``, one per
    segment (the signature's events end them in turn)."""
    t0, xs, Ts = op.unpack(u)
    out, t = [], float(t0)
    for x, T in zip(xs, Ts):
        out.append([t, np.asarray(x, dtype=float), float(T)])
        t += float(T)
    return out


def _pack(prob, segs):
    """``u`` of ``prob`` from segments ``[start time, start state, duration]``."""
    return prob.pack(segs[0][0], [x for _, x, _ in segs], [T for _, _, T in segs])


def slide_at_crossing(op, u, lam, seg: int):
    """Past a crossing-sliding at the crossing ending segment ``seg`` (the field beyond now
    points back at the crossing point): the orbit slides from there to the sliding region's
    boundary, where the field beyond becomes tangent, and leaves into the mode it crossed
    into. The crossing becomes a sliding entry, a sliding segment and its exit; the slide's
    guessed duration is the time for the field beyond's normal velocity ``hdot`` to reach zero
    at its rate along the sliding field, ``|hdot / (d hdot / dt)|``: ``(problem, u)`` or a
    reason string."""
    from ..orbits.signature import SignatureEvent
    from ..orbits.surfaces import (FieldKey, model_context, normal_velocity,
                                   sliding_boundary_rate, state_field)

    m = op.model
    b = op.bounds[seg]
    fk = op.fields[seg]
    if b.kind != "crossing" or fk.kind != "mode" or len(op.bounds) != len(op.signature):
        return "only a crossing out of a mode is re-segmented"
    sw = m.switches[b.ref]
    beyond = sw.above if fk.index == sw.below else sw.below
    p = np.array([lam])
    s = op.evaluate(u, p, jacobian=False).segs[seg]
    te, y = float(s.te), np.asarray(s.y[:op.n], dtype=float)
    ctx = model_context(m, op.param_dict(p), op.sliding)
    fs = state_field(ctx, FieldKey("slide", b.ref), te, y)
    hd = normal_velocity(ctx, b.surface, beyond)(te, y)
    rate = sliding_boundary_rate(ctx, b.ref, beyond, te, y)
    if hd * rate >= 0.0:
        return "the sliding flow does not carry the crossing point to the region's boundary"
    tau = abs(hd / rate)
    sname = f"slide:{sw.name}"
    old = op.signature[seg]
    new = [SignatureEvent("slide_start", sw.name, old.mode_before, sname),
           SignatureEvent("slide_end", sw.name, sname, old.mode_after)]
    prob = op.replace(signature=list(op.signature[:seg]) + new + list(op.signature[seg + 1:]))
    segs = _segments(op, u)
    nxt = (seg + 1) % len(segs)
    t_b, x_b, T_b = segs[nxt]
    segs[nxt] = [t_b + tau, y + tau * fs, T_b - tau]
    slide = [te, y, tau]
    if nxt == 0:
        segs.append(slide)
        # the exit now starts the first segment a little later
    else:
        segs.insert(seg + 1, slide)
    return prob, _pack(prob, segs)


def _merge_next(op, u, lam, seg: int, event):
    """The event ending segment ``seg`` replaced by ``event`` and the next segment dropped,
    its duration given to the one after it, which now starts where the dropped one did:
    ``(problem, u)``."""
    mm = len(op.signature)
    j, k = (seg + 1) % mm, (seg + 2) % mm
    sig = list(op.signature)
    sig[seg] = event
    segs = _segments(op, u)
    t_j, x_j, T_j = segs[j]
    T_k = segs[k][2]
    # where the merged segment is the first one, it starts a period before the dropped one
    # (an autonomous orbit has no forcing period: its period is its segments' durations)
    P = 0.0 if k != 0 else (op.period_value(np.array([lam])) if op.forced
                            else float(sum(seg_[2] for seg_ in segs)))
    segs[k] = [t_j - P, x_j, T_j + T_k]
    del segs[j]
    del sig[j]
    prob = op.replace(signature=sig)
    return prob, _pack(prob, segs)


def split_sliding(op, u, lam, seg: int, side: str):
    """Past an adding-sliding on sliding segment ``seg``: the sliding flow of the old solution
    now leaves the sliding region on an interval ``(ta, tb)`` (the field on ``side`` points
    away there). The orbit leaves at ``ta`` into that side's mode, runs a short arc and slides
    again: the segment is split by an exit, an arc (guessed as lasting ``tb - ta``) and an
    entry: ``(problem, u)`` or a reason string."""
    from ..orbits.signature import SignatureEvent
    from ..orbits.surfaces import normal_velocity

    m = op.model
    fk = op.fields[seg]
    if fk.kind == "slide_multi":
        # the weight of one surface touches 0 or 1 inside the segment: past it that contact
        # releases and sticks again while the others stick on (a slide_end, a segment
        # sliding on the rest, a slide_start), a signature not built here
        return (f"a weight of segment {seg}'s sliding on an intersection reaches the edge of "
                f"[0, 1] inside it (a contact releases and sticks again there); splitting "
                f"such a segment is not supported")
    if fk.kind != "slide" or len(op.bounds) != len(op.signature):
        return "only a sliding segment between single events is split"
    sw = m.switches[fk.index]
    mode, sign = (sw.above, -1.0) if side == "above" else (sw.below, 1.0)
    p, s, tr, ctx = _old_segment(op, u, lam, seg)
    n = op.n
    hd = normal_velocity(ctx, sw.surface, mode)

    def g(t):                      # positive inside the sliding region
        return sign * hd(t, tr(t)[:n])
    ts = np.linspace(s.t, s.t + s.T, 2001)[1:-1]
    gv = np.array([g(t) for t in ts])
    out = np.flatnonzero((gv[:-1] > 0) & (gv[1:] <= 0))
    if not out.size:
        return "the sliding flow past the adding-sliding stays in the sliding region"
    back = np.flatnonzero((gv[:-1] <= 0) & (gv[1:] > 0))
    back = back[back > out[0]]
    if not back.size:
        return "the sliding flow past the adding-sliding does not come back into the region"
    ta = brentq(g, ts[out[0]], ts[out[0] + 1], xtol=1e-14)
    tb = brentq(g, ts[back[0]], ts[back[0] + 1], xtol=1e-14)
    sname, mname = op.state_names[seg], m.mode_names[mode]
    new = [SignatureEvent("slide_end", sw.name, sname, mname),
           SignatureEvent("slide_start", sw.name, mname, sname)]
    prob = op.replace(signature=list(op.signature[:seg]) + new + list(op.signature[seg:]))
    segs = _segments(op, u)
    t_s, x_s, T_s = segs[seg]
    segs[seg:seg + 1] = [[t_s, x_s, ta - t_s],
                         [ta, np.asarray(tr(ta)[:n], dtype=float), tb - ta],
                         [tb, np.asarray(tr(tb)[:n], dtype=float), t_s + T_s - tb]]
    return prob, _pack(prob, segs)


def join_sliding(op, u, lam, seg: int):
    """Past an adding-sliding seen from its split side (the sliding segment ``seg`` ends in an
    exit whose field no longer curves away, followed by a short arc and an entry back): the
    sliding flow no longer leaves the region there. Exit, arc and entry go, and the two
    sliding segments become one: ``(problem, u)`` or a reason string."""
    mm = len(op.signature)
    if (op.fields[seg].kind != "slide" or op.bounds[seg].kind != "slide_end"
            or len(op.bounds) != mm or mm < 3):
        return "only a sliding exit followed by an arc and an entry back is re-segmented"
    j = (seg + 1) % mm
    if op.bounds[j].kind != "slide_start" or op.bounds[j].ref != op.bounds[seg].ref:
        return "the arc after the exit does not slide again on the same surface"
    return _merge_run(op, u, lam, seg, 2)


def _merge_run(op, u, lam, first: int, drop: int):
    """The ``drop`` events from the one ending segment ``first`` on (cyclically) removed and
    the segments they separated joined into segment ``first`` (its field goes on through
    them): ``(problem, u)``. With no event left the orbit is one segment of a whole period."""
    mm = len(op.signature)
    segs = _segments(op, u)
    pairs = [[segs[r], op.signature[r]] for r in range(mm)]
    gone = [(first + r) % mm for r in range(1, drop + 1)]
    t, x, _ = segs[first]
    pairs[first] = [[t, x, sum(segs[(first + r) % mm][2] for r in range(drop + 1))],
                    op.signature[(first + drop) % mm]]
    if drop >= mm:
        prob = op.replace(signature=[], t_ref=float(t), state=str(op.state_names[first]))
        return prob, prob.pack(float(t), [x], [op.period_value(np.array([lam]))])
    keep = [r for r in range(mm) if r not in gone]
    # the list starts at the first kept segment: times go on cyclically from there
    kept = [pairs[r] for r in keep]
    prob = op.replace(signature=[e for _, e in kept])
    return prob, _pack(prob, [sg for sg, _ in kept])


def remove_sliding(op, u, lam, seg: int):
    """Past a grazing-sliding seen from its sliding side (the sliding entry ending segment
    ``seg`` is followed by an exit back into the same mode): the orbit no longer reaches the
    surface; entry, sliding segment and exit go, and the mode runs on through them:
    ``(problem, u)`` or a reason string."""
    mm = len(op.signature)
    if op.bounds[seg].kind != "slide_start" or len(op.bounds) != mm:
        return "only a sliding entry followed by its exit is re-segmented"
    j = (seg + 1) % mm
    if op.bounds[j].kind != "slide_end" or op.bounds[j].mode != op.bounds[seg].mode:
        return "the sliding segment does not leave into the mode it came from"
    return _merge_run(op, u, lam, seg, 2)


def remove_arc(op, u, lam, seg: int):
    """Past the graze where the arc of segment ``seg`` between two crossings of one surface
    vanished: the orbit stays on the side it crossed from. Both crossings and the arc go,
    and the segments before and after become one: ``(problem, u)`` or a reason string."""
    mm = len(op.signature)
    if len(op.bounds) != mm or mm < 2:
        return "only orbits whose boundaries are single events are re-segmented"
    first = (seg - 1) % mm
    if op.fields[first] != op.fields[(seg + 1) % mm]:
        return "the segments on either side of the arc are in different states"
    return _merge_run(op, u, lam, first, 2)


def slide_instead_of_arc(op, u, lam, seg: int):
    """Past a switching-sliding seen from its crossing side (the crossing ending segment
    ``seg`` is followed by a short arc beyond the surface and a sliding entry back): the
    crossing point is now in the sliding region and the orbit slides from there. The crossing
    becomes the sliding entry and the arc goes: ``(problem, u)`` or a reason string."""
    from ..orbits.signature import SignatureEvent

    mm = len(op.signature)
    b = op.bounds[seg]
    if b.kind != "crossing" or len(op.bounds) != mm or mm < 3:
        return "only a crossing followed by an arc and a sliding entry is re-segmented"
    j = (seg + 1) % mm
    if op.bounds[j].kind != "slide_start" or op.bounds[j].ref != b.ref:
        return "the arc after the crossing does not end sliding on the same surface"
    old_in, old_entry = op.signature[seg], op.signature[j]
    return _merge_next(op, u, lam, seg, SignatureEvent("slide_start", old_entry.name,
                                                       old_in.mode_before,
                                                       old_entry.mode_after))


def cross_instead_of_sliding(op, u, lam, seg: int):
    """Past a crossing-sliding at the sliding entry ending segment ``seg``, whose sliding
    segment leaves into the mode beyond: the entry and the exit have met on the boundary of
    the sliding region, and past it the orbit crosses there. The entry becomes a crossing and
    the sliding segment goes, its duration given to the mode after it (which now starts at
    the entry point): ``(problem, u)`` or a reason string."""
    from ..orbits.signature import SignatureEvent

    mm = len(op.signature)
    b = op.bounds[seg]
    if b.kind != "slide_start" or len(op.bounds) != mm or mm < 3:
        return "only a sliding entry followed by its exit is re-segmented"
    j = (seg + 1) % mm
    if op.bounds[j].kind != "slide_end":
        return "the sliding segment does not end in an exit"
    old_in, old_out = op.signature[seg], op.signature[j]
    return _merge_next(op, u, lam, seg, SignatureEvent("crossing", old_in.name,
                                                       old_in.mode_before, old_out.mode_after))


def resimulated(op, u, lam):
    """Past a bifurcation whose new event sequence is not built from the old one (a corner
    collision, where the order of events around the corner changes): the sequence a direct
    simulation follows over one period from the old solution's start at ``lam`` (close to the
    new orbit, a short step past the bifurcation), and that simulation as the start of
    Newton on it: ``(problem, u)`` or a reason string."""
    from ..orbits.signature import Signature
    from ..orbits.surfaces import model_context

    if not op.forced or len(op.bounds) != len(op.signature):
        return "only forced orbits whose boundaries are single events are re-simulated"
    p = np.array([lam])
    t0, xs, _ = op.unpack(u)
    x0 = np.asarray(xs[0], dtype=float)
    ctx = model_context(op.model, op.param_dict(p), op.sliding)
    st = ctx.state(str(op.state_names[0]))
    P = op.period_value(p)
    opts = dict(op.opts, variational=False, dense=False, throw=False, mode=None)
    try:
        run = ctx.run(x0, st, float(t0), float(t0) + 1.5 * P, opts, admit=False)
    except (ValueError, FloatingPointError) as exc:
        return f"the simulation past the bifurcation failed: {exc}"
    # one period: up to the event back into the starting state nearest to t0 + P (the old
    # start lies on the old orbit's last event, which the new orbit passes a little before
    # or after)
    evs = list(run.event_log(ctx.model))
    start = str(op.state_names[0])
    ends = [i for i, e in enumerate(evs) if str(e.mode_after) == start]
    if not ends:
        return "a simulation past the bifurcation does not come back to its starting state"
    last = min(ends, key=lambda i: abs(float(evs[i].t_after) - float(t0) - P))
    sig = Signature(evs[:last + 1])
    prob = op.replace(signature=list(sig))
    u2 = prob.from_simulation(float(t0), x0, p)
    if u2 is None:
        return f"the simulation past the bifurcation does not repeat its sequence {sig}"
    return prob, u2


def past_graze(op, key: str, u, lam, solve_at=None):
    """The new signature's problem and solution just past the graze ``key`` at ``lam``:
    ``(problem, u)``, or a reason string. ``u`` solves the old signature at ``lam``; with
    ``solve_at`` the new problem is built there and solved at ``solve_at``."""
    made = _past_graze(op, key, u, lam, solve_at)
    return made if isinstance(made, str) else made[:2]


def _past_graze(op, key: str, u, lam, solve_at=None):
    """:func:`past_graze` with Newton's start: ``(problem, u, guess)`` or a reason."""
    from ..orbits.monitors import MonitorKey

    try:
        k = MonitorKey.parse(key)
    except ValueError:
        kind = str(key).split("/", 1)[0]
        return (f"the orbit's new event sequence past a {kind} is not built yet (the branch "
                f"stops here; on_dib='continue' follows the old one, not admissible beyond)")
    kind, seg = k.kind, k.segment
    try:
        if kind == "CC":
            made = resimulated(op, u, lam)
        elif kind == "AS":
            if k.side:
                made = split_sliding(op, u, lam, seg, k.side)
            else:
                made = join_sliding(op, u, lam, seg)
        elif kind in ("SS", "CS"):
            at_crossing = op.bounds[seg].kind == "crossing"
            if kind == "SS":
                made = (slide_instead_of_arc if at_crossing else insert_crossing)(op, u, lam, seg)
            else:
                made = (slide_at_crossing if at_crossing else cross_instead_of_sliding)(
                    op, u, lam, seg)
        elif k.at == "boundary":
            made = (remove_sliding if kind == "GS" else remove_impact)(op, u, lam, seg)
        elif k.at == "arc":
            made = remove_arc(op, u, lam, seg)
        elif kind == "GS":
            made = insert_sliding(op, u, lam, seg, k.name)
        else:
            made = insert_impact(op, u, lam, seg, k.name, touch=solve_at is not None)
    except TrialRejected as exc:
        return f"no orbit past the {kind}: {exc.message}"
    if isinstance(made, str):
        return f"no orbit past the {kind}: {made}"
    prob, u2 = made
    lam = lam if solve_at is None else solve_at
    res = prob.solve(u2, np.array([lam]))
    if not res.converged:
        return f"Newton on the new signature {prob.signature}: {res.reason} ({res.message})"
    adm = prob.admissibility(res.x, np.array([lam]))
    if not adm:
        return f"the orbit of the new signature {prob.signature} is not admissible: {adm.reason}"
    return prob, res.x, u2


#: Ratio of the gaps between Newton's start and the new orbit at ``delta / 4`` and at
#: ``delta`` below which the new orbit is the one that connects at the bifurcation: its
#: distance from the old orbit there vanishes with ``delta`` (like ``delta`` where an impact's
#: velocity grows linearly, like ``sqrt(delta)``, ratio 1/2, where it grows like a square root;
#: thesis Paper A), while an orbit of another branch stays a fixed distance away (ratio 1).
CONNECTED_RATIO = 0.6
#: Halvings of the restart offset ``delta`` before the search gives up.
RESTART_HALVINGS = 10


def _old_past(op, key, u, lam, lam1):
    """The old signature's solution at ``lam1`` from ``u`` (at ``lam``) and the value of its
    monitor ``key`` there: ``(u1, value)``; ``(None, None)`` where it has no solution, value
    ``None`` where the monitor is gone."""
    res = op.solve(u, np.array([lam1]))
    if not res.converged:
        return None, None
    try:
        mon = op.dib_monitors(res.x, np.array([lam1])).get(key)
    except TrialRejected:
        mon = None
    return res.x, (None if mon is None else mon.value)


def _candidate(op, key, u, lam, lam1):
    """The orbit of the new signature at ``lam1``: ``((problem, u, guess), old monitor)`` or
    ``(reason, old monitor)``. Built from the old signature's solution at ``lam1`` where it
    crosses the surface there; else (it has none there, or it does not reach the surface:
    ``lam1`` is on the side the branch came from) from the bifurcation itself."""
    x_old, m_old = _old_past(op, key, u, lam, lam1)
    made = None
    if x_old is not None:
        made = _past_graze(op, key, x_old, lam1)
    if made is None or isinstance(made, str):
        again = _past_graze(op, key, u, lam, solve_at=lam1)
        if made is None or not isinstance(again, str):
            made = again
    return made, m_old


def _back(value) -> bool:
    """Whether an old monitor's value past the bifurcation is positive again."""
    return value is not None and value > 0.0


def _gap(made) -> float:
    prob, x, guess = made
    return float(np.max(np.abs(np.asarray(x) - np.asarray(guess))))


def _connected(op, key, u, lam, made, lam_near) -> bool:
    """Whether the new orbit ``made`` (at an offset ``delta`` from the bifurcation at ``lam``)
    lies on the branch through the bifurcation: built the same way at ``lam_near`` (a quarter
    of the offset), its distance from Newton's start must shrink (see
    :data:`pwsdyn.continuation.dib.CONNECTED_RATIO`)."""
    g = _gap(made)
    if g <= 1e-9 * (1.0 + float(np.max(np.abs(made[1])))):
        return True
    near, _ = _candidate(op, key, u, lam, lam_near)
    if isinstance(near, str) or near[0].signature != made[0].signature:
        return False
    return _gap(near) <= CONNECTED_RATIO * g


def restart(op, key: str, u, lam: float, direction: float, span, delta: float):
    """Where the branch goes on past the discontinuity-induced bifurcation ``key`` located at
    ``(u, lam)`` (a solution of ``op``), arrived at going ``direction`` (+1 or -1) in the
    parameter: ``(problem, u1, lam1, direction1, nonsmooth_fold)``, or why there is none.

    The branch goes on with the orbit of the new signature that connects there. It is sought
    a short offset ``delta`` past the bifurcation (the new problem is singular at it): first
    on the far side (persistence), where the old orbit must have crossed the surface -- its
    monitor negative there and at twice the offset; a positive one means a second
    bifurcation closer than ``2 delta``,
    and a new orbit that is not admissible or does not connect (``_connected``: Newton
    landed on another branch) may mean the same -- then on the side the branch came from: a
    new orbit there is the other half of a non-smooth fold (the branches with and without
    the new event meet from one side, the branch turns back, ``direction1 = -direction``).
    Neither: ``delta`` is halved (a second bifurcation or a smooth fold of the new branch
    closer than it), :data:`pwsdyn.continuation.dib.RESTART_HALVINGS` times. Where only an
    admissible far-side orbit that does not pass the connection test was found, it is taken
    (as before the test)."""
    lo, hi = span
    if not lo <= lam + direction * delta <= hi:
        return "the span ends at the graze"
    fallback, why = None, ""
    for _ in range(RESTART_HALVINGS + 1):
        lam1 = lam + direction * delta
        if lo <= lam1 <= hi:
            made, m_old = _candidate(op, key, u, lam, lam1)
            if isinstance(made, str):
                why = made
            elif _back(m_old) or _back(_old_past(op, key, u, lam, lam + 2 * direction * delta)[1]
                                      if lo <= lam + 2 * direction * delta <= hi else None):
                # the new orbit at lam1 must not sit on (or past) a second bifurcation: the old
                # orbit still crosses the surface at twice the offset
                why = (f"the old orbit is back on its side of the surface within "
                       f"{2 * delta:.3g} of {lam:.12g}: a second bifurcation there")
            else:
                if fallback is None:
                    fallback = (made[0], made[1], lam1, direction, False)
                if _connected(op, key, u, lam, made, lam + direction * delta / 4):
                    return made[0], made[1], lam1, direction, False
        elif not why:
            why = "the span ends at the graze"
        lam2 = lam - direction * delta
        if lo <= lam2 <= hi:
            made, _ = _candidate(op, key, u, lam, lam2)
            if not isinstance(made, str) and _connected(op, key, u, lam, made,
                                                        lam - direction * delta / 4):
                return made[0], made[1], lam2, -direction, True
        delta *= 0.5
    return fallback if fallback is not None else why


def dip_suspected(s, m) -> bool:
    """Whether a monitor positive at three consecutive points of a branch (arclengths ``s``,
    values ``m``) may reach zero between them, out of sight of the points themselves: the
    parabola through them is convex, its vertex lies between the first and the last point,
    and its least value is smaller than the monitor's variation over the two steps (the
    extremum approaches zero relative to the step: a dip to zero and back as narrow as a
    fraction of the step would show no sign change at the points)."""
    s0, s1, s2 = (float(x) for x in s)
    m0, m1, m2 = (float(x) for x in m)
    if not (m0 > 0.0 and m1 > 0.0 and m2 > 0.0) or not (s0 < s1 < s2 or s0 > s1 > s2):
        return False
    d01, d12 = (m1 - m0) / (s1 - s0), (m2 - m1) / (s2 - s1)
    c2 = (d12 - d01) / (s2 - s0)
    if not c2 > 0.0:
        return False
    sv = 0.5 * (s0 + s1) - d01 / (2.0 * c2)
    if not min(s0, s2) < sv < max(s0, s2):
        return False
    qv = m1 + d01 * (sv - s1) + c2 * (sv - s0) * (sv - s1)
    return qv < max(m0, m1, m2) - qv
