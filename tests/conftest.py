"""Test-session set-up: the suite writes only to temporary directories and pytest's cache.

pwsdyn keeps the modules it generates for each model, with numba's machine code for them, in
a cache directory (:func:`pwsdyn.model.cache.cache_dir`: ``$PWSDYN_CACHE_DIR/models``, by
default ``~/.cache/pwsdyn/models``). The suite compiles some 60 models there, throw-away
models of the argument and model tests among them, which must not pile up in the user's cache.
Unless ``PWSDYN_CACHE_DIR`` is set explicitly, the suite therefore uses a cache of its own
under pytest's cache directory (``.pytest_cache/d/pwsdyn-models`` in the checkout, ignored by
git, removed by ``pytest --cache-clear``). It persists across runs because the suite's 60-odd
models compile again in a cold cache: on two cores the default suite took 3 min 18 s (2 min
42 s CPU) with an empty cache against 2 min 53 s (2 min 3 s CPU) with a warm one. Without
pytest's cache (``-p no:cacheprovider``) a temporary directory is used, removed at the end of
the session.

Hypothesis keeps its example database and caches next to it, not in ``.hypothesis`` in the
working directory (unless ``HYPOTHESIS_STORAGE_DIRECTORY`` is set), and so does matplotlib its
font cache (unless ``MPLCONFIGDIR`` is set) -- which also keeps the user's ``matplotlibrc``
(a style, ``text.usetex``) out of the figure tests.

This runs before any test module is imported, so before pwsdyn looks at its cache.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

_TEMPORARY: list[Path] = []


def _session_dir(config, name: str) -> Path:
    """A directory under pytest's cache that persists across runs; else a temporary one."""
    cache = getattr(config, "cache", None)
    if cache is not None:
        return Path(cache.mkdir(name))
    path = Path(tempfile.mkdtemp(prefix=f"pwsdyn-tests-{name}-"))
    _TEMPORARY.append(path)
    return path


def pytest_configure(config) -> None:
    if not os.environ.get("PWSDYN_CACHE_DIR"):
        os.environ["PWSDYN_CACHE_DIR"] = str(_session_dir(config, "pwsdyn-models"))
    if not os.environ.get("MPLCONFIGDIR"):
        os.environ["MPLCONFIGDIR"] = str(_session_dir(config, "matplotlib"))
    if not os.environ.get("HYPOTHESIS_STORAGE_DIRECTORY"):
        where = _session_dir(config, "hypothesis")
        os.environ["HYPOTHESIS_STORAGE_DIRECTORY"] = str(where)
        try:  # read once by Hypothesis, possibly before this hook: set it directly too
            from hypothesis.configuration import set_hypothesis_home_dir
        except ImportError:
            pass
        else:
            set_hypothesis_home_dir(where)


def pytest_unconfigure(config) -> None:
    for path in _TEMPORARY:
        shutil.rmtree(path, ignore_errors=True)


# --------------------------------------------------------------------------------------------
# summaries printed at the end of the run
# --------------------------------------------------------------------------------------------
# The fuzz tests count what happened to their inputs. The counts are the evidence that the
# inputs reached the code (not only its first refusal), so they are printed where they are
# read: in the terminal summary. They travel as a property of the test's report, since the
# tests run in pytest-xdist's worker processes, whose own output pytest does not show.

_SUMMARY = "pwsdyn_summary"


@pytest.fixture
def summary(request):
    """``summary(text)``: print ``text`` in the terminal summary at the end of the run."""
    return lambda text: request.node.user_properties.append((_SUMMARY, text))


def pytest_terminal_summary(terminalreporter) -> None:
    texts = [value for reports in terminalreporter.stats.values() for report in reports
             if getattr(report, "when", None) == "call"
             for name, value in getattr(report, "user_properties", ()) if name == _SUMMARY]
    if texts:
        terminalreporter.section("summaries of the fuzz runs")
        for text in texts:
            terminalreporter.write_line(text)
