"""Argument checks shared by every public entry point.

Each function checks one argument and returns it normalised (a ``float``, an ``int``, an
array), or raises :class:`pwsdyn.errors.ArgumentError` whose message names the argument, what
it must be and what it got. Entry points call them first, before any model is compiled or any
memory is allocated, so a bad call costs nothing and leaves nothing behind.

Conventions
-----------
* Numbers are Python or NumPy ints and floats; ``bool`` is refused where a number is expected
  (``True`` is an ``int`` to Python but never a meaningful tolerance or count).
* Every comparison is written so that NaN fails it (``not (lo < x)``): NaN is refused
  everywhere, and infinities unless ``allow_inf``.
* Counts (steps, periods, iterations, segments) are ints within :data:`MAX_COUNT`, far below
  the int64 range of the compiled kernels.
* :func:`memory` refuses a call that would allocate more than :data:`MEMORY_LIMIT` bytes of
  result arrays, naming the size it would need (raise the limit to allow it).

Time resolution
---------------
The kernel resolves time to ``ulp(t) = eps * max(1, |t|)`` and takes no step shorter than four
of those (a shorter remaining span counts as reached). A span ``(t0, t_end)`` is therefore
accepted only if ``t_end - t0 >= TIME_RESOLUTION_ULPS * eps * max(1, |t0|, |t_end|)`` (1024
ulps, i.e. 256 of the shortest steps, the time resolved to 1e-3 of the span). Below that the
span cannot be integrated at all (for example ``(1e16, 1e16 + 2)``: the spacing of doubles
at 1e16 is 2, so the run would "succeed" after zero steps) or an event in it cannot be
located. The same rule applies to every period, segment or interval an analysis integrates
over (a forcing period at the time it is reached, a Lyapunov segment, a shooting period).
"""

from __future__ import annotations

import math
import numbers
import os
import reprlib
from typing import Mapping

import numpy as np

from .errors import ArgumentError

#: Largest accepted count (steps, events, periods, iterations, segments, grid points, ...).
MAX_COUNT = 10**12
#: Largest total size in bytes of the arrays one call may allocate for its result.
MEMORY_LIMIT = 2 * 2**30
#: A time span must hold this many time-resolution units ``eps * max(1, |t|)``.
TIME_RESOLUTION_ULPS = 1024

_EPS = float(np.finfo(float).eps)
_repr = reprlib.Repr()
_repr.maxstring = 60
_repr.maxother = 60
_repr.maxlist = _repr.maxtuple = _repr.maxdict = 6


def describe(value) -> str:
    """A short ``repr`` of ``value`` for a message (long containers and strings cut)."""
    try:
        if isinstance(value, np.ndarray):
            text = np.array2string(value, threshold=8, precision=6)
            return f"array {text} of shape {value.shape}, dtype {value.dtype}"
        return _repr.repr(value)
    except Exception:  # a value whose repr fails still gets a message
        return f"<{type(value).__name__}>"


def fail(name: str, must: str, value, *, detail: str = "") -> ArgumentError:
    """The error for argument ``name`` that ``must`` be something and got ``value``."""
    msg = f"`{name}` must be {must}, got {describe(value)}"
    return ArgumentError(msg + (f" ({detail})" if detail else ""))


def is_real(value) -> bool:
    """A real number (Python or NumPy int or float, or a 0-d numeric array), not a bool."""
    if type(value) is float or type(value) is int:
        return True     # most calls: the abstract-class check below costs ten times more
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, numbers.Real):
        return True
    return (isinstance(value, np.ndarray) and value.ndim == 0
            and value.dtype.kind in "iuf")


