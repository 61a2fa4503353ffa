"""The discrete state a run starts in when its initial state touches an impact constraint.

A state carried from one run to the next (``traj.x_final`` restarted, a sweep's next parameter
value, a Lyapunov segment, a shooting guess) may lie *on* a unilateral constraint
``sigma h >= 0`` of an impact event (``sigma = -direction``; ``direction = -1``, the usual
``h >= 0``), at rest on it or arriving at it, up to round-off. The kernel starts in a regular
mode unless told otherwise: a start a few ulps behind the constraint then never registers the
contact (the watch function starts on the far side and never crosses) and the motion passes
through the wall; a resting state a few ulps in front of it falls through a tiny gap every
restart. :func:`start_state` decides, before the kernel runs, what the start is:

Bands. The round-off band is the kernel's own (``_surface_offset``, the band that decides
the side of switching surfaces and Filippov sliding at a start): a value of ``h`` is zero when
``|h| <= 64 eps xmax gmax``, ``xmax = max(1, max_i |x_i|)``, ``gmax = max(1, max_i |h_x,i|)``;
the normal velocity ``hdot = h_t + h_x f`` (of the mode) by the same rule on its gradient
``hdot_x``. The kernel's sticking motion holds ``h = 0, hdot = 0`` only to the integrator's
tolerance, not to round-off (measured: ``|h|`` 2e-13, ``|hdot|`` 6e-13 after 0.05 time units
on a vibrating table at ``rtol = 1e-10``), so a restart from a sticking run's ``x_final``
needs more: with ``pos_tol = atol + rtol max_i |x_i|`` (the position tolerance that the
kernel's chattering velocity floor is built on) the bands are
``band_h = max(64 eps xmax gmax, gmax pos_tol)`` and
``band_v = max(64 eps xmax gvmax, gvmax pos_tol)`` (``gvmax = max(1, max_i |hdot_x,i|)``).

For every impact constraint active in the start mode (after taking the side of each
switching surface as the kernel does, :func:`side_mode`), with ``H = sigma h``:

* ``H > band_h``: off the constraint, nothing to do;
* ``|H| <= band_h`` (or ``H < 0`` by at most ``max(band_h, gmax behind_tol)``, with
  ``behind_tol = ADMIT_BEHIND (1 + max_i |x_i|)`` for simulate, shooting and the sweeps): the
  state
  is *on* the constraint; it is put on it (``x -= h h_x / |h_x|^2``) when behind it, and then
  by ``Hdot = sigma hdot``:

  - ``|Hdot| <= band_v``, the free normal acceleration ``sigma (hdot_t + hdot_x f)``
    negative (pointing into the constraint) and the impact law reversing ``hdot``
    (``hdot_x W < 0``, slides "Simulation: Chattering"): **sticking** on that event (the event
    on the surface whose guard holds), the state projected onto ``{h = 0, hdot = 0}`` as the
    kernel does after a chattering sequence;
  - ``Hdot < -band_v`` (moving into the constraint): left with ``H >= 0``, so the kernel
    registers the **impact at the start time** (a watch value that starts at zero and moves
    in the event direction crosses, ``_kernel.watch._crosses``);
  - otherwise (moving away, or at rest with the free motion leaving): **free motion** from
    ``H >= 0``.
* ``H`` further behind: the state is inside the wall. ``refuse=True`` (the public entry
  points) raises :class:`~pwsdyn.errors.ArgumentError` naming the event and the value;
  otherwise (internal runs, sweeps that carry a state to a new parameter value where the wall
  moved) the state is left as it is.

Filippov switching surfaces need nothing here: the kernel puts a start within the round-off
band of a surface into sliding itself when both fields point into it (``_resolve``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError
from ..model.codegen import W_F, W_GUARD, W_GX, W_H, W_HD, W_HDT, W_HDX, W_HX
from ._codes import EV_IMPACT, REGULAR, SLIDE, STICK, SW_FILIPPOV  # noqa: F401 (SLIDE: stability)

#: Ulps of the round-off band: the kernel's ``_surface_offset`` (64 eps xmax gmax).
BAND_ULPS = 64.0
#: Relative distance (of ``1 + max |x_i|``, times ``max(1, |h_x|)``) within which a state
#: *behind* a constraint is put on it rather than refused: the kernel's sticking motion is
#: not projected onto the constraint and drifts quadratically in time with a round-off
#: acceleration (about 1e-15 t^2, 2e-12 after 50 time units of a ball resting on a table),
#: so a long sticking run ends behind the wall by more than any tolerance; about sqrt(eps).
ADMIT_BEHIND = 1e-8
_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class Start:
    """The start of a run: state ``x`` (possibly moved onto a constraint) and the kernel's
    discrete state ``(kind, index, mode)``; ``action`` per impact constraint touched:
    ``(event index, 'stick' | 'impact' | 'free' | 'inside', h)``."""

    x: np.ndarray
    kind: int
    index: int
    mode: int
    actions: tuple = ()


def abs_max(v) -> float:
    """``float(np.max(np.abs(v)))`` of a non-empty 1-D float array (NaN if it holds one):
    the same number, without NumPy's reduction, which costs microseconds on a few entries."""
    a = [abs(u) for u in v.tolist()]
    m = max(a)
    return m if not math.isnan(sum(a)) else math.nan


