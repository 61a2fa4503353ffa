"""Symbolic derivatives and compiled code for a :class:`~pwsdyn.model.spec.Model`.

Every function the numerical kernels need is produced from the model's SymPy expressions:
the vector fields ``f`` and their derivatives ``f_x``, ``f_t``; the surfaces ``h``, ``h_x``,
``h_t``; the normal velocity of each surface in each mode ``hdot = h_t + h_x f`` with its
derivatives ``hdot_x``, ``hdot_t`` (for chattering, sticking and grazing); the resets ``g``,
``g_x``, ``g_t``; and the guards.

They are emitted as one Python module with a single numba function

    evaluate(which, idx, t, x, p, out)

where ``which`` selects the quantity (the ``W_*`` constants below) and ``idx`` the mode,
surface, event or (surface, mode) pair. The module is written to a private cache directory
under the model's full SHA-256 and compiled by numba with ``cache=True``, so a second process
loads machine code from disk (:mod:`pwsdyn.model.cache` says how the cache is protected).
Only validated identifiers (states and parameters, prefixed) and numbers reach the source;
the model's name and other text never do. All models share this one signature, so the
integrator kernel is compiled once for all models (it receives ``evaluate`` as a first-class
function) and a new model costs only the compilation of its own small function.
"""

from __future__ import annotations

import dataclasses
import operator
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import sympy as sp
from numba import types
from sympy.printing.codeprinter import PrintMethodNotImplementedError

from .._codes import MODEL_EVENT_KINDS
from .._compiling import type_once
from ..errors import ModelError
from .affine import affine_structure
from .cache import cache_dir as cache_dir, load_module
from ._printer import NumbaPrinter, unprintable
from .discontinuities import U_SYMBOL, side_symbol
from .elements import Mode
from .spec import Model, check_identifiers

# quantity selectors (the ``which`` argument); the kernel uses the same numbers
W_F, W_FX, W_FT = 0, 1, 2
W_H, W_HX, W_HT = 3, 4, 5
W_HD, W_HDX, W_HDT = 6, 7, 8
W_G, W_GX, W_GT = 9, 10, 11
W_GUARD = 12
W_HHD = 13  # h and hdot together (one call per step in the event detection hot loop)
# Utkin's equivalent control on switch ``idx``: the switch's family f(t, x, u) (n values),
# hdot(u) = h_t + h_x f(t, x, u) and its u-derivative (one value each); u is read from out[0]
W_FU, W_HDU, W_HDUD = 14, 15, 16
# exact propagation of affine modes (:mod:`pwsdyn.model.affine`): with idx = -1 the dimension
# nz of the augmented state (0 if no mode is affine); with idx = mode a flag (1 affine, 0 not)
# followed by the augmented matrix M (nz x nz, row-major)
W_AFFINE = 17
# sign families (:class:`~pwsdyn.model.elements.SignFamily`) whose field is multilinear in
# its sides on the surfaces: with idx = mode, W_FAMILY gives k (0: the mode is in none), the
# index of the family's first variant, then its k surfaces; with idx = that first variant,
# W_FS is the field f(t, x, side) with the k sides read from out[:k] (n values) and W_FSD its
# side derivatives (n x k, row-major)
W_FAMILY, W_FS, W_FSD = 18, 19, 20

# what each selector computes, for messages
_QUANTITIES = {W_F: "vector field", W_FX: "Jacobian f_x", W_FT: "time derivative f_t",
               W_H: "surface", W_HX: "surface gradient h_x", W_HT: "surface rate h_t",
               W_HD: "normal velocity", W_HDX: "normal velocity gradient",
               W_HDT: "normal velocity rate", W_G: "reset map", W_GX: "reset Jacobian",
               W_GT: "reset time derivative", W_GUARD: "guard", W_HHD: "surface",
               W_FU: "sliding family", W_HDU: "sliding normal velocity",
               W_HDUD: "sliding normal velocity derivative", W_AFFINE: "affine matrix",
               W_FAMILY: "sign family", W_FS: "sign family's field",
               W_FSD: "sign family's side derivatives"}

