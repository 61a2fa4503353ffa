"""What flow models (:mod:`pwsdyn.model.spec`) and map models (:mod:`pwsdyn.model.maps`)
share: the rules for names, the checks of states, parameters and annotations, the location of
a field in the model file for error messages, and the symbolic system both are built on.

It sits below both, so the two kinds of model read their files with the same rules without
importing each other.
"""

from __future__ import annotations

import math
import re
from typing import Any, Mapping

import numpy as np
import sympy as sp

from .._codes import MODEL_EVENT_KINDS
from ..errors import ArgumentError, ModelError

#: Name of the independent variable in expressions.
TIME = "t"
#: Kinds of model events (the one list, shared with the integrator's codes).
EVENT_KINDS = MODEL_EVENT_KINDS
#: Longest name of a state, parameter, definition, mode, event or switch.
MAX_NAME_LENGTH = 64
#: Longest model name (free text, shown in files and figures; never part of generated code).
MAX_MODEL_NAME_LENGTH = 128
# ``\Z``, not ``$``: ``$`` also matches before a final newline ("x\n" is not a name)
_NAME_RE = re.compile(rf"[A-Za-z_][A-Za-z0-9_]{{0,{MAX_NAME_LENGTH - 1}}}\Z")
# time, the constants of expressions, and the switching variable of Utkin's family
# (pwsdyn.model.discontinuities.U_SYMBOL): a state of that name would be the same symbol
_RESERVED = {TIME, "pi", "e_const", "inf", "u_switch"}


def _is_name(s) -> bool:
    """An identifier of at most :data:`MAX_NAME_LENGTH` ASCII letters, digits and ``_``."""
    return isinstance(s, str) and _NAME_RE.match(s) is not None


def check_identifiers(states, parameters, origin: str = "<model>") -> None:
    """Refuse state and parameter names that are not plain identifiers or are reserved: they
    become identifiers of generated code (:mod:`pwsdyn.model.codegen`)."""
    for kind, names in (("state", states), ("parameter", parameters)):
        for s in names:
            if not _is_name(s) or s in _RESERVED:
                raise ModelError(f"invalid {kind} name {s!r}: names are identifiers of at most "
                                 f"{MAX_NAME_LENGTH} ASCII letters, digits and '_', not "
                                 f"{sorted(_RESERVED)}", source=origin)


def check_text(text, W: "_Where", fieldname: str, limit: int, value=None) -> str:
    """Free text of a model (its name, a unit, a description): a string of 1 to ``limit``
    printable characters -- no control characters, line breaks or bidirectional overrides,
    which could rewrite what a terminal or a file shows. Errors name ``fieldname``."""
    if not isinstance(text, str) or not text.strip():
        raise W.error(f"`{fieldname}` must be a non-empty string", fieldname, value)
    bad = next((c for c in text if not c.isprintable()), None)
    if bad is not None:
        raise W.error(f"`{fieldname}` contains the non-printable character U+{ord(bad):04X}; "
                      "use printable characters only", fieldname, value)
    if len(text) > limit:
        raise W.error(f"`{fieldname}` is {len(text)} characters long; at most {limit} are "
                      "allowed", fieldname, value)
    return text


def check_model_name(name, W: "_Where") -> str:
    """The model's ``name``: text of 1 to :data:`MAX_MODEL_NAME_LENGTH` printable characters
    (:func:`check_text`)."""
    return check_text(name, W, "name", MAX_MODEL_NAME_LENGTH)


#: Longest unit in a model's ``[units]`` table (UDUNITS strings such as ``"m s-2"``).
MAX_UNIT_LENGTH = 64
#: Longest entry of a model's ``[descriptions]`` table.
MAX_DESCRIPTION_LENGTH = 256
#: The optional tables of text about the model's quantities, with the limits of their entries.
ANNOTATION_TABLES = {"units": MAX_UNIT_LENGTH, "descriptions": MAX_DESCRIPTION_LENGTH}


