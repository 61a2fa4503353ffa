"""The compiled event-driven integrator (numba).

One function, :func:`run_kernel`, integrates a hybrid model from ``t0`` to ``t_end`` with an
embedded explicit Runge-Kutta pair and handles every discontinuity in the same compiled loop:
no Python call is made per step or per event. The model enters as one first-class function
``evaluate(which, idx, t, x, p, out)`` (see :mod:`pwsdyn.model.codegen`), so this kernel is
compiled once for all models and cached on disk.

Discrete state
--------------
``dkind`` is what governs the motion now:

* ``REGULAR``: the vector field of mode ``mode``;
* ``STICK``: sticking on the surface of impact event ``didx`` after a complete chattering
  sequence, or after an impact that leaves the normal velocity at round-off while the free
  motion presses into the surface (a plastic impact, an impact at rest): constrained motion
  ``f - lambda W`` (slides "Simulation: Chattering"), on an oblique or curved surface the
  frictionless motion along it, released where the constraint force vanishes;
* ``SLIDE``: Filippov sliding on switch ``didx`` with the convex field
  ``f12 = (1 - alpha) f_above + alpha f_below`` (thesis eq. 2.7-2.8) or Utkin's equivalent
  control ``f(t, x, u_eq)`` (slides; switch table column 4), optionally with the stabilising
  term ``-C h h_x^T`` of the slides; each accepted sliding step is projected back onto
  ``h = 0``.

Switching surfaces
------------------
At the start, and after every reset, release or change of mode by an event, the mode is made
consistent with the side of every switching surface (:func:`_resolve`); a state on a Filippov
surface starts sliding if both fields point into it. An arrival at a surface crosses or starts
sliding according to the signs of ``h_t + h_x f`` of the two modes (thesis eq. 2.6-2.8);
switches of kind ``SW_CONTINUOUS`` (kinks of ``Abs``/``Max``/``Min``) always cross. Sliding
ends (``slide_end``) where ``hdot`` of the mode above turns positive (``alpha = 0``) or that of
the mode below turns negative (``alpha = 1``), located by Newton on that ``hdot``. Reaching
another switching surface while sliding crosses it if the sliding motion continues on its far
side; if the sliding fields on both sides point into it (sliding on the intersection) the run
ends with ``ST_INTERSECTION``.

Watch functions
---------------
In each discrete state the kernel watches a small list of scalar functions of ``(t, x)`` for
zero crossings: surfaces ``h`` (events, switches), normal velocities ``hdot`` (sliding exit)
and normal accelerations ``hddot`` (release from sticking). On every accepted step each is
sampled on the dense output -- surfaces at the ends and at the interior extrema of the cubic
Hermite fit from ``h`` and ``hdot`` at the ends, the other functions at the ends and the
midpoint (the normal acceleration of a sticking motion also at the extrema of its Hermite
fit, its slopes by central differences). Where such a function has one sign at two
consecutive samples and an extremum towards zero between them (``hdot`` changes sign: near
grazing, a short release window), that extremum is searched for on the dense output -- the
exact flow on an exact step -- with a lower bound from the tangents at the bracket's ends
(:func:`_extremum_search`), so a crossing and re-crossing inside one step is found whenever
it is deeper than the dense output's error. The earliest crossing is bracketed and located
by the Illinois method on the dense output to a few ulps, then the step is re-taken exactly
to that time ("landing step") and the time is polished with Newton steps on ``h`` (or
``hdot`` for a sliding exit) so the event state comes from the integrator itself, not from
the interpolant.
A surface that depends on ``t`` explicitly (a moving constraint) must also be resolved by the
step: where the Hermite fit misses ``h`` at the step's midpoint by more than 1% the step is
retaken shorter, so a state at rest cannot step over an oscillating wall.

A function that is zero at the start of a step fires at that time if the next sample lies on
the far side of the event direction, never otherwise. On the first step after a restart (the
start of the run, every event) a surface within its round-off band (:func:`_surface_offset`)
counts as zero, and its rate within its own band (:func:`_rate_band`) as tangency: a start on
a wall moving (or curving) into it, a sliding exit or release that ends on another surface,
is an event at that time whatever the sign of the round-off; a start on a surface moving away
is none. The same band decides after an event: a round-off normal velocity is not "moving
away", and after an impact with the free normal acceleration into the surface it is contact
(``STICK``).

Watch arrays are sized from the model (one entry per event and switch, plus spares), so any
number of events and switches per mode is watched.

Output
------
``iopt[IO_SAVE]``: ``SAVE_EVENTS`` stores the nodes on both sides of every event and the end
(sweeps); ``SAVE_DENSE`` every step with its power-form dense output; ``SAVE_NODES`` every
step with its length only -- the dense output is rebuilt when it is read by taking the step
again from its start node (:func:`dense_coefficients`: the same stages from the same numbers,
so the same coefficients), which costs the run nothing (storing it doubled the cost of a
Runge-Kutta run and added the three extra stages of DOP853's interpolant to every step).

Sampling
--------
With ``FO_SAMPLE_DT > 0`` the state at ``FO_SAMPLE_T0 + k FO_SAMPLE_DT`` is recorded from each
step's dense output as the integration passes it (stroboscopic sections: no event, no landing
step); across a chattering gap it is the linear interpolation the trajectory also uses.

Exact propagation
-----------------
With ``iopt[IO_EXACT]`` the regular modes that are affine in the state with harmonic forcing
(:mod:`pwsdyn.model.affine`) are not integrated but propagated by the exact flow
``z(t + h) = exp(h M) z(t)`` of the state augmented with the forcing. Steps are limited to
``||h D^-1 M D||_inf <= 1`` (after scaling the constant and forcing columns; ``D`` balances
``M`` by powers of two, so a stiff spring's steps follow its frequency, not its stiffness:
:func:`_affine_setup`): a full step is one
product with a propagator made once per mode and run (:func:`_exact_propagator`), any other
step sums the Taylor series of the vector (:func:`_exact_step`), whose terms are the step's
dense output -- the exact flow, so the event search runs on it and the landing on an event
is its evaluation, the terms then rescaled to the shortened interval. Their error estimate
is zero; sticking, sliding, non-affine modes and the variational equations stay on the
Runge-Kutta pair.

Termination
-----------
No input makes the kernel spin. Non-finite input (``t0``, ``t_end``, ``x0``, first step,
a NaN largest step, tolerances, sampling time or period) ends the run before any work with
``ST_NONFINITE``, as does a non-finite time, state or field at the start and after every
event (a NaN reset) or a step size that turns NaN. A Runge-Kutta stage or a watch function
that turns non-finite inside a step has the step retaken shorter, down to 4 ulp of ``t``:
the run ends with ``ST_NONFINITE`` at the last finite state. Accepted steps are counted
against ``max_steps`` and events against ``max_events``; a rejection shrinks the step by at
least 10% (an accepted step grows it at most 10x) and a step below 4 ulp of ``t`` ends the
run, so rejections are bounded too; samples are bounded by ``max_steps`` (more requested
ends the run at once with ``ST_MAX_STEPS``); inner loops (event location, Newton
polishing, projections, the equivalent control) have fixed iteration caps.

Time never passes ``t_end``: the last step ends at ``t_end`` exactly, and a complete-
chattering jump is taken only where its accumulation point lies within ``t_end``; before a
later one the impacts are integrated one by one, and where they fall below the velocity
floor (unresolvable) the run ends at ``t_end`` on the chord of the chattering gap.

Variational equations
---------------------
With ``variational`` the state is augmented by the n x n matrix ``Phi`` (row-major), integrated
with ``Phi' = J Phi`` and updated at every event by the full saltation matrix (slides,
"Saltation matrices"; Adolfsson et al. 2001) with the ``h_t`` and ``g_t`` terms of
time-dependent surfaces and resets: :func:`_event_saltation` (impacts, transitions),
:func:`_switch_saltation` (Filippov crossing, sliding entry), :func:`_chatter_saltation`
(complete chattering, the slides' ``G = C + (f_out - C f_in) h_x / (h_x f_in)`` with the time
derivatives of the map); release and sliding exit leave the field continuous (``S = I``).
``J`` is symbolic in a regular mode and a central difference (step ~ eps^(1/3)) of the
sticking or sliding field. Steps are accepted only when ``Phi`` meets the tolerances too.
With ``iopt[IO_VAR] == VAR_SEGMENTS`` ``Phi`` restarts at the identity after every event and
each event record carries the segment's ``Phi`` and ``S`` (the per-segment transfer matrices;
see :mod:`pwsdyn.integrate._variational`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model.codegen import (W_AFFINE, W_F, W_FU, W_FX, W_G, W_GUARD, W_GX, W_GT, W_H, W_HD,
                             W_HDT, W_HDU, W_HDUD, W_HDX, W_HHD, W_HT, W_HX)

# The integer codes (discrete states, watch types, actions, log kinds, statuses, options) are
# defined once in ._codes, shared with the Python side; numba reads them as compile-time
# constants. Numba's on-disk cache is keyed on this file alone; the loader (._load) removes
# the cached kernel when ._codes or the model interface changes (its KERNEL_SOURCES).
from ._codes import (  # noqa: F401 (re-exported for the kernel's users)
    ACT_EVENT, ACT_EXIT_ABOVE, ACT_EXIT_BELOW, ACT_INTERSECTION, ACT_RELEASE, ACT_SWITCH,
    EV_IMPACT, EV_TRANSITION, FO_ATOL, FO_CHAT_ABS, FO_CHAT_REL, FO_H0, FO_HMAX, FO_N, FO_RTOL,
    FO_SAMPLE_DT, FO_SAMPLE_T0, FO_SLIDE_C, IO_CHATTER, IO_DIDX0, IO_DKIND0, IO_EXACT,
    IO_MAXEVENTS, IO_MAXSTEPS, IO_METHOD, IO_MODE0, IO_N, IO_NMODES, IO_ORDER, IO_SAVE,
    IO_STOP_COUNT, IO_STOP_MASK, IO_STOP_REF, IO_VAR, IV_CHATTER, IV_JUMP, IV_STEP, K_CHATTER,
    K_CROSSING, K_IMPACT, K_RELEASE, K_SLIDE_END, K_SLIDE_START, K_STICK, K_TRANSITION, REGULAR,
    SAVE_DENSE, SAVE_EVENTS, SAVE_NODES, SLIDE, SLIDE_CONVEX, SLIDE_UTKIN, STICK, ST_INTERSECTION,
    ST_MAX_EVENTS, ST_MAX_STEPS, ST_NONFINITE, ST_STEP_TOO_SMALL, ST_SUCCESS, ST_TERMINAL, ST_ZENO,
    SW_CONTINUOUS, SW_FILIPPOV, VAR_GLOBAL, VAR_NONE, VAR_SEGMENTS, WF_HDDOT, WF_HDOT, WF_SURFACE)

#: The decorator of the helpers that allocate nothing: compiled without numba's reference
#: counting (``_nrt=False``). With it every call increfs and decrefs each array argument
#: at entry and exit -- two atomic updates per array, ~20 per call of the vector field of a
#: sticking or sliding state, measured a third of the time of an event and of a landing step.
#: The arrays are the kernel's, alive for the whole run, so borrowing them is safe; a helper
#: that allocates (growing the outputs, saltation matrices) keeps ``njit(cache=True)``.
_hot = njit(cache=True, _nrt=False, forceinline=False)
#: The same, and inlined by LLVM into every caller (``forceinline``: the function's body
#: replaces the call after numba has compiled it without reference counting, so the caller
#: counts nothing either; numba's ``inline="always"`` inlines its IR instead, whose array
#: arguments the caller then counts: measured no faster). For the exact stepper and the
#: helpers of its full step: as calls they cost 5-7% of an exact run (callgrind instruction
#: counts, ``benchmarks/compare_revisions.py``), ~130 words of arguments pushed per step for
#: a few dozen multiply-adds. The Taylor sum of a shorter step (``_exact_step``) stays a call:
#: inlined as well it saved another 1.5% of an exact run but cost the Runge-Kutta runs 1.5%
#: (a longer stepping loop, more of it spilled). ``forceinline=False`` is explicit on
#: ``_hot``: numba passes an unset flag on from a caller to the functions it compiles for it,
#: so a helper first compiled for an inlined caller would be inlined too.
_hot_inline = njit(cache=True, _nrt=False, forceinline=True)

_EPS = np.finfo(np.float64).eps
#: Relative step of the central differences of the variational code (cube root of eps).
_FD_STEP = 6e-6
#: Spare entries of the watch list beyond one per event and switch (see the kernel's set-up).
_MAXW = 64
#: Terms of the Taylor-summed exponential of an exact step (||h M|| <= 1: 1/20! < 1e-18).
_EXACT_TERMS = 20
#: Events this many ulps of t apart happen at one instant: the re-trigger guards of all of
#: them hold at the restart (a function that fired is not fired again by the start-on-surface
#: rule after another event at the same instant moved t by round-off).
_COINCIDENT_ULPS = 64.0


# --------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------

@njit(cache=True)
def _grow2(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty((max(need, 2 * a.shape[0]),) + a.shape[1:], dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow3(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty((max(need, 2 * a.shape[0]), a.shape[1], a.shape[2]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow1(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@_hot
def _log_event(log_t, log_t2, log_info, log_xb, log_xa, n_ev, t, t_after, rec, xb, xa):
    """Write record ``n_ev`` of the event log (the kernel keeps room for it: see its outer
    loop)."""
    log_t[n_ev] = t
    log_t2[n_ev] = t_after
    for c in range(rec.shape[0]):
        log_info[n_ev, c] = rec[c]
    for c in range(xb.shape[0]):
        log_xb[n_ev, c] = xb[c]
        log_xa[n_ev, c] = xa[c]


@_hot
def _dot(a, b, n):
    s = 0.0
    for i in range(n):
        s += a[i] * b[i]
    return s


@_hot
def _ulp(t):
    return max(abs(t), 1.0) * _EPS


# --------------------------------------------------------------------------------------
# vector fields of the discrete states
# --------------------------------------------------------------------------------------

@_hot
def _impact_direction(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx):
    """W of the impact law ``x+ = x- + W hdot`` (slides, "Simulation: Chattering").

    For a reset ``g`` that is the identity at zero normal velocity ``hdot``, differentiating
    ``g(x) - x = W(x) hdot(x)`` on ``hdot = 0`` gives ``g_x - I = W hdot_x``, hence
    ``W = (g_x - I) hdot_x^T / |hdot_x|^2`` -- computed from the compiled derivatives.
    Returns ``hdot_x . W`` (so the restitution coefficient is ``r = -(1 + hdot_x W)``).
    """
    ev(W_GX, j, t, x, p, gx)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    nrm2 = _dot(hdx, hdx, n)
    for i in range(n):
        s = -hdx[i]
        for c in range(n):
            s += gx[i * n + c] * hdx[c]
        W[i] = s / nrm2 if nrm2 > 0.0 else 0.0
    return _dot(hdx, W, n)


@_hot
def _field(ev, p, dkind, didx, mode, nm, t, x, n, out, etab, stab, slide_c, w1, w2, gx, hdx):
    """Vector field of the current discrete state at (t, x) into out[:n]."""
    if dkind == REGULAR:
        ev(W_F, mode, t, x, p, out)
        return
    if dkind == STICK:
        # constrained motion f - lambda W with lambda from hddot = 0 (slides):
        # lambda = (hdot_t + hdot_x f) / (hdot_x W)
        j = didx
        k = etab[j, 0]
        ev(W_F, mode, t, x, p, out)
        hw = _impact_direction(ev, p, j, k, mode, nm, t, x, n, w1, gx, hdx)
        ev(W_HDT, k * nm + mode, t, x, p, w2)
        acc = w2[0] + _dot(hdx, out, n)
        lam = acc / hw if hw != 0.0 else 0.0
        for i in range(n):
            out[i] -= lam * w1[i]
        return
    # SLIDE on switch didx: Filippov's convex combination (thesis eq. 2.7-2.8)
    #     f12 = (1 - alpha) f_above + alpha f_below,
    #     alpha = (h_t + h_x f_above) / (h_x (f_above - f_below)),
    # (eq. 2.8 with the h_t of a time-dependent surface) or Utkin's equivalent control
    # f(t, x, u_eq) with h_t + h_x f(t, x, u_eq) = 0 (slides, "Simulation: Filippov systems"),
    # plus the stabilising term of the slides, -C h h_x^T, scaled by 1/|h_x|^2 so that the
    # drift obeys hdot = -C h whatever the scale of h (C is a rate, 1/time; default 0: the
    # kernel projects each accepted sliding step back onto h = 0 instead)
    s = didx
    k = stab[s, 0]
    ev(W_HX, k, t, x, p, hdx)
    ev(W_H, k, t, x, p, out)
    hval = out[0]
    if stab.shape[1] > 4 and stab[s, 4] == SLIDE_UTKIN:
        u = _equivalent_control(ev, p, s, t, x, out)
        out[0] = u
        ev(W_FU, s, t, x, p, out)
    else:
        ev(W_F, stab[s, 1], t, x, p, w1)
        ev(W_F, stab[s, 2], t, x, p, w2)
        ev(W_HT, k, t, x, p, out)
        ha = out[0] + _dot(hdx, w1, n)
        den = _dot(hdx, w1, n) - _dot(hdx, w2, n)
        alpha = ha / den if den != 0.0 else 0.5
        for i in range(n):
            out[i] = (1.0 - alpha) * w1[i] + alpha * w2[i]
    # h_t + h_x f12 = 0 holds by construction up to round-off; remove that round-off along h_x
    # (a linear surface, e.g. v = V, is then conserved exactly by the Runge-Kutta stages even
    # over very long sliding steps)
    nrm2 = _dot(hdx, hdx, n)
    if nrm2 > 0.0:
        ev(W_HT, k, t, x, p, w2)
        res = (w2[0] + _dot(hdx, out, n)) / nrm2
        for i in range(n):
            out[i] -= res * hdx[i]
    if slide_c != 0.0 and hval != 0.0:
        nrm2 = _dot(hdx, hdx, n)
        if nrm2 > 0.0:
            g = slide_c * hval / nrm2
            for i in range(n):
                out[i] -= g * hdx[i]


@_hot
def _equivalent_control(ev, p, s, t, x, buf):
    """Utkin's equivalent control on switch ``s``: the root ``u`` of
    ``g(u) = h_t + h_x f(t, x, u)`` in ``[-1, 1]`` (``u = +1`` is the field above the surface,
    ``-1`` below), by Newton's method safeguarded by bisection on the bracket
    ``g(-1) > 0 > g(+1)`` that holds while sliding. The first guess is the root of the line
    through ``g(-1)`` and ``g(+1)``: exact (the convex method) when ``f`` is affine in ``u``.
    Outside the sliding region (stage values of a step that overshoots an exit) plain Newton
    continues the root smoothly; ``buf[0]`` is overwritten."""
    buf[0] = 1.0
    ev(W_HDU, s, t, x, p, buf)
    ga = buf[0]
    buf[0] = -1.0
    ev(W_HDU, s, t, x, p, buf)
    gb = buf[0]
    u = (ga + gb) / (gb - ga) if gb != ga else 0.0
    lo = -1.0
    hi = 1.0
    bracket = ga < 0.0 < gb
    if bracket:
        u = min(max(u, lo), hi)
    for it in range(60):
        buf[0] = u
        ev(W_HDU, s, t, x, p, buf)
        g = buf[0]
        if g == 0.0:
            break
        if bracket:
            if g > 0.0:
                lo = u
            else:
                hi = u
        buf[0] = u
        ev(W_HDUD, s, t, x, p, buf)
        d = buf[0]
        un = u - g / d if d != 0.0 else np.nan
        if bracket and not (lo < un < hi):
            un = 0.5 * (lo + hi)
        if not np.isfinite(un):
            break
        if abs(un - u) <= 4.0 * _EPS * max(1.0, abs(u)):
            u = un
            break
        u = un
    return u


@_hot
def _project_surface(ev, p, k, t, y, n, hdx, buf):
    """One Newton step onto ``h = 0`` along ``h_x``: at sliding entry the state is a few ulps
    off the surface; this removes them, so a linear ``h`` is then held to round-off."""
    ev(W_H, k, t, y, p, buf)
    hv = buf[0]
    ev(W_HX, k, t, y, p, hdx)
    nrm2 = _dot(hdx, hdx, n)
    if nrm2 > 0.0 and hv != 0.0:
        for i in range(n):
            y[i] -= hv * hdx[i] / nrm2


@_hot
def _partner(stab, k, m):
    """The mode across surface ``k`` from mode ``m`` (-1 if no switch joins them)."""
    for s in range(stab.shape[0]):
        if stab[s, 0] == k:
            if stab[s, 1] == m:
                return stab[s, 2]
            if stab[s, 2] == m:
                return stab[s, 1]
    return -1


@_hot
def _find_switch(stab, k, a, b):
    """The switch on surface ``k`` with mode ``a`` above and ``b`` below (-1 if none)."""
    for s in range(stab.shape[0]):
        if stab[s, 0] == k and stab[s, 1] == a and stab[s, 2] == b:
            return s
    return -1


@_hot
def _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx):
    """h of surface ``k`` at (t, y) and the round-off band around zero it is judged with
    (64 ulps of the state and gradient scales)."""
    ev(W_H, k, t, y, p, buf)
    hv = buf[0]
    ev(W_HX, k, t, y, p, hdx)
    gmax = 1.0
    for i in range(n):
        gmax = max(gmax, abs(hdx[i]))
    return hv, 64.0 * _EPS * xmax * gmax


@_hot
def _start_on_surface(ev, p, k, dkind, mode, nm, t, y, n, v0, r0, buf, hdx):
    """``(h, hdot)`` of surface ``k`` at the start of the first step after a restart, with
    round-off taken as zero: a surface within its band (:func:`_surface_offset`) is ON it,
    whatever the sign of that round-off (a slide exit or release that ends on a wall, a state
    given on a constraint). Taken as exactly zero, the crossing test fires at ``t`` if the
    flow goes into the event direction and never if it leaves. A rate within its own band
    (:func:`_rate_band`) is tangency, zero too: a start tangent to the surface and curving
    into it fires at ``t``, not where ``-c (t - t0)^2`` outgrows the round-off (~sqrt(eps)
    later)."""
    xmax = 1.0
    for i in range(n):
        xmax = max(xmax, abs(y[i]))
    hv, tolb = _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx)
    if abs(v0) <= tolb:
        v0 = 0.0
        if dkind == REGULAR and abs(r0) <= _rate_band(ev, p, k, mode, nm, t, y, n, hdx):
            r0 = 0.0
    return v0, r0


@_hot
def _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx):
    """The discrete state that the switches impose at ``(t, y)`` starting from ``mode``.

    Off every surface the mode must be the one on the side of ``h`` (a model written with
    ``sign``, or a state given or reset by the user, may name a mode on the other side).
    On a Filippov surface (``|h|`` within round-off of the state) the signs of
    ``hdot`` of the two modes decide, as at an arrival (thesis eq. 2.6-2.8): both pointing
    into the surface, sliding (the state is projected onto it); both pointing to one side,
    that side's mode. Returns ``(dkind, didx, mode)``.
    """
    n_sw = stab.shape[0]
    xmax = 1.0
    for i in range(n):
        xmax = max(xmax, abs(y[i]))
    # 1. the side of every surface the state is off
    for sweep in range(n_sw + 1):
        changed = False
        for s in range(n_sw):
            a = stab[s, 1]
            b = stab[s, 2]
            if mode != a and mode != b:
                continue
            hv, tol = _surface_offset(ev, p, stab[s, 0], t, y, n, xmax, buf, hdx)
            new = mode
            if hv > tol:
                new = a
            elif hv < -tol:
                new = b
            if new != mode:
                mode = new
                changed = True
        if not changed:
            break
    # 2. on a surface: slide, or take the side the flow leaves to
    for s in range(n_sw):
        a = stab[s, 1]
        b = stab[s, 2]
        if mode != a and mode != b:
            continue
        k = stab[s, 0]
        hv, tol = _surface_offset(ev, p, k, t, y, n, xmax, buf, hdx)
        if abs(hv) > tol:
            continue
        ev(W_HD, k * nm + a, t, y, p, buf)
        sa = buf[0]
        ev(W_HD, k * nm + b, t, y, p, buf)
        sb = buf[0]
        filippov = stab.shape[1] <= 3 or stab[s, 3] == SW_FILIPPOV
        if filippov and sa < 0.0 and sb > 0.0:
            _project_surface(ev, p, k, t, y, n, hdx, buf)
            return SLIDE, s, a
        if sa >= 0.0 and sb > 0.0 or sa > 0.0 and sb >= 0.0:
            mode = a
        elif sa <= 0.0 and sb < 0.0 or sa < 0.0 and sb <= 0.0:
            mode = b
    return REGULAR, -1, mode


@_hot
def _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, out, etab, stab, slide_c,
         w1, w2, gx, hdx, jac, xt, ft):
    """Right-hand side of the (optionally variational) system."""
    _field(ev, p, dkind, didx, mode, nm, t, y, n, out, etab, stab, slide_c, w1, w2, gx, hdx)
    if nvar == 0:
        return
    _jacobian(ev, p, dkind, didx, mode, nm, t, y, n, out, etab, stab, slide_c,
              w1, w2, gx, hdx, jac, xt, ft)
    # Phi' = J Phi, Phi stored row-major after the state
    for i in range(n):
        for c in range(n):
            s = 0.0
            for m in range(n):
                s += jac[i * n + m] * y[n + m * n + c]
            out[n + i * n + c] = s


@_hot
def _jacobian(ev, p, dkind, didx, mode, nm, t, y, n, f0, etab, stab, slide_c,
              w1, w2, gx, hdx, jac, xt, ft):
    """Jacobian of the current field: symbolic in a regular mode, central differences of the
    constrained (sticking) or sliding field otherwise (those involve second derivatives of
    h and g that the generated code does not carry)."""
    if dkind == REGULAR:
        ev(W_FX, mode, t, y, p, jac)
        return
    for c in range(n):
        for i in range(n):
            xt[i] = y[i]
        # step ~ eps^(1/3): truncation (dx^2) and rounding (eps/dx) errors balance near 1e-11
        dx = _FD_STEP * max(1.0, abs(y[c]))
        xt[c] = y[c] + dx
        _field(ev, p, dkind, didx, mode, nm, t, xt, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
        for i in range(n):
            jac[i * n + c] = ft[i]
        xt[c] = y[c] - dx
        _field(ev, p, dkind, didx, mode, nm, t, xt, n, ft, etab, stab, slide_c, w1, w2, gx, hdx)
        for i in range(n):
            jac[i * n + c] = (jac[i * n + c] - ft[i]) / (2.0 * dx)


# --------------------------------------------------------------------------------------
# Runge-Kutta step and dense output
# --------------------------------------------------------------------------------------

@_hot
def _error_norm(K, E, method, s, y, ynew, h, i0, i1, rtol, atol):
    """Scaled RMS error of the components ``y[i0:i1]``.

    The kernel takes the state (``0:n``) and, with variational equations, ``Phi`` (``n:nY``)
    separately and accepts a step only when both meet the tolerances: on a sliding surface,
    for example, the state moves trivially while ``Phi`` contracts at the stabilising rate,
    and a step chosen for the state alone misses that."""
    m = i1 - i0
    if method == 0:
        acc = 0.0
        for i in range(i0, i1):
            e = 0.0
            for j in range(s + 1):
                e += E[0, j] * K[j, i]
            sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
            acc += (h * e / sc) ** 2
        return np.sqrt(acc / m)
    # DOP853 (Hairer et al. II.10): combined 5th and 3rd order estimates
    e5 = 0.0
    e3 = 0.0
    for i in range(i0, i1):
        a5 = 0.0
        a3 = 0.0
        for j in range(s + 1):
            a5 += E[0, j] * K[j, i]
            a3 += E[1, j] * K[j, i]
        sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
        e5 += (a5 / sc) ** 2
        e3 += (a3 / sc) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * m)


@_hot
def _dense_coeffs(K, P, h, nY, s_ext, deg, out):
    """out[i, k] = h * sum_j K[j, i] P[j, k]  (power form, theta^(k+1))."""
    for i in range(nY):
        for k in range(deg):
            acc = 0.0
            for j in range(s_ext):
                pj = P[j, k]
                if pj != 0.0:
                    acc += K[j, i] * pj
            out[i, k] = h * acc


@njit(cache=True)
def _take_samples(t, h, y, Q, nY, n, deg, s0, sdt, k, t_end, samp, n_samp, xs, max_samp):
    """Record the states at the sample times ``s0 + k sdt`` in ``(t, t + h]`` (and not past
    ``t_end``) from the step's dense output into ``samp`` (allocated for all of them), at most
    ``max_samp`` in all. Returns ``(n_samp, k)``."""
    ts = s0 + k * sdt
    # bounded: the kernel admits only finite s0, t, h, t_end and 0 < sdt < inf, so ts grows
    # with k; the cap bounds a tiny sdt (the kernel's set-up already refuses more samples
    # than it, so it is only a backstop and never drops a sample of a run it accepted)
    while ts <= t + h and ts <= t_end and n_samp < max_samp:
        _dense_eval(y, Q, (ts - t) / h if h > 0.0 else 1.0, nY, deg, xs)
        samp[n_samp, 0] = ts
        for i in range(n):
            samp[n_samp, 1 + i] = xs[i]
        n_samp += 1
        k += 1
        ts = s0 + k * sdt
    return n_samp, k


@_hot
def _exact_step(M, sc, wt, md, nz, n, t, y, h, z, v, Q, ynew):
    """One exact step of affine mode ``md``: ``z(t + h) = exp(h M) z(t)`` for the augmented
    state ``z = (x, 1, cos(w_j t), sin(w_j t), ...)`` (:mod:`pwsdyn.model.affine`); ``M``,
    ``sc``, ``wt`` are the per-mode tables of :func:`_affine_setup` (indexed here, not sliced
    by the caller: an array view costs two atomic reference-count updates per step).

    The exponential is summed as its Taylor series ``sum_k (h M)^k z / k!`` (dense products: a
    compressed-row product skipping the zeros of ``M`` measured slower at these sizes). The
    caller keeps ``||h D^-1 M D||_inf <= 1`` (``D`` the balancing scales of the mode, ``wt``
    their inverses, powers of two: see :func:`_affine_setup`), so in the balanced coordinates
    the terms fall faster than ``1/k!`` and the sum is exact to rounding after at most
    ``_EXACT_TERMS`` terms; it stops once a term is below 1e-18 of ``z`` (both measured in
    those coordinates). The terms are also the dense output: ``x(t + theta h) = x + sum_k
    Q[:, k-1] theta^k`` is the same series at ``theta h``, so events are located on the exact
    flow too. Columns of ``Q`` past the last term are zeroed."""
    _augment(M, sc, md, nz, n, t, y, z)
    zmax = 0.0
    for i in range(nz):
        zmax = max(zmax, abs(z[i]) * wt[md, i])
    for i in range(n):
        ynew[i] = y[i]
    ncol = Q.shape[1]
    k = 1
    while k <= ncol:
        # v = (h / k) M z, then z = v (z holds the previous term)
        c = h / k
        big = 0.0
        for i in range(nz):
            acc = 0.0
            for m in range(nz):
                acc += M[md, i, m] * z[m]
            v[i] = c * acc
            big = max(big, abs(v[i]) * wt[md, i])
        for i in range(nz):
            z[i] = v[i]
        for i in range(n):
            Q[i, k - 1] = v[i]
            ynew[i] += v[i]
        k += 1
        if big <= 1e-18 * zmax or k > _EXACT_TERMS:
            break
    for kk in range(k - 1, ncol):
        for i in range(n):
            Q[i, kk] = 0.0


@_hot
def _exact_propagator(M, wt, md, nz, h, Pm, T1, T2):
    """``Pm = exp(h M)`` summed as its Taylor series (``||h D^-1 M D||_inf <= 1``, as in
    :func:`_exact_step`; the stop test on the balanced entries ``T_ic d_c / d_i``): steps of
    the same length then cost one matrix-vector product."""
    for i in range(nz):
        for c in range(nz):
            T1[i, c] = 1.0 if i == c else 0.0
            Pm[md, i, c] = T1[i, c]
    for k in range(1, _EXACT_TERMS + 1):
        big = 0.0
        for i in range(nz):
            for c in range(nz):
                acc = 0.0
                for m in range(nz):
                    acc += T1[i, m] * M[md, m, c]
                T2[i, c] = acc * h / k
                big = max(big, abs(T2[i, c]) * wt[md, i] / wt[md, c])
        for i in range(nz):
            for c in range(nz):
                T1[i, c] = T2[i, c]
                Pm[md, i, c] += T2[i, c]
        if big <= 1e-18:
            break


@_hot_inline
def _exact_apply(M, sc, Pm, md, nz, n, t, y, z, ynew):
    """``x(t + h)`` from a cached propagator ``Pm[md] = exp(h M)`` (see :func:`_exact_step`)."""
    _augment(M, sc, md, nz, n, t, y, z)
    for i in range(n):
        acc = 0.0
        for m in range(nz):
            acc += Pm[md, i, m] * z[m]
        ynew[i] = acc


@_hot
def _balance(M, nz, w, B):
    """Balancing of ``M`` by a diagonal similarity of powers of two (Parlett & Reinsch 1969,
    as LAPACK's ``gebal`` without permutations): ``B = D^-1 M D`` with row and column norms
    (off the diagonal) made comparable. Writes ``w = 1 / diag(D)`` (exact: powers of two) and
    returns ``||B||_inf``. Rows or columns that are zero off the diagonal (the constant of the
    augmented state) keep their scale.

    The exponential's Taylor terms in the balanced coordinates are those of ``M`` scaled by
    powers of two, so only the step bound and the stop tests use ``D``: a stiff spring
    ``[[0, 1], [-k, -c]]`` has ``||M|| ~ k`` but ``||B|| ~ sqrt(k)``, its frequency."""
    for i in range(nz):
        w[i] = 1.0
        for c in range(nz):
            B[i, c] = M[i, c]
    for sweep in range(64):
        done = True
        for i in range(nz):
            c = 0.0
            r = 0.0
            for j in range(nz):
                if j != i:
                    c += abs(B[j, i])
                    r += abs(B[i, j])
            if c == 0.0 or r == 0.0 or not (np.isfinite(c) and np.isfinite(r)):
                continue
            g = r / 2.0
            f = 1.0
            tot = c + r
            while c < g and f < 2.0 ** 500:
                f *= 2.0
                c *= 4.0
            g = r * 2.0
            while c > g and f > 2.0 ** -500:
                f /= 2.0
                c /= 4.0
            if (c + r) / f < 0.95 * tot:
                done = False
                # column i times f, row i divided by f: D_ii *= f
                w[i] /= f
                for j in range(nz):
                    B[i, j] /= f
                    B[j, i] *= f
        if done:
            break
    nrm = 0.0
    for i in range(nz):
        row = 0.0
        for c in range(nz):
            row += abs(B[i, c])
        nrm = max(nrm, row)
    return nrm


@njit(cache=True)
def _affine_setup(ev, t0, x0, p, n, nm, enabled):
    """The exact propagation data of a run: ``(nz, ok, M, hmax, scale, weight)``.

    ``nz`` is the size of the augmented state (0: exact propagation off, or no mode is
    affine); per mode ``ok`` (affine with a finite matrix), its augmented matrix ``M`` with the
    constant and forcing columns divided by ``scale``, the largest exact step ``hmax`` with
    ``||hmax D^-1 M D||_inf <= 1`` and the inverse balancing scales ``weight = 1 / diag(D)``
    (:func:`_balance`; the identity where balancing does not lower the norm)."""
    nz = 0
    if enabled:
        abuf = np.zeros(1)
        ev(W_AFFINE, -1, t0, x0, p, abuf)
        nz = int(abuf[0])
    aff_ok = np.zeros(nm, dtype=np.int64)
    aff_M = np.zeros((nm, max(nz, 1), max(nz, 1)))
    aff_h = np.zeros(nm)
    aff_s = np.ones((nm, max(nz, 1)))
    aff_w = np.ones((nm, max(nz, 1)))
    if nz > 0:
        abuf = np.zeros(1 + nz * nz)
        B = np.zeros((nz, nz))
        wb = np.ones(nz)
        for m in range(nm):
            ev(W_AFFINE, m, t0, x0, p, abuf)
            if abuf[0] == 0.0:
                continue
            for i in range(nz):
                for c in range(nz):
                    aff_M[m, i, c] = abuf[1 + i * nz + c]
            # scale the constant and each (cos, sin) pair of z by the largest coefficient
            # multiplying it (z = (x, s_0, s_1 cos, s_1 sin, ...), those columns of M divided
            # by s): the step bound ||h M|| <= 1 then reflects the dynamics, not the units of
            # b or of the forcing amplitude (a ball in flight: b = -g)
            for c in range(n, nz):
                aff_s[m, c] = 1.0
            for c in range(n, nz):
                if c > n and (c - n) % 2 == 0:
                    continue  # the sin column shares the scale of its cos column
                big = 0.0
                for i in range(n):
                    big = max(big, abs(aff_M[m, i, c]))
                    if c > n:
                        big = max(big, abs(aff_M[m, i, c + 1]))
                if big > 1.0 and np.isfinite(big):
                    aff_s[m, c] = big
                    if c > n:
                        aff_s[m, c + 1] = big
            for c in range(n, nz):
                for i in range(n):
                    aff_M[m, i, c] /= aff_s[m, c]
            nrm = 0.0
            for i in range(nz):
                row = 0.0
                for c in range(nz):
                    row += abs(aff_M[m, i, c])
                nrm = max(nrm, row)
            if not np.isfinite(nrm):
                continue
            # balanced: the step bound of a stiff spring is its frequency, not its stiffness
            nb = _balance(aff_M[m], nz, wb, B)
            if nb < nrm:
                nrm = nb
                for i in range(nz):
                    aff_w[m, i] = wb[i]
            aff_ok[m] = 1
            aff_h[m] = 1.0 / nrm if nrm > 0.0 else np.inf
    return nz, aff_ok, aff_M, aff_h, aff_s, aff_w


@_hot_inline
def _augment(M, sc, md, nz, n, t, y, z):
    """The augmented state ``z = (x, s_0, s_1 cos(w_1 t), s_1 sin(w_1 t), ...)``, the
    frequencies read off the rotation blocks ``(0, -w_j; w_j, 0)`` of ``M`` and the scales
    ``s`` from ``sc`` (``M``'s columns are divided by them: see the kernel's set-up)."""
    for i in range(n):
        z[i] = y[i]
    z[n] = sc[md, n]
    for j in range((nz - n - 1) // 2):
        om = M[md, n + 2 + 2 * j, n + 1 + 2 * j]
        z[n + 1 + 2 * j] = sc[md, n + 1 + 2 * j] * np.cos(om * t)
        z[n + 2 + 2 * j] = sc[md, n + 2 + 2 * j] * np.sin(om * t)


@_hot
def _dense_eval(y0, Q, theta, nY, deg, out):
    for i in range(nY):
        acc = 0.0
        for k in range(deg - 1, -1, -1):
            acc = (acc + Q[i, k]) * theta
        out[i] = y0[i] + acc


# --------------------------------------------------------------------------------------
# watch functions
# --------------------------------------------------------------------------------------

@_hot
def _watch_value(ev, p, wtype, widx, wmode, nm, t, x, n, buf, fbuf, hdx):
    if wtype == WF_SURFACE:
        ev(W_H, widx, t, x, p, buf)
        return buf[0]
    if wtype == WF_HDOT:
        ev(W_HD, widx * nm + wmode, t, x, p, buf)
        return buf[0]
    # WF_HDDOT: free normal acceleration hdot_t + hdot_x f
    ev(W_F, wmode, t, x, p, fbuf)
    ev(W_HDX, widx * nm + wmode, t, x, p, hdx)
    ev(W_HDT, widx * nm + wmode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n)


@_hot
def _surface_rate(ev, p, dkind, k, mode, nm, t, x, f, n, buf, hdx):
    """dh/dt along the current field f: one call of the compiled hdot in a regular mode."""
    if dkind == REGULAR:
        ev(W_HD, k * nm + mode, t, x, p, buf)
        return buf[0]
    ev(W_HX, k, t, x, p, hdx)
    ev(W_HT, k, t, x, p, buf)
    return buf[0] + _dot(hdx, f, n)


@_hot
def _hdot_rate(ev, p, k, wm, nm, t, x, f, n, buf, hdx):
    """d/dt of ``hdot`` of mode ``wm`` on surface ``k`` along the current field ``f``:
    ``hdot_t + hdot_x f`` (to polish a sliding exit, where that ``hdot`` reaches zero)."""
    ev(W_HDX, k * nm + wm, t, x, p, hdx)
    ev(W_HDT, k * nm + wm, t, x, p, buf)
    return buf[0] + _dot(hdx, f, n)


@_hot
def _crosses(v0, v1, direction):
    """A zero crossing from v0 to v1 in ``direction``. A function that starts exactly at zero
    and moves in the event direction crosses (a start on an impact surface with approaching
    velocity is an impact at the initial time)."""
    if direction < 0:
        return (v0 > 0.0 and v1 <= 0.0) or (v0 == 0.0 and v1 < 0.0)
    if direction > 0:
        return (v0 < 0.0 and v1 >= 0.0) or (v0 == 0.0 and v1 > 0.0)
    return (v0 > 0.0 and v1 <= 0.0) or (v0 < 0.0 and v1 >= 0.0)


@_hot
def _watch_slope(ev, p, wtype, widx, wmode, nm, t, h, y, Q, n, deg, th, xs, buf, fbuf, hdx):
    """d/dt of a watch function along the step's dense output at ``theta``: a central
    difference (relative step ``_FD_STEP`` of the step; the dense output is a polynomial, so
    ``theta +- step`` may lie just outside ``[0, 1]``). For the normal acceleration of a
    sticking motion, whose time derivative the generated code does not carry."""
    ta = t + (th - _FD_STEP) * h
    tb = t + (th + _FD_STEP) * h
    if not tb > ta:
        return 0.0
    _dense_eval(y, Q, th - _FD_STEP, n, deg, xs)
    ga = _watch_value(ev, p, wtype, widx, wmode, nm, ta, xs, n, buf, fbuf, hdx)
    _dense_eval(y, Q, th + _FD_STEP, n, deg, xs)
    gb = _watch_value(ev, p, wtype, widx, wmode, nm, tb, xs, n, buf, fbuf, hdx)
    return (gb - ga) / (tb - ta)


@_hot
def _watch_pair(ev, p, wtype, widx, wmode, dkind, didx, mode, nm, t, h, y, Q, n, deg, th, xs,
                buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2, gx):
    """Value and time derivative of a watch function at ``theta`` on the step's dense output
    (the exact flow on an exact step). Surfaces: ``h`` and ``hdot`` from the model at the
    interpolated state (one call in a regular mode; along the sticking or sliding field
    otherwise); other watch functions: :func:`_watch_slope`."""
    tt = t + th * h
    _dense_eval(y, Q, th, n, deg, xs)
    if wtype == WF_SURFACE:
        if dkind == REGULAR:
            ev(W_HHD, widx * nm + mode, tt, xs, p, buf)
            return buf[0], buf[1]
        ev(W_H, widx, tt, xs, p, buf)
        g = buf[0]
        _field(ev, p, dkind, didx, mode, nm, tt, xs, n, f, etab, stab, slide_c, w1, w2, gx, hdx)
        return g, _surface_rate(ev, p, dkind, widx, mode, nm, tt, xs, f, n, buf, hdx)
    g = _watch_value(ev, p, wtype, widx, wmode, nm, tt, xs, n, buf, fbuf, hdx)
    return g, _watch_slope(ev, p, wtype, widx, wmode, nm, t, h, y, Q, n, deg, th, xs, buf, fbuf,
                           hdx)


@_hot
def _extremum_search(ev, p, wtype, widx, wmode, dkind, didx, mode, nm, t, h, y, Q, n, deg,
                     a, ga, da, b, gb, db, xs, buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2,
                     gx):
    """Bounded search for a crossing hidden at an extremum of a watch function ``g`` between
    two samples ``a < b`` (in theta) of one sign ``s`` where ``s g`` decreases at ``a``
    (``s da < 0``) and increases at ``b`` (``s db > 0``; ``da``, ``db`` are time derivatives).

    With ``G = s g`` convex on the bracket, the tangents at its ends bound ``G`` from below;
    their intersection gives the bound ``LB`` on its minimum. While ``LB <= 0`` the bracket
    is shrunk by the zero of the secant of ``G'`` (Illinois, safeguarded by bisection), ``g``
    and ``g'`` evaluated on the dense output, until a sample with ``G <= 0`` is found (the
    crossing), ``LB > 0`` (no crossing) or the bound is tight to rounding. The bound is
    second order in the bracket, so the error of one sample at an estimated extremum (the
    Hermite fit's, which grows like ``h^3``) no longer decides whether a graze is seen: a
    graze deeper than the dense output's error is found. Returns the sample with the smallest
    ``G``: ``(theta, g, g')``."""
    s = 1.0 if ga > 0.0 else -1.0
    Ga = s * ga
    Gb = s * gb
    Da = s * da * h     # derivatives in theta units
    Db = s * db * h
    best_th = a
    best_g = ga
    best_d = da
    if Gb < Ga:
        best_th = b
        best_g = gb
        best_d = db
    gnoise = 64.0 * _EPS * (Ga + Gb) + 1e-300
    Sa = Da             # the Illinois-weighted end derivatives of the secant
    Sb = Db
    side = 0
    width_check = b - a
    for it in range(48):
        W = b - a
        if W * h <= 4.0 * _ulp(t + b * h):
            break
        u = (Gb - Ga - Db * W) / (Da - Db)
        u = min(max(u, 0.0), W)
        LB = max(Ga + Da * u, Gb + Db * (u - W))
        if LB > 0.0 or s * best_g - LB <= gnoise:
            break
        m = a + W * Sa / (Sa - Sb)
        if it % 2 == 1:
            if W > 0.5 * width_check:
                m = 0.5 * (a + b)
            width_check = W
        if not (a < m < b):
            m = 0.5 * (a + b)
        gm, dm = _watch_pair(ev, p, wtype, widx, wmode, dkind, didx, mode, nm, t, h, y, Q, n,
                             deg, m, xs, buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2, gx)
        if not (np.isfinite(gm) and np.isfinite(dm)):
            break
        Gm = s * gm
        Dm = s * dm * h
        if Gm < s * best_g:
            best_th = m
            best_g = gm
            best_d = dm
        if Gm <= 0.0:
            break
        if Dm < 0.0:
            a = m
            Ga = Gm
            Da = Dm
            Sa = Dm
            if side == -1:
                Sb *= 0.5
            side = -1
        elif Dm > 0.0:
            b = m
            Gb = Gm
            Db = Dm
            Sb = Dm
            if side == 1:
                Sa *= 0.5
            side = 1
        else:
            break
    return best_th, best_g, best_d


@_hot
def _graze_samples(ev, p, wtype, widx, wmode, wdir, dkind, didx, mode, nm, t, h, y, Q, n, deg,
                   th, g, gd, ns, xs, buf, fbuf, hdx, f, etab, stab, slide_c, w1, w2, gx):
    """Samples ``th[:ns]`` (increasing theta) of a watch function with values ``g`` and time
    derivatives ``gd``: between consecutive samples of one sign where it moves towards zero
    and then away (an extremum towards zero, in a direction the watch reacts to) run
    :func:`_extremum_search` and insert the sample it returns. Stops at the first pair that
    brackets a crossing. Returns the new number of samples."""
    q = 0
    while q < ns - 1 and ns < th.shape[0]:
        ga = g[q]
        gb = g[q + 1]
        if _crosses(ga, gb, wdir):
            break
        if ga != 0.0 and gb != 0.0 and (ga > 0.0) == (gb > 0.0):
            s = 1.0 if ga > 0.0 else -1.0
            if s * wdir <= 0 and s * gd[q] < 0.0 and s * gd[q + 1] > 0.0:
                tm, gm, dm = _extremum_search(ev, p, wtype, widx, wmode, dkind, didx, mode, nm,
                                              t, h, y, Q, n, deg, th[q], ga, gd[q], th[q + 1],
                                              gb, gd[q + 1], xs, buf, fbuf, hdx, f, etab, stab,
                                              slide_c, w1, w2, gx)
                if th[q] < tm < th[q + 1]:
                    for r in range(ns, q + 1, -1):
                        th[r] = th[r - 1]
                        g[r] = g[r - 1]
                        gd[r] = gd[r - 1]
                    th[q + 1] = tm
                    g[q + 1] = gm
                    gd[q + 1] = dm
                    ns += 1
                    if _crosses(ga, gm, wdir):
                        break
                    q += 1
        q += 1
    return ns


@_hot
def _hermite_extrema(v0, v1, d0, d1):
    """Interior extrema ``ra <= rb`` in ``(0, 1)`` of the cubic Hermite fit with values ``v0``,
    ``v1`` and theta-derivatives ``d0``, ``d1`` at the ends (2.0: none). With
    ``H(th) = ca th^3 + cb th^2 + d0 th + v0``, the roots of ``H'`` by the cancellation-free
    form of the quadratic formula (Numerical Recipes 5.6): the cubic term vanishes for a
    parabolic ``h``, where the textbook formula loses all digits."""
    qa = 3.0 * (2.0 * v0 - 2.0 * v1 + d0 + d1)
    qb = 2.0 * (-3.0 * v0 + 3.0 * v1 - 2.0 * d0 - d1)
    disc = qb * qb - 4.0 * qa * d0
    ra = 2.0
    rb = 2.0
    if disc >= 0.0:
        qq = -0.5 * (qb + (np.sqrt(disc) if qb >= 0.0 else -np.sqrt(disc)))
        if qa != 0.0:
            ra = qq / qa
        if qq != 0.0:
            rb = d0 / qq
        if ra > rb:
            ra, rb = rb, ra
    if not (0.0 < ra < 1.0):
        ra = 2.0
    if not (0.0 < rb < 1.0) or rb == ra:
        rb = 2.0
    if rb < ra:
        ra, rb = rb, ra
    return ra, rb


@_hot
def _merge_samples(th, g, ns, th2, g2, ns2):
    """Insert the interior samples ``th2[1:ns2-1]`` into the increasing samples ``th[:ns]``
    (same ends), as room allows. Returns the new number of samples."""
    for q2 in range(1, ns2 - 1):
        if ns >= th.shape[0]:
            break
        tq = th2[q2]
        r = ns
        while r > 0 and th[r - 1] > tq:
            th[r] = th[r - 1]
            g[r] = g[r - 1]
            r -= 1
        if r > 0 and th[r - 1] == tq:
            # already sampled there: undo the shift
            for r2 in range(r, ns):
                th[r2] = th[r2 + 1]
                g[r2] = g[r2 + 1]
            continue
        th[r] = tq
        g[r] = g2[q2]
        ns += 1
    return ns


# --------------------------------------------------------------------------------------
# event maps and saltation matrices
# --------------------------------------------------------------------------------------

@_hot
def _project_stick(ev, p, k, mode, nm, t, x, n, hdx, w2, buf):
    """Project x onto {h = 0, hdot = 0} along span(h_x, hdot_x) (two Newton iterations)."""
    for it in range(3):
        ev(W_H, k, t, x, p, buf)
        r1 = buf[0]
        ev(W_HD, k * nm + mode, t, x, p, buf)
        r2 = buf[0]
        ev(W_HX, k, t, x, p, w2)
        ev(W_HDX, k * nm + mode, t, x, p, hdx)
        # solve [a.a a.b; b.a b.b] c = -r for x += c0 a + c1 b with a = h_x, b = hdot_x
        aa = _dot(w2, w2, n)
        ab = _dot(w2, hdx, n)
        bb = _dot(hdx, hdx, n)
        det = aa * bb - ab * ab
        if det == 0.0 or not np.isfinite(det):
            return
        # rows: h_x.(c0 a + c1 b) = -r1, hdot_x.(c0 a + c1 b) = -r2
        c0 = (-r1 * bb + r2 * ab) / det
        c1 = (-r2 * aa + r1 * ab) / det
        for i in range(n):
            x[i] += c0 * w2[i] + c1 * hdx[i]


#: Relative size of ``h_t + h_x f`` below which an event is grazing and its saltation matrix
#: singular (the same test as :func:`pwsdyn.stability.saltation_matrix`).
GRAZING_RTOL = 1e-13


@_hot
def _grazing(den, hx, f, n):
    """``den = h_t + h_x f`` is zero within ``GRAZING_RTOL |h_x| |f|`` (or not finite): the
    flow is tangent to the surface and the saltation matrix, with ``den`` as its
    denominator, is unbounded."""
    return not (abs(den) > GRAZING_RTOL * np.sqrt(_dot(hx, hx, n)) * np.sqrt(_dot(f, f, n)))


@_hot
def _rate_band(ev, p, k, mode, nm, t, x, n, hdx):
    """The round-off band around zero of ``hdot`` of surface ``k`` in ``mode`` at (t, x): 64
    ulps of the state and gradient scales, as :func:`_surface_offset` for ``h``. A normal
    velocity within it is tangency; its sign is noise (after a plastic impact on an oblique
    or curved surface ``hdot`` is +-1e-16)."""
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    xmax = 1.0
    gmax = 1.0
    for i in range(n):
        xmax = max(xmax, abs(x[i]))
        gmax = max(gmax, abs(hdx[i]))
    return 64.0 * _EPS * xmax * gmax


@_hot
def _free_normal_acc(ev, p, k, mode, nm, t, x, n, buf, fbuf, hdx):
    """The free normal acceleration ``hdot_t + hdot_x f`` of surface ``k`` in ``mode``."""
    ev(W_F, mode, t, x, p, fbuf)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n)


@_hot
def _stays_in_contact(ev, p, k, mode, nm, t, x, n, buf, fbuf, hdx):
    """A state on impact surface ``k`` whose normal velocity ``hdot`` is round-off
    (:func:`_rate_band`) while the free normal acceleration ``hdot_t + hdot_x f`` points into
    the surface: contact (sticking, i.e. constrained motion along the surface), never free
    flight through it."""
    ev(W_HD, k * nm + mode, t, x, p, buf)
    vn = buf[0]
    if not abs(vn) <= _rate_band(ev, p, k, mode, nm, t, x, n, hdx):
        return False
    ev(W_F, mode, t, x, p, fbuf)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    return buf[0] + _dot(hdx, fbuf, n) < 0.0


@njit(cache=True)
def _event_saltation(ev, p, j, k, mode_in, mode_out, nm, t, x_in, x_out, n, S, gx, hx, buf,
                     f_in, f_out, gt, etab, stab, slide_c, old_kind, old_idx, tmp, new_kind,
                     new_idx):
    """S = g_x + (f_out - g_x f_in - g_t) h_x / (h_t + h_x f_in)  (slides, "Saltation
    matrices", with the time derivatives of time-dependent surfaces and resets): the full
    saltation matrix, ``Phi+ = S Phi-``. ``f_in`` is the field of the discrete state before the
    event at ``x_in``, ``f_out`` the field of the state after it at ``x_out = g(x_in)``.

    At a grazing event (``h_t + h_x f_in`` zero within :func:`_grazing`) the saltation matrix
    is unbounded: S is all NaN, so the variational result (the event's transfer matrix, the
    Jacobian through it) is marked singular instead of silently losing its singular term;
    :func:`pwsdyn.stability.saltation_matrix` raises there by the same test."""
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    hdx = np.zeros(n)
    _field(ev, p, old_kind, old_idx, mode_in, nm, t, x_in, n, f_in, etab, stab, slide_c,
           w1, w2, gx, hdx)
    _field(ev, p, new_kind, new_idx, mode_out, nm, t, x_out, n, f_out, etab, stab, slide_c,
           w1, w2, gx, hdx)
    ev(W_GX, j, t, x_in, p, gx)
    ev(W_GT, j, t, x_in, p, gt)
    ev(W_HX, k, t, x_in, p, hx)
    ev(W_HT, k, t, x_in, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    if _grazing(den, hx, f_in, n):
        S[:, :] = np.nan
        return
    for i in range(n):
        gf = 0.0
        for c in range(n):
            gf += gx[i * n + c] * f_in[c]
        v = f_out[i] - gf - gt[i]
        for c in range(n):
            S[i, c] = gx[i * n + c] + (v * hx[c] / den if den != 0.0 else 0.0)


@njit(cache=True)
def _switch_saltation(ev, p, dkind, didx, mode_in, mode_out, nm, k, t, x, n, S, hx, buf,
                      f_in, w1, w2, gx, etab, stab, slide_c, old_kind, old_idx):
    """Crossing or sliding entry: S = I + (f_out - f_in) h_x / (h_t + h_x f_in), with f_in
    the field of the discrete state before (``old_kind``, ``old_idx``, ``mode_in``) and f_out
    that of the state after (the sliding field at sliding entry). At sliding entry
    ``h_x S = 0``: the normal perturbation is lost (a zero multiplier). Grazing (see
    :func:`_grazing`): S is all NaN, as in :func:`_event_saltation`."""
    f_out = np.zeros(n)
    hdx = np.zeros(n)
    _field(ev, p, old_kind, old_idx, mode_in, nm, t, x, n, f_in, etab, stab, slide_c, w1, w2, gx,
           hdx)
    _field(ev, p, dkind, didx, mode_out, nm, t, x, n, f_out, etab, stab, slide_c, w1, w2, gx, hdx)
    ev(W_HX, k, t, x, p, hx)
    ev(W_HT, k, t, x, p, buf)
    den = buf[0] + _dot(hx, f_in, n)
    if _grazing(den, hx, f_in, n):
        S[:, :] = np.nan
        return
    for i in range(n):
        for c in range(n):
            S[i, c] = (1.0 if i == c else 0.0) + ((f_out[i] - f_in[i]) * hx[c] / den
                                                  if den != 0.0 else 0.0)


@_hot
def _chatter_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf):
    """Complete-chattering map Q and time q at x (slides; Nordmark & Piiroinen 2009).
    Returns the duration q(x) - t; writes Q(x) into out."""
    ev(W_HD, k * nm + mode, t, x, p, buf)
    vin = buf[0]
    ev(W_F, mode, t, x, p, f)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    acc = buf[0] + _dot(hdx, f, n)
    hw = _impact_direction(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx)
    r = -(1.0 + hw)
    for i in range(n):
        out[i] = x[i] + (2.0 * r * f[i] / acc + W[i]) * vin / (1.0 - r)
    return 2.0 * r * vin / ((1.0 - r) * acc)


@_hot
def _chatter_event_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf, hx):
    """The complete-chattering event map as the kernel applies it: ``(t_in, x_in) -> (t_out,
    x_out)`` with ``t_out = q(t_in, x_in)`` and ``x_out`` the map ``Q(t_in, x_in)`` (slides,
    "Local mapping at complete chattering") projected onto the sticking manifold
    ``{h = 0, hdot = 0}`` at ``t_out``. Returns ``t_out``; writes ``x_out`` into ``out``."""
    dur = _chatter_map(ev, p, j, k, mode, nm, t, x, n, out, W, gx, hdx, f, buf)
    t_out = t + dur
    _project_stick(ev, p, k, mode, nm, t_out, out, n, hdx, hx, buf)
    return t_out


