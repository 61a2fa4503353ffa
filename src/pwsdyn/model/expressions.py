"""Safe parsing of user expressions into SymPy.

User text is never passed to ``eval`` (SymPy's ``sympify``/``parse_expr`` do call ``eval``).
Instead the text is parsed with Python's ``ast`` module and the tree is walked node by node; only
numbers, known names, arithmetic, comparisons, boolean connectives and calls of the whitelisted
functions below are accepted. Anything else -- attribute access, subscripts, lambdas,
comprehensions, strings, unknown names -- raises :class:`~pwsdyn.ExpressionError` naming the
offending construct.
"""

from __future__ import annotations

import ast
import math
import operator

import sympy as sp
from sympy.calculus.accumulationbounds import AccumBounds

from ..errors import ExpressionError

#: Functions an expression may call, by the name users write.
FUNCTIONS = {
    "sin": sp.sin, "cos": sp.cos, "tan": sp.tan,
    "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "atan2": sp.atan2,
    "arcsin": sp.asin, "arccos": sp.acos, "arctan": sp.atan, "arctan2": sp.atan2,
    "sinh": sp.sinh, "cosh": sp.cosh, "tanh": sp.tanh,
    "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt,
    "abs": sp.Abs, "Abs": sp.Abs,
    "sign": sp.sign, "Heaviside": sp.Heaviside, "heaviside": sp.Heaviside,
    "Max": sp.Max, "Min": sp.Min, "max": sp.Max, "min": sp.Min,
}

# the SymPy classes those names build (and DiracDelta, the derivative of sign and Heaviside)
_FUNCTION_CLASSES = {f for f in FUNCTIONS.values() if isinstance(f, type)} | {sp.DiracDelta}

#: How many arguments each function takes, as (min, max); max None = any number.
ARITY = {name: (1, 1) for name in FUNCTIONS}
ARITY.update({"atan2": (2, 2), "arctan2": (2, 2), "log": (1, 2), "Max": (1, None),
              "Min": (1, None), "max": (1, None), "min": (1, None)})

#: Largest exponent allowed in a power of two numbers (``9**9**9`` would be computed exactly
#: by SymPy and never finish).
MAX_NUMERIC_EXPONENT = 1000

#: Largest size of one expression once definitions are substituted, counted as its distinct
#: subexpressions plus, for each product of m factors, m**2 (its derivative is a sum of m
#: products of m - 1 factors): symbolic differentiation and code generation grow with it. A
#: product of 300 distinct factors costs 90,000 and would take seconds to differentiate and
#: minutes to compile; the largest field of the built-in models costs under 100.
MAX_EXPRESSION_COST = 20_000
#: Largest syntax tree of one expression's text (a 500-term polynomial has 3,500 nodes).
MAX_SYNTAX_NODES = 10_000

#: Deepest nesting accepted (SymPy, the code printer and numba recurse on it).
MAX_DEPTH = 100

# every number must be a finite double: 2**1024 is the first power of two that is not
_LOG2_DOUBLE_MAX = 1024.0

#: Constants an expression may use.
CONSTANTS = {"pi": sp.pi, "e_const": sp.E, "inf": sp.oo}

_BINOPS = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
    ast.Div: operator.truediv, ast.Pow: operator.pow,
}
_CMPOPS = {
    ast.Lt: sp.StrictLessThan, ast.LtE: sp.LessThan,
    ast.Gt: sp.StrictGreaterThan, ast.GtE: sp.GreaterThan,
}


def check_expression(expr, fail, text="") -> None:
    """Refuse an expression that holds a non-finite or complex constant (``0/0``, ``x/0``,
    ``log(0)``, ``sqrt(-1)``, ``sin(inf)``) or a number outside double precision, or that is
    too large: ``fail(message)`` raises.

    Such a constant would make the vector field NaN or infinite everywhere, or fail to
    compile; saying so at load names the field."""
    what = f" {text[:200]!r}" if text else ""
    if not isinstance(expr, sp.Basic):
        return
    nodes, stack, cost = set(), [expr], 0
    while stack:
        e = stack.pop()
        if e in nodes:
            continue
        nodes.add(e)
        cost += 1 + (len(e.args) ** 2 if isinstance(e, sp.Mul) else 0)
        if cost > MAX_EXPRESSION_COST:
            fail(f"expression{what} is too large to differentiate and compile in reasonable "
                 f"time once its definitions are substituted (size over {MAX_EXPRESSION_COST}; "
                 "simplify it)")
        if e in (sp.nan, sp.zoo, sp.oo, -sp.oo) or isinstance(e, AccumBounds):
            fail(f"expression{what} evaluates to the non-finite value {e} (a division by zero, "
                 "log(0), inf - inf, ...)")
        if e is sp.I:
            fail(f"expression{what} has a complex value (square root or logarithm of a "
                 "negative number, ...)")
        if isinstance(e, sp.Number):
            try:
                ok = math.isfinite(float(e))
            except (OverflowError, TypeError, ValueError):
                ok = False
            if not ok:
                fail(f"the number {str(e)[:40]} in expression{what} is outside double precision")
        stack.extend(e.args)