def round_off_band(xmax: float, grad) -> float:
    """The kernel's round-off band of a function with gradient ``grad`` at a state of scale
    ``xmax`` (``max(1, max |x_i|)``): ``64 eps xmax max(1, max |grad_i|)``."""
    g = abs_max(grad) if len(grad) else 0.0
    return BAND_ULPS * _EPS * xmax * max(1.0, g)


class _Eval:
    """Point evaluations of a compiled model (``cm.evaluate``) at one parameter vector."""

    def __init__(self, cm, p):
        self.ev = cm.evaluate
        self.n = cm.model.n_states
        self.nm = len(cm.model.modes)
        self.p = np.ascontiguousarray(p if len(p) else np.zeros(1), dtype=float)
        self.buf = np.zeros(max(self.n * self.n, self.n, 2))

    def __call__(self, which, idx, t, x, size=1):
        self.ev(which, int(idx), float(t), np.ascontiguousarray(x, dtype=float), self.p,
                self.buf)
        return self.buf[:size].copy()

    def scalar(self, which, idx, t, x) -> float:
        self.ev(which, int(idx), float(t), np.ascontiguousarray(x, dtype=float), self.p,
                self.buf)
        return float(self.buf[0])


def side_mode(E: _Eval, stab, t, x, mode: int) -> tuple:
    """``(mode, switch)``: the mode the kernel's ``_resolve`` starts in from ``mode`` at
    ``(t, x)`` (the side of every switching surface; on one within round-off, the side both
    fields leave to) and the Filippov switch it starts sliding on instead (-1: none)."""
    n_sw = stab.shape[0]
    if n_sw == 0:
        return mode, -1
    xmax = max(1.0, float(np.max(np.abs(x)))) if len(x) else 1.0

    def offset(k):
        return E.scalar(W_H, k, t, x), round_off_band(xmax, E(W_HX, k, t, x, E.n))

    for _ in range(n_sw + 1):
        changed = False
        for s in range(n_sw):
            a, b = int(stab[s]["above"]), int(stab[s]["below"])
            if mode not in (a, b):
                continue
            hv, tol = offset(int(stab[s]["surface"]))
            new = a if hv > tol else b if hv < -tol else mode
            if new != mode:
                mode, changed = new, True
        if not changed:
            break
    for s in range(n_sw):
        a, b = int(stab[s]["above"]), int(stab[s]["below"])
        if mode not in (a, b):
            continue
        k = int(stab[s]["surface"])
        hv, tol = offset(k)
        if abs(hv) > tol:
            continue
        sa = E.scalar(W_HD, k * E.nm + a, t, x)
        sb = E.scalar(W_HD, k * E.nm + b, t, x)
        filippov = stab[s]["kind"] == SW_FILIPPOV
        if filippov and sa < 0.0 and sb > 0.0:
            return a, s
        if (sa >= 0.0 and sb > 0.0) or (sa > 0.0 and sb >= 0.0):
            mode = a
        elif (sa <= 0.0 and sb < 0.0) or (sa < 0.0 and sb <= 0.0):
            mode = b
    return mode, -1


