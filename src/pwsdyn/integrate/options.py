"""The integrator's options: their defaults, their checks, and what the kernel makes of them.

:data:`DEFAULTS` lists every option of :func:`pwsdyn.simulate` (documented there);
:func:`integrator_options` merges a caller's options over them and checks each once per set
of values (loops pass the same options on every call). :func:`kernel_tables` builds the
kernel's event and switch tables once per model and sliding method; :func:`resolve_method`,
``_exact_code`` and ``_max_step`` turn the options into the kernel's option record
(``_codes.kernel_options``), which :mod:`pwsdyn.integrate.compiled`
builds for each run.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError
from ..model.affine import affine_structure
from ..model.codegen import CompiledModel
from ._codes import EVENT_TABLE, SW_FILIPPOV, SWITCH_TABLE
from .tableaus import METHODS

#: Default options of :func:`~pwsdyn.simulate` (each documented there).
DEFAULTS = dict(method="auto", exact="auto", rtol=1e-10, atol=1e-12, first_step=None,
                max_step=math.inf, max_steps=1_000_000, max_events=100_000, chatter=True,
                chatter_ratio=None, chatter_velocity=None, sliding="convex", sliding_gain=0.0,
                variational=False, dense=True, mode=None, throw=True)

#: Ratio of the impact speed to the largest of its sequence below which the chattering map
#: applies by default, where it is accurate (option ``chatter_ratio``).
DEFAULT_CHATTER_RATIO = 1e-4

#: ``method="auto"`` takes the 8th-order pair below this relative tolerance, RK45 from it on
#: (measured: ``benchmarks/bench_defaults.py``).
AUTO_DOP853_BELOW = 1e-7

#: Sliding methods (option ``sliding``) and their kernel codes.
SLIDING_METHODS = {"convex": 0, "utkin": 1}


def integrator_options(options: Mapping, caller: str, reserved=()) -> dict:
    """``options`` merged over :data:`DEFAULTS` and checked (:func:`check_options`), after
    rejecting unknown names and those the caller sets itself (``reserved``), with an
    :class:`~pwsdyn.errors.ArgumentError` (a ``TypeError``) naming ``caller``."""
    bad = sorted(set(options) & set(reserved)) if reserved else None
    if bad:
        raise ArgumentError(f"{caller}: option(s) {bad} are set by {caller} itself; remove them")
    if not options.keys() <= DEFAULTS.keys():
        unknown = sorted(set(options) - set(DEFAULTS), key=str)
        raise ArgumentError(f"{caller} got unexpected keyword argument(s) {unknown}; "
                            f"integrator options are {sorted(set(DEFAULTS) - set(reserved))}")
    opts = {**DEFAULTS, **options}
    _check_options(opts)
    return opts



def check_mode(model, opts) -> None:
    """The ``mode`` option names a mode of ``model`` (or is None)."""
    mode = opts.get("mode")
    if mode is None:
        return
    if not isinstance(mode, str):
        raise V.fail("mode", f"None or a mode name of model {model.name!r} "
                     f"{list(model.mode_names)}", mode)
    try:
        model.mode_index(mode)
    except ValueError:
        raise ArgumentError(f"`mode` must be a mode of model {model.name!r}: unknown mode "
                            f"{mode!r}; modes are {list(model.mode_names)}") from None


#: Largest step and event budgets (the kernel counts in int64).
MAX_BUDGET = V.MAX_COUNT


def check_options(opts) -> None:
    """Check every integrator option of a merged option dict (types, ranges, finiteness),
    raising :class:`~pwsdyn.errors.ArgumentError` naming the option."""
    if not isinstance(opts["method"], str) or (opts["method"] not in METHODS
                                                and opts["method"] != "auto"):
        raise V.fail("method", f"'auto' or one of {sorted(METHODS)}", opts["method"])
    if "exact" in opts and not (isinstance(opts["exact"], str) and opts["exact"] == "auto"):
        if not isinstance(opts["exact"], (bool, np.bool_)):
            raise V.fail("exact", "'auto', True or False", opts["exact"])
    for k in ("chatter", "variational", "dense", "throw"):
        if k in opts:
            V.flag(k, opts[k])
    for k in ("rtol", "atol"):
        V.positive(k, opts[k])
    if opts["rtol"] < 1e-15:
        raise ArgumentError("`rtol` below 1e-15 cannot be met in double precision, got "
                            f"{opts['rtol']!r}")
    if not opts["rtol"] < 1.0:
        raise V.fail("rtol", "a number in [1e-15, 1) (a relative tolerance)", opts["rtol"])
    for k in ("max_steps", "max_events"):
        V.integer(k, opts[k], lo=1, hi=MAX_BUDGET)
    V.positive("first_step", opts["first_step"], allow_none=True)
    V.positive("max_step", opts["max_step"], allow_inf=True)
    # >= 1: the chattering map applies at the first impact (ratio to the largest impact speed)
    V.positive("chatter_ratio", opts["chatter_ratio"], allow_none=True)
    V.nonnegative("chatter_velocity", opts["chatter_velocity"], allow_none=True)
    if not isinstance(opts.get("sliding", "convex"), str) \
            or opts.get("sliding", "convex") not in SLIDING_METHODS:
        raise V.fail("sliding", f"one of {sorted(SLIDING_METHODS)}", opts.get("sliding"))
    V.nonnegative("sliding_gain", opts.get("sliding_gain", 0.0))
    mode = opts.get("mode")
    if mode is not None and not isinstance(mode, str):
        raise V.fail("mode", "None or a mode name", mode)


#: Option sets that passed :func:`check_options`, as their items and the values' types: the
#: check is a function of the values and their types alone, and loops (sweeps, shooting,
#: continuation) pass the same options on every call.
_CHECKED: set = set()
_CHECKED_MAX = 512


def _check_options(opts):
    """:func:`check_options`, once per set of option values."""
    try:
        key = (tuple(opts.items()), tuple(map(type, opts.values())))
        known = key in _CHECKED
    except TypeError:       # an unhashable value: checked every time
        key, known = None, False
    if known:
        return
    check_options(opts)
    if key is not None:
        if len(_CHECKED) >= _CHECKED_MAX:
            _CHECKED.clear()
        _CHECKED.add(key)


def resolve_method(opts) -> str:
    """The Runge-Kutta pair that runs: ``method``, or for ``'auto'`` DOP853 below
    ``rtol = AUTO_DOP853_BELOW`` and RK45 from it on."""
    method = opts["method"]
    if method != "auto":
        return method
    return "DOP853" if opts["rtol"] < AUTO_DOP853_BELOW else "RK45"


def _exact_code(model, exact) -> int:
    """The kernel option ``exact``: 1 (the affine modes propagated exactly) for ``exact=True``, after
    checking that the model has one, and for ``'auto'`` (the kernel finds the affine modes;
    a model without any runs on the Runge-Kutta pair alone); 0 for False."""
    if isinstance(exact, str):
        return 1
    if exact:
        _check_exact(model)
        return 1
    return 0


def _max_step(model, p, max_step) -> float:
    """The largest step: the user's, else a quarter forcing period for forced models."""
    if math.isfinite(max_step) or model.forcing_period is None:
        return min(max_step, 1e300)
    fn = model.forcing_period_function
    # by the function and the parameter vector's bits (loops run at the same parameters;
    # the key holds the function, so its identity is not reused while the entry lives)
    key = (fn, p.dtype.str, p.tobytes()) if isinstance(p, np.ndarray) else None
    step = _PERIOD_STEPS.get(key)
    if step is None:
        period = fn(*p)
        step = period / 4.0 if math.isfinite(period) and period > 0 else 1e300
        if key is not None:
            if len(_PERIOD_STEPS) >= 1024:
                _PERIOD_STEPS.clear()
            _PERIOD_STEPS[key] = step
    return step


