"""Hybrid models as data: definition, loading from TOML / dict / zoo name, validation.

A model is states, parameters with defaults, optional named definitions, modes with vector
fields, and events. An event has a surface ``h(t, x, p)``, a crossing direction, the modes it is
active in, an optional guard, an optional reset map ``g(t, x, p)`` and a target mode, and a kind:
``impact`` marks a unilateral constraint (``h >= 0`` is the admissible side), so chattering and
sticking apply to it; ``transition`` is any other switch of mode or state.

Filippov switching surfaces between two modes are ``switches``: a surface ``h`` with the mode
used where ``h > 0`` and the mode used where ``h < 0``.

The model is symbolic (SymPy). :mod:`pwsdyn.model.codegen` turns it into compiled functions.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import marshal
import math
import os
import re
import time
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import sympy as sp

from .. import _validate as V
from ..errors import ArgumentError, ModelError, PwsdynError
from .elements import Event as Event, Mode as Mode, Surface as Surface, Switch as Switch
from .expressions import check_expression, parse_expression

from .symbolic import (ANNOTATION_TABLES as ANNOTATION_TABLES, EVENT_KINDS as EVENT_KINDS,
                       MAX_DESCRIPTION_LENGTH as MAX_DESCRIPTION_LENGTH,
                       MAX_MODEL_NAME_LENGTH as MAX_MODEL_NAME_LENGTH,
                       MAX_NAME_LENGTH as MAX_NAME_LENGTH, MAX_UNIT_LENGTH as MAX_UNIT_LENGTH,
                       TIME as TIME, SymbolicSystem as SymbolicSystem, _RESERVED, _Where,
                       _is_name, check_annotations as check_annotations,
                       check_identifiers as check_identifiers, check_model_name as check_model_name,
                       check_text as check_text, default_parameters as default_parameters,
                       states_and_parameters as states_and_parameters)


@dataclass(frozen=True, eq=False)
class Model(SymbolicSystem):
    """A piecewise-smooth hybrid model (symbolic). Create it with :func:`load_model`.

    ``parameters`` holds the values a run uses unless ``params`` overrides them: the
    ``[parameters]`` table with the ``[defaults] params`` table over it (the API and the
    command line use the same values). ``units`` and ``descriptions`` hold the optional
    ``[units]`` and ``[descriptions]`` tables (by state, parameter or ``t``); ``text`` is the
    TOML source the model was read from (empty for a model built from a dict). None of the
    three enters :attr:`digest`.
    """

    name: str
    states: tuple
    parameters: dict
    modes: tuple
    surfaces: tuple
    events: tuple
    switches: tuple = ()
    #: :class:`~pwsdyn.model.elements.SignFamily` of each split mode whose variants are one
    #: field of their sides (compiled once for all of them)
    families: tuple = ()
    description: str = ""
    reference: str = ""
    definitions: dict = field(default_factory=dict)
    forcing_period: Any = None
    initial_mode: int = 0
    origin: str = "<dict>"
    spec: dict = field(default_factory=dict, repr=False)
    units: dict = field(default_factory=dict, repr=False)
    descriptions: dict = field(default_factory=dict, repr=False)
    text: str = field(default="", repr=False)

    # --- symbols -------------------------------------------------------------------------
    @property
    def t(self) -> sp.Symbol:
        return sp.Symbol(TIME, real=True)

    @property
    def mode_names(self) -> tuple:
        return tuple(m.name for m in self.modes)

    def mode_index(self, name: str) -> int:
        try:
            return self.mode_names.index(name)
        except ValueError:
            # a mode split at its discontinuous terms (``slip`` -> ``slip[v-V>0]``, ...): its
            # first variant; the simulator picks the variant on the right side of each surface
            for i, m in enumerate(self.mode_names):
                if m.startswith(name + "["):
                    return i
            raise ArgumentError(f"unknown mode {name!r}; modes are "
                                f"{list(self.mode_names)}") from None

    def event_index(self, name: str) -> int:
        for i, ev in enumerate(self.events):
            if ev.name == name:
                return i
        raise ArgumentError(f"unknown event {name!r}; events are {[e.name for e in self.events]}")

    # --- parameters ----------------------------------------------------------------------
    def forcing_period_value(self, params: Mapping[str, float] | None = None) -> float | None:
        """The forcing period for these parameters (by name), or ``None`` for an autonomous
        model; see :meth:`forcing_period_at`."""
        return self.forcing_period_at(self.parameter_vector(params))

    def forcing_period_at(self, p) -> float | None:
        """The forcing period at the parameter vector ``p`` (values in parameter order), or
        ``None`` for an autonomous model. Where it is not a positive finite number (``2*pi/
        omega`` at ``omega = 0``) an :class:`ArgumentError` names the parameters.

        Every part of pwsdyn that needs the forcing period as a number asks here (or, for
        the raw value in a hot loop, :attr:`forcing_period_function`)."""
        if self.forcing_period is None:
            return None
        try:
            val = float(self.forcing_period_function(*(float(q) for q in p)))
            got = repr(val)
        except (ArithmeticError, ValueError, TypeError) as exc:
            val, got = math.nan, f"undefined ({exc})"
        if not (math.isfinite(val) and val > 0):
            where = ", ".join(f"{k}={float(v):.17g}" for k, v in zip(self.parameters, p))
            raise ArgumentError(f"the forcing period {self.forcing_period} of model "
                                f"{self.name!r} must be a positive finite number, got {got} "
                                f"at the parameters ({where}): choose parameters where it is")
        return val

    @functools.cached_property
    def forcing_period_function(self):
        """The forcing period as a fast function of the parameter values (in order), unchecked;
        NaN for an autonomous model. Lambdified once per model from the trusted symbolic
        expression (a SymPy substitution costs milliseconds, as much as a shooting step)."""
        if self.forcing_period is None:
            return lambda *p: math.nan
        return _lambdified_period(tuple(self.parameters), self.forcing_period)

    # --- identity ------------------------------------------------------------------------
    @functools.cached_property
    def hash(self) -> str:
        """A short hash (16 hex digits) of everything that defines the compiled model, for
        display and provenance; :attr:`digest` is the full one."""
        return self.digest[:16]

    @functools.cached_property
    def digest(self) -> str:
        """SHA-256 (64 hex digits) of everything that defines the compiled model (not its
        description, units, descriptions or parameter values); names the compiled module in
        the cache."""
        # sp.srepr of a tuple, each element object printed once: the variants of a mode split
        # at k contacts share most of their components and sliding families (the same
        # objects; by identity, since SymPy may call 1 and 1.0 equal)
        printed: dict = {}

        def srepr(items) -> str:
            if items is None:
                return "None"
            out = []
            for e in items:
                text = printed.get(id(e))
                if text is None:
                    text = printed[id(e)] = sp.srepr(e)
                out.append(text)
            return f"({out[0]},)" if len(out) == 1 else f"({', '.join(out)})"

        parts = [self.name, repr(self.states), repr(list(self.parameters))]
        parts += [f"mode {m.name}: " + srepr(m.rhs) for m in self.modes]
        parts += [f"surface {s.name}: " + sp.srepr(s.expr) for s in self.surfaces]
        for e in self.events:
            parts.append(f"event {e.name} {e.kind} {e.surface} {e.direction} {e.modes} "
                         f"{e.target} {e.terminal} {sp.srepr(e.guard)} {sp.srepr(e.reset)}")
        for s in self.switches:
            parts.append(f"switch {s.name} {s.surface} {s.above} {s.below} {s.kind} "
                         f"{srepr(s.family)}")
        for f in self.families:
            parts.append(f"family {f.first} {f.surfaces} {f.switches} {sp.srepr(f.rhs)}")
        return hashlib.sha256("\n".join(parts).encode()).hexdigest()

    def __repr__(self):
        return (f"Model({self.name!r}, states={list(self.states)}, modes={list(self.mode_names)}, "
                f"events={[e.name for e in self.events]}, "
                f"switches={[s.name for s in self.switches]})")


@functools.lru_cache(maxsize=256)
def _lambdified_period(parameters: tuple, period):
    # shared by the models of one structure: every load of a file by name makes a new Model
    return sp.lambdify([sp.Symbol(p, real=True) for p in parameters], period, modules="math")


# ======================================================================================
# loading
# ======================================================================================

@functools.cache
def _zoo_dir() -> Path:
    return Path(str(resources.files("pwsdyn.model") / "zoo"))


#: The built-in model names with the directory's (mtime, size) they were listed at.
_ZOO_NAMES: list = [None, ()]


def zoo_names() -> list[str]:
    """Names of the built-in models."""
    return list(_zoo_names())


def _zoo_names() -> tuple:
    root = _zoo_dir()
    st = os.stat(root)
    key = (st.st_mtime_ns, st.st_size, st.st_ino)
    if _ZOO_NAMES[0] != key:
        # listed again whenever the directory changes (a model file added or removed)
        _ZOO_NAMES[:] = [key, tuple(sorted(p.name[:-5] for p in root.iterdir()
                                           if p.name.endswith(".toml")))]
    return _ZOO_NAMES[1]


def zoo_path(name: str) -> Path:
    path = _ZOO_PATHS.get(name)
    if path is None:
        path = _zoo_dir() / f"{name}.toml"
        if len(_ZOO_PATHS) < 1024:
            _ZOO_PATHS[name] = path
    return path


_ZOO_PATHS: dict = {}


#: Models read from files, by the path as given: ``(file key, model)``. The model is never
#: handed out; each load returns a copy (:func:`_copy_model`), so a caller that changes its
#: model changes no later load. The key (:func:`_file_key`) makes an edited file read again.
_LOADED: dict = {}
_LOADED_MAX = 128
#: A file modified less than this long (ns) before it was read is not cached: a second edit
#: within the file system's timestamp resolution could leave its key unchanged.
_RACY_NS = 2_000_000_000


def _file_key(path: Path):
    """What identifies a version of a file: device, inode, size and modification time;
    None when it does not exist (or cannot be examined)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        # what ``Path.exists`` counts as absent; other errors (permissions) propagate
        if exc.errno in (errno.ENOENT, errno.ENOTDIR, errno.EBADF, errno.ELOOP):
            return None
        raise
    except ValueError:      # a NUL in the path
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def _copy_data(value):
    """A copy of parsed TOML data (dicts and lists of immutable values) that shares no
    container with ``value``."""
    if isinstance(value, dict):
        return {k: _copy_data(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy_data(v) for v in value]
    return value


def _copy_model(model, spec_bytes: bytes | None = None):
    """A new model equal to ``model`` (a :class:`Model` or a map): the immutable parts
    (names, modes, surfaces, events, switches, pieces: tuples of frozen values and SymPy
    expressions) and what is derived from them alone (``digest``, ``hash``, the forcing
    period's function) shared, every dict and list copied (``spec`` to the leaves: from
    ``spec_bytes``, its :mod:`marshal` form, where given)."""
    new = object.__new__(type(model))
    d = new.__dict__
    d.update(model.__dict__)
    for k, v in d.items():
        if type(v) is dict:
            d[k] = dict(v)      # values immutable: parameters, units, definitions, ...
        elif isinstance(v, (dict, list)):
            d[k] = _copy_data(v)
    d["spec"] = _copy_data(model.spec) if spec_bytes is None else marshal.loads(spec_bytes)
    return new


def _marshalled(data) -> bytes | None:
    """``data`` in :mod:`marshal` form (unmarshalling is the fastest deep copy), or None
    where it holds what marshal does not write (TOML dates and times)."""
    try:
        return marshal.dumps(data)
    except ValueError:
        return None


def _load_file(path: Path, key) -> "Model":
    """The model in the file ``path`` (whose :func:`_file_key` is ``key``), from
    :data:`_LOADED` while the file is unchanged."""
    name = str(path)
    hit = _LOADED.get(name)
    if hit is not None and hit[0] == key:
        return _copy_model(hit[1], hit[2])
    read_at = time.time_ns()
    try:
        text = path.read_text()
    except OSError as exc:
        raise ModelError(f"cannot read model file: {exc}", source=name) from None
    model = _model_from_toml_text(text, name)
    if _file_key(path) == key and read_at - key[3] > _RACY_NS:
        # what every run needs (the digest names the compiled model; the forcing period
        # bounds the steps), computed once for the copies
        model.digest, model.hash
        if getattr(model, "forcing_period", None) is not None:
            model.forcing_period_function
        spec_bytes = _marshalled(model.spec)
        if len(_LOADED) >= _LOADED_MAX:
            _LOADED.clear()
        _LOADED[name] = (key, model, spec_bytes)
        return _copy_model(model, spec_bytes)
    return model


def loaded_original(name: str):
    """``(model, copy)`` for a model name or path whose file is in ``_LOADED`` and
    unchanged (the same ``_file_key``): the kept model itself, never to be handed out or
    changed, and a function making the copy :func:`~pwsdyn.load_model` would return; None
    otherwise (not loaded yet, edited, a TOML string).

    For a caller that only *reads* the model during a call and hands a copy out later, if at
    all: :func:`pwsdyn.simulate` runs on the kept model and gives its trajectory the copy
    when ``traj.model`` is first read, so a model by name costs a file check per call, not a
    copy, and every trajectory still has a model of its own. Reading the file's key on every
    call keeps the rule of :func:`~pwsdyn.load_model`: an edited file is read again."""
    # the file load_model would read (a built-in name first, as there); a built-in name
    # looked up before is in _ZOO_PATHS (a file of it removed since: its key is None below)
    path = _ZOO_PATHS.get(name)
    if path is None:
        if "\n" in name:
            return None
        path = zoo_path(name) if name in _ZOO_NAMES[1] or name in _zoo_names() else Path(name)
    hit = _LOADED.get(str(path))
    if hit is None:
        return None
    # the one system call per call: an edited file is read again (load_model's rule)
    key = _file_key(path)
    if key is None or hit[0] != key:
        return None
    _, model, spec_bytes = hit
    return model, functools.partial(_copy_model, model, spec_bytes)


def as_model(value, *, kind: str | None = None, caller: str = "", name: str = "model"):
    """The model an entry point was given: ``value`` loaded with :func:`~pwsdyn.load_model`, a
    wrong type an :class:`~pwsdyn.ArgumentError` naming ``name``; ``kind='flow'`` or ``'map'``
    refuses the other kind, naming ``caller``."""
    if type(value) is Model and kind != "map":
        return value        # the common case, on every call of a loop
    if not (isinstance(value, (str, os.PathLike, Mapping, SymbolicSystem))
            or getattr(value, "is_map", False)):
        raise V.fail(name, "a Model, a model name, a path to a TOML file or a dict", value)
    if isinstance(value, (str, os.PathLike)) and not V.is_path(value):
        raise V.fail(name, "a Model, a model name, a path to a TOML file or a dict", value)
    try:
        m = load_model(value)
    except PwsdynError:
        raise
    except Exception as exc:
        # a wrong type, an unreadable path, or a dict the model parser does not expect
        # (keys that are not strings, ...): the argument, not pwsdyn, is at fault
        raise ArgumentError(f"`{name}` cannot be loaded as a model: "
                            f"{type(exc).__name__}: {exc}") from exc
    is_map = bool(getattr(m, "is_map", False))
    who = f"{caller} " if caller else ""
    if kind == "flow" and is_map:
        raise ArgumentError(f"`{name}`: {who}needs a flow (a model with modes and events); "
                            f"{m.name!r} is a map (iterate it with pwsdyn.model.iterate, "
                            "explore it with pwsdyn.sweep, pwsdyn.basins or "
                            "pwsdyn.lyapunov_spectrum)")
    if kind == "map" and not is_map:
        raise ArgumentError(f"`{name}`: {who}needs a map; {m.name!r} is a flow (use "
                            "pwsdyn.simulate)")
    return m


def load_model(source: str | os.PathLike[str] | Mapping[str, Any] | Model,
               **kwargs: Any) -> Model:
    """Load a model from a TOML file path, a built-in name, a TOML string or a dict.

    Parameters
    ----------
    source : str, pathlib.Path, dict or Model
        A path to a ``.toml`` file; the name of a built-in model (``pwsdyn.zoo_names()``); a
        dict with the same structure as the TOML file; or a ``Model`` (returned as is).

    Returns
    -------
    Model

    Raises
    ------
    ModelError
        A malformed model; the message names the file, line and field.

    Examples
    --------
    >>> m = load_model("bouncing-ball")
    >>> m.states
    ('y', 'v')
    """
    if kwargs:
        raise ArgumentError(f"load_model() got unexpected keyword argument(s) {sorted(kwargs)}")
    if type(source) is not str:     # (a name or path: the common case, tested first)
        if isinstance(source, Model) or getattr(source, "is_map", False):
            return source
        if isinstance(source, Mapping):
            return _built(model_from_dict, dict(source), origin="<dict>")
    if isinstance(source, (str, Path)):
        text_source = str(source)
        if "\n" in text_source:
            return _model_from_toml_text(text_source, "<string>")
        # a name in the listing kept is looked up without listing the directory again
        # while its file is there; any other string lists it again (a model added)
        zoo = text_source in _ZOO_NAMES[1] or text_source in _zoo_names()
        path = zoo_path(text_source) if zoo else Path(text_source)
        key = _file_key(path)
        if key is None and zoo and text_source not in _zoo_names():
            path = Path(text_source)       # the built-in model was removed
            key = _file_key(path)
        if key is None and "=" in text_source:
            return _model_from_toml_text(text_source, "<string>")
        if key is None:
            raise ModelError(f"no model file {text_source!r} and no built-in model of that name; "
                             f"built-in models are {', '.join(zoo_names())}", source=text_source)
        return _load_file(path, key)
    raise ArgumentError(f"`source` must be a path, a model name, a dict or a Model, "
                    f"got {type(source).__name__}")


def _built(build, *args, origin: str, **kwargs):
    """``build(*args, origin=origin, ...)``, with any error that is not pwsdyn's own turned into
    a :class:`ModelError` naming the source: model files are untrusted input, and SymPy raises
    many kinds of errors on degenerate expressions."""
    try:
        return build(*args, origin=origin, **kwargs)
    except PwsdynError:
        raise
    except RecursionError:
        raise ModelError("the model is nested too deeply to build", source=origin) from None
    except (TypeError, ValueError, ArithmeticError, AttributeError, IndexError,
            KeyError) as exc:
        raise ModelError(f"the model cannot be built ({type(exc).__name__}: {exc})",
                         source=origin) from None


def _model_from_toml_text(text: str, origin: str) -> Model:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        # Python < 3.14 has no ``lineno`` attribute: the position is only in the message,
        # '... (at line 3, column 20)' or '... (at end of document)'
        line = getattr(exc, "lineno", None)
        if line is None:
            m = re.search(r"at line (\d+)", str(exc))
            if m:
                line = int(m.group(1))
            elif "end of document" in str(exc):
                line = max(1, len(text.splitlines()))
        raise ModelError(f"malformed TOML: {exc}", source=origin, line=line) from None
    return _built(model_from_dict, data, origin=origin, text=text)


_TOP_KEYS = {"name", "description", "source", "reference", "states", "parameters",
             "definitions", "modes", "events", "switches", "forcing_period", "initial_mode",
             "notes", "defaults", "units", "descriptions"}
_EVENT_KEYS = {"name", "kind", "surface", "direction", "modes", "mode", "guard", "reset",
               "target", "terminal", "description"}


def model_from_dict(data: dict, origin: str = "<dict>", text: str | None = None) -> Model:
    """Build and validate a :class:`Model` from a dict with the TOML file's structure.

    A dict with ``kind = "map"`` describes a piecewise-smooth map instead
    (:mod:`pwsdyn.model.maps`)."""
    keys = [k for k in data if not isinstance(k, str)]
    if keys:
        raise ModelError(f"top-level keys must be strings, got {keys[0]!r}", source=origin)
    if data.get("kind") == "map":
        from .maps import map_model_from_dict

        return map_model_from_dict(data, origin=origin, text=text)
    W = _Where(origin, text)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise W.error(f"unknown top-level key(s) {unknown}; allowed keys are "
                      f"{sorted(_TOP_KEYS)}", unknown[0])

    def need(key, typ, where=data, prefix=""):
        if key not in where:
            raise W.error(f"missing required field `{prefix}{key}`", prefix + key)
        val = where[key]
        if not isinstance(val, typ):
            raise W.error(f"`{prefix}{key}` must be {typ.__name__ if isinstance(typ, type) else typ}"
                          f", got {type(val).__name__}", prefix + key)
        return val

    name = check_model_name(need("name", str), W)
    need("states", list)
    states, parameters = states_and_parameters(data, W, "model")

    t = sp.Symbol(TIME, real=True)
    names = {TIME: t}
    names.update({s: sp.Symbol(s, real=True) for s in states})
    names.update({p: sp.Symbol(p, real=True) for p in parameters})

    # definitions: substituted into every expression that uses them, in order
    defs_raw = data.get("definitions", {})
    if not isinstance(defs_raw, dict):
        raise W.error("`definitions` must be a table of name = expression", "definitions")
    definitions = {}
    for k, v in defs_raw.items():
        if not _is_name(k) or k in names or k in _RESERVED:
            raise W.error(f"invalid or clashing definition name {k!r}", f"definitions.{k}")
        expr = parse_expression(v, names, field=f"definitions.{k}", source=origin,
                                line=W.line(k, v if isinstance(v, str) else None))
        definitions[k] = expr
        names[k] = expr

    def expr(val, fieldname, boolean=False):
        return parse_expression(val, names, field=fieldname, source=origin,
                                line=W.line(fieldname, val if isinstance(val, str) else None),
                                boolean=boolean)

    # modes
    modes_raw = need("modes", dict)
    if not modes_raw:
        raise W.error("a model needs at least one mode", "modes")
    modes = []
    for mname, rhs in modes_raw.items():
        if not _is_name(mname):
            raise W.error(f"invalid mode name {mname!r}", f"modes.{mname}")
        if not isinstance(rhs, dict):
            raise W.error(f"mode {mname!r} must be a table of state = derivative", f"modes.{mname}")
        extra = sorted(set(rhs) - set(states))
        if extra:
            raise W.error(f"mode {mname!r} gives a derivative for unknown state(s) {extra}; states "
                          f"are {states}", f"modes.{mname}.{extra[0]}")
        missing = [s for s in states if s not in rhs]
        if missing:
            raise W.error(f"mode {mname!r} has no derivative for state(s) {missing}",
                          f"modes.{mname}")
        modes.append(Mode(mname, tuple(expr(rhs[s], f"modes.{mname}.{s}") for s in states)))
    mode_names = [m.name for m in modes]

    def mode_ref(val, fieldname):
        if val not in mode_names:
            raise W.error(f"unknown mode {val!r}; modes are {mode_names}", fieldname, val)
        return mode_names.index(val)

    surfaces: list[Surface] = []

    def add_surface(val, fieldname, sname):
        e = expr(val, fieldname)
        for i, s in enumerate(surfaces):
            if s.expr == e:
                return i
        surfaces.append(Surface(sname, e))
        return len(surfaces) - 1

    # events
    events_raw = data.get("events", [])
    if not isinstance(events_raw, list):
        raise W.error("`events` must be an array of tables ([[events]])", "events")
    events = []
    seen = set()
    for i, ev in enumerate(events_raw):
        pre = f"events[{i}]."
        if not isinstance(ev, dict):
            raise W.error("each event must be a table", f"events[{i}]")
        bad = sorted(set(ev) - _EVENT_KEYS)
        if bad:
            raise W.error(f"unknown key(s) {bad} in event; allowed keys are {sorted(_EVENT_KEYS)}",
                          pre + bad[0])
        ename = ev.get("name", f"event{i}")
        if not isinstance(ename, str) or not _is_name(ename.replace("-", "_")):
            raise W.error(f"invalid event name {ename!r}", pre + "name")
        if ename in seen:
            raise W.error(f"duplicate event name {ename!r}", pre + "name", ename)
        seen.add(ename)
        kind = ev.get("kind", "transition")
        if kind not in EVENT_KINDS:
            raise W.error(f"event kind must be one of {EVENT_KINDS}, got {kind!r}", pre + "kind",
                          str(kind))
        if "surface" not in ev:
            raise W.error(f"event {ename!r} has no `surface`", pre + "surface")
        surf = add_surface(ev["surface"], pre + "surface", ename)
        direction = ev.get("direction", -1 if kind == "impact" else 0)
        if direction not in (-1, 0, 1) or isinstance(direction, bool):
            raise W.error(f"`direction` must be -1, 0 or 1, got {direction!r}", pre + "direction")
        if kind == "impact" and direction != -1:
            raise W.error("an impact event must have direction -1 (the admissible side is "
                          "h >= 0)", pre + "direction")
        mlist = ev.get("modes", ev.get("mode", mode_names))
        if isinstance(mlist, str):
            mlist = [mlist]
        if not isinstance(mlist, list) or not mlist:
            raise W.error("`modes` must be a non-empty list of mode names", pre + "modes")
        emodes = tuple(mode_ref(m, pre + "modes") for m in mlist)
        guard = None
        if "guard" in ev:
            guard = expr(ev["guard"], pre + "guard", boolean=True)
        reset = None
        if "reset" in ev:
            r = ev["reset"]
            if not isinstance(r, dict):
                raise W.error("`reset` must be a table of state = new value", pre + "reset")
            extra = sorted(set(r) - set(states))
            if extra:
                raise W.error(f"reset of unknown state(s) {extra}; states are {states}",
                              pre + "reset", extra[0])
            reset = tuple(expr(r[s], pre + f"reset.{s}") if s in r else names[s] for s in states)
        target = None
        if "target" in ev:
            target = mode_ref(ev["target"], pre + "target")
        if kind == "impact" and reset is None:
            raise W.error("an impact event needs a `reset` (the impact law)", pre + "reset")
        terminal = ev.get("terminal", False)
        if not isinstance(terminal, bool):
            raise W.error("`terminal` must be true or false", pre + "terminal")
        events.append(Event(ename, kind, surf, int(direction), emodes, guard, reset, target,
                            terminal))

    switches = []
    switches_raw = data.get("switches", []) or []
    if not isinstance(switches_raw, list):
        raise W.error("`switches` must be an array of tables ([[switches]])", "switches")
    for i, sw in enumerate(switches_raw):
        pre = f"switches[{i}]."
        if not isinstance(sw, dict):
            raise W.error("each switch must be a table", f"switches[{i}]")
        sname = sw.get("name", f"switch{i}")
        if not isinstance(sname, str) or not _is_name(sname.replace("-", "_")):
            raise W.error(f"invalid switch name {sname!r}", pre + "name")
        for key in ("surface", "above", "below"):
            if key not in sw:
                raise W.error(f"switch {sname!r} needs `{key}`", pre + key)
        surf = add_surface(sw["surface"], pre + "surface", sname)
        switches.append(Switch(sname, surf, mode_ref(sw["above"], pre + "above"),
                               mode_ref(sw["below"], pre + "below")))

    fp = None
    if data.get("forcing_period") is not None:
        # a function of the parameters only (not of time or state)
        pnames = {p: sp.Symbol(p, real=True) for p in parameters}
        fp = parse_expression(data["forcing_period"], pnames, field="forcing_period",
                              source=origin, line=W.line("forcing_period"))
    init = 0
    if "initial_mode" in data:
        init = mode_ref(data["initial_mode"], "initial_mode")

    _check_defaults(data.get("defaults"), states, parameters, W)
    units, descriptions = check_annotations(data, states, parameters, W)

    desc = data.get("description", "")
    ref = data.get("reference", data.get("source", ""))
    if not isinstance(desc, str) or not isinstance(ref, str):
        raise W.error("`description` and `reference` must be strings", "description")
    # sign / Heaviside / Abs / Max / Min in vector fields: modes split into their smooth
    # variants joined by switching surfaces (pwsdyn.model.discontinuities)
    from .discontinuities import expand_discontinuities

    try:
        modes, events, switches, init, families = expand_discontinuities(
            modes, surfaces, events, switches, init, definitions,
            variables=tuple(names[s] for s in states) + (t,))
    except ModelError as exc:
        raise W.error(exc.reason, exc.field or "modes") from None
    except (TypeError, ValueError, ArithmeticError) as exc:
        # SymPy on a variant that is not defined: Max(0**-7.3, x) where Heaviside(x) = 0
        raise W.error(f"a mode split at its discontinuous terms has a variant SymPy cannot "
                      f"build ({type(exc).__name__}: {exc})", "modes") from None
    # a variant of a split mode can hold a constant its parent did not: Min(x, -5)**-0.5 is
    # (-5)**-0.5, complex, where x > -5
    def refuse(prefix, fieldname):
        def fail(msg):
            raise W.error(f"{prefix}: {msg}", fieldname)
        return fail

    # each expression object once: the variants of a mode split at k contacts share most of
    # their components (the loader gives them the same objects; the first variant that holds
    # a bad one is named, as before)
    checked: set = set()
    for mode in modes:
        for s, e in zip(states, mode.rhs):
            if id(e) not in checked:
                check_expression(e, refuse(f"in mode {mode.name!r}",
                                           f"modes.{mode.name.split('[', 1)[0]}.{s}"))
                checked.add(id(e))
    for sw in switches:
        for e in sw.family or ():
            if id(e) not in checked:
                check_expression(e, refuse(f"in the sliding family of switch {sw.name!r}",
                                           "modes"))
                checked.add(id(e))
    # the values runs use: [parameters] with [defaults] params over them (checked above)
    parameters = default_parameters(parameters, data.get("defaults"))
    return Model(name=name, states=tuple(states), parameters=parameters, modes=tuple(modes),
                 surfaces=tuple(surfaces), events=tuple(events), switches=tuple(switches),
                 families=tuple(families), description=desc, reference=ref,
                 definitions=definitions, forcing_period=fp, initial_mode=init, origin=origin,
                 spec=data, units=units, descriptions=descriptions, text=text or "")


_DEFAULTS_KEYS = {"x0", "t0", "t_end", "params"}


def _check_defaults(d, states, parameters, W: _Where) -> None:
    """Validate the optional ``[defaults]`` table: ``x0`` (by state name or in state order),
    ``t0`` (a number, default 0), ``t_end`` (a number after ``t0``) and ``params`` (known
    parameter names, finite values)."""
    if d is None:
        return
    if not isinstance(d, dict):
        raise W.error("`defaults` must be a table with x0, t_end and optionally t0, params",
                      "defaults")
    bad = sorted(set(d) - _DEFAULTS_KEYS)
    if bad:
        raise W.error(f"unknown key(s) {bad} in `defaults`; allowed keys are "
                      f"{sorted(_DEFAULTS_KEYS)}", f"defaults.{bad[0]}")

    def number(v):
        return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)

    if "x0" in d:
        x0 = d["x0"]
        if isinstance(x0, dict):
            unknown = sorted(set(x0) - set(states))
            if unknown:
                raise W.error(f"`defaults.x0` names unknown state(s) {unknown}; states are "
                              f"{states}", "defaults.x0")
            missing = [s for s in states if s not in x0]
            if missing:
                raise W.error(f"`defaults.x0` is missing state(s) {missing}", "defaults.x0")
            vals = list(x0.values())
        elif isinstance(x0, list):
            if len(x0) != len(states):
                raise W.error(f"`defaults.x0` must have {len(states)} entries (states "
                              f"{states}), got {len(x0)}", "defaults.x0")
            vals = x0
        else:
            raise W.error("`defaults.x0` must be a table by state name or an array",
                          "defaults.x0")
        if not all(number(v) for v in vals):
            raise W.error(f"`defaults.x0` must hold finite numbers, got {x0!r}", "defaults.x0")
    if "t0" in d and not number(d["t0"]):
        raise W.error(f"`defaults.t0` must be a finite number, got {d['t0']!r}", "defaults.t0")
    t0 = d.get("t0", 0.0)
    if "t_end" in d and not (number(d["t_end"]) and d["t_end"] > t0):
        raise W.error(f"`defaults.t_end` must be a number after t0 = {t0!r}, got "
                      f"{d['t_end']!r}", "defaults.t_end")
    if "params" in d:
        ps = d["params"]
        if not isinstance(ps, dict):
            raise W.error("`defaults.params` must be a table of parameter = value",
                          "defaults.params")
        for k, v in ps.items():
            if k not in parameters:
                raise W.error(f"`defaults.params` sets unknown parameter {k!r}; parameters "
                              f"are {list(parameters)}", "defaults.params", k)
            if not number(v):
                raise W.error(f"`defaults.params.{k}` must be a finite number, got {v!r}",
                              "defaults.params", k)


