r"""Nordmark's discontinuity map at a grazing orbit, and the persistence test.

At a graze of an impact surface :math:`h = 0` by a periodic orbit at :math:`x^*` (thesis
eq. 2.30-2.32: :math:`h(x^*) = 0`, :math:`h_x f = 0` and :math:`a^* = (h_x f)_x f > 0`), the
effect of a low-velocity impact is a correction applied on the section
:math:`h_{turning} = h_x f = 0` (the points of zero normal velocity) to the smooth flow that
ignores the surface. To lowest order (eq. 2.33-2.34)

.. math::

    x \mapsto \begin{cases}
        x & \text{where } h(x) \ge 0, \\
        x + \beta \sqrt{-h_x(x^*) \cdot (x - x^*)} & \text{where } h(x) < 0,
    \end{cases}
    \qquad
    \beta = \sqrt{\frac{2}{a^*}}
        \left(\frac{f(x^*)\, h_{turning,x}(x^*)}{a^*} - I\right) g_x(x^*) f(x^*),

with :math:`g` the impact's reset. The square root makes the composition with the smooth
Poincaré map :math:`P` singular at the graze; whether a local attractor persists through the
grazing bifurcation is decided (eq. 2.35; the thesis's ref. [19]) by the signs of

.. math::

    h_x(x^*) \cdot P^n \beta, \qquad n = 1, 2, \ldots

all positive: persistence; otherwise loss of the local attractor (typically hysteresis).

A forced system is written autonomously in :math:`(x, t)` with :math:`t' = 1` (the surfaces,
fields and resets may depend on time; the map shifts the time of an impacting orbit at first
order: for the impact oscillator :math:`\beta` has only a time component,
:math:`-(1 + r) \sqrt{2 / a^*}`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ArgumentError

#: Scenarios of a grazing bifurcation (thesis section 2.6.1).
SCENARIOS = ("persistence", "loss")


@dataclass
class DiscontinuityMap:
    """The discontinuity map at a grazing point (module docstring).

    Attributes
    ----------
    x_star : numpy.ndarray
        The grazing point ``x*`` (with the time last, for a forced model).
    a_star : float
        ``a* = (h_x f)_x f`` at ``x*`` (> 0: the grazing orbit is a parabola with its minimum
        of ``h`` at ``x*``).
    beta : numpy.ndarray
        The direction of the square-root correction (eq. 2.34).
    P : numpy.ndarray
        Jacobian of the smooth Poincaré map on the section ``h_turning = 0`` at ``x*``.
    h_x : numpy.ndarray
        Gradient of the impact surface at ``x*``.
    names : tuple of str
        The coordinates (states, then ``t`` for a forced model).
    event : str
        The impact event.
    """

    x_star: np.ndarray
    a_star: float
    beta: np.ndarray
    P: np.ndarray
    h_x: np.ndarray
    names: tuple
    event: str
    f_star: np.ndarray = field(repr=False, default=None)

    def __repr__(self):
        from .._display import num, state_text

        return (f"DiscontinuityMap(event={self.event!r}, a_star={num(self.a_star)}, "
                f"beta=[{state_text(self.names, self.beta)}], scenario={self._scenario()!r})")

    def _repr_html_(self):
        from .._display import html_table, num, state_text

        seq = self._sequence(6)
        return html_table("DiscontinuityMap", [
            ("event", self.event), ("x_star", state_text(self.names, self.x_star)),
            ("a_star", num(self.a_star)), ("beta", state_text(self.names, self.beta)),
            ("persistence", "?" if seq is None else
             ", ".join(num(v, 4) for v in seq) + ", ..."),
            ("scenario", self._scenario())])

    def _sequence(self, n):
        # a summary shows a map whose matrices are malformed too
        try:
            return self.persistence(n)
        except (ValueError, TypeError):
            return None

    def _scenario(self) -> str:
        return "?" if self._sequence(1) is None else self.scenario

    def __call__(self, x) -> np.ndarray:
        """The map at ``x`` (a point of the section, same coordinates as ``x_star``)."""
        x = np.asarray(x, dtype=float)
        if x.shape != self.x_star.shape:
            raise ArgumentError(f"`x` must have the {self.x_star.size} coordinates "
                                f"{list(self.names)}")
        d = float(self.h_x @ (x - self.x_star))
        return x.copy() if d >= 0.0 else x + self.beta * np.sqrt(-d)

    def persistence(self, n: int = 50) -> np.ndarray:
        """The sequence ``h_x(x*) . P^k beta`` for ``k = 1..n`` (eq. 2.35)."""
        from .. import _validate as V

        n = V.integer("n", n, lo=1)
        out = np.empty(n)
        v = self.beta.copy()
        for k in range(n):
            v = self.P @ v
            out[k] = self.h_x @ v
        return out

    @property
    def scenario(self) -> str:
        """``"persistence"`` when every term of :meth:`persistence` (50 terms, or until they
        have decayed below 1e-12 of the first) is positive, ``"loss"`` otherwise."""
        seq = self.persistence(50)
        scale = np.max(np.abs(seq)) or 1.0
        significant = np.abs(seq) > 1e-12 * scale
        return "persistence" if np.all(seq[significant] > 0.0) else "loss"


def _tangency(point):
    """``(problem, u, p, monitor)`` of a grazing point of an orbit branch: a ``GR`` point
    (a segment touching a surface inside it), or a ``CC`` point that is a graze at a kink
    (``_kink_graze``)."""
    mon = getattr(point, "monitor", None)
    kind = getattr(point, "kind", None)
    if kind == "CC" and mon is not None:
        return _kink_graze(point)
    if kind != "GR" or mon is None or "@" in point.key or point.key.endswith("/arc"):
        raise ArgumentError("discontinuity_map needs a GR special point where a segment "
                            "grazes a surface inside it (pwsdyn.continue_orbit; not the end "
                            "of an impacting branch), or a CC point where the orbit grazes an "
                            "impact surface at a kink of the field")
    prob = point.problem.orbit_problem
    return prob, point.point.u, np.array([point.value]), mon


#: Relative size below which the normal velocity ``h_t + h_x f`` of a surface at a corner
#: collision counts as zero (a tangency) and the two fields at a crossing count as equal:
#: far above the rounding of a located point (~1e-12), far below an O(1) transversal rate.
_KINK_TOL = 1e-7


def _kink_graze(point):
    """A corner collision that is a graze at a kink of the field, as a monitor on the
    segment after the kink.

    Where the surface ``h_turning = h_t + h_x f`` of an impact surface is itself a surface
    across which the field is continuous with a jump in its slope (a ``continuous`` surface:
    ``Max``, ``Min``, ``Abs`` -- the quarter-car's bilinear damper, whose kink ``vr = 0`` is
    the zero of the suspension's relative velocity), the orbit reaches its minimum of ``h``
    exactly at the crossing of the kink: the graze is an event point, and continuation sees
    it as the event point reaching the impact surface (``CC``). Conditions 2.30-2.32 hold
    with the one field ``f(x*)`` of both sides, and the lowest-order discontinuity map
    (eq. 2.33-2.34) uses only ``f``, ``h_x``, ``(h_x f)_x f`` and ``g_x`` at ``x*``, which
    the two sides share; the smooth Poincare map crosses the kink with the identity as its
    saltation matrix (equal fields). So the graze is analysed on the segment that starts at
    the kink, at its start.
    """
    from ..orbits.monitors import Monitor
    from ..orbits.surfaces import model_context

    mon = point.monitor
    prob = point.problem.orbit_problem
    u, p = point.point.u, np.array([point.value])
    m = prob.model
    i = mon.segment
    b = prob.bounds[i] if i < len(prob.bounds) else None
    impacts = [e for e in m.events if e.kind == "impact"
               and m.surfaces[e.surface].name == mon.surface]
    if b is None or b.kind != "crossing" or not impacts:
        raise ArgumentError(f"the corner collision at {point.parameter} = {point.value:.12g} "
                            f"is not a graze at a kink: the discontinuity map needs an impact "
                            f"surface met at the crossing of a surface of continuity")
    nseg = len(prob.fields)
    j = (i + 1) % nseg
    fa, fb = prob.fields[i], prob.fields[j]
    if fa.kind != "mode" or fb.kind != "mode":
        raise ArgumentError("the corner collision is not between two modes")
    ctx = model_context(m, prob.param_dict(p), prob.sliding)
    t, x = float(mon.t), np.asarray(mon.x, dtype=float)
    f_in = ctx.mode_field(fa.index, t, x)
    f_out = ctx.mode_field(fb.index, t, x)
    scale = float(np.linalg.norm(f_in)) or 1.0
    if np.linalg.norm(f_out - f_in) > _KINK_TOL * scale:
        raise ArgumentError(f"the field jumps across {m.surfaces[b.surface].name!r} at the "
                            f"corner collision: not a graze at a kink (the discontinuity map "
                            f"of eq. 2.34 assumes one field at the graze)")
    k = impacts[0].surface
    h_x = ctx.h_x(k, t, x)
    rate = float(h_x @ f_in + ctx.h_t(k, t, x))
    if abs(rate) > _KINK_TOL * (float(np.linalg.norm(h_x)) * scale + abs(ctx.h_t(k, t, x))):
        raise ArgumentError(f"the orbit crosses {mon.surface!r} at the corner collision with "
                            f"normal velocity {rate:.3e}: a transversal corner collision, not "
                            f"a graze")
    t0 = float(prob.evaluate(u, p).segs[j].t)
    return prob, u, p, Monitor(mon.value, j, mon.surface, t0, x)


def discontinuity_map(point) -> DiscontinuityMap:
    r"""Nordmark's discontinuity map at a grazing point, to lowest order.

    The map of thesis eq. 2.33-2.34,

    .. math::

        x \mapsto x + \beta \sqrt{-h_x (x - x^*)},

    on the section of zero normal velocity through the grazing point :math:`x^*`.

    Parameters
    ----------
    point : SpecialPoint
        A ``GR`` point of an orbit branch where a segment touches an impact surface inside it
        (``Branch.special("GR")``), or a ``CC`` point where the orbit touches an impact
        surface at a kink of its field (``Branch.special("CC")``: the quarter-car's bumpstop,
        grazed where the bilinear damper switches).

    Returns
    -------
    DiscontinuityMap
        With ``a_star``, ``beta``, ``x_star``, the map itself (``__call__``), the persistence
        sequence (eq. 2.35) and the predicted ``scenario``.
    """
    from ..orbits.surfaces import model_context

    prob, u, p, mon = _tangency(point)
    m, n = prob.model, prob.n
    seg = mon.segment
    fk = prob.fields[seg]
    if fk.kind != "mode":
        raise ArgumentError("the grazing segment is not in a mode")
    mode = fk.index
    events = [(j, e) for j, e in enumerate(m.events) if e.kind == "impact" and mode in e.modes
              and m.surfaces[e.surface].name == mon.surface]
    if not events:
        raise ArgumentError(f"no impact event on surface {mon.surface!r}: the discontinuity map "
                            f"is that of an impact")
    j, e = events[0]
    k = e.surface
    ctx = model_context(m, prob.param_dict(p), prob.sliding)
    ts, xs = float(mon.t), np.asarray(mon.x, dtype=float)
    f = ctx.mode_field(mode, ts, xs)
    hT_x = ctx.hdot_x(k, mode, ts, xs)        # h_turning = h_t + h_x f
    hT_t = ctx.hdot_t(k, mode, ts, xs)
    h_x = ctx.h_x(k, ts, xs)
    h_t = ctx.h_t(k, ts, xs)
    g_x = ctx.g_x(j, ts, xs)
    g_t = ctx.g_t(j, ts, xs)
    a_star = float(hT_x @ f + hT_t)
    if not a_star > 0.0:
        raise ArgumentError(f"a* = {a_star:.3e} is not positive: not a grazing minimum of h")
    M = _monodromy_at(prob, u, p, seg, ts)
    forced = prob.forced
    if forced:
        N = n + 1
        f_e = np.append(f, 1.0)
        hT_e = np.append(hT_x, hT_t)
        h_e = np.append(h_x, h_t)
        G = np.zeros((N, N))
        G[:n, :n] = g_x
        G[:n, n] = g_t
        G[n, n] = 1.0
        Phi = np.zeros((N, N))
        Phi[:n, :n] = M
        # the time-T flow of (x, t): d phi / d t0 = f(t + T, x_T) - M f(t, x) = (I - M) f on a
        # periodic orbit
        Phi[:n, n] = (np.eye(n) - M) @ f
        Phi[n, n] = 1.0
        x_star = np.append(xs, ts)
        names = tuple(m.states) + ("t",)
    else:
        N = n
        f_e, hT_e, h_e, G, Phi = f, hT_x, h_x, g_x, M
        x_star = xs
        names = tuple(m.states)
    I = np.eye(N)
    beta = np.sqrt(2.0 / a_star) * ((np.outer(f_e, hT_e) / a_star - I) @ (G @ f_e))
    # the smooth Poincare map on h_turning = 0: the period map projected along the flow
    P = (I - np.outer(f_e, hT_e) / a_star) @ Phi
    return DiscontinuityMap(x_star=x_star, a_star=a_star, beta=beta, P=P, h_x=h_e,
                            names=names, event=e.name, f_star=f_e)


def _monodromy_at(prob, u, p, seg, t_star):
    """The one-period Jacobian of the smooth flow (the grazing segment integrated through,
    the orbit's other events with their saltation matrices) at the grazing time."""
    ev = prob.evaluate(u, p)
    n = prob.n
    m = len(ev.segs)
    # transfer of each segment: S_i Phi_i (Phi over the whole segment)
    T = []
    for i, s in enumerate(ev.segs):
        A = s.Phi[:n, :n]
        if i < len(prob.bounds):
            A = prob.boundary_saltation(i, s) @ A
        T.append(A)
    s = ev.segs[seg]
    opts = prob.segment_options(p)
    _, Phi_a, _ = prob.flow(seg, s.t, s.z, t_star - s.t, opts)
    Pa = Phi_a[:n, :n]
    # from x*: the rest of segment seg, then the others, then segment seg up to t*
    rest = T[seg] @ np.linalg.inv(Pa)
    acc = rest
    for i in list(range(seg + 1, m)) + list(range(0, seg)):
        acc = T[i] @ acc
    return Pa @ acc
