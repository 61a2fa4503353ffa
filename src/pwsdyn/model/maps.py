r"""Piecewise-smooth maps as models.

The slides ("Simulation: ODEs vs. Hybrid (ODEs and maps)") list discrete-time systems beside
flows: a map :math:`x_{k+1} = F_i(x_k)` whose definition :math:`F_i` changes across borders in
state space ("border crossing"). Nordmark's square-root normal form of a grazing impact,

.. math::

    x \mapsto \begin{cases} \mu + \lambda x & \text{for } x \le 0, \\
                            \mu - \sqrt{x} & \text{for } x > 0, \end{cases}

is the zoo's example (``sqrt-map``). A map model is data like a flow model: a TOML file or a
dict with ``kind = "map"``, states, parameters, optional definitions and either one smooth
map (``[map]``, a table of state = new value) or ordered ``[[pieces]]``, each with a
``condition`` (a boolean expression of the states and parameters; the first piece whose
condition holds is applied, and the last piece may omit its condition: "otherwise") and a
``map`` table. Expressions are parsed safely (:mod:`pwsdyn.model.expressions`), the Jacobian of
every piece is derived symbolically, and one numba function per model is generated and cached
on disk by the model hash, as for flows (:mod:`pwsdyn.model.codegen`)::

    step(x, p, out, jac, want_jac) -> piece index (or -1 if no piece applies)

The iteration loops (``orbit_kernel`` and ``lyapunov_kernel`` in ``pwsdyn.model._map_kernels``,
loaded on first use) take that function as a first-class numba function of one fixed
signature, so they are compiled once for all maps.
"""

from __future__ import annotations

import functools
import hashlib
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import sympy as sp
from ..errors import ModelError
from .cache import header, load_module
from ._map_step import (MAP_DIVERGED, MAP_NO_PIECE, MAP_NONFINITE, MAP_OK,  # noqa: F401
                        MAP_STEP_SIGNATURE, MAP_STEP_TYPE)
from ._printer import NumbaPrinter, unprintable
from .expressions import parse_expression
from .symbolic import (_RESERVED, SymbolicSystem, _Where, _is_name, check_annotations,
                       check_identifiers, check_model_name, default_parameters,
                       states_and_parameters)

_MAP_CODEGEN_VERSION = "3"
_NAME_OK = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_0123456789"
_TOP_KEYS = {"name", "kind", "description", "source", "reference", "states", "parameters",
             "definitions", "map", "pieces", "defaults", "notes", "units", "descriptions"}
_PIECE_KEYS = {"name", "condition", "map", "description"}
_DEFAULT_KEYS = {"x0", "t_end", "params"}



@dataclass(frozen=True)
class MapPiece:
    """One smooth piece of a map: applied where ``condition`` holds (``None``: everywhere
    not claimed by an earlier piece)."""

    name: str
    condition: Any
    exprs: tuple


@dataclass(frozen=True, eq=False)
class MapModel(SymbolicSystem):
    """A piecewise-smooth map ``x -> F_i(x)`` (symbolic). Create it with
    :func:`pwsdyn.load_model` from a file or dict with ``kind = "map"``.

    It offers the parts of :class:`~pwsdyn.model.spec.Model`'s interface that do not depend on
    time (``name``, ``states``, ``parameters``, ``parameter_vector``, ``hash``, ``spec``); a map
    has no modes, events or forcing period, and its ``mode_names`` are the names of its pieces.
    """

    name: str
    states: tuple
    parameters: dict
    pieces: tuple
    description: str = ""
    reference: str = ""
    definitions: dict = field(default_factory=dict)
    origin: str = "<dict>"
    spec: dict = field(default_factory=dict, repr=False)
    units: dict = field(default_factory=dict, repr=False)
    descriptions: dict = field(default_factory=dict, repr=False)
    text: str = field(default="", repr=False)

    kind = "map"
    is_map = True
    modes = ()
    events = ()
    switches = ()
    forcing_period = None
    initial_mode = 0

    @property
    def mode_names(self) -> tuple:
        return tuple(pc.name for pc in self.pieces)

    def forcing_period_value(self, params=None):
        """Maps have no forcing period (``None``); one iteration is their unit of time."""
        return None

    def forcing_period_at(self, p):
        """Maps have no forcing period (``None``)."""
        return None

    @functools.cached_property
    def hash(self) -> str:
        """A short hash (16 hex digits) of the map, for display and provenance; :attr:`digest`
        is the full one."""
        return self.digest[:16]

    @functools.cached_property
    def digest(self) -> str:
        """SHA-256 (64 hex digits) of everything that defines the compiled map (not its
        description); names the compiled module in the cache."""
        parts = ["map", self.name, repr(self.states), repr(list(self.parameters))]
        for pc in self.pieces:
            parts.append(f"piece {pc.name}: {sp.srepr(pc.condition)} {sp.srepr(pc.exprs)}")
        return hashlib.sha256("\n".join(parts).encode()).hexdigest()

    def __repr__(self):
        return (f"MapModel({self.name!r}, states={list(self.states)}, "
                f"pieces={list(self.mode_names)})")


