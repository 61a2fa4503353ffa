"""Generators of hostile and careless model definitions, and the check each one must pass.

Used by ``test_fuzz_models.py`` (a bounded run by default, 5,000 models under ``slow``). Every
generated model is loaded; one that loads has its generated module checked to be inert (see
:func:`assert_inert`) and, for a sample, is compiled with numba and simulated (or iterated)
for a short span. The outcome must be an answer or one of pwsdyn's own errors, and the
sentinel file that every code payload below would write must never appear.
"""

from __future__ import annotations

import _thread
import ast
import contextlib
import json
import math
import os
import signal
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

import pwsdyn
from pwsdyn.errors import PwsdynError

#: The last message of the rarer refusals (printed with the counts, to tell a refusal that
#: protects from one that is a bug).
LAST_REFUSAL: dict = {}

#: Where the payloads write if they ever run.
SENTINEL = Path(__file__).resolve().parent / ".fuzz-sentinel-must-not-exist"

_PAYLOAD = f"open({str(SENTINEL)!r}, 'w').write('ran')"

# --------------------------------------------------------------------------------------
# names
# --------------------------------------------------------------------------------------

_INJECTIONS = [
    f"a # coding: unicode_escape \n{_PAYLOAD}#",
    f"x\n# -*- coding: unicode_escape -*-\n{_PAYLOAD}\n",
    f"# coding=utf-7\n+AAo-{_PAYLOAD}",
    f"name'); {_PAYLOAD}; ('",
    f'n"""\n{_PAYLOAD}\n"""',
    f"\\\n{_PAYLOAD}",
    f"\r{_PAYLOAD}",
    f"x\x00{_PAYLOAD}",
    f"\u2028{_PAYLOAD}",
    "\x1b[2J\x1b]0;title\x07",
    "\u202eevil",
    "x" * 10_000,
]

_ident = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,8}", fullmatch=True)
_odd_idents = st.sampled_from([
    "x\n", "t", "pi", "inf", "e_const", "u_switch", "if", "lambda", "None", "__import__",
    "s_x", "p_x", "_c0", "out", "which", "idx", "math", "numba", "evaluate", "x" * 65, "é",
    "a-b", "a b", "1x", "", "x\r", "x\x00", "EVALUATE_SIGNATURE",
])
identifiers = st.one_of(_ident, _ident, _ident, _odd_idents)
model_names = st.one_of(st.sampled_from(_INJECTIONS), st.text(max_size=40),
                        st.text(alphabet=st.characters(codec="utf-8"), max_size=20),
                        _ident, st.integers(), st.none())

# --------------------------------------------------------------------------------------
# expressions
# --------------------------------------------------------------------------------------

_FUNCS = ["sin", "cos", "exp", "log", "sqrt", "abs", "sign", "Heaviside", "Max", "Min",
          "atan2", "tanh", "asin", "eval", "exec", "__import__", "getattr", "open", "print",
          "compile", "globals", "sympify", "Symbol", "lambdify"]
_OPS = ["+", "-", "*", "/", "**", "^", "%", "//", "@", "&", "|", "<<", " and ", " or ", "<",
        ">=", "==", " if 1 else "]
_ATOMS = ["1", "0", "-1", "2.5", "1e-320", "1e308", "1e309", "nan", "inf", "-inf", "9" * 400,
          "0x1F", "1_000", "1j", "True", "None", "'s'", "b''", "...", "[]", "{}", "pi",
          "e_const", "t", "zoo", "oo", "I", "E", "nan()", "x.__class__", "().__class__",
          "x[0]", "lambda: 1", "[a for a in ()]", "f'{1}'", "__builtins__", "os", "sys",
          _PAYLOAD, f"__import__('os').system({str(SENTINEL)!r})"]


#: Longest text :func:`_repeated` makes: far past the loader's bound on syntax nodes (so the
#: refusal of a long expression is still exercised), but bounded. The repetition is the one
#: operation that multiplies lengths; nested, unbounded, it made strings of gigabytes and the
#: out-of-memory killer ended the whole test run.
MAX_REPEATED_TEXT = 200_000