@_hot
def _chatter_coef(ev, p, j, k, mode, nm, t, x, n, c, W, gx, hdx, f, buf):
    """The coefficients of the complete-chattering map, smooth functions of ``(t, x)``:
    ``Q = x + c hdot``, ``q = b hdot`` with ``b = 2 r / ((1 - r) a)`` and
    ``c = (2 r f / a + W) / (1 - r)`` (:func:`_chatter_map`). Writes c; returns b."""
    ev(W_F, mode, t, x, p, f)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    ev(W_HDT, k * nm + mode, t, x, p, buf)
    acc = buf[0] + _dot(hdx, f, n)
    hw = _impact_direction(ev, p, j, k, mode, nm, t, x, n, W, gx, hdx)
    r = -(1.0 + hw)
    for i in range(n):
        c[i] = (2.0 * r * f[i] / acc + W[i]) / (1.0 - r)
    return 2.0 * r / ((1.0 - r) * acc)


@_hot
def _stick_gradients(ev, p, k, mode, nm, t, x, n, mu0, mu1, out, hdx):
    """``G = mu0 h_x + mu1 hdot_x`` at ``(t, x)`` into out (the normal displacement of the
    projection onto the sticking manifold, as a function of the point)."""
    ev(W_HX, k, t, x, p, out)
    ev(W_HDX, k * nm + mode, t, x, p, hdx)
    for i in range(n):
        out[i] = mu0 * out[i] + mu1 * hdx[i]