#: Signature of the generated function, ``evaluate(which, idx, t, x, p, out) -> None``.
EVALUATE_SIGNATURE = types.void(types.int64, types.int64, types.float64, types.float64[::1],
                                types.float64[::1], types.float64[::1])
EVALUATE_TYPE = types.FunctionType(EVALUATE_SIGNATURE)

_CODEGEN_VERSION = "10"

#: Largest generated module (characters) handed to the compiler -- numba's time grows faster
#: than the source (40,000 characters, sixteen split modes, compile in about 7 s; the largest
#: built-in model needs 25,000). A model past it is refused before minutes of compiling.
MAX_SOURCE_CHARS = 100_000


def without_dirac_deltas(e):
    """Replace Dirac deltas (derivatives of sign/Heaviside) by 0: they live on surfaces."""
    if isinstance(e, sp.Basic) and e.has(sp.DiracDelta):
        e = e.replace(sp.DiracDelta, lambda *a: sp.Integer(0))
    return e


@dataclass
class Derivatives:
    """All symbolic quantities of a model, flattened per ``(which, idx)`` case (``idx`` an
    index, or a :class:`FamilyRange` of indices that share one expression in the sides)."""

    cases: dict  # (which, idx) -> list of expressions (flat)


@dataclass(frozen=True)
class FamilyRange:
    """The indices ``lo..hi`` of one case body written in the side variables of a
    :class:`~pwsdyn.model.elements.SignFamily` with ``k`` surfaces, each index decoding its
    sides from ``idx - lo``: the variant ``c = idx - lo`` (``kind="variant"``: modes, and
    normal velocities of one surface), or the ``r``-th Filippov switch on the family's
    surface ``j`` (``kind="switch"``: its variant above is ``c`` = ``r`` with a zero bit
    inserted at position ``k - 1 - j``, and side ``j`` is Utkin's ``u``)."""

    lo: int
    hi: int
    k: int
    kind: str = "variant"
    j: int = -1

    def __index__(self) -> int:  # sorts with the plain indices
        return self.lo

    def __str__(self) -> str:  # in messages: the indices it stands for
        return f"{self.lo}..{self.hi}"

    def prologue(self, used) -> list:
        """The lines decoding the side variables in ``used`` (names) from ``idx``."""
        lines = [f"            _v = idx - {self.lo}"]
        if self.kind == "switch":
            b = self.k - 1 - self.j
            lines.append(f"            _v = ((_v >> {b}) << {b + 1}) | (_v & {(1 << b) - 1})")
        for q in range(self.k):
            if q != self.j and f"side_{q}" in used:
                lines.append(f"            side_{q} = -1.0 if (_v >> {self.k - 1 - q}) & 1 "
                             "else 1.0")
        return lines


