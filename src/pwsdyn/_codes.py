"""The integer codes shared by the compiled kernel and the Python side, in one place.

Plain Python (no numba): importing it costs nothing, and the kernel reads these module-level
integers as compile-time constants. Each enumeration is written once as a tuple of names; the
integer of a name is its position, so adding a code is adding a name at the end of one tuple
(see docs/extending.md). The kernel's ``K_*``, ``ST_*``, ... constants are generated from the
tuples below, so the two sides cannot drift apart.

Also here: :func:`kernel_options`, the only place that builds the kernel's option arrays
``iopt``/``fopt`` from named arguments, and :class:`KernelResult`, the named form of the
tuple :func:`pwsdyn.integrate._kernel.run_kernel` returns.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# --------------------------------------------------------------------------------------
# enumerations (name tuples; code = index)
# --------------------------------------------------------------------------------------

#: Discrete states (``dkind``): a regular mode, sticking on an impact surface, Filippov
#: sliding on a switching surface (the kernel's module docstring).
STATE_KINDS = ("mode", "stick", "slide")
REGULAR, STICK, SLIDE = range(3)

#: Kinds of the event log, indexed by the kernel's ``K_*`` codes (``trajectory.EVENT_KINDS``
#: and ``orbits.signature.KINDS`` must list the same names in the same order; a test checks).
EVENT_LOG_KINDS = ("impact", "transition", "chatter", "stick", "release", "crossing",
                   "slide_start", "slide_end")
(K_IMPACT, K_TRANSITION, K_CHATTER, K_STICK, K_RELEASE, K_CROSSING, K_SLIDE_START,
 K_SLIDE_END) = range(len(EVENT_LOG_KINDS))

#: Kinds of events in the model tables (``etab`` column 2; ``model.spec.EVENT_KINDS``).
MODEL_EVENT_KINDS = ("impact", "transition")
EV_IMPACT, EV_TRANSITION = range(2)

#: Watch function types: a surface ``h``, a normal velocity ``hdot`` (sliding exit), a normal
#: acceleration ``hddot`` (release from sticking).
WATCH_TYPES = ("surface", "hdot", "hddot")
WF_SURFACE, WF_HDOT, WF_HDDOT = range(3)

#: What a watch function does when it fires: one action handler each in the kernel.
ACTIONS = ("event", "switch", "release", "exit_above", "exit_below", "intersection")
ACT_EVENT, ACT_SWITCH, ACT_RELEASE, ACT_EXIT_ABOVE, ACT_EXIT_BELOW, ACT_INTERSECTION = range(6)

#: Status codes of a run (``errors.Status`` has the same values; a test checks).
STATUSES = ("success", "terminal", "max_steps", "max_events", "step_too_small", "nonfinite",
            "intersection", "zeno")
(ST_SUCCESS, ST_TERMINAL, ST_MAX_STEPS, ST_MAX_EVENTS, ST_STEP_TOO_SMALL, ST_NONFINITE,
 ST_INTERSECTION, ST_ZENO) = range(len(STATUSES))

#: Kinds of switching surfaces (``stab`` column 3): Filippov (cross or slide) or continuous
#: (only a derivative jumps: always cross); sliding methods (column 4).
SWITCH_KINDS = ("filippov", "continuous")
SW_FILIPPOV, SW_CONTINUOUS = range(2)
SLIDE_METHODS = ("convex", "utkin")
SLIDE_CONVEX, SLIDE_UTKIN = range(2)

#: Interval kinds of the node list: a step, a jump at an event, a chattering gap.
INTERVAL_KINDS = ("step", "jump", "chatter_gap")
IV_STEP, IV_JUMP, IV_CHATTER = range(3)

#: What a run stores (``IO_SAVE``): the nodes of events and the end; every step with its dense
#: output; every step with its length only (the dense output rebuilt on demand).
SAVE_MODES = ("events", "dense", "nodes")
SAVE_EVENTS, SAVE_DENSE, SAVE_NODES = range(3)

#: Variational equations (``IO_VAR``): none; Phi through every event; Phi per segment.
VAR_MODES = ("none", "global", "segments")
VAR_NONE, VAR_GLOBAL, VAR_SEGMENTS = range(3)

# --------------------------------------------------------------------------------------
# option arrays
# --------------------------------------------------------------------------------------

#: Integer options, by position in ``iopt``.
INT_OPTIONS = ("mode0", "n_modes", "max_steps", "max_events", "method", "variational",
               "chatter", "save", "stop_mask", "stop_ref", "stop_count", "dkind0", "didx0",
               "exact", "order")
(IO_MODE0, IO_NMODES, IO_MAXSTEPS, IO_MAXEVENTS, IO_METHOD, IO_VAR, IO_CHATTER, IO_SAVE,
 IO_STOP_MASK, IO_STOP_REF, IO_STOP_COUNT, IO_DKIND0, IO_DIDX0, IO_EXACT, IO_ORDER) = range(
    len(INT_OPTIONS))
IO_N = len(INT_OPTIONS)

#: Float options, by position in ``fopt``.
FLOAT_OPTIONS = ("rtol", "atol", "first_step", "max_step", "chatter_ratio", "chatter_velocity",
                 "sliding_gain", "sample_t0", "sample_dt")
(FO_RTOL, FO_ATOL, FO_H0, FO_HMAX, FO_CHAT_REL, FO_CHAT_ABS, FO_SLIDE_C, FO_SAMPLE_T0,
 FO_SAMPLE_DT) = range(len(FLOAT_OPTIONS))
FO_N = len(FLOAT_OPTIONS)


def kernel_options(*, mode0: int, n_modes: int, max_steps: int, max_events: int, method: int,
                   variational: int = VAR_NONE, chatter: bool = True, save: int = SAVE_EVENTS,
                   stop: tuple[int, int, int] | None = None, dkind0: int = REGULAR,
                   didx0: int = -1, exact: int = 0, order: int = 0, rtol: float, atol: float,
                   first_step: float = 0.0, max_step: float = np.inf,
                   chatter_ratio: float, chatter_velocity: float = -1.0,
                   sliding_gain: float = 0.0,
                   sample: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's option arrays ``(iopt, fopt)`` from named values.

    ``stop``: ``(kind_mask, ref, count)``, stop after the ``count``-th logged event whose
    ``K_*`` kind has its bit set in ``kind_mask`` and whose event or switch index is ``ref``
    (-1: any). ``first_step`` 0: estimated. ``chatter_ratio`` negative: the default ratio, applied
    only where the chattering map is accurate; ``chatter_velocity`` negative: the floor from
    the tolerances. ``sample``: ``(t0, dt)`` of stroboscopic samples (``dt <= 0``: none).
    ``method``: the tableau's ``code`` (its error estimator), ``order`` its order (the
    exponent of the step-size control; 0: 5 for code 0, 8 for code 1)."""
    iopt = np.zeros(IO_N, dtype=np.int64)
    iopt[IO_MODE0] = mode0
    iopt[IO_NMODES] = n_modes
    iopt[IO_MAXSTEPS] = max_steps
    iopt[IO_MAXEVENTS] = max_events
    iopt[IO_METHOD] = method
    iopt[IO_VAR] = variational
    iopt[IO_CHATTER] = 1 if chatter else 0
    iopt[IO_SAVE] = save
    if stop is not None:
        iopt[IO_STOP_MASK], iopt[IO_STOP_REF], iopt[IO_STOP_COUNT] = stop
    iopt[IO_DKIND0] = dkind0
    iopt[IO_DIDX0] = didx0
    iopt[IO_EXACT] = exact
    iopt[IO_ORDER] = order
    fopt = np.zeros(FO_N, dtype=float)
    fopt[FO_RTOL] = rtol
    fopt[FO_ATOL] = atol
    fopt[FO_H0] = first_step
    fopt[FO_HMAX] = max_step
    fopt[FO_CHAT_REL] = chatter_ratio
    fopt[FO_CHAT_ABS] = chatter_velocity
    fopt[FO_SLIDE_C] = sliding_gain
    if sample is not None:
        fopt[FO_SAMPLE_T0], fopt[FO_SAMPLE_DT] = sample
    return iopt, fopt


