"""The printer of generated model and map code: SymPy expressions as Python source for numba.

Its own module so that flows (:mod:`pwsdyn.model.codegen`) and maps
(:mod:`pwsdyn.model.maps`) print with the same rules without the maps importing the flows'
code generator.
"""

from __future__ import annotations

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter


def unprintable(expr) -> str | None:
    """Why the generated code, which computes in real doubles, cannot hold ``expr``:
    ``"derivative"`` (a derivative SymPy left unevaluated), ``"complex"`` (a complex or
    non-finite term: NaN at every point, or code that does not compile), or None. Flows and
    maps refuse such a model at code generation."""
    if not isinstance(expr, sp.Basic):
        return None
    if expr.has(sp.Derivative, sp.Subs):
        return "derivative"
    if expr.has(sp.I, sp.nan, sp.zoo, sp.oo, -sp.oo):
        return "complex"
    return None


class NumbaPrinter(PythonCodePrinter):
    """SymPy expressions as Python source that numba compiles to what the model means."""

    def __init__(self):
        super().__init__({"fully_qualified_modules": True, "inline": True})

    # numba types integer literals as int64: one beyond 2**53 (where doubles stop being
    # exact anyway) is written as the double it stands for
    def _print_Integer(self, expr):
        if abs(int(expr)) > 2**53:
            return repr(float(expr))
        return super()._print_Integer(expr)

    def _print_Rational(self, expr):
        if abs(int(expr.p)) > 2**53 or int(expr.q) > 2**53:
            return repr(float(expr))
        return super()._print_Rational(expr)

    # SymPy differentiates Abs(f) of an f it cannot prove real into re() and im() terms; the
    # generated code computes in real doubles (a complex value is NaN there), so re(f) = f,
    # im(f) = 0 and conjugate(f) = f
    def _print_re(self, expr):
        return f"({self._print(expr.args[0])})"

    def _print_im(self, expr):
        return "0.0"

    def _print_conjugate(self, expr):
        return f"({self._print(expr.args[0])})"

    def _print_Heaviside(self, expr):
        a = self._print(expr.args[0])
        return f"(1.0 if {a} > 0 else (0.0 if {a} < 0 else 0.5))"

    def _print_DiracDelta(self, expr):
        # derivative of sign/Heaviside: zero away from the surface; the surface is an event
        return "0.0"

    def _print_BooleanTrue(self, expr):
        return "True"

    def _print_BooleanFalse(self, expr):
        return "False"

    # numba raises ZeroDivisionError for ``0.0 ** -k`` (a negative integer power) whatever the
    # error model, where ``1.0 / 0.0 ** k`` is inf: a model that divides by zero somewhere
    # must get a non-finite value the integrator reports, not an exception out of the kernel
    def _print_Pow(self, expr, rational=False):
        base, ex = expr.args
        if ex.is_Integer and ex < -1:
            return f"(1.0/({self._print(sp.Pow(base, -ex, evaluate=False))}))"
        return super()._print_Pow(expr, rational=rational)
