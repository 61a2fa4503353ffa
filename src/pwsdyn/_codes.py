"""The integer codes shared by the compiled kernel and the Python side, in one place.

Plain Python (no numba): importing it costs nothing, and the kernel reads these module-level
integers as compile-time constants. Each enumeration is written once as a tuple of names; the
integer of a name is its position, so adding a code is adding a name at the end of one tuple
(see docs/extending.md). The kernel's ``K_*``, ``ST_*``, ... constants are generated from the
tuples below, so the two sides cannot drift apart.

Also here: the record types of the kernel's event and switch tables and of its options
(:data:`KERNEL_OPTIONS`), with :func:`kernel_options`, the only place that builds the options,
and :class:`KernelResult`, the named form of the tuple
:func:`pwsdyn.integrate._kernel.run_kernel` returns.
"""

from __future__ import annotations

import operator
from typing import NamedTuple

import numpy as np

# --------------------------------------------------------------------------------------
# enumerations (name tuples; code = index)
# --------------------------------------------------------------------------------------

#: Discrete states (``dkind``): a regular mode, sticking on an impact surface, Filippov
#: sliding on a switching surface, sliding on the intersection of several switching surfaces
#: (``didx`` the bit mask of their surface indices, ``mode`` the corner above all of them;
#: the kernel's module docstring).
STATE_KINDS = ("mode", "stick", "slide", "slide_multi")
REGULAR, STICK, SLIDE, SLIDE_MULTI = range(4)

#: Most switching surfaces slid on at once (``SLIDE_MULTI``): 2**k corner modes, as many as
#: the variants of a mode split at k terms (``model.discontinuities.MAX_FAMILY_MODES`` = 1024),
#: and as many as the surfaces of one sign family (``FAMILY_MAX``), so that every contact of a
#: chain of ten blocks can stick at once. The kernel's work vectors hold the corners of the
#: largest intersection a model's switch table allows, not of ``MULTI_MAX`` surfaces.
MULTI_MAX = 10

#: Most surfaces of a sign family whose field the kernel evaluates at continuous sides on an
#: intersection (``model.discontinuities.MAX_SURFACES_PER_MODE``); a larger one is summed
#: over its corners.
FAMILY_MAX = 10

#: Kinds of the event log, indexed by the kernel's ``K_*`` codes (``trajectory.EVENT_KINDS``
#: and ``orbits.signature.KINDS`` must list the same names in the same order; a test checks).
EVENT_LOG_KINDS = ("impact", "transition", "chatter", "stick", "release", "crossing",
                   "slide_start", "slide_end")
(K_IMPACT, K_TRANSITION, K_CHATTER, K_STICK, K_RELEASE, K_CROSSING, K_SLIDE_START,
 K_SLIDE_END) = range(len(EVENT_LOG_KINDS))

#: Kinds of events in the model tables (``etab[j].kind``; ``model.spec.EVENT_KINDS``).
MODEL_EVENT_KINDS = ("impact", "transition")
EV_IMPACT, EV_TRANSITION = range(2)

#: Watch function types: a surface ``h``, a normal velocity ``hdot`` (sliding exit), a normal
#: acceleration ``hddot`` (release from sticking), ``min(lambda_i, 1 - lambda_i)`` of a weight
#: of the multilinear sliding field on an intersection (exit from one of its surfaces).
WATCH_TYPES = ("surface", "hdot", "hddot", "lambda")
WF_SURFACE, WF_HDOT, WF_HDDOT, WF_LAMBDA = range(4)

#: What a watch function does when it fires: one action handler each in the kernel.
ACTIONS = ("event", "switch", "release", "exit_above", "exit_below", "intersection",
           "exit_multi")
(ACT_EVENT, ACT_SWITCH, ACT_RELEASE, ACT_EXIT_ABOVE, ACT_EXIT_BELOW, ACT_INTERSECTION,
 ACT_EXIT_MULTI) = range(7)

#: Status codes of a run (``errors.Status`` has the same values; a test checks).
STATUSES = ("success", "terminal", "max_steps", "max_events", "step_too_small", "nonfinite",
            "intersection", "zeno")
