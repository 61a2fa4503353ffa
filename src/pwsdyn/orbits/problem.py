r"""A hybrid periodic orbit on a fixed signature as a problem with exact Jacobians.

The problem is :math:`F(u, p) = 0`, with its Jacobians :math:`F_u` and :math:`F_p`.

Unknowns (the segment formulation of COCO's ``hspo`` toolbox, Dankowicz & Schilder,
*Recipes for Continuation*, SIAM 2013, ch. 4; Thota & Dankowicz, TC-HAT, SIAM J. Appl.
Dyn. Syst. 7 (2008)): the orbit's signature (:class:`~pwsdyn.orbits.signature.Signature`) is
cut into ``m`` segments, segment ``i`` ending with boundary ``i`` (one event, or an impact or a
chattering sequence followed at the same instant by the start of sticking). With :math:`n`
states,

.. math::

    u = (t_0, x_0, T_0, x_1, T_1, \ldots, x_{m-1}, T_{m-1}),

:math:`x_i` the state at the start of segment :math:`i` (just after boundary :math:`i - 1`),
:math:`T_i` its duration and :math:`t_0` the time segment 0 starts -- an unknown for a forced
model (the phase of the orbit), left out for an autonomous one. Segment :math:`i` starts at
:math:`t_i = t_0 + \sum_{j<i} (T_j + \delta_j)`, :math:`\delta_j` the jump in time of boundary
:math:`j` (the complete-chattering map; zero otherwise). Residual, per segment:

.. math::

    x_{i+1} - E_i(t_i + T_i, y_i) &= 0
        \qquad \text{($n$ rows: continuity through the event map $E_i$)}, \\
    c_i(t_i + T_i, y_i) &= 0 \qquad \text{(1 row: the event condition)},

with :math:`y_i = \varphi_i(t_i + T_i; t_i, x_i, p)` the segment's flow (:math:`x_m = x_0`),
:math:`c_i` the surface :math:`h` (impacts, transitions, crossings, sliding entry,
chattering), the normal velocity of the exit mode (sliding exit) or the free normal
acceleration (release), and :math:`E_i` the reset, the identity or the chattering map. A
forced model adds the period :math:`t_m - t_0 - k T_f(p) = 0` (:math:`k` forcing periods); an
autonomous one needs no phase condition: the event conditions fix where the segments start
(the section is the last event's surface). Square: :math:`1 + m (n + 1)` (forced) or
:math:`m (n + 1)` unknowns and equations. Without events (:math:`m = 0`) the problem is single
shooting: :math:`\varphi(t_0 + P; t_0, x_0) - x_0` with :math:`t_0` fixed, plus, autonomous,
the unknown :math:`P` and the phase condition :math:`n \cdot (x_0 - x_{ref}) = 0`.

Jacobians: each segment is integrated by the compiled kernel with its variational equations
in the state extended by the chosen parameters (:math:`p' = 0`; ``pwsdyn.orbits._segments``),
so :math:`\Phi = \partial(y, p)/\partial(x, p)` holds :math:`\partial y/\partial x` and
:math:`\partial y/\partial p`; :math:`\partial y/\partial T = f(t_e, y)` and
:math:`\partial y/\partial t_i = f(t_e, y) - \Phi f(t_i, x_i)`. The conditions and maps are
generated with their gradients over :math:`(x, p)` and :math:`t`; the chattering map's
projection onto the sticking manifold is differentiated implicitly. All are chained by the
product rule (forward mode) into :math:`[F_u \mid F_p]`: exact up to the integration
tolerance, no difference quotient of :math:`F`.

On a fixed signature nothing stops a segment at a surface it is not meant to end at: the orbit
can be followed past a grazing into the region where it is not a solution of the hybrid
model. :meth:`~pwsdyn.orbits.OrbitProblem.admissibility` says whether it is one and, if not,
why (a segment crossing a constraint or a switching surface, an impact with the flow leaving
the surface, sticking with a pulling contact force, sliding outside the sliding region, a
negative duration).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from .. import _validate as V
from ..errors import ArgumentError, Status
from ..integrate.simulate import _simulate_compiled
from ..integrate.trajectory import EventRecord, Trajectory
from ..model.codegen import W_GUARD, W_HD, W_HDT, W_HDX
from ..model.spec import as_model
from ..newton import TrialRejected, newton
from ..integrate._codes import REGULAR, SLIDE, STICK
from ..integrate.trajectory import DiscreteState
from ..stability._context import KernelState, ModelContext
from ..stability._floquet import floquet_multipliers
from ..stability._saltation import event_map_saltation
from ._base import STABILITY_MARGIN, OrbitError, shooting_options
from ._orbit import PeriodicOrbit
from ._segments import FieldKey, SegmentSystem
from .signature import Signature

#: Relative size below which a surface value, normal velocity or acceleration counts as zero
#: in the admissibility checks (the orbit is at a grazing, a sliding or sticking boundary).
ADMISSIBILITY_RTOL = 1e-8
#: Dense-output samples per step in the admissibility checks and the search of a condition.
_SAMPLES = 8

_SYSTEMS: dict = {}


#: Kinds of the monitors of :meth:`~pwsdyn.orbits.OrbitProblem.dib_monitors` (discontinuity-induced
#: bifurcations of an orbit): grazing, grazing-, switching-, crossing- and adding-sliding,
#: corner collision.
DIB_KINDS = ("GR", "GS", "SS", "CS", "AS", "CC")


@dataclass(frozen=True)
class Monitor:
    """A monitor of a discontinuity-induced bifurcation on an orbit: ``value`` (zero at the
    bifurcation, positive on the side where the orbit keeps its signature), the ``segment``
    and ``surface`` (or event) it watches, and where: time ``t`` and state ``x``."""

    value: float
    segment: int
    surface: str
    t: float
    x: np.ndarray


class SegmentFailed(Exception):
    """A segment could not be integrated (the kernel stopped)."""

    def __init__(self, index: int, message: str):
        super().__init__(message)
        self.index = index
        self.message = message


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


@dataclass(frozen=True)
class _Boundary:
    kind: str            # impact, transition, chatter, crossing, slide_start, slide_end, release
    events: tuple        # the SignatureEvents of the boundary (an event, or event + stick)
    ref: int             # event or switch index
    surface: int         # surface index of the model
    mode: int            # regular mode of the segment before (the field's mode)
    cond: tuple          # scalar key of the condition
    direction: int       # the condition's crossing direction at the end (-1, 0, +1)


@dataclass
class _Seg:
    """One segment of an evaluation (extended states ``z = (x, p)``; ``D*``: derivatives over
    ``w = (u, p)``)."""

    t: float
    z: np.ndarray
    T: float
    te: float
    y: np.ndarray
    tau: float
    X: np.ndarray
    Phi: np.ndarray
    f_start: np.ndarray
    f_end: np.ndarray
    c: float = 0.0
    Dt: np.ndarray | None = None
    Dz: np.ndarray | None = None
    Dte: np.ndarray | None = None
    Dy: np.ndarray | None = None
    Dtau: np.ndarray | None = None
    DX: np.ndarray | None = None
    # partial derivatives of the boundary at (te, y): condition, map, jump
    c_z: np.ndarray | None = None
    c_t: float = 0.0
    X_y: np.ndarray | None = None
    X_t: np.ndarray | None = None
    tau_y: np.ndarray | None = None
    tau_t: float = 1.0


@dataclass
class ProblemEvaluation:
    """``F``, ``F_u``, ``F_p`` of an :class:`OrbitProblem` at ``(u, p)`` and what the
    segments computed on the way.

    Attributes
    ----------
    u, p : numpy.ndarray
    F : numpy.ndarray
    F_u : numpy.ndarray or None
        ``dF/du`` (square).
    F_p : numpy.ndarray or None
        ``dF/dp``, one column per parameter of the problem.
    period : float
        ``t_m - t_0``.
    """

    u: np.ndarray
    p: np.ndarray
    F: np.ndarray
    F_u: np.ndarray | None
    F_p: np.ndarray | None
    period: float
    segs: list = field(default_factory=list, repr=False)
    Dperiod: np.ndarray | None = field(default=None, repr=False)


def _mode_by_name(model, name: str) -> int:
    if name in model.mode_names:
        return model.mode_names.index(name)
    return model.mode_index(name)


class OrbitProblem:
    """A periodic orbit of a hybrid model on a fixed signature: ``F(u, p) = 0``.

    See the module docstring for the unknowns ``u`` and the residual.

    Parameters
    ----------
    model : Model, str, path or dict
    signature : Signature or sequence
        The orbit's events over one period (``PeriodicOrbit.signature``); it must be closed
        (each event starts in the state the previous one ends in). Empty: an orbit without
        events, in discrete state ``state``.
    params : dict, optional
        Parameter values (the model's defaults otherwise).
    parameters : sequence of str, optional
        The parameters ``p`` of ``F(u, p)`` (columns of ``F_p``), in order; default all of
        the model's. The others are fixed at ``params``.
    periods : int
        Forced models: the period in forcing periods.
    t_ref : float
        Autonomous models (and orbits without events): the start time of segment 0.
    state : str, optional
        Orbits without events: their discrete state (a mode name).
    phase_ref, phase_normal : array_like, optional
        Autonomous orbits without events: the phase condition ``normal . (x_0 - ref) = 0``.
    sliding : {'convex', 'utkin'}
    **options
        Integrator options of :func:`pwsdyn.simulate` (defaults as
        :func:`pwsdyn.find_periodic_orbit`: DOP853, ``rtol = atol = 1e-12``).

    Examples
    --------
    >>> import pwsdyn
    >>> orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [0.0, -0.5])
    >>> prob, u = OrbitProblem.from_orbit(orbit, parameters=["sigma"])
    >>> F_u, F_p = prob.jacobian(u, prob.p0)
    """

    def __init__(self, model, signature, *, params=None, parameters=None, periods: int = 1,
                 t_ref: float = 0.0, state: str | None = None, phase_ref=None,
                 phase_normal=None, sliding: str = "convex", **options):
        self.opts = shooting_options(options, "OrbitProblem()")
        self.model = as_model(model, kind="flow", caller="OrbitProblem()")
        self.sliding = V.choice("sliding", sliding, ("convex", "utkin"))
        self.opts["sliding"] = self.sliding
        m = self.model
        p_all = m.parameter_vector(params)
        self.params = dict(zip(m.parameters, (float(v) for v in p_all)))
        if parameters is None:
            parameters = list(m.parameters)
        if isinstance(parameters, str):
            parameters = [parameters]
        parameters = list(parameters)
        bad = [k for k in parameters if k not in m.parameters]
        if bad or len(set(parameters)) != len(parameters):
            raise ArgumentError(f"`parameters` must be distinct parameters of model {m.name!r} "
                                f"{list(m.parameters)}, got {parameters}")
        self.parameters = tuple(parameters)
        self.p0 = np.array([self.params[k] for k in self.parameters], dtype=float)
        if isinstance(signature, str):
            signature = Signature.parse(signature)
        self.signature = Signature(signature)
        if self.signature and not self.signature.closed:
            raise ArgumentError(f"the signature {self.signature} is not closed: each event must "
                                f"start in the discrete state the previous one ends in")
        self.n = m.n_states
        self.q = len(self.parameters)
        self.forced = m.forcing_period is not None
        self.periods = V.integer("periods", periods, lo=1)
        self.t_ref = V.number("t_ref", t_ref)
        self._plan(state)
        self.m = len(self.bounds)
        if self.forced:
            self.size = 1 + self.m * (self.n + 1) if self.m else self.n
        else:
            self.size = self.m * (self.n + 1) if self.m else self.n + 1
        if not self.forced and not self.m:
            if phase_ref is None or phase_normal is None:
                raise ArgumentError("an autonomous orbit without events needs `phase_ref` and "
                                    "`phase_normal` (its phase condition)")
        self.phase_ref = None if phase_ref is None else V.vector("phase_ref", phase_ref,
                                                                  size=self.n)
        self.phase_normal = None if phase_normal is None else V.vector(
            "phase_normal", phase_normal, size=self.n)
        self._build_system()
        if self.forced:
            syms = m.parameter_symbols
            fp = m.forcing_period
            # the period itself is the model's (Model.forcing_period_at); its derivatives
            # with respect to the problem's parameters are the problem's own
            self._Tf_p = [sp.lambdify(syms, sp.diff(fp, sp.Symbol(k, real=True)), modules="math")
                          for k in self.parameters]

    def replace(self, *, signature=None, params=None, parameters=None, periods=None,
                t_ref=None, state=None, **options) -> "OrbitProblem":
        """The same problem (model, integrator options, sliding method, phase condition) with
        some of its definition changed: another signature (an event added or removed, the
        period doubled), other parameter values or continued parameters, another period or
        start time, integrator ``options`` over its own. An orbit without events keeps its
        discrete state unless ``state`` is given."""
        from ..integrate.simulate import DEFAULTS

        opts = {k: v for k, v in self.opts.items() if k in DEFAULTS
                and k not in ("variational", "dense", "throw", "mode", "sliding")}
        opts.update(options)
        sig = self.signature if signature is None else Signature(signature)
        kw = {}
        if not sig:
            kw["state"] = state if state is not None else str(self.state_names[0])
        return OrbitProblem(self.model, sig, params=self.params if params is None else params,
                            parameters=list(self.parameters if parameters is None
                                            else parameters),
                            periods=self.periods if periods is None else periods,
                            t_ref=self.t_ref if t_ref is None else t_ref,
                            phase_ref=self.phase_ref, phase_normal=self.phase_normal,
                            sliding=self.sliding, **kw, **opts)

    @classmethod
    def from_orbit(cls, orbit, *, parameters=None, params=None):
        """The problem of an orbit's signature and the ``u`` of that orbit.

        Parameters
        ----------
        orbit : PeriodicOrbit
            A converged orbit (of :func:`pwsdyn.find_periodic_orbit` or of this class).
        parameters : sequence of str, optional
            The problem's parameters (default all).
        params : dict, optional
            Parameter values overriding the orbit's (``u`` is still the orbit's).

        Returns
        -------
        (OrbitProblem, numpy.ndarray)
        """
        sig = Signature(orbit.signature)
        opts = {k: v for k, v in (orbit.options or {}).items()
                if k not in ("variational", "dense", "throw", "mode")}
        sliding = opts.pop("sliding", "convex")
        allp = dict(orbit.params)
        allp.update(params or {})
        P = float(orbit.period)
        evs = list(orbit.events)
        if not evs:
            kw = {}
            if orbit.autonomous:
                kw = dict(phase_ref=orbit.x0, phase_normal=orbit.phase_normal)
            prob = cls(orbit.model, sig, params=allp, parameters=parameters,
                       periods=orbit.periods or 1, t_ref=orbit.t0, state=orbit.state0,
                       sliding=sliding, **kw, **opts)
            return prob, prob.pack(orbit.t0, [orbit.x0], [P])
        groups = _groups(sig)
        te = [float(evs[g[0]].t) for g in groups]
        tau = [float(evs[g[-1]].t_after) for g in groups]
        X = [np.asarray(evs[g[-1]].x_after, dtype=float) for g in groups]
        t_start = [tau[-1] - P] + tau[:-1]
        x_start = [X[-1]] + X[:-1]
        durs = [a - b for a, b in zip(te, t_start)]
        prob = cls(orbit.model, sig, params=allp, parameters=parameters,
                   periods=orbit.periods or 1, t_ref=t_start[0], sliding=sliding, **opts)
        return prob, prob.pack(t_start[0], x_start, durs)

    # ==================================================================================
    # the signature as segments
    # ==================================================================================
    def _plan(self, state):
        m = self.model
        sig = self.signature
        if not sig:
            if state is None:
                state = m.mode_names[m.initial_mode]
            if not (isinstance(state, str) and _is_mode(state)):
                raise ArgumentError(f"an orbit without events runs in a mode of model "
                                    f"{m.name!r} {list(m.mode_names)}, got {state!r}")
            self.fields = [FieldKey("mode", _mode_by_name(m, state))]
            self.bounds = []
            self.state_names = [state]
            return
        if sig[0].kind == "stick":
            raise ArgumentError(f"the signature {sig} starts with the start of sticking, which "
                                f"follows an impact or chattering at the same instant: rotate it "
                                f"(Signature.rotated) to start after that")
        groups = [[sig[k] for k in g] for g in _groups(sig)]
        nev = len(sig)
        # the regular mode before each event (sticking constrains it)
        regular = [None] * nev
        for k in range(nev):
            for back in range(1, nev + 1):
                e = sig[(k - back) % nev]
                if _is_mode(e.mode_after):
                    regular[k] = e.mode_after
                    break
                if _is_mode(e.mode_before):
                    regular[k] = e.mode_before
                    break
        fields, bounds, names = [], [], []
        pos = 0
        for g in groups:
            e0 = g[0]
            name = e0.mode_before
            names.append(name)
            try:
                st = DiscreteState.parse(name)
            except ValueError:
                raise ArgumentError(f"unknown discrete state {name!r} in the signature") \
                    from None
            kind, ref = st.kind, st.name
            if kind == "mode":
                fk = FieldKey("mode", _mode_by_name(m, name))
                mode = fk.index
            elif kind == "stick":
                if regular[pos] is None:
                    raise ArgumentError(f"no regular mode precedes the sticking in {sig}")
                mode = _mode_by_name(m, regular[pos])
                fk = FieldKey("stick", m.event_index(ref), mode)
            elif kind == "slide":
                s = self._switch(ref)
                fk = FieldKey("slide", s)
                mode = int(m.switches[s].above)
            else:
                raise ArgumentError(f"unknown discrete state {name!r} in the signature")
            fields.append(fk)
            bounds.append(self._boundary(g, fk, mode))
            pos += len(g)
        self.fields = fields
        self.bounds = bounds
        self.state_names = names

    def _switch(self, name):
        for i, s in enumerate(self.model.switches):
            if s.name == name:
                return i
        raise ArgumentError(f"unknown switch {name!r} in the signature; switches are "
                            f"{[s.name for s in self.model.switches]}")

    def _boundary(self, g, fk: FieldKey, mode: int) -> _Boundary:
        m = self.model
        e = g[0]
        if e.kind in ("impact", "transition", "chatter"):
            j = m.event_index(e.name)
            ev = m.events[j]
            if e.kind == "chatter" and fk.kind != "mode":
                raise ArgumentError("a chattering sequence must start from a regular mode")
            k = ev.surface
            d = -1 if e.kind == "chatter" else int(ev.direction)
            return _Boundary(e.kind, tuple(g), j, k, mode, ("h", k), d)
        if e.kind in ("crossing", "slide_start"):
            s = self._switch(e.name)
            sw = m.switches[s]
            k = sw.surface
            d = 0
            if fk.kind == "mode":
                d = -1 if fk.index == sw.above else 1
            return _Boundary(e.kind, tuple(g), s, k, mode, ("h", k), d)
        if e.kind == "slide_end":
            s = self._switch(e.name)
            sw = m.switches[s]
            out = _mode_by_name(m, e.mode_after)
            if fk.kind != "slide" or fk.index != s:
                raise ArgumentError(f"a slide_end on {e.name!r} must end sliding on it")
            if out == sw.above:
                return _Boundary(e.kind, tuple(g), s, sw.surface, sw.above,
                                 ("hd", sw.surface, sw.above), 1)
            return _Boundary(e.kind, tuple(g), s, sw.surface, sw.below,
                             ("hd", sw.surface, sw.below), -1)
        if e.kind == "release":
            j = m.event_index(e.name)
            if fk.kind != "stick":
                raise ArgumentError("a release must end sticking")
            k = m.events[j].surface
            return _Boundary(e.kind, tuple(g), j, k, fk.mode, ("acc", k, fk.mode), 1)
        raise ArgumentError(f"a {e.kind!r} event cannot end a segment here")

    def _build_system(self):
        scalars, vectors = [], []
        for b in self.bounds:
            scalars.append(b.cond)
            if b.kind in ("impact", "transition"):
                vectors.append(("reset", b.ref))
            elif b.kind == "chatter":
                scalars += [("chat_dt", b.ref, b.mode), ("h", b.surface),
                            ("hd", b.surface, b.mode)]
                vectors += [("chat_z", b.ref, b.mode), ("hx", b.surface),
                            ("hdx", b.surface, b.mode)]
        key = (self.model.digest, self.parameters, self.sliding, tuple(self.fields),
               tuple(scalars), tuple(vectors))
        sysm = _SYSTEMS.get(key)
        if sysm is None:
            sysm = SegmentSystem(self.model, self.parameters, self.sliding, self.fields,
                                 scalars, vectors)
            _SYSTEMS[key] = sysm
        self.sys = sysm
        self._pv = np.ascontiguousarray(
            [self.params[k] for k in sysm.rest] or [0.0], dtype=float)
        self._fidx = [sysm.field_index(f) for f in self.fields]
        self._cidx = [sysm.scalar_index(b.cond) for b in self.bounds]

    # ==================================================================================
    # layout of u
    # ==================================================================================
    def _xcol(self, i: int) -> int:
        if not self.m:
            return 0
        return (1 if self.forced else 0) + i * (self.n + 1)

    def _Tcol(self, i: int) -> int:
        if not self.m:
            return self.n
        return self._xcol(i) + self.n

    def pack(self, t0, states, durations) -> np.ndarray:
        """``u`` from the start time of segment 0 (forced models), the segments' start states
        and durations (orbits without events: the state, and the period of an autonomous
        one)."""
        states = [np.asarray(x, dtype=float).reshape(self.n) for x in states]
        if not self.m:
            u = states[0]
            return np.append(u, float(durations[0])) if not self.forced else u.copy()
        parts = [[float(t0)]] if self.forced else []
        for x, T in zip(states, durations):
            parts += [x, [float(T)]]
        return np.concatenate([np.asarray(v, dtype=float) for v in parts])

    def unpack(self, u):
        """``(t0, states, durations)`` of ``u`` (the inverse of :meth:`pack`)."""
        u = np.asarray(u, dtype=float)
        if u.shape != (self.size,):
            raise ArgumentError(f"`u` must have {self.size} entries, got shape {u.shape}")
        if not self.m:
            return (self.t_ref, [u[:self.n].copy()],
                    [self.period_value(self.p0) if self.forced else float(u[self.n])])
        t0 = float(u[0]) if self.forced else self.t_ref
        xs = [u[self._xcol(i):self._xcol(i) + self.n].copy() for i in range(self.m)]
        Ts = [float(u[self._Tcol(i)]) for i in range(self.m)]
        return t0, xs, Ts

    # ==================================================================================
    # parameters
    # ==================================================================================
    def _p(self, p):
        if p is None:
            return self.p0.copy()
        p = np.asarray(p, dtype=float).reshape(-1)
        if p.shape != (self.q,) or not np.all(np.isfinite(p)):
            raise ArgumentError(f"`p` must hold {self.q} finite values {list(self.parameters)}")
        return p

    def param_dict(self, p=None) -> dict:
        """All parameter values of the model at the problem's ``p``."""
        out = dict(self.params)
        out.update(zip(self.parameters, (float(v) for v in self._p(p))))
        return out

    def period_value(self, p=None) -> float:
        """The period: ``periods * forcing_period`` (forced models)."""
        d = self.param_dict(p)
        return self.periods * self.model.forcing_period_at([d[k] for k in self.model.parameters])

    def _period_grad(self, p) -> np.ndarray:
        d = self.param_dict(p)
        args = [d[k] for k in self.model.parameters]
        return self.periods * np.array([float(g(*args)) for g in self._Tf_p])

    def _seg_opts(self, p, dense=False, variational=True):
        o = dict(self.opts, variational=variational, dense=dense, throw=False, chatter=False,
                 exact=False, mode=None)
        if self.forced and not math.isfinite(o["max_step"]):
            o["max_step"] = self.period_value(p) / self.periods / 4.0
        return o

    # ==================================================================================
    # evaluation
    # ==================================================================================
    def _dense_segment(self, i, s, p):
        """Segment ``i`` of an evaluation integrated again with dense output (no variational
        equations), for the checks along it; the last few are kept, so that the
        admissibility check and the monitors of one point integrate each segment once."""
        key = (i, float(s.t), np.asarray(s.z).tobytes(), float(s.T),
               np.asarray(p, dtype=float).tobytes())
        cache = self.__dict__.setdefault("_dense_cache", {})
        if key not in cache:
            if len(cache) > 4 * max(self.m, 1):
                cache.clear()
            cache[key] = self._flow(i, s.t, s.z, s.T,
                                    self._seg_opts(p, dense=True, variational=False))[2]
        return cache[key]

    def _flow(self, i, t, z, T, opts, dense=False):
        """``(y, Phi, traj)`` of segment field ``i`` from ``(t, z)`` for duration ``T``."""
        fidx = self._fidx[i]
        n = self.sys.naug
        if T == 0.0 or abs(T) <= 4 * np.spacing(max(1.0, abs(t))):
            return z.copy(), np.eye(n), None
        if T > 0:
            tr = _simulate_compiled(self.sys.cm, z, t, t + T, self._pv, opts, mode0=fidx,
                                    admit=False)
        else:
            tr = _simulate_compiled(self.sys.cm, z, -t, -t - T, self._pv, opts,
                                    mode0=self.sys.field_index(self.fields[i], reverse=True),
                                    admit=False)
        if tr.status.failed or not np.all(np.isfinite(tr.x_final)) or (
                tr.jacobian is not None and not np.all(np.isfinite(tr.jacobian))):
            raise SegmentFailed(i, f"segment {i} ({self.state_names[i]}) could not be "
                                f"integrated over {T:.6g} from t = {t:.10g}: {tr.message}")
        return np.array(tr.x_final, dtype=float), tr.jacobian, tr

    def _map(self, b: _Boundary, te, y, sysm):
        """``(tau, X, tau_t, tau_y, X_t, X_y)`` of boundary ``b`` at the event point."""
        n, na = self.n, sysm.naug
        pv = self._pv
        if b.kind in ("impact", "transition"):
            g, gz, gt = sysm.vector(sysm.vector_index(("reset", b.ref)), te, y, pv)
            return te, g, 1.0, np.zeros(na), gt, gz
        if b.kind != "chatter":
            return te, y.copy(), 1.0, np.zeros(na), np.zeros(na), np.eye(na)
        j, mode, k = b.ref, b.mode, b.surface
        Zv, Zz, Zt = sysm.vector(sysm.vector_index(("chat_z", j, mode)), te, y, pv)
        d, dz, dt = sysm.scalar(sysm.scalar_index(("chat_dt", j, mode)), te, y, pv)
        tau = te + d
        tau_t, tau_y = 1.0 + dt, dz
        X, Xtau, XZ = self._project(b, tau, Zv, sysm)
        # X(tau(te, y), Z(te, y))
        X_y = XZ @ Zz + np.outer(Xtau, tau_y)
        X_t = XZ @ Zt + Xtau * tau_t
        return tau, X, tau_t, tau_y, X_t, X_y

    def _project(self, b, tau, Z, sysm):
        """The kernel's projection of the chattering map onto the sticking manifold, as the
        solution of ``X = Z + N(tau, X) mu``, ``h(tau, X) = 0``, ``hd(tau, X) = 0`` with
        ``N = (h_x, hd_x)`` over the model's states; returns ``X`` (extended) and its
        derivatives with respect to ``tau`` and the extended ``Z`` (implicit function
        theorem)."""
        n, na = self.n, sysm.naug
        pv = self._pv
        ih, ihd = sysm.scalar_index(("h", b.surface)), sysm.scalar_index(("hd", b.surface,
                                                                          b.mode))
        i1, i2 = sysm.vector_index(("hx", b.surface)), sysm.vector_index(("hdx", b.surface,
                                                                          b.mode))
        X = Z.copy()
        mu = np.zeros(2)

        def parts(X):
            h, hz, ht = sysm.scalar(ih, tau, X, pv)
            hd, hdz, hdt = sysm.scalar(ihd, tau, X, pv)
            N1, J1, N1t = sysm.vector(i1, tau, X, pv)
            N2, J2, N2t = sysm.vector(i2, tau, X, pv)
            return h, hz, ht, hd, hdz, hdt, N1, J1, N1t, N2, J2, N2t

        for _ in range(8):
            h, hz, ht, hd, hdz, hdt, N1, J1, N1t, N2, J2, N2t = parts(X)
            R = np.concatenate([X[:n] - Z[:n] - N1[:n] * mu[0] - N2[:n] * mu[1], [h, hd]])
            A = self._proj_matrix(n, mu, hz, hdz, N1, J1, N2, J2)
            step = np.linalg.solve(A, -R)
            X[:n] += step[:n]
            mu += step[n:]
            if np.max(np.abs(step[:n])) <= 4 * np.finfo(float).eps * (1 + np.max(np.abs(X))):
                break
        h, hz, ht, hd, hdz, hdt, N1, J1, N1t, N2, J2, N2t = parts(X)
        A = self._proj_matrix(n, mu, hz, hdz, N1, J1, N2, J2)
        # G(X, mu; tau, Z) = 0: dG/dtau, dG/dZ (Z extended: its parameter part is p, which
        # also enters through the extended X)
        Gt = np.concatenate([-(N1t[:n] * mu[0] + N2t[:n] * mu[1]), [ht, hdt]])
        GZ = np.zeros((n + 2, na))
        GZ[:n, :n] = -np.eye(n)
        # parameter columns: through X's parameter part, which equals Z's
        GZ[:n, n:] = -(mu[0] * J1[:n, n:] + mu[1] * J2[:n, n:])
        GZ[n, n:] = hz[n:]
        GZ[n + 1, n:] = hdz[n:]
        Ainv = np.linalg.inv(A)
        Xtau = np.zeros(na)
        Xtau[:n] = -(Ainv @ Gt)[:n]
        XZ = np.zeros((na, na))
        XZ[:n, :] = -(Ainv @ GZ)[:n]
        XZ[n:, n:] = np.eye(na - n)
        return X, Xtau, XZ

    @staticmethod
    def _proj_matrix(n, mu, hz, hdz, N1, J1, N2, J2):
        A = np.zeros((n + 2, n + 2))
        A[:n, :n] = np.eye(n) - (mu[0] * J1[:n, :n] + mu[1] * J2[:n, :n])
        A[:n, n] = -N1[:n]
        A[:n, n + 1] = -N2[:n]
        A[n, :n] = hz[:n]
        A[n + 1, :n] = hdz[:n]
        return A

    def evaluate(self, u, p=None, *, jacobian: bool = True) -> ProblemEvaluation:
        """``F`` and (with ``jacobian``) ``F_u``, ``F_p`` at ``(u, p)``.

        Raises :class:`~pwsdyn.orbits.problem.SegmentFailed` when a segment cannot be integrated.
        """
        p = self._p(p)
        t0, xs, Ts = self.unpack(u)
        n, q, sysm = self.n, self.q, self.sys
        na = sysm.naug
        N = self.size
        Nw = N + q
        opts = self._seg_opts(p)
        pv = self._pv
        F = np.zeros(N)
        J = np.zeros((N, Nw))
        Dp = np.zeros((q, Nw))
        Dp[:, N:] = np.eye(q)

        def Dz_of(i):
            D = np.zeros((na, Nw))
            c = self._xcol(i)
            D[:n, c:c + n] = np.eye(n)
            D[n:] = Dp
            return D

        if not self.m:
            T = self.period_value(p) if self.forced else Ts[0]
            return self._evaluate_smooth(u, p, t0, xs[0], T, opts, Dz_of(0), jacobian)
        t = t0
        Dt = np.zeros(Nw)
        if self.forced:
            Dt[0] = 1.0
        segs = []
        for i, b in enumerate(self.bounds):
            z = np.concatenate([xs[i], p])
            T = Ts[i]
            y, Phi, _ = self._flow(i, t, z, T, opts)
            te = t + T
            fi = self._fidx[i]
            f_start = sysm.field(fi, t, z, pv)
            f_end = sysm.field(fi, te, y, pv)
            c, cz, ct = sysm.scalar(self._cidx[i], te, y, pv)
            tau, X, tau_t, tau_y, X_t, X_y = self._map(b, te, y, sysm)
            s = _Seg(t=t, z=z, T=T, te=te, y=y, tau=tau, X=X, Phi=Phi, f_start=f_start,
                     f_end=f_end, c=c, c_z=cz, c_t=ct, X_y=X_y, X_t=X_t, tau_y=tau_y,
                     tau_t=tau_t)
            r0 = i * (n + 1)
            k = (i + 1) % self.m
            F[r0:r0 + n] = xs[k] - X[:n]
            F[r0 + n] = c
            if jacobian:
                Dz = Dz_of(i)
                Dte = Dt.copy()
                Dte[self._Tcol(i)] += 1.0
                Dy = Phi @ Dz + np.outer(f_end, Dte) - np.outer(Phi @ f_start, Dt)
                Dtau = tau_t * Dte + tau_y @ Dy
                DX = np.outer(X_t, Dte) + X_y @ Dy
                J[r0 + n] = ct * Dte + cz @ Dy
                J[r0:r0 + n] = -DX[:n]
                c1 = self._xcol(k)
                J[r0:r0 + n, c1:c1 + n] += np.eye(n)
                s.Dt, s.Dz, s.Dte, s.Dy, s.Dtau, s.DX = Dt, Dz, Dte, Dy, Dtau, DX
                Dt = Dtau
            segs.append(s)
            t = tau
        period = t - t0
        Dper = None
        if jacobian:
            Dper = Dt.copy()
            if self.forced:
                Dper[0] -= 1.0
        if self.forced:
            F[-1] = period - self.period_value(p)
            if jacobian:
                J[-1] = Dper
                J[-1, N:] -= self._period_grad(p)
        return ProblemEvaluation(np.asarray(u, dtype=float).copy(), p, F,
                                 J[:, :N] if jacobian else None,
                                 J[:, N:] if jacobian else None, period, segs, Dper)

    def _evaluate_smooth(self, u, p, t0, x0, T, opts, Dz, jacobian):
        """No events: single shooting over the period (autonomous: with a phase condition)."""
        n, q, sysm = self.n, self.q, self.sys
        N = self.size
        z = np.concatenate([x0, p])
        y, Phi, _ = self._flow(0, t0, z, T, opts)
        f_end = sysm.field(self._fidx[0], t0 + T, y, self._pv)
        f_start = sysm.field(self._fidx[0], t0, z, self._pv)
        F = np.zeros(N)
        F[:n] = y[:n] - x0
        J = np.zeros((N, N + q))
        Dt = np.zeros(N + q)
        DT = np.zeros(N + q)
        if self.forced:
            DT[N:] = self._period_grad(p)
        else:
            DT[n] = 1.0
            F[n] = self.phase_normal @ (x0 - self.phase_ref)
            J[n, :n] = self.phase_normal
        Dy = Phi @ Dz + np.outer(f_end, DT)
        J[:n] = Dy[:n]
        J[:n, :n] -= np.eye(n)
        s = _Seg(t=t0, z=z, T=T, te=t0 + T, y=y, tau=t0 + T, X=y, Phi=Phi, f_start=f_start,
                 f_end=f_end, Dt=Dt, Dz=Dz, Dte=DT, Dy=Dy, Dtau=DT, DX=Dy)
        return ProblemEvaluation(np.asarray(u, dtype=float).copy(), p, F,
                                 J[:, :N] if jacobian else None, J[:, N:] if jacobian else None,
                                 T, [s], DT)

    def residual(self, u, p=None) -> np.ndarray:
        """``F(u, p)``."""
        return self.evaluate(u, p, jacobian=False).F

    def jacobian(self, u, p=None):
        """``(F_u, F_p)`` at ``(u, p)``."""
        ev = self.evaluate(u, p)
        return ev.F_u, ev.F_p

    def norm(self, F, u) -> float:
        """Size of a residual: ``max|F| / (1 + max|x_i|)`` (the states, not the times)."""
        _, xs, _ = self.unpack(u)
        return float(np.max(np.abs(F)) / (1.0 + max(float(np.max(np.abs(x))) for x in xs)))

    # ==================================================================================
    # Newton
    # ==================================================================================
    def solve(self, u0, p=None, *, tol: float = 1e-10, max_iter: int = 30, history=None):
        """Newton's method on ``F(., p) = 0`` from ``u0`` (:func:`pwsdyn.newton.newton`).

        Returns the :class:`~pwsdyn.newton.NewtonResult` (its ``x`` is ``u``); a segment that
        cannot be integrated rejects the trial (reason ``'simulation'`` at the start).
        """
        p = self._p(p)
        cache: dict = {}

        def fun(u):
            try:
                ev = self.evaluate(u, p)
            except SegmentFailed as exc:
                raise TrialRejected(exc.message, "simulation") from None
            cache["ev"] = ev
            return ev.F

        def jac(u):
            return cache["ev"].F_u

        res = newton(fun, u0, jac=jac, tol=tol, max_iter=max_iter, norm=self.norm,
                     history=history)
        res.evaluation = cache.get("ev")
        return res

    # ==================================================================================
    # a guess that follows the signature
    # ==================================================================================
    def follow(self, t0: float, x0, p=None, *, horizon: float | None = None) -> np.ndarray:
        """``u`` from a state ``x0`` at ``t0`` in segment 0 (the segment the signature's first
        event ends): each segment is integrated in its discrete state, whatever surfaces it
        meets, to the first zero of its condition, the event map applied, and so on around
        the signature and once more through segment 0.

        Raises :class:`~pwsdyn.ArgumentError` when a segment does not reach its condition within
        ``horizon`` (default: twice the period of a forced orbit; required for an autonomous
        one, whose ``t_ref`` is set to the start of segment 0 found).
        """
        p = self._p(p)
        x0 = np.asarray(x0, dtype=float).reshape(self.n)
        if not self.m:
            T = self.period_value(p) if self.forced else float(horizon)
            return self.pack(t0, [x0], [T])
        if horizon is None:
            horizon = 2.0 * self.period_value(p) if self.forced else None
        if horizon is None:
            raise ArgumentError("give `horizon` (a bound on a segment's duration) to follow the "
                                "signature of an autonomous orbit")
        # a first step far below the horizon: the kernel's steps then grow from it (at most
        # tenfold each), so a short segment (a bounce of a chattering sequence) is resolved
        opts = dict(self._seg_opts(p, dense=True, variational=False),
                    first_step=max(1e-10 * horizon, 1e-300))
        z = np.concatenate([x0, p])
        t = float(t0)
        starts, durs = [None] * self.m, [None] * self.m
        for step, i in enumerate(list(range(self.m)) + [0]):
            start_t, start_x = t, z[:self.n].copy()
            te, y = self._first_zero(i, t, z, horizon, opts)
            tau, X, *_ = self._map(self.bounds[i], te, y, self.sys)
            if step:
                starts[i] = (start_t, start_x)
                durs[i] = te - start_t
            t = tau
            z = np.array(X, dtype=float)
            z[self.n:] = p
        if not self.forced:
            self.t_ref = float(starts[0][0])
        return self.pack(starts[0][0], [s[1] for s in starts], durs)

    def from_simulation(self, t0: float, x0, p=None, *, horizon: float | None = None):
        """``u`` from a simulation of the model from ``x0`` at ``t0`` (in the state of segment
        0), when its events reproduce the signature (from its first event on, and the first
        event once more); ``None`` otherwise. The simulator resolves what :meth:`follow`
        cannot: the bounces at the end of a chattering sequence rise less than the
        integration error."""
        p = self._p(p)
        if not self.m:
            return None
        if horizon is None:
            horizon = 2.5 * self.period_value(p) if self.forced else None
        if horizon is None:
            return None
        ctx = _context(self.model, self.param_dict(p), self.sliding)
        fk = self.fields[0]

        if fk.kind == "mode":
            st = KernelState(REGULAR, -1, fk.index)
        elif fk.kind == "stick":
            st = KernelState(STICK, fk.index, fk.mode)
        else:
            st = KernelState(SLIDE, fk.index, int(ctx.stab[fk.index]["above"]))
        opts = dict(self.opts, variational=False, dense=False, throw=False, mode=None)
        nev = len(self.signature)
        try:
            tr = _simulate_compiled(ctx.cm, np.asarray(x0, dtype=float), float(t0),
                                    float(t0) + horizon, ctx.p, opts, mode0=st.mode,
                                    dkind0=st.kind, didx0=st.index, admit=False,
                                    stop=((1 << 8) - 1, -1, nev + 1))
        except (ValueError, FloatingPointError):
            return None
        evs = list(tr.events)
        if len(evs) < nev + 1 or Signature(evs[:nev]) != self.signature or \
                (evs[nev].kind, evs[nev].name) != (self.signature[0].kind,
                                                   self.signature[0].name):
            return None
        groups = _groups(self.signature)
        te = [float(evs[g[0]].t) for g in groups]
        tau = [float(evs[g[-1]].t_after) for g in groups]
        X = [np.asarray(evs[g[-1]].x_after, dtype=float) for g in groups]
        t_s = tau[-1]
        xs = [X[-1]] + X[:-1]
        durs = [float(evs[nev].t) - t_s] + [te[i] - tau[i - 1] for i in range(1, self.m)]
        if not self.forced:
            self.t_ref = float(t_s)
        return self.pack(t_s, xs, durs)

    def _first_zero(self, i, t, z, horizon, opts):
        """The first zero of segment ``i``'s condition from ``(t, z)`` within ``horizon``,
        searched in eight pieces of the horizon (a mode's field continued far beyond its
        surfaces may blow up: the search stops at the zero, or where integration fails)."""
        from scipy.optimize import brentq

        sysm = self.sys
        ci = self._cidx[i]
        side = None
        t_a, z_a = t, z
        for piece in range(8):
            tr = _simulate_compiled(self.sys.cm, z_a, t_a, t_a + horizon / 8.0, self._pv, opts,
                                    mode0=self._fidx[i], admit=False)
            ts = _sample_times(tr)
            if len(ts) < 2:
                break
            Y = tr(ts)
            vals = np.array([sysm.scalar(ci, tt, yy, self._pv, grad=False)
                             for tt, yy in zip(ts, Y)])
            if side is None:
                # the condition may vanish at the start (an impact surface just after the
                # impact, a bounce of a chattering sequence): its side is then the one its
                # rate points to
                scale = 1.0 + float(np.max(np.abs(Y[:, :self.n])))
                band = ADMISSIBILITY_RTOL * scale
                c0, cz0, ct0 = sysm.scalar(ci, ts[0], Y[0], self._pv)
                side = np.sign(vals[0])
                # a start tangent to the condition (a sliding exit on the surface the next
                # sliding entry is on) cannot tell its side from round-off: a crossing must
                # then leave the band
                need = 0.0
                if abs(vals[0]) <= band:
                    f0 = sysm.field(self._fidx[i], ts[0], Y[0], self._pv)
                    rate = ct0 + cz0 @ f0
                    side = np.sign(rate)
                    rband = band * max(1.0, float(np.max(np.abs(cz0))) * float(
                        np.max(np.abs(f0))))
                    if abs(rate) <= rband:
                        need = band
                        nz = vals[np.abs(vals) > band]
                        side = np.sign(nz[0]) if len(nz) else 1.0

            def g(tt):
                return sysm.scalar(ci, tt, tr(tt), self._pv, grad=False)

            for k in range(1, len(vals)):
                if vals[k] * side < -need and np.isfinite(vals[k]):
                    a, b = ts[k - 1], ts[k]
                    if g(a) * side <= 0:
                        # the start's own zero (round-off on the wrong side): the last point
                        # on the condition's side before b
                        grid = np.linspace(a, b, 65)[1:-1]
                        on = [tt for tt in grid if g(tt) * side > 0]
                        if not on:
                            continue
                        a = on[-1]
                    tz = brentq(g, a, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)
                    return tz, np.array(tr(tz), dtype=float)
            if tr.status.failed or not np.all(np.isfinite(tr.x_final)):
                break
            t_a, z_a = float(tr.t_final), np.array(tr.x_final, dtype=float)
        raise ArgumentError(f"cannot follow the signature from t = {t:.10g}: segment {i} "
                            f"({self.state_names[i]}) does not reach its "
                            f"{self.bounds[i].kind} condition within {horizon:.6g}; the guess "
                            f"is not near an orbit of signature {self.signature}")

    # ==================================================================================
    # admissibility
    # ==================================================================================
    def admissibility(self, u, p=None, evaluation: ProblemEvaluation | None = None
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
        p = self._p(p)
        ev = evaluation if evaluation is not None else self.evaluate(u, p, jacobian=False)
        ctx = _context(self.model, self.param_dict(p), self.sliding)
        out = []
        # a segment that vanishes at a graze (a sliding segment shrinking to nothing) has a
        # duration of round-off size, of either sign, at the located point
        t_band = ADMISSIBILITY_RTOL * max(1.0, sum(abs(float(s.T)) for s in ev.segs))
        for i, s in enumerate(ev.segs):
            name = self.state_names[i]
            if s.T < -t_band:
                out.append(f"segment {i} ({name}) has a negative duration {s.T:.3e}: the "
                           f"event that should end it comes before its start")
                continue
            if s.T > 0:
                out += self._interior(i, s, ctx, p)
            if i < len(self.bounds):
                out += self._at_boundary(i, s, ctx)
        return Admissibility(not out, out[0] if out else None, tuple(out))

    def _interior(self, i, s, ctx, p):
        n = self.n
        tr = self._dense_segment(i, s, p)
        if tr is None:
            return []
        ts = _sample_times(tr)[1:-1]
        if not len(ts):
            return []
        Y = np.asarray(tr(ts))[:, :n]
        scale = 1.0 + float(np.max(np.abs(Y)))
        fk = self.fields[i]
        m = self.model
        checks = []   # ("side", label, fn, sign): sign * fn >= -band; ("event", label, fn, j)
        if fk.kind in ("mode", "stick"):
            mode = fk.index if fk.kind == "mode" else fk.mode
            for j, e in enumerate(m.events):
                if mode not in e.modes:
                    continue
                if fk.kind == "stick" and e.surface == m.events[fk.index].surface:
                    continue
                checks.append(("event", f"{e.kind} event {e.name!r}", _h(ctx, e.surface), j))
            for sw in m.switches:
                if sw.above == mode:
                    checks.append(("side", f"side of switching surface {sw.name!r} (mode "
                                   f"{m.modes[mode].name!r} holds above it)",
                                   _h(ctx, sw.surface), +1))
                elif sw.below == mode:
                    checks.append(("side", f"side of switching surface {sw.name!r} (mode "
                                   f"{m.modes[mode].name!r} holds below it)",
                                   _h(ctx, sw.surface), -1))
            if fk.kind == "stick":
                k = m.events[fk.index].surface
                checks.append(("side", f"contact of sticking on {m.events[fk.index].name!r} "
                               f"(the free normal acceleration must press into the surface)",
                               _acc(ctx, k, fk.mode), -1))
        else:
            sw = m.switches[fk.index]
            k = sw.surface
            checks.append(("side", f"sliding region of {sw.name!r} (the field above must point "
                           f"into the surface)", _hd(ctx, k, sw.above), -1))
            checks.append(("side", f"sliding region of {sw.name!r} (the field below must point "
                           f"into the surface)", _hd(ctx, k, sw.below), +1))
            for j, e in enumerate(m.events):
                if sw.above in e.modes or sw.below in e.modes:
                    checks.append(("event", f"{e.kind} event {e.name!r}", _h(ctx, e.surface),
                                   j))
        out = []
        for what, label, fn, rule in checks:
            vals = fn.rows(ts, Y)
            band = ADMISSIBILITY_RTOL * scale * fn.gscale
            if what == "side":
                worst = _worst(fn, tr, ts, vals, rule, n, limit=-band)
                if rule * worst[1] < -band:
                    out.append(f"segment {i} ({self.state_names[i]}) leaves the {label}: "
                               f"value {worst[1]:.3e} at t = {worst[0]:.10g}")
                continue
            # an event of the model: does it fire inside the segment?
            e = m.events[rule]
            if e.kind == "impact":
                worst = _worst(fn, tr, ts, vals, +1, n, limit=-band)
                if worst[1] < -band and _guard(ctx, rule, worst[0], tr(worst[0])[:n]):
                    out.append(f"segment {i} ({self.state_names[i]}) passes through the "
                               f"constraint of impact event {e.name!r}: h = {worst[1]:.3e} < 0 "
                               f"at t = {worst[0]:.10g} (the orbit is past a grazing)")
                continue
            for kk in range(1, len(vals)):
                a, bb = vals[kk - 1], vals[kk]
                crossed = ((e.direction <= 0 and a > band and bb < -band)
                           or (e.direction >= 0 and a < -band and bb > band))
                if crossed and _guard(ctx, rule, ts[kk], Y[kk]):
                    out.append(f"segment {i} ({self.state_names[i]}) crosses the surface of "
                               f"transition {e.name!r} near t = {ts[kk]:.10g} without the "
                               f"event")
                    break
        return out

    def _at_boundary(self, i, s, ctx):
        b = self.bounds[i]
        n, m = self.n, self.model
        te, y = s.te, s.y[:n]
        st = self.state_names[i]
        scale = 1.0 + float(np.max(np.abs(y)))
        out = []
        fk = self.fields[i]
        f_in = _state_field(ctx, fk, te, y)
        if b.kind in ("impact", "transition", "chatter"):
            e = m.events[b.ref]
            hx = ctx.h_x(b.surface, te, y)
            rate = ctx.h_t(b.surface, te, y) + hx @ f_in
            band = ADMISSIBILITY_RTOL * scale * max(1.0, float(np.max(np.abs(hx))))
            d = -1 if b.kind == "chatter" else e.direction
            if d * rate < -band:
                what = ("the flow leaves the constraint there instead of hitting it (an impact "
                        "with the wrong sign of the normal velocity)" if e.kind == "impact"
                        else "the flow crosses the surface against the event's direction")
                out.append(f"{b.kind} {e.name!r} ending segment {i} ({st}) at t = {te:.10g}: "
                           f"h_t + h_x f = {rate:.3e}; {what}")
            if not _guard(ctx, b.ref, te, y):
                out.append(f"{b.kind} {e.name!r} ending segment {i} at t = {te:.10g}: its "
                           f"guard does not hold")
            if b.kind == "chatter":
                acc = _acc(ctx, b.surface, b.mode)(te, y)
                if acc > ADMISSIBILITY_RTOL * scale:
                    out.append(f"chattering on {e.name!r} at t = {te:.10g}: the free normal "
                               f"acceleration {acc:.3e} pulls away from the surface")
                if s.tau < te:
                    out.append(f"chattering on {e.name!r} at t = {te:.10g}: the accumulation "
                               f"time lies before the first impact")
        elif b.kind in ("crossing", "slide_start"):
            sw = m.switches[b.ref]
            ha = _hd(ctx, b.surface, sw.above)(te, y)
            hb = _hd(ctx, b.surface, sw.below)(te, y)
            band = ADMISSIBILITY_RTOL * scale * _hd(ctx, b.surface, sw.above).gscale
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

    # ==================================================================================
    # monitors of discontinuity-induced bifurcations
    # ==================================================================================
    def _bounding_surfaces(self, mode: int) -> list:
        """``(name, surface index, sign, other mode)`` of the surfaces a segment in ``mode``
        must not cross: its impact surfaces (sign +1: ``h >= 0``) and the switching surfaces
        bounding its region (sign +1 above, -1 below; ``other`` the mode beyond a Filippov
        switch, -1 otherwise)."""
        m = self.model
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

    def dib_monitors(self, u, p=None, evaluation: ProblemEvaluation | None = None) -> dict:
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
        * ``"CC/<surface>@<i>"`` at an impact, transition or crossing ending a segment in a
          mode: the value of another surface of the mode there, signed positive on the
          segment's side (a corner collision where it vanishes: the event point reaches the
          intersection of the two surfaces).

        A segment with no interior local minimum of a surface gives no monitor for it.
        """
        p = self._p(p)
        ev = evaluation if evaluation is not None else self.evaluate(u, p, jacobian=False)
        ctx = _context(self.model, self.param_dict(p), self.sliding)
        m, n = self.model, self.n
        out = {}
        for i, s in enumerate(ev.segs):
            fk = self.fields[i]
            out.update(self._arc_monitor(i, s))
            if fk.kind == "mode" and s.T > 0:
                tr = self._dense_segment(i, s, p)
                if tr is None:
                    continue
                ts = _sample_times(tr)[1:-1]
                if len(ts) < 3:
                    continue
                Y = np.asarray(tr(ts))[:, :n]
                for name, k, sign, other in self._bounding_surfaces(fk.index):
                    fn = _h(ctx, k)
                    vals = sign * fn.rows(ts, Y)
                    found = _interior_minimum(lambda tt: sign * fn(tt, tr(tt)[:n]), ts, vals)
                    if found is None:
                        continue
                    tg, hg = found
                    xg = np.asarray(tr(tg)[:n], dtype=float)
                    kind = "GR"
                    if other >= 0:
                        # a Filippov surface: where the field on the other side points back
                        # into it, touching it starts sliding (grazing-sliding, GS); else the
                        # orbit would cross it (a grazing of the crossing region, GR)
                        rate = _hd(ctx, k, other)(tg, xg)
                        kind = "GS" if sign * rate > 0 else "GR"
                    out[f"{kind}/{name}/{i}"] = Monitor(float(hg), i, name, float(tg), xg)
            elif fk.kind == "slide" and s.T > 0:
                out.update(self._sliding_monitors(i, s, p, ctx))
            b = self.bounds[i] if i < len(self.bounds) else None
            if b is None:
                continue
            te, y = s.te, np.asarray(s.y[:n], dtype=float)
            if fk.kind == "mode" and b.kind in ("impact", "transition", "crossing"):
                # corner collision: the event point reaches another surface of the segment's
                # mode (the orbit passes through the intersection of two surfaces)
                for name, k, sign, _ in self._bounding_surfaces(fk.index):
                    if k != b.surface:
                        out[f"CC/{name}@{i}"] = Monitor(float(sign * ctx.h(k, te, y)), i, name,
                                                        float(te), y)
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
                    value = sign * _hd(ctx, b.surface, beyond)(te, y)
                    kind = "CS" if _boundary_rate(ctx, b.ref, beyond, te, y) * sign > 0 else "SS"
                    out[f"{kind}/{sw.name}@{i}"] = Monitor(float(value), i, sw.name,
                                                           float(te), y)
            if b.kind == "impact":
                e = m.events[b.ref]
                f_in = _state_field(ctx, fk, te, y)
                rate = ctx.h_t(b.surface, te, y) + ctx.h_x(b.surface, te, y) @ f_in
                out[f"GR/{e.name}@{i}"] = Monitor(float(-rate), i, e.name, float(te), y)
            elif b.kind == "slide_start" and fk.kind == "mode":
                # switching-sliding: the point where the orbit reaches the surface leaves the
                # sliding region through its other boundary (the field beyond stops pointing
                # back); past it the orbit crosses, runs in the other mode and returns
                sw = m.switches[b.ref]
                other = sw.above if fk.index == sw.below else sw.below
                sign = -1.0 if other == sw.above else 1.0
                rate = _hd(ctx, b.surface, other)(te, y)
                # where the sliding flow at the entry leaves the region into that other mode,
                # entry and exit meet on the boundary and the sliding segment shrinks to
                # nothing: past it the orbit just crosses (crossing-sliding, seen from its
                # sliding side); else it slides away and the exit is elsewhere
                # (switching-sliding)
                kind = "CS" if _boundary_rate(ctx, b.ref, other, te, y) * sign < 0 else "SS"
                out[f"{kind}/{sw.name}@{i}"] = Monitor(float(sign * rate), i, sw.name,
                                                       float(te), y)
                nb = self.bounds[(i + 1) % self.m]
                if nb.kind == "slide_end" and nb.mode == fk.index:
                    # grazing-sliding seen from the sliding side: the orbit arrives ever more
                    # tangentially and leaves back into the same mode; where its normal
                    # velocity vanishes the sliding segment shrinks to nothing and past it
                    # the orbit only touches the surface
                    into = 1.0 if fk.index == sw.above else -1.0
                    arrival = _hd(ctx, b.surface, fk.index)(te, y)
                    out[f"GS/{sw.name}@{i}"] = Monitor(float(-into * arrival), i, sw.name,
                                                       float(te), y)
            elif b.kind == "slide_end":
                # adding-sliding: the field the orbit leaves the surface with is tangent to it
                # at the exit (h_x f = 0) and its normal acceleration vanishes too (a cubic
                # tangency, the slides' <<h_x, f1>_x, f1> = 0): past it the orbit comes back
                sw = m.switches[b.ref]
                acc = _acc(ctx, b.surface, b.mode)(te, y)
                sign = 1.0 if b.mode == sw.above else -1.0
                out[f"AS/{sw.name}@{i}"] = Monitor(float(sign * acc), i, sw.name, float(te), y)
        return out

    def _arc_monitor(self, i, s) -> dict:
        """``"GR/<surface>/<i>/arc"``: for segment ``i`` entered and left by crossings of one
        switching surface (an arc on its other side), the arc's duration. Where it falls to
        zero the two crossings meet: the orbit grazes the surface from the side it used to
        cross from, and past it stays there. (Not the arc's height: the branch of the locked
        signature folds back at the graze, so the height only touches zero; the duration
        changes sign along the branch.)"""
        if not self.m or len(self.bounds) != len(self.signature):
            return {}
        before, after = self.bounds[(i - 1) % self.m], self.bounds[i]
        if not (before.kind == after.kind == "crossing" and before.ref == after.ref):
            return {}
        name = self.model.surfaces[after.surface].name
        return {f"GR/{name}/{i}/arc": Monitor(float(s.T), i, name, float(s.t),
                                              np.asarray(s.y[:self.n], dtype=float))}

    def _sliding_monitors(self, i, s, p, ctx) -> dict:
        """``"AS/<switch>:<above|below>/<i>"``: along sliding segment ``i``, the smallest
        interior local minimum of the normal velocity of the field on each side, signed
        positive while it points into the surface (inside the sliding region). Where it
        reaches zero the sliding flow touches the region's boundary (``h_x f = 0`` and
        ``(h_x f)_x f = 0`` there: adding-sliding, the slides' defining conditions); past it
        the orbit leaves at the touching point, runs a short arc and slides again."""
        sw = self.model.switches[self.fields[i].index]
        tr = self._dense_segment(i, s, p)
        if tr is None:
            return {}
        ts = _sample_times(tr)[1:-1]
        if len(ts) < 3:
            return {}
        n = self.n
        Y = np.asarray(tr(ts))[:, :n]
        out = {}
        for side, mode, sign in (("above", sw.above, -1.0), ("below", sw.below, 1.0)):
            fn = _hd(ctx, sw.surface, mode)
            vals = np.array([sign * fn(t, y) for t, y in zip(ts, Y)])
            found = _interior_minimum(lambda tt: sign * fn(tt, tr(tt)[:n]), ts, vals)
            if found is not None:
                tg, hg = found
                out[f"AS/{sw.name}:{side}/{i}"] = Monitor(
                    float(hg), i, sw.name, float(tg), np.asarray(tr(tg)[:n], dtype=float))
        return out

    # ==================================================================================
    # results
    # ==================================================================================
    def monodromy(self, ev: ProblemEvaluation) -> np.ndarray:
        """The one-period Jacobian (full saltation matrices) at the start of segment 0."""
        M = np.eye(self.n)
        for i, s in enumerate(ev.segs):
            M = s.Phi[:self.n, :self.n] @ M
            if i < len(self.bounds):
                M = self._saltation(i, s) @ M
        return M

    def _saltation(self, i, s) -> np.ndarray:
        """Full saltation matrix of boundary ``i`` (model states), of its event map
        ``(t, x) -> (tau, X)`` (:func:`~pwsdyn.stability._saltation.event_map_saltation`)."""
        n = self.n
        k = (i + 1) % self.m
        zX = np.array(s.X, dtype=float)
        Fo = self.sys.field(self._fidx[k], s.tau, zX, self._pv)[:n]
        fi = s.f_end[:n]
        cx = s.c_z[:n]
        den = s.c_t + cx @ fi
        # den = 0 at an event with zero normal velocity (a graze): the matrix is infinite,
        # left to the callers to see (multipliers NaN)
        with np.errstate(divide="ignore", invalid="ignore"):
            return event_map_saltation(s.X_y[:n, :n], s.X_t[:n], fi, Fo, cx, den,
                                       tau_x=s.tau_y[:n], tau_t=s.tau_t)

    def multipliers(self, ev: ProblemEvaluation) -> np.ndarray:
        """Floquet multipliers of the orbit at ``ev`` (nontrivial ones, autonomous)."""
        M = self.monodromy(ev)
        if self.forced:
            return floquet_multipliers(M)
        f0 = ev.segs[0].f_start[:self.n]
        return floquet_multipliers(M, flow_direction=f0)

    # ---- the base point of a reported orbit ------------------------------------------------
    def _base(self, ev, t0=None, x_ref=None, normal=None):
        """``(k, s, shift)``: the base point lies in segment ``k``, ``s`` after its start, and
        its time is ``t_k + s + shift`` (``shift`` a multiple of the period).

        Forced: the segment containing ``t0`` modulo the period. Autonomous with a section
        (``x_ref``, ``normal``): where the orbit crosses ``normal . (x - x_ref) = 0`` with
        ``normal . f > 0``, nearest ``x_ref``. Otherwise the middle of the longest segment in
        a mode (the longest segment)."""
        segs = ev.segs
        P = ev.period
        if not self.m:
            if t0 is not None and self.forced:
                k = math.floor((t0 - segs[0].t) / P)
                return 0, t0 - segs[0].t - k * P, k * P
            return 0, 0.0, 0.0
        if self.forced and t0 is not None:
            kshift = math.floor((t0 - segs[0].t) / P)
            tt = t0 - kshift * P
            for i, sg in enumerate(segs):
                if sg.T > 0 and sg.t <= tt < sg.te:
                    return i, tt - sg.t, kshift * P
        if not self.forced and x_ref is not None and normal is not None:
            best = None
            opts = self._seg_opts(ev.p, dense=True, variational=False)
            x_ref = np.asarray(x_ref, dtype=float)
            normal = np.asarray(normal, dtype=float)
            for i, sg in enumerate(segs):
                if sg.T <= 0:
                    continue
                _, _, tr = self._flow(i, sg.t, sg.z, sg.T, opts)
                ts = _sample_times(tr)
                g = np.asarray(tr(ts))[:, :self.n] @ normal - normal @ x_ref
                for kk in range(1, len(ts)):
                    if g[kk - 1] < 0 <= g[kk]:
                        from scipy.optimize import brentq

                        tz = brentq(lambda tt: normal @ (tr(tt)[:self.n] - x_ref), ts[kk - 1],
                                    ts[kk], xtol=1e-15, rtol=4 * np.finfo(float).eps)
                        d = float(np.linalg.norm(tr(tz)[:self.n] - x_ref))
                        if (0.0 < tz - sg.t < sg.T) and (best is None or d < best[0]):
                            best = (d, i, tz - sg.t)
            if best is not None:
                shift = 0.0
                if t0 is not None and P > 0:
                    tb = segs[best[1]].t + best[2]
                    shift = round((t0 - tb) / P) * P
                return best[1], best[2], shift
        cands = [i for i, f in enumerate(self.fields) if f.kind == "mode"] or list(
            range(self.m))
        k = max(cands, key=lambda i: segs[i].T)
        return k, 0.5 * segs[k].T, 0.0

    def _order(self, k):
        return list(range(k, self.m)) + list(range(k))

    # ---- the reported orbit ----------------------------------------------------------------
    def orbit(self, u, p=None, *, t0=None, x_ref=None, phase_normal=None, history=None,
              converged: bool = True):
        """The :class:`~pwsdyn.PeriodicOrbit` at ``(u, p)``.

        Its base point: forced orbits at time ``t0`` (default: the middle of the longest
        segment in a mode); autonomous orbits where they cross the hyperplane through
        ``x_ref`` with normal ``phase_normal`` (the section of
        :func:`pwsdyn.find_periodic_orbit`), else the middle of the longest segment. The
        trajectory (one period, dense, with the variational solution) is assembled from the
        segments integrated in their discrete states and the events from the signature, so
        an orbit that is not admissible is reported as it is, with ``admissible = False`` and
        the reason. Monodromy: the segments' flow Jacobians and the boundaries' full
        saltation matrices (``_saltation``).
        """

        p = self._p(p)
        ev = self.evaluate(u, p, jacobian=False)
        adm = self.admissibility(u, p, ev)
        n = self.n
        k, s_off, shift = self._base(ev, t0, x_ref, phase_normal)
        P = ev.period
        opts = self._seg_opts(p, dense=True, variational=True)
        segs = ev.segs
        sk = segs[k]
        t_base = sk.t + s_off + shift
        zb, _, _ = self._flow(k, sk.t, sk.z, s_off, opts)
        # pieces: (run or None for no time, state name, start time, start state)
        first = P if not self.m else sk.T - s_off
        pieces = [(self._flow(k, t_base, zb, first, opts)[2], self.state_names[k], t_base, zb)]
        records, salts = [], []
        order = self._order(k) if self.m else []
        for pos, i in enumerate(order):
            sg = segs[i]
            off = shift + (P if i < k else 0.0)
            b = self.bounds[i] if self.m else None
            if b is not None:
                S = self._saltation(i, sg)
                e0 = b.events[0]
                records.append(EventRecord(sg.te + off, e0.name, e0.kind, sg.y[:n].copy(),
                                           np.array(sg.X[:n]), e0.mode_before, e0.mode_after,
                                           sg.tau + off))
                salts.append(S)
                for e in b.events[1:]:
                    records.append(EventRecord(sg.tau + off, e.name, e.kind,
                                               np.array(sg.X[:n]), np.array(sg.X[:n]),
                                               e.mode_before, e.mode_after, sg.tau + off))
                    salts.append(np.eye(n))
            nxt = order[pos + 1] if pos + 1 < len(order) else None
            if nxt is not None:
                sn = segs[nxt]
                offn = shift + (P if nxt < k else 0.0)
                pieces.append((self._flow(nxt, sn.t + offn, sn.z, sn.T, opts)[2],
                               self.state_names[nxt], sn.t + offn, sn.z))
        if self.m:
            pieces.append((self._flow(k, sk.t + shift + P, sk.z, s_off, opts)[2],
                           self.state_names[k], sk.t + shift + P, sk.z))
        traj, transfer, M = self._assemble(pieces, records, salts, p, t_base, t_base + P)
        x0 = np.array(zb[:n], dtype=float)
        state0 = self.state_names[k]
        autonomous = not self.forced
        ctx = _context(self.model, self.param_dict(p), self.sliding)
        trivial = pj = nv = None
        if not np.all(np.isfinite(M)):
            # an event at zero normal velocity (the orbit at a graze of its own impact): the
            # saltation matrix is infinite there and the orbit has no multipliers
            mult = np.full(n - (1 if autonomous else 0), np.nan + 0j)
        elif autonomous:
            f0 = _state_field(ctx, self.fields[k], t_base, x0)
            nv = f0 if phase_normal is None else np.asarray(phase_normal, dtype=float)
            mult = floquet_multipliers(M, flow_direction=f0, section_normal=nv)
            pj = M - np.outer(f0, nv @ M) / (nv @ f0)
            eg = np.linalg.eigvals(M)
            trivial = complex(eg[np.argmin(np.abs(eg - 1.0))])
        else:
            mult = floquet_multipliers(M)
        hist = list(history) if history is not None else [self.norm(ev.F, u)]
        nodes = np.array([t_base] + [segs[i].t + shift + (P if i < k else 0.0)
                                     for i in order[1:]])
        if not self.m:
            nodes = np.array([t_base])
        orbit = PeriodicOrbit(
            model=self.model, params=self.param_dict(p), t0=float(t_base), x0=x0,
            state0=state0, period=float(P), events=records, trajectory=traj, monodromy=M,
            multipliers=mult, stable=bool(np.all(np.abs(mult) < 1.0 - STABILITY_MARGIN)),
            history=hist, converged=converged, autonomous=autonomous,
            trivial_multiplier=trivial, poincare_jacobian=pj,
            phase_normal=None if nv is None else np.asarray(nv, dtype=float).copy(),
            nodes=nodes, residual=float(hist[-1]),
            closure=float(np.max(np.abs(traj.x[-1] - x0))),
            options={k2: v for k2, v in self.opts.items() if k2 != "throw"},
            admissible=adm.admissible, reason=adm.reason, locked=True)
        orbit._source = (self, np.asarray(u, dtype=float).copy(), p.copy())
        return orbit

    def _assemble(self, pieces, records, salts, p, t_start, t_end):
        """One period as a :class:`Trajectory` of the model from the segments' runs (their
        model states and Jacobian block), the event records and the saltation matrices
        between them; returns it, its transfer matrices ``[Phi, S, Phi, ..., S, Phi]`` (an
        event followed by the start of sticking: ``S, I, I``) and the monodromy."""
        n, na = self.n, self.sys.naug
        cols = list(range(n)) + [na + i * na + c for i in range(n) for c in range(n)]
        eye = np.eye(n)
        phis = [tr.jacobian[:n, :n].copy() if tr is not None else eye for tr, *_ in pieces]
        transfer = [phis[0]]
        Pstart = [eye]
        Pm = phis[0].copy()
        r = 0
        for idx in range(1, len(pieces)):
            transfer.append(salts[r])
            Pm = salts[r] @ Pm
            r += 1
            while r < len(records) and records[r].kind == "stick":
                transfer += [eye, salts[r]]
                Pm = salts[r] @ Pm
                r += 1
            Pstart.append(Pm.copy())
            transfer.append(phis[idx])
            Pm = phis[idx] @ Pm
        return self._build_traj(pieces, cols, Pstart, p, t_start, t_end, records, transfer, Pm)

    def _build_traj(self, pieces, cols, Pstart, p, t_start, t_end, records, transfer, M):
        n = self.n
        ts, ys, states, dense, ikind = [], [], [], [], []
        deg = None
        for tr, *_ in pieces:
            if tr is not None:
                deg = np.asarray(tr.dense).shape[2]
                break
        for idx, ((tr, name, ta, za), P0) in enumerate(zip(pieces, Pstart)):
            if tr is None:
                y = np.concatenate([za[:n], P0.reshape(-1)])[None, :]
                t = np.array([float(ta)])
                d = np.zeros((0, n + n * n, deg or 1))
                ik = np.zeros(0, dtype=np.int64)
            else:
                y = np.asarray(tr.y, dtype=float)[:, cols].copy()
                t = np.asarray(tr.t, dtype=float)
                d = np.asarray(tr.dense, dtype=float)[:, cols, :].copy()
                ik = np.asarray(tr.interval_kind, dtype=np.int64)
                N = len(y)
                y[:, n:] = np.matmul(y[:, n:].reshape(N, n, n), P0).reshape(N, n * n)
                if len(d):
                    d[:, n:, :] = np.einsum("iabk,bc->iack",
                                            d[:, n:, :].reshape(len(d), n, n, -1),
                                            P0).reshape(len(d), n * n, -1)
            if idx:
                ikind.append(np.array([2 if t[0] > ts[-1][-1] else 1], dtype=np.int64))
                dense.append(np.zeros((1, n + n * n, deg or 1)))
            ts.append(t)
            ys.append(y)
            states.append(np.array([name] * len(t)))
            ikind.append(ik)
            dense.append(d)
        Y = np.concatenate(ys)
        traj = Trajectory.from_parts(
            t=np.concatenate(ts), x=Y[:, :n].copy(), state=np.concatenate(states),
            events=list(records), status=Status.SUCCESS, message=Status.SUCCESS.message,
            stats={}, model=self.model, params=self.param_dict(p),
            options={k: v for k, v in self.opts.items() if k != "throw"}, t0=float(t_start),
            t_end=float(t_end), jacobian=M, transfer_matrices=transfer,
            dense=np.concatenate(dense) if deg else None, interval_kind=np.concatenate(ikind),
            y=Y, provenance={"model": self.model.name, "model_hash": self.model.hash,
                              "pwsdyn_version": _version()})
        return traj, transfer, M

    # ---- sensitivity -------------------------------------------------------------------------
    def sensitivity(self, u, p, name, *, t0=None, x_ref=None, phase_normal=None,
                    rel_step: float = 1e-4):
        """Derivatives of a solution ``(u, p)`` along its branch in parameter ``name``.

        ``du/dp = -F_u^-1 F_p`` (the implicit function theorem), carried to the base point of
        :meth:`orbit` (forced: the state at the fixed time ``t0``; autonomous: the crossing of
        the fixed section ``(x_ref, phase_normal)``, or the middle of the segment), the period,
        the events' times and states (exact, from the same chain rule as ``F_u``), and the
        Floquet multipliers: ``d mu_i = (V^-1 dM V)_ii`` (first-order perturbation of a simple
        eigenvalue of the monodromy ``M = V diag(mu) V^-1``), with ``dM`` the fourth-order
        central difference of the monodromy of the orbits at ``p +- h``, ``p +- 2h`` (solved by
        Newton from the tangent predictor), ``h = rel_step * max(1, |p|)``: error ``O(h^4)``
        plus the integration error over ``h``, about ``1e-8`` with the default tolerances.
        """
        if name not in self.parameters:
            raise ArgumentError(f"`name` must be a parameter of the problem "
                                f"{list(self.parameters)}, got {name!r}")
        p = self._p(p)
        j = self.parameters.index(name)
        ev = self.evaluate(u, p)
        N, n = self.size, self.n
        up = np.linalg.solve(ev.F_u, -ev.F_p[:, j])
        dw = np.zeros(N + self.q)
        dw[:N] = up
        dw[N + j] = 1.0
        k, s_off, shift = self._base(ev, t0, x_ref, phase_normal)
        sg = ev.segs[k]
        opts = self._seg_opts(p)
        yb, Phib, _ = self._flow(k, sg.t, sg.z, s_off, opts)
        fb = self.sys.field(self._fidx[k], sg.t + s_off, yb, self._pv)
        D = Phib @ sg.Dz - np.outer(Phib @ sg.f_start, sg.Dt)
        if self.forced and t0 is not None:
            pass   # the base time is fixed
        elif not self.forced and x_ref is not None and phase_normal is not None and self.m:
            nv = np.asarray(phase_normal, dtype=float)
            Dsec = D + np.outer(fb, sg.Dt)
            Ds = -(nv @ Dsec[:n]) / (nv @ fb[:n])
            D = Dsec + np.outer(fb, Ds)
        elif self.m:
            # the middle of segment k: s = T_k / 2
            Ds = 0.5 * (sg.Dte - sg.Dt)
            D = D + np.outer(fb, sg.Dt + Ds)
        dx0 = (D @ dw)[:n]
        if self.forced:
            dP = float(self._period_grad(p)[j])
        else:
            dP = float(ev.Dperiod @ dw)
        times, before, after = [], [], []
        for i in self._order(k) if self.m else []:
            s = ev.segs[i]
            b = self.bounds[i]
            times.append(float(s.Dte @ dw))
            before.append((s.Dy @ dw)[:n])
            after.append((s.DX @ dw)[:n])
            for _ in b.events[1:]:
                times.append(float(s.Dtau @ dw))
                before.append((s.DX @ dw)[:n])
                after.append((s.DX @ dw)[:n])
        # d mu: first-order perturbation of the eigenvalues of the monodromy matrix M(u, p)
        # (Wilkinson: d lambda_i = (V^-1 dM V)_ii for a simple eigenvalue, V its right
        # eigenvectors), dM the central difference of M along the branch tangent; an
        # autonomous orbit's nontrivial multipliers are the eigenvalues of M other than 1
        h = rel_step * max(1.0, abs(p[j]))
        mu0 = np.atleast_1d(self.multipliers(ev))
        e = np.zeros(self.q)
        e[j] = h

        def M_at(s):
            # the orbit at p + s h: Newton from the tangent predictor (off the branch, M has
            # large higher derivatives: an open cycle's trivial multiplier drifts from 1)
            ut = u + s * h * up
            res = self.solve(ut, p + s * e, tol=1e-13, max_iter=8)
            if res.converged or res.history[-1] < 1e-11:
                ut = res.x
            return self.monodromy(self.evaluate(ut, p + s * e, jacobian=False))

        # fourth-order central difference (Richardson): error O(h^4) + noise / h
        dM = (8.0 * (M_at(1.0) - M_at(-1.0)) - (M_at(2.0) - M_at(-2.0))) / (12.0 * h)
        M0 = self.monodromy(ev)
        lam, Vr = np.linalg.eig(M0)
        if np.linalg.cond(Vr) < 1e8:
            dlam = np.diag(np.linalg.solve(Vr, dM @ Vr))
            dmu = np.array([dlam[int(np.argmin(np.abs(lam - m0)))] for m0 in mu0])
        else:
            # repeated eigenvalues (two zero multipliers of sticking): differences of the
            # eigenvalues themselves, matched to the nearest
            lp = np.linalg.eigvals(M0 + h * dM)
            lm = np.linalg.eigvals(M0 - h * dM)
            dmu = np.array([(_nearest(lp, m0) - _nearest(lm, m0)) / (2 * h) for m0 in mu0])
        if np.all(np.isreal(mu0)) and np.all(np.abs(np.imag(dmu)) <= 1e-12 * (
                1 + np.abs(dmu))):
            dmu = np.real(dmu)
        return OrbitSensitivity(parameter=name, x0=dx0, period=dP, multipliers=dmu,
                                event_times=np.array(times), x_before=np.array(before),
                                x_after=np.array(after), u=up)


@dataclass(frozen=True)
class OrbitSensitivity:
    """Derivatives of a periodic orbit with respect to a parameter along its branch
    (:meth:`~pwsdyn.PeriodicOrbit.sensitivity`).

    Attributes
    ----------
    parameter : str
    x0 : numpy.ndarray
        ``d x0 / d p``: forced orbits at the fixed time ``t0``; autonomous orbits in the fixed
        section through ``x0`` with normal ``phase_normal``.
    period : float
        ``d period / d p`` (forced: ``periods * d forcing_period / d p``).
    multipliers : numpy.ndarray
        ``d mu / d p`` of each of ``orbit.multipliers`` (same order).
    event_times, x_before, x_after : numpy.ndarray
        Derivatives of each event's time and states (order of ``orbit.events``).
    u : numpy.ndarray
        ``d u / d p`` of the orbit problem's unknowns.
    """

    parameter: str
    x0: np.ndarray
    period: float
    multipliers: np.ndarray
    event_times: np.ndarray
    x_before: np.ndarray
    x_after: np.ndarray
    u: np.ndarray


def _is_mode(text) -> bool:
    """``text`` is a regular mode's state (not sticking, sliding or unreadable)."""
    try:
        return DiscreteState.parse(text).is_mode
    except ValueError:
        return False


