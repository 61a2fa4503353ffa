"""Discontinuous functions in vector fields turned into modes and switching surfaces.

A paper writes dry friction as ``mu*sign(v - V)``, a relay as ``-sign(C x)``, bilinear
damping as ``ce*Max(vr, 0) + cc*Min(vr, 0)``, loss of tyre contact as ``Max(0, F)``. Each of
these is a piecewise-smooth vector field whose pieces are smooth: this module finds the
discontinuous terms of every mode, splits the mode into its smooth variants and joins the
variants by switching surfaces, so that the model the loader returns is the hybrid system the
formula denotes (thesis eq. 2.6: ``f = f1`` where ``h > 0``, ``f2`` where ``h < 0``).

* ``sign(s)`` and ``Heaviside(s)``: the field jumps across ``s = 0``. The two variants are
  joined by a Filippov switch (kind ``"filippov"``), so the simulation crosses, slides (thesis
  eq. 2.7-2.8, convex method; or Utkin's equivalent control, slides "Simulation: Filippov
  systems") and leaves the surface as the Filippov solution does.
* ``Abs(s)``, ``Max(a, b, ...)``, ``Min(a, b, ...)``: the field is continuous and only its
  derivative jumps (across ``s = 0``, ``a - b = 0``). The variants are joined by a switch of
  kind ``"continuous"``: its crossing is located to a few ulps (so the Runge-Kutta steps never
  straddle the kink and keep their order) and logged as a ``crossing``; there is no sliding.

Several discontinuous terms give the product of their sides: a mode with ``sign(s1)`` and
``sign(s2)`` becomes four variants, joined pairwise across ``s1`` and across ``s2``. Nested
terms (``Max(lo, Min(hi, x))``) are split from the inside out; the variants are all sign
patterns of all the surfaces that occur, so that two variants that differ in the side of one
surface only are always joined by a switch on it.

Variant names keep the user's mode name recognisable: ``slip[v-V>0]``, ``ride[vr<0,tyre>0]``.
A surface whose expression is (plus or minus) a named definition is called by that name.

For Utkin's equivalent control each Filippov switch carries its *family* ``f(t, x, u)``: the
mode's field with the switching term replaced by a scalar ``u`` in ``[-1, 1]`` (``sign(s) ->
u``, ``Heaviside(s) -> (1 + u)/2``), so ``f(u=+1)`` is the field above the surface and
``f(u=-1)`` the one below. The equivalent control solves ``h_t + h_x f(t, x, u) = 0`` for ``u``.
Where ``f`` is affine in ``u`` this is Filippov's convex combination (thesis eq. 2.7 with
``alpha = (1 - u)/2``); where the switching term enters nonlinearly (``sign(s)**2``,
``exp(sign(s))``, a relay inside a nonlinear actuator) the two methods give different sliding
motions.
"""

from __future__ import annotations

import itertools

import sympy as sp

from ..errors import ModelError
from .elements import Mode, SignFamily, Surface, Switch

#: The scalar switching variable of Utkin's equivalent control in a switch's family f(t, x, u).
U_SYMBOL = sp.Symbol("u_switch", real=True)


def side_symbol(j: int) -> sp.Symbol:
    """The side variable ``side_j`` of a :class:`~pwsdyn.model.elements.SignFamily`'s field."""
    return sp.Symbol(f"side_{j}", real=True)


#: Kinds of switch.
FILIPPOV, CONTINUOUS = "filippov", "continuous"

#: Most distinct surfaces in one mode (2**k variants).
MAX_SURFACES_PER_MODE = 10

#: Most modes a model may have once its modes are split -- each variant is compiled with its
#: derivatives, surfaces and switches, and compilation grows faster than the number of modes
#: (16 modes of one field with four ``sign`` terms compile in about 7 s, 64 in minutes).
MAX_SPLIT_MODES = 16

#: Most variants of one mode split into a sign family (one field of their sides, compiled
#: once for all of them: :class:`~pwsdyn.model.elements.SignFamily`), counted apart from the
#: other modes; the variants are still listed one by one (names, switches, tables), which
#: bounds them: ``2**MAX_SURFACES_PER_MODE``, one variant per side of each of the most
#: surfaces a mode may have.
MAX_FAMILY_MODES = 2 ** MAX_SURFACES_PER_MODE

