"""The README's Python blocks run unchanged as scripts and print what their comments say.

Every ```python block of README.md is written to its own file and run with this interpreter
in a fresh process, in a temporary directory (files the block writes land there), with this
process's environment: the same pwsdyn, and the user's (or CI's) model cache, so the zoo
models are not compiled again for every block. A block fails the test if it exits with an
error; its output is shown.

A block states what it prints in the comment of the printing line, after ``# ->``
(``print(orbit.period)  # -> 2.51327``): the k-th such comment is the k-th printed line, a
number in it is the printed number rounded to the digits shown, ``...`` stands for any text,
whitespace is free around punctuation and a further ``  # remark`` is not part of the value.
The test compares every printed line with its comment (``tests/_snippets.py`` has the rules
in full), so a comment cannot claim what the code does not print.

The blocks that run global analyses (sweeps, scans, basins, Lyapunov spectra) take minutes on two
cores: they are marked ``slow`` (CI runs them, ``.ci/run``); the others run by default.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from _snippets import bare_values, check_printed, run_script, stated_lines  # noqa: E402

README = Path(__file__).resolve().parent.parent / "README.md"
_BLOCK = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)
#: Calls that make a block a long one (global analyses).
_LONG = re.compile(r"\b(sweep|scan|basins|lyapunov_spectrum)\(")


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


def test_readme_blocks_state_what_they_print():
    # the blocks that compute print their values (a block that only writes files need not)
    stated = [len(stated_lines(code)) for _, code in readme_blocks()]
    assert sum(n > 0 for n in stated) >= 5 and sum(stated) >= 20
    bare = [line for _, code in readme_blocks() for line in bare_values(code)]
    assert not bare, f"values shown only in a comment: {bare}"


@pytest.mark.parametrize("code", _params())
def test_readme_block_runs_as_a_script(code, tmp_path):
    proc = run_script(code, tmp_path)
    assert proc.returncode == 0, (
        f"the README block exited with {proc.returncode}:\n--- block ---\n{code}"
        f"--- stdout ---\n{proc.stdout[-5000:]}\n--- stderr ---\n{proc.stderr[-5000:]}")
    problems = check_printed(code, proc.stdout)
    assert not problems, ("the README block printed other values than its comments state:\n"
                          + "\n".join(problems) + f"\n--- block ---\n{code}")