def _nearest(values, target):
    values = np.atleast_1d(values)
    return values[int(np.argmin(np.abs(values - target)))]


def _version():
    from .._version import __version__

    return __version__


# ======================================================================================
# helpers
# ======================================================================================

def locked_orbit(model, x0, *, params, T, Tf, t0, mode, signature, phase, tol, max_iter,
                 options):
    """``find_periodic_orbit(..., signature=...)``: the orbit solved on a fixed signature
    (arguments validated by the caller)."""
    if isinstance(signature, str):
        try:
            signature = Signature.parse(signature)
        except ValueError as exc:
            raise ArgumentError(f"`signature`: {exc}") from None
    try:
        sig = Signature(signature)
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"`signature` must be a Signature (orbit.signature), a sequence of "
                            f"(kind, name, mode_before, mode_after) or its string: {exc}") \
            from None
    if sig:
        state = sig[0].mode_before
        if mode is not None and mode != state:
            raise ArgumentError(f"`mode` {mode!r} is not the state {state!r} of the segment "
                                f"the signature's first event ends (where the guess lies)")
    else:
        state = mode if mode is not None else model.mode_names[model.initial_mode]
    forced = Tf is not None
    periods = int(round(T / Tf)) if forced else 1
    kw = {}
    if not forced:
        ctx = _context(model, params, options.get("sliding", "convex"))
        st = ctx.state(state)
        f0 = ctx.field(t0, x0, st, options.get("sliding_gain", 0.0))
        normal = f0 if phase is None else np.asarray(phase, dtype=float)
        if not np.any(normal) or abs(normal @ f0) <= 1e-8 * np.linalg.norm(normal) * \
                np.linalg.norm(f0):
            raise OrbitError("phase", "singular phase condition: the vector field vanishes at "
                             "the guess or the phase normal is tangent to the flow there")
        kw = dict(phase_ref=x0, phase_normal=normal)
    prob = OrbitProblem(model, sig, params=params, periods=periods, t_ref=t0, state=state,
                        **kw, **options)
    try:
        if sig:
            # the simulator's own events where they follow the signature; otherwise (a guess
            # past a grazing) each segment in its discrete state
            u0 = prob.from_simulation(t0, x0, horizon=None if forced else 2.5 * T)
            if u0 is None:
                u0 = prob.follow(t0, x0, horizon=None if forced else 2.0 * T)
        else:
            u0 = prob.pack(t0, [x0], [T])
    except ArgumentError as exc:
        raise OrbitError("signature", str(exc)) from None
    res = prob.solve(u0, tol=tol, max_iter=max_iter)
    if res.converged:
        try:
            return prob.orbit(res.x, t0=t0, x_ref=None if forced else x0,
                              phase_normal=None if forced else kw["phase_normal"],
                              history=res.history)
        except SegmentFailed as exc:
            raise OrbitError("simulation", exc.message, history=res.history) from None
    last = None
    try:
        last = prob.orbit(res.x, t0=t0, x_ref=None if forced else x0,
                          phase_normal=None if forced else kw["phase_normal"],
                          history=res.history, converged=False)
    except Exception:  # the last iterate may not even integrate; report what we have
        last = None
    reason = {"nonfinite": "simulation", "evaluation": "simulation"}.get(res.reason, res.reason)
    raise OrbitError(reason, f"Newton on the locked signature {sig}: {res.message}",
                     result=last, history=res.history)


