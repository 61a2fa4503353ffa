"""The README's Python blocks run unchanged as scripts.

Every ```python block of README.md is written to its own file and run with this interpreter
in a fresh process, in a temporary directory (files the block writes land there), with this
process's environment: the same pwsdyn, and the user's (or CI's) model cache, so the zoo
models are not compiled again for every block. A block fails the test if it exits with an
error; its output is shown.

The blocks that run global analyses (sweeps, basins, Lyapunov spectra) take minutes on two
cores: they are marked ``slow`` (CI runs them, ``.ci/run``); the others run by default.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import pwsdyn

README = Path(__file__).resolve().parent.parent / "README.md"
_BLOCK = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)
#: Calls that make a block a long one (global analyses).
_LONG = re.compile(r"\b(sweep|basins|lyapunov_spectrum)\(")


def readme_blocks() -> list[tuple[int, str]]:
    """``(line, code)`` of every ```python block of the README."""
    text = README.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start()) + 1, m.group(1)) for m in _BLOCK.finditer(text)]


def _params():
    out = []
    for line, code in readme_blocks():
        marks = [pytest.mark.slow] if _LONG.search(code) else []
        out.append(pytest.param(code, id=f"README-line-{line}", marks=marks))
    return out


def test_readme_has_python_blocks():
    blocks = readme_blocks()
    assert len(blocks) >= 3
    assert any(_LONG.search(code) for _, code in blocks)


@pytest.mark.parametrize("code", _params())
def test_readme_block_runs_as_a_script(code, tmp_path):
    script = tmp_path / "readme_block.py"
    script.write_text(code, encoding="utf-8")
    env = dict(os.environ)
    # the pwsdyn this test imported, whether installed or on PYTHONPATH
    src = str(Path(pwsdyn.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in env.get("PYTHONPATH", "").split(
        os.pathsep) if p])
    env.setdefault("MPLBACKEND", "Agg")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                          capture_output=True, text=True)
    assert proc.returncode == 0, (
        f"the README block exited with {proc.returncode}:\n--- block ---\n{code}"
        f"--- stdout ---\n{proc.stdout[-5000:]}\n--- stderr ---\n{proc.stderr[-5000:]}")