def _project_stick(E: _Eval, k: int, mode: int, t, x):
    """``x`` projected onto ``{h = 0, hdot = 0}`` along ``span(h_x, hdot_x)`` (the kernel's
    ``_project_stick``: three Gauss-Newton iterations)."""
    n = E.n
    for _ in range(3):
        r1 = E.scalar(W_H, k, t, x)
        r2 = E.scalar(W_HD, k * E.nm + mode, t, x)
        a = E(W_HX, k, t, x, n)
        b = E(W_HDX, k * E.nm + mode, t, x, n)
        aa, ab, bb = a @ a, a @ b, b @ b
        det = aa * bb - ab * ab
        if det == 0.0 or not np.isfinite(det):
            break
        c0 = (-r1 * bb + r2 * ab) / det
        c1 = (-r2 * aa + r1 * ab) / det
        x = x + c0 * a + c1 * b
    return x


def _onto(E: _Eval, k: int, sigma: float, t, x, band: float):
    """``x`` moved along ``h_x`` onto the admissible side of surface ``k`` (``sigma h >= 0``):
    one Newton step onto ``h = 0``, then, if round-off leaves it behind, a nudge of a few
    ulps in front of it."""
    for it in range(4):
        h = E.scalar(W_H, k, t, x)
        if sigma * h >= 0.0:
            return x
        g = E(W_HX, k, t, x, E.n)
        nrm2 = float(g @ g)
        if nrm2 == 0.0 or not np.isfinite(nrm2):
            return x
        # first the plain Newton step (h = 0 exactly for a surface linear in x), then aim a
        # growing fraction of the round-off band in front of the surface (not of the
        # position tolerance: a start moving into a curved surface nudged that far reached
        # it ~1e-11 after t0)
        target = 0.0 if it == 0 else sigma * band * 2.0 ** (it - 3)
        x = x + (target - h) * g / nrm2
    return x


#: The impact events of an event table and activity table, by their ``id``s: ``(etab,
#: eact, rows)`` (the tables are held, so the ``id``s are not reused while the entry lives).
#: The tables are built once per model (:func:`pwsdyn.integrate.simulate.kernel_tables`);
#: reading their records cost more than the rest of a start off every constraint.
_IMPACTS: dict = {}


def _impacts(etab, eact) -> tuple:
    """``(j, surface, sigma, active)`` of each impact event ``j`` of ``etab`` with a
    direction: ``sigma = -direction``, ``active[m]`` whether it is watched in mode ``m``."""
    hit = _IMPACTS.get((id(etab), id(eact)))
    if hit is not None and hit[0] is etab and hit[1] is eact:
        return hit[2]
    rows = tuple((j, int(etab[j]["surface"]), -float(etab[j]["direction"]),
                  tuple(bool(v) for v in eact[j]))
                 for j in range(etab.shape[0])
                 if etab[j]["kind"] == EV_IMPACT and etab[j]["direction"] != 0)
    if len(_IMPACTS) >= 256:
        _IMPACTS.clear()
    _IMPACTS[(id(etab), id(eact))] = (etab, eact, rows)
    return rows


def _made(x, kind: int, index: int, mode: int, actions: tuple = ()) -> Start:
    """``Start(x, kind, index, mode, actions)`` without the frozen dataclass's ``__init__``
    (its ``object.__setattr__`` per field cost ~1.5 us, on every run of ``simulate()``)."""
    st = object.__new__(Start)
    st.__dict__.update(x=x, kind=kind, index=index, mode=mode, actions=actions)
    return st


