"""Model quantities at a point, for the stability and shooting code (Python side).

:class:`ModelContext` holds a compiled model with one parameter vector and evaluates what the
projections of thesis eq. 2.25 and 2.36 and the shooting Jacobians need: the vector field of a
discrete state (the kernel's own :func:`~pwsdyn.integrate._kernel.state_field`, so sticking and
sliding fields are the ones integrated), surfaces ``h`` with ``h_x``, ``h_t``, resets ``g``
with ``g_x``, ``g_t``. It also maps the discrete-state names of a trajectory (``"flight"``,
``"stick:impact"``, ``"slide:slip"``) to the kernel's codes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np
import sympy as sp

from .. import _validate as V
from ..errors import ArgumentError
from ..integrate._load import kernel
from ..integrate._start import REGULAR, SLIDE, STICK
from ..integrate.simulate import kernel_tables
from ..model import compile_model
from ..model.codegen import W_F, W_G, W_GT, W_GX, W_H, W_HT, W_HX


_FORCING_FUNCTIONS: dict = {}


@dataclass(frozen=True)
class DiscreteState:
    """A discrete state of the kernel: ``kind`` 0 regular mode, 1 sticking on impact event
    ``index``, 2 sliding on switch ``index``; ``mode`` the mode index (for sticking the mode
    whose field is constrained)."""

    kind: int
    index: int
    mode: int


class ModelContext:
    """A compiled model with parameter values: point evaluations for stability code.

    Parameters
    ----------
    model : Model, str, path or dict
        Anything :func:`pwsdyn.load_model` accepts.
    params : dict, optional
        Parameter values by name (defaults of the model otherwise).
    sliding : str
        The sliding method of Filippov switches (the ``sliding`` option of
        :func:`pwsdyn.simulate`).
    """

    def __init__(self, model, params: Mapping[str, float] | None = None,
                 sliding: str = "convex"):
        self.model = V.model(model, kind="flow")
        self.cm = compile_model(self.model)
        self.p = self.model.parameter_vector(params)
        self._pv = np.ascontiguousarray(self.p if self.p.size else np.zeros(1), dtype=float)
        self.etab, self.eact, self.stab = kernel_tables(self.cm, sliding)
        self.n = self.model.n_states
        self.nm = len(self.model.modes)
        self.params = dict(zip(self.model.parameters, (float(v) for v in self.p)))

    # ---- identity -----------------------------------------------------------------------
    @property
    def forcing_period(self) -> float | None:
        """``model.forcing_period_value(params)``, through a cached compiled expression (the
        SymPy substitution costs milliseconds per call, as much as a shooting step)."""
        fp = self.model.forcing_period
        if fp is None:
            return None
        key = (self.model.hash, str(fp))
        fn = _FORCING_FUNCTIONS.get(key)
        if fn is None:
            fn = sp.lambdify(self.model.parameter_symbols, fp, modules="math")
            _FORCING_FUNCTIONS[key] = fn
        return forcing_period(self.model, self.p, fn)

    @property
    def autonomous(self) -> bool:
        """True when no vector field, surface or reset depends explicitly on time."""
        t = self.model.t
        exprs = [e for m in self.model.modes for e in m.rhs]
        exprs += [s.expr for s in self.model.surfaces]
        exprs += [e for ev in self.model.events if ev.reset is not None for e in ev.reset]
        return not any(sp.sympify(e).has(t) for e in exprs)

    # ---- raw evaluations ----------------------------------------------------------------
    def _eval(self, which: int, idx: int, t: float, x, size: int) -> np.ndarray:
        out = np.zeros(max(size, self.n * self.n, 2))
        self.cm.evaluate(which, int(idx), float(t), np.ascontiguousarray(x, dtype=float),
                         self._pv, out)
        return out[:size].copy()

    def h(self, k: int, t: float, x) -> float:
        """Surface ``k`` at ``(t, x)``."""
        return float(self._eval(W_H, k, t, x, 1)[0])

    def h_x(self, k: int, t: float, x) -> np.ndarray:
        return self._eval(W_HX, k, t, x, self.n)

    def h_t(self, k: int, t: float, x) -> float:
        return float(self._eval(W_HT, k, t, x, 1)[0])

    def g(self, j: int, t: float, x) -> np.ndarray:
        """Reset map of event ``j``."""
        return self._eval(W_G, j, t, x, self.n)

    def g_x(self, j: int, t: float, x) -> np.ndarray:
        return self._eval(W_GX, j, t, x, self.n * self.n).reshape(self.n, self.n)

    def g_t(self, j: int, t: float, x) -> np.ndarray:
        return self._eval(W_GT, j, t, x, self.n)

    def mode_field(self, mode: int, t: float, x) -> np.ndarray:
        return self._eval(W_F, mode, t, x, self.n)

    def field(self, t: float, x, state: DiscreteState, sliding_gain: float = 0.0) -> np.ndarray:
        """The vector field the kernel integrates in discrete state ``state``."""
        out = np.zeros(self.n)
        kernel().state_field(self.cm.evaluate, self._pv, int(state.kind), int(state.index),
                             int(state.mode), self.nm, float(t),
                             np.ascontiguousarray(x, dtype=float), self.etab, self.stab,
                             float(sliding_gain), out)
        return out

    # ---- names ---------------------------------------------------------------------------
    def event_index(self, name: str) -> int:
        return self.model.event_index(name)

    def switch_index(self, name: str) -> int:
        for i, s in enumerate(self.model.switches):
            if s.name == name:
                return i
        raise ValueError(f"unknown switch {name!r}; switches are "
                         f"{[s.name for s in self.model.switches]}")

    def surface_of(self, kind: str, name: str) -> int:
        """Index of the surface of the event (impact, transition, chatter) or switch
        (crossing, slide_start) ``name``."""
        if kind in ("crossing", "slide_start", "slide_end"):
            return int(self.stab[self.switch_index(name), 0])
        return int(self.etab[self.event_index(name), 0])

    def state(self, name: str, mode_hint: str | int | None = None) -> DiscreteState:
        """The kernel code of a discrete-state name (``Trajectory.state`` entries).

        ``mode_hint`` is the regular mode a sticking state constrains (the ``mode_before`` of
        the ``stick`` event that started it); by default the first mode of the impact event.
        """
        if ":" not in name:
            return DiscreteState(REGULAR, -1, self.model.mode_index(name))
        kind, ref = name.split(":", 1)
        if kind == "stick":
            j = self.event_index(ref)
            if mode_hint is None:
                mode = self.model.events[j].modes[0]
            elif isinstance(mode_hint, str):
                mode = self.model.mode_index(mode_hint)
            else:
                mode = int(mode_hint)
            return DiscreteState(STICK, j, mode)
        if kind == "slide":
            s = self.switch_index(ref)
            # the kernel keeps the `above` mode while sliding (only the switch index matters
            # for the sliding field)
            return DiscreteState(SLIDE, s, int(self.stab[s, 1]))
        raise ValueError(f"unknown discrete state {name!r}")

    def state_name(self, st: DiscreteState) -> str:
        if st.kind == REGULAR:
            return self.model.modes[st.mode].name
        if st.kind == STICK:
            return f"stick:{self.model.events[st.index].name}"
        return f"slide:{self.model.switches[st.index].name}"


def forcing_period(model, p, fn=None) -> float | None:
    """The forcing period of ``model`` at the parameter vector ``p`` (``None`` for an
    autonomous model); an :class:`ArgumentError` naming the parameters where it is not a
    positive finite number (``2*pi/omega`` at ``omega = 0``)."""
    if model.forcing_period is None:
        return None
    fn = fn or model.forcing_period_function
    try:
        val = float(fn(*(float(q) for q in p)))
        got = repr(val)
    except (ArithmeticError, ValueError, TypeError) as exc:
        val, got = math.nan, f"undefined ({exc})"
    if not (math.isfinite(val) and val > 0):
        where = ", ".join(f"{k}={float(v):.17g}" for k, v in zip(model.parameters, p))
        raise ArgumentError(f"the forcing period {model.forcing_period} of model "
                            f"{model.name!r} must be a positive finite number, got {got} at "
                            f"the parameters ({where}): choose parameters where it is")
    return val


def check_state_name(model, mode, name: str = "mode") -> None:
    """``mode`` names a discrete state of the (symbolic) flow ``model``: None, a
    :class:`DiscreteState`, a mode name, ``stick:<event>`` or ``slide:<switch>``. Checked
    before anything is compiled; :func:`initial_state` then makes the kernel's code."""
    if mode is None or isinstance(mode, DiscreteState):
        return
    must = (f"None or a discrete state of model {model.name!r}: a mode "
            f"{list(model.mode_names)}, 'stick:<event>' with an event "
            f"{[e.name for e in model.events]} or 'slide:<switch>' with a switch "
            f"{[s.name for s in model.switches]}")
    if not isinstance(mode, str):
        raise V.fail(name, must, mode)
    kind, sep, ref = mode.partition(":")
    try:
        if not sep:
            model.mode_index(mode)
            return
    except ValueError:
        raise V.fail(name, must, mode) from None
    if kind == "stick" and ref in [e.name for e in model.events]:
        return
    if kind == "slide" and ref in [s.name for s in model.switches]:
        return
    raise V.fail(name, must, mode)