@njit(cache=True)
def _chatter_saltation(ev, p, j, k, mode, nm, t, x_in, n, S, etab, stab, slide_c):
    """Saltation matrix of a complete chattering sequence (the full form, ``Phi+ = S Phi-``).

    For an event map ``(t_in, x_in) -> (tau, X)`` applied where the flow reaches
    ``h(t, x) = 0``, a perturbation ``dx`` before the event reaches the surface ``dt = -h_x dx /
    (h_t + h_x f_in)`` later, at ``x_in + dx + f_in dt``; comparing the two solutions at a common
    time after the event gives

        S = C - (X_t + C f_in - F tau_t) h_x / (h_t + h_x f_in),   C = X_x - F tau_x,

    with ``F`` the sticking field at ``(tau, X)``. For a time-independent map ``tau = t + q``,
    ``X = Q`` this is the slides' chattering saltation ``G = C + (f_out - C f_in) h_x / (h_x
    f_in)``, ``C = Q_x - f_out q_x`` (Nordmark & Piiroinen 2009); for ``tau = t``, ``X = g`` it
    is the impact saltation of :func:`_event_saltation`. ``(tau, X)`` is the map the kernel
    applies, :func:`_chatter_event_map`: ``tau = t + b v``, ``Z = x + c v`` (``v = hdot``,
    ``b``, ``c`` of :func:`_chatter_coef`), ``X`` = Z projected onto ``{h = 0, hdot = 0}`` at
    ``tau`` along ``N = (h_x, hdot_x)``: ``X = Z + N mu``.

    The derivatives are analytic in ``v`` (the entry speed):

        tau_x = b v_x + v b_x,  Z_x = I + c v_x^T + v c_x,  D = d/dt + f_in . d/dx,
        D v = a,  D tau = 1 + a b + v D b,  D Z = f + a c + v D c = (1 + a b) F0 + v D c,

    ``F0`` the sticking field at ``(t, x_in)`` (``f + a c = (1 + a b)(f + a W / (1 + r))``
    identically). The projection's derivative is ``dX = L(dZ, dtau)``: ``(I - G_y) dX - N dmu
    = dZ + G_t dtau``, ``B dX = -Phi_t dtau`` (``B = N^T``, ``Phi = (h, hdot)`` at (tau, X),
    ``G = N mu`` with mu held, ``(I - G_y)^-1 ~ I + G_y``: ``G`` is O(v^2)). Since ``F`` is
    tangent to the manifold, ``L((I - G_y) F - G_t, 1) = F``, so with ``Fs = (I - G_y) F - G_t``

        C = L(Z_x - Fs tau_x^T, 0),
        (X_t + C f_in - F tau_t) / v = L(R / v, 0),
        R / v = -(1 + a b) (F - F0) / v + D c - D b F + D tau (G_y F + G_t) / v,

    so the 1/v of the formula multiplies no difference of O(1) numbers: ``(F - F0) / v`` is the
    divided difference of the sticking field over the jump, taken at the jump's ends or, when
    they are closer than a difference step, as a central difference along the jump about its
    midpoint (step relative to max(1, |t|)^(1/3) in time and max(1, |x_i|) in state); ``b_x, c_x,
    b_t, c_t`` and ``G_y, G_t`` are central differences of first derivatives of the model,
    multiplied by v or by ``mu = O(v^2)``. The result does not lose accuracy as the entry speed
    goes to 0 or as |t| grows (issue "events", item 5: the earlier central difference of the
    whole map divided its error, growing with |t|, by v).
    """
    W = np.zeros(n)
    gx = np.zeros(n * n)
    hdx = np.zeros(n)
    f = np.zeros(n)
    buf = np.zeros(max(n, 2))
    hx = np.zeros(n)
    hx1 = np.zeros(n)
    hd1 = np.zeros(n)
    vx = np.zeros(n)
    fi = np.zeros(n)
    xo = np.zeros(n)
    z = np.zeros(n)
    xt = np.zeros(n)
    cc = np.zeros(n)
    cp = np.zeros(n)
    cm = np.zeros(n)
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    F0 = np.zeros(n)
    F1 = np.zeros(n)
    Fp = np.zeros(n)
    Fm = np.zeros(n)
    bx = np.zeros(n)
    cx = np.zeros((n, n))
    ct = np.zeros(n)
    Gy = np.zeros((n, n))
    Gt = np.zeros(n)
    Rv = np.zeros(n)
    RC = np.zeros((n, n))
    Nt = np.zeros((n, 2))
    tmp = np.zeros(n)
    # input point: v = hdot, its derivatives, the field and the surface gradient
    ev(W_HD, k * nm + mode, t, x_in, p, buf)
    v = buf[0]
    ev(W_HDT, k * nm + mode, t, x_in, p, buf)
    vt = buf[0]
    ev(W_HDX, k * nm + mode, t, x_in, p, vx)
    ev(W_F, mode, t, x_in, p, fi)
    ev(W_HX, k, t, x_in, p, hx)
    a = vt + _dot(vx, fi, n)
    for i in range(n):
        xt[i] = x_in[i]
    b = _chatter_coef(ev, p, j, k, mode, nm, t, xt, n, cc, W, gx, hdx, f, buf)
    # the map as applied: Z = Q(x_in) and X, tau = the projected one
    _chatter_map(ev, p, j, k, mode, nm, t, xt, n, z, W, gx, hdx, f, buf)
    t_out = _chatter_event_map(ev, p, j, k, mode, nm, t, xt, n, xo, W, gx, hdx, f, buf, hx1)
    # derivatives of the coefficients b, c (O(1), multiplied by v below); actual steps
    for col in range(n):
        dx = _FD_STEP * max(1.0, abs(x_in[col]))
        xt[col] = x_in[col] + dx
        hp = xt[col]
        bp = _chatter_coef(ev, p, j, k, mode, nm, t, xt, n, cp, W, gx, hdx, f, buf)
        xt[col] = x_in[col] - dx
        hm = xt[col]
        bm = _chatter_coef(ev, p, j, k, mode, nm, t, xt, n, cm, W, gx, hdx, f, buf)
        xt[col] = x_in[col]
        bx[col] = (bp - bm) / (hp - hm)
        for i in range(n):
            cx[i, col] = (cp[i] - cm[i]) / (hp - hm)
    dt = _FD_STEP * max(1.0, abs(t)) ** (1.0 / 3.0)
    tp = t + dt
    tm = t - dt
    bp = _chatter_coef(ev, p, j, k, mode, nm, tp, xt, n, cp, W, gx, hdx, f, buf)
    bm = _chatter_coef(ev, p, j, k, mode, nm, tm, xt, n, cm, W, gx, hdx, f, buf)
    bt = (bp - bm) / (tp - tm)
    for i in range(n):
        ct[i] = (cp[i] - cm[i]) / (tp - tm)
    Db = bt + _dot(bx, fi, n)
    Dtau = 1.0 + a * b + v * Db
    # sticking fields at both ends of the jump
    _field(ev, p, STICK, j, mode, nm, t_out, xo, n, F1, etab, stab, slide_c, w1, w2, gx, hdx)
    _field(ev, p, STICK, j, mode, nm, t, x_in, n, F0, etab, stab, slide_c, w1, w2, gx, hdx)
    # projection geometry at (tau, X): N = (h_x, hdot_x), X - Z = N mu
    ev(W_HX, k, t_out, xo, p, hx1)
    ev(W_HDX, k * nm + mode, t_out, xo, p, hd1)
    aa = _dot(hx1, hx1, n)
    ab = _dot(hx1, hd1, n)
    bb = _dot(hd1, hd1, n)
    det = aa * bb - ab * ab
    proj = det != 0.0 and np.isfinite(det)
    if proj:
        for i in range(n):
            tmp[i] = xo[i] - z[i]
        r1 = _dot(hx1, tmp, n)
        r2 = _dot(hd1, tmp, n)
        mu0 = (bb * r1 - ab * r2) / det
        mu1 = (aa * r2 - ab * r1) / det
        if mu0 != 0.0 or mu1 != 0.0:
            for col in range(n):
                for i in range(n):
                    xt[i] = xo[i]
                dx = _FD_STEP * max(1.0, abs(xo[col]))
                xt[col] = xo[col] + dx
                hp = xt[col]
                _stick_gradients(ev, p, k, mode, nm, t_out, xt, n, mu0, mu1, cp, hdx)
                xt[col] = xo[col] - dx
                hm = xt[col]
                _stick_gradients(ev, p, k, mode, nm, t_out, xt, n, mu0, mu1, cm, hdx)
                for i in range(n):
                    Gy[i, col] = (cp[i] - cm[i]) / (hp - hm)
            for i in range(n):
                xt[i] = xo[i]
            dt = _FD_STEP * max(1.0, abs(t_out)) ** (1.0 / 3.0)
            tp = t_out + dt
            tm = t_out - dt
            _stick_gradients(ev, p, k, mode, nm, tp, xt, n, mu0, mu1, cp, hdx)
            _stick_gradients(ev, p, k, mode, nm, tm, xt, n, mu0, mu1, cm, hdx)
            for i in range(n):
                Gt[i] = (cp[i] - cm[i]) / (tp - tm)
    # (F - F0) / v over the jump from (t, x_in) to (t_out, xo), direction e = (b, (X - x) / v)
    if v != 0.0:
        et = (t_out - t) / v
        scl = abs(et) / max(1.0, abs(t)) ** (1.0 / 3.0)
        for i in range(n):
            tmp[i] = (xo[i] - x_in[i]) / v
            scl = max(scl, abs(tmp[i]) / max(1.0, abs(x_in[i])))
        smin = _FD_STEP / scl if scl > 0.0 else 0.0
        if scl == 0.0:
            for i in range(n):
                Rv[i] = 0.0
        elif 0.5 * abs(v) >= smin:
            for i in range(n):
                Rv[i] = (F1[i] - F0[i]) / v
        else:
            # central difference along the jump about its midpoint, the time steps as taken
            tmid = t + 0.5 * (t_out - t)
            tp = tmid + smin * et
            tm = tmid - smin * et
            s2 = (tp - tm) / et if et != 0.0 else 2.0 * smin
            for i in range(n):
                xt[i] = 0.5 * (x_in[i] + xo[i]) + 0.5 * s2 * tmp[i]
            _field(ev, p, STICK, j, mode, nm, tp, xt, n, Fp, etab, stab, slide_c, w1, w2, gx,
                   hdx)
            for i in range(n):
                xt[i] = 0.5 * (x_in[i] + xo[i]) - 0.5 * s2 * tmp[i]
            _field(ev, p, STICK, j, mode, nm, tm, xt, n, Fm, etab, stab, slide_c, w1, w2, gx,
                   hdx)
            for i in range(n):
                Rv[i] = (Fp[i] - Fm[i]) / s2
        # R / v = -(1 + a b) (F - F0) / v + D c - D b F + D tau (G_y F + G_t) / v
        for i in range(n):
            gf = Gt[i]
            dc = ct[i]
            for c in range(n):
                gf += Gy[i, c] * F1[c]
                dc += cx[i, c] * fi[c]
            Rv[i] = -(1.0 + a * b) * Rv[i] + dc - Db * F1[i] + Dtau * gf / v
    # C = L(Z_x - Fs tau_x^T, 0), Fs = (I - G_y) F - G_t
    for i in range(n):
        fs = F1[i] - Gt[i]
        for c in range(n):
            fs -= Gy[i, c] * F1[c]
        for c in range(n):
            RC[i, c] = ((1.0 if i == c else 0.0) + cc[i] * vx[c] + v * cx[i, c]
                        - fs * (b * vx[c] + v * bx[c]))
    # L(R, 0): dX = (I + G_y)(R + N dmu) with B dX = 0, B = N^T at (tau, X)
    if proj:
        for i in range(n):
            Nt[i, 0] = hx1[i]
            Nt[i, 1] = hd1[i]
            for c in range(n):
                Nt[i, 0] += Gy[i, c] * hx1[c]
                Nt[i, 1] += Gy[i, c] * hd1[c]
        m00 = _dot(hx1, Nt[:, 0], n)
        m01 = _dot(hx1, Nt[:, 1], n)
        m10 = _dot(hd1, Nt[:, 0], n)
        m11 = _dot(hd1, Nt[:, 1], n)
        dm = m00 * m11 - m01 * m10
        proj = dm != 0.0 and np.isfinite(dm)
    else:
        m00 = m01 = m10 = m11 = dm = 1.0
    for col in range(n + 1):
        # columns of C, then R / v
        for i in range(n):
            w1[i] = RC[i, col] if col < n else Rv[i]
        for i in range(n):
            s = w1[i]
            for c in range(n):
                s += Gy[i, c] * w1[c]
            w2[i] = s
        if proj:
            q0 = _dot(hx1, w2, n)
            q1 = _dot(hd1, w2, n)
            d0 = -(m11 * q0 - m01 * q1) / dm
            d1 = -(m00 * q1 - m10 * q0) / dm
            for i in range(n):
                w2[i] += Nt[i, 0] * d0 + Nt[i, 1] * d1
        if col < n:
            for i in range(n):
                S[i, col] = w2[i]
        else:
            for i in range(n):
                tmp[i] = w2[i]
    if v != 0.0:
        for i in range(n):
            for c in range(n):
                S[i, c] -= tmp[i] * hx[c]


