"""The maps whose manifolds are grown: a piecewise-smooth map model iterated ``k`` times, or the
stroboscopic Poincaré map of a forced flow, each with its piece sequence (the signature that
tells on which side of a border a point lies) and its Jacobian.

Both are evaluated point by point through the compiled layers: a map model's generated
``step`` function (:func:`pwsdyn.model.maps.compile_map`) and, for a flow, one run of the
kernel over the forcing period from :meth:`pwsdyn.integrate.compiled.ModelContext.run` with
:class:`~pwsdyn.integrate.compiled.AtTime` (no :class:`~pwsdyn.Trajectory` is built).
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from .._codes import EVENT_LOG_KINDS
from ..integrate.compiled import AtTime, ModelContext
from ..integrate.options import integrator_options
from ..model.maps import compile_map


class MapSection:
    """``x -> F^k(x)`` of a map model at one parameter vector.

    ``evaluate(x, jacobian=False)`` returns ``(y, signature, J)``: the image, the tuple of the
    pieces applied (one index per iteration; ``None`` when no piece applies or the image is not
    finite) and the Jacobian (the ordered product of the pieces' Jacobians) or ``None``.
    """

    is_map = True

    def __init__(self, model, params, k: int = 1):
        self.model = model
        self.n = model.n_states
        p = model.parameter_vector(params)
        self.p = np.ascontiguousarray(p if p.size else np.zeros(1), dtype=float)
        self.params = dict(zip(model.parameters, (float(v) for v in p)))
        self.step = compile_map(model).step
        self.k = int(k)
        self.evaluations = 0
        self._out = np.empty(self.n)
        self._jac = np.empty(self.n * self.n)

    def iterate(self, m: int) -> "MapSection":
        """The same map iterated ``m`` times more (``F^(k m)``)."""
        return MapSection(self.model, self.params, self.k * m)

    def evaluate(self, x, jacobian: bool = False):
        n = self.n
        y = np.array(x, dtype=float)
        J = np.eye(n) if jacobian else None
        sig = []
        for _ in range(self.k):
            piece = self.step(y, self.p, self._out, self._jac, 1 if jacobian else 0)
            self.evaluations += 1
            if piece < 0 or not np.all(np.isfinite(self._out)):
                return y, None, J
            if jacobian:
                J = self._jac.reshape(n, n) @ J
            y = self._out.copy()
            sig.append(int(piece))
        return y, tuple(sig), J

    def piece_names(self, sig) -> tuple:
        names = self.model.mode_names
        return tuple(names[i] for i in sig)


class StroboscopicSection:
    """The stroboscopic Poincaré map ``x(t0) -> x(t0 + k T)`` of a forced flow (``T`` the
    orbit's period) at one parameter vector; its signature is the sequence of (event kind,
    event or switch index) of the run, so a point whose orbit starts or stops hitting a
    surface (grazing) has another signature than its neighbour."""

    is_map = False

    def __init__(self, model, params, t0: float, period: float, k: int = 1, options=None):
        self.model = model
        self.ctx = ModelContext(model, params)
        self.params = self.ctx.params
        self.n = model.n_states
        self.t0 = float(t0)
        self.period = float(period)
        self.k = int(k)
        self.options = dict(options or {})
        self.opts = integrator_options(self.options, "manifold()")
        self.evaluations = 0
        # the impact constraints sigma h >= 0 (sigma = -direction): the section's state space
        # is the admissible side; beyond it the map is not defined (a branch ends there)
        self._constraints = [(self.ctx.surface_of("impact", ev.name), -float(ev.direction))
                             for ev in model.events if ev.kind == "impact"]

    def admissible(self, x) -> bool:
        band = 1e3 * max(self.opts["rtol"], self.opts["atol"]) * (1.0 + float(
            np.max(np.abs(x))))
        return all(sigma * self.ctx.h(k, self.t0, x) >= -band
                   for k, sigma in self._constraints)

    def iterate(self, m: int) -> "StroboscopicSection":
        return StroboscopicSection(self.model, self.params, self.t0, self.period,
                                   self.k * m, self.options)

    def evaluate(self, x, jacobian: bool = False):
        t_end = self.t0 + self.k * self.period
        if self._constraints and not self.admissible(x):
            return np.asarray(x, dtype=float), None, None
        res = self.ctx.run(np.asarray(x, dtype=float), t0=self.t0, opts=self.opts,
                           stop=AtTime(t_end), variational=jacobian)
        self.evaluations += 1
        if res.failed or not np.all(np.isfinite(res.x)):
            return np.asarray(x, dtype=float), None, None
        sig = tuple(zip(res.event_kind.tolist(), res.event_ref.tolist()))
        J = np.array(res.jacobian, dtype=float) if jacobian else None
        return np.array(res.x, dtype=float), sig, J

    def piece_names(self, sig) -> tuple:
        return tuple(f"{EVENT_LOG_KINDS[kind]}:{ref}" for kind, ref in sig)


def check_section(section, is_map: bool) -> None:
    """Only the stroboscopic section of a forced flow is built so far; a map has none."""
    if is_map:
        if section not in (None, "map"):
            raise ArgumentError(f"manifold(): a map model takes no `section` (got {section!r})")
        return
    if section not in (None, "stroboscopic"):
        raise ArgumentError("manifold(): only section='stroboscopic' (the forcing period's "
                            f"Poincaré map) is available for a flow, got {section!r}")
