r"""Modes that are affine in the state with harmonic forcing, for exact propagation.

Most models of the field are piecewise linear: the impact oscillator, the ball on a vibrating
table, linear friction oscillators, relay feedback of a linear plant. In such a mode the
vector field has the form

.. math::

    f(t, x) = A x + b + \sum_j \left(c_j \cos(\omega_j t) + d_j \sin(\omega_j t)\right),

with :math:`A, b, c_j, d_j, \omega_j` depending on the parameters only. Appending the forcing
to the state, :math:`z = (x, 1, \cos(\omega_1 t), \sin(\omega_1 t), \ldots)`, makes the flow
autonomous and linear,

.. math::

    z' = M z, \qquad
    M = \begin{pmatrix} A & b & c_1 & d_1 & \cdots \\ 0 & 0 & 0 & 0 & \cdots \\
                        0 & 0 & R_1 & & \\ \vdots & & & \ddots & \end{pmatrix}, \qquad
    R_j = \begin{pmatrix} 0 & -\omega_j \\ \omega_j & 0 \end{pmatrix},

so :math:`z(t + h) = e^{M h} z(t)` exactly (the augmentation of Van Loan, IEEE TAC 23 (1978),
which also covers singular ``A``, as for a ball in flight, and resonant forcing, where the
particular solution of the textbook method does not exist).

:func:`affine_structure` recognises such modes symbolically and builds ``M`` for each, over
one set of frequencies shared by all modes of the model (so that ``z`` has the same layout in
every mode). The compiled kernel evaluates ``M`` through the model's ``evaluate`` function
(selector ``W_AFFINE``) and propagates with a Taylor-summed exponential (see
``pwsdyn.integrate._kernel``).
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .discontinuities import U_SYMBOL


@dataclass(frozen=True)
class AffineStructure:
    """The affine forms of a model's modes.

    Attributes
    ----------
    frequencies : tuple of sympy expressions
        The forcing frequencies ``w_j`` (functions of the parameters), shared by all modes.
    matrices : tuple
        Per mode, the augmented matrix ``M`` (sympy Matrix, ``nz x nz`` with
        ``nz = n + 1 + 2 * len(frequencies)``), or ``None`` if the mode is not affine.
    reasons : tuple of str
        Per mode, why it is not affine ('' if it is).
    """

    n_states: int
    frequencies: tuple
    matrices: tuple
    reasons: tuple

    @property
    def dimension(self) -> int:
        """``nz``: states, the constant 1 and a (cos, sin) pair per frequency."""
        return self.n_states + 1 + 2 * len(self.frequencies)

    @property
    def affine_modes(self) -> tuple:
        return tuple(m is not None for m in self.matrices)

    @property
    def any(self) -> bool:
        return any(self.affine_modes)


def _harmonic_atoms(expr, t):
    """The sin/cos terms of ``expr`` whose argument contains ``t``."""
    return [a for a in expr.atoms(sp.sin, sp.cos) if a.args[0].has(t)]


def _frequency_of(atom, t, states, forbidden):
    """``(w, phi)`` with the atom's argument ``w t + phi``, or a reason string."""
    arg = sp.expand(atom.args[0])
    w = sp.diff(arg, t)
    if w.has(t) or w.free_symbols & forbidden:
        return f"the argument of {atom} is not of the form w*t + phi with constant w"
    phi = sp.expand(arg - w * t)
    if phi.has(t) or phi.free_symbols & (set(states) | forbidden):
        return f"the phase of {atom} depends on the state"
    return w, phi


def _same_frequency(w, known):
    """Index and sign (+1 / -1) of ``w`` among the ``known`` frequencies, or ``(None, 0)``."""
    for j, wk in enumerate(known):
        if sp.simplify(w - wk) == 0:
            return j, 1
        if sp.simplify(w + wk) == 0:
            return j, -1
    return None, 0