def _chatter_saltation_signature():
    from numba import types as nt

    from ..model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    i2 = nt.int64[:, ::1]
    return nt.void(EVALUATE_TYPE, f1, nt.int64, nt.int64, nt.int64, nt.float64, f1, i2, i2,
                   nt.float64, nt.float64[:, ::1])


@njit(_chatter_saltation_signature(), cache=True)
def chatter_saltation(ev, p, j, mode, nm, t, x, etab, stab, slide_c, S):
    """The saltation matrix :func:`_chatter_saltation` of the complete-chattering map of
    impact event ``j`` entered from mode ``mode`` at ``(t, x)`` into ``S`` (n x n): the matrix
    the kernel applies, for Python callers (:func:`pwsdyn.stability.saltation_matrix`)."""
    _chatter_saltation(ev, p, j, etab[j, 0], mode, nm, t, x, x.shape[0], S, etab, stab, slide_c)


def _state_field_signature():
    from numba import types as nt

    from ..model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    i2 = nt.int64[:, ::1]
    return nt.void(EVALUATE_TYPE, f1, nt.int64, nt.int64, nt.int64, nt.int64, nt.float64, f1, i2,
                   i2, nt.float64, f1)


@njit(_state_field_signature(), cache=True)
def state_field(ev, p, dkind, didx, mode, nm, t, x, etab, stab, slide_c, out):
    """The vector field of a discrete state (``dkind``: REGULAR, STICK, SLIDE; ``didx``; mode)
    at ``(t, x)`` into ``out``: the same function the kernel integrates, for Python callers
    (Poincaré-map projections, shooting, projected saltation matrices)."""
    n = x.shape[0]
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(n * n)
    hdx = np.zeros(n)
    _field(ev, p, dkind, didx, mode, nm, t, x, n, out, etab, stab, slide_c, w1, w2, gx, hdx)


# --------------------------------------------------------------------------------------
# steppers: one step from (t, y) of length h, Runge-Kutta or exact, behind one interface
# --------------------------------------------------------------------------------------
# The Runge-Kutta step itself is written out in the stepping loop of run_kernel (its cost is
# that of a few multiply-adds and field calls, and any call costs a visible fraction of it);
# the exact stepper (inlined by LLVM: ``_hot_inline``), the dense output and the landing step
# are functions with the same arguments. Each is a plain call of a ``_hot`` function with at
# most 30 arguments: longer calls are made by Python as ``f(*args)``, for which numba builds a
# tuple of the arrays (a reference-count update per array: measured 1.7x the cost of an RK45
# step), and numba's inlining assigns each array argument to a new variable (the same
# updates). The work vectors
# of the vector fields travel as one tuple ``wk = (w1, w2, gx, hdx, jac, xt, ft)`` and the
# affine tables as ``aff = (M, sc, wt, z, v)``, both built once per run.

@_hot_inline
def _exact_stepper(ev, p, mode, t, y, h, K, s_fsal, ynew, kst, Q, aff, aff_P, aff_ph, aff_full,
                   nz, T1, T2):
    """One exact step of affine mode ``mode`` (see "Exact propagation" in the module
    docstring), with the outputs of the Runge-Kutta step of run_kernel: the new state into
    ``ynew``, the FSAL stage ``f(t + h, ynew)`` into ``K[s_fsal]``. The error is zero (the
    step is limited only by the convergence of the Taylor sum, the largest step and the
    events). A full step (``h == aff_full``) is one product with the propagator made once per
    mode and length; a shorter one sums the Taylor series of the vector, whose terms are the
    dense output in ``Q``. Returns ``(err, finite, dense_made, nfev)``."""
    aff_M, aff_s, aff_w, zv, zv1 = aff
    n = y.shape[0]   # (exact steps carry no variational equations)
    q_made = False
    if h == aff_full:
        if h != aff_ph[mode]:
            _exact_propagator(aff_M, aff_w, mode, nz, h, aff_P, T1, T2)
            aff_ph[mode] = h
        _exact_apply(aff_M, aff_s, aff_P, mode, nz, n, t, y, zv, ynew)
    else:
        _exact_step(aff_M, aff_s, aff_w, mode, nz, n, t, y, h, zv, zv1, Q, ynew)
        q_made = True
    ev(W_F, mode, t + h, ynew, p, kst)
    finite = True
    for i in range(n):
        K[s_fsal, i] = kst[i]
        if not (np.isfinite(kst[i]) and np.isfinite(ynew[i])):
            finite = False
    return (0.0 if finite else np.inf), finite, q_made, 1


