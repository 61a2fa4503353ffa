"""Monitors of discontinuity-induced bifurcations of a periodic orbit: for a solution of an
orbit problem (:class:`~pwsdyn.orbits.OrbitProblem`), signed distances from a grazing, a
sliding bifurcation or a corner collision, each zero at the bifurcation and positive on the
side where the orbit keeps its signature
(:func:`~pwsdyn.orbits.monitors.dib_monitors`).

A monitor is named by a :class:`~pwsdyn.orbits.MonitorKey` (its kind, the surface, event
or switch it watches, the segment and where on it); its string form ``"GR/impact/0"``,
``"GR/impact@0"``, ``"GR/x/2/arc"``, ``"AS/vrel:above/2"`` is the name a branch's column, a
special point and a saved file carry (:meth:`~pwsdyn.orbits.MonitorKey.parse` reads it
back).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ._admissibility import boundary_normal_velocity
from ._sampling import interior_minimum
from .surfaces import normal_acceleration, normal_velocity, sliding_boundary_rate, surface

#: Kinds of the monitors of :func:`~pwsdyn.orbits.monitors.dib_monitors` (discontinuity-induced
#: bifurcations of an orbit): grazing, grazing-, switching-, crossing- and adding-sliding,
#: corner collision.
DIB_KINDS = ("GR", "GS", "SS", "CS", "AS", "CC")
#: Where on its segment a monitor is evaluated: along it (an interior minimum), at the
#: boundary that ends it, or over the whole of it (the duration of an arc).
MONITOR_PLACES = ("interior", "boundary", "arc")


class MonitorKey(NamedTuple):
    """The name of a monitor: its ``kind`` (one of
    :data:`~pwsdyn.orbits.monitors.DIB_KINDS`), the ``name`` of the surface, event or switch it
    watches, its ``segment``, where on it (``at``, one of
    :data:`~pwsdyn.orbits.monitors.MONITOR_PLACES`) and, for a sliding segment's
    adding-sliding monitor, the ``side`` (``'above'`` or ``'below'``) whose field it watches.

    ``str(key)`` is its string form (``"GR/impact/0"``, ``"GR/impact@0"``,
    ``"GR/x/2/arc"``, ``"AS/vrel:above/2"``); :meth:`parse` the inverse.
    """

    kind: str
    name: str
    segment: int
    at: str = "interior"
    side: str = ""

    def __str__(self) -> str:
        if self.at == "boundary":
            return f"{self.kind}/{self.name}@{self.segment}"
        if self.at == "arc":
            return f"{self.kind}/{self.name}/{self.segment}/arc"
        where = f"{self.name}:{self.side}" if self.side else self.name
        return f"{self.kind}/{where}/{self.segment}"

    @classmethod
    def parse(cls, text: str) -> "MonitorKey":
        """The key of a monitor's string form; ``ValueError`` for a text that names no
        monitor of :func:`~pwsdyn.orbits.monitors.dib_monitors`."""
        kind, sep, body = str(text).partition("/")
        if not sep or kind not in DIB_KINDS:
            raise ValueError(f"{text!r} is not a monitor key (KIND/... with KIND one of "
                             f"{DIB_KINDS})")
        try:
            if body.endswith("/arc"):
                name, seg = body[:-len("/arc")].rsplit("/", 1)
                return cls(kind, name, int(seg), "arc")
            if "@" in body:
                name, seg = body.rsplit("@", 1)
                return cls(kind, name, int(seg), "boundary")
            name, seg = body.rsplit("/", 1)
            side = ""
            if ":" in name:
                name, side = name.rsplit(":", 1)
            return cls(kind, name, int(seg), "interior", side)
        except ValueError:
            raise ValueError(f"{text!r} is not a monitor key: no segment number") from None


@dataclass(frozen=True)
class Monitor:
    """A monitor of a discontinuity-induced bifurcation on an orbit: ``value`` (zero at the
    bifurcation, positive on the side where the orbit keeps its signature), the ``segment``
    and ``surface`` (or event) it watches, and where: time ``t`` and state ``x``; ``key`` its
    :class:`MonitorKey`."""

    value: float
    segment: int
    surface: str
    t: float
    x: np.ndarray
    key: MonitorKey | None = field(default=None, compare=False)


def _put(out: dict, key: MonitorKey, value, t, x) -> None:
    """``out[str(key)]``: the monitor of ``key`` (by its string form, the name it has on a
    branch)."""
    out[str(key)] = Monitor(float(value), key.segment, key.name, float(t), x, key)


def _bounding_surfaces(prob, mode: int) -> list:
    """``(name, surface index, sign, other mode)`` of the surfaces a segment in ``mode``
    must not cross: its impact surfaces (sign +1: ``h >= 0``) and the switching surfaces
    bounding its region (sign +1 above, -1 below; ``other`` the mode beyond a Filippov
    switch, -1 otherwise)."""
    m = prob.model
    out = []
    for e in m.events:
        if e.kind == "impact" and mode in e.modes:
            out.append((m.surfaces[e.surface].name, e.surface, 1.0, -1))
    for sw in m.switches:
        if mode in (sw.above, sw.below):
            above = mode == sw.above
            other = sw.below if above else sw.above
            out.append((m.surfaces[sw.surface].name, sw.surface, 1.0 if above else -1.0,
                        other if sw.kind == "filippov" else -1))
    return list(dict.fromkeys(out))


def dib_monitors(prob, u, p=None, evaluation=None) -> dict:
    """Monitors of discontinuity-induced bifurcations on a solution: ``{key: Monitor}``,
    each a signed distance from the bifurcation, positive on the side where the orbit
    keeps its signature.

    * ``"GR/<surface>/<i>"``: the smallest interior local minimum of ``h`` (or ``-h``
      below a switching surface) along segment ``i`` in a mode -- a graze of the surface
      inside the segment where it reaches zero: ``h = 0`` and ``h_t + h_x f = 0`` at an
      interior point (thesis conditions 2.30-2.31), refined by minimizing on the dense
      output; ``"GS/..."`` for a Filippov surface where the field on its other side points
      back into it at the tangency: touching it there starts sliding (grazing-sliding,
      the slides' "sliding bifurcations");
    * ``"GR/<event>@<i>"``: ``-(h_t + h_x f)`` at the impact ending segment ``i`` -- the
      impact's normal velocity going to zero (the end of a branch of impacting orbits
      at a graze);
    * ``"SS/<switch>@<i>"`` at a sliding entry: the normal velocity of the field beyond the
      surface, signed to be positive while it points back (switching-sliding where it
      vanishes);
    * ``"AS/<switch>@<i>"`` at a sliding exit: the normal acceleration of the field the
      orbit leaves with, positive while it curves away (adding-sliding where it
      vanishes);
    * ``"AS/<surface>:<above|below>/<i>"`` along a segment sliding on an intersection: the
      smallest interior local minimum of the surface's weight ``lambda`` (``above``: the
      motion leaves to the side above where it reaches 0) or of ``1 - lambda``
      (``below``); where it touches zero a contact starts or ends its stick inside the
      orbit (the multilinear field's analogue of adding-sliding);
    * ``"CC/<surface>@<i>"`` at an impact, transition or crossing ending a segment in a
      mode: the value of another surface of the mode there, signed positive on the
      segment's side (a corner collision where it vanishes: the event point reaches the
      intersection of the two surfaces).

    A segment with no interior local minimum of a surface gives no monitor for it.
    """
    p = prob._p(p)
    ev = evaluation if evaluation is not None else prob.evaluate(u, p, jacobian=False)
    ctx = prob._context_at(p)
    m, n = prob.model, prob.n
    out = {}
    for i, s in enumerate(ev.segs):
        fk = prob.fields[i]
        out.update(_arc_monitor(prob, i, s))
        if fk.kind == "mode" and s.T > 0:
            tr, ts, Y = prob._dense_samples(i, s, p)
            if tr is None or len(ts) < 3:
                continue
            for name, k, sign, other in _bounding_surfaces(prob, fk.index):
                fn = surface(ctx, k)
                # (the values on the samples the admissibility check read too)
                vals = sign * prob._surface_samples(i, s, p, k, ctx)
                found = interior_minimum(lambda tt: sign * fn(tt, tr(tt)[:n]), ts, vals)
                if found is None:
                    continue
                tg, hg = found
                xg = np.asarray(tr(tg)[:n], dtype=float)
                kind = "GR"
                if other >= 0:
                    # a Filippov surface: where the field on the other side points back
                    # into it, touching it starts sliding (grazing-sliding, GS); else the
                    # orbit would cross it (a grazing of the crossing region, GR)
                    rate = normal_velocity(ctx, k, other)(tg, xg)
                    kind = "GS" if sign * rate > 0 else "GR"
                _put(out, MonitorKey(kind, name, i), hg, tg, xg)
        elif fk.kind == "slide" and s.T > 0:
            out.update(_sliding_monitors(prob, i, s, p, ctx))
        elif fk.kind == "slide_multi" and s.T > 0:
            out.update(_multi_monitors(prob, i, s, p))
        b = prob.bounds[i] if i < len(prob.bounds) else None
        if b is None:
            continue
        te, y = s.te, np.asarray(s.y[:n], dtype=float)
        if fk.kind == "mode" and b.kind in ("impact", "transition", "crossing"):
            # corner collision: the event point reaches another surface of the segment's
            # mode (the orbit passes through the intersection of two surfaces)
            for name, k, sign, _ in _bounding_surfaces(prob, fk.index):
                if k != b.surface:
                    _put(out, MonitorKey("CC", name, i, "boundary"), sign * ctx.h(k, te, y), te, y)
        if b.kind == "crossing" and fk.kind == "mode":
            sw = m.switches[b.ref]
            if sw.kind == "filippov":
                # the field beyond stops carrying the orbit away from the surface at the
                # crossing point: the point reaches the sliding region's boundary. Where
                # the sliding flow leaves the region there, the orbit past it slides a
                # short way and leaves as before (crossing-sliding); where the sliding
                # flow enters the region, it slides away (switching-sliding, seen from
                # its crossing side)
                beyond = sw.above if fk.index == sw.below else sw.below
                sign = 1.0 if beyond == sw.above else -1.0
                value = sign * normal_velocity(ctx, b.surface, beyond)(te, y)
                kind = "CS" if sliding_boundary_rate(ctx, b.ref, beyond, te, y) * sign > 0 else "SS"
                _put(out, MonitorKey(kind, sw.name, i, "boundary"), value, te, y)
        if b.kind == "impact":
            e = m.events[b.ref]
            rate = boundary_normal_velocity(prob, i, s, ctx)[0]
            _put(out, MonitorKey("GR", e.name, i, "boundary"), -rate, te, y)
        elif b.kind == "slide_start" and fk.kind == "mode":
            # switching-sliding: the point where the orbit reaches the surface leaves the
            # sliding region through its other boundary (the field beyond stops pointing
            # back); past it the orbit crosses, runs in the other mode and returns
            sw = m.switches[b.ref]
            other = sw.above if fk.index == sw.below else sw.below
            sign = -1.0 if other == sw.above else 1.0
            rate = normal_velocity(ctx, b.surface, other)(te, y)
            # where the sliding flow at the entry leaves the region into that other mode,
            # entry and exit meet on the boundary and the sliding segment shrinks to
            # nothing: past it the orbit just crosses (crossing-sliding, seen from its
            # sliding side); else it slides away and the exit is elsewhere
            # (switching-sliding)
            kind = "CS" if sliding_boundary_rate(ctx, b.ref, other, te, y) * sign < 0 else "SS"
            _put(out, MonitorKey(kind, sw.name, i, "boundary"), sign * rate, te, y)
            nb = prob.bounds[(i + 1) % prob.m]
            if nb.kind == "slide_end" and nb.mode == fk.index:
                # grazing-sliding seen from the sliding side: the orbit arrives ever more
                # tangentially and leaves back into the same mode; where its normal
                # velocity vanishes the sliding segment shrinks to nothing and past it
                # the orbit only touches the surface
                into = 1.0 if fk.index == sw.above else -1.0
                arrival = normal_velocity(ctx, b.surface, fk.index)(te, y)
                _put(out, MonitorKey("GS", sw.name, i, "boundary"), -into * arrival, te, y)
        elif b.kind == "slide_end" and fk.kind == "slide":
            # adding-sliding: the field the orbit leaves the surface with is tangent to it
            # at the exit (h_x f = 0) and its normal acceleration vanishes too (a cubic
            # tangency, the slides' <<h_x, f1>_x, f1> = 0): past it the orbit comes back
            sw = m.switches[b.ref]
            acc = normal_acceleration(ctx, b.surface, b.mode)(te, y)
            sign = 1.0 if b.mode == sw.above else -1.0
            _put(out, MonitorKey("AS", sw.name, i, "boundary"), sign * acc, te, y)
    return out


def _arc_monitor(prob, i, s) -> dict:
    """``"GR/<surface>/<i>/arc"``: for segment ``i`` entered and left by crossings of one
    switching surface (an arc on its other side), the arc's duration. Where it falls to
    zero the two crossings meet: the orbit grazes the surface from the side it used to
    cross from, and past it stays there. (Not the arc's height: the branch of the locked
    signature folds back at the graze, so the height only touches zero; the duration
    changes sign along the branch.)"""
    if not prob.m or len(prob.bounds) != len(prob.signature):
        return {}
    before, after = prob.bounds[(i - 1) % prob.m], prob.bounds[i]
    if not (before.kind == after.kind == "crossing" and before.ref == after.ref):
        return {}
    name = prob.model.surfaces[after.surface].name
    out: dict = {}
    _put(out, MonitorKey("GR", name, i, "arc"), s.T, s.t, np.asarray(s.y[:prob.n], dtype=float))
    return out


def _sliding_monitors(prob, i, s, p, ctx) -> dict:
    """``"AS/<switch>:<above|below>/<i>"``: along sliding segment ``i``, the smallest
    interior local minimum of the normal velocity of the field on each side, signed
    positive while it points into the surface (inside the sliding region). Where it
    reaches zero the sliding flow touches the region's boundary (``h_x f = 0`` and
    ``(h_x f)_x f = 0`` there: adding-sliding, the slides' defining conditions); past it
    the orbit leaves at the touching point, runs a short arc and slides again."""
    sw = prob.model.switches[prob.fields[i].index]
    tr, ts, Y = prob._dense_samples(i, s, p)
    if tr is None or len(ts) < 3:
        return {}
    n = prob.n
    out = {}
    for side, mode, sign in (("above", sw.above, -1.0), ("below", sw.below, 1.0)):
        fn = normal_velocity(ctx, sw.surface, mode)
        vals = np.array([sign * fn(t, y) for t, y in zip(ts, Y)])
        found = interior_minimum(lambda tt: sign * fn(tt, tr(tt)[:n]), ts, vals)
        if found is not None:
            tg, hg = found
            _put(out, MonitorKey("AS", sw.name, i, side=side), hg, tg,
                 np.asarray(tr(tg)[:n], dtype=float))
    return out


def _multi_monitors(prob, i, s, p) -> dict:
    """``"AS/<surface>:<above|below>/<i>"``: along segment ``i``, sliding on an intersection,
    the smallest interior local minimum of each surface's weight ``lambda`` (``above``) and
    of ``1 - lambda`` (``below``). Where one touches zero the multilinear field touches the
    boundary of its region (the corner fields on that side of the surface turn tangent to
    it): past it the motion leaves that surface inside the segment and returns to it (a
    contact ends and restarts its stick inside the orbit)."""
    tr, ts, Y = prob._dense_samples(i, s, p)
    if tr is None or len(ts) < 3:
        return {}
    m, n = prob.model, prob.n
    fk = prob.fields[i]
    names = [m.surfaces[k].name for k in range(len(m.surfaces)) if (fk.index >> k) & 1]
    lam = prob.multi_weights(i, ts, Y, p)
    out: dict = {}
    for j, nm in enumerate(names):
        for side, sign, shift in (("above", 1.0, 0.0), ("below", -1.0, 1.0)):
            def val(tt, j=j, sign=sign, shift=shift):
                return sign * (float(prob.multi_weights(i, [tt], [tr(tt)[:n]], p)[0, j])
                               - shift)
            found = interior_minimum(val, ts, sign * (lam[:, j] - shift))
            if found is not None:
                tg, hg = found
                _put(out, MonitorKey("AS", nm, i, side=side), hg, tg,
                     np.asarray(tr(tg)[:n], dtype=float))
    return out
