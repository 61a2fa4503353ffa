"""The package's architecture, checked: the import-linter contracts of pyproject.toml (layers,
private modules, no import cycles at any depth, function-local imports included) and what
import-linter cannot see, private *names* imported across subpackages.

The layers, bottom up: model, integrate, stability, orbits, continuation, grazing, explore,
manifolds, then io and plot, then cli. A subpackage's private modules and names (a leading ``_``) are
its own; the package-level private modules (``pwsdyn._netcdf``, ``pwsdyn._validate``, ...)
are shared by the whole package, their underscore names are not.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "pwsdyn"


def test_the_import_contracts_hold(capsys):
    cli = pytest.importorskip("importlinter.cli",
                              reason="import-linter not installed (pip install -e .[lint])")
    rc = cli.lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True)
    out = capsys.readouterr().out
    assert rc == 0, out


def test_the_contracts_name_every_layer():
    """A subpackage added later must be placed in the layers, or nothing checks it."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    layers = next(c for c in config["contracts"] if c["type"] == "layers")["layers"]
    listed = {name.strip() for layer in layers for name in layer.split("|")}
    subpackages = {f"pwsdyn.{p.parent.name}" for p in SRC.glob("*/__init__.py")}
    assert subpackages - {"pwsdyn.__pycache__"} <= listed
    assert {"pwsdyn.io"} <= listed     # a module, not a package: listed by hand
    kinds = {c["type"] for c in config["contracts"]}
    assert {"layers", "private_modules", "acyclic_siblings"} <= kinds


def _owner(parts: tuple) -> str:
    """The subpackage a module belongs to ("" for the package-level modules)."""
    return parts[0] if len(parts) > 1 else ""


def _private_names_across() -> list[str]:
    bad = []
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        pkg = ("pwsdyn",) + (parts[:-1] if parts[-1] != "__init__" else parts[:-1])
        mine = _owner(parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = list(pkg[:len(pkg) - node.level + 1]) + (node.module or "").split(".")
            else:
                base = (node.module or "").split(".")
            base = [b for b in base if b]
            if not base or base[0] != "pwsdyn":
                continue
            target = tuple(base[1:])
            theirs = target[0] if target else ""
            if (SRC / theirs).is_file() or (SRC / f"{theirs}.py").is_file():
                theirs = ""            # a package-level module: shared
            if theirs == mine:
                continue
            where = SRC.joinpath(*target)
            for alias in node.names:
                if (where / f"{alias.name}.py").is_file() or (where / alias.name).is_dir():
                    continue           # a module: the private-modules contract's business
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    bad.append(f"{path.relative_to(SRC)}:{node.lineno} imports "
                               f"{'.'.join(base)}.{alias.name}")
    return bad


def test_no_private_name_is_imported_from_another_subpackage():
    assert _private_names_across() == []