def _repeated(a) -> str:
    """``(e+1)*(e+1)*...``: ``a = (e, times)``, as many times as fit in MAX_REPEATED_TEXT
    (``e`` itself where not even one term fits)."""
    term = f"({a[0]}+1)"
    times = min(a[1], (MAX_REPEATED_TEXT + 1) // (len(term) + 1))
    return "*".join([term] * times) if times else a[0]


def expressions(names: list[str]):
    leaves = st.one_of(st.sampled_from(names or ["x"]), st.sampled_from(_ATOMS),
                       st.integers(-10**30, 10**30).map(str),
                       st.floats(allow_nan=True, allow_infinity=True).map(repr))

    def extend(inner):
        return st.one_of(
            st.tuples(inner, st.sampled_from(_OPS), inner).map(lambda a: f"({a[0]}{a[1]}{a[2]})"),
            st.tuples(st.sampled_from(["-", "+", "~", "not "]), inner).map("".join),
            st.tuples(st.sampled_from(_FUNCS), st.lists(inner, max_size=3)).map(
                lambda a: f"{a[0]}({', '.join(a[1])})"),
            st.tuples(st.sampled_from(["sin(", "sqrt(", "("]), st.integers(1, 220), inner).map(
                lambda a: a[0] * a[1] + a[2] + ")" * a[1]),
            st.tuples(inner, st.integers(2, 3000)).map(_repeated),
        )

    text = st.recursive(leaves, extend, max_leaves=12)
    # mostly text; sometimes a bare number, a boolean, a list or a table where text belongs
    return st.one_of(text, text, text, st.floats(allow_nan=True), st.integers(-10**400, 10**400),
                     st.booleans(), st.lists(text, max_size=2), st.none())


# --------------------------------------------------------------------------------------
# model definitions
# --------------------------------------------------------------------------------------

def benign_expressions(names: list[str]):
    """Well-formed expressions of the known names with the allowed functions."""
    leaves = st.one_of(st.sampled_from(names or ["x"]),
                       st.floats(-10, 10, allow_nan=False).map(lambda v: repr(round(v, 3))),
                       st.integers(-5, 5).map(str))

    def extend(inner):
        return st.one_of(
            st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**"]), inner).map(
                lambda a: f"({a[0]} {a[1]} {a[2]})"),
            st.tuples(st.sampled_from(["sin", "cos", "exp", "tanh", "sqrt", "log", "abs",
                                       "sign", "Heaviside", "atan"]), inner).map(
                lambda a: f"{a[0]}({a[1]})"),
            st.tuples(st.sampled_from(["Max", "Min", "atan2"]), inner, inner).map(
                lambda a: f"{a[0]}({a[1]}, {a[2]})"))

    return st.recursive(leaves, extend, max_leaves=6)