def derivatives(model: Model) -> Derivatives:
    """Differentiate the model symbolically (SymPy)."""
    t = model.t
    X = sp.Matrix(model.state_symbols)
    n = model.n_states
    cases = {}
    nm = len(model.modes)
    # the variants of a sign family are one field of their sides, differentiated and compiled
    # once (the per-variant fields stay in model.modes, for everything else that reads them)
    fields = []          # (index or FamilyRange of modes, field)
    in_family = set()
    for fam in model.families:
        in_family.update(range(fam.first, fam.first + fam.size))
        fields.append((FamilyRange(fam.first, fam.first + fam.size - 1, len(fam.surfaces)),
                       sp.Matrix(fam.rhs)))
    fields += [(i, sp.Matrix(mode.rhs)) for i, mode in enumerate(model.modes)
               if i not in in_family]
    fields.sort(key=lambda c: operator.index(c[0]))
    for i, f in fields:
        cases[(W_F, i)] = list(f)
        cases[(W_FX, i)] = [without_dirac_deltas(e) for e in f.jacobian(X)]
        cases[(W_FT, i)] = [without_dirac_deltas(e) for e in f.diff(t)]
    for k, surf in enumerate(model.surfaces):
        h = surf.expr
        hx = sp.Matrix([h]).jacobian(X)
        ht = sp.diff(h, t)
        cases[(W_H, k)] = [h]
        cases[(W_HX, k)] = [without_dirac_deltas(e) for e in hx]
        cases[(W_HT, k)] = [without_dirac_deltas(ht)]
        for i, f in fields:
            at = (k * nm + i if isinstance(i, int)
                  else dataclasses.replace(i, lo=k * nm + i.lo, hi=k * nm + i.hi))
            hd = without_dirac_deltas(ht + (hx * f)[0])
            cases[(W_HD, at)] = [hd]
            cases[(W_HDX, at)] = [without_dirac_deltas(e) for e in sp.Matrix([hd]).jacobian(X)]
            cases[(W_HDT, at)] = [without_dirac_deltas(sp.diff(hd, t))]
            cases[(W_HHD, at)] = [h, hd]
    family_switches = set()
    for fam in model.families:
        k = len(fam.surfaces)
        for j, s0 in enumerate(fam.switches):
            if s0 < 0:
                continue
            half = fam.size // 2
            family_switches.update(range(s0, s0 + half))
            at = FamilyRange(s0, s0 + half - 1, k, "switch", j)
            fu = sp.Matrix(fam.rhs).xreplace({side_symbol(j): U_SYMBOL})
            h = model.surfaces[fam.surfaces[j]].expr
            hdu = sp.diff(h, t) + (sp.Matrix([h]).jacobian(X) * fu)[0]
            cases[(W_FU, at)] = list(fu)
            cases[(W_HDU, at)] = [without_dirac_deltas(hdu)]
            cases[(W_HDUD, at)] = [without_dirac_deltas(sp.diff(hdu, U_SYMBOL))]
    for s, sw in enumerate(model.switches):
        if s in family_switches:
            continue
        # family f(t, x, u) of Utkin's equivalent control; affine (the convex combination,
        # thesis eq. 2.7 with alpha = (1 - u)/2) for switches written as two explicit modes
        if sw.family is not None:
            fu = sp.Matrix(sw.family)
        else:
            fu = ((1 + U_SYMBOL) / 2 * sp.Matrix(model.modes[sw.above].rhs)
                  + (1 - U_SYMBOL) / 2 * sp.Matrix(model.modes[sw.below].rhs))
        h = model.surfaces[sw.surface].expr
        hdu = sp.diff(h, t) + (sp.Matrix([h]).jacobian(X) * fu)[0]
        cases[(W_FU, s)] = list(fu)
        cases[(W_HDU, s)] = [without_dirac_deltas(hdu)]
        cases[(W_HDUD, s)] = [without_dirac_deltas(sp.diff(hdu, U_SYMBOL))]
    for j, ev in enumerate(model.events):
        g = sp.Matrix(ev.reset if ev.reset is not None else model.state_symbols)
        cases[(W_G, j)] = list(g)
        cases[(W_GX, j)] = [without_dirac_deltas(e) for e in g.jacobian(X)]
        cases[(W_GT, j)] = [without_dirac_deltas(e) for e in g.diff(t)]
        cases[(W_GUARD, j)] = [ev.guard if ev.guard is not None else sp.true]
    multi = {fam.first: fam for fam in model.families if fam.multilinear}
    for i in range(nm):
        fam = next((f for f in multi.values() if f.first <= i < f.first + f.size), None)
        cases[(W_FAMILY, i)] = ([sp.Integer(0)] if fam is None else
                                [sp.Integer(len(fam.surfaces)), sp.Integer(fam.first),
                                 *(sp.Integer(q) for q in fam.surfaces)])
    for first, fam in multi.items():
        sides = [side_symbol(j) for j in range(len(fam.surfaces))]
        f = sp.Matrix(fam.rhs)
        cases[(W_FS, first)] = list(f)
        cases[(W_FSD, first)] = [without_dirac_deltas(e) for e in f.jacobian(sides)]
    assert all(len(v) in (1, 2, n, n * n) or which in (W_FAMILY, W_FSD)
               for (which, _), v in cases.items())
    # derivatives of finite expressions are finite where they exist; refuse a constant that
    # is not (it would be NaN at every point, or not compile)
    for (which, idx), exprs in cases.items():
        for e in exprs:
            why = unprintable(e)
            if why == "derivative":
                raise ModelError(f"the {_QUANTITIES.get(which, 'derivative')} (case {idx}) "
                                 f"of model {model.name!r} has a term SymPy cannot differentiate "
                                 f"in closed form ({str(e)[:200]}); simplify the expression",
                                 source=model.origin)
            if why == "complex":
                raise ModelError(f"the {_QUANTITIES.get(which, 'derivative')} (case {idx}) "
                                 f"of model {model.name!r} has the non-finite or complex value "
                                 f"{str(e)[:200]}; a field that is complex (a negative number to "
                                 "a non-integer power, ...) cannot be integrated",
                                 source=model.origin)
    # the affine matrices of the modes, then those of the families' fields in their sides
    # (after the modes, so that the forcing frequencies keep the modes' order)
    # (the families' fields are looked at only where all their variants are affine: the
    # affine test simplifies a field's constant term, which in the sides of an arbitrary
    # field can take long)
    aff = affine_structure(model)
    fams = [f for f in model.families
            if all(aff.matrices[i] is not None for i in range(f.first, f.first + f.size))]
    if fams:
        aff = affine_structure(SimpleNamespace(
            t=model.t, state_symbols=model.state_symbols, states=model.states,
            modes=tuple(model.modes) + tuple(Mode(f"family {j}", f.rhs)
                                             for j, f in enumerate(fams))))
    cases[(W_AFFINE, -1)] = [sp.Integer(aff.dimension if aff.any else 0)]
    per_mode = set(range(nm))
    for j, fam in enumerate(fams):
        variants = range(fam.first, fam.first + fam.size)
        M = aff.matrices[nm + j]
        # one body where the family's field is affine (each variant keeps its own matrix
        # otherwise)
        if M is not None:
            per_mode -= set(variants)
            at = FamilyRange(fam.first, fam.first + fam.size - 1, len(fam.surfaces))
            cases[(W_AFFINE, at)] = [sp.Integer(1), *M]
    for i in sorted(per_mode):
        M = aff.matrices[i]
        cases[(W_AFFINE, i)] = [sp.Integer(0)] if M is None else [sp.Integer(1), *M]
    return Derivatives(cases)


