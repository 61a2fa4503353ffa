"""A compiled model with parameter values: the one context of the analyses (Python side).

:class:`ModelContext` holds a compiled model (a flow or a map) with one parameter vector. For
a flow it evaluates what the projections of thesis eq. 2.25 and 2.36 and the shooting
Jacobians need: the vector field of a discrete state (the kernel's own
:func:`~pwsdyn.integrate._kernel.state_field`, so sticking and sliding fields are the ones
integrated), surfaces ``h`` with ``h_x``, ``h_t``, resets ``g`` with ``g_x``, ``g_t``. It
also maps the discrete states of a trajectory
(:class:`~pwsdyn.integrate.trajectory.DiscreteState`: ``"flight"``, ``"stick:impact"``,
``"slide:slip"``) to the kernel's codes (:class:`KernelState`).

The global analyses (:mod:`pwsdyn.explore`) build one context per model and process with
:meth:`ModelContext.get`, from a model or from the spec a worker receives.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Mapping

import numpy as np
import sympy as sp

from .. import _validate as V
from ..errors import ArgumentError
from ..integrate._load import kernel
from ..integrate._start import REGULAR, SLIDE, STICK
from ..integrate.simulate import kernel_tables
from ..integrate.trajectory import DiscreteState
from ..model import compile_model, load_model
from ..model.codegen import W_F, W_G, W_GT, W_GX, W_H, W_HT, W_HX
from ..model.spec import as_model


@dataclass(frozen=True)
class KernelState:
    """A discrete state as the kernel codes it: ``kind`` 0 regular mode, 1 sticking on impact
    event ``index``, 2 sliding on switch ``index``; ``mode`` the mode index (for sticking the
    mode whose field is constrained). :meth:`ModelContext.state` and
    :meth:`ModelContext.state_name` translate to and from :class:`DiscreteState`."""

    kind: int
    index: int
    mode: int


#: The contexts of this process by model hash (:meth:`ModelContext.get`); worker threads
#: share them, so each model is built once per process.
_CONTEXTS: dict = {}
_CONTEXTS_LOCK = threading.RLock()


class ModelContext:
    """A compiled model with parameter values: point evaluations for the analyses.

    Parameters
    ----------
    model : Model, MapModel, str, path or dict
        Anything :func:`pwsdyn.load_model` accepts.
    params : dict, optional
        Parameter values by name (defaults of the model otherwise).
    sliding : str
        The sliding method of Filippov switches (the ``sliding`` option of
        :func:`pwsdyn.simulate`).
    kind : {'flow', 'map', None}
        The kind of model required (None: either).

    Attributes
    ----------
    model : Model or MapModel
    is_map : bool
    cm : CompiledModel or CompiledMap
    p : numpy.ndarray
        The parameter vector; ``params`` the same by name.
    """

    def __init__(self, model, params: Mapping[str, float] | None = None,
                 sliding: str = "convex", *, kind: str | None = "flow"):
        self.model = as_model(model, kind=kind)
        self.is_map = bool(getattr(self.model, "is_map", False))
        self.p = self.model.parameter_vector(params)
        self.params = dict(zip(self.model.parameters, (float(v) for v in self.p)))
        self.n = self.model.n_states
        if self.is_map:
            from ..model.maps import compile_map

            self.cm = compile_map(self.model)
            return
        self.cm = compile_model(self.model)
        self._pv = np.ascontiguousarray(self.p if self.p.size else np.zeros(1), dtype=float)
        self.etab, self.eact, self.stab = kernel_tables(self.cm, sliding)
        self.nm = len(self.model.modes)

    @classmethod
    def get(cls, payload_or_model) -> "ModelContext":
        """The context of a model in this process, built once: from a model (anything
        :func:`pwsdyn.load_model` accepts) or from the payload a worker receives (``spec``,
        ``origin`` and ``hash`` of the model: a worker never receives compiled functions).
        A flow or a map, with the model's default parameters."""
        with _CONTEXTS_LOCK:
            if isinstance(payload_or_model, dict):
                key = payload_or_model["hash"]
                if key not in _CONTEXTS:
                    from ..model.spec import model_from_dict

                    model = model_from_dict(dict(payload_or_model["spec"]),
                                            origin=payload_or_model["origin"])
                    if model.hash != key:
                        raise RuntimeError(f"model {model.name!r} rebuilt on a worker has hash "
                                           f"{model.hash}, expected {key} (different pwsdyn "
                                           "versions on the client and the workers?)")
                    _CONTEXTS[key] = cls(model, kind=None)
                return _CONTEXTS[key]
            model = load_model(payload_or_model)
            if model.hash not in _CONTEXTS:
                _CONTEXTS[model.hash] = cls(model, kind=None)
            return _CONTEXTS[model.hash]

    # ---- identity -----------------------------------------------------------------------
    @property
    def forcing_period(self) -> float | None:
        """The forcing period at the context's parameters (:meth:`Model.forcing_period_at
        <pwsdyn.model.Model.forcing_period_at>`)."""
        return self.model.forcing_period_at(self.p)

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

    def h_rows(self, k: int, ts, X) -> np.ndarray:
        """Surface ``k`` at the points ``(ts[i], X[i])``, in one compiled loop."""
        from ..model._rows import first_of_rows

        ts = np.ascontiguousarray(ts, dtype=float)
        X = np.ascontiguousarray(X, dtype=float)
        out = np.empty(ts.shape[0])
        buf = np.zeros(max(self.n * self.n, self.n, 2))
        first_of_rows(self.cm.evaluate, W_H, int(k), ts, X, self._pv, buf, out)
        return out

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

    def field(self, t: float, x, state: KernelState, sliding_gain: float = 0.0) -> np.ndarray:
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
            return int(self.stab[self.switch_index(name)]["surface"])
        return int(self.etab[self.event_index(name)]["surface"])

    def state(self, name, mode_hint: str | int | None = None) -> KernelState:
        """The kernel code of a discrete state (a :class:`DiscreteState` or its text, as in
        ``Trajectory.state``).

        ``mode_hint`` is the regular mode a sticking state constrains (the ``mode_before`` of
        the ``stick`` event that started it); by default the first mode of the impact event.
        """
        st = DiscreteState.parse(name)
        if st.kind == "mode":
            return KernelState(REGULAR, -1, self.model.mode_index(st.name))
        if st.kind == "stick":
            j = self.event_index(st.name)
            if mode_hint is None:
                mode = self.model.events[j].modes[0]
            elif isinstance(mode_hint, str):
                mode = self.model.mode_index(mode_hint)
            else:
                mode = int(mode_hint)
            return KernelState(STICK, j, mode)
        s = self.switch_index(st.name)
        # the kernel keeps the `above` mode while sliding (only the switch index matters
        # for the sliding field)
        return KernelState(SLIDE, s, int(self.stab[s]["above"]))

    def state_name(self, st: KernelState) -> DiscreteState:
        if st.kind == REGULAR:
            return DiscreteState("mode", self.model.modes[st.mode].name)
        if st.kind == STICK:
            return DiscreteState("stick", self.model.events[st.index].name)
        return DiscreteState("slide", self.model.switches[st.index].name)