@st.composite
def model_dicts(draw):
    """A flow model, or sometimes a map, as a dict. Hostility: 0 a well-formed model, 1 a
    hostile name, 2 one hostile expression or identifier in a well-formed model, 3 hostile
    throughout (names, expressions and structure)."""
    hostility = draw(st.sampled_from([0, 0, 1, 2, 2, 3]))
    ident = identifiers if hostility == 3 else _ident
    states = draw(st.lists(ident, min_size=1, max_size=3, unique=True))
    if hostility < 3:
        states = [f"s{i}_{s}" for i, s in enumerate(states)]
    number = (st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                        st.integers(-10**20, 10**20), st.text(max_size=5), st.booleans())
              if hostility == 3 else st.floats(-5, 5, allow_nan=False))
    params = {(f"q{i}_{k}" if hostility < 3 else k): v for i, (k, v) in enumerate(
        draw(st.dictionaries(ident, number, max_size=3)).items())}
    names = [s for s in states if isinstance(s, str)] + list(params)
    hostile = expressions(names + ["t"])
    benign = benign_expressions(names + ["t"])
    expr = hostile if hostility == 3 else benign
    spec = {"name": draw(model_names) if hostility in (1, 3) else draw(_ident),
            "states": states, "parameters": params}
    if draw(st.integers(0, 9)) == 0:
        spec["kind"] = "map"
        spec["pieces"] = draw(st.lists(st.fixed_dictionaries(
            {"name": ident, "map": st.dictionaries(st.sampled_from(states), expr)},
            optional={"condition": expr.map(lambda e: f"{e} > 0")}), min_size=1, max_size=2,
            unique_by=lambda pc: pc["name"]))
        if hostility == 2:
            spec["pieces"][0]["map"][states[0]] = draw(hostile)
        return spec
    mode_names = draw(st.lists(ident, min_size=1, max_size=3, unique=True))
    if hostility < 3:
        spec["modes"] = {m: {s: draw(expr) for s in states} for m in mode_names}
    else:
        spec["modes"] = {m: draw(st.dictionaries(st.sampled_from(states + ["zz"]), expr,
                                                 min_size=len(states) - 1,
                                                 max_size=len(states) + 1))
                         for m in mode_names}
    event = st.fixed_dictionaries(
        {"surface": expr},
        optional={"name": ident,
                  "kind": st.sampled_from(["impact", "transition", "boom", 3]
                                          if hostility == 3 else ["transition"]),
                  "direction": st.sampled_from([-1, 0, 1, 2, "down", True]
                                               if hostility == 3 else [-1, 0, 1]),
                  "reset": st.dictionaries(st.sampled_from(states), expr, max_size=2),
                  "guard": expr.map(lambda e: f"{e} < 1"),
                  "target": st.sampled_from(mode_names + (["nowhere"] if hostility == 3
                                                          else [])),
                  "terminal": st.sampled_from([True, False, "yes"] if hostility == 3
                                              else [True, False])})
    events = draw(st.lists(event, max_size=2))
    for i, ev in enumerate(events):
        ev.setdefault("name", f"ev{i}")
        if hostility < 3:
            ev["name"] = f"ev{i}_{ev['name']}"
    spec["events"] = events
    if len(mode_names) > 1 and draw(st.booleans()):
        spec["switches"] = [{"name": draw(ident), "surface": draw(expr),
                             "above": mode_names[0], "below": mode_names[1]}]
    if draw(st.booleans()):
        spec["definitions"] = {f"d_{k}" if hostility < 3 else k: v for k, v in
                               draw(st.dictionaries(ident, expr, max_size=2)).items()}
    if draw(st.integers(0, 3)) == 0:
        spec["forcing_period"] = draw(expr) if hostility == 3 else "2*pi"
    if hostility == 2:
        # one hostile expression or identifier in an otherwise well-formed model
        where = draw(st.sampled_from(["mode", "state", "parameter", "event"]))
        if where == "mode":
            spec["modes"][mode_names[0]][states[0]] = draw(hostile)
        elif where == "state":
            spec["states"] = states[:-1] + [draw(_odd_idents)]
        elif where == "parameter":
            spec["parameters"][draw(_odd_idents)] = 1.0
        else:
            spec["events"] = [{"name": "hostile", "surface": draw(hostile)}]
    if hostility == 3 and draw(st.integers(0, 3)) == 0:
        spec[draw(st.sampled_from(["junk", "description", "reference", "defaults"]))] = \
            draw(st.one_of(st.text(max_size=20), st.integers(), st.dictionaries(
                st.text(max_size=3), st.integers(), max_size=2)))
    return spec


