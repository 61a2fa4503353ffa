"""Fuzzing model files and dicts: hostile names, expressions and structure never run code,
never raise anything but pwsdyn's own errors, and always get an answer.

The default run is bounded (a few hundred models, a sample of them compiled and run); the
``slow`` run covers 5,000 models and prints the count of each outcome.
"""

from __future__ import annotations

import time

import hypothesis
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from _fuzz_models import (MAX_REPEATED_TEXT, SENTINEL, Tally, _repeated, model_dicts,
                          to_toml)

import pwsdyn

# no shrinking: a failing input is reported as generated (shrinking re-runs it hundreds of
# times, each a compile)
_SETTINGS = dict(deadline=None, derandomize=True, database=None,
                 suppress_health_check=list(HealthCheck),
                 phases=[Phase.explicit, Phase.generate])


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("PWSDYN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "fuzz-cache"))
    SENTINEL.unlink(missing_ok=True)
    yield
    assert not SENTINEL.exists(), "a payload ran"


def _seeded(seed):
    """Hypothesis's seed for a run (the default: derived from the test function)."""
    return (lambda f: f) if seed is None else hypothesis.seed(seed)


def _fuzz_dicts(n: int, tally: Tally, seed=None):
    @_seeded(seed)
    @settings(max_examples=n, **_SETTINGS)
    @given(spec=model_dicts())
    def run(spec):
        tally.run(spec)

    run()


def _fuzz_toml(n: int, tally: Tally, seed=None):
    @_seeded(seed)
    @settings(max_examples=n, **_SETTINGS)
    @given(spec=model_dicts())
    def run(spec):
        tally.run(to_toml(spec))

    run()


def _fuzz_mutated_zoo(n: int, tally: Tally, seed=None):
    """Valid built-in model files with characters inserted, deleted or replaced."""
    texts = [pwsdyn.model.spec.zoo_path(z).read_text() for z in pwsdyn.zoo_names()]

    @_seeded(seed)
    @settings(max_examples=n, **_SETTINGS)
    @given(i=st.integers(0, len(texts) - 1), data=st.data())
    def run(i, data):
        text = texts[i]
        for _ in range(data.draw(st.integers(1, 4))):
            at = data.draw(st.integers(0, len(text)))
            cut = data.draw(st.integers(0, 3))
            ins = data.draw(st.sampled_from(["", "\n", "\"", "'", "=", "[", "]", "{", "x",
                                             "nan", "inf", "1e999", "\\", "\x1b", "#",
                                             "sign(x)", "/0", "**999", "__import__"]))
            text = text[:at] + ins + text[at + cut:]
        tally.run(text)

    run()


def test_fuzzed_model_dicts(summary):
    tally = Tally(compile_every=12)
    with tally.watching():
        _fuzz_dicts(120, tally)
    summary(tally.report("model dicts"))
    assert tally.total >= 120
    assert tally.counts["refused at load"] and len(tally.counts) >= 2


def test_fuzzed_model_files(summary):
    tally = Tally(compile_every=25, cli_every=10)
    with tally.watching():
        _fuzz_toml(60, tally)
        _fuzz_mutated_zoo(90, tally)
    summary(tally.report("TOML model files"))
    assert tally.total >= 150 and tally.counts["also run through the CLI"]


#: The slow campaign: 5,000 inputs in parts that run in parallel under pytest-xdist, each with
#: its own seed (the same seed would draw the same inputs again).
_CAMPAIGN = {"dicts-1": (_fuzz_dicts, 1250, 1), "dicts-2": (_fuzz_dicts, 1250, 2),
             "toml-1": (_fuzz_toml, 750, 3), "toml-2": (_fuzz_toml, 750, 4),
             "mutated-zoo": (_fuzz_mutated_zoo, 1000, 5)}


def test_the_campaign_has_5000_inputs():
    assert sum(n for _, n, _ in _CAMPAIGN.values()) == 5000
    assert len({s for _, _, s in _CAMPAIGN.values()}) == len(_CAMPAIGN)


@pytest.mark.slow
@pytest.mark.parametrize("part", list(_CAMPAIGN))
def test_fuzz_campaign_of_5000_models(part, summary):
    fuzz, n, seed = _CAMPAIGN[part]
    tally = Tally(compile_every=10, cli_every=10)
    with tally.watching():
        fuzz(n, tally, seed=seed)
    summary(tally.report(f"fuzz campaign, part {part}"))
    assert tally.total >= n


def test_memory_watch_names_what_the_run_was_doing(monkeypatch):
    """A fuzz run whose process grows past the budget fails, naming the input it was running
    (or the one before the input being generated), where the out-of-memory killer would end
    the whole test run without a word."""
    import _fuzz_models

    def hog(source, **kw):
        block = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:    # grows until interrupted (or gives up)
            block.append(np.ones(2**20))     # 8 MiB a step
            time.sleep(0.005)
        return "accepted (source checked)"

    monkeypatch.setattr(_fuzz_models, "exercise", lambda source, **kw: "refused at load")
    tally = Tally()
    tally.watch.budget = 200 * 2**20
    with tally.watching():
        assert tally.run("a quiet one") == "refused at load"
    monkeypatch.setattr(_fuzz_models, "exercise", hog)
    with pytest.raises(AssertionError, match=r"grew by .* while running the input 'the hog'"):
        with tally.watching():
            tally.run("the hog")
    monkeypatch.setattr(_fuzz_models, "exercise", lambda source, **kw: "refused at load")
    with pytest.raises(AssertionError, match=r"while generating the input after 'quiet'"):
        with tally.watching():
            tally.run("quiet")
            hog(None)                        # as a generator gone wild would


@settings(max_examples=300, **_SETTINGS)
@given(text=st.recursive(st.just("x"), lambda inner: st.tuples(inner, st.integers(2, 3000))
                         .map(_repeated), max_leaves=12))
def test_generated_expressions_stay_bounded(text):
    """The repetition of the expression generator, nested as deep as it goes, stays within its
    bound: unbounded it multiplied lengths into gigabytes (3000 copies of 3000 copies ...)."""
    assert len(text) <= MAX_REPEATED_TEXT