def start_state(cm, etab, eact, stab, t, x, p, mode: int, *, pos_tol: float = 0.0,
                behind_tol: float = 0.0, refuse: bool = False, names=None) -> Start:
    """The start of a run from ``(t, x)`` in regular mode ``mode`` (see the module docstring).

    ``cm``: the compiled model; ``etab``, ``eact``, ``stab``: the kernel tables
    (:func:`pwsdyn.integrate.simulate.kernel_tables`); ``p``: parameter vector; ``pos_tol``:
    the position tolerance (state units) within which a state behind a constraint is put on
    it and within which ``h`` and ``hdot`` count as zero (measured through ``h_x`` and
    ``hdot_x``: ``max(1, max |h_x,i|) pos_tol``, never below the round-off band);
    ``behind_tol``: a wider tolerance (state units) for putting a state that lies *behind* a
    constraint onto it (the sweeps'); ``refuse``: raise :class:`ArgumentError` for a state
    behind a constraint beyond that; ``names``: what to call the state in that message
    (default ``x0``).
    """
    model = cm.model
    x = np.array(x, dtype=float)
    n = model.n_states
    impacts = _impacts(etab, eact)
    xl = x.tolist()
    if not impacts or not all(map(math.isfinite, xl)):
        return _made(x, REGULAR, -1, mode)
    E = _Eval(cm, p)
    mode_r, slide = side_mode(E, stab, t, x, int(mode))
    sliding = slide >= 0
    if sliding:
        # the kernel slides on that surface (it keeps the mode above, watching the events
        # of both modes); only keep the state on the admissible side of the constraints
        modes = {int(stab[slide]["above"]), int(stab[slide]["below"])}
    else:
        modes = {mode_r}
    # (x is finite here: abs_max's NaN check is not needed)
    xmax = max(1.0, max(map(abs, xl))) if xl else 1.0
    actions = []
    done = set()
    for j, k, sigma, active in impacts:
        if k in done or not (active[mode_r] if not sliding else
                             any(active[m] for m in modes)):
            continue
        h = E.scalar(W_H, k, t, x)
        hx = E(W_HX, k, t, x, n)
        gmax = max(1.0, abs_max(hx))
        rband = BAND_ULPS * _EPS * xmax * gmax      # round_off_band(xmax, hx)
        band = max(rband, gmax * pos_tol)
        H = sigma * h
        if H > band or not np.isfinite(H):
            continue
        admit = max(band, gmax * behind_tol)
        ev_name = model.events[j].name
        if H < -admit:
            if refuse:
                what = names or "x0"
                raise ArgumentError(
                    f"`{what}` lies inside the constraint of impact event {ev_name!r} of model "
                    f"{model.name!r}: its surface {model.surfaces[k].expr} = {h!r} at t = "
                    f"{float(t)!r} is on the inadmissible side (must be "
                    f"{'>=' if sigma > 0 else '<='} 0) by more than the band {admit:.3g} "
                    "(round-off and the position tolerance (atol + rtol |x|) |h_x|) within "
                    "which a state counts as on it; give a state on the admissible side")
            actions.append((j, "inside", h))
            continue
        done.add(k)
        if sliding:
            x = _onto(E, k, sigma, t, x, rband)
            actions.append((j, "free", h))
            continue
        nm = E.nm
        if H < 0.0:
            x = _onto(E, k, sigma, t, x, rband)
        hd = E.scalar(W_HD, k * nm + mode_r, t, x)
        hdx = E(W_HDX, k * nm + mode_r, t, x, n)
        vband = max(round_off_band(xmax, hdx),
                    max(1.0, float(np.max(np.abs(hdx)))) * pos_tol)
        Hd = sigma * hd
        if abs(Hd) <= vband:
            f = E(W_F, mode_r, t, x, n)
            acc = E.scalar(W_HDT, k * nm + mode_r, t, x) + float(hdx @ f)
            # impact direction W = (g_x - I) hdot_x / |hdot_x|^2; hdot_x W = -(1 + r)
            nrm2 = float(hdx @ hdx)
            hw = 0.0
            jj = -1
            for j2, k2, _, active2 in impacts:
                if k2 != k or not active2[mode_r]:
                    continue
                if E.scalar(W_GUARD, j2, t, x) != 0.0:
                    jj = j2
                    break
            if jj >= 0 and nrm2 > 0.0:
                gx = E(W_GX, jj, t, x, n * n).reshape(n, n)
                W = (gx @ hdx - hdx) / nrm2
                hw = float(hdx @ W)
            if sigma * acc < 0.0 and hw < 0.0 and jj >= 0:
                xs = _project_stick(E, k, mode_r, t, x)
                if np.all(np.isfinite(xs)):
                    actions.append((jj, "stick", h))
                    return Start(xs, STICK, int(jj), int(mode_r), tuple(actions))
            actions.append((j, "free", h))
        elif Hd < 0.0:
            actions.append((j, "impact", h))
        else:
            actions.append((j, "free", h))
    return _made(x, REGULAR, -1, int(mode), tuple(actions))


__all__ = ["Start", "start_state", "round_off_band", "side_mode", "BAND_ULPS", "ADMIT_BEHIND"]