_JUMP = (sp.sign, sp.Heaviside)
_KINK = (sp.Abs, sp.Max, sp.Min)
_DISC = _JUMP + _KINK


def _is_disc(e) -> bool:
    return isinstance(e, _DISC)


def has_discontinuities(expr) -> bool:
    """Whether ``expr`` contains ``sign``, ``Heaviside``, ``Abs``, ``Max`` or ``Min``."""
    return isinstance(expr, sp.Basic) and any(expr.has(f) for f in _DISC)


def _innermost(exprs) -> list:
    """Discontinuous terms of ``exprs`` whose arguments contain no discontinuous term."""
    return [node for node in _disc_nodes(exprs)
            if not any(has_discontinuities(a) for a in _switch_args(node))]


def _disc_nodes(exprs):
    """The distinct discontinuous terms of ``exprs``, nested ones included."""
    seen = set()
    for e in exprs:
        for node in sp.preorder_traversal(e):
            if _is_disc(node) and node not in seen:
                seen.add(node)
                yield node


def _switch_args(atom) -> tuple:
    """The arguments of a discontinuous term that decide its side (Heaviside's optional value
    at zero does not)."""
    if isinstance(atom, sp.Heaviside):
        return atom.args[:1]
    return atom.args


def _surface_of(atom):
    """The switching function of an innermost term: ``s`` for sign/Heaviside/Abs, ``a1 - a2``
    for Max/Min (their first two arguments)."""
    if isinstance(atom, (sp.Max, sp.Min)):
        return atom.args[0] - atom.args[1]
    return atom.args[0]


class _Registry:
    """The model's surfaces (shared with events and explicit switches), found up to sign."""

    def __init__(self, surfaces: list, definitions: dict, variables: tuple):
        self._Surface = Surface
        self.surfaces = surfaces
        self.variables = variables
        self.defs = {}
        for name, e in (definitions or {}).items():
            self.defs.setdefault(e, name)

    def find(self, expr):
        """Index and orientation (``expr = orient * surface``) of ``expr``, registering it."""
        for i, s in enumerate(self.surfaces):
            if s.expr == expr:
                return i, 1
            if s.expr == -expr or sp.expand(s.expr + expr) == 0:
                return i, -1
        orient = self._orientation(expr)
        surf = orient * expr
        self.surfaces.append(self._Surface(self._name(surf), surf))
        return len(self.surfaces) - 1, orient

    def _orientation(self, expr) -> int:
        """SymPy stores ``sign(v - V)`` as ``-sign(V - v)``; orient a new surface the way
        users write it: as a named definition if it is one, else increasing in the first
        state (then time) it depends on."""
        if expr in self.defs:
            return 1
        if -expr in self.defs:
            return -1
        for var in self.variables:
            d = sp.diff(expr, var)
            if d != 0:
                return -1 if d.could_extract_minus_sign() else 1
        return -1 if expr.could_extract_minus_sign() else 1

    def _name(self, expr) -> str:
        if expr in self.defs:
            return self.defs[expr]
        return sp.sstr(expr, order="none").replace(" ", "")

    def label(self, k: int) -> str:
        """The name of surface ``k`` in mode and switch names: its definition's name or its
        expression (also when the surface is shared with an event named otherwise)."""
        return self._name(self.surfaces[k].expr)