(ST_SUCCESS, ST_TERMINAL, ST_MAX_STEPS, ST_MAX_EVENTS, ST_STEP_TOO_SMALL, ST_NONFINITE,
 ST_INTERSECTION, ST_ZENO) = range(len(STATUSES))

#: Why sliding cannot start on an intersection (the run then ends with ``ST_INTERSECTION``):
#: it can (the weights of the multilinear rule lie in ``[0, 1]^k``); more surfaces than
#: ``MULTI_MAX``; a corner mode missing (no switch joins a corner's variant across one of the
#: surfaces); no weights (the rule's Newton iteration met a singular matrix or ran away);
#: weights outside ``[0, 1]^k`` (the intersection does not attract the motion).
INTERSECTION_CAUSES = ("attracting", "too_many", "no_corner", "no_weights", "not_attracting")
IX_ATTRACTING, IX_TOO_MANY, IX_NO_CORNER, IX_NO_WEIGHTS, IX_NOT_ATTRACTING = range(5)

#: Kinds of switching surfaces (``stab`` column 3): Filippov (cross or slide) or continuous
#: (only a derivative jumps: always cross); sliding methods (column 4).
SWITCH_KINDS = ("filippov", "continuous")
SW_FILIPPOV, SW_CONTINUOUS = range(2)
SLIDE_METHODS = ("convex", "utkin")
SLIDE_CONVEX, SLIDE_UTKIN = range(2)

#: Interval kinds of the node list: a step, a jump at an event, a chattering gap.
INTERVAL_KINDS = ("step", "jump", "chatter_gap")
IV_STEP, IV_JUMP, IV_CHATTER = range(3)

#: What a run stores (``KERNEL_OPTIONS`` field ``save``): the nodes of events and the end; every step
#: with its dense output; every step with its length only (the dense output rebuilt on demand).
SAVE_MODES = ("events", "dense", "nodes")
SAVE_EVENTS, SAVE_DENSE, SAVE_NODES = range(3)

#: Variational equations (field ``variational``): none; Phi through every event; Phi
#: per segment.
VAR_MODES = ("none", "global", "segments")
VAR_NONE, VAR_GLOBAL, VAR_SEGMENTS = range(3)

# --------------------------------------------------------------------------------------
# the kernel's tables
# --------------------------------------------------------------------------------------

#: The event table: one record per model event (numba reads a field of a record as it read a
#: column of a 2-d array). ``kind``: ``EV_*``; ``target``: the mode after a transition (-1:
#: unchanged); ``time_dependent``: 1 if the event's surface depends on t explicitly.
EVENT_TABLE = np.dtype([("surface", np.int64), ("direction", np.int64), ("kind", np.int64),
                        ("target", np.int64), ("terminal", np.int64), ("has_reset", np.int64),
                        ("time_dependent", np.int64)])

#: The switch table: one record per switching surface between two modes. ``above``/``below``:
#: the mode on either side; ``kind``: ``SW_*``; ``sliding``: ``SLIDE_*`` (the sliding vector
#: field); ``time_dependent`` as in :data:`EVENT_TABLE`.
#:
#: The Filippov switches of a sign family on one of its surfaces are a *block*: ``2**(k-1)``
#: consecutive records, ordered by the variant above them, each joining variant ``first + c``
#: (bit ``bit`` of ``c`` clear, above) to ``first + (c | 1 << bit)`` (below). A record of a
#: block holds its first record ``block``, the record after its last ``block_end``, the
#: family's first variant ``first`` and the ``bit`` the switch flips, so that the record of a
#: block touching a variant is found by arithmetic, not by a search of the table: at a chain
#: of ten contacts the table has 5120 records and a search through it at every event cost
#: more than the integration. ``block = -1`` outside blocks (the other fields unused).
SWITCH_TABLE = np.dtype([("surface", np.int64), ("above", np.int64), ("below", np.int64),
                         ("kind", np.int64), ("sliding", np.int64), ("time_dependent", np.int64),
                         ("block", np.int64), ("block_end", np.int64), ("first", np.int64),
                         ("bit", np.int64)])


# --------------------------------------------------------------------------------------
# the kernel's options
# --------------------------------------------------------------------------------------

