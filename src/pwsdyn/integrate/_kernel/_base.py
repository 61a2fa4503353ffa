"""What every part of the kernel shares: the decorators of its compiled functions, its
constants, small vector helpers, and the growable output buffers and event log.
"""

from __future__ import annotations

import numpy as np
from numba import from_dtype, njit
from numba import types as nt

from .._codes import EVENT_TABLE, KERNEL_OPTIONS, SWITCH_TABLE


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
#: (a longer stepping loop, more of it spilled). Inlined too (the six workloads of that
#: script, instructions of a run): the impact action and the resolution after a reset (exact
#: -1.2%, RK -0.3 to -0.5%); the Runge-Kutta error norm, called on every step, with the
#: start-on-surface test and the event-log writer (RK45 -2.4%, DOP853 -1.0%); a step's dense
#: output (exact -1.0%, RK45 +0.1%). The stages of a landing step (``_step_stages``) stay a
#: call: inlined as well they cost RK45 0.9%. ``forceinline=False`` is explicit on ``_hot``:
#: numba passes an unset flag on from a caller to the functions it compiles for it, so a
#: helper first compiled for an inlined caller would be inlined too.
_hot_inline = njit(cache=True, _nrt=False, forceinline=True)

#: numba's types of the options (one record), the event and the switch tables: contiguous
#: 1-d arrays of records, part of the kernel's signature.
OPTIONS_TYPE = nt.Array(from_dtype(KERNEL_OPTIONS), 1, "C")
EVENT_TABLE_TYPE = nt.Array(from_dtype(EVENT_TABLE), 1, "C")
SWITCH_TABLE_TYPE = nt.Array(from_dtype(SWITCH_TABLE), 1, "C")

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


@_hot_inline
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


def compiled_on_first_use(fn, signature, **options):
    """``fn`` compiled with the numba signature ``signature()`` (its types made only then) at
    its first call, and from then on (in later processes: loaded from numba's cache): an
    entry point that most runs never call costs them nothing. Numba's warning that the
    model's first-class function type is experimental is not shown, as for the kernel."""
    compiled = None

    def call(*args):
        nonlocal compiled
        if compiled is None:
            import warnings

            from numba.core.errors import NumbaExperimentalFeatureWarning
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
                compiled = njit(signature(), cache=True, **options)(fn)
        return compiled(*args)

    return call