def check_state_name(model, mode, name: str = "mode") -> None:
    """``mode`` names a discrete state of the (symbolic) flow ``model``: None, a
    :class:`KernelState`, a mode name, ``stick:<event>`` or ``slide:<switch>`` (a
    :class:`DiscreteState` or its text). Checked before anything is compiled;
    :func:`initial_state` then makes the kernel's code."""
    if mode is None or isinstance(mode, KernelState):
        return
    must = (f"None or a discrete state of model {model.name!r}: a mode "
            f"{list(model.mode_names)}, 'stick:<event>' with an event "
            f"{[e.name for e in model.events]} or 'slide:<switch>' with a switch "
            f"{[s.name for s in model.switches]}")
    try:
        st = DiscreteState.parse(mode)
    except ValueError:
        raise V.fail(name, must, mode) from None
    if st.kind == "mode" and st.name in model.mode_names:
        return
    if st.kind == "stick" and st.name in [e.name for e in model.events]:
        return
    if st.kind == "slide" and st.name in [s.name for s in model.switches]:
        return
    raise V.fail(name, must, mode)


def initial_state(ctx, mode, name: str = "mode") -> KernelState:
    """The kernel code of the discrete state named by ``mode`` (None: the model's initial
    mode; a :class:`KernelState`; a mode name, ``stick:<event>`` or ``slide:<switch>``), with
    an :class:`ArgumentError` naming ``name`` otherwise."""
    if mode is None:
        return KernelState(REGULAR, -1, ctx.model.initial_mode)
    if isinstance(mode, KernelState):
        return mode
    if not isinstance(mode, str):
        raise V.fail(name, "None, a mode name, 'stick:<event>' or 'slide:<switch>'", mode)
    try:
        return ctx.state(mode)
    except (ValueError, IndexError, KeyError) as exc:
        raise ArgumentError(f"`{name}` must name a discrete state of model "
                            f"{ctx.model.name!r} (a mode {list(ctx.model.mode_names)}, "
                            f"'stick:<impact event>' or 'slide:<switch>'): {exc}") from None


def event_states(ctx: ModelContext, events, start: KernelState):
    """The kernel codes of the discrete states before and after each event of a log,
    starting in ``start``.

    Sticking states take their constrained mode from the regular mode before them.
    """
    out = []
    cur = start
    last_mode = ctx.model.modes[start.mode].name
    for e in events:
        before = cur
        if DiscreteState.parse(e.mode_after).is_mode:
            last_mode = e.mode_after
        after = ctx.state(e.mode_after, mode_hint=last_mode)
        out.append((before, after))
        cur = after
    return out


def trajectory_start_state(ctx: ModelContext, traj) -> KernelState:
    """Kernel code of the discrete state of a trajectory at its start (its first node)."""
    name = DiscreteState.parse(str(traj.state[0]))
    hint = None
    if name.kind == "stick" and traj.events:
        # a run that starts sticking releases (or leaves) into the constrained mode
        e = traj.events[0]
        hint = next((m for m in (e.mode_before, e.mode_after)
                     if DiscreteState.parse(m).is_mode), None)
    return ctx.state(name, mode_hint=hint)
