"""What a wheel or sdist carries besides the code: the licence, the type marker, the zoo."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

import pwsdyn

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(pwsdyn.__file__).resolve().parent


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_licence_file_matches_the_declared_licence():
    project = _pyproject()["project"]
    assert project["license"] == "BSD-3-Clause"
    assert project["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("BSD 3-Clause License")
    assert "Copyright (c) 2026, the pwsdyn authors" in text
    assert "Neither the name of the copyright holder" in text


def test_type_marker_and_zoo_are_package_data():
    data = _pyproject()["tool"]["setuptools"]["package-data"]
    assert "py.typed" in data["pwsdyn"]
    assert "zoo/*.toml" in data["pwsdyn.model"]
    assert (PACKAGE / "py.typed").is_file()
    assert len(list((PACKAGE / "model" / "zoo").glob("*.toml"))) == len(pwsdyn.zoo_names())


def _lower_bounds():
    """The constraints the minimum-versions job of CI installs (.ci/lower_bounds.py)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("lower_bounds", ROOT / ".ci" / "lower_bounds.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_minimum_versions_job_pins_every_declared_dependency():
    """Every dependency (and every test dependency) has a lower bound, and the constraints
    of the minimum-versions job pin each to exactly that bound."""
    module = _lower_bounds()
    project = _pyproject()["project"]
    pins = dict(line.split("==") for line in module.lower_bounds(ROOT / "pyproject.toml",
                                                                   ["test"]))
    declared = project["dependencies"] + project["optional-dependencies"]["test"]
    assert len(pins) == len(declared)
    for req in declared:
        name, bound = req.split(">=")
        assert pins[name.split("[")[0].lower()] == bound, req
    # the job installs the bounds of the project and of the test extra
    assert "lower_bounds.py test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_a_dependency_without_lower_bound_is_refused(tmp_path):
    module = _lower_bounds()
    for deps, words in [('["numpy>=1.26", "scipy"]', "'scipy' declares no lower bound"),
                        ('["numpy<3"]', "'numpy<3' declares no lower bound"),
                        ('["numpy>=1.26", "numpy>=2"]', "two lower bounds")]:
        path = tmp_path / "pyproject.toml"
        path.write_text(f'[project]\nname = "x"\ndependencies = {deps}\n', encoding="utf-8")
        with pytest.raises(SystemExit, match=re.escape(words)):
            module.lower_bounds(path, [])
    path.write_text('[project]\nname = "x"\ndependencies = ["dask[distributed]>=2024.1, <2030"]\n',
                    encoding="utf-8")
    assert module.lower_bounds(path, []) == ["dask==2024.1"]


def test_ci_checks_the_import_contracts():
    """The architecture's contracts (pyproject.toml [tool.importlinter]) run in CI on their
    own, before the suite, so a broken layer is named first."""
    run = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert "lint-imports --config pyproject.toml" in run
    lines = [ln.strip() for ln in run.splitlines()]
    assert lines.index("lint-imports --config pyproject.toml --no-cache") < lines.index(
        "python -m pytest -q")