#: :func:`_max_step`'s default for forced models, by period function and parameters.
_PERIOD_STEPS: dict = {}


_TABLES: dict = {}
_AFFINE_CHECKED: set = set()


def _check_exact(model) -> None:
    """``exact=True`` needs at least one affine mode; say why each mode is not one."""
    if model.hash in _AFFINE_CHECKED:
        return
    aff = affine_structure(model)
    if not aff.any:
        why = "; ".join(f"mode {m.name!r}: {r}" for m, r in zip(model.modes, aff.reasons))
        raise ArgumentError(f"`exact=True` needs a mode that is affine in the states with harmonic "
                         f"forcing; model {model.name!r} has none ({why})")
    _AFFINE_CHECKED.add(model.hash)


def kernel_tables(cm: CompiledModel, sliding: str = "convex"):
    """The kernel's event table (records of ``EVENT_TABLE``: surface, direction, kind,
    target, terminal, has_reset, time_dependent), event activity per mode and switch table
    (records of ``SWITCH_TABLE``: surface, above, below, kind, sliding, time_dependent, and
    the layout of the sign families' blocks).
    Built once per model and sliding method: loops (shooting, sweeps) call the kernel many
    times."""
    key = (cm.model.hash, cm.source_path, sliding)
    if key not in _TABLES:
        _TABLES[key] = _build_kernel_tables(cm, sliding)
    return _TABLES[key]