def initial_state(ctx, mode, name: str = "mode") -> DiscreteState:
    """The discrete state named by ``mode`` (None: the model's initial mode; a
    :class:`DiscreteState`; a mode name, ``stick:<event>`` or ``slide:<switch>``), with an
    :class:`ArgumentError` naming ``name`` otherwise."""
    if mode is None:
        return DiscreteState(0, -1, ctx.model.initial_mode)
    if isinstance(mode, DiscreteState):
        return mode
    if not isinstance(mode, str):
        raise V.fail(name, "None, a mode name, 'stick:<event>' or 'slide:<switch>'", mode)
    try:
        return ctx.state(mode)
    except (ValueError, IndexError, KeyError) as exc:
        raise ArgumentError(f"`{name}` must name a discrete state of model "
                            f"{ctx.model.name!r} (a mode {list(ctx.model.mode_names)}, "
                            f"'stick:<impact event>' or 'slide:<switch>'): {exc}") from None


def event_states(ctx: ModelContext, events, start: DiscreteState):
    """The discrete states before and after each event of a log, starting in ``start``.

    Sticking states take their constrained mode from the regular mode before them.
    """
    out = []
    cur = start
    last_mode = ctx.model.modes[start.mode].name
    for e in events:
        before = cur
        if ":" not in e.mode_after:
            last_mode = e.mode_after
        after = ctx.state(e.mode_after, mode_hint=last_mode)
        out.append((before, after))
        cur = after
    return out


def trajectory_start_state(ctx: ModelContext, traj) -> DiscreteState:
    """Discrete state of a trajectory at its start (from its first node)."""
    name = traj.state[0]
    hint = None
    if name.startswith("stick:") and traj.events:
        # a run that starts sticking releases (or leaves) into the constrained mode
        e = traj.events[0]
        hint = next((m for m in (e.mode_before, e.mode_after) if ":" not in m), None)
    return ctx.state(name, mode_hint=hint)
