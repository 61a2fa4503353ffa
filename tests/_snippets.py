"""Running the documentation's Python snippets and checking what they print against their
comments (tests/test_readme.py, tests/test_docs.py).

The convention
--------------
A snippet states a printed value in the comment of the line that prints it, after ``# ->``::

    print(orbit.period)            # -> 2.24399
    print(traj.status)             # -> SUCCESS
    print(branch.special_points)   # -> [SpecialPoint(PD at omega = 4.31998, ...)]

* Every line the snippet prints has one ``# ->`` comment, in the order of the output: the
  ``k``-th such comment states the ``k``-th line of standard output (so each ``print`` of a
  checked line prints one line). A snippet with more or fewer printed lines than comments
  fails the check.
* A number in the comment is the printed number rounded to the digits the comment shows:
  ``2.24399`` matches a printed ``2.243994752564`` (it is within half a unit of its last
  digit); ``2.2439`` does not (truncated, not rounded). ``1e-10`` has a unit of ``1e-10``.
* ``...`` in the comment stands for any text (the rest of a long list, digits not shown).
* Whitespace is free between words, numbers and punctuation (NumPy pads its arrays); other
  text must be as printed.
* Text after ``  #`` following the stated value is a remark, not part of it:
  ``print(x)  # -> 0.99909  # law 5.3``.
"""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import tokenize
from decimal import Decimal
from pathlib import Path

import pwsdyn

#: ``# -> <expected>`` (an optional second ``  # remark`` is not part of the value).
_ARROW = re.compile(r"#\s*->\s?(.*?)(?:\s+#\s.*)?$")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
#: A number of a comment: not part of a name (``x0``, ``c_x``).
_EXPECTED_NUMBER = re.compile(rf"(?<![\w.]){_NUMBER}")


def stated_lines(code: str) -> list[str]:
    """The values the ``# ->`` comments of ``code`` state, in order."""
    out = []
    # the tokenizer tells a comment from a '#' inside a string
    for tok in tokenize.generate_tokens(io.StringIO(code).readline):
        if tok.type == tokenize.COMMENT:
            m = _ARROW.match(tok.string)
            if m:
                out.append(m.group(1).strip())
    return out


#: A line that is only attributes or items, or a tuple of them, with a comment after it
#: (``orbit.multipliers, orbit.stable   # ...``): run as a script it shows nothing.
_BARE_VALUE = re.compile(r"^[A-Za-z_][\w.]*(\[[^]]*\])?(, *[A-Za-z_][\w.]*(\[[^]]*\])?)*\s+#")


def bare_values(code: str) -> list[str]:
    """The lines of ``code`` whose value is shown only in a comment (not printed)."""
    return [line for line in code.splitlines() if _BARE_VALUE.match(line)]


def _pattern(expected: str) -> tuple[re.Pattern, list[str]]:
    """A regular expression for the printed line and the comment's numbers, in order."""
    parts, numbers, pos = [], [], 0
    for m in re.finditer(rf"\.\.\.|{_EXPECTED_NUMBER.pattern}", expected):
        parts.append(_literal(expected[pos:m.start()]))
        if m.group(0) == "...":
            parts.append(".*?")
        else:
            parts.append(f"({_NUMBER})")
            numbers.append(m.group(0))
        pos = m.end()
    parts.append(_literal(expected[pos:]))
    return re.compile(r"\s*" + r"\s*".join(p for p in parts if p) + r"\s*"), numbers


def _literal(text: str) -> str:
    words = text.split()
    if not words:
        return ""
    # whitespace inside the text is needed where the comment has it, free elsewhere
    core = r"\s+".join(r"\s*".join(re.escape(c) for c in _chunks(w)) for w in words)
    return core


def _chunks(word: str) -> list[str]:
    # punctuation may have NumPy's padding around it: "[0." matches "[ 0."
    return [c for c in re.split(r"([^\w])", word) if c]


def line_matches(expected: str, printed: str) -> bool:
    """Whether a printed line is what the comment states (the convention above)."""
    pattern, numbers = _pattern(expected)
    m = pattern.fullmatch(printed)
    if m is None:
        return False
    for want, got in zip(numbers, m.groups()):
        d = Decimal(want)
        unit = Decimal(1).scaleb(d.as_tuple().exponent)
        if abs(Decimal(got) - d) > unit / 2 + abs(d) * Decimal("1e-12"):
            return False
    return True


def check_printed(code: str, stdout: str) -> list[str]:
    """The mismatches between what ``code`` printed and what its comments state (empty when
    every printed line is as stated)."""
    stated = stated_lines(code)
    printed = stdout.splitlines()
    problems = []
    if len(printed) != len(stated):
        problems.append(f"{len(printed)} printed line(s) but {len(stated)} '# ->' comment(s)")
    for k, (want, got) in enumerate(zip(stated, printed)):
        if not line_matches(want, got):
            problems.append(f"line {k + 1}: printed {got!r}, the comment states {want!r}")
    return problems


def run_script(code: str, cwd: Path) -> subprocess.CompletedProcess:
    """``code`` run as a script in a fresh process in ``cwd`` (files it writes land there),
    with this process's pwsdyn and model cache."""
    script = cwd / "snippet.py"
    script.write_text(code, encoding="utf-8")
    env = dict(os.environ)
    # the pwsdyn this test imported, whether installed or on PYTHONPATH
    src = str(Path(pwsdyn.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in env.get("PYTHONPATH", "").split(
        os.pathsep) if p])
    env.setdefault("MPLBACKEND", "Agg")
    env.setdefault("PWSDYN_QUIET", "1")
    return subprocess.run([sys.executable, str(script)], cwd=cwd, env=env,
                          capture_output=True, text=True)
