"""Point evaluations on a model at parameter values, for the checks and monitors of an orbit.

The functions an admissibility check, a monitor of a discontinuity-induced bifurcation or a
discontinuity map evaluates at a point ``(t, x)`` of an orbit: a surface ``h``, the normal
velocity ``h_t + h_x f`` of a mode's field on it, its normal acceleration
``d/dt (h_t + h_x f)`` (thesis conditions 2.30-2.31 at a graze), the rate at which a sliding
flow crosses the sliding region's boundary, an event's guard and the field of a discrete
state. Each takes the model's compiled evaluation at the parameter values
(:func:`model_context`) and the model's own surface, mode, event or switch indices.

The analyses above the orbits (continuation past a bifurcation, the discontinuity map of a
grazing orbit) use these and no private name of :mod:`pwsdyn.orbits`.
"""

from __future__ import annotations

import numpy as np

from .._codes import REGULAR, SLIDE_MULTI, STICK
from ..integrate.compiled import KernelState, ModelContext
from ._segments import FieldKey as FieldKey


def model_context(model, params: dict, sliding: str = "convex") -> ModelContext:
    """The model's compiled point evaluations at the parameter values ``params`` (a dict of
    all of them), with the sliding method of its Filippov switches."""
    return ModelContext(model, params, sliding)


class ScalarFunction:
    """A scalar function of ``(t, x)`` with the size of its gradient (for its zero band), and
    optionally a compiled evaluation at many points (:meth:`rows`). ``surface``: the model's
    surface index where the function is that surface's ``h`` (None otherwise), so that its
    values on an orbit's samples can be shared by the checks and monitors that read them."""

    def __init__(self, fn, gscale=1.0, rows=None, surface=None):
        self.fn = fn
        self.gscale = gscale
        self._rows = rows
        self.surface = surface

    def __call__(self, t, x):
        return self.fn(t, x)

    def rows(self, ts, X) -> np.ndarray:
        """The function at the points ``(ts[i], X[i])``."""
        if self._rows is not None:
            return self._rows(ts, X)
        return np.array([self.fn(t, x) for t, x in zip(ts, X)])


def surface(ctx, k: int) -> ScalarFunction:
    """Surface ``k``: ``h_k(t, x)``."""
    def fn(t, x):
        return ctx.h(k, t, x)
    return ScalarFunction(fn, rows=lambda ts, X: ctx.h_rows(k, ts, X), surface=k)


def normal_velocity(ctx, k: int, mode: int) -> ScalarFunction:
    """The normal velocity of mode ``mode``'s field on surface ``k``: ``h_t + h_x f_mode``."""
    def fn(t, x):
        return ctx.hdot(k, mode, t, x)
    return ScalarFunction(fn)


def normal_velocity_rate(ctx, k: int, mode: int, t, x, f) -> float:
    """``d/dt (h_t + h_x f_mode)`` on surface ``k`` at ``(t, x)`` along the field ``f``."""
    return ctx.hdot_rate(k, mode, t, x, f)


def normal_acceleration(ctx, k: int, mode: int) -> ScalarFunction:
    """The normal acceleration of mode ``mode`` on surface ``k``: the rate of its normal
    velocity along its own field (zero with the velocity at a graze, thesis 2.30-2.31; the
    free normal acceleration of sticking)."""
    def fn(t, x):
        return normal_velocity_rate(ctx, k, mode, t, x, ctx.mode_field(mode, t, x))
    return ScalarFunction(fn)


def sliding_boundary_rate(ctx, j: int, mode: int, t, x) -> float:
    """``d/dt (h_x f_mode)`` along the sliding field of switch ``j`` at ``(t, x)`` (its
    convex combination extended smoothly where the point is not in the sliding region): the
    rate at which the sliding flow crosses the sliding region's boundary ``h_x f_mode = 0``."""
    return ctx.boundary_rate(j, mode, t, x)


def guard_holds(ctx, j: int, t, x) -> bool:
    """Whether the guard of event ``j`` holds at ``(t, x)`` (an event without one: always)."""
    return ctx.guard(j, t, x)


def state_field(ctx, fk: FieldKey, t, x):
    """The field of the discrete state ``fk`` (a mode, sticking, sliding on a surface or an
    intersection) at ``(t, x)``."""
    if fk.kind == "mode":
        st = KernelState(REGULAR, -1, fk.index)
    elif fk.kind == "stick":
        st = KernelState(STICK, fk.index, fk.mode)
    elif fk.kind == "slide_multi":
        st = KernelState(SLIDE_MULTI, fk.index, fk.mode)
    else:
        st = ctx.sliding_state(fk.index)
    return ctx.field(t, x, st)
