"""Fuzzing model files and dicts: hostile names, expressions and structure never run code,
never raise anything but pwsdyn's own errors, and always get an answer.

The default run is bounded (a few hundred models, a sample of them compiled and run); the
``slow`` run covers 5,000 models and prints the count of each outcome.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from _fuzz_models import SENTINEL, Tally, model_dicts, to_toml

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


def _fuzz_dicts(n: int, tally: Tally):
    @settings(max_examples=n, **_SETTINGS)
    @given(spec=model_dicts())
    def run(spec):
        tally.run(spec)

    run()


def _fuzz_toml(n: int, tally: Tally):
    @settings(max_examples=n, **_SETTINGS)
    @given(spec=model_dicts())
    def run(spec):
        tally.run(to_toml(spec))

    run()


def _fuzz_mutated_zoo(n: int, tally: Tally):
    """Valid built-in model files with characters inserted, deleted or replaced."""
    texts = [pwsdyn.model.spec.zoo_path(z).read_text() for z in pwsdyn.zoo_names()]

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


def test_fuzzed_model_dicts(capsys):
    tally = Tally(compile_every=12)
    _fuzz_dicts(300, tally)
    with capsys.disabled():
        print("\n" + tally.report("model dicts"))
    assert tally.total >= 300
    assert tally.counts["refused at load"] and len(tally.counts) >= 2


def test_fuzzed_model_files(capsys):
    tally = Tally(compile_every=25, cli_every=10)
    _fuzz_toml(150, tally)
    _fuzz_mutated_zoo(150, tally)
    with capsys.disabled():
        print("\n" + tally.report("TOML model files"))
    assert tally.total >= 300 and tally.counts["also run through the CLI"]


@pytest.mark.slow
def test_fuzz_campaign_of_5000_models(capsys):
    tally = Tally(compile_every=10, cli_every=10)
    _fuzz_dicts(2500, tally)
    _fuzz_toml(1500, tally)
    _fuzz_mutated_zoo(1000, tally)
    with capsys.disabled():
        print("\n" + tally.report("fuzz campaign"))
    assert tally.total >= 5000