def _fail(msg, origin, fieldname):
    return ModelError(msg, source=origin, field=fieldname)


def map_model_from_dict(data: dict, origin: str = "<dict>", text: str | None = None) -> MapModel:
    """Build and validate a :class:`MapModel` from a dict with the TOML file's structure.

    Raises
    ------
    ModelError
        A malformed map model; the message names the source and the field.
    """
    W = _Where(origin, text)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise W.error(f"unknown top-level key(s) {unknown} for a map model; allowed keys are "
                      f"{sorted(_TOP_KEYS)}", unknown[0])
    if "name" not in data:
        raise W.error("missing required field `name`", "name")
    name = check_model_name(data["name"], W)
    states, parameters = states_and_parameters(data, W, "map")

    names = {s: sp.Symbol(s, real=True) for s in states}
    names.update({p: sp.Symbol(p, real=True) for p in parameters})
    defs_raw = data.get("definitions", {})
    if not isinstance(defs_raw, dict):
        raise W.error("`definitions` must be a table of name = expression", "definitions")
    definitions = {}
    for k, v in defs_raw.items():
        if not _is_name(k) or k in names or k in _RESERVED:
            raise W.error(f"invalid or clashing definition name {k!r}", f"definitions.{k}")
        definitions[k] = names[k] = parse_expression(
            v, names, field=f"definitions.{k}", source=origin,
            line=W.line(k, v if isinstance(v, str) else None))

    def expr(val, fieldname, boolean=False):
        return parse_expression(val, names, field=fieldname, source=origin,
                                line=W.line(fieldname, val if isinstance(val, str) else None),
                                boolean=boolean)

    def map_table(tab, fieldname):
        if not isinstance(tab, dict):
            raise W.error(f"`{fieldname}` must be a table of state = new value", fieldname)
        extra = sorted(set(tab) - set(states))
        if extra:
            raise W.error(f"`{fieldname}` gives unknown state(s) {extra}; states are {states}",
                          fieldname, extra[0])
        # a state the table does not name is left unchanged
        return tuple(expr(tab[s], f"{fieldname}.{s}") if s in tab else names[s] for s in states)

    if ("map" in data) == ("pieces" in data):
        raise W.error("a map model needs exactly one of `map` (one smooth map) or "
                      "`[[pieces]]` (pieces with conditions)", "pieces" if "pieces" in data
                      else "map")
    pieces = []
    if "map" in data:
        pieces.append(MapPiece("map", None, map_table(data["map"], "map")))
    else:
        raw = data["pieces"]
        if not isinstance(raw, list) or not raw:
            raise W.error("`pieces` must be a non-empty array of tables ([[pieces]])", "pieces")
        for i, pc in enumerate(raw):
            pre = f"pieces[{i}]"
            if not isinstance(pc, dict):
                raise W.error("each piece must be a table", pre)
            bad = sorted(set(pc) - _PIECE_KEYS)
            if bad:
                raise W.error(f"unknown key(s) {bad} in piece; allowed keys are "
                              f"{sorted(_PIECE_KEYS)}", f"{pre}.{bad[0]}")
            pname = pc.get("name", f"piece{i}")
            if not _is_name(pname):
                raise W.error(f"invalid piece name {pname!r}", f"{pre}.name")
            if "map" not in pc:
                raise W.error(f"piece {pname!r} has no `map`", f"{pre}.map")
            cond = None
            if "condition" in pc:
                cond = expr(pc["condition"], f"{pre}.condition", boolean=True)
            elif i != len(raw) - 1:
                raise W.error(f"piece {pname!r} has no `condition`; only the last piece may "
                              "omit it (it then applies wherever no earlier piece does)",
                              f"{pre}.condition")
            pieces.append(MapPiece(pname, cond, map_table(pc["map"], f"{pre}.map")))
        if len({pc.name for pc in pieces}) != len(pieces):
            raise W.error("duplicate piece names", "pieces")

    d = data.get("defaults")
    if d is not None:
        if not isinstance(d, dict):
            raise W.error("`defaults` must be a table with x0, t_end (iterations), params",
                          "defaults")
        bad = sorted(set(d) - _DEFAULT_KEYS)
        if bad:
            raise W.error(f"unknown key(s) {bad} in `defaults`; allowed keys are "
                          f"{sorted(_DEFAULT_KEYS)}", f"defaults.{bad[0]}")
        ps = d.get("params", {}) or {}
        if not isinstance(ps, dict):
            raise W.error("`defaults.params` must be a table of parameter = value",
                          "defaults.params")
        for k, v in ps.items():
            if k not in parameters:
                raise W.error(f"`defaults.params` sets unknown parameter {k!r}",
                              "defaults.params", k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise W.error(f"`defaults.params.{k}` must be a finite number, got {v!r}",
                              "defaults.params", k)
    units, descriptions = check_annotations(data, states, parameters, W, time=False)
    desc = data.get("description", "")
    ref = data.get("reference", data.get("source", ""))
    if not isinstance(desc, str) or not isinstance(ref, str):
        raise W.error("`description` and `reference` must be strings", "description")
    # the values runs use: [parameters] with [defaults] params over them
    parameters = default_parameters(parameters, d)
    return MapModel(name=name, states=tuple(states), parameters=parameters, pieces=tuple(pieces),
                    description=desc, reference=ref, definitions=definitions, origin=origin,
                    spec=data, units=units, descriptions=descriptions, text=text or "")


# ======================================================================================
# code generation
# ======================================================================================

def generate_map_source(model: MapModel) -> str:
    """Python/numba source of the map's ``step`` function (value and Jacobian per piece), as
    written to the cache."""
    body = _generate_map_body(model)
    return header("map", _MAP_CODEGEN_VERSION, model.digest, body) + "\n" + body


def _check_closed_form(model: MapModel, k: int, values: list, jacobian: list) -> None:
    """Refuse a piece whose value or Jacobian has a term that is not a finite real expression:
    a complex constant (the derivative of a negative number to a symbolic power has
    ``log(-a) = log(a) + I pi``), a non-finite one, or a derivative SymPy leaves unevaluated.
    The generated code computes in real doubles, where such a term would be NaN at every point
    or not compile (flows are refused alike, :func:`pwsdyn.model.codegen.derivatives`)."""
    pc = model.pieces[k]
    for what, exprs in (("value", values), ("Jacobian", jacobian)):
        for i, e in enumerate(exprs):
            why = unprintable(e)
            if why is None:
                continue
            state = model.states[i if what == "value" else i // model.n_states]
            fieldname = (f"pieces[{k}].map.{state}" if "pieces" in (model.spec or {})
                         else f"map.{state}")
            if why == "derivative":
                raise _fail(f"the {what} of piece {pc.name!r} of map {model.name!r} has a term "
                            f"SymPy cannot differentiate in closed form ({str(e)[:200]}); "
                            "simplify the expression", model.origin, fieldname)
            raise _fail(f"the {what} of piece {pc.name!r} of map {model.name!r} has the "
                        f"non-finite or complex value {str(e)[:200]}; a map that is complex "
                        "(a negative number to a non-integer power, ...) cannot be iterated",
                        model.origin, fieldname)


def _generate_map_body(model: MapModel) -> str:
    """The module's text after its header line: only identifiers and numbers (the map's name
    and other text never reach it)."""
    check_identifiers(model.states, model.parameters, origin=model.origin)
    pr = NumbaPrinter()
    X = sp.Matrix(model.state_symbols)
    rename = {sym: sp.Symbol(f"s_{sym.name}", real=True) for sym in model.state_symbols}
    rename.update({sym: sp.Symbol(f"p_{sym.name}", real=True)
                   for sym in model.parameter_symbols})
    lines = [
        "import math",
        "import numba",
        "from pwsdyn.model.maps import MAP_STEP_SIGNATURE",
        "",
        "",
        "@numba.njit(MAP_STEP_SIGNATURE, cache=True, fastmath=False, error_model='numpy')",
        "def step(x, p, out, jac, want_jac):",
    ]
    for i, s in enumerate(model.states):
        lines.append(f"    s_{s} = x[{i}]")
    for i, s in enumerate(model.parameters):
        lines.append(f"    p_{s} = p[{i}]")
    for k, pc in enumerate(model.pieces):
        cond = "True" if pc.condition is None else pr.doprint(pc.condition.xreplace(rename))
        lines.append(f"    if {cond}:")
        F = sp.Matrix(pc.exprs)
        J = F.jacobian(X)
        _check_closed_form(model, k, list(F), list(J))
        exprs = [e.xreplace(rename) for e in list(F) + list(J)]
        subs, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_c"))
        for sym, val in subs:
            lines.append(f"        {sym} = {pr.doprint(val)}")
        n = model.n_states
        for i in range(n):
            lines.append(f"        out[{i}] = {pr.doprint(reduced[i])}")
        lines.append("        if want_jac:")
        for i in range(n * n):
            lines.append(f"            jac[{i}] = {pr.doprint(reduced[n + i])}")
        lines.append(f"        return {k}")
    lines.append("    return -1")
    return "\n".join(lines) + "\n"


@dataclass
class CompiledMap:
    """A map model with its compiled ``step`` function."""

    model: MapModel
    step: object
    source_path: Path


_COMPILED: dict[str, CompiledMap] = {}


def compile_map(model: MapModel) -> CompiledMap:
    """Generate, cache on disk (by model hash) and compile the map's ``step`` function."""
    key = model.digest
    if key in _COMPILED:
        return _COMPILED[key]
    n = model.n_states

    def warm_up(step):
        step(np.zeros(n), np.zeros(max(1, len(model.parameters))), np.zeros(n),
             np.zeros(n * n), 1)

    step, path = load_module("map", _MAP_CODEGEN_VERSION, key,
                             lambda: _generate_map_body(model), model_name=model.name,
                             attribute="step", warm_up=warm_up)
    cm = CompiledMap(model, step, path)
    _COMPILED[key] = cm
    return cm


# ======================================================================================
# iteration kernels (compiled once for all maps, in pwsdyn.model._map_kernels)
# ======================================================================================

_MAP_KERNELS = ("orbit_kernel", "lyapunov_kernel")
_KERNELS_LOCK = threading.Lock()
_LOADED = None


def _map_kernel(name: str):
    """The compiled iteration loop ``name``, loaded (or compiled, a few seconds, with a
    message) on first use only."""
    global _LOADED
    if _LOADED is None:
        with _KERNELS_LOCK:
            if _LOADED is None:
                from .._compiling import check_cache, compile_notice, memoize_function_addresses

                check_cache(("model/_map_kernels.py",), ("model/_map_step.py",))
                # the map's step function is an argument of every loop's call
                memoize_function_addresses()
                with compile_notice("the map iteration", __package__ + "._map_kernels",
                                    expected="a few seconds"):
                    from . import _map_kernels
                _LOADED = _map_kernels
    return getattr(_LOADED, name)


def __getattr__(name: str):
    if name in _MAP_KERNELS:
        return _map_kernel(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
