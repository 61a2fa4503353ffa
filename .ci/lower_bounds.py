"""Print a pip constraints file that pins every dependency to its declared lower bound.

    python .ci/lower_bounds.py [EXTRA ...] > constraints.txt

Reads ``pyproject.toml`` (the project's dependencies and those of the extras named), so the
minimum-versions job of ``.ci/run`` always installs exactly the lower bounds the project
declares. A dependency without a ``>=`` lower bound is an error: an unbounded requirement
promises every version ever released. Only direct dependencies are pinned; pip resolves what
they need to the newest versions that fit, as it would for a user who has the oldest
supported release of each.
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"

#: name, optional [extras], then a ">=" bound (other clauses after a comma are allowed)
_REQUIREMENT = re.compile(
    r"^\s*(?P<name>[A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[[^\]]*\])?\s*"
    r"(?P<spec>[^;]*)(?:;.*)?$")
_LOWER = re.compile(r">=\s*(?P<version>[0-9][0-9A-Za-z.+!-]*)")


def lower_bounds(pyproject: Path, extras: list[str]) -> list[str]:
    meta = tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]
    optional = meta.get("optional-dependencies", {})
    unknown = [e for e in extras if e not in optional]
    if unknown:
        raise SystemExit(f"{pyproject}: no optional dependencies named {unknown}")
    requirements = list(meta["dependencies"])
    for extra in extras:
        requirements += optional[extra]
    pins: dict[str, str] = {}
    for req in requirements:
        m = _REQUIREMENT.match(req)
        low = _LOWER.search(m.group("spec")) if m else None
        if low is None:
            raise SystemExit(f"{pyproject}: the dependency {req!r} declares no lower bound "
                             f"(NAME>=VERSION)")
        name = m.group("name").lower().replace("_", "-")
        if pins.get(name, low.group("version")) != low.group("version"):
            raise SystemExit(f"{pyproject}: {name} has two lower bounds, {pins[name]} and "
                             f"{low.group('version')}")
        pins[name] = low.group("version")
    return [f"{name}=={version}" for name, version in sorted(pins.items())]


if __name__ == "__main__":
    print("\n".join(lower_bounds(PYPROJECT, sys.argv[1:])))