def generate_source(model: Model) -> str:
    """Python/numba source of the model's ``evaluate`` function, as written to the cache."""
    from .cache import header

    body = _generate_body(model)
    return header("model", _CODEGEN_VERSION, model.digest, body) + "\n" + body


def _generate_body(model: Model) -> str:
    """The module's text after its header line; what SymPy cannot differentiate or print is a
    :class:`ModelError` naming the model."""
    try:
        return _emit_body(model)
    except RecursionError:
        raise ModelError(f"model {model.name!r} is too deeply nested to differentiate; "
                         "simplify its expressions", source=model.origin) from None
    except PrintMethodNotImplementedError as exc:
        what = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ModelError(f"model {model.name!r} needs a function that cannot be compiled "
                         f"({what}); simplify the expression", source=model.origin) from None
    except ModelError:
        raise
    except (TypeError, ValueError, ArithmeticError, AttributeError, IndexError,
            KeyError) as exc:
        # SymPy on a degenerate derivative (an undefined constant, an incomparable Max)
        raise ModelError(f"model {model.name!r} cannot be differentiated "
                         f"({type(exc).__name__}: {str(exc)[:200]})",
                         source=model.origin) from None


def _emit_body(model: Model) -> str:
    # a Model built by hand (not through the loader) is checked here too: only identifiers
    # reach the source
    check_identifiers(model.states, model.parameters, origin=model.origin)
    der = derivatives(model)
    return emit_evaluate(der.cases, model.states, model.parameters)