def is_int(value) -> bool:
    """A Python or NumPy integer, not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _as_float(name, value, must):
    if not is_real(value):
        raise fail(name, must, value)
    try:
        return float(value)
    except (OverflowError, ValueError, TypeError):
        raise fail(name, must, value, detail="not representable as a double") from None


def number(name: str, value, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, hi_open: bool = False, allow_inf: bool = False,
           allow_none: bool = False, must: str | None = None) -> float | None:
    """A real number, finite unless ``allow_inf``, within ``[lo, hi]`` (ends open as asked).

    ``None`` is returned as is where ``allow_none``."""
    if value is None and allow_none:
        return None
    if must is None:
        parts = ["a finite number" if not allow_inf else "a number (not NaN)"]
        if lo is not None:
            parts.append(f"{'>' if lo_open else '>='} {lo:g}")
        if hi is not None:
            parts.append(f"{'<' if hi_open else '<='} {hi:g}")
        must = " ".join(parts[:1]) + (" " + " and ".join(parts[1:]) if parts[1:] else "")
        if allow_none:
            must += " or None"
    v = _as_float(name, value, must)
    if math.isnan(v) or (not allow_inf and not math.isfinite(v)):
        raise fail(name, must, value)
    if lo is not None and not (v > lo if lo_open else v >= lo):
        raise fail(name, must, value)
    if hi is not None and not (v < hi if hi_open else v <= hi):
        raise fail(name, must, value)
    return v


def positive(name: str, value, *, allow_inf: bool = False, allow_none: bool = False,
             hi: float | None = None) -> float | None:
    """A number ``> 0`` (finite unless ``allow_inf``)."""
    return number(name, value, lo=0.0, lo_open=True, hi=hi, allow_inf=allow_inf,
                  allow_none=allow_none)


def nonnegative(name: str, value, *, allow_none: bool = False) -> float | None:
    """A finite number ``>= 0``."""
    return number(name, value, lo=0.0, allow_none=allow_none)


def tolerance(name: str, value) -> float:
    """A relative tolerance: a number in the open interval ``(0, 1)``."""
    return number(name, value, lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                  must="a number in the open interval (0, 1)")


def integer(name: str, value, *, lo: int = 0, hi: int = MAX_COUNT,
            allow_none: bool = False) -> int | None:
    """An int (Python or NumPy, not bool) in ``[lo, hi]``."""
    if value is None and allow_none:
        return None
    must = f"an integer in [{lo}, {'10**12' if hi == MAX_COUNT else hi}]"
    if allow_none:
        must += " or None"
    if not is_int(value) or not lo <= int(value) <= hi:
        raise fail(name, must, value)
    return int(value)


def flag(name: str, value) -> bool:
    """``True`` or ``False`` (also NumPy bools)."""
    if not isinstance(value, (bool, np.bool_)):
        raise fail(name, "True or False", value)
    return bool(value)


def text(name: str, value, *, allow_none: bool = False) -> str | None:
    """A non-empty string."""
    if value is None and allow_none:
        return None
    if not isinstance(value, str) or not value:
        raise fail(name, "a non-empty string" + (" or None" if allow_none else ""), value)
    return value


def choice(name: str, value, options) -> str:
    """One of the strings ``options``."""
    opts = list(options)
    if not isinstance(value, str) or value not in opts:
        raise fail(name, f"one of {opts}", value)
    return value


def mapping(name: str, value, *, allow_none: bool = True) -> dict:
    """A mapping (``None`` gives ``{}`` where ``allow_none``)."""
    if value is None and allow_none:
        return {}
    if not isinstance(value, Mapping):
        raise fail(name, "a dict" + (" or None" if allow_none else ""), value)
    return dict(value)


def path(name: str, value, *, allow_none: bool = True):
    """A path (``str`` or ``os.PathLike``), or ``None``."""
    if value is None and allow_none:
        return None
    if not is_path(value):
        raise fail(name, "a file or directory path" + (" or None" if allow_none else ""), value)
    return value


def is_path(value) -> bool:
    """A non-empty ``str`` or ``os.PathLike`` naming a text path without NUL characters."""
    if not isinstance(value, (str, os.PathLike)):
        return False
    try:
        fs = os.fspath(value)
    except TypeError:
        return False
    return isinstance(fs, str) and bool(fs) and "\x00" not in fs


def _real_entries(name: str, value) -> np.ndarray:
    """``value`` (a sequence or array of real numbers) as a 1-D float array."""
    must = "a sequence of finite numbers"
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise fail(name, must, value)
        try:
            return np.asarray(value, dtype=float).reshape(-1)
        except (OverflowError, ValueError):
            raise fail(name, must, value) from None
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") \
            or not hasattr(value, "__iter__"):
        raise fail(name, must, value)
    out = np.empty(len(value))
    for i, v in enumerate(value):
        if not is_real(v):
            raise fail(name, must, value, detail=f"entry {i} is {describe(v)}")
        try:
            out[i] = float(v)
        except (OverflowError, ValueError):
            raise fail(name, must, value, detail=f"entry {i} is not representable") from None
    return out


def vector(name: str, value, *, size: int | None = None, finite: bool = True,
           names=None) -> np.ndarray:
    """A 1-D float vector of real numbers (``size`` entries), finite where ``finite``.

    ``names`` (e.g. the state names) also allows a dict by name."""
    if names is not None and isinstance(value, Mapping):
        names = list(names)
        unknown = sorted(set(map(str, value)) - set(names))
        if unknown or not all(isinstance(k, str) for k in value):
            raise ArgumentError(f"`{name}` names unknown state(s) {unknown}; states are "
                                f"{names}")
        missing = [s for s in names if s not in value]
        if missing:
            raise ArgumentError(f"`{name}` is missing state(s) {missing}")
        vec = np.empty(len(names))
        for i, s in enumerate(names):
            vec[i] = number(f"{name}[{s!r}]", value[s])
        return vec
    what = ("a sequence of numbers" if names is None else
            "a sequence of numbers or a dict by state name")
    try:
        vec = _real_entries(name, value)
    except ArgumentError as exc:
        raise ArgumentError(str(exc).replace("a sequence of finite numbers", what)) from None
    if size is not None and vec.shape != (size,):
        states = f" (states {list(names)})" if names is not None else ""
        raise ArgumentError(f"`{name}` must have {size} entries{states}, got {vec.size}")
    if finite and not np.all(np.isfinite(vec)):
        raise ArgumentError(f"`{name}` must be finite, got {describe(value)}")
    return vec


def matrix(name: str, value, *, square: bool = True) -> np.ndarray:
    """A finite 2-D float matrix (square where ``square``) with at least one entry."""
    must = "a finite square matrix of numbers" if square else "a finite matrix of numbers"
    if isinstance(value, (str, bytes, Mapping)) or value is None or is_real(value):
        raise fail(name, must, value)
    try:
        arr = np.asarray(value)
    except Exception:
        raise fail(name, must, value) from None
    if arr.dtype.kind not in "iuf" or arr.ndim != 2 or arr.size == 0 \
            or (square and arr.shape[0] != arr.shape[1]):
        raise fail(name, must, value)
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise fail(name, must, value)
    return arr


def resolution(t: float) -> float:
    """The kernel's resolution of the time variable at ``t``: ``eps * max(1, |t|)``."""
    return _EPS * max(1.0, abs(t))