@_hot
def _step_stages(ev, p, exact, dkind, didx, mode, nm, t, y, h, h_full, K, A, C, s_fsal, Q, ytmp,
                 etab, stab, slide_c, wk):
    """Stages 1..s_fsal of the step of length ``h`` from ``(t, y)`` (``K[0] = f(t, y)`` is
    given), its end state into ``ytmp``: the step retaken to an event at ``t + h`` inside the
    accepted step of length ``h_full`` (the landing step: the event state comes from the
    integrator, not from an interpolant), or a step rebuilt from its node. On an exact step the
    dense output ``Q`` of the full step is the exact flow: the landing is its evaluation and
    the FSAL stage ``K[s_fsal]`` its field. Returns the number of function evaluations."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    nY = y.shape[0]
    n = w1.shape[0]
    if exact:
        _dense_eval(y, Q, h / h_full, nY, Q.shape[1], ytmp)
        ev(W_F, mode, t + h, ytmp, p, K[s_fsal])
        return 1
    nvar = 1 if nY > n else 0
    for st in range(1, s_fsal + 1):
        for i in range(nY):
            acc = 0.0
            for m in range(st):
                a = A[st, m]
                if a != 0.0:
                    acc += a * K[m, i]
            ytmp[i] = y[i] + h * acc
        if dkind == REGULAR and nvar == 0:
            ev(W_F, mode, t + C[st] * h, ytmp, p, K[st])
        else:
            _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h, ytmp, n, nvar, K[st], etab, stab,
                 slide_c, w1, w2, gx, hdx, jac, xt, ft)
    return s_fsal


@_hot
def _step_dense(ev, p, exact, dkind, didx, mode, nm, t, y, h, h_full, K, A, C, s_fsal, P, Q, ytmp,
                etab, stab, slide_c, wk, nz, aff):
    """The dense output ``Q`` (power form) of the step of length ``h`` just taken from
    ``(t, y)`` with stages ``K``: for the Runge-Kutta pair the extra stages of the tableau
    (DOP853: 3) and the interpolant's coefficients; for an exact step the Taylor terms of the
    exact flow, made once for the full step (``h == h_full``) and rescaled to a landing step
    inside it (term k by ``(h / h_full)^k``). Made only where it is needed (stored steps,
    samples, event search). Returns the number of function evaluations."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    nY = y.shape[0]
    n = w1.shape[0]
    if exact:
        if h == h_full:
            aff_M, aff_s, aff_w, zv, zv1 = aff
            # (the end state of the series goes to the scratch ytmp: the step's is in ynew)
            _exact_step(aff_M, aff_s, aff_w, mode, nz, n, t, y, h, zv, zv1, Q, ytmp)
        else:
            ratio = h / h_full
            scale = 1.0
            for k in range(Q.shape[1]):
                scale *= ratio
                for i in range(n):
                    Q[i, k] *= scale
        return 0
    nvar = 1 if nY > n else 0
    s_ext = A.shape[0]
    for st in range(s_fsal + 1, s_ext):
        for i in range(nY):
            acc = 0.0
            for m in range(st):
                acc += A[st, m] * K[m, i]
            ytmp[i] = y[i] + h * acc
        _rhs(ev, p, dkind, didx, mode, nm, t + C[st] * h, ytmp, n, nvar, K[st], etab, stab,
             slide_c, w1, w2, gx, hdx, jac, xt, ft)
    _dense_coeffs(K, P, h, nY, s_ext, P.shape[1], Q)
    # columns beyond the method's degree are used by exact steps only
    for k in range(P.shape[1], Q.shape[1]):
        for i in range(nY):
            Q[i, k] = 0.0
    return s_ext - s_fsal - 1


# --------------------------------------------------------------------------------------
# event actions: one function per action, called from the one dispatch in run_kernel
# --------------------------------------------------------------------------------------
# Each takes the state at the event (``t``, ``y``; ``xs`` the copy before it), updates ``y``
# in place and returns the new discrete state ``(dkind, didx, mode)`` and the kind of the log
# record (``K_*``; -1: none). At most 30 arguments each (see the steppers above). The
# saltation matrix of every action is made by :func:`_action_saltation`, called after the
# action where the variational equations are on: the saltation helpers allocate, so they keep
# numba's reference counting, which the actions (like every other per-step or per-event
# helper) are compiled without (with it, measured 5-10% of an event-dominated run).

@_hot
def _act_impact(ev, p, j, dkind, didx, mode, nm, t, y, xs, n, etab, t_end, fopt, chatter_on,
                chain_event, chain_vmax, buf, fbuf, ytmp, wk):
    """Impact on event ``j``: the reset ``g``, or the complete-chattering map where the
    sequence of impacts accumulates (:func:`_act_chatter`), or, where the accumulation point
    lies past ``t_end`` and the bounces are below the velocity floor, the end of the run on
    the chord of the chattering gap. ``chain_event``/``chain_vmax``: the impacts of the
    current sequence and its largest normal speed (the relative chattering threshold).
    Returns ``(dkind, didx, mode, log_kind, t_after, chatter_tail, chain_event, chain_vmax,
    chattered)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    rtol = fopt[FO_RTOL]
    atol = fopt[FO_ATOL]
    chat_rel = fopt[FO_CHAT_REL]
    # a negative ratio is the default one, applied only where the chattering map is accurate
    chat_gated = chat_rel < 0.0
    chat_rel = abs(chat_rel)
    chat_abs = fopt[FO_CHAT_ABS]
    k = etab[j, 0]
    # normal velocity and acceleration at impact, impact direction W, restitution r
    ev(W_HD, k * nm + mode, t, y, p, buf)
    vin = buf[0]
    ev(W_F, mode, t, y, p, fbuf)
    ev(W_HDX, k * nm + mode, t, y, p, hdx)
    ev(W_HDT, k * nm + mode, t, y, p, buf)
    acc = buf[0] + _dot(hdx, fbuf, n)
    hw = _impact_direction(ev, p, j, k, mode, nm, t, y, n, w1, gx, hdx)
    r = -(1.0 + hw)
    if chain_event != j:
        chain_event = j
        chain_vmax = 0.0
    chain_vmax = max(chain_vmax, abs(vin))
    # velocity floor: a bounce of speed v rises v^2 / (2|a|); below the position tolerance it
    # cannot be told from sticking (default when chat_abs < 0)
    vfloor = chat_abs
    if vfloor < 0.0:
        xmax = 0.0
        for i in range(n):
            xmax = max(xmax, abs(y[i]))
        vfloor = np.sqrt(2.0 * abs(acc) * (atol + rtol * xmax))
    do_chatter = (chatter_on == 1 and acc < 0.0 and r >= 0.0 and r < 1.0
                  and (abs(vin) <= vfloor or r == 0.0))
    if (chatter_on == 1 and not do_chatter and acc < 0.0 and 0.0 <= r < 1.0
            and abs(vin) <= chat_rel * chain_vmax and not chat_gated):
        do_chatter = True
    elif (chatter_on == 1 and not do_chatter and acc < 0.0 and 0.0 <= r < 1.0
            and abs(vin) <= chat_rel * chain_vmax):
        # the map takes the normal acceleration as constant over the sequence: jump only
        # where its change over the sequence's duration moves the state by less than the
        # position tolerance, dt^2 |a(t + dt) - a(t)| (a table whose acceleration varies put
        # the accumulation point 3e-6 off when entered at 1e-4 of the first impact's speed;
        # below the floor the bounces are unresolvable anyway)
        dtq = 2.0 * r * vin / ((1.0 - r) * acc)
        for i in range(n):
            xt[i] = y[i] + dtq * fbuf[i]
        acc2 = _free_normal_acc(ev, p, k, mode, nm, t + dtq, xt, n, buf, ft, w2)
        xmax = 0.0
        for i in range(n):
            xmax = max(xmax, abs(y[i]))
        do_chatter = dtq * dtq * abs(acc2 - acc) <= atol + rtol * xmax
    # complete-chattering map (Nordmark & Piiroinen 2009; slides):
    # x_out = x_in + (2 r f_in / a + W) hdot_in / (1 - r),
    # t_out = t_in + 2 r hdot_in / ((1 - r) a)
    dtc = 2.0 * r * vin / ((1.0 - r) * acc) if do_chatter else 0.0
    chatter_tail = False
    if do_chatter and not (t + dtc <= t_end):
        # the accumulation point lies beyond t_end: up to t_end the motion is a finite number
        # of ordinary impacts, so take this one (and the next ones) as an impact and
        # integrate on; jumping would end the run past t_end with the state of a time not
        # asked for
        do_chatter = False
        # ... unless the bounces are below the velocity floor: they rise less than the
        # position tolerance, so the event search cannot resolve them (their crossings drown
        # in the round-off band of the re-trigger guard and the state would fall through the
        # surface). Up to t_end the motion then is the start of the chattering sequence,
        # within the resolution of the run: end at t_end on the chord from x_in to the
        # accumulation state (Q(x_in) projected onto the sticking manifold, as below) that a
        # chattering gap is drawn with (error O(floor) in hdot, O(tolerance) in h)
        chatter_tail = abs(vin) <= vfloor and dtc > 0.0
    log_kind = -1
    t_after = t
    chattered = 0
    if chatter_tail:
        _chatter_jump(ev, p, k, mode, nm, t + dtc, xs, ytmp, n, r, vin, acc, fbuf, w1, hdx, w2,
                      buf)
        th = (t_end - t) / dtc
        for i in range(n):
            y[i] = (1.0 - th) * xs[i] + th * ytmp[i]
    elif do_chatter:
        t_after = t + dtc
        _chatter_jump(ev, p, k, mode, nm, t_after, xs, y, n, r, vin, acc, fbuf, w1, hdx, w2, buf)
        log_kind = K_CHATTER
        dkind = STICK
        didx = j
        chattered = 1
        chain_event = -1
    else:
        # the impact law x+ = g_j(t, x-) (written out: a call per event is measurable)
        ev(W_G, j, t, xs, p, ytmp)
        for i in range(n):
            y[i] = ytmp[i]
        if etab[j, 3] >= 0:
            mode = etab[j, 3]
        log_kind = K_IMPACT
    return dkind, didx, mode, log_kind, t_after, chatter_tail, chain_event, chain_vmax, chattered


@_hot
def _chatter_jump(ev, p, k, mode, nm, t_out, xs, out, n, r, vin, acc, f, W, hdx, w2, buf):
    """The complete-chattering map ``Q(x_in) = x_in + (2 r f_in / a + W) hdot_in / (1 - r)``
    (Nordmark & Piiroinen 2009) into ``out``. Q is first order in hdot; the accumulation point
    lies on the sticking manifold {h = 0, hdot = 0} by definition, so it is projected onto
    it at ``t_out``."""
    for i in range(n):
        out[i] = xs[i] + (2.0 * r * f[i] / acc + W[i]) * vin / (1.0 - r)
    _project_stick(ev, p, k, mode, nm, t_out, out, n, hdx, w2, buf)


@_hot
def _act_transition(ev, p, j, mode, t, y, xs, n, etab, ytmp):
    """Transition on event ``j``: the reset ``x+ = g_j(t, x-)`` into ``y`` (the identity where
    the event has none) and its target mode (unchanged where it has none). Returns the
    mode."""
    ev(W_G, j, t, xs, p, ytmp)
    for i in range(n):
        y[i] = ytmp[i]
    if etab[j, 3] >= 0:
        return etab[j, 3]
    return mode


@_hot
def _after_reset(ev, p, j, log_kind, chatter_tail, dkind, didx, mode, nm, t, y, n, etab, stab,
                 buf, fbuf, wk):
    """After an impact or a transition: the switching variant the new state lies in (a reset
    or a new mode may put the state on the other side of a switching surface, or on one: take
    the variant on the right side, or slide; an event without reset or target while sliding,
    a section or a terminal event, leaves the sliding motion alone); sticking where an impact
    left the normal velocity at round-off while the free motion presses into the surface (a
    plastic impact on an oblique or curved surface, an impact at rest: constrained motion
    along the surface, released where the constraint force vanishes; the impact's saltation
    matrix then maps into the sticking field). Returns ``(dkind, didx, mode,
    contact_stick)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    k = etab[j, 0]
    contact_stick = False
    if (log_kind != K_CHATTER and not chatter_tail and stab.shape[0] > 0
            and (dkind == REGULAR or etab[j, 5] == 1 or etab[j, 3] >= 0)):
        dkind, didx, mode = _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx)
    if (log_kind == K_IMPACT and dkind == REGULAR
            and _stays_in_contact(ev, p, k, mode, nm, t, y, n, buf, fbuf, hdx)):
        contact_stick = True
        dkind = STICK
        didx = j
        _project_stick(ev, p, k, mode, nm, t, y, n, hdx, w2, buf)
    return dkind, didx, mode, contact_stick


@_hot
def _act_release(ev, p, k, mode, nm, t, y, n, stab, buf, wk):
    """Release from sticking on surface ``k``: the flight starts on the sticking manifold
    {h = 0, hdot = 0} (the sticking steps drift off it by their local error, and a drift to
    the far side, deeper than the re-trigger guard's round-off band, would hide a short
    flight's landing), in the switching variant on the side the released motion takes (a
    kink surface held at zero while sticking, e.g. the relative velocity of bilinear damping).
    Returns ``(dkind, didx, mode, log_kind)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    _project_stick(ev, p, k, mode, nm, t, y, n, hdx, w2, buf)
    dkind = REGULAR
    didx = -1
    if stab.shape[0] > 0:
        dkind, didx, mode = _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx)
    return dkind, didx, mode, K_RELEASE


@_hot
def _act_switch(ev, p, s, old_kind, old_idx, old_mode, nm, t, y, n, stab, buf, hdx):
    """Arrival at switching surface ``s``: sliding starts where both fields point into the
    surface (h_t + h_x f_above < 0 < h_t + h_x f_below), otherwise the flow crosses (thesis
    eq. 2.6-2.8); kink surfaces (SW_CONTINUOUS) always cross. Arriving with the own field
    tangent (hdot = 0) while the other one points back is a graze: no event. Returns
    ``(dkind, didx, mode, log_kind, graze)``."""
    k = stab[s, 0]
    a_m = stab[s, 1]
    b_m = stab[s, 2]
    ev(W_HD, k * nm + a_m, t, y, p, buf)
    sa = buf[0]
    ev(W_HD, k * nm + b_m, t, y, p, buf)
    sb = buf[0]
    filippov = stab.shape[1] <= 3 or stab[s, 3] == SW_FILIPPOV
    graze = filippov and ((old_mode == a_m and sa >= 0.0 and sb > 0.0)
                          or (old_mode == b_m and sb <= 0.0 and sa < 0.0))
    if graze:
        return old_kind, old_idx, old_mode, -1, True
    dkind = old_kind
    didx = old_idx
    if filippov and sa < 0.0 and sb > 0.0:
        dkind = SLIDE
        didx = s
        mode = a_m
        log_kind = K_SLIDE_START
        _project_surface(ev, p, k, t, y, n, hdx, buf)
    else:
        log_kind = K_CROSSING
        mode = b_m if old_mode == a_m else a_m
    return dkind, didx, mode, log_kind, False


@_hot
def _act_slide_exit(s, above, stab):
    """End of sliding on switch ``s`` into the mode above (``alpha -> 0``) or below
    (``alpha -> 1``). Returns ``(dkind, didx, mode, log_kind)``."""
    return REGULAR, -1, (stab[s, 1] if above else stab[s, 2]), K_SLIDE_END


@_hot
def _act_intersection(ev, p, k2, new_sign, log_ref, old_kind, old_idx, old_mode, nm, t, y, n,
                      etab, stab, slide_c, buf, fbuf, wk):
    """Sliding on switch ``old_idx`` reached surface ``k2`` of another switch. Across ``k2``
    the sliding pair (a, b) becomes (a2, b2): if the flow slides on the first surface there
    too and its sliding field carries the state away from k2, it crosses k2 while sliding; if
    both pairs leave the first surface to one side, the sliding ends; if the sliding field on
    the far side points back into k2 the motion would slide on the intersection of the two
    surfaces, which is not supported (``ST_INTERSECTION``). Returns ``(status, dkind, didx,
    mode, log_kind, log_ref)``."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    dkind = old_kind
    didx = old_idx
    mode = old_mode
    log_kind = -1
    k1 = stab[old_idx, 0]
    a2 = _partner(stab, k2, stab[old_idx, 1])
    b2 = _partner(stab, k2, stab[old_idx, 2])
    s_new = _find_switch(stab, k1, a2, b2) if a2 >= 0 and b2 >= 0 else -1
    if s_new >= 0:
        ev(W_HD, k1 * nm + a2, t, y, p, buf)
        sa = buf[0]
        ev(W_HD, k1 * nm + b2, t, y, p, buf)
        sb = buf[0]
        if sa < 0.0 and sb > 0.0:
            _field(ev, p, SLIDE, s_new, a2, nm, t, y, n, fbuf, etab, stab, slide_c, w1, w2, gx,
                   hdx)
            rate = _surface_rate(ev, p, SLIDE, k2, a2, nm, t, y, fbuf, n, buf, hdx)
            if rate * new_sign > 0.0:
                dkind = SLIDE
                didx = s_new
                mode = a2
                log_kind = K_CROSSING
        elif sa >= 0.0 and sb > 0.0:
            dkind = REGULAR
            didx = -1
            mode = a2
            log_kind = K_SLIDE_END
            log_ref = old_idx
        elif sa < 0.0 and sb <= 0.0:
            dkind = REGULAR
            didx = -1
            mode = b2
            log_kind = K_SLIDE_END
            log_ref = old_idx
    if log_kind < 0:
        return ST_INTERSECTION, dkind, didx, mode, log_kind, log_ref
    return ST_SUCCESS, dkind, didx, mode, log_kind, log_ref


@njit(cache=True)
def _action_saltation(ev, p, act, log_kind, chatter_tail, ref, k, old_kind, old_idx, old_mode,
                      dkind, didx, mode, nm, t, xs, y, n, S, etab, stab, slide_c, buf, fbuf,
                      ytmp, wk):
    """The saltation matrix ``S`` of the action just taken (slides, "Saltation matrices";
    Adolfsson et al. 2001): of the reset or transition (:func:`_event_saltation`), of the
    complete-chattering map (:func:`_chatter_saltation`), of a Filippov crossing or sliding
    entry on surface ``k`` (:func:`_switch_saltation`); release and sliding exit leave the
    field continuous (``S = I``). ``ref``: the event or switch index of the action; ``xs``
    the state before it, ``y`` after it."""
    w1, w2, gx, hdx, jac, xt, ft = wk
    if act == ACT_EVENT:
        if log_kind == K_CHATTER:
            _chatter_saltation(ev, p, ref, k, old_mode, nm, t, xs, n, S, etab, stab, slide_c)
        elif not chatter_tail:
            _event_saltation(ev, p, ref, k, old_mode, mode, nm, t, xs, y, n, S, gx, hdx, buf, fbuf,
                             w1, w2, etab, stab, slide_c, old_kind, old_idx, ytmp, dkind, didx)
    elif act == ACT_SWITCH or act == ACT_INTERSECTION:
        _switch_saltation(ev, p, dkind, didx, old_mode, mode, nm, k, t, y, n, S, hdx, buf, fbuf,
                          w1, w2, gx, etab, stab, slide_c, old_kind, old_idx)
    else:
        _identity(S, n)


@_hot
def _identity(S, n):
    for i in range(n):
        for c in range(n):
            S[i, c] = 1.0 if i == c else 0.0


@_hot
def _apply_saltation(y, S, Phi, n, seg_var):
    """The variational part of ``y`` after an event: ``Phi+ = S Phi-`` (slides, "Saltation
    matrices"); per segment the record keeps ``S`` (the segment's ``Phi`` is in x_before)."""
    if seg_var:
        for i in range(n):
            for c in range(n):
                y[n + i * n + c] = S[i, c]
        return
    for i in range(n):
        for c in range(n):
            Phi[i, c] = y[n + i * n + c]
    for i in range(n):
        for c in range(n):
            acc = 0.0
            for m in range(n):
                acc += S[i, m] * Phi[m, c]
            y[n + i * n + c] = acc


# --------------------------------------------------------------------------------------
# dense output on demand
# --------------------------------------------------------------------------------------

def _dense_coefficients(ev, p, etab, stab, iopt, fopt, A, C, P, s_fsal, t0, x0, nodes_t,
                        nodes_y, nodes_s, hstep, which, deg):
    """Power-form dense output (as stored with ``SAVE_DENSE``) of the step intervals
    ``which`` of a run made with ``SAVE_NODES``, rebuilt from their start nodes: the step from
    ``(nodes_t[i], nodes_y[i])`` of length ``hstep[i]`` in the discrete state ``nodes_s[i]``
    is taken again -- the Runge-Kutta stages and the dense-output stages, or the Taylor terms
    of the exact flow -- with the run's options (``iopt``, ``fopt``, the tableau). The
    stages are computed as in the kernel from the same numbers, so the coefficients are the
    ones it would have stored (to rounding: after a projected sliding step the kernel's first
    stage is the field before the projection). Rows of intervals with ``hstep <= 0`` (jumps,
    chattering gaps) are zero. Not for variational runs, whose nodes are transformed after
    the run (they store their dense output: ``SAVE_DENSE``)."""
    n = x0.shape[0]
    nm = iopt[IO_NMODES]
    nvar = 1 if iopt[IO_VAR] != VAR_NONE else 0
    nY = nodes_y.shape[1]
    slide_c = fopt[FO_SLIDE_C]
    nz, aff_ok, aff_M, aff_h, aff_s, aff_w = _affine_setup(
        ev, t0, x0, p, n, nm, iopt.shape[0] > IO_EXACT and iopt[IO_EXACT] != 0)
    s_ext = A.shape[0]
    K = np.zeros((s_ext, nY))
    ytmp = np.zeros(nY)
    y = np.zeros(nY)
    Q = np.zeros((nY, max(deg, P.shape[1], _EXACT_TERMS if nz > 0 else 1)))
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(n * n)
    hdx = np.zeros(n)
    jac = np.zeros(n * n)
    xt = np.zeros(n)
    ft = np.zeros(n)
    zv = np.zeros(max(nz, 1))
    zv1 = np.zeros(max(nz, 1))
    out = np.zeros((which.shape[0], nY, deg))
    wk = (w1, w2, gx, hdx, jac, xt, ft)
    aff = (aff_M, aff_s, aff_w, zv, zv1)
    for r in range(which.shape[0]):
        i = which[r]
        h = hstep[i]
        if not h > 0.0:
            continue
        dkind = nodes_s[i, 0]
        didx = nodes_s[i, 1]
        mode = nodes_s[i, 2]
        t = nodes_t[i]
        for c in range(nY):
            y[c] = nodes_y[i, c]
        exact = nz > 0 and dkind == REGULAR and nvar == 0 and aff_ok[mode] == 1
        if not exact:
            _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, K[0], etab, stab, slide_c,
                 w1, w2, gx, hdx, jac, xt, ft)
            _step_stages(ev, p, exact, dkind, didx, mode, nm, t, y, h, h, K, A, C, s_fsal, Q, ytmp,
                         etab, stab, slide_c, wk)
        _step_dense(ev, p, exact, dkind, didx, mode, nm, t, y, h, h, K, A, C, s_fsal, P, Q, ytmp,
                    etab, stab, slide_c, wk, nz, aff)
        for c in range(nY):
            for k in range(deg):
                out[r, c, k] = Q[c, k]
    return out