def _apply(expr, registry: _Registry, sides: dict, u_surface: int | None = None):
    """Evaluate the discontinuous terms of ``expr`` on the sides ``{surface: +1 or -1}``.

    With ``u_surface``, terms on that surface are replaced by the switching variable
    ``U_SYMBOL`` instead (Utkin's family). Returns ``(expr, pending)``: ``pending`` is the
    index of a surface met that has no side in ``sides`` (``None`` when ``expr`` is smooth;
    -1 when a term's surface would depend on ``U_SYMBOL``).
    """
    for _ in range(10_000):
        atoms = _innermost([expr])
        if not atoms:
            return expr, None
        rep = {}
        for atom in atoms:
            s = _surface_of(atom)
            if s.has(U_SYMBOL):
                # a term whose surface depends on the switching variable (Max(Heaviside(b),
                # b + 4) in Utkin's family of b): the family is not of the affine form the
                # kernel solves; no surface of the model may hold U_SYMBOL
                return expr, -1
            k, orient = registry.find(s)
            if k == u_surface:
                sg = orient * U_SYMBOL
            elif k in sides:
                sg = orient * sides[k]
            else:
                return expr, k
            rep[atom] = _value(atom, s, sg)
        expr = expr.xreplace(rep)
    raise ModelError("discontinuous terms nested too deeply")  # pragma: no cover


def _value(atom, s, sg):
    """The term on the side where ``sign(s) = sg`` (``sg`` = +-1 or ``+-U_SYMBOL``)."""
    if isinstance(atom, sp.sign):
        return sg
    if isinstance(atom, sp.Heaviside):
        return (1 + sg) / 2
    if isinstance(atom, sp.Abs):
        return s * sg
    a1, a2, rest = atom.args[0], atom.args[1], atom.args[2:]
    if sg in (1, -1):
        big, small = (a1, a2) if sg == 1 else (a2, a1)
        pick = big if isinstance(atom, sp.Max) else small
    else:
        # Max(a1, a2) = (a1 + a2 + |a1 - a2|)/2 and |a1 - a2| = s sign(s)
        half = (a1 + a2) / 2
        pick = half + s * sg / 2 if isinstance(atom, sp.Max) else half - s * sg / 2
    if not rest:
        return pick
    return type(atom)(pick, *rest)


def _family_rhs(rhs, registry: _Registry, found: list, jumps: set):
    """The field of all the variants of ``rhs`` in the side variables of the surfaces
    ``found`` (:class:`~pwsdyn.model.elements.SignFamily`), or ``None`` where it is not one
    field of that form: a term nested in another's argument (its surface then depends on a
    side), a ``Max``/``Min`` of more than two arguments, or one on a surface where the field
    also jumps (Utkin's family of that surface takes the kink's mean there, not its sides).

    The terms on side ``sg = +-1`` become what :func:`_value` gives on that side, written so
    that each variant's arithmetic is exact: ``sign -> sg``, ``Heaviside -> (1 + sg)/2``,
    ``Abs(s) -> s sg`` (exact multiplications by +-1, 0 or 1), ``Max``/``Min`` -> the argument
    the side picks (a ``Piecewise``, not the mean plus half the difference, which would lose
    the smaller argument to cancellation)."""
    sides = {k: side_symbol(j) for j, k in enumerate(found)}
    out = []
    for expr in rhs:
        for _ in range(10_000):
            atoms = _innermost([expr])
            if not atoms:
                break
            rep = {}
            for atom in atoms:
                s = _surface_of(atom)
                if s.free_symbols & set(sides.values()):
                    return None
                k, orient = registry.find(s)
                if k not in sides:  # pragma: no cover - found covers every surface
                    return None
                sg = orient * sides[k]
                if isinstance(atom, (sp.Max, sp.Min)):
                    if len(atom.args) != 2 or k in jumps:
                        return None
                    a1, a2 = atom.args
                    big, small = (a1, a2) if isinstance(atom, sp.Max) else (a2, a1)
                    rep[atom] = sp.Piecewise((big, sg > 0), (small, True))
                else:
                    rep[atom] = _value(atom, s, sg)
            expr = expr.xreplace(rep)
        else:  # pragma: no cover
            return None
        if _side_masks_a_term(expr, set(sides.values()), registry.variables):
            return None
        out.append(expr)
    return tuple(out)