def _build_kernel_tables(cm: CompiledModel, sliding: str):
    model = cm.model
    ne = len(model.events)
    tdep = cm.surface_time_dependent
    if tdep is None:
        tdep = np.zeros(len(model.surfaces), dtype=np.int64)
    etab = np.zeros(max(ne, 0), dtype=EVENT_TABLE)
    for j in range(ne):
        etab[j] = (cm.event_surface[j], cm.event_direction[j], cm.event_kind[j],
                   cm.event_target[j], cm.event_terminal[j], cm.event_has_reset[j],
                   tdep[cm.event_surface[j]])
    eact = np.ascontiguousarray(cm.event_active[:ne].astype(np.int64)).reshape(ne, len(model.modes))
    ns = len(model.switches)
    if sliding not in SLIDING_METHODS:
        raise ArgumentError(f"`sliding` must be one of {sorted(SLIDING_METHODS)}, got {sliding!r}")
    stab = np.zeros(ns, dtype=SWITCH_TABLE)
    kinds = cm.switch_kind if cm.switch_kind is not None else np.zeros(ns, dtype=np.int64)
    for s in range(ns):
        stab[s] = (cm.switch_surface[s], cm.switch_above[s], cm.switch_below[s], kinds[s],
                   SLIDING_METHODS[sliding], tdep[cm.switch_surface[s]], -1, -1, -1, -1)
    _mark_family_blocks(model, stab)
    return etab, eact, stab


def _mark_family_blocks(model, stab) -> None:
    """Mark the switches of each sign family on each of its surfaces as one block of the
    switch table (``SWITCH_TABLE``), where the records are laid out as a block must be:
    ``2**(k-1)`` consecutive Filippov switches on the surface, record ``r`` joining the
    variant ``first + c`` above, ``c`` the ``r``-th index with bit ``bit`` clear, to
    ``first + (c | 1 << bit)`` below (variant ``first + c`` lies below ``surfaces[j]`` where
    bit ``k - 1 - j`` of ``c`` is set). A family whose switches are laid out otherwise keeps
    unmarked records, which the kernel searches one by one: slower, never wrong."""
    for fam in model.families:
        k = len(fam.surfaces)
        half = 1 << (k - 1)
        for j, s0 in enumerate(fam.switches):
            if s0 < 0 or s0 + half > len(stab):
                continue
            bit = k - 1 - j
            rows = stab[s0:s0 + half]
            r = np.arange(half, dtype=np.int64)
            above = ((r >> bit) << (bit + 1)) | (r & ((1 << bit) - 1))
            if (np.all(rows["surface"] == fam.surfaces[j])
                    and np.all(rows["kind"] == SW_FILIPPOV)
                    and np.all(rows["above"] == fam.first + above)
                    and np.all(rows["below"] == fam.first + (above | (1 << bit)))):
                rows["block"] = s0
                rows["block_end"] = s0 + half
                rows["first"] = fam.first
                rows["bit"] = bit            # (rows is a view: the table itself)
