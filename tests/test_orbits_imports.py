"""The import structure of :mod:`pwsdyn.orbits`, read from the sources (every import, at
module level or inside a function: a function-local import that closes a circle is still a
circle, only deferred).

* No import circle among the modules of ``pwsdyn.orbits``: the problem and its evaluation
  below, what is computed from a solution (guesses, admissibility, monitors, results) above
  it, the result type :class:`~pwsdyn.PeriodicOrbit` below every solver.
* ``pwsdyn.continuation`` and ``pwsdyn.grazing`` import no private module or name of
  ``pwsdyn.orbits``: they use its public faces (``orbits.problem``, ``orbits.monitors``,
  ``orbits.surfaces``, ``orbits.signature``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pwsdyn

SRC = Path(pwsdyn.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = ("pwsdyn",) + path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict:
    return {_module_name(p): p for p in SRC.rglob("*.py")}


def _imports(path: Path, modules: dict) -> list:
    """``(module, names)`` of every import in ``path``: the module each one loads (a name
    that is itself a module counts as that module) and the names it takes from it."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, ()) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                full = ".".join(base + ([node.module] if node.module else []))
            else:
                full = node.module or ""
            for a in node.names:
                sub = f"{full}.{a.name}"
                out.append((sub, ()) if sub in modules else (full, (a.name,)))
    return out


def _cycle(graph: dict) -> list | None:
    """One cycle of the directed graph ``{node: set of nodes}``, or ``None``."""
    state: dict = {}
    stack: list = []

    def visit(v):
        state[v] = 1
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return stack[stack.index(w):] + [w]
            if w not in state:
                found = visit(w)
                if found:
                    return found
        stack.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state:
            found = visit(v)
            if found:
                return found
    return None


def test_the_cycle_finder_sees_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_orbits_has_no_import_circle():
    modules = _modules()
    inside = {m: p for m, p in modules.items() if m.startswith("pwsdyn.orbits.")}
    graph = {m: {t for t, _ in _imports(p, modules) if t in inside and t != m}
             for m, p in inside.items()}
    assert len(graph) >= 8                                 # the walk sees the modules
    assert "pwsdyn.orbits._residual" in graph["pwsdyn.orbits._results"] or \
        "pwsdyn.orbits._admissibility" in graph["pwsdyn.orbits._results"]
    assert _cycle(graph) is None, f"import circle in pwsdyn.orbits: {_cycle(graph)}"
    # and no module of the package imports the package itself (its __init__ imports them)
    back = sorted(m for m, p in inside.items()
                  if any(t == "pwsdyn.orbits" for t, _ in _imports(p, modules)))
    assert not back, f"modules importing pwsdyn.orbits from inside it: {back}"


def test_the_result_type_imports_no_solver():
    modules = _modules()
    loaded = {t for t, _ in _imports(SRC / "orbits" / "_orbit.py", modules)}
    solvers = {"pwsdyn.orbits._shooting", "pwsdyn.orbits.problem", "pwsdyn.orbits._residual",
               "pwsdyn.orbits._results"}
    assert not loaded & solvers


def test_continuation_and_grazing_use_the_public_faces_of_orbits():
    modules = _modules()
    bad = []
    for m, p in modules.items():
        if not m.startswith(("pwsdyn.continuation", "pwsdyn.grazing")):
            continue
        for target, names in _imports(p, modules):
            if not target.startswith("pwsdyn.orbits"):
                continue
            private = [part for part in target.split(".") if part.startswith("_")]
            private += [n for n in names if n.startswith("_")]
            if private:
                bad.append(f"{m}: {target} {names}")
    assert not bad, "private parts of pwsdyn.orbits imported:\n" + "\n".join(bad)