def check_annotations(data: dict, states, parameters, W: "_Where", *, time: bool = True
                      ) -> tuple[dict, dict]:
    """The optional ``[units]`` and ``[descriptions]`` tables: ``name = "text"`` for states,
    parameters and (flows) the time ``t``, e.g. ``y = "m"`` and ``y = "height above the
    table"``. Unknown names, values that are not strings, and text that is empty, too long
    or not printable are refused naming the file, line and field. Returns the two tables
    (name -> text; empty when absent). They document the model (files, figures) and never
    enter its digest."""
    names = ([TIME] if time else []) + list(states) + list(parameters)
    out = []
    for table, limit in ANNOTATION_TABLES.items():
        raw = data.get(table)
        if raw is None:
            out.append({})
            continue
        if not isinstance(raw, dict):
            raise W.error(f"`{table}` must be a table of name = \"text\" (states, parameters"
                          + (f", time {TIME!r}" if time else "") + ")", table)
        entries = {}
        for k, v in raw.items():
            if k not in names:
                known = (f"states are {list(states)}, parameters are {list(parameters)}"
                         + (f", time is {TIME!r}" if time else " (a map has no time)"))
                raise W.error(f"`{table}` names unknown state or parameter {k!r}; {known}",
                              f"{table}.{k}")
            if not isinstance(v, str):
                raise W.error(f"`{table}.{k}` must be a string, got {type(v).__name__} "
                              f"{v!r}", f"{table}.{k}")
            entries[k] = check_text(v, W, f"{table}.{k}", limit, v)
        out.append(entries)
    return out[0], out[1]


def default_parameters(parameters: dict, defaults) -> dict:
    """The parameter values a run uses when the caller gives none: the ``[parameters]``
    table with the model's ``[defaults] params`` over it (both checked already)."""
    values = dict(parameters)
    if isinstance(defaults, dict):
        for k, v in (defaults.get("params") or {}).items():
            values[k] = float(v)
    return values


class SymbolicSystem:
    """What flows (:class:`~pwsdyn.model.spec.Model`) and maps
    (:class:`~pwsdyn.model.maps.MapModel`) share: symbols of states and parameters, and
    parameter values by name."""

    @property
    def state_symbols(self) -> tuple:
        return tuple(sp.Symbol(s, real=True) for s in self.states)

    @property
    def parameter_symbols(self) -> tuple:
        return tuple(sp.Symbol(p, real=True) for p in self.parameters)

    @property
    def n_states(self) -> int:
        return len(self.states)

    @property
    def defaults(self) -> dict:
        """The model's ``[defaults]`` table (``x0``, ``t0``, ``t_end``, ``params``; checked
        when the model was loaded), ``{}`` when it has none. Its ``params`` are already in
        ``parameters``."""
        d = (self.spec or {}).get("defaults")
        return d if isinstance(d, dict) else {}

    def unit(self, name: str) -> str | None:
        """The unit of a state, parameter or the time ``t`` from the ``[units]`` table, or
        ``None`` where the model gives none."""
        return (getattr(self, "units", None) or {}).get(name)

    def describe(self, name: str) -> str | None:
        """The description of a state, parameter or the time ``t`` from the
        ``[descriptions]`` table, or ``None``."""
        return (getattr(self, "descriptions", None) or {}).get(name)

    def parameter_vector(self, params: Mapping[str, float] | None = None):
        """Default parameter values overridden by ``params`` (by name), as a float array.

        The defaults are ``parameters``: the ``[parameters]`` table with the model's
        ``[defaults] params`` over it -- the values the command line uses too.

        Raises :class:`~pwsdyn.errors.ArgumentError` (a ``ValueError``) naming an unknown
        parameter, a value that is not a real number (a string, ``None``, a bool) or a
        non-finite value, or ``params`` that is not a mapping.
        """
        if params is None or (type(params) is dict and not params):
            # the defaults (most calls): in the order of ``parameters``, as below
            vals = list(self.parameters.values())
            try:
                finite = all(map(math.isfinite, vals))
            except (TypeError, OverflowError):
                finite = False      # reported below
            if finite:
                return np.array(vals, dtype=float)
        from .._validate import describe, is_real

        if params is not None and not isinstance(params, Mapping):
            raise ArgumentError(f"`params` must be a dict of parameter values by name or None, "
                                f"got {describe(params)}")
        values = dict(self.parameters)
        for k, v in (params or {}).items():
            if not isinstance(k, str) or k not in values:
                raise ArgumentError(f"unknown parameter {k!r} for model {self.name!r}; "
                                    f"parameters are {list(self.parameters)}")
            if not is_real(v):
                raise ArgumentError(f"parameter {k!r} must be a number, got {describe(v)}")
            try:
                values[k] = float(v)
            except (OverflowError, TypeError, ValueError):
                raise ArgumentError(f"parameter {k!r} must be a number, got "
                                    f"{describe(v)}") from None
        p = np.array([values[k] for k in self.parameters], dtype=float)
        bad = [k for k, v in zip(self.parameters, p) if not math.isfinite(v)]
        if bad:
            raise ArgumentError(f"parameter(s) {', '.join(bad)} of model {self.name!r} must be "
                                f"finite, got {[values[k] for k in bad]}")
        return p