def parse_expression(text, names: dict, *, field: str = "", source: str | None = None,
                     line: int | None = None, boolean: bool = False) -> sp.Expr:
    """Parse ``text`` into a SymPy expression using only ``names``.

    Parameters
    ----------
    text : str, int, float or sympy.Basic
        The expression. Numbers pass through; SymPy objects are checked for unknown symbols.
    names : dict[str, sympy.Basic]
        The names the expression may use (states, parameters, definitions, time).
    field, source, line :
        Where the expression comes from, for error messages.
    boolean : bool
        Accept comparisons and ``and``/``or``/``not`` (guards).

    Raises
    ------
    ExpressionError
        On a syntax error, a forbidden construct or an unknown name.
    """
    def fail(msg):
        raise ExpressionError(msg, source=source, field=field, line=line)

    if isinstance(text, bool):
        fail(f"expected an expression, got the boolean {text!r}")
    if isinstance(text, (int, float)):
        if isinstance(text, float) and not math.isfinite(text):
            fail(f"the number {text!r} is not finite")
        if isinstance(text, int) and abs(text).bit_length() > _LOG2_DOUBLE_MAX:
            fail("the integer is too large for double precision")
        return sp.Float(text) if isinstance(text, float) else sp.Integer(text)
    if isinstance(text, sp.Basic):
        allowed = set(names.values())
        unknown = sorted(str(s) for s in text.free_symbols if s not in allowed)
        if unknown:
            fail(f"unknown name(s) {', '.join(repr(u) for u in unknown)} in expression")
        # a SymPy object may hold any function, whose name the code printer would write out
        foreign = sorted({type(f).__name__ for f in text.atoms(sp.Function)
                          if type(f) not in _FUNCTION_CLASSES})
        if foreign:
            fail(f"function(s) {', '.join(foreign)} are not allowed; allowed functions are "
                 f"{', '.join(sorted(FUNCTIONS))}")
        check_expression(text, fail)
        return text
    if not isinstance(text, str):
        fail(f"expected an expression string, got {type(text).__name__}")
    src = text.strip()
    if not src:
        fail("empty expression")
    if len(src) > 20_000:
        fail("expression longer than 20000 characters")
    src = src.replace("^", "**")
    try:
        tree = ast.parse(src, mode="eval")
    except SyntaxError as exc:
        fail(f"invalid expression {text!r}: {exc.msg}")
    except (MemoryError, RecursionError):
        # CPython's parser gives up on very deep nesting ('-' * 10000 + '1')
        fail("expression nested too deeply (or too long a chain of operators) to parse")
    n_nodes = sum(1 for _ in ast.walk(tree))
    if n_nodes > MAX_SYNTAX_NODES:
        fail(f"expression has {n_nodes} syntax nodes; at most {MAX_SYNTAX_NODES} are "
             "allowed (split it into definitions or simplify it)")

    def number(value):
        """A literal as a SymPy number, refused unless it is a finite double."""
        if isinstance(value, float) and not math.isfinite(value):
            fail(f"the number in {text!r} is not finite in double precision")
        if isinstance(value, int) and abs(value).bit_length() > _LOG2_DOUBLE_MAX:
            fail(f"the integer in {text!r} is too large for double precision")
        return sp.Integer(value) if isinstance(value, int) else sp.Float(value)

    def power(base, expo):
        # two numbers: refuse a result outside the range of doubles before SymPy computes it
        # exactly (9**999 has 954 digits, ((9**999)**999)**999 would never finish)
        if base.is_number and expo.is_number and expo.is_real and base not in (0, 1, -1):
            if abs(float(expo)) > MAX_NUMERIC_EXPONENT:
                fail(f"the power in {text!r} has a numeric exponent larger than "
                     f"{MAX_NUMERIC_EXPONENT}; write the number as a literal")
            b = abs(complex(base))
            if b != 0.0 and abs(float(expo) * math.log2(b)) > _LOG2_DOUBLE_MAX:
                fail(f"the power in {text!r} is outside the range of double precision")
        return base ** expo

    def walk(node, depth=0):
        if depth > MAX_DEPTH:
            fail(f"expression nested deeper than {MAX_DEPTH} levels")
        if isinstance(node, ast.Expression):
            return walk(node.body, depth + 1)
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                fail(f"only numeric literals are allowed, not {node.value!r}")
            return number(node.value)
        if isinstance(node, ast.Name):
            if node.id in names:
                return names[node.id]
            if node.id in CONSTANTS:
                return CONSTANTS[node.id]
            if node.id in FUNCTIONS:
                fail(f"function {node.id!r} used without arguments")
            fail(f"unknown name {node.id!r} in expression {text!r}; known names are "
                 f"{', '.join(sorted(names))}")
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS \
                and not isinstance(node.op, ast.Pow):
            # a long sum or product 'a + b + c + ...' is a deep left spine: walk it iteratively
            # so that its length does not count as nesting depth
            spine = []
            while isinstance(node, ast.BinOp) and type(node.op) in _BINOPS \
                    and not isinstance(node.op, ast.Pow):
                spine.append(node)
                node = node.left
            # runs of + and - (or * and /) are built as one n-ary Add (Mul): adding terms one at
            # a time re-flattens the sum each time, quadratic in its length
            val = walk(node, depth + 1)
            run, family = [val], None
            for op_node in reversed(spine):
                op, right = type(op_node.op), walk(op_node.right, depth + 1)
                fam = sp.Add if op in (ast.Add, ast.Sub) else sp.Mul
                if fam is not family and family is not None:
                    run = [family(*run)]
                family = fam
                if op is ast.Sub:
                    right = -right
                elif op is ast.Div:
                    right = sp.Pow(right, -1)
                run.append(right)
            return family(*run) if family is not None else val
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return power(walk(node.left, depth + 1), walk(node.right, depth + 1))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            val = walk(node.operand, depth + 1)
            return -val if isinstance(node.op, ast.USub) else val
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                what = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
                fail(f"call of {what!r} is not allowed; allowed functions are "
                     f"{', '.join(sorted(FUNCTIONS))}")
            if node.keywords:
                fail(f"keyword arguments are not allowed in a call of {node.func.id!r}")
            lo, hi = ARITY[node.func.id]
            if len(node.args) < lo or (hi is not None and len(node.args) > hi):
                want = f"{lo}" if lo == hi else (f"at least {lo}" if hi is None
                                                 else f"{lo} to {hi}")
                fail(f"{node.func.id!r} takes {want} argument(s), got {len(node.args)} in "
                     f"{text!r}")
            if any(isinstance(a, ast.Starred) for a in node.args):
                fail(f"starred arguments are not allowed in a call of {node.func.id!r}")
            args = [walk(a, depth + 1) for a in node.args]
            try:
                return FUNCTIONS[node.func.id](*args)
            except TypeError as exc:
                fail(f"bad call of {node.func.id!r}: {exc}")
        if boolean:
            if isinstance(node, ast.Compare):
                parts = []
                left = walk(node.left, depth + 1)
                for op, comp in zip(node.ops, node.comparators):
                    if type(op) not in _CMPOPS:
                        fail(f"comparison {type(op).__name__} is not allowed (use <, <=, >, >=)")
                    right = walk(comp, depth + 1)
                    parts.append(_CMPOPS[type(op)](left, right))
                    left = right
                return sp.And(*parts) if len(parts) > 1 else parts[0]
            if isinstance(node, ast.BoolOp):
                vals = [walk(v, depth + 1) for v in node.values]
                return sp.And(*vals) if isinstance(node.op, ast.And) else sp.Or(*vals)
            if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
                return sp.Not(walk(node.operand, depth + 1))
        fail(f"construct {type(node).__name__} is not allowed in expression {text!r}")

    try:
        expr = walk(tree)
    except ExpressionError:
        raise
    except RecursionError:
        fail(f"expression nested deeper than SymPy can handle: {text[:80]!r}")
    except Exception as exc:  # noqa: BLE001 -- SymPy raises many types on degenerate input
        # ('Invalid NaN comparison', "The argument 'I' is not comparable", ...)
        fail(f"cannot evaluate {text[:200]!r}: {type(exc).__name__}: {exc}")
    check_expression(expr, fail, text)
    is_condition = isinstance(expr, (sp.core.relational.Relational,
                                     sp.logic.boolalg.BooleanFunction,
                                     sp.logic.boolalg.BooleanAtom)) and not isinstance(expr, sp.Expr)
    if boolean and not is_condition:
        fail(f"a guard must be a condition such as 'v < 0', got {text!r}")
    if not boolean and not isinstance(expr, sp.Expr):
        fail(f"expected a value, got the condition {text!r}")
    return expr
