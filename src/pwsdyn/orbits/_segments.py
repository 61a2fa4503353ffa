"""The segments of a hybrid orbit as smooth pieces: fields, end conditions and event maps.

A periodic orbit on a fixed signature is a cycle of smooth segments. Each segment has a field
(a mode's, the constrained field of sticking on an impact surface, the Filippov sliding field
on a switch), ends where a scalar *condition* vanishes (a surface ``h``, a normal velocity
``h_t + h_x f`` at a sliding exit, a free normal acceleration at a release), and is joined to
the next by an *event map* (a reset, the identity, or the complete-chattering map with its
jump in time). :class:`SegmentSystem` writes all of these as SymPy expressions of the model
and compiles them into one function of the code generator's signature
(:func:`pwsdyn.model.codegen.emit_evaluate`), with the model's chosen parameters appended to
the states (``p' = 0``, :mod:`pwsdyn.model.augment`): every Jacobian is then symbolic and
carries the parameter derivatives ``f_p``, ``h_p``, ``g_p`` as its last columns.

The fields are integrated by the compiled kernel as *regular modes of a model without events
or switches*, so a segment runs for the duration it is given whatever surfaces it meets: the
orbit can be followed into the region where it is not admissible. A negative duration is
integrated backwards in time by the field's time-reversed twin ``-f(-s, z)``.

Fields and derivatives (all from the model's expressions; ``f`` the mode's field,
``hd = h_t + h_x f`` the normal velocity, ``a = hd_t + hd_x f`` the free normal acceleration):

* sticking on impact event ``j`` (slides, "Simulation: Chattering"; the kernel's
  :func:`~pwsdyn.integrate._kernel.fields._field`): ``f - lambda W`` with
  ``W = (g_x - I) hd_x^T / |hd_x|^2`` and ``lambda = a / (hd_x W)``;
* sliding on switch ``s`` (thesis eq. 2.7-2.8): ``(1 - alpha) f_above + alpha f_below`` with
  ``alpha = hd_above / (hd_above - hd_below)``; for ``sliding='utkin'`` the family
  ``f(t, x, u)`` at the root of ``h_t + h_x f(u) = 0`` where that root is explicit (a family
  affine in ``u``, where it equals the convex field);
* sliding on the intersection of ``k >= 2`` switching surfaces (the kernel's multilinear
  extension of Dieci and Lopez, :mod:`pwsdyn.integrate`): ``sum_c prod_i w_i(c) f_c`` over
  the ``2^k`` corner modes, ``w_i = lambda_i`` below surface ``i`` and ``1 - lambda_i``
  above, with ``lambda`` the root of ``h_i,t + h_i,x f = 0``. Where those conditions are
  linear in ``lambda`` (the coefficients of every ``lambda_i lambda_j`` vanish: fields affine
  in the signs, as dry friction and relays written with ``sign``) the ``k x k`` linear system
  is solved here in closed form; otherwise the rule has no closed form and the orbit problem
  refuses it (plain shooting integrates it with the kernel's Newton iteration);
* complete chattering (slides, "Local mapping at complete chattering"; Nordmark & Piiroinen
  2009; the kernel's ``_chatter_map``): ``Z = x + c v``, ``tau = t + b v`` with ``v = hd``,
  ``r = -(1 + hd_x W)``, ``b = 2 r / ((1 - r) a)``, ``c = (2 r f / a + W) / (1 - r)``, then
  ``Z`` projected onto the sticking manifold ``{h = 0, hd = 0}`` at ``tau`` along
  ``N = (h_x, hd_x)`` (:mod:`pwsdyn.orbits.problem` solves that projection and differentiates
  it implicitly, with the second derivatives ``h_xx``, ``hd_xx`` generated here).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass

import numpy as np
import sympy as sp

from .._compiling import type_once
from ..errors import ArgumentError, ModelError, Status
from ..model.cache import load_module
from ..model.codegen import (W_AFFINE, W_F, W_FX, W_G, W_GT, W_GX, W_H,
                             W_HT, W_HX, CompiledModel, without_dirac_deltas, emit_evaluate)
from ..model.discontinuities import U_SYMBOL
from ..model.spec import Mode, Model
from ._base import OrbitError

_VERSION = "1"


@dataclass(frozen=True)
class FieldKey:
    """A segment's field: ``('mode', m)``, ``('stick', j, m)`` (impact event ``j``, constrained
    mode ``m``), ``('slide', s)`` (switch ``s``) or ``('slide_multi', mask, m)`` (sliding on
    the intersection of the surfaces in the bit mask ``mask``, ``m`` the corner mode above all
    of them, as the kernel codes it)."""

    kind: str
    index: int
    mode: int = -1


class SegmentSystem:
    """Compiled fields, scalar and vector functions of a model with parameters as states.

    Parameters
    ----------
    model : Model
    free : tuple of str
        Parameters appended to the states (their derivatives are the last columns of every
        Jacobian).
    sliding : {'convex', 'utkin'}
    fields : sequence of FieldKey
    scalars : sequence of tuple
        Keys of scalar functions: ``('h', k)`` surface ``k``; ``('hd', k, m)`` its normal
        velocity in mode ``m``; ``('acc', k, m)`` the free normal acceleration;
        ``('chat_dt', j, m)`` the time ``b v`` of the chattering map of impact event ``j``;
        ``('lam', mask, m, i, e)`` the weight ``lambda_i - e`` (``e`` 0 or 1) of the ``i``-th
        surface of sliding on the intersection ``('slide_multi', mask, m)``.
    vectors : sequence of tuple
        Keys of vector functions (``n + q`` entries): ``('reset', j)`` the reset of event
        ``j``; ``('chat_z', j, m)`` the chattering map ``Z``; ``('hx', k)``, ``('hdx', k, m)``
        the gradients of ``h`` and ``hd`` over the model's states (zero parameter entries).
    """

    def __init__(self, model: Model, free, sliding: str, fields, scalars, vectors):
        self.model = model
        self.free = tuple(free)
        self.sliding = sliding
        self.fields = list(dict.fromkeys(fields))
        self.scalars = list(dict.fromkeys(scalars))
        self.vectors = list(dict.fromkeys(vectors))
        self.n = model.n_states
        self.q = len(self.free)
        self.naug = self.n + self.q
        self.rest = [k for k in model.parameters if k not in self.free]
        self.states = tuple(model.states) + self.free
        key = "\n".join([f"segments v{_VERSION}", model.digest, repr(self.free), sliding,
                         repr(self.fields), repr(self.scalars), repr(self.vectors)])
        self.digest = hashlib.sha256(key.encode()).hexdigest()
        t0 = time.perf_counter()
        nz = self.naug

        def warm_up(fn):
            fn(W_F, 0, 0.0, np.zeros(nz), np.zeros(max(1, len(self.rest))), np.zeros(nz * nz))

        evaluate, path = load_module("segments", _VERSION, self.digest, self._source,
                                     model_name=model.name, attribute="evaluate",
                                     warm_up=warm_up)
        # passed to the kernel on every segment run: its numba type resolved once, as the
        # model's own evaluate is (pwsdyn._compiling.type_once)
        self.evaluate = type_once(evaluate)
        self.compile_seconds = time.perf_counter() - t0
        nf = 2 * len(self.fields)
        names = [f"segment_field_{i}" for i in range(nf)]
        self.kernel_model = Model(
            name=f"segments-{self.digest[:16]}", states=self.states,
            parameters={k: float(model.parameters[k]) for k in self.rest},
            modes=tuple(Mode(nm, ()) for nm in names), surfaces=(), events=(), switches=(),
            origin="<segments>")
        z = np.zeros(0, dtype=np.int64)
        self.cm = CompiledModel(
            model=self.kernel_model, evaluate=self.evaluate, compile_seconds=self.compile_seconds,
            source_path=path, event_surface=z, event_direction=z, event_kind=z, event_target=z,
            event_terminal=z, event_active=np.zeros((1, nf), dtype=np.int8), event_has_reset=z,
            switch_surface=z, switch_above=z, switch_below=z, switch_kind=z,
            surface_time_dependent=z)
        self._buf = np.zeros(max(nz * nz, 2))

    # ---- indices --------------------------------------------------------------------------
    def field_index(self, key: FieldKey, reverse: bool = False) -> int:
        i = self.fields.index(key)
        return i + len(self.fields) if reverse else i

    def scalar_index(self, key) -> int:
        return self.scalars.index(key)

    def vector_index(self, key) -> int:
        return self.vectors.index(key)

    # ---- point evaluations ----------------------------------------------------------------
    def _eval(self, which, idx, t, z, pv, size):
        out = self._buf
        self.evaluate(which, int(idx), float(t), z, pv, out)
        return out[:size].copy()

    def field(self, i, t, z, pv) -> np.ndarray:
        return self._eval(W_F, i, t, z, pv, self.naug)

    def field_jacobian(self, i, t, z, pv) -> np.ndarray:
        return self._eval(W_FX, i, t, z, pv, self.naug * self.naug).reshape(self.naug, self.naug)

    def scalar(self, i, t, z, pv, grad: bool = True):
        """Value, gradient over the extended state and time derivative of scalar ``i``."""
        # (the three evaluations in a row into the one buffer, the scalars read from it
        # without a copy: an orbit evaluation asks for a few of these per segment)
        ev, out, na = self.evaluate, self._buf, self.naug
        i, t = int(i), float(t)
        ev(W_H, i, t, z, pv, out)
        v = float(out[0])
        if not grad:
            return v
        ev(W_HX, i, t, z, pv, out)
        g = out[:na].copy()
        ev(W_HT, i, t, z, pv, out)
        return v, g, float(out[0])

    def vector(self, i, t, z, pv, jac: bool = True):
        """Value, Jacobian over the extended state and time derivative of vector ``i``."""
        ev, out, na = self.evaluate, self._buf, self.naug
        i, t = int(i), float(t)
        ev(W_G, i, t, z, pv, out)
        v = out[:na].copy()
        if not jac:
            return v
        ev(W_GX, i, t, z, pv, out)
        J = out[:na * na].reshape(na, na).copy()
        ev(W_GT, i, t, z, pv, out)
        return v, J, out[:na].copy()

    # ---- symbolic construction (only when the compiled module is not cached) ---------------
    def _source(self) -> str:
        try:
            cases = self._cases()
        except (TypeError, ValueError, ArithmeticError, AttributeError, RecursionError) as exc:
            raise ModelError(f"the segment fields of model {self.model.name!r} cannot be "
                             f"derived ({type(exc).__name__}: {str(exc)[:200]})") from None
        return emit_evaluate(cases, self.states, self.rest)

    def _cases(self) -> dict:
        m = self.model
        t = m.t
        Z = sp.Matrix(list(m.state_symbols) + [sp.Symbol(k, real=True) for k in self.free])
        n, q = self.n, self.q
        S = _Symbolic(m, self.sliding)
        cases: dict = {}
        nf = len(self.fields)
        for i, key in enumerate(self.fields):
            f = sp.Matrix(list(S.field(key)) + [0] * q)
            cases[(W_F, i)] = list(f)
            cases[(W_FX, i)] = [without_dirac_deltas(e) for e in f.jacobian(Z)]
            # time-reversed twin: s = -t, dz/ds = -f(-s, z)
            fr = -f.subs(t, -t)
            cases[(W_F, i + nf)] = list(fr)
            cases[(W_FX, i + nf)] = [without_dirac_deltas(e) for e in fr.jacobian(Z)]
        for i, key in enumerate(self.scalars):
            e = without_dirac_deltas(S.scalar(key))
            cases[(W_H, i)] = [e]
            cases[(W_HX, i)] = [without_dirac_deltas(v) for v in sp.Matrix([e]).jacobian(Z)]
            cases[(W_HT, i)] = [without_dirac_deltas(sp.diff(e, t))]
        for i, key in enumerate(self.vectors):
            v = S.vector(key)
            if key[0] in ("reset", "chat_z"):
                v = list(v) + [sp.Symbol(k, real=True) for k in self.free]
            else:
                v = list(v) + [0] * q
            vm = sp.Matrix([without_dirac_deltas(e) for e in v])
            cases[(W_G, i)] = list(vm)
            cases[(W_GX, i)] = [without_dirac_deltas(e) for e in vm.jacobian(Z)]
            cases[(W_GT, i)] = [without_dirac_deltas(e) for e in vm.diff(t)]
        cases[(W_AFFINE, -1)] = [sp.Integer(0)]
        assert all(len(v) in (1, n + q, (n + q) ** 2) for v in cases.values())
        for (which, idx), exprs in cases.items():
            for e in exprs:
                if isinstance(e, sp.Basic) and e.has(sp.Derivative, sp.Subs, sp.I, sp.nan,
                                                     sp.zoo):
                    raise ModelError(f"a segment quantity of model {m.name!r} cannot be "
                                     f"written in closed form ({str(e)[:200]})")
        return cases


class _Symbolic:
    """SymPy expressions of the segment quantities of a model (over its own states)."""

    def __init__(self, model: Model, sliding: str):
        self.m = model
        self.t = model.t
        self.X = sp.Matrix(model.state_symbols)
        self.sliding = sliding
        self._multi: dict = {}

    def f(self, mode: int) -> sp.Matrix:
        return sp.Matrix(self.m.modes[mode].rhs)

    def grad(self, e) -> sp.Matrix:
        return sp.Matrix([e]).jacobian(self.X)

    def h(self, k: int):
        return self.m.surfaces[k].expr

    def hd(self, k: int, mode: int):
        h = self.h(k)
        return sp.diff(h, self.t) + (self.grad(h) * self.f(mode))[0]

    def acc(self, k: int, mode: int):
        hd = self.hd(k, mode)
        return sp.diff(hd, self.t) + (self.grad(hd) * self.f(mode))[0]

    def W(self, j: int, mode: int) -> sp.Matrix:
        """Impact direction of the kernel's ``_impact_direction``: ``(g_x - I) hd_x^T /
        |hd_x|^2``."""
        ev = self.m.events[j]
        g = sp.Matrix(ev.reset) if ev.reset is not None else self.X
        gx = g.jacobian(self.X)
        hdx = self.grad(self.hd(ev.surface, mode))
        return (gx - sp.eye(len(self.X))) * hdx.T / (hdx * hdx.T)[0]

    def field(self, key: FieldKey) -> sp.Matrix:
        if key.kind == "mode":
            return self.f(key.index)
        if key.kind == "stick":
            j, mode = key.index, key.mode
            k = self.m.events[j].surface
            W = self.W(j, mode)
            hdx = self.grad(self.hd(k, mode))
            lam = self.acc(k, mode) / (hdx * W)[0]
            return self.f(mode) - lam * W
        if key.kind == "slide":
            sw = self.m.switches[key.index]
            k = sw.surface
            if self.sliding == "utkin" and sw.family is not None:
                fam = sp.Matrix(sw.family)
                hdu = sp.diff(self.h(k), self.t) + (self.grad(self.h(k)) * fam)[0]
                poly = sp.Poly(sp.expand(hdu), U_SYMBOL)
                if poly.degree() != 1:
                    raise ArgumentError(f"sliding='utkin' on switch {sw.name!r}: its family is "
                                        f"not affine in the switching variable, so the "
                                        f"equivalent control has no closed form; orbit "
                                        f"problems support the convex method there")
                a1, a0 = poly.all_coeffs()
                return fam.subs(U_SYMBOL, -a0 / a1)
            fa, fb = self.f(sw.above), self.f(sw.below)
            ha, hb = self.hd(k, sw.above), self.hd(k, sw.below)
            alpha = ha / (ha - hb)
            return (1 - alpha) * fa + alpha * fb
        if key.kind == "slide_multi":
            return self.multi(key.index, key.mode)[0]
        raise ValueError(key)

    def multi(self, mask: int, ref: int):
        """``(field, lambda)`` of sliding on the intersection of the surfaces of ``mask``
        (corner ``ref`` above all of them): the multilinear extension at the root ``lambda``
        of its tangency conditions, solved in closed form where they are linear in
        ``lambda``; :class:`~pwsdyn.OrbitError` where they are not."""
        got = self._multi.get((mask, ref))
        if got is not None:
            return got
        m = self.m
        ks = [k for k in range(len(m.surfaces)) if (mask >> k) & 1]
        nk = len(ks)
        lam = sp.symbols(f"lambda_0:{nk}", real=True)
        total = sp.zeros(len(self.X), 1)
        for c in range(1 << nk):
            mode = ref
            for i, k in enumerate(ks):
                if (c >> i) & 1:
                    mode = _below(m, k, mode)
            weight = sp.Integer(1)
            for i in range(nk):
                weight *= lam[i] if (c >> i) & 1 else 1 - lam[i]
            total += weight * self.f(mode)
        # the tangency conditions h_i,t + h_i,x f(lambda) = 0, multilinear in lambda
        conds = [sp.diff(self.h(k), self.t) + (self.grad(self.h(k)) * total)[0] for k in ks]
        names = "&".join(m.surfaces[k].name for k in ks)
        for i, g in enumerate(conds):
            for a in range(nk):
                for b in range(a + 1, nk):
                    d2 = sp.expand(sp.diff(g, lam[a], lam[b]))
                    if d2 != 0 and sp.simplify(d2) != 0:
                        raise OrbitError(
                            Status.SIGNATURE,
                            f"sliding on the intersection {names} of model {m.name!r}: its "
                            f"tangency condition on {m.surfaces[ks[i]].name!r} is not linear "
                            f"in the weights (the coefficient of {lam[a]}*{lam[b]} is "
                            f"{str(d2)[:120]}), so the multilinear rule has no closed form and "
                            f"an orbit problem cannot follow such a segment; plain shooting "
                            f"(find_periodic_orbit without `signature`) integrates it")
        zero = {v: 0 for v in lam}
        A = sp.Matrix(nk, nk, lambda i, j: sp.diff(conds[i], lam[j]).subs(zero))
        b = sp.Matrix([g.subs(zero) for g in conds])
        sol = A.LUsolve(-b)
        sol = [sp.cancel(v) if v.count_ops() < 400 else v for v in sol]
        field = total.subs(dict(zip(lam, sol)))
        got = self._multi[(mask, ref)] = (field, sol)
        return got

    def chatter(self, j: int, mode: int):
        ev = self.m.events[j]
        k = ev.surface
        f = self.f(mode)
        v = self.hd(k, mode)
        a = self.acc(k, mode)
        W = self.W(j, mode)
        hdx = self.grad(v)
        r = -(1 + (hdx * W)[0])
        b = 2 * r / ((1 - r) * a)
        c = (2 * r * f / a + W) / (1 - r)
        return self.X + c * v, b * v

    def scalar(self, key):
        kind = key[0]
        if kind == "h":
            return self.h(key[1])
        if kind == "hd":
            return self.hd(key[1], key[2])
        if kind == "acc":
            return self.acc(key[1], key[2])
        if kind == "chat_dt":
            return self.chatter(key[1], key[2])[1]
        if kind == "lam":
            return self.multi(key[1], key[2])[1][key[3]] - key[4]
        raise ValueError(key)

    def vector(self, key):
        kind = key[0]
        if kind == "reset":
            ev = self.m.events[key[1]]
            return list(ev.reset) if ev.reset is not None else list(self.X)
        if kind == "chat_z":
            return list(self.chatter(key[1], key[2])[0])
        if kind == "hx":
            return list(self.grad(self.h(key[1])))
        if kind == "hdx":
            return list(self.grad(self.hd(key[1], key[2])))
        raise ValueError(key)


def _below(model, k: int, mode: int) -> int:
    """The mode across surface ``k`` below ``mode`` (the product variants are joined pairwise
    by switches, :mod:`pwsdyn.model.discontinuities`)."""
    for sw in model.switches:
        if sw.surface == k and sw.above == mode:
            return int(sw.below)
    raise ArgumentError(f"mode {model.modes[mode].name!r} of model {model.name!r} has no "
                        f"switch to a mode below surface {model.surfaces[k].name!r}")