#: The options of one kernel run, by name: one record (a structured array of shape (1,),
#: which numba passes as cheaply as a plain array; a named tuple of these fields cost ~1.6 us
#: more per call to dispatch). The kernel reads ``opts.rtol`` from ``options[0]``. Built by
#: :func:`kernel_options` only.
KERNEL_OPTIONS = np.dtype([
    ("mode0", np.int64),               # mode at t0
    ("n_modes", np.int64),
    ("max_steps", np.int64),
    ("max_events", np.int64),
    ("method", np.int64),              # the tableau's code (its error estimator)
    ("variational", np.int64),         # VAR_*
    ("chatter", np.int64),             # 1: the complete-chattering map is on
    ("save", np.int64),                # SAVE_*
    ("stop_mask", np.int64),           # stop after a logged event: K_* bit mask (0: never) ...
    ("stop_ref", np.int64),            # ... of this event or switch (-1: any) ...
    ("stop_count", np.int64),          # ... the count-th time
    ("dkind0", np.int64),              # discrete state at t0: kind and index
    ("didx0", np.int64),
    ("exact", np.int64),               # 1: affine modes with harmonic forcing propagated exactly
    ("order", np.int64),               # exponent of the step-size control (0: from ``method``)
    ("rtol", np.float64),
    ("atol", np.float64),
    ("first_step", np.float64),        # 0: estimated
    ("max_step", np.float64),
    ("chatter_ratio", np.float64),     # negative: the default, where the chattering map is accurate
    ("chatter_velocity", np.float64),  # negative: the floor from the tolerances
    ("sliding_gain", np.float64),      # rate of the sliding field's stabilising term
    ("sample_t0", np.float64),         # stroboscopic samples at sample_t0 + k sample_dt ...
    ("sample_dt", np.float64),         # ... (<= 0: none)
])


def kernel_options(*, mode0: int, n_modes: int, max_steps: int, max_events: int, method: int,
                   variational: int = VAR_NONE, chatter: bool = True, save: int = SAVE_EVENTS,
                   stop: tuple[int, int, int] | None = None, dkind0: int = REGULAR,
                   didx0: int = -1, exact: int = 0, order: int = 0, rtol: float, atol: float,
                   first_step: float = 0.0, max_step: float = np.inf,
                   chatter_ratio: float, chatter_velocity: float = -1.0,
                   sliding_gain: float = 0.0,
                   sample: tuple[float, float] | None = None) -> np.ndarray:
    """The kernel's options (one record of :data:`KERNEL_OPTIONS`) from named values: integers
    (numpy's too, and bools) for the integer fields, real numbers for the others; anything else
    raises TypeError.

    ``stop``: ``(kind_mask, ref, count)``, stop after the ``count``-th logged event whose
    ``K_*`` kind has its bit set in ``kind_mask`` and whose event or switch index is ``ref``
    (-1: any). ``first_step`` 0: estimated. ``chatter_ratio`` negative: the default ratio, applied
    only where the chattering map is accurate; ``chatter_velocity`` negative: the floor from
    the tolerances. ``sample``: ``(t0, dt)`` of stroboscopic samples (``dt <= 0``: none).
    ``method``: the tableau's ``code`` (its error estimator), ``order`` its order (the
    exponent of the step-size control; 0: 5 for code 0, 8 for code 1)."""
    stop_mask, stop_ref, stop_count = stop if stop is not None else (0, 0, 0)
    sample_t0, sample_dt = sample if sample is not None else (0.0, 0.0)
    # an integer field takes an integer (numpy would truncate 1.5 silently), a float field a
    # real number (numpy would store None as NaN); in the order of KERNEL_OPTIONS
    i, f = operator.index, float
    row = (i(mode0), i(n_modes), i(max_steps), i(max_events), i(method), i(variational),
           1 if chatter else 0, i(save), i(stop_mask), i(stop_ref), i(stop_count), i(dkind0),
           i(didx0), i(exact), i(order), f(rtol), f(atol), f(first_step), f(max_step),
           f(chatter_ratio), f(chatter_velocity), f(sliding_gain), f(sample_t0), f(sample_dt))
    return np.array([row], dtype=KERNEL_OPTIONS)


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