def emit_evaluate(cases: dict, states, parameters) -> str:
    """Source of a module with one numba function ``evaluate(which, idx, t, x, p, out)`` of
    :data:`EVALUATE_SIGNATURE` that writes the expressions ``cases[(which, idx)]`` (SymPy, in
    the symbols ``t``, ``states`` and ``parameters``) into ``out``.

    The model's own module is ``emit_evaluate(derivatives(model).cases, ...)``; other code
    (the orbit problems of :mod:`pwsdyn.orbits.problem`) emits its own cases the same way, so
    that the compiled kernel integrates them. ``states`` and ``parameters`` must be checked
    identifiers (:func:`~pwsdyn.model.symbolic.check_identifiers`): they become prefixed locals.
    """
    check_identifiers(states, parameters)
    pr = NumbaPrinter()
    lines = [
        "import math",
        "import numba",
        "from pwsdyn.model.codegen import EVALUATE_SIGNATURE",
        "",
        "",
        "@numba.njit(EVALUATE_SIGNATURE, cache=True, fastmath=False, error_model='numpy')",
        "def evaluate(which, idx, t, x, p, out):",
    ]
    # User names become locals with a prefix (``s_`` states, ``p_`` parameters), so that no
    # state or parameter (``x``, ``p``, ``out``, ``math``, ...) can shadow an argument of
    # ``evaluate``, a module global or a CSE temporary (``_c0``, ...).
    rename = {sp.Symbol(s, real=True): sp.Symbol(f"s_{s}", real=True) for s in states}
    rename.update({sp.Symbol(s, real=True): sp.Symbol(f"p_{s}", real=True)
                   for s in parameters})
    rename[U_SYMBOL] = sp.Symbol("u_sw", real=True)
    for i, s in enumerate(states):
        lines.append(f"    s_{s} = x[{i}]")
    for i, s in enumerate(parameters):
        lines.append(f"    p_{s} = p[{i}]")
    by_which: dict = {}
    for (which, idx), exprs in cases.items():
        by_which.setdefault(which, []).append((idx, exprs))
    for which in sorted(by_which):
        lines.append(f"    if which == {which}:")
        # cases with the same expressions share one body (emitted at the first of them): the
        # variants of a mode split at several sign() terms repeat most of their derivatives
        # (the normal velocity of a friction contact depends on its own side only), and
        # numba's compile time grows with the text. The arithmetic is the same either way.
        # A family's range of cases is one body already, its sides decoded from idx.
        bodies: dict = {}
        for idx, exprs in sorted(by_which[which], key=lambda c: operator.index(c[0])):
            body = _case_body(pr, which, [sp.sympify(e).xreplace(rename) for e in exprs])
            if isinstance(idx, FamilyRange):
                used = {str(q) for e in exprs for q in sp.sympify(e).free_symbols}
                bodies[idx] = (tuple(idx.prologue(used)) + body, [idx])
                continue
            bodies.setdefault(body, (body, []))[1].append(idx)
        for body, idxs in sorted(bodies.values(), key=lambda b: operator.index(b[1][0])):
            if isinstance(idxs[0], FamilyRange):
                lines.append(f"        if {idxs[0].lo} <= idx <= {idxs[0].hi}:")
            else:
                lines.append(f"        if {_idx_test(idxs)}:")
            lines.extend(body)
    lines.append("    return")
    return "\n".join(lines) + "\n"


def _idx_test(idxs) -> str:
    """The condition ``idx`` is one of ``idxs`` (sorted): runs of consecutive values as
    ranges, so that a long list stays one short line."""
    runs, start = [], idxs[0]
    for a, b in zip(idxs, idxs[1:] + [None]):
        if b != a + 1:
            runs.append((start, a))
            start = b
    parts = [f"idx == {lo}" if lo == hi else f"{lo} <= idx <= {hi}" for lo, hi in runs]
    return " or ".join(parts)


def _case_body(pr, which, exprs) -> tuple:
    """The lines (indented) writing the expressions of one case into ``out``."""
    lines = []
    if which == W_GUARD:
        lines.append(f"            out[0] = 1.0 if ({pr.doprint(exprs[0])}) else 0.0")
        lines.append("            return")
        return tuple(lines)
    if which in (W_FU, W_HDU, W_HDUD):
        lines.append("            u_sw = out[0]")
    if which in (W_FS, W_FSD):
        used = sorted({str(q) for e in exprs for q in e.free_symbols
                       if str(q).startswith("side_")}, key=lambda q: int(q[5:]))
        lines.extend(f"            {q} = out[{q[5:]}]" for q in used)
    subs, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_c"))
    for sym, val in subs:
        lines.append(f"            {sym} = {pr.doprint(val)}")
    for k, e in enumerate(reduced):
        lines.append(f"            out[{k}] = {pr.doprint(e)}")
    lines.append("            return")
    return tuple(lines)