def affine_structure(model) -> AffineStructure:
    """Recognise the modes of ``model`` that are affine in the state with harmonic forcing.

    A mode qualifies when, after writing every ``sin``/``cos`` of ``w t + phi`` through
    ``cos(w t)`` and ``sin(w t)``, its vector field has a gradient with respect to the states
    and these harmonics that depends on the parameters only. ``t`` anywhere else (``t*x``,
    ``exp(-t)``, ``cos(w t)**2``), nonlinear terms and unresolved switching terms disqualify
    the mode, with the reason recorded.
    """
    t = model.t
    X = list(model.state_symbols)
    n = len(X)
    forbidden = {t, U_SYMBOL} | set(X)
    # pass 1: the frequencies of all modes
    freqs: list = []
    reasons = [""] * len(model.modes)
    atoms_of = []
    for i, mode in enumerate(model.modes):
        found = []
        for e in mode.rhs:
            for a in _harmonic_atoms(sp.sympify(e), t):
                wf = _frequency_of(a, t, X, forbidden)
                if isinstance(wf, str):
                    reasons[i] = reasons[i] or wf
                    continue
                w, phi = wf
                j, sign = _same_frequency(w, freqs)
                if j is None:
                    freqs.append(w)
                    j, sign = len(freqs) - 1, 1
                found.append((a, j, sign, phi))
        atoms_of.append(found)
    C = [sp.Dummy(f"cos{j}") for j in range(len(freqs))]
    S = [sp.Dummy(f"sin{j}") for j in range(len(freqs))]
    Z = X + [v for pair in zip(C, S) for v in pair]
    nz = n + 1 + 2 * len(freqs)
    matrices = []
    for i, mode in enumerate(model.modes):
        if reasons[i]:
            matrices.append(None)
            continue
        # sin(s w t + phi) = s sin(w t) cos(phi) + cos(w t) sin(phi), and cos likewise
        sub = {}
        for a, j, s, phi in atoms_of[i]:
            if isinstance(a, sp.sin):
                sub[a] = s * S[j] * sp.cos(phi) + C[j] * sp.sin(phi)
            else:
                sub[a] = C[j] * sp.cos(phi) - s * S[j] * sp.sin(phi)
        M = sp.zeros(nz, nz)
        for r, e in enumerate(mode.rhs):
            fe = sp.sympify(e).xreplace(sub)
            if fe.has(t):
                reasons[i] = f"f[{model.states[r]}] = {e} depends on t other than by sin/cos(w*t)"
                break
            if fe.has(U_SYMBOL) or fe.has(sp.sign) or fe.has(sp.Heaviside):
                reasons[i] = f"f[{model.states[r]}] = {e} has a switching term"
                break
            grad = [sp.diff(fe, z) for z in Z]
            bad = [g for g in grad if g.free_symbols & set(Z) or g.has(sp.DiracDelta)]
            if bad:
                reasons[i] = f"f[{model.states[r]}] = {e} is not affine in the states"
                break
            # what is left after the linear part must not depend on the states: a term whose
            # derivative vanishes almost everywhere (atan2(0, f(x)), piecewise constant) is
            # not affine even though its gradient is constant
            rest = sp.expand(fe - sum(g * z for g, z in zip(grad, Z)))
            if rest.free_symbols & set(Z):
                reasons[i] = f"f[{model.states[r]}] = {e} is not affine in the states"
                break
            try:
                const = sp.simplify(rest)
            except (TypeError, ValueError, ArithmeticError):
                const = sp.nan
            if const.has(sp.nan, sp.zoo, sp.oo, -sp.oo, sp.I):
                reasons[i] = f"f[{model.states[r]}] = {e} has no finite constant term"
                break
            for c, g in enumerate(grad[:n]):
                M[r, c] = g
            M[r, n] = const
            for c, g in enumerate(grad[n:]):
                M[r, n + 1 + c] = g
        if reasons[i]:
            matrices.append(None)
            continue
        for j, w in enumerate(freqs):
            # d/dt cos(w t) = -w sin(w t), d/dt sin(w t) = w cos(w t)
            M[n + 1 + 2 * j, n + 2 + 2 * j] = -w
            M[n + 2 + 2 * j, n + 1 + 2 * j] = w
        matrices.append(M)
    return AffineStructure(n, tuple(freqs), tuple(matrices), tuple(reasons))