def _multilinear(rhs, registry: _Registry, found: list, jumps: set) -> bool:
    """Whether the family of ``rhs`` is affine in each side on the surfaces, where every
    ``Abs`` term is zero (``Abs(v - V)`` of a velocity-weakening friction law), with only
    ``sign``/``Heaviside``/``Abs`` terms (a ``Max``/``Min`` kink is a ``Piecewise`` in its
    side)."""
    if any(e.has(sp.Max, sp.Min) for e in rhs):
        return False
    # each Abs term as a symbol of its own, free of the sides (it is zero on its surface;
    # substituting 0 itself would let SymPy evaluate what surrounds it, (0 + 2)**(10**12)
    # included), then: affine in each side where the second derivative in it vanishes
    # (SymPy's derivative of a side times anything free of it is that thing, whose
    # derivative is 0; nothing is expanded or evaluated)
    absent = {a: sp.Dummy() for e in rhs for a in e.atoms(sp.Abs)}
    fam = _family_rhs([e.xreplace(absent) for e in rhs], registry, found, jumps)
    if fam is None:
        return False
    sides = [side_symbol(j) for j in range(len(found))]
    return all(sp.diff(e, s, 2) == 0 for e in fam for s in sides)


def _side_masks_a_term(expr, sides: set, variables: tuple) -> bool:
    """Whether a product in ``expr`` has a factor in the sides that may be zero on some side
    (``(1 + side)/2`` of a ``Heaviside``: any factor but a side or a power of one) next to
    factors that are not a polynomial in ``variables`` (the states and time): the variant on
    that side drops the product, the family would compute ``0 * g`` and give NaN where ``g``
    is not finite (``Heaviside(x)*sqrt(x)`` at ``x < 0``). Nothing is evaluated (a side set
    to +-1 in ``(side + 2)**(10**12)`` would be)."""
    for node in sp.preorder_traversal(expr):
        if not isinstance(node, sp.Mul):
            continue
        for f in node.args:
            if not f.free_symbols & sides or f in sides or (f.is_Pow and f.base in sides):
                continue
            # the other factors finite wherever the states are (a polynomial): nothing to mask
            if not sp.Mul(*(g for g in node.args if g is not f)).is_polynomial(*variables):
                return True
    return False


def _surfaces_of_mode(rhs, registry: _Registry) -> tuple[list, set]:
    """All surfaces met in any variant of ``rhs`` (in order of discovery) and those of them
    on which a jump (sign/Heaviside) is met."""
    found: list = []
    jumps: set = set()

    def note(atoms):
        for atom in atoms:
            k, _ = registry.find(_surface_of(atom))
            if k not in found:
                found.append(k)
            if isinstance(atom, _JUMP):
                jumps.add(k)

    atoms = _innermost(rhs)
    if len(atoms) == sum(1 for _ in _disc_nodes(rhs)):
        # no term nested in another's argument: every surface is met in the field as it is
        # written (the search below, over the 2**k sides, would find them in this order)
        note(atoms)
        return found, jumps

    def explore(exprs, sides, depth):
        if depth > 2 * MAX_SURFACES_PER_MODE + 2:
            return
        atoms = _innermost(exprs)
        if not atoms:
            return
        note(atoms)
        if len(found) > MAX_SURFACES_PER_MODE:
            return
        free = [registry.find(_surface_of(a))[0] for a in atoms]
        free = [k for k in free if k not in sides]
        if not free:
            return
        k = free[0]
        for side in (1, -1):
            s2 = dict(sides)
            s2[k] = side
            new = []
            for e in exprs:
                # substitute every term whose surface has a side; keep the others
                new.append(_partial(e, registry, s2))
            explore(new, s2, depth + 1)

    explore(list(rhs), {}, 0)
    return found, jumps


def _partial(expr, registry, sides):
    """Substitute the innermost terms whose surface has a side, repeatedly."""
    for _ in range(10_000):
        atoms = _innermost([expr])
        rep = {}
        for atom in atoms:
            s = _surface_of(atom)
            if s.has(U_SYMBOL):
                # a term whose surface depends on the switching variable (Max(Heaviside(b),
                # b + 4) in Utkin's family of b): the family is not of the affine form the
                # kernel solves; no surface of the model may hold U_SYMBOL
                return expr, -1
            k, orient = registry.find(s)
            if k in sides:
                rep[atom] = _value(atom, s, orient * sides[k])
        if not rep:
            return expr
        expr = expr.xreplace(rep)
    return expr  # pragma: no cover


