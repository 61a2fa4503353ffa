"""Why a run ended at an intersection of switching surfaces: the words of its message.

A run ends with ``SURFACE_INTERSECTION`` where a sliding motion reaches a further switching
surface and can neither cross it, nor leave the surfaces it slides on, nor slide on the
intersection by the multilinear rule (the kernel's module docstring), and where a contact
would stick (on an impact surface) while a switching surface is slid on, a pair of
constraints no discrete state of the kernel holds. :func:`intersection_detail`
names the surface reached and the cause, from the compiled test the kernel applied
(:func:`pwsdyn.integrate._kernel.intersection_cause`), at the run's end state.
"""

from __future__ import annotations

import numpy as np

from ..model.codegen import W_H, W_HX
from ._codes import (IX_ATTRACTING, IX_NO_CORNER, IX_NO_WEIGHTS, IX_NOT_ATTRACTING, IX_TOO_MANY,
                     MULTI_MAX, SLIDE, SLIDE_MULTI, STICK)
from ._load import kernel


def _distance(cm, pv, k, t, x, n) -> float:
    """``|h| / |h_x|`` of surface ``k`` at ``(t, x)``: how far the state lies from it."""
    out = np.zeros(max(n * n, n, 2))
    cm.evaluate(W_H, int(k), t, x, pv, out)
    h = abs(out[0])
    cm.evaluate(W_HX, int(k), t, x, pv, out)
    g = float(np.sqrt(out[:n] @ out[:n]))
    return h / g if g > 0.0 else h


def intersection_detail(res, model) -> str:
    """The surface reached, the intersection and why the motion cannot go on there, for the
    message of the run ``res`` (a :class:`~pwsdyn.integrate.compiled.RunResult` that ended
    with ``SURFACE_INTERSECTION``) of ``model``."""
    raw = res._raw
    kind, idx, mode = (int(v) for v in raw.state)
    cm, pv, etab, stab = res._run[:4]
    n = model.n_states
    t = float(raw.t)
    x = np.ascontiguousarray(raw.y[:n], dtype=float)
    names = [s.name for s in model.surfaces]
    if kind == STICK:
        # sticking on a contact reached a switching surface where sliding would start
        near = [(_distance(cm, pv, s.surface, t, x, n), s.surface) for s in model.switches
                if mode in (s.above, s.below)]
        ev = model.events[idx]
        reached = f"switching surface {names[min(near)[1]]!r}" if near else "a switching surface"
        return (f"Sticking on the contact of impact event {ev.name!r} (surface "
                f"{names[ev.surface]!r}), it reached {reached}, where it would slide: a "
                f"contact that sticks and a switching surface slid on at once have no "
                f"discrete state in the integrator.")
    if kind not in (SLIDE, SLIDE_MULTI):
        return ""
    out = np.full(3 + MULTI_MAX + 2, -1.0)
    cause = int(kernel().intersection_cause(cm.evaluate, pv, kind, idx, mode, len(model.modes),
                                            t, x, stab, out))
    impacts = [(_distance(cm, pv, e.surface, t, x, n), j) for j, e in enumerate(model.events)
               if e.kind == "impact"]
    if impacts and (cause < 0 or min(impacts)[0] < _distance(cm, pv, int(out[0]), t, x, n)):
        # sliding reached an impact surface where the impact leaves the state in contact
        ev = model.events[min(impacts)[1]]
        return (f"Sliding, it reached the surface {names[ev.surface]!r} of impact event "
                f"{ev.name!r}, where the impact would leave the state in contact (sticking, "
                f"or a complete chattering sequence): a contact that sticks and a switching "
                f"surface slid on at once have no discrete state in the integrator.")
    if kind == SLIDE:
        mask = 1 << model.switches[idx].surface
    else:
        mask = idx
    if cause < 0:
        return ("No switching surface bounding the sliding motion lies at the end state: the "
                "surface it reached could not be named.")
    k2 = int(out[0])
    mask |= 1 << k2
    inter = "&".join(names[k] for k in range(len(names)) if mask >> k & 1)
    text = f"It reached surface {names[k2]!r}, on the intersection {inter}"
    if cause == IX_NOT_ATTRACTING:
        k = int(out[2])
        surf = [names[kk] for kk in range(len(names)) if mask >> kk & 1]
        lams = out[3:3 + k]
        weights = ", ".join(f"lambda[{s}] = {v:.6g}" for s, v in zip(surf, lams))
        out_of = ", ".join(s for s, v in zip(surf, lams) if not 0.0 <= v <= 1.0)
        return (f"{text}, where the weights of the multilinear rule are {weights}: the "
                f"weight of {out_of} lies outside [0, 1] (the intersection is not attracting: "
                "the fields of its corners do not all press the state into it).")
    if cause == IX_NO_WEIGHTS:
        return (f"{text}, where the multilinear rule has no weights: Newton's method finds no "
                "root of its tangency conditions from any of its starts (the rule has no "
                "solution there).")
    if cause == IX_TOO_MANY:
        return (f"{text}: {bin(mask).count('1')} surfaces, more than the {MULTI_MAX} the "
                "multilinear rule is applied to.")
    if cause == IX_NO_CORNER:
        ks, mm = int(out[3]), int(out[4])
        where = (f": no switch on surface {names[ks]!r} joins mode "
                 f"{model.modes[mm].name!r} to another" if ks >= 0 and mm >= 0 else "")
        return (f"{text}, which lacks a corner mode{where} (the multilinear rule needs the "
                f"fields of all {2 ** bin(mask).count('1')} corners).")
    if cause == IX_ATTRACTING:
        return (f"{text}; at the end state the intersection attracts the motion (the run ended "
                "within the location error of the crossing, where it did not).")
    return text + "."