def _dense_coefficients_signature():
    from numba import types as nt

    from ..model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    f2 = nt.float64[:, ::1]
    i1 = nt.int64[::1]
    i2 = nt.int64[:, ::1]
    return nt.float64[:, :, ::1](EVALUATE_TYPE, f1, i2, i2, i1, f1, f2, f1, f2, nt.int64,
                                 nt.float64, f1, f1, f2, i2, f1, i1, nt.int64)


_DENSE_COEFFICIENTS = None


def dense_coefficients(*args):
    """:func:`_dense_coefficients`, compiled on first use (then loaded from numba's cache):
    runs that never evaluate their dense output do not wait for it."""
    global _DENSE_COEFFICIENTS
    if _DENSE_COEFFICIENTS is None:
        import warnings

        from numba.core.errors import NumbaExperimentalFeatureWarning
        with warnings.catch_warnings():
            # the first-class function type of the model's `evaluate` (as in the kernel)
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            _DENSE_COEFFICIENTS = njit(_dense_coefficients_signature(), cache=True,
                                       nogil=True)(_dense_coefficients)
    return _DENSE_COEFFICIENTS(*args)


# --------------------------------------------------------------------------------------
# the kernel
# --------------------------------------------------------------------------------------

def _kernel_signature():
    from numba import types as nt

    from ..model.codegen import EVALUATE_TYPE
    f1 = nt.float64[::1]
    f2 = nt.float64[:, ::1]
    i1 = nt.int64[::1]
    i2 = nt.int64[:, ::1]
    ret = nt.Tuple((nt.int64, nt.float64, f1, i1, f1, f2, i2, nt.float64[:, :, ::1], i1, f1, f1,
                    i2, f2, f2, i1, f2, f1))
    return ret(EVALUATE_TYPE, nt.float64, nt.float64, f1, f1, i2, i2, i2, i1, f1, f2, f1, f2, f2,
               nt.int64)