class _Where:
    """Finds the line of a field in the TOML text for error messages (best effort)."""

    def __init__(self, origin: str, text: str | None):
        self.origin = origin
        self.lines = text.splitlines() if text else []

    def _table(self, name: str) -> tuple[int, int] | None:
        """Lines ``(header, end]`` of the table ``[name]`` (to the next header), if any."""
        head = re.compile(rf"^\s*\[\s*{re.escape(name)}\s*\]\s*(#.*)?$")
        for i, ln in enumerate(self.lines):
            if head.match(ln):
                end = next((j for j in range(i + 1, len(self.lines))
                            if self.lines[j].lstrip().startswith("[")), len(self.lines))
                return i + 1, end
        return None

    def line(self, key: str, value: Any = None) -> int | None:
        # the innermost plain table holding the key ([modes.flight] for modes.flight.y)
        parts = key.split(".")
        table = next((t for t in (self._table(".".join(parts[:k]))
                                  for k in range(len(parts) - 1, 0, -1)) if t is not None),
                     None)
        key = key.split(".")[-1]
        key = re.sub(r"\[\d+\]$", "", key)
        pat = re.compile(rf"^\s*(\[+\s*)?[\"']?{re.escape(key)}[\"']?\s*(=|\]|\.)")
        hits = [i + 1 for i, ln in enumerate(self.lines) if pat.search(ln)]
        inside = [h for h in hits if table[0] < h <= table[1]] if table is not None else []
        # a key of a plain table ([units], [defaults], [modes.m]): its line within that table
        hits = inside or hits
        if value is not None and isinstance(value, str):
            sharp = [h for h in hits if value in self.lines[h - 1]]
            if sharp:
                return sharp[0]
            if inside:
                return inside[0]
            anywhere = [i + 1 for i, ln in enumerate(self.lines) if value in ln]
            if anywhere:
                return anywhere[0]
        return hits[0] if hits else None

    def error(self, msg: str, fieldname: str, value: Any = None) -> ModelError:
        return ModelError(msg, source=self.origin, field=fieldname,
                          line=self.line(fieldname, value))


def states_and_parameters(data: dict, W: "_Where", what: str) -> tuple[list, dict]:
    """The validated ``states`` list and ``parameters`` table (name -> float default) of a
    model or map definition; errors name the field and its line."""
    states = data.get("states")
    if not isinstance(states, list) or not states:
        raise W.error(f"a {what} needs at least one state (a non-empty list `states`)",
                      "states")
    for s in states:
        if not _is_name(s) or s in _RESERVED:
            raise W.error(f"invalid state name {s!r}: a state is an identifier of at most "
                          f"{MAX_NAME_LENGTH} ASCII letters, digits and '_', not one of "
                          f"{sorted(_RESERVED)}", "states", str(s))
    if len(set(states)) != len(states):
        raise W.error("duplicate state names", "states")
    params_raw = data.get("parameters", {})
    if not isinstance(params_raw, dict):
        raise W.error("`parameters` must be a table of name = default value", "parameters")
    parameters = {}
    for k, v in params_raw.items():
        if not _is_name(k) or k in _RESERVED or k in states:
            raise W.error(f"invalid or clashing parameter name {k!r}: a parameter is an "
                          f"identifier of at most {MAX_NAME_LENGTH} ASCII letters, digits and "
                          f"'_', not a state or one of {sorted(_RESERVED)}", f"parameters.{k}")
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise W.error(f"parameter {k!r} must have a numeric default, got {v!r}",
                          f"parameters.{k}")
        if not math.isfinite(float(v)):
            raise W.error(f"parameter {k!r} must be finite, got {v!r}", f"parameters.{k}")
        parameters[k] = float(v)
    return states, parameters
