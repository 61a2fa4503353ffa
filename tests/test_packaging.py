"""What a wheel or sdist carries besides the code: the licence, the type marker, the zoo."""

from __future__ import annotations

import tomllib
from pathlib import Path

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