class _Components:
    """The components of one mode's field on given sides, each evaluated once per combination
    of the sides of the surfaces it meets: a contact's friction force depends on its own side
    only, so a mode split at ``k`` contacts has two values per component, not ``2**k``.

    The result is :func:`_apply`'s on all the sides: a component is evaluated on the sides of
    the surfaces found in it (``_surfaces_of_mode`` on the component alone), and again on all
    the sides where it meets one more."""

    def __init__(self, rhs, registry: _Registry):
        self.rhs, self.registry = tuple(rhs), registry
        self.met = [frozenset(_surfaces_of_mode((e,), registry)[0]) for e in self.rhs]
        self._values: dict = {}
        self._disc: dict = {}

    def on(self, i: int, sides: dict, u_surface: int | None = None):
        """``_apply(rhs[i], registry, sides, u_surface)``."""
        met = self.met[i]
        u = u_surface if u_surface in met else None
        key = (i, u, tuple(sorted((k, sd) for k, sd in sides.items() if k in met and k != u)))
        out = self._values.get(key)
        if out is None:
            out = _apply(self.rhs[i], self.registry, dict(key[2]), u)
            if out[1] is not None:
                # a surface the search did not list (or none may be resolved): on every side
                return _apply(self.rhs[i], self.registry, sides, u_surface)
            self._values[key] = out
        return out

    def discontinuous(self, expr) -> bool:
        """``has_discontinuities(expr)``, once per distinct expression."""
        out = self._disc.get(expr)
        if out is None:
            out = self._disc[expr] = has_discontinuities(expr)
        return out