def time_span(name: str, t0: float, t_end: float, *, what: str = "the span") -> None:
    """``t_end > t0``, both finite, and ``t_end - t0`` resolvable (module docstring)."""
    if not (math.isfinite(t0) and math.isfinite(t_end)):
        raise ArgumentError(f"`{name}`: {what} from t0 = {t0!r} to {t_end!r} must be finite")
    if not t_end > t0:
        raise ArgumentError(f"`{name}` must have t_end > t0, got t0 = {t0!r}, t_end = "
                            f"{t_end!r}")
    need = TIME_RESOLUTION_ULPS * resolution(max(abs(t0), abs(t_end)))
    if not (t_end - t0 >= need):
        raise ArgumentError(
            f"`{name}`: {what} ({t_end - t0:.6g} long, from t0 = {t0!r}) is not resolved by "
            f"double-precision time there: it must be at least {TIME_RESOLUTION_ULPS} times the "
            f"time resolution eps*max(1, |t|), i.e. >= {need:.6g} (shift the time origin "
            f"towards 0 or lengthen it)")


def time_window(name: str, t0: float, length: float, *, what: str = "the span") -> None:
    """A span of ``length`` from ``t0``: both finite, ``length > 0``, ``t0 + length`` finite,
    and ``length`` resolvable at ``max(|t0|, |t0 + length|)`` (module docstring). Use it
    where the length is known apart from the end (a period, a segment): ``t0 + length`` may
    round to ``t0``."""
    if not (math.isfinite(t0) and math.isfinite(length) and length > 0
            and math.isfinite(t0 + length)):
        raise ArgumentError(f"`{name}`: {what} of length {length!r} from t0 = {t0!r} must be "
                            f"finite and positive")
    need = TIME_RESOLUTION_ULPS * resolution(max(abs(t0), abs(t0 + length)))
    if not length >= need:
        raise ArgumentError(
            f"`{name}`: {what} ({length:.6g} long, from t0 = {t0!r}) is not resolved by "
            f"double-precision time there: it must be at least {TIME_RESOLUTION_ULPS} times the "
            f"time resolution eps*max(1, |t|), i.e. >= {need:.6g} (shift the time origin "
            f"towards 0 or lengthen it)")


def memory(what: str, nbytes: float) -> None:
    """Refuse a call whose result arrays would need more than :data:`MEMORY_LIMIT` bytes."""
    if not nbytes <= MEMORY_LIMIT:
        raise ArgumentError(
            f"{what} would allocate about {_size(nbytes)} for its result, more than the limit "
            f"of {_size(MEMORY_LIMIT)} (pwsdyn._validate.MEMORY_LIMIT): reduce it")


def _size(nbytes: float) -> str:
    if not math.isfinite(nbytes):
        return "an unbounded amount of memory"
    for unit, k in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= k:
            return f"{nbytes / k:.3g} {unit}"
    return f"{int(nbytes)} bytes"


def state_vector(model, x0, *, name: str = "x0") -> np.ndarray:
    """``x0`` as a float vector of the states of ``model``: a sequence in state order or a
    dict by state name.

    Raises :class:`~pwsdyn.errors.ArgumentError` naming ``name`` for a wrong type, length,
    unknown or missing state, an entry that is not a real number, or a non-finite entry."""
    if x0 is None:
        raise fail(name, f"a sequence of {model.n_states} numbers or a dict by state name", x0)
    return vector(name, x0, size=model.n_states, names=model.states)


__all__ = ["MAX_COUNT", "MEMORY_LIMIT", "TIME_RESOLUTION_ULPS", "choice", "describe", "fail",
           "flag", "integer", "is_int", "is_path", "is_real", "mapping", "matrix", "memory",
           "nonnegative", "number", "path", "positive", "resolution", "state_vector", "text",
           "time_span", "time_window", "tolerance", "vector"]