# nogil: a run holds no Python object, so a Dask worker's event loop (heartbeats, transfers)
# and other threads go on while it integrates
@njit(_kernel_signature(), cache=True, nogil=True)
def run_kernel(ev, t0, t_end, x0, p, etab, eactive, stab, iopt, fopt, A, C, E, P, s_fsal):
    """Integrate from ``t0`` to ``t_end``. See the module docstring.

    Tables
    ------
    etab : (n_events, 6 or 7) int64 -- surface, direction, kind, target, terminal, has_reset,
        and optionally whether the surface depends on t explicitly
    eactive : (n_events, n_modes) int8
    stab : (n_switches, 3 to 6) int64 -- surface, above, below, and optionally the kind
        (SW_FILIPPOV / SW_CONTINUOUS), the sliding method (SLIDE_CONVEX / SLIDE_UTKIN) and
        whether the surface depends on t explicitly
    iopt, fopt : options, indexed by the IO_* / FO_* constants

    Returns
    -------
    status, t, y, final discrete state, nodes_t, nodes_y, nodes_state (kind, idx, mode), dense
    (per interval; ``SAVE_DENSE`` only, else no rows), interval kind (0 step, 1 jump, 2
    chatter gap), event log (t, t_after, info, x_before, x_after), stats, samples, and the
    length of the step of each interval (0 for jumps; with ``SAVE_NODES`` the dense output is
    rebuilt from it, :func:`dense_coefficients`)
    """
    n = x0.shape[0]
    nm = iopt[IO_NMODES]
    nvar = 1 if iopt[IO_VAR] != VAR_NONE else 0
    seg_var = iopt[IO_VAR] == VAR_SEGMENTS
    stop_mask = 0
    stop_ref = -1
    stop_count = 0
    if iopt.shape[0] > IO_STOP_COUNT:
        stop_mask = iopt[IO_STOP_MASK]
        stop_ref = iopt[IO_STOP_REF]
        stop_count = iopt[IO_STOP_COUNT]
    n_stop = 0
    nY = n + nvar * n * n
    method = iopt[IO_METHOD]
    max_steps = iopt[IO_MAXSTEPS]
    max_events = iopt[IO_MAXEVENTS]
    chatter_on = iopt[IO_CHATTER]
    save_all = iopt[IO_SAVE] != SAVE_EVENTS
    store_q = iopt[IO_SAVE] == SAVE_DENSE
    rtol = fopt[FO_RTOL]
    atol = fopt[FO_ATOL]
    hmax = fopt[FO_HMAX]
    slide_c = fopt[FO_SLIDE_C]
    s_ext = A.shape[0]
    deg = P.shape[1]
    n_events = etab.shape[0]
    # exact propagation of affine modes: their augmented matrices, balancing weights and the
    # largest step (see _affine_setup)
    nz, aff_ok, aff_M, aff_h, aff_s, aff_w = _affine_setup(
        ev, t0, x0, p, n, nm, iopt.shape[0] > IO_EXACT and iopt[IO_EXACT] != 0)
    if nz > 0:
        deg = max(deg, _EXACT_TERMS)
    zv = np.zeros(max(nz, 1))
    zv1 = np.zeros(max(nz, 1))
    # propagator exp(h M) per mode for the step length aff_ph (most steps have the same one)
    aff_P = np.zeros((nm, max(nz, 1), max(nz, 1)))
    aff_ph = np.full(nm, -1.0)
    T1 = np.zeros((max(nz, 1), max(nz, 1)))
    T2 = np.zeros((max(nz, 1), max(nz, 1)))
    n_sw = stab.shape[0]
    # the order of the propagated solution: the exponent of the step-size control (Hairer,
    # Norsett & Wanner I, II.4)
    order = 5.0 if method == 0 else 8.0
    if iopt.shape[0] > IO_ORDER and iopt[IO_ORDER] > 0:
        order = float(iopt[IO_ORDER])

    # work arrays
    K = np.zeros((s_ext, nY))
    kst = np.zeros(nY)
    ytmp = np.zeros(nY)
    ynew = np.zeros(nY)
    y = np.zeros(nY)
    Q = np.zeros((nY, deg))
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    gx = np.zeros(n * n)
    hdx = np.zeros(n)
    jac = np.zeros(n * n)
    xt = np.zeros(n)
    ft = np.zeros(n)
    buf = np.zeros(max(n, 2))
    fbuf = np.zeros(n)
    xs = np.zeros(nY)
    Kland = np.zeros((s_ext, nY))
    S = np.zeros((n, n))
    Phi = np.zeros((n, n))
    # the vector fields' work vectors and the affine tables, passed as one argument each
    wk = (w1, w2, gx, hdx, jac, xt, ft)
    aff = (aff_M, aff_s, aff_w, zv, zv1)

    # outputs
    cap = 256
    nodes_t = np.empty(cap)
    nodes_y = np.empty((cap, nY))
    nodes_s = np.empty((cap, 3), dtype=np.int64)
    # power-form dense output per interval (SAVE_DENSE only) and the length of each step
    dense = np.empty((cap if store_q else 0, nY, deg))
    hstep = np.empty(cap)
    ikind = np.empty(cap, dtype=np.int64)
    ecap = 16
    ev_t = np.empty(ecap)
    ev_t2 = np.empty(ecap)
    # columns: kind, ref, kind/idx/mode before, kind/idx/mode after, index of the post-event node
    ev_info = np.empty((ecap, 9), dtype=np.int64)
    ev_xb = np.empty((ecap, nY))
    ev_xa = np.empty((ecap, nY))
    rec = np.zeros(9, dtype=np.int64)   # one event record's integer columns
    stats = np.zeros(6, dtype=np.int64)  # steps, rejected, nfev, events, chatter, landing steps
    n_nodes = 0
    n_ev = 0

    # state
    t = t0
    for i in range(n):
        y[i] = x0[i]
    if nvar:
        for i in range(n):
            for c in range(n):
                y[n + i * n + c] = 1.0 if i == c else 0.0
    dkind = REGULAR
    didx = -1
    mode = iopt[IO_MODE0]
    if iopt.shape[0] > IO_DIDX0:
        dkind = iopt[IO_DKIND0]
        didx = iopt[IO_DIDX0]
    status = ST_SUCCESS
    # Non-finite input ends the run at once, before any work: a NaN compares false with
    # everything, so a NaN time or step size would never reach t_end nor fall below the
    # smallest step, and the stepping loop would spin (rejected steps do not count against
    # max_steps). Infinite ones are refused too: t_end = inf never ends, and x0 or
    # first_step = inf make the first step NaN. max_step = inf is fine (no limit).
    h0 = fopt[FO_H0]
    if not (np.isfinite(t0) and np.isfinite(t_end) and np.isfinite(h0) and not np.isnan(hmax)
            and np.isfinite(rtol) and np.isfinite(atol)):
        status = ST_NONFINITE
    for i in range(n):
        if not np.isfinite(x0[i]):
            status = ST_NONFINITE
    if fopt.shape[0] > FO_SAMPLE_DT:
        # sampling: off for dt <= 0; a NaN or infinite dt (a NaN forcing period or phase of a
        # sweep) or a non-finite first sample time is non-finite input
        sdt_in = fopt[FO_SAMPLE_DT]
        if np.isnan(sdt_in) or (sdt_in > 0.0 and not (np.isfinite(sdt_in)
                                                       and np.isfinite(fopt[FO_SAMPLE_T0]))):
            status = ST_NONFINITE
    if status == ST_SUCCESS and dkind == REGULAR and n_sw > 0:
        # the mode on the right side of every switching surface; sliding from a start on one
        dkind, didx, mode = _resolve(ev, p, t, y, n, nm, mode, stab, buf, hdx)

    # watch list. Sized from the model's tables, never a fixed capacity: in any discrete
    # state an event or a switch is watched at most once (the loops below add one entry per
    # event or switch at most), plus the release (sticking) or the two exits (sliding); the
    # _MAXW spare entries leave room for more functions per state
    wcap = n_events + n_sw + _MAXW
    wtype = np.zeros(wcap, dtype=np.int64)
    widx = np.zeros(wcap, dtype=np.int64)
    wmode = np.zeros(wcap, dtype=np.int64)
    wdir = np.zeros(wcap, dtype=np.int64)
    wact = np.zeros(wcap, dtype=np.int64)
    wref = np.zeros(wcap, dtype=np.int64)
    wforce = np.zeros(wcap)      # forced sign at the start of the next step (re-trigger guard)
    wv = np.zeros(wcap)          # watch values at the end of the last accepted step ...
    wd = np.zeros(wcap)          # ... and their time derivatives (surfaces), reused next step
    wvalid = np.zeros(wcap, dtype=np.int64)
    wtdep = np.zeros(wcap, dtype=np.int64)  # surface depends on t explicitly (moving wall)
    nw = 0
    # the surface/function that just fired, to suppress an immediate re-trigger
    last_type = -1
    last_idx = -1
    last_mode = -1
    last_sign = 0.0
    last_t = np.nan
    # events at one instant: the guards of functions that fired earlier at last_t (kept with
    # the last one's), and crossings that coincide with the event being handled (found
    # between the bracketed and the polished event time) still to fire at pend_t
    co_type = np.zeros(wcap, dtype=np.int64)
    co_idx = np.zeros(wcap, dtype=np.int64)
    co_mode = np.zeros(wcap, dtype=np.int64)
    co_sign = np.zeros(wcap)
    co_t = np.zeros(wcap)
    n_co = 0
    pend_type = np.zeros(wcap, dtype=np.int64)
    pend_idx = np.zeros(wcap, dtype=np.int64)
    pend_mode = np.zeros(wcap, dtype=np.int64)
    pend_act = np.zeros(wcap, dtype=np.int64)
    pend_ref = np.zeros(wcap, dtype=np.int64)
    n_pend = 0
    pend_t = np.nan
    wpend = np.zeros(wcap, dtype=np.int64)
    # chattering chain bookkeeping
    chain_event = -1
    chain_vmax = 0.0
    zeno = 0
    last_depth = 0.0

    noise = 0.0
    vals = np.zeros((wcap, 8))
    thetas = np.zeros(8)
    rates = np.zeros(8)           # time derivatives of a watch function at the samples
    ex_th = np.zeros(8)           # samples of the release watch's extremum search
    ex_g = np.zeros(8)

    # first node
    nodes_t[0] = t
    nodes_y[0, :] = y
    nodes_s[0, 0] = dkind
    nodes_s[0, 1] = didx
    nodes_s[0, 2] = mode
    n_nodes = 1

    # stroboscopic sampling on the dense output (no event, no landing step)
    n_samp = 0
    n_need = 0
    s0 = 0.0
    sdt = 0.0
    sk = 0
    # the samples are bounded by the step budget (each costs about what a stored step does):
    # a run that would record more than max_steps of them ends at once with ST_MAX_STEPS
    # instead of looping ~(t_end - t0) / dt times (dt = 1e-300); max_samp caps the sampling
    # loops as a backstop (one more for the rounding of the count)
    max_samp = max_steps + 2
    if status == ST_SUCCESS and fopt.shape[0] > FO_SAMPLE_DT and fopt[FO_SAMPLE_DT] > 0.0:
        s0 = fopt[FO_SAMPLE_T0]
        sdt = fopt[FO_SAMPLE_DT]
        kf = max(0.0, np.ceil((t - s0) / sdt))
        # index of the first sample; beyond 2^53 (an s0 that far before t0) neither it nor
        # s0 + k sdt is exact, and int() of it would overflow
        if kf > 2.0 ** 53 or (t_end - s0) / sdt - kf + 1.0 > max_steps:
            status = ST_MAX_STEPS
            sdt = 0.0
        sk = int(kf) if status == ST_SUCCESS else 0
        if sdt > 0.0:
            # room for every sample (at most max_steps + 2, checked above): the array is not
            # grown inside the stepping loop (see the outer loop below)
            n_need = int(max(0.0, min((t_end - s0) / sdt - kf, float(max_steps)))) + 3
    samp = np.empty((max(n_need, 1), 1 + n))
    max_samp = min(max_samp, samp.shape[0])
    if sdt > 0.0:
        if s0 + sk * sdt == t:
            samp[0, 0] = t
            for i in range(n):
                samp[0, 1 + i] = y[i]
            n_samp = 1
            sk += 1

    restart = True
    h = h0
    # Every iteration of this loop either accepts a step (counted in stats[0], bounded by
    # max_steps; event handling, also without an event, follows an accepted step) or rejects
    # one (error, non-finite stage, unresolved moving surface). A rejection shrinks h by a
    # factor <= 0.9, a step grows it by <= 10, and h below 4 ulp(t) ends the run, so the
    # rejections are bounded too -- provided t and h stay finite, which the checks at each
    # restart (t, y, field) and before each step (h) guarantee.
    # The stepping loop never reassigns an array: numba keeps a reassigned array in a phi
    # variable and updates its reference count (two atomic operations) at every pass of the
    # loop, ~15% of a step for the seven output arrays. Room for the next iteration's nodes
    # (at most two) and event records (at most two) is made here, in an outer loop that the
    # stepping loop leaves only to grow them.
    finished = False
    while not finished:
        if n_nodes + 4 > nodes_t.shape[0]:
            need = 2 * nodes_t.shape[0] + 4
            nodes_t = _grow1(nodes_t, need)
            nodes_y = _grow2(nodes_y, need)
            nodes_s = _grow2(nodes_s, need)
            ikind = _grow1(ikind, need)
            hstep = _grow1(hstep, need)
            if store_q:
                dense = _grow3(dense, need)
        if n_ev + 4 > ev_t.shape[0]:
            need = 2 * ev_t.shape[0] + 4
            ev_t = _grow1(ev_t, need)
            ev_t2 = _grow1(ev_t2, need)
            ev_info = _grow2(ev_info, need)
            ev_xb = _grow2(ev_xb, need)
            ev_xa = _grow2(ev_xa, need)
        finished = True
        while True:
            if n_nodes + 4 > nodes_t.shape[0] or n_ev + 4 > ev_t.shape[0]:
                finished = False
                break
            if restart:
                if status != ST_SUCCESS:
                    # refused input (above); tested here, not in the loop condition, which
                    # measured ~40% slower on every step
                    break
                # (re)build the watch list for the current discrete state
                nw = 0
                for j in range(n_events):
                    if eactive[j, mode] == 0:
                        continue
                    if dkind == STICK and etab[j, 0] == etab[didx, 0]:
                        continue
                    if dkind == SLIDE:
                        continue
                    wtype[nw] = WF_SURFACE; widx[nw] = etab[j, 0]; wmode[nw] = mode
                    wdir[nw] = etab[j, 1]; wact[nw] = ACT_EVENT; wref[nw] = j
                    nw += 1
                for s in range(n_sw):
                    if dkind == SLIDE:
                        # another surface bounding the sliding pair's modes: crossing it while
                        # sliding, or reaching the intersection of the two surfaces
                        if stab[s, 0] == stab[didx, 0]:
                            continue
                        if (stab[s, 1] != stab[didx, 1] and stab[s, 2] != stab[didx, 1]
                                and stab[s, 1] != stab[didx, 2] and stab[s, 2] != stab[didx, 2]):
                            continue
                        dup = False
                        for ww in range(nw):
                            if wact[ww] == ACT_INTERSECTION and widx[ww] == stab[s, 0]:
                                dup = True
                        if dup:
                            continue
                        wtype[nw] = WF_SURFACE; widx[nw] = stab[s, 0]; wmode[nw] = mode
                        wdir[nw] = 0; wact[nw] = ACT_INTERSECTION; wref[nw] = s
                        nw += 1
                        continue
                    if stab[s, 1] == mode or stab[s, 2] == mode:
                        if (dkind == STICK and stab.shape[1] > 3 and stab[s, 3] == SW_CONTINUOUS):
                            # a kink surface that the sticking motion lies in (bilinear damping of
                            # a relative velocity held at zero against a stop): the two variants
                            # agree there, and its sign is round-off
                            ev(W_H, stab[s, 0], t, y, p, buf)
                            xmax = 1.0
                            for i in range(n):
                                xmax = max(xmax, abs(y[i]))
                            if abs(buf[0]) <= 1e3 * _EPS * xmax:
                                continue
                        wtype[nw] = WF_SURFACE; widx[nw] = stab[s, 0]; wmode[nw] = mode
                        wdir[nw] = -1 if stab[s, 1] == mode else 1
                        wact[nw] = ACT_SWITCH; wref[nw] = s
                        nw += 1
                if dkind == STICK:
                    k = etab[didx, 0]
                    wtype[nw] = WF_HDDOT; widx[nw] = k; wmode[nw] = mode
                    wdir[nw] = 1; wact[nw] = ACT_RELEASE; wref[nw] = didx
                    nw += 1
                if dkind == SLIDE:
                    k = stab[didx, 0]
                    # leave above when hdot of the above field turns positive (alpha -> 0),
                    # below when hdot of the below field turns negative (alpha -> 1)
                    wtype[nw] = WF_HDOT; widx[nw] = k; wmode[nw] = stab[didx, 1]
                    wdir[nw] = 1; wact[nw] = ACT_EXIT_ABOVE; wref[nw] = didx
                    nw += 1
                    wtype[nw] = WF_HDOT; widx[nw] = k; wmode[nw] = stab[didx, 2]
                    wdir[nw] = -1; wact[nw] = ACT_EXIT_BELOW; wref[nw] = didx
                    nw += 1
                    for j in range(n_events):
                        if eactive[j, stab[didx, 1]] == 0 and eactive[j, stab[didx, 2]] == 0:
                            continue
                        wtype[nw] = WF_SURFACE; widx[nw] = etab[j, 0]; wmode[nw] = mode
                        wdir[nw] = etab[j, 1]; wact[nw] = ACT_EVENT; wref[nw] = j
                        nw += 1
                for w in range(nw):
                    wvalid[w] = 0
                    wtdep[w] = 0
                    if wtype[w] == WF_SURFACE:
                        if wact[w] == ACT_EVENT and etab.shape[1] > 6:
                            wtdep[w] = etab[wref[w], 6]
                        elif wact[w] != ACT_EVENT and stab.shape[1] > 5:
                            wtdep[w] = stab[wref[w], 5]
                    wforce[w] = 0.0
                    if (t == last_t and wtype[w] == last_type and widx[w] == last_idx
                            and (wtype[w] == WF_SURFACE or wmode[w] == last_mode)):
                        wforce[w] = last_sign
                    else:
                        for c in range(n_co):
                            if (wtype[w] == co_type[c] and widx[w] == co_idx[c]
                                    and (wtype[w] == WF_SURFACE or wmode[w] == co_mode[c])
                                    and abs(t - co_t[c]) <= _COINCIDENT_ULPS * _ulp(t)):
                                wforce[w] = co_sign[c]
                    wpend[w] = 0
                    if t == pend_t and wforce[w] == 0.0:
                        for c in range(n_pend):
                            if (pend_type[c] == wtype[w] and pend_idx[c] == widx[w]
                                    and pend_mode[c] == wmode[w] and pend_act[c] == wact[w]
                                    and pend_ref[c] == wref[w]):
                                wpend[w] = 1
                _rhs(ev, p, dkind, didx, mode, nm, t, y, n, nvar, kst, etab, stab, slide_c,
                     w1, w2, gx, hdx, jac, xt, ft)
                for i in range(nY):
                    K[0, i] = kst[i]
                stats[2] += 1
                # at the start and after every event (a reset, a chattering jump in time, a new
                # mode): time, state and field must be finite. A NaN field here would make the
                # first step size NaN (a step then neither accepted nor rejected for good).
                ok = np.isfinite(t)
                for i in range(nY):
                    if not (np.isfinite(y[i]) and np.isfinite(K[0, i])):
                        ok = False
                if not ok:
                    status = ST_NONFINITE
                    break
                if h <= 0.0:
                    # initial step (Hairer, Norsett & Wanner I, II.4): from the scales of y and f
                    d0 = 0.0
                    d1 = 0.0
                    for i in range(n):
                        sc = atol + rtol * abs(y[i])
                        d0 += (y[i] / sc) ** 2
                        d1 += (K[0, i] / sc) ** 2
                    d0 = np.sqrt(d0 / n)
                    d1 = np.sqrt(d1 / n)
                    h = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
                    h = min(h, abs(t_end - t))
                restart = False

            if t >= t_end:
                break
            if stats[0] >= max_steps:
                status = ST_MAX_STEPS
                break
            if not np.isfinite(h):
                # NaN from the error control (an error norm 0/0) or the initial-step estimate;
                # compared with anything it is false, so it must not reach the clipping below
                status = ST_NONFINITE
                break
            exact_now = nz > 0 and dkind == REGULAR and nvar == 0 and aff_ok[mode] == 1
            if exact_now:
                h = min(h, aff_h[mode])
            h = min(h, hmax, t_end - t)
            if h < 4.0 * _ulp(t):
                if t_end - t <= 4.0 * _ulp(t):
                    t = t_end
                    break
                status = ST_STEP_TOO_SMALL
                break

            # ---- one step: the exact flow of an affine mode or the Runge-Kutta pair
            if exact_now:
                err, finite, q_made, nf = _exact_stepper(ev, p, mode, t, y, h, K, s_fsal, ynew,
                        kst, Q, aff, aff_P, aff_ph, min(aff_h[mode], hmax), nz, T1, T2)
            else:
                # the Runge-Kutta step, written out here (the stepper with the interface of
                # _exact_stepper): as a call it passes ~20 arrays per step, measured 10-15% of
                # an RK45 step on a two-state model
                q_made = False
                nf = s_fsal
                fast = dkind == REGULAR and nvar == 0
                for st in range(1, s_fsal + 1):
                    cst = t + C[st] * h
                    for i in range(nY):
                        acc = 0.0
                        for m in range(st):
                            acc += A[st, m] * K[m, i]
                        ytmp[i] = y[i] + h * acc
                    # into a scratch vector: passing the row K[st] makes an array view, whose
                    # reference counting (two atomic updates) measured 30% of a step
                    if fast:
                        ev(W_F, mode, cst, ytmp, p, kst)
                    else:
                        _rhs(ev, p, dkind, didx, mode, nm, cst, ytmp, n, nvar, kst, etab, stab,
                             slide_c, w1, w2, gx, hdx, jac, xt, ft)
                    for i in range(nY):
                        K[st, i] = kst[i]
                # the FSAL stage was evaluated at y + h sum B K = the new solution
                finite = True
                for i in range(nY):
                    ynew[i] = ytmp[i]
                    if not (np.isfinite(K[s_fsal, i]) and np.isfinite(ynew[i])):
                        finite = False
                err = (_error_norm(K, E, method, s_fsal, y, ynew, h, 0, n, rtol, atol) if finite
                       else np.inf)
                if nvar and finite:
                    err = max(err, _error_norm(K, E, method, s_fsal, y, ynew, h, n, nY, rtol,
                              atol))
            stats[2] += nf
            if not (err <= 1.0):
                stats[1] += 1
                if not finite or err != err:
                    h *= 0.25
                    if h < 4.0 * _ulp(t):
                        status = ST_NONFINITE
                        break
                else:
                    h *= max(0.2, 0.9 * err ** (-1.0 / order))
                continue
            stats[0] += 1
            # dense output coefficients are made only when needed (stored steps, interior samples)
            q_ready = q_made
            if store_q and not q_ready:
                stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h, h, K, A,
                        C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                q_ready = True
            t_new = t + h
            if t_new > t_end or h >= t_end - t:
                # the last step, clipped to t_end - t: t + (t_end - t) can round one ulp past (or
                # short of) t_end; the run ends exactly at t_end
                t_new = t_end

            # ---- event detection on [t, t_new]
            best = -1
            best_th = 2.0
            best_sign = 0.0
            unresolved = False
            bad_watch = False  # a watch function (surface, hdot, hddot) NaN or inf at a step end
            tratio = 0.0   # largest midpoint mismatch / tolerance of time-dependent surfaces
            for w in range(nw):
                # Samples in increasing theta. Surfaces: the ends and the interior extrema of the
                # cubic Hermite fit built from h and hdot at the ends (where a graze hides);
                # other watch functions: the ends and the midpoint.
                if wtype[w] == WF_SURFACE:
                    if wvalid[w] == 1:
                        v0 = wv[w]
                        r0 = wd[w]
                    else:
                        v0 = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t, y, n, buf,
                                          fbuf, hdx)
                        r0 = _surface_rate(ev, p, dkind, widx[w], mode, nm, t, y, K[0], n, buf,
                                           hdx)
                        if ((wact[w] == ACT_EVENT or wact[w] == ACT_SWITCH)
                                and not (wforce[w] != 0.0 and t == last_t)):
                            # first step after a restart (start of the run, any event): on the
                            # surface within round-off is on it (the surface that just fired
                            # keeps its guard)
                            v0, r0 = _start_on_surface(ev, p, widx[w], dkind, mode, nm, t, y, n,
                                                       v0, r0, buf, hdx)
                            if wpend[w] == 1:
                                # crossed at the instant of the event just handled (see below):
                                # on the surface now, it fires here if the flow still goes on
                                v0 = 0.0
                    if dkind == REGULAR:
                        ev(W_HHD, widx[w] * nm + mode, t_new, ynew, p, buf)
                        v1 = buf[0]
                        r1 = buf[1]
                    else:
                        v1 = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t_new, ynew, n,
                                          buf, fbuf, hdx)
                        # (kst holds the last stage, K[s_fsal]: no array view per step)
                        r1 = _surface_rate(ev, p, dkind, widx[w], mode, nm, t_new, ynew, kst, n,
                                           buf, hdx)
                    if not (np.isfinite(v0) and np.isfinite(v1)):
                        bad_watch = True
                        break
                    wv[w] = v1
                    wd[w] = r1
                    d0 = r0 * h
                    d1 = r1 * h
                    if wtdep[w] == 1:
                        # a surface that moves in time (an oscillating constraint) while the state
                        # barely does (a mass at rest, free flight): the error control does not see
                        # the surface, so a step may span several of its oscillations. The cubic
                        # Hermite fit must reproduce h at the midpoint, or the step is retaken
                        # shorter.
                        if not q_ready:
                            stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y,
                                    h, h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz,
                                    aff)
                            q_ready = True
                        _dense_eval(y, Q, 0.5, nY, deg, xs)
                        hm = _watch_value(ev, p, WF_SURFACE, widx[w], wmode[w], nm, t + 0.5 * h,
                                          xs, n, buf, fbuf, hdx)
                        hh = 0.5 * (v0 + v1) + 0.125 * (d0 - d1)
                        hsc = max(abs(v0), abs(v1), abs(hm))
                        ratio = abs(hm - hh) / (0.01 * hsc + 64.0 * _EPS * (1.0 + hsc))
                        tratio = max(tratio, ratio)
                        if ratio > 1.0:
                            unresolved = True
                            break
                    ns = 1
                    thetas[0] = 0.0
                    vals[w, 0] = v0
                    # the interior extrema of the cubic Hermite fit (2.0: none)
                    ra, rb = _hermite_extrema(v0, v1, d0, d1)
                    if ra < 1.0:
                        thetas[ns] = ra
                        ns += 1
                    if rb < 1.0:
                        thetas[ns] = rb
                        ns += 1
                    if ns > 1 and not q_ready:
                        stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h,
                                h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                        q_ready = True
                    rates[0] = r0
                    for q in range(1, ns):
                        if dkind == REGULAR:
                            _dense_eval(y, Q, thetas[q], n, deg, xs)
                            ev(W_HHD, widx[w] * nm + mode, t + thetas[q] * h, xs, p, buf)
                            vals[w, q] = buf[0]
                            rates[q] = buf[1]
                        else:
                            vq, rq = _watch_pair(ev, p, wtype[w], widx[w], wmode[w], dkind, didx,
                                                 mode, nm, t, h, y, Q, n, deg, thetas[q], xs, buf,
                                                 fbuf, hdx, ft, etab, stab, slide_c, w1, w2, gx)
                            vals[w, q] = vq
                            rates[q] = rq
                    thetas[ns] = 1.0
                    vals[w, ns] = v1
                    rates[ns] = r1
                    ns += 1
                    # an extremum of h towards zero between two samples (near grazing): bounded
                    # search on the dense output instead of trusting the fit's extremum
                    search = False
                    for q in range(ns - 1):
                        if vals[w, q] * vals[w, q + 1] > 0.0:
                            sg = 1.0 if vals[w, q] > 0.0 else -1.0
                            if sg * wdir[w] <= 0 and sg * rates[q] < 0.0 < sg * rates[q + 1]:
                                search = True
                    if search:
                        ns = _graze_samples(ev, p, wtype[w], widx[w], wmode[w], wdir[w], dkind,
                                            didx, mode, nm, t, h, y, Q, n, deg, thetas, vals[w],
                                            rates, ns, xs, buf, fbuf, hdx, ft, etab, stab, slide_c,
                                            w1, w2, gx)
                else:
                    thetas[0] = 0.0
                    thetas[1] = 0.5
                    thetas[2] = 1.0
                    ns = 3
                    if wvalid[w] == 1:
                        vals[w, 0] = wv[w]
                    else:
                        vals[w, 0] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t, y, n,
                                                  buf, fbuf, hdx)
                        if wpend[w] == 1:
                            # changed sign at the instant of the event just handled (see below)
                            vals[w, 0] = 0.0
                    if not q_ready:
                        stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h,
                                h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                        q_ready = True
                    _dense_eval(y, Q, 0.5, nY, deg, xs)
                    vals[w, 1] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + 0.5 * h,
                                              xs, n, buf, fbuf, hdx)
                    vals[w, 2] = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t_new, ynew,
                                              n, buf, fbuf, hdx)
                    if not (np.isfinite(vals[w, 0]) and np.isfinite(vals[w, 2])):
                        bad_watch = True
                        break
                    wv[w] = vals[w, 2]
                    if wtype[w] == WF_HDDOT or wtype[w] == WF_HDOT:
                        # release from sticking, exit from sliding: the free normal
                        # acceleration, or the normal velocity of the field beyond, may change
                        # sign only in a short window around its extremum inside the step (the
                        # sliding flow touching the boundary of the sliding region, near an
                        # adding-sliding). Its slopes at the ends (central differences on the
                        # dense output; the end one is kept for the next step), the extrema of
                        # the Hermite fit and the bounded search of surfaces add samples there
                        if wvalid[w] == 1:
                            sd0 = wd[w]
                        else:
                            sd0 = _watch_slope(ev, p, wtype[w], widx[w], wmode[w], nm, t, h, y, Q,
                                               n, deg, 0.0, xs, buf, fbuf, hdx)
                        sd1 = _watch_slope(ev, p, wtype[w], widx[w], wmode[w], nm, t, h, y, Q, n,
                                           deg, 1.0, xs, buf, fbuf, hdx)
                        wd[w] = sd1
                        ra, rb = _hermite_extrema(vals[w, 0], vals[w, 2], sd0 * h, sd1 * h)
                        ex_th[0] = 0.0
                        ex_g[0] = vals[w, 0]
                        rates[0] = sd0
                        ne = 1
                        for rr in (ra, rb):
                            if 0.0 < rr < 1.0:
                                vq, rq = _watch_pair(ev, p, wtype[w], widx[w], wmode[w], dkind,
                                                     didx, mode, nm, t, h, y, Q, n, deg, rr, xs,
                                                     buf, fbuf, hdx, ft, etab, stab, slide_c, w1,
                                                     w2, gx)
                                ex_th[ne] = rr
                                ex_g[ne] = vq
                                rates[ne] = rq
                                ne += 1
                        ex_th[ne] = 1.0
                        ex_g[ne] = vals[w, 2]
                        rates[ne] = sd1
                        ne += 1
                        if ne > 2:
                            ne = _graze_samples(ev, p, wtype[w], widx[w], wmode[w], wdir[w], dkind,
                                                didx, mode, nm, t, h, y, Q, n, deg, ex_th, ex_g,
                                                rates, ne, xs, buf, fbuf, hdx, ft, etab, stab,
                                                slide_c, w1, w2, gx)
                            ns = _merge_samples(thetas, vals[w], ns, ex_th, ex_g, ne)
                forced = wforce[w] != 0.0 and t == last_t
                if forced:
                    vals[w, 0] = wforce[w] * max(abs(vals[w, 0]), 1e-300)
                    # right after an event on this function, values at round-off level are noise
                    noise = 0.0
                    for i in range(n):
                        noise = max(noise, abs(y[i]))
                    noise = max(1e3 * _EPS * (1.0 + noise), last_depth)
                # the first crossing in the event direction between consecutive samples
                prev_th = thetas[0]
                prev_v = vals[w, 0]
                for q in range(1, ns):
                    th = thetas[q]
                    vq = vals[w, q]
                    # a bracket that starts before the earliest crossing found so far may hold
                    # an earlier one (two surfaces crossed in one step: the later sample end is
                    # no bound)
                    if prev_th >= best_th:
                        break
                    if forced and abs(vq) <= noise:
                        prev_th = th
                        continue
                    if _crosses(prev_v, vq, wdir[w]):
                        if not q_ready:
                            stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y,
                                    h, h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz,
                                    aff)
                            q_ready = True
                        # locate by Illinois on the dense output within [prev_th, th]
                        a_th = prev_th
                        b_th = th
                        fa = prev_v
                        fb = vq
                        side = 0
                        width_check = b_th - a_th
                        if fa == 0.0:
                            # the function is exactly zero at the left sample and moves into the
                            # event direction from there (a start on the surface, or one within
                            # its round-off band, see above): the crossing is at that sample. The
                            # sign test below would take a zero end for the far side and slide
                            # the bracket to the step's end
                            b_th = a_th
                        for it in range(400):
                            if (b_th - a_th) * h <= 2.0 * _ulp(t + b_th * h):
                                break
                            m_th = ((a_th * fb - b_th * fa) / (fb - fa) if fb != fa
                                    else 0.5 * (a_th + b_th))
                            # safeguard: bisect when two secant steps did not halve the bracket
                            # (Illinois stalls when one end value is tiny, e.g. right after an
                            # event)
                            if it % 2 == 1:
                                if b_th - a_th > 0.5 * width_check:
                                    m_th = 0.5 * (a_th + b_th)
                                width_check = b_th - a_th
                            if not (a_th < m_th < b_th):
                                m_th = 0.5 * (a_th + b_th)
                            _dense_eval(y, Q, m_th, nY, deg, xs)
                            fm = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + m_th * h,
                                              xs, n, buf, fbuf, hdx)
                            if forced and abs(fm) <= noise:
                                # still on the side just left: round-off around the last event
                                fm = wforce[w] * max(abs(fm), 1e-300)
                            if (fm > 0.0) == (fa > 0.0) and fm != 0.0:
                                a_th = m_th
                                fa = fm
                                if side == -1:
                                    fb *= 0.5
                                side = -1
                            else:
                                b_th = m_th
                                fb = fm
                                if side == 1:
                                    fa *= 0.5
                                side = 1
                        if b_th < best_th:
                            best_th = b_th
                            best = w
                            best_sign = -1.0 if prev_v > 0.0 else 1.0
                        break
                    prev_th = th
                    prev_v = vq

            if bad_watch:
                # a crossing of a NaN surface can never be seen: events would be missed silently.
                # Treated like a non-finite stage: retake the step shorter, down to the point
                # where the function turns non-finite (or at once, if it is at the start)
                stats[1] += 1
                for ww in range(nw):
                    wvalid[ww] = 0
                h *= 0.25
                if h < 4.0 * _ulp(t):
                    status = ST_NONFINITE
                    break
                continue

            if unresolved:
                # retake the step shorter (the surface was not resolved); cached watch values
                # belong to the rejected step
                stats[1] += 1
                # the Hermite midpoint error is O(h^4)
                h *= max(0.2, 0.9 * tratio ** -0.25)
                for ww in range(nw):
                    wvalid[ww] = 0
                continue

            if best < 0:
                # accept the whole step
                if dkind == SLIDE:
                    # keep the sliding state on its surface: the Runge-Kutta step conserves a
                    # linear h exactly but drifts off a curved or moving one by the local error;
                    # one Newton step along h_x removes that (projection; it leaves the sliding
                    # field non-stiff, unlike a large gain C of the -C h grad h term)
                    _project_surface(ev, p, stab[didx, 0], t_new, ynew, n, hdx, buf)
                if save_all:
                    if store_q:
                        for i in range(nY):
                            for k in range(deg):
                                dense[n_nodes - 1, i, k] = Q[i, k]
                    for i in range(nY):
                        nodes_y[n_nodes, i] = ynew[i]
                    ikind[n_nodes - 1] = IV_STEP
                    hstep[n_nodes - 1] = h
                    nodes_t[n_nodes] = t_new
                    nodes_s[n_nodes, 0] = dkind
                    nodes_s[n_nodes, 1] = didx
                    nodes_s[n_nodes, 2] = mode
                    n_nodes += 1
                if sdt > 0.0 and s0 + sk * sdt <= t_new:
                    if not q_ready:
                        stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h,
                                h, K, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
                        q_ready = True
                    n_samp, sk = _take_samples(t, h, y, Q, nY, n, deg, s0, sdt, sk, t_end,
                                                     samp, n_samp, xs, max_samp)
                if t == last_t:
                    # the re-trigger guard holds while its function stays within the round-off
                    # band on the far side: a step ending there must not start the next one on the
                    # far side unguarded (a release whose flight rises less than the band would
                    # have its landing stepped over)
                    for ww in range(nw):
                        if wforce[ww] * wv[ww] < 0.0 and abs(wv[ww]) <= noise:
                            last_t = t_new
                t = t_new
                for i in range(nY):
                    y[i] = ynew[i]
                    K[0, i] = K[s_fsal, i]
                for ww in range(nw):
                    wvalid[ww] = 1
                fac = 10.0 if err == 0.0 else min(10.0, max(0.2, 0.9 * err ** (-1.0 / order)))
                if tratio > 0.0:
                    # nor grow past the resolution of a moving surface
                    fac = min(fac, max(0.2, 0.9 * tratio ** -0.25))
                h = h * fac
                continue

            # ---- an event inside the step: land exactly on it with a shortened step, then
            # polish the time with Newton on the watch function (h / hdot) for surfaces. The
            # dense output of an exact step is the exact flow: there the landing "step" is its
            # evaluation, and the step's Taylor terms are rescaled to the shorter interval.
            w = best
            h_ev = best_th * h
            for i in range(nY):
                Kland[0, i] = K[0, i]
            for polish in range(8):
                stats[2] += _step_stages(ev, p, exact_now, dkind, didx, mode, nm, t, y, h_ev, h,
                        Kland, A, C, s_fsal, Q, ytmp, etab, stab, slide_c, wk)
                stats[5] += 1
                for i in range(nY):
                    ynew[i] = ytmp[i]
                if (wtype[w] != WF_SURFACE and wtype[w] != WF_HDOT) or polish == 7:
                    break
                if best_th == 0.0:
                    # the function was zero at the step's start (on the surface, see the bracket
                    # above): the event is at t, where the state is given; Newton on round-off
                    # values (tangency: hv / hd ~ 1e-16 / 1e-16) would move it anywhere
                    break
                # Newton on h(t + h_ev) (or on hdot of a mode, for a sliding exit) with the
                # landing step as the flow: quadratic, so a few iterations bring the watch function
                # to round-off even for slow (near-grazing, tangential-exit) arrivals
                hv = _watch_value(ev, p, wtype[w], widx[w], wmode[w], nm, t + h_ev, ynew, n, buf,
                                  fbuf, hdx)
                if wtype[w] == WF_SURFACE:
                    hd = _surface_rate(ev, p, dkind, widx[w], mode, nm, t + h_ev, ynew,
                                       Kland[s_fsal], n, buf, hdx)
                else:
                    hd = _hdot_rate(ev, p, widx[w], wmode[w], nm, t + h_ev, ynew, Kland[s_fsal], n,
                                    buf, hdx)
                if hd == 0.0 or hv == 0.0:
                    break
                dt = -hv / hd
                # (a NaN correction, from a NaN watch function, keeps the bracketed time)
                if (not np.isfinite(dt) or abs(dt) <= 2.0 * _ulp(t + h_ev) or h_ev + dt <= 0.0
                        or h_ev + dt > h):
                    break
                h_ev += dt
            # landing-step dense output (extra stages for DOP853; Taylor terms rescaled), where it
            # is stored or sampled
            if store_q or sdt > 0.0:
                stats[2] += _step_dense(ev, p, exact_now, dkind, didx, mode, nm, t, y, h_ev, h,
                        Kland, A, C, s_fsal, P, Q, ytmp, etab, stab, slide_c, wk, nz, aff)
            t_ev = min(t + h_ev, t_end)
            # Events at one instant: another watched function (an event surface, a release or a
            # sliding exit) that changed sign between the step's start and the polished event
            # time crossed within the location error of this event (this one was bracketed
            # first; polishing moved its time past the other crossing). It fires at the same
            # time, right after this one (unless the new motion leaves it), instead of being
            # found on its far side after the restart and lost (a release lost that way left a
            # ball stuck to a table that pulls it).
            n_pend = 0
            pend_t = t_ev
            for ww in range(nw):
                if ww == w or (wtype[ww] == WF_SURFACE and widx[ww] == widx[w]):
                    continue
                vw = _watch_value(ev, p, wtype[ww], widx[ww], wmode[ww], nm, t_ev, ynew, n, buf,
                                  fbuf, hdx)
                if vals[ww, 0] != 0.0 and _crosses(vals[ww, 0], vw, wdir[ww]):
                    pend_type[n_pend] = wtype[ww]
                    pend_idx[n_pend] = widx[ww]
                    pend_mode[n_pend] = wmode[ww]
                    pend_act[n_pend] = wact[ww]
                    pend_ref[n_pend] = wref[ww]
                    n_pend += 1
            if sdt > 0.0:
                # samples up to the event (one at the event time takes the state before it)
                n_samp, sk = _take_samples(t, h_ev, y, Q, nY, n, deg, s0, sdt, sk, t_end,
                                                 samp, n_samp, xs, max_samp)
            # store the node just before the event (always, also when not saving all steps)
            if store_q:
                for i in range(nY):
                    for k in range(deg):
                        dense[n_nodes - 1, i, k] = Q[i, k]
            ikind[n_nodes - 1] = IV_STEP if save_all else IV_JUMP
            hstep[n_nodes - 1] = h_ev
            nodes_t[n_nodes] = t_ev
            for i in range(nY):
                nodes_y[n_nodes, i] = ynew[i]
            nodes_s[n_nodes, 0] = dkind
            nodes_s[n_nodes, 1] = didx
            nodes_s[n_nodes, 2] = mode
            n_nodes += 1

            # ---- handle the event: one action per kind of watch function
            n_ev0 = n_ev
            for i in range(nY):
                y[i] = ynew[i]
                xs[i] = ynew[i]
            t = t_ev
            old_kind = dkind
            old_idx = didx
            old_mode = mode
            log_kind = -1
            t_after = t
            act = wact[w]
            new_sign = best_sign
            chatter_tail = False
            contact_stick = False
            if act == ACT_EVENT:
                # Is the crossing an event? (Written out here, as the re-trigger guard below: a
                # call passing the watch arrays measured a few % of an event-dominated run.)
                # Events on one surface with complementary guards (stick or reverse at v = 0,
                # thesis eq. 5.4): the crossing belongs to the one whose guard holds.
                j = wref[w]
                ev(W_GUARD, j, t, y, p, buf)
                guard_ok = buf[0] != 0.0
                if not guard_ok:
                    for ww in range(nw):
                        if (ww != w and wact[ww] == ACT_EVENT and wtype[ww] == WF_SURFACE
                                and widx[ww] == widx[w]
                                and (wdir[ww] == 0 or wdir[ww] * new_sign > 0.0)):
                            ev(W_GUARD, wref[ww], t, y, p, buf)
                            if buf[0] != 0.0:
                                w = ww
                                j = wref[ww]
                                guard_ok = True
                                break
                # a crossing whose normal velocity points against the event direction is
                # round-off around a previous event (the state is already leaving): not an
                # event, unless that velocity is round-off itself (a state on the surface and
                # tangent to it is not leaving; the sign of the round-off must not decide)
                if dkind == REGULAR:
                    ev(W_HD, widx[w] * nm + mode, t, y, p, buf)
                    vn = buf[0]
                else:
                    _field(ev, p, dkind, didx, mode, nm, t, y, n, fbuf, etab, stab, slide_c, w1,
                           w2, gx, hdx)
                    vn = _surface_rate(ev, p, dkind, widx[w], mode, nm, t, y, fbuf, n, buf, hdx)
                moving_away = etab[j, 1] != 0 and vn * etab[j, 1] < 0.0
                if moving_away and abs(vn) <= _rate_band(ev, p, widx[w], mode, nm, t, y, n, hdx):
                    moving_away = False
                if not guard_ok or moving_away:
                    # no event: continue past this crossing
                    last_type = wtype[w]
                    last_idx = widx[w]
                    last_mode = wmode[w]
                    last_sign = new_sign
                    if moving_away:
                        last_sign = 1.0 if vn > 0.0 else -1.0
                        # the state sits a little on the far side (round-off of an earlier
                        # event) and is moving back: values within that depth are not a new
                        # crossing
                        ev(W_H, widx[w], t, y, p, buf)
                        last_depth = 4.0 * abs(buf[0])
                    last_t = t
                    # the interval [t_ev, ...] continues smoothly: the stored one is a step
                    ikind[n_nodes - 2] = IV_STEP if save_all else IV_JUMP
                    restart = True
                    continue
                j = wref[w]
                if etab[j, 2] == EV_IMPACT:
                    (dkind, didx, mode, log_kind, t_after, chatter_tail, chain_event, chain_vmax,
                     chattered) = _act_impact(ev, p, j, dkind, didx, mode, nm, t, y, xs, n, etab,
                                              t_end, fopt, chatter_on, chain_event, chain_vmax,
                                              buf, fbuf, ytmp, wk)
                    stats[4] += chattered
                else:
                    mode = _act_transition(ev, p, j, mode, t, y, xs, n, etab, ytmp)
                    log_kind = K_TRANSITION
                    chain_event = -1
                dkind, didx, mode, contact_stick = _after_reset(
                    ev, p, j, log_kind, chatter_tail, dkind, didx, mode, nm, t, y, n, etab, stab,
                    buf, fbuf, wk)
            elif act == ACT_RELEASE:
                dkind, didx, mode, log_kind = _act_release(ev, p, etab[old_idx, 0], mode, nm, t,
                                                           y, n, stab, buf, wk)
            elif act == ACT_SWITCH:
                dkind, didx, mode, log_kind, graze = _act_switch(ev, p, wref[w], old_kind,
                                                                 old_idx, old_mode, nm, t, y, n,
                                                                 stab, buf, hdx)
                if graze:
                    last_type = wtype[w]
                    last_idx = widx[w]
                    last_mode = wmode[w]
                    last_sign = new_sign
                    last_t = t
                    ikind[n_nodes - 2] = IV_STEP if save_all else IV_JUMP
                    restart = True
                    continue
            elif act == ACT_EXIT_ABOVE or act == ACT_EXIT_BELOW:
                dkind, didx, mode, log_kind = _act_slide_exit(wref[w], act == ACT_EXIT_ABOVE,
                                                              stab)
            else:
                status, dkind, didx, mode, log_kind, log_ref = _act_intersection(
                    ev, p, widx[w], new_sign, wref[w], old_kind, old_idx, old_mode, nm, t, y, n,
                    etab, stab, slide_c, buf, fbuf, wk)
            if act != ACT_INTERSECTION:
                log_ref = wref[w]

            if log_kind >= 0:
                if nvar:
                    # the saltation matrix of the action, then Phi+ = S Phi-
                    _action_saltation(ev, p, act, log_kind, chatter_tail, log_ref,
                                      widx[w] if act != ACT_SWITCH else stab[wref[w], 0],
                                      old_kind, old_idx, old_mode, dkind, didx, mode, nm, t, xs,
                                      y, n, S, etab, stab, slide_c, buf, fbuf, ytmp, wk)
                    _apply_saltation(y, S, Phi, n, seg_var)
                rec[0] = log_kind
                rec[1] = log_ref
                rec[2] = old_kind
                rec[3] = old_idx
                rec[4] = old_mode
                # the chatter record is the jump x_in -> Q(x_in); the change of discrete state
                # to sticking is the `stick` record that follows it
                rec[5] = (old_kind if log_kind == K_CHATTER
                          else (REGULAR if contact_stick else dkind))
                rec[6] = old_idx if log_kind == K_CHATTER else (-1 if contact_stick else didx)
                rec[7] = old_mode if log_kind == K_CHATTER else mode
                rec[8] = n_nodes
                _log_event(ev_t, ev_t2, ev_info, ev_xb, ev_xa, n_ev, t, t_after, rec, xs, y)
                n_ev += 1
                stats[3] += 1
                if nvar and seg_var:
                    # the next segment's Phi starts at the identity
                    for i in range(n):
                        for c in range(n):
                            y[n + i * n + c] = 1.0 if i == c else 0.0
                # jump (or chatter gap) interval to the post-event node
                nodes_t[n_nodes] = t_after
                for i in range(nY):
                    nodes_y[n_nodes, i] = y[i]
                nodes_s[n_nodes, 0] = dkind
                nodes_s[n_nodes, 1] = didx
                nodes_s[n_nodes, 2] = mode
                ikind[n_nodes - 1] = IV_CHATTER if log_kind == K_CHATTER else IV_JUMP
                hstep[n_nodes - 1] = 0.0
                if store_q:
                    for i in range(nY):
                        for k in range(deg):
                            dense[n_nodes - 1, i, k] = 0.0
                n_nodes += 1
                if contact_stick or log_kind == K_CHATTER:
                    # sticking starts here (after an impact that left the state in contact, or
                    # at the accumulation point of a chattering sequence): its own record, from
                    # the mode the reset gave
                    rec[0] = K_STICK
                    if contact_stick:
                        rec[2] = REGULAR
                        rec[3] = -1
                        rec[4] = mode
                    rec[5] = dkind
                    rec[6] = didx
                    rec[7] = mode
                    rec[8] = n_nodes - 1
                    _log_event(ev_t, ev_t2, ev_info, ev_xb, ev_xa, n_ev, t_after, t_after, rec, y,
                               y)
                    n_ev += 1
                if log_kind == K_CHATTER:
                    # samples across the chattering gap on its chord
                    while (sdt > 0.0 and s0 + sk * sdt < t_after and s0 + sk * sdt <= t_end
                           and n_samp < max_samp):
                        ts = s0 + sk * sdt
                        th = (ts - t) / (t_after - t)
                        samp[n_samp, 0] = ts
                        for i in range(n):
                            samp[n_samp, 1 + i] = (1.0 - th) * xs[i] + th * y[i]
                        n_samp += 1
                        sk += 1
                t = t_after
            if chatter_tail:
                # the run ends at t_end inside the unresolvable tail of a chattering sequence
                # (see the impact above); samples on the same chord
                while (sdt > 0.0 and s0 + sk * sdt <= t_end and n_samp < max_samp):
                    ts = s0 + sk * sdt
                    th = (ts - t) / (t_end - t) if t_end > t else 1.0
                    samp[n_samp, 0] = ts
                    for i in range(n):
                        samp[n_samp, 1 + i] = (1.0 - th) * xs[i] + th * y[i]
                    n_samp += 1
                    sk += 1
                t = t_end
                break
            if stop_mask != 0:
                # stop at the stop_count-th logged event of the requested kinds and index
                for r in range(n_ev0, n_ev):
                    if ((stop_mask >> ev_info[r, 0]) & 1) == 1 and (stop_ref < 0
                                                                    or ev_info[r, 1] == stop_ref):
                        n_stop += 1
                if n_stop >= stop_count and status == ST_SUCCESS:
                    status = ST_TERMINAL
                    break
            if status != ST_SUCCESS:
                break
            if act == ACT_EVENT and etab[wref[w], 4] == 1:
                status = ST_TERMINAL
                break
            if stats[3] >= max_events:
                status = ST_MAX_EVENTS
                break
            # Zeno: events on the same function closer than the resolution of t, repeatedly
            if (last_type == wtype[w] and last_idx == widx[w]
                    and t - last_t <= 64.0 * _ulp(t)):
                zeno += 1
                if zeno >= 3:
                    status = ST_ZENO
                    break
            else:
                zeno = 0
            # re-trigger guard: the side of the function after the event; the guards of
            # functions that fired earlier at this same instant are kept
            if abs(t - last_t) <= _COINCIDENT_ULPS * _ulp(t) and last_type >= 0:
                if n_co < wcap:
                    co_type[n_co] = last_type
                    co_idx[n_co] = last_idx
                    co_mode[n_co] = last_mode
                    co_sign[n_co] = last_sign
                    co_t[n_co] = last_t
                    n_co += 1
            else:
                n_co = 0
            last_depth = 0.0
            last_mode = wmode[w]
            last_t = t
            last_type = wtype[w]
            last_idx = widx[w]
            # re-trigger guard: the function that fired and the side of it the state is on now
            if act == ACT_EVENT:
                # after a reset the surface value is ~0; its new side is hdot after the reset
                if dkind == REGULAR:
                    ev(W_HD, widx[w] * nm + mode, t, y, p, buf)
                    last_sign = 1.0 if buf[0] > 0.0 else -1.0
                    vout = buf[0]
                    if etab[wref[w], 2] == EV_IMPACT and vout != 0.0:
                        # hdot after an impact within round-off (a plastic impact that does not
                        # stick: the free motion leaves tangentially): its sign is noise, the
                        # state is on the allowed side
                        if abs(vout) <= _rate_band(ev, p, widx[w], mode, nm, t, y, n, hdx):
                            vout = 0.0
                    if vout == 0.0:
                        # tangent after the event: an impact leaves the state on the admissible
                        # side, a transition has crossed into the event direction
                        if etab[wref[w], 2] == EV_IMPACT or etab[wref[w], 1] == 0:
                            last_sign = 1.0 if etab[wref[w], 1] <= 0 else -1.0
                        else:
                            last_sign = 1.0 if etab[wref[w], 1] > 0 else -1.0
                else:
                    last_sign = 1.0
            elif act == ACT_RELEASE:
                last_sign = 1.0
                last_type = WF_SURFACE
                last_idx = etab[wref[w], 0]
            elif act == ACT_SWITCH:
                if dkind == SLIDE:
                    last_type = -1
                else:
                    last_sign = 1.0 if mode == stab[wref[w], 1] else -1.0
            elif act == ACT_INTERSECTION:
                # crossed surface widx[w] while sliding: we are on the new side of it
                last_type = WF_SURFACE
                last_sign = new_sign
            else:
                # sliding exit: we leave into the mode's side of the surface
                last_type = WF_SURFACE
                last_idx = stab[wref[w], 0]
                last_sign = 1.0 if act == ACT_EXIT_ABOVE else -1.0
            restart = True

    # final node (when only events are saved, the end state still is)
    if nodes_t[n_nodes - 1] != t:
        nodes_t = _grow1(nodes_t, n_nodes + 1)
        nodes_y = _grow2(nodes_y, n_nodes + 1)
        nodes_s = _grow2(nodes_s, n_nodes + 1)
        ikind = _grow1(ikind, n_nodes + 1)
        hstep = _grow1(hstep, n_nodes + 1)
        ikind[n_nodes - 1] = IV_JUMP
        hstep[n_nodes - 1] = 0.0
        if store_q:
            dense = _grow3(dense, n_nodes + 1)
            dense[n_nodes - 1, :, :] = 0.0
        nodes_t[n_nodes] = t
        nodes_y[n_nodes, :] = y
        nodes_s[n_nodes, 0] = dkind
        nodes_s[n_nodes, 1] = didx
        nodes_s[n_nodes, 2] = mode
        n_nodes += 1
    # the node arrays are returned as they are (views of their first rows): a copy is another
    # pass over memory (~10% of a run storing every step); the spare rows (the arrays grow
    # by doubling) are at most as many as the used ones
    return (status, t, y.copy(), np.array([dkind, didx, mode], dtype=np.int64),
            nodes_t[:n_nodes], nodes_y[:n_nodes], nodes_s[:n_nodes],
            dense[: max(n_nodes - 1, 0) if store_q else 0],
            ikind[: max(n_nodes - 1, 0)],
            ev_t[:n_ev].copy(), ev_t2[:n_ev].copy(), ev_info[:n_ev].copy(),
            ev_xb[:n_ev].copy(), ev_xa[:n_ev].copy(), stats, samp[:n_samp].copy(),
            hstep[: max(n_nodes - 1, 0)])