def _groups(sig) -> list:
    """Indices of the events of each boundary: an event, or an impact, transition or
    chattering sequence followed by the start of sticking at the same instant."""
    groups: list = []
    for k, e in enumerate(sig):
        if e.kind == "stick":
            if not groups or sig[groups[-1][-1]].kind not in ("impact", "chatter",
                                                                "transition"):
                raise ArgumentError(f"sticking starts after a "
                                    f"{sig[groups[-1][-1]].kind if groups else 'no'} event in "
                                    f"{sig}: not supported")
            groups[-1].append(k)
        else:
            groups.append([k])
    return groups


def _context(model, params, sliding):
    return ModelContext(model, params, sliding)


class _Fn:
    """A scalar function of ``(t, x)`` with the size of its gradient (for its zero band), and
    optionally a compiled evaluation at many points."""

    def __init__(self, fn, gscale=1.0, rows=None):
        self.fn = fn
        self.gscale = gscale
        self._rows = rows

    def __call__(self, t, x):
        return self.fn(t, x)

    def rows(self, ts, X) -> np.ndarray:
        """The function at the points ``(ts[i], X[i])``."""
        if self._rows is not None:
            return self._rows(ts, X)
        return np.array([self.fn(t, x) for t, x in zip(ts, X)])


def _h(ctx, k):
    def fn(t, x):
        return ctx.h(k, t, x)
    return _Fn(fn, rows=lambda ts, X: ctx.h_rows(k, ts, X))