# --------------------------------------------------------------------------------------
# the kernel's result
# --------------------------------------------------------------------------------------

class KernelResult(NamedTuple):
    """What :func:`pwsdyn.integrate._kernel.run_kernel` returns (numba returns the plain
    tuple; ``KernelResult(*res)`` names it)."""

    status: int                 # ST_*
    t: float                    # final time
    y: np.ndarray               # final state (with Phi, row-major, for variational runs)
    state: np.ndarray           # final discrete state (kind, index, mode)
    nodes_t: np.ndarray
    nodes_y: np.ndarray
    nodes_s: np.ndarray         # (kind, index, mode) per node
    dense: np.ndarray           # power-form dense output per interval (SAVE_DENSE only)
    ikind: np.ndarray           # IV_* per interval
    ev_t: np.ndarray            # event log: time, time after (chattering), integer record
    ev_t2: np.ndarray
    ev_info: np.ndarray         # kind, ref, kind/idx/mode before, after, post-event node
    ev_xb: np.ndarray
    ev_xa: np.ndarray
    stats: np.ndarray           # steps, rejected, nfev, events, chatter, landing steps
    samples: np.ndarray         # (t, x) rows of stroboscopic samples
    hstep: np.ndarray           # step length per interval (0 for jumps)


#: Names of the entries of ``stats``.
STATS = ("steps", "rejected_steps", "nfev", "events", "chatter", "landing_steps")


__all__ = [name for name in dir() if not name.startswith("_") and name not in
           ("annotations", "NamedTuple", "np")]