def to_toml(spec: dict) -> str:
    """``spec`` as TOML text, one top-level key a line (inline tables below that), so that
    errors have lines to name. Values TOML cannot hold (None) become the string 'None'."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int):
            return str(v)
        if isinstance(v, float):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") \
                if math.isinf(v) else repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, dict):
            return "{" + ", ".join(f"{json.dumps(str(k))} = {value(x)}" for k, x in v.items()) + "}"
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return json.dumps(str(v))

    return "".join(f"{json.dumps(str(k))} = {value(v)}\n" for k, v in spec.items())


# --------------------------------------------------------------------------------------
# the check
# --------------------------------------------------------------------------------------

_ENTRY = {"evaluate": ("which", "idx", "t", "x", "p", "out"),
          "step": ("x", "p", "out", "jac", "want_jac")}
_CALLS = {"min", "max", "abs", "float"}
_NODES = (ast.Module, ast.Import, ast.ImportFrom, ast.alias, ast.FunctionDef, ast.arguments,
          ast.arg, ast.Assign, ast.Name, ast.Subscript, ast.Constant, ast.If, ast.IfExp,
          ast.Compare, ast.BoolOp, ast.UnaryOp, ast.BinOp, ast.Call, ast.Attribute, ast.Return,
          ast.keyword, ast.Load, ast.Store, ast.operator, ast.unaryop, ast.cmpop, ast.boolop)


def assert_inert(source: str) -> None:
    """The generated module can do nothing but arithmetic.

    Parsed from bytes, as the import system reads it (so an encoding declaration would take
    effect), it must be: three imports, one function decorated by ``numba.njit``, and in the
    function only assignments, conditions, returns and calls of ``math`` functions and a few
    numeric builtins on names the function defines -- no other strings, attributes, globals
    or calls."""
    assert source.isascii(), "generated source is not ASCII"
    tree = ast.parse(source.encode("ascii"))
    assert [type(n) for n in tree.body] == [ast.Import, ast.Import, ast.ImportFrom,
                                            ast.FunctionDef], ast.dump(tree)[:300]
    assert [a.name for n in tree.body[:2] for a in n.names] == ["math", "numba"]
    fn = tree.body[3]
    assert fn.name in _ENTRY and tuple(a.arg for a in fn.args.args) == _ENTRY[fn.name]
    assert len(fn.decorator_list) == 1 and ast.unparse(fn.decorator_list[0].func) == "numba.njit"
    local = set(_ENTRY[fn.name])
    for node in ast.walk(fn):
        if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            local.add(node.id)
    for stmt in fn.body:
        for node in ast.walk(stmt):
            assert isinstance(node, _NODES), f"unexpected {type(node).__name__} in generated code"
            if isinstance(node, ast.Constant):
                assert type(node.value) in (int, float, bool), f"constant {node.value!r}"
            if isinstance(node, ast.Attribute):
                assert isinstance(node.value, ast.Name) and node.value.id == "math" \
                    and hasattr(math, node.attr), ast.unparse(node)
            if isinstance(node, ast.Call):
                f = node.func
                assert (isinstance(f, ast.Attribute) or (isinstance(f, ast.Name)
                                                         and f.id in _CALLS)), ast.unparse(f)
                assert not node.keywords
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
                assert node.id in local or node.id in _CALLS or node.id == "math", node.id


def run_cli(text: str, n_states: int | None) -> None:
    """``pwsdyn simulate FILE`` on the model text: a clean exit (0, or 1/2 with one error
    line), never a traceback or raw control characters."""
    import tempfile

    from click.testing import CliRunner

    from pwsdyn.cli import main

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "model.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        args = ["simulate", str(path), "--t-end", "0.5"]
        if n_states:
            args += ["--x0", ",".join(["0.5"] * n_states)]
        res = CliRunner().invoke(main, args)
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise AssertionError(f"the CLI raised {res.exception!r}") from res.exception
    assert res.exit_code in (0, 1, 2), res.output
    assert "Traceback" not in res.output and "\x1b" not in res.output, res.output[-500:]


def exercise(source, *, compile_it, cli_it=lambda: False) -> str:
    """Load ``source`` (a dict or TOML text) and, if it loads, check its generated module and,
    if ``compile_it()`` says so, compile and run it; TOML text goes through the command line
    too when ``cli_it()`` says so. Returns the outcome; raises on anything that is not
    pwsdyn's own error, and if the sentinel appeared."""
    from pwsdyn.model import codegen, iteration, maps

    try:
        if isinstance(source, str) and cli_it():
            try:
                n = pwsdyn.load_model(source).n_states
            except PwsdynError:
                n = None
            run_cli(source, n)
        try:
            m = pwsdyn.load_model(source)
        except PwsdynError:
            return "refused at load"
        is_map = getattr(m, "is_map", False)
        try:
            src = maps.generate_map_source(m) if is_map else codegen.generate_source(m)
        except PwsdynError as exc:
            LAST_REFUSAL["refused at code generation"] = str(exc)[:200]
            return "refused at code generation"
        assert_inert(src)
        if not compile_it():
            return "accepted (source checked)"
        try:
            if is_map:
                iteration.iterate(m, np.full(m.n_states, 0.5), 20)
            else:
                pwsdyn.simulate(m, np.full(m.n_states, 0.5), (0.0, 0.5), max_steps=5000,
                                max_events=200, throw=False)
        except PwsdynError as exc:
            LAST_REFUSAL["refused at compile or run"] = str(exc)[:200]
            return "refused at compile or run"
        return "accepted and ran"
    finally:
        assert not SENTINEL.exists(), "a payload ran"


