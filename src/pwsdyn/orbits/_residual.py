"""The orbit problem ``F(u, p) = 0`` of a hybrid periodic orbit on a fixed signature: its
segments and boundaries, the layout of the unknowns ``u``, the evaluation of ``F`` with the
exact Jacobians ``F_u``, ``F_p`` (forward mode through the segments' variational equations,
the boundaries' conditions and maps) and Newton's method on it. The formulation is written
out in :mod:`pwsdyn.orbits.problem`; what is computed from a solution lives in the modules
that import this one (guesses, admissibility, monitors, results).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from .. import _validate as V
from ..errors import ArgumentError
from ..integrate.compiled import run_compiled
from ..integrate.options import check_options
from ..integrate.trajectory import DiscreteState
from ..model.spec import as_model
from ..newton import TrialRejected, newton
from ._base import shooting_options
from ._sampling import sample_times
from ._segments import FieldKey, SegmentSystem
from .signature import Signature
from .surfaces import model_context

_SYSTEMS: dict = {}


class SegmentFailed(Exception):
    """A segment could not be integrated (the kernel stopped)."""

    def __init__(self, index: int, message: str):
        super().__init__(message)
        self.index = index
        self.message = message



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
    """``F``, ``F_u``, ``F_p`` of an :class:`~pwsdyn.orbits.OrbitProblem` at ``(u, p)`` and what the
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