def expand_discontinuities(modes, surfaces, events, switches, initial_mode, definitions,
                           variables=()):
    """Split every mode with discontinuous terms into its smooth variants.

    Parameters
    ----------
    modes : list[Mode]
    surfaces : list[Surface]
        Extended in place with the new switching surfaces.
    events : list[Event]
    switches : list[Switch]
        The explicit switches of the model.
    initial_mode : int
    definitions : dict[str, sympy.Expr]
        Named definitions (to name surfaces).
    variables : tuple of sympy.Symbol
        The states, then time: a new surface is oriented increasing in the first of them it
        depends on (``v - V``, not ``V - v``).

    Returns
    -------
    modes, events, switches, initial_mode, families
        The model with the variants in place of the split modes: events active in a split
        mode are active in all its variants, an event or explicit switch that targets it
        targets its first variant (the simulator then picks the variant on the right side of
        each surface), explicit switches are repeated for each pair of compatible variants, and
        new switches join the variants. ``families`` holds a
        :class:`~pwsdyn.model.elements.SignFamily` for each split mode whose variants are
        one field of their sides.

    Raises
    ------
    ModelError
        A mode with more than ``MAX_SURFACES_PER_MODE`` distinct surfaces, or a split that
        would give more than ``MAX_SPLIT_MODES`` modes (the variants of a sign family counted
        apart: at most ``MAX_FAMILY_MODES`` per family).
    """
    if not any(has_discontinuities(e) for m in modes for e in m.rhs):
        return list(modes), list(events), list(switches), initial_mode, []
    registry = _Registry(surfaces, definitions, tuple(variables))
    new_modes: list = []
    variants: list[list[int]] = []      # original mode -> new mode indices
    conds: list[dict] = []              # new mode -> {surface: side}
    new_switches: list = []
    families: list = []                 # switch indices relative to new_switches for now
    for m in modes:
        if not any(has_discontinuities(e) for e in m.rhs):
            variants.append([len(new_modes)])
            new_modes.append(m)
            conds.append({})
            continue
        found, jumps = _surfaces_of_mode(m.rhs, registry)
        if len(found) > MAX_SURFACES_PER_MODE:
            raise ModelError(f"mode {m.name!r} has more than {MAX_SURFACES_PER_MODE} distinct "
                             f"switching surfaces ({', '.join(registry.label(k) for k in found)}"
                             f"); write it as explicit modes and switches", field=f"modes.{m.name}")
        fam_rhs = _family_rhs(m.rhs, registry, found, jumps)
        # the variants of a family count against their own bound, the rest together
        rest = sum(1 for later in modes[modes.index(m) + 1:]
                   if not any(has_discontinuities(e) for e in later.rhs))
        if fam_rhs is None:
            total = len(new_modes) - sum(f.size for f in families) + 2 ** len(found) + rest
            limit = MAX_SPLIT_MODES
        else:
            total, limit = 2 ** len(found), MAX_FAMILY_MODES
        if total > limit:
            raise ModelError(f"splitting mode {m.name!r} at its {len(found)} switching surfaces "
                             f"({', '.join(registry.label(k) for k in found)}) would give the "
                             f"model at least {total} modes; at most {limit} are "
                             "allowed. Write the modes and switches explicitly, or use fewer "
                             "discontinuous terms per field", field=f"modes.{m.name}")
        first = len(new_modes)
        index = {}
        terms = _Components(m.rhs, registry)
        labels = [registry.label(k) for k in found]
        for pattern in itertools.product((1, -1), repeat=len(found)):
            sides = dict(zip(found, pattern))
            rhs = []
            for i, e in enumerate(m.rhs):
                val, pending = terms.on(i, sides)
                if pending is not None:  # pragma: no cover - found covers every surface
                    raise ModelError(f"mode {m.name!r}: could not resolve the discontinuous "
                                     f"terms of {e}", field=f"modes.{m.name}")
                rhs.append(val)
            label = ",".join(f"{lab}{'>' if sd > 0 else '<'}0" for lab, sd in zip(labels, pattern))
            index[pattern] = len(new_modes)
            new_modes.append(Mode(f"{m.name}[{label}]", tuple(rhs)))
            conds.append(sides)
        variants.append(list(range(first, len(new_modes))))
        # switches between variants that differ in the side of one surface: surface by
        # surface, each in the order of the variant above it (so that a family's switches on
        # one surface are a run of indices the generated code decodes)
        fam_switches = []
        for j, k in enumerate(found):
            fam_switches.append(len(new_switches) if k in jumps else -1)
            for pattern, above in index.items():
                if pattern[j] != 1:
                    continue
                other = pattern[:j] + (-1,) + pattern[j + 1:]
                below = index[other]
                kind = FILIPPOV if k in jumps else CONTINUOUS
                family = None
                if kind == FILIPPOV:
                    sides = dict(zip(found, pattern))
                    fam = []
                    for i in range(len(m.rhs)):
                        val, pending = terms.on(i, sides, u_surface=k)
                        if pending is not None or terms.discontinuous(val):
                            fam = None
                            break
                        fam.append(val)
                    family = tuple(fam) if fam is not None else None
                new_switches.append(Switch(labels[j], k, above, below, kind=kind,
                                           family=family))
        if fam_rhs is not None:
            families.append(SignFamily(first, tuple(found), fam_rhs, tuple(fam_switches),
                                       _multilinear(m.rhs, registry, found, jumps)))

    def compatible(a, b):
        ca, cb = conds[a], conds[b]
        return all(ca[k] == cb[k] for k in ca.keys() & cb.keys())

    out_switches = []
    for sw in switches:
        for a in variants[sw.above]:
            for b in variants[sw.below]:
                if compatible(a, b):
                    out_switches.append(Switch(sw.name, sw.surface, a, b, kind=sw.kind,
                                               family=None))
    offset = len(out_switches)
    out_switches.extend(new_switches)
    families = [SignFamily(f.first, f.surfaces, f.rhs,
                           tuple(-1 if q < 0 else q + offset for q in f.switches), f.multilinear)
                for f in families]

    out_events = []
    for ev in events:
        emodes = tuple(v for m in ev.modes for v in variants[m])
        target = None if ev.target is None else variants[ev.target][0]
        out_events.append(type(ev)(ev.name, ev.kind, ev.surface, ev.direction, emodes, ev.guard,
                                   ev.reset, target, ev.terminal))
    return new_modes, out_events, out_switches, variants[initial_mode][0], families