def _hd(ctx, k, mode):
    nm = ctx.nm

    def fn(t, x):
        return float(ctx._eval(W_HD, k * nm + mode, t, x, 1)[0])
    return _Fn(fn)


def _hdot_rate(ctx, k, mode, t, x, f) -> float:
    """``d/dt (h_x f_mode)`` on surface ``k`` at ``(t, x)`` along the field ``f``."""
    i = k * ctx.nm + mode
    return float(ctx._eval(W_HDT, i, t, x, 1)[0] + ctx._eval(W_HDX, i, t, x, ctx.n) @ f)


def _acc(ctx, k, mode):
    def fn(t, x):
        return _hdot_rate(ctx, k, mode, t, x, ctx.mode_field(mode, t, x))
    return _Fn(fn)


def _boundary_rate(ctx, j, mode, t, x) -> float:
    """``d/dt (h_x f_mode)`` along the sliding field of switch ``j`` at ``(t, x)`` (its
    convex combination extended smoothly where the point is not in the sliding region): the
    rate at which the sliding flow crosses the sliding region's boundary ``h_x f_mode = 0``."""
    k = ctx.model.switches[j].surface
    return _hdot_rate(ctx, k, mode, t, x, _state_field(ctx, FieldKey("slide", j), t, x))


def _guard(ctx, j, t, x) -> bool:
    if ctx.model.events[j].guard is None:
        return True
    return bool(ctx._eval(W_GUARD, j, t, x, 1)[0] != 0.0)