# ======================================================================================
# the defaults of a run: one rule for the API and the command line
# ======================================================================================

#: End time of a run when neither the caller nor the model's ``[defaults]`` give one.
FALLBACK_T_END = 10.0


@dataclass(frozen=True)
class RunDefaults:
    """The start of a run as :func:`run_defaults` resolved it.

    ``x0`` is the caller's (a sequence or a dict) or the model's ``[defaults] x0``, else the
    zero state; ``t0`` and ``t_end`` the caller's, else the model's ``[defaults]``, else 0 and
    ``t0 +`` :data:`FALLBACK_T_END`. ``fallback`` names the values (``"x0"``, ``"t_end"``)
    for which neither the caller nor the model gave one: callers say so (a warning, a note).
    """

    x0: Any
    t0: float
    t_end: float
    fallback: tuple = ()

    def note(self, model, flags: Mapping[str, str] | None = None) -> list[str]:
        """One sentence per fallback value; ``flags`` names the caller's spelling of each
        (``{"x0": "--x0"}`` on the command line)."""
        flags = {"x0": "x0", "t_end": "t_end", **(flags or {})}
        out = []
        if "x0" in self.fallback:
            zero = ", ".join(f"{s}=0" for s in model.states)
            out.append(f"no {flags['x0']} given and model {model.name!r} has no defaults.x0; "
                       f"starting from zero ({zero})")
        if "t_end" in self.fallback:
            out.append(f"no {flags['t_end']} given and model {model.name!r} has no "
                       f"defaults.t_end; using t_end = {self.t_end:g}")
        return out


def run_defaults(model, x0=None, t0=None, t_end=None) -> RunDefaults:
    """The initial state and time span of a run of ``model``: what the caller gives, else
    the model's ``[defaults]`` table, else the zero state, ``t0 = 0`` and
    ``t_end = t0 +`` :data:`FALLBACK_T_END` (the one rule of :func:`pwsdyn.simulate` and of
    ``pwsdyn simulate`` and ``pwsdyn orbit``). Parameter defaults need no resolving:
    ``[defaults] params`` are in ``model.parameters``."""
    d = model.defaults
    fallback = []
    if x0 is None:
        x0 = d.get("x0")
        if x0 is None:
            x0 = [0.0] * model.n_states
            fallback.append("x0")
    if t0 is None:
        t0 = float(d.get("t0", 0.0))
    if t_end is None:
        if d.get("t_end") is not None:
            t_end = float(d["t_end"])
        else:
            t_end = t0 + FALLBACK_T_END
            fallback.append("t_end")
    return RunDefaults(x0, t0, t_end, tuple(fallback))