class _OrbitProblemBase:
    """The orbit problem ``F(u, p) = 0`` on a fixed signature: the segments of the signature,
    the layout of ``u``, the evaluation of ``F`` with its Jacobians and Newton's method on it
    (see the module docstring). :class:`~pwsdyn.orbits.OrbitProblem` adds what is computed
    from a solution (guesses, admissibility, monitors, the reported orbit); its arguments are
    this class's."""

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
                t_ref=None, state=None, **options):
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
        return type(self)(self.model, sig, params=self.params if params is None else params,
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
                s = self._switch(ref, self._near_modes(regular, pos))
                fk = FieldKey("slide", s)
                mode = int(m.switches[s].above)
            elif kind == "slide_multi":
                fk = self._multi_key(st, self._near_modes(regular, pos))
                mode = fk.mode
            else:
                raise ArgumentError(f"unknown discrete state {name!r} in the signature")
            fields.append(fk)
            near = [fk.index] if fk.kind == "mode" else self._near_modes(regular, pos)
            bounds.append(self._boundary(g, fk, mode, near, pos))
            pos += len(g)
        self.fields = fields
        self.bounds = bounds
        self.state_names = names

    def _switch(self, name, near=()):
        """The switch ``name``; where several switches share the name (the variants of a mode
        split at several surfaces are joined by one switch per pair), the one between the
        modes ``near`` (the first that fits)."""
        cands = [i for i, s in enumerate(self.model.switches) if s.name == name]
        if not cands:
            raise ArgumentError(f"unknown switch {name!r} in the signature; switches are "
                                f"{[s.name for s in self.model.switches]}")
        for mode in near:
            for i in cands:
                if mode in (self.model.switches[i].above, self.model.switches[i].below):
                    return i
        return cands[0]

    def _near_modes(self, regular, pos) -> list:
        """The regular modes nearest to the boundary at signature position ``pos``: the one
        before it, then the one after it (they fix the sides of the surfaces not slid on)."""
        sig = self.signature
        out = [] if regular[pos] is None else [_mode_by_name(self.model, regular[pos])]
        for back in range(len(sig)):
            e = sig[(pos + back) % len(sig)]
            if _is_mode(e.mode_after):
                out.append(_mode_by_name(self.model, e.mode_after))
                break
        return out

    def _multi_key(self, st, near) -> FieldKey:
        """The field of sliding on the intersection ``st`` (``slide_multi:<a>&<b>...``): the
        bit mask of its surfaces and the corner mode above all of them, reached from a mode
        ``near`` across the surfaces it lies below (as the kernel codes the state)."""
        m = self.model
        idx = {s.name: k for k, s in enumerate(m.surfaces)}
        names = st.surfaces
        if len(names) < 2 or any(nm not in idx for nm in names):
            raise ArgumentError(f"{str(st)!r} in the signature must name two or more "
                                f"surfaces of model {m.name!r} {list(idx)}")
        mask = 0
        for nm in names:
            mask |= 1 << idx[nm]
        for mode in list(near) + list(range(len(m.modes))):
            ref = mode
            for k in sorted(idx[nm] for nm in names):
                up = [sw.above for sw in m.switches if sw.surface == k and sw.below == ref]
                if up:
                    ref = int(up[0])
                elif not any(sw.surface == k and sw.above == ref for sw in m.switches):
                    ref = -1
                    break
            if ref >= 0:
                return FieldKey("slide_multi", mask, ref)
        raise ArgumentError(f"no mode of model {m.name!r} lies on every side of the "
                            f"surfaces of {str(st)!r}")

    def _multi_exit(self, g, fk: FieldKey, pos: int) -> _Boundary:
        """The end of sliding on an intersection where the surface of switch event ``g[0]``
        is left: its weight ``lambda_i`` reaches 0 (the motion leaves to the side above) or
        1 (below). The side is read from the first regular mode of the signature after the
        exit (an error where the surface is met again before one)."""
        m, sig = self.model, self.signature
        e = g[0]
        s = self._switch(e.name)
        k = m.switches[s].surface
        ks = [j for j in range(len(m.surfaces)) if (fk.index >> j) & 1]
        if k not in ks:
            raise ArgumentError(f"a slide_end on {e.name!r} must end sliding on its surface, "
                                f"not on the intersection {e.mode_before!r}")
        i = ks.index(k)
        side = None
        for step in range(1, len(sig) + 1):
            x = sig[(pos + step - 1) % len(sig)]
            if step > 1 and x.kind in ("crossing", "slide_start", "slide_end") and \
                    m.switches[self._switch(x.name)].surface == k:
                break
            if _is_mode(x.mode_after):
                mode = _mode_by_name(m, x.mode_after)
                if any(sw.surface == k and sw.above == mode for sw in m.switches):
                    side = 0
                elif any(sw.surface == k and sw.below == mode for sw in m.switches):
                    side = 1
                break
        if side is None:
            raise ArgumentError(f"the signature {sig} does not tell to which side of "
                                f"{m.surfaces[k].name!r} the slide_end at position {pos} "
                                f"leaves (no regular mode follows before that surface is "
                                f"met again)")
        # lambda_i falls to 0 (leaving above) or rises to 1 (leaving below)
        return _Boundary(e.kind, tuple(g), s, k, fk.mode,
                         ("lam", fk.index, fk.mode, i, side), 1 if side else -1)

    def _boundary(self, g, fk: FieldKey, mode: int, near=(), pos: int = 0) -> _Boundary:
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
            s = self._switch(e.name, near)
            sw = m.switches[s]
            k = sw.surface
            d = 0
            if fk.kind == "mode":
                d = -1 if fk.index == sw.above else 1
            return _Boundary(e.kind, tuple(g), s, k, mode, ("h", k), d)
        if e.kind == "slide_end" and fk.kind == "slide_multi":
            return self._multi_exit(g, fk, pos)
        if e.kind == "slide_end":
            s = (fk.index if fk.kind == "slide" and m.switches[fk.index].name == e.name
                 else self._switch(e.name))
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
        for fk in self.fields:
            if fk.kind == "slide_multi":
                # the weights of sliding on an intersection, for its admissibility check
                # and monitors
                scalars += [("lam", fk.index, fk.mode, i, 0)
                            for i in range(bin(fk.index).count("1"))]
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

    def multi_weights(self, i: int, ts, X, p=None) -> np.ndarray:
        """The weights ``lambda`` (one column per surface, in increasing surface index) of
        segment ``i``, sliding on an intersection, at the times ``ts`` and model states
        ``X`` (rows): in ``[0, 1]`` while the segment is admissible, 0 where its motion
        leaves a surface to the side above, 1 below."""
        fk = self.fields[i]
        if fk.kind != "slide_multi":
            raise ArgumentError(f"segment {i} ({self.state_names[i]}) does not slide on an "
                                f"intersection")
        p = self._p(p)
        sysm = self.sys
        idx = [sysm.scalar_index(("lam", fk.index, fk.mode, j, 0))
               for j in range(bin(fk.index).count("1"))]
        X = np.atleast_2d(np.asarray(X, dtype=float))
        out = np.empty((len(X), len(idx)))
        for r, (t, x) in enumerate(zip(np.atleast_1d(ts), X)):
            z = np.concatenate([x[:self.n], p])
            for c, j in enumerate(idx):
                out[r, c] = sysm.scalar(j, float(t), z, self._pv, grad=False)
        return out

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
        if type(p) is np.ndarray and p.dtype == np.float64 and p.shape == (self.q,) and all(
                map(math.isfinite, p.tolist())):
            # already checked (a point's ~16 calls pass the problem's own array): as below
            return p
        p = np.asarray(p, dtype=float).reshape(-1)
        if p.shape != (self.q,) or not np.isfinite(p).all():
            raise ArgumentError(f"`p` must hold {self.q} finite values {list(self.parameters)}")
        return p

    def _context_at(self, p):
        """The model's point evaluations at ``p`` (:func:`~pwsdyn.orbits.surfaces.model_context`),
        kept for the last ``p``: the admissibility check and the monitors of a point ask for
        them at one ``p``."""
        p = self._p(p)
        # (keyed by p's bytes: the other parameters are the problem's own)
        key = p.tobytes()
        got = self.__dict__.get("_context_cache")
        if got is None or got[2] != self.sliding:
            got = (key, model_context(self.model, self.param_dict(p), self.sliding),
                   self.sliding)
        elif got[0] != key:
            # the compiled model and its tables as they were, other parameter values
            got = (key, got[1].with_params(self.param_dict(p)), self.sliding)
        self.__dict__["_context_cache"] = got
        return got[1]

    def param_dict(self, p=None) -> dict:
        """All parameter values of the model at the problem's ``p``."""
        out = dict(self.params)
        out.update(zip(self.parameters, (float(v) for v in self._p(p))))
        return out

    def period_value(self, p=None) -> float:
        """The period: ``periods * forcing_period`` (forced models)."""
        return self._period_at(p)[0]

    def _period_grad(self, p) -> np.ndarray:
        return self._period_at(p)[1].copy()

    def _period_at(self, p):
        """``(period, its gradient over p)`` at ``p``, kept for the last few ``p``: a
        continuation step asks for them at each Newton iterate and check at one ``p``."""
        p = self._p(p)
        key = p.tobytes()
        cache = self.__dict__.get("_period_cache")
        if cache is None:
            cache = self.__dict__["_period_cache"] = {}
        got = cache.get(key)
        if got is None:
            if len(cache) > 16:
                cache.clear()
            # the model's parameter vector: the problem's values at p (param_dict's values
            # in model order, without its dict)
            slots = self.__dict__.get("_p_slots")
            if slots is None:
                names = list(self.model.parameters)
                slots = self.__dict__["_p_slots"] = (
                    [float(self.params[k]) for k in names],
                    [names.index(k) for k in self.parameters])
            args = list(slots[0])
            for j, v in zip(slots[1], p.tolist()):
                args[j] = v
            value = self.periods * self.model.forcing_period_at(args)
            grad = (self.periods * np.array([float(g(*args)) for g in self._Tf_p])
                    if self.forced else None)
            got = cache[key] = (value, grad)
        return got

    def _shooting_opts(self, p, dense=False):
        """:meth:`_seg_opts` of the variational runs of :meth:`evaluate` (``dense``: of the
        dense runs without variational equations of the checks along a solution), kept for
        the last ``p`` (a continuation step evaluates at one ``p`` per iterate); not for
        callers that change the dict."""
        # (by the options dict's identity: set when the problem is made, never changed)
        key = p.tobytes()
        slot = "_dense_opts_cache" if dense else "_opts_cache"
        got = self.__dict__.get(slot)
        if got is None or got[0] != key or got[2] is not self.opts:
            got = self.__dict__[slot] = (key, self._seg_opts(p, dense=dense,
                                                             variational=not dense), self.opts)
        return got[1]

    def _seg_opts(self, p, dense=False, variational=True):
        o = dict(self.opts, variational=variational, dense=dense, throw=False, chatter=False,
                 exact=False, mode=None)
        if self.forced and not math.isfinite(o["max_step"]):
            o["max_step"] = self.period_value(p) / self.periods / 4.0
        return o

    # ==================================================================================
    # evaluation
    # ==================================================================================
    def segment_options(self, p, dense=False, variational=True) -> dict:
        """The integrator options of a segment's run at ``p`` (with or without dense output
        and variational equations)."""
        return self._seg_opts(p, dense=dense, variational=variational)

    def flow(self, i: int, t: float, z, T: float, opts: dict):
        """``(y, Phi, run)`` of segment ``i``'s discrete state from ``(t, z)`` (extended state
        ``z = (x, p)``) for a duration ``T``: the end state, its Jacobian (with
        ``opts['variational']``) and, with ``opts['dense']``, its Trajectory (else None).
        ``opts``: :meth:`segment_options`, possibly changed; checked here."""
        check_options(opts)
        return self._flow(i, t, z, T, opts)

    def dense_segment(self, i: int, s, p):
        """Segment ``s`` of an evaluation (its ``segs[i]``) integrated again with dense output
        and no variational equations; the last few are kept."""
        return self._dense_segment(i, s, p)

    def _dense_segment(self, i, s, p):
        """Segment ``i`` of an evaluation integrated again with dense output (no variational
        equations), for the checks along it; the last few are kept, so that the
        admissibility check and the monitors of one point integrate each segment once."""
        return self._dense_entry(i, s, p)[0]

    def _dense_entry(self, i, s, p) -> list:
        pb = np.asarray(p, dtype=float).tobytes()
        # the entry of this segment object at this p, kept on it: the checks and monitors of
        # a point ask for it ~5 times
        mine = s.__dict__.get("_dense_entry")
        if mine is not None and mine[0] == i and mine[1] == pb and mine[2] is self:
            return mine[3]
        key = (i, float(s.t), np.asarray(s.z).tobytes(), float(s.T), pb)
        cache = self.__dict__.get("_dense_cache")
        if cache is None:
            cache = self.__dict__["_dense_cache"] = {}
        if key not in cache:
            if len(cache) > 4 * max(self.m, 1):
                cache.clear()
            # the dense output stored as the run goes: every step of it is read (the
            # samples), and rebuilding it from the nodes afterwards costs more than the run
            cache[key] = [self._flow(i, s.t, s.z, s.T,
                                     self._shooting_opts(np.asarray(p, dtype=float),
                                                         dense=True),
                                     store_dense=True)[2], None, {}]
        s.__dict__["_dense_entry"] = (i, pb, self, cache[key])
        return cache[key]

    def _surface_samples(self, i, s, p, k, ctx) -> np.ndarray:
        """Surface ``k`` (``ctx.h_rows``, ``ctx`` the model's evaluations at ``p``) at the
        samples of :meth:`_dense_samples`, evaluated once for the admissibility check and the
        monitors of a point (both read it on the same samples). Read it, do not write into
        it."""
        entry = self._dense_entry(i, s, p)
        got = entry[2].get(k)
        if got is None:
            _, ts, Y = self._dense_samples(i, s, p)
            got = entry[2][k] = ctx.h_rows(k, ts, Y)
        return got

    def _dense_samples(self, i, s, p):
        """``(run, ts, Y)``: the run of :meth:`_dense_segment`, the sample times inside it
        (``sample_times(run)[1:-1]``) and the model states there, evaluated once for the
        admissibility check and the monitors of a point (``(None, None, None)`` for a
        segment of no time). Read them, do not write into them."""
        entry = self._dense_entry(i, s, p)
        tr = entry[0]
        if tr is None:
            return None, None, None
        if entry[1] is None:
            ts = sample_times(tr)[1:-1]
            Y = np.asarray(tr(ts))[:, :self.n] if len(ts) else np.zeros((0, self.n))
            entry[1] = (ts, Y)
        return (tr,) + entry[1]

    def _flow(self, i, t, z, T, opts, store_dense=False):
        """``(y, Phi, traj)`` of segment field ``i`` from ``(t, z)`` for duration ``T``; the
        :class:`~pwsdyn.Trajectory` only for a run with dense output (the samples of the
        admissibility check and the monitors), None otherwise. ``store_dense``: the run
        stores each step's dense output as it goes (the same coefficients as those rebuilt
        from its nodes on demand)."""
        fidx = self._fidx[i]
        n = self.sys.naug
        if T == 0.0 or abs(T) <= 4 * np.spacing(max(1.0, abs(t))):
            return z.copy(), np.eye(n), None
        if T > 0:
            t0, t1, mode = t, t + T, fidx
        else:
            t0, t1, mode = -t, -t - T, self.sys.field_index(self.fields[i], reverse=True)
        # opts: the problem's options (checked when it was built) with the segment's settings
        run = run_compiled(self.sys.cm, z, t0, t1, self._pv, opts, mode0=mode, admit=False,
                           checked=True, store_dense=store_dense)
        if run.status.failed or not np.isfinite(run.x).all() or (
                run.jacobian is not None and not np.isfinite(run.jacobian).all()):
            raise SegmentFailed(i, f"segment {i} ({self.state_names[i]}) could not be "
                                f"integrated over {T:.6g} from t = {t:.10g}: {run.message}")
        tr = run.trajectory(self.sys.cm.model, opts, t0, t1) if opts["dense"] else None
        return np.array(run.x, dtype=float), run.jacobian, tr

    def _map(self, b: _Boundary, te, y, sysm):
        """``(tau, X, tau_t, tau_y, X_t, X_y)`` of boundary ``b`` at the event point."""
        na = sysm.naug
        pv = self._pv
        if b.kind in ("impact", "transition"):
            g, gz, gt = sysm.vector(sysm.vector_index(("reset", b.ref)), te, y, pv)
            return te, g, 1.0, np.zeros(na), gt, gz
        if b.kind != "chatter":
            return te, y.copy(), 1.0, np.zeros(na), np.zeros(na), np.eye(na)
        j, mode = b.ref, b.mode
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

        Raises :class:`~pwsdyn.orbits.SegmentFailed` when a segment cannot be integrated.
        """
        p = self._p(p)
        t0, xs, Ts = self.unpack(u)
        n, q, sysm = self.n, self.q, self.sys
        N = self.size
        Nw = N + q
        opts = self._shooting_opts(p)
        pv = self._pv
        F = np.zeros(N)
        J = np.zeros((N, Nw))
        Dz_all = self._dz_templates()

        if not self.m:
            T = self.period_value(p) if self.forced else Ts[0]
            return self._evaluate_smooth(u, p, t0, xs[0], T, opts, Dz_all[0].copy(), jacobian)
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
                # (outer products as broadcast products, numpy.outer's own operation; the
                # problem's identity block, not a new one per segment)
                Dz = Dz_all[i].copy()
                Dte = Dt.copy()
                Dte[self._Tcol(i)] += 1.0
                Dy = Phi @ Dz + f_end[:, None] * Dte - (Phi @ f_start)[:, None] * Dt
                Dtau = tau_t * Dte + tau_y @ Dy
                DX = X_t[:, None] * Dte + X_y @ Dy
                J[r0 + n] = ct * Dte + cz @ Dy
                J[r0:r0 + n] = -DX[:n]
                c1 = self._xcol(k)
                J[r0:r0 + n, c1:c1 + n] += self._eye_n
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
            per, per_grad = self._period_at(p)
            F[-1] = period - per
            if jacobian:
                J[-1] = Dper
                J[-1, N:] -= per_grad
        return ProblemEvaluation(np.asarray(u, dtype=float).copy(), p, F,
                                 J[:, :N] if jacobian else None,
                                 J[:, N:] if jacobian else None, period, segs, Dper)

    def _dz_templates(self) -> list:
        """``Dz`` of each segment's start over ``w = (u, p)`` (the identity on its start
        state's columns of ``u`` and on the parameter columns), made once per problem; an
        evaluation copies them (its segments keep theirs)."""
        got = self.__dict__.get("_dz_cache")
        if got is None:
            n, q, na = self.n, self.q, self.sys.naug
            N = self.size
            Nw = N + q
            got = []
            for i in range(max(self.m, 1)):
                D = np.zeros((na, Nw))
                c = self._xcol(i)
                D[:n, c:c + n] = np.eye(n)
                D[n:, N:] = np.eye(q)
                got.append(D)
            self.__dict__["_dz_cache"] = got
            self.__dict__["_eye_n"] = np.eye(n)
        return got

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


def _is_mode(text) -> bool:
    """``text`` is a regular mode's state (not sticking, sliding or unreadable)."""
    try:
        return DiscreteState.parse(text).is_mode
    except ValueError:
        return False


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