def _rss_bytes() -> int:
    """This process's resident memory (Linux; 0 where /proc is not there)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _interrupted(signum, frame):
    raise KeyboardInterrupt


class MemoryWatch:
    """Ends a fuzz run whose process grows by more than ``budget`` bytes with an error that
    says what it was doing (running an input, or generating the one after it), instead of
    letting the machine's out-of-memory killer end the whole test run without a word.

    A thread samples the resident memory; past the budget it interrupts the main thread with
    SIGUSR1, whose handler (installed for the watch) raises KeyboardInterrupt between two
    bytecodes of whatever runs (a single allocation in C is seen once it returns), which
    :meth:`Tally.watching` turns into an AssertionError. Not SIGINT: a process started in the
    background by a shell without job control ignores it, and then ``interrupt_main`` does
    nothing. Enter the watch from the main thread (signal handlers are set there)."""

    def __init__(self, budget: float = 4 * 2**30, period: float = 0.1):
        self.budget, self.period = budget, period
        self.base = 0
        self.tripped = ""
        self._active = False
        self._thread = None
        # held while the interrupt is sent, so that it lands inside the ``with`` block (at
        # worst in ``__exit__``, which is still inside it)
        self._lock = threading.Lock()
        self._previous = signal.SIG_DFL

    def __enter__(self):
        self._previous = signal.signal(signal.SIGUSR1, _interrupted)
        self.base, self.tripped, self._active = _rss_bytes(), "", True
        if self._thread is None or not self._thread.is_alive():
            self._thread = threading.Thread(target=self._watch, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        with self._lock:
            self._active = False
        signal.signal(signal.SIGUSR1, self._previous)
        return False

    def _watch(self):
        while True:
            time.sleep(self.period)
            with self._lock:
                if self._active and not self.tripped:
                    grown = _rss_bytes() - self.base
                    if grown > self.budget:
                        self.tripped = (f"the process grew by {grown / 2**30:.1f} GiB (budget "
                                        f"{self.budget / 2**30:.1f} GiB)")
                        _thread.interrupt_main(signal.SIGUSR1)


class Tally:
    """Counts of outcomes, and the slowest input, over a fuzz run. The first model that
    loads, and every ``compile_every``-th after it, is compiled and run (numba takes about a
    second a model; the inertness check of the source takes milliseconds)."""

    def __init__(self, compile_every: int = 0, cli_every: int = 0):
        self.counts: Counter = Counter()
        self.slowest = 0.0
        self.slowest_by: dict = {}   # outcome -> slowest input (s) with that outcome
        self.slowest_input = ""      # the slowest input, for a look at what made it slow
        self.compile_every = compile_every
        self.cli_every = cli_every
        self._accepted = 0
        self._seen = 0
        self.watch = MemoryWatch()
        self.doing = "starting"

    def _cli_next(self) -> bool:
        self._seen += 1
        if self.cli_every and (self._seen - 1) % self.cli_every == 0:
            self.counts["also run through the CLI"] += 1
            return True
        return False

    def _compile_next(self) -> bool:
        self._accepted += 1
        return bool(self.compile_every) and (self._accepted - 1) % self.compile_every == 0

    @contextlib.contextmanager
    def watching(self):
        """The fuzz run inside, under :class:`MemoryWatch`."""
        try:
            with self.watch:
                yield self
        except KeyboardInterrupt:
            if not self.watch.tripped:
                raise
        # interrupted by the watch, or tripped as the run ended, before the interrupt landed
        if self.watch.tripped:
            raise AssertionError(f"{self.watch.tripped} while {self.doing}"[:20_000]) from None

    def run(self, source) -> str:
        t0 = time.perf_counter()
        self.doing = f"running the input {source!r}"
        outcome = exercise(source, compile_it=self._compile_next, cli_it=self._cli_next)
        self.doing = f"generating the input after {source!r}"
        dt = time.perf_counter() - t0
        if dt > self.slowest:
            self.slowest, self.slowest_input = dt, repr(source)
        self.slowest_by[outcome] = max(self.slowest_by.get(outcome, 0.0), dt)
        self.counts[outcome] += 1
        return outcome

    @property
    def total(self) -> int:
        return sum(v for k, v in self.counts.items() if k != "also run through the CLI")

    def report(self, what: str) -> str:
        total = self.total
        parts = ", ".join(f"{k}: {v}" for k, v in sorted(self.counts.items()))
        examples = "".join(f"\n  last {k}: {v}" for k, v in LAST_REFUSAL.items())
        slow = ", ".join(f"{k} {v:.2f} s" for k, v in sorted(self.slowest_by.items()))
        shown = self.slowest_input
        if len(shown) > 600:
            shown = shown[:300] + f" ... ({len(shown) - 600} characters) ... " + shown[-300:]
        return (f"{what}: {total} inputs; {parts}; 0 code executions, 0 foreign exceptions; "
                f"slowest input {self.slowest:.2f} s (by outcome: {slow}){examples}"
                f"\n  the slowest input: {shown}")