@dataclass
class CompiledModel:
    """A model with its compiled ``evaluate`` function and the tables the kernel reads."""

    model: Model
    evaluate: object
    compile_seconds: float
    source_path: Path
    # kernel tables (numpy arrays)
    event_surface: np.ndarray
    event_direction: np.ndarray
    event_kind: np.ndarray
    event_target: np.ndarray
    event_terminal: np.ndarray
    event_active: np.ndarray  # (n_events, n_modes) bool -> int8
    event_has_reset: np.ndarray
    switch_surface: np.ndarray
    switch_above: np.ndarray
    switch_below: np.ndarray
    #: 0 Filippov, 1 continuous (crossing only) per switch
    switch_kind: np.ndarray | None = None
    #: Per surface, 1 if h depends on t explicitly (the kernel then checks that each step
    #: resolves h in time, not only the state)
    surface_time_dependent: np.ndarray | None = None


_COMPILED: dict[str, CompiledModel] = {}

EVENT_KIND_CODES = {k: i for i, k in enumerate(MODEL_EVENT_KINDS)}


def compile_model(model: Model) -> CompiledModel:
    """Generate, cache and compile the model's functions (once per process and per disk cache).

    The generated module is ``<cache_dir>/m_<sha256>_v<version>.py``; numba keeps its machine
    code next to it, so a second process loads it without compiling.
    """
    key = model.digest
    if key in _COMPILED:
        cm = _COMPILED[key]
        # the same code with the caller's model: what the digest leaves out (description,
        # units, text) may differ from the model compiled first, and results carry the model
        return cm if cm.model is model else dataclasses.replace(cm, model=model)
    t0 = time.perf_counter()
    n = model.n_states

    def warm_up(evaluate):
        # force compilation (or the load from numba's cache) now, so its cost is measured here
        evaluate(W_F, 0, 0.0, np.zeros(n), np.zeros(max(1, len(model.parameters))),
                 np.zeros(n * n))

    def generate():
        body = _generate_body(model)
        if len(body) > MAX_SOURCE_CHARS:
            raise ModelError(f"model {model.name!r} needs {len(body)} characters of generated "
                             f"code ({len(model.modes)} modes, {len(model.surfaces)} surfaces, "
                             f"{len(model.switches)} switches, {model.n_states} states); at most "
                             f"{MAX_SOURCE_CHARS} are compiled. Use fewer modes or simpler "
                             "expressions", source=model.origin)
        return body

    evaluate, path = load_module("model", _CODEGEN_VERSION, key, generate, model_name=model.name,
                                 attribute="evaluate", warm_up=warm_up)
    # passed to the kernel on every run: its numba type is built once, not per call
    evaluate = type_once(evaluate)
    elapsed = time.perf_counter() - t0

    ne, nm = len(model.events), len(model.modes)
    active = np.zeros((max(ne, 1), nm), dtype=np.int8)
    for j, ev in enumerate(model.events):
        for m in ev.modes:
            active[j, m] = 1
    cm = CompiledModel(
        model=model, evaluate=evaluate, compile_seconds=elapsed, source_path=path,
        event_surface=np.array([e.surface for e in model.events], dtype=np.int64),
        event_direction=np.array([e.direction for e in model.events], dtype=np.int64),
        event_kind=np.array([EVENT_KIND_CODES[e.kind] for e in model.events], dtype=np.int64),
        event_target=np.array([-1 if e.target is None else e.target for e in model.events],
                              dtype=np.int64),
        event_terminal=np.array([e.terminal for e in model.events], dtype=np.int64),
        event_active=active,
        event_has_reset=np.array([e.reset is not None for e in model.events], dtype=np.int64),
        switch_surface=np.array([s.surface for s in model.switches], dtype=np.int64),
        switch_above=np.array([s.above for s in model.switches], dtype=np.int64),
        switch_below=np.array([s.below for s in model.switches], dtype=np.int64),
        switch_kind=np.array([0 if s.kind == "filippov" else 1 for s in model.switches],
                             dtype=np.int64),
        surface_time_dependent=np.array([1 if sp.diff(s.expr, model.t) != 0 else 0
                                         for s in model.surfaces], dtype=np.int64),
    )
    _COMPILED[key] = cm
    return cm