def _state_field(ctx, fk: FieldKey, t, x):
    from ..stability._context import KernelState

    if fk.kind == "mode":
        st = KernelState(REGULAR, -1, fk.index)
    elif fk.kind == "stick":
        st = KernelState(STICK, fk.index, fk.mode)
    else:
        st = KernelState(SLIDE, fk.index, int(ctx.stab[fk.index]["above"]))
    return ctx.field(t, x, st)


def _sample_times(tr) -> np.ndarray:
    """Nodes of a run and ``_SAMPLES - 1`` points inside each step."""
    t = np.asarray(tr.t, dtype=float)
    if len(t) < 2:
        return t
    th = np.arange(_SAMPLES) / _SAMPLES
    inner = (t[:-1, None] + np.diff(t)[:, None] * th[None, :]).reshape(-1)
    return np.unique(np.append(inner, t[-1]))


def _interior_minimum(val, ts, g):
    """``(t, value)`` of the smallest local minimum of the samples ``g`` at ``ts`` strictly
    inside the range (not at its ends), refined by minimizing ``val`` between the
    neighbouring samples; ``None`` when the samples have no interior local minimum."""
    cands = [i for i in range(1, len(g) - 1) if g[i] <= g[i - 1] and g[i] <= g[i + 1]]
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
    t0, t1, t2 = (float(v) for v in t3)
    g0, g1, g2 = (float(v) for v in g3)
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


def _worst(fn, tr, ts, vals, sign, n, limit=None):
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
    cands = [k] + [i for i in range(1, len(g) - 1) if g[i] <= g[i - 1] and g[i] <= g[i + 1]]
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
