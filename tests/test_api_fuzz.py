"""Fuzzing the public API with bad arguments (hypothesis).

Each call takes a small, cheap, valid call of one entry point and replaces one or two of its
arguments by a bad value (None, strings, NaN, +-inf, negative numbers, zero, huge ints and
floats, wrong containers, bools, ...). The call must either raise a subclass of
:class:`pwsdyn.errors.PwsdynError` (normally :class:`~pwsdyn.errors.ArgumentError`, before
any work) or, where the value happens to be valid, return a result of the documented type:
never another exception (``TypeError``, ``KeyError``, ``OverflowError``, ...), never a hang
(the base calls carry small step budgets, and ints are drawn small or out of range).

The default run makes ``N_EXAMPLES`` calls per entry point (``len(ENTRIES) * N_EXAMPLES``
>= 300 in all), derandomised so CI is reproducible; the ``slow`` variant draws many more at
random. Counts per entry point and class (refused with ArgumentError, another PwsdynError,
accepted) are checked and printed per entry point in the terminal summary of the run, and as a
table by ``python tests/test_api_fuzz.py [examples]``.
"""

from __future__ import annotations

import collections
import functools
import math
import sys
from unittest import mock

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings, strategies as st

import pwsdyn
from pwsdyn import PeriodicOrbit
from pwsdyn.continuation import Branch
from pwsdyn.errors import ArgumentError, PwsdynError
from pwsdyn.explore._lyapunov import LyapunovSpectrum
from pwsdyn.integrate.trajectory import Trajectory
from pwsdyn.model.iteration import iterate
from pwsdyn.stability import monodromy
from pwsdyn.stability._poincare import PoincareResult

IO = "impact-oscillator"
MAP = "sqrt-map"
N_EXAMPLES = 30
N_EXAMPLES_SLOW = 400

# --------------------------------------------------------------------------------------
# bad values
# --------------------------------------------------------------------------------------

NAN, INF = float("nan"), float("inf")
_FIXED = [None, True, False, np.bool_(True), 0, -1, -7, 10**20, -10**20, 2**63, 2**64 + 1,
          0.0, -0.0, -1.5, 1e300, -1e300, 1e-300, 5e-324, NAN, INF, -INF, np.float64(NAN),
          np.int64(-3), np.int64(2**62), np.float32(INF), "1", "1.0", "abc", "", "nan", b"x",
          "g=1", 1j, complex(NAN, 0), [], [1.0], [NAN, 0.0], [None, 0.0], ["a", "b"], [[1.0]],
          (1.0,), (1.0, 2.0, 3.0), (NAN, 1.0), {}, {"a": 1.0}, {"x": None}, {1: 2},
          np.array([]), np.array([NAN]), np.array(["a", "b"]), np.zeros((2, 2)),
          np.array([1.0, INF]), set(), frozenset({1.0}), object(), range(3), slice(1),
          float, 10**400]
_SMALL_INTS = [0, 1, 2, 3]


def bad_values() -> st.SearchStrategy:
    """A bad value, or a random value that may happen to be valid but is always cheap."""
    return st.one_of(
        st.sampled_from(_FIXED),
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(min_value=-10**25, max_value=-1),
        st.integers(min_value=10**13, max_value=10**25),
        st.sampled_from(_SMALL_INTS),
        st.text(max_size=4),
        st.lists(st.one_of(st.none(), st.floats(), st.text(max_size=2)), max_size=3),
        st.dictionaries(st.text(max_size=3), st.one_of(st.floats(), st.none()), max_size=2),
    )


#: Arguments that may only get values that are never valid (a valid one would start a Dask
#: cluster or write files).
_NEVER_VALID = [0, -1, 1.5, NAN, INF, "", b"x", True, 10**20, [1], {}, 1j]


@functools.lru_cache(maxsize=None)
def _trajectory():
    return pwsdyn.simulate(IO, [0.0, -0.5], (0.0, 30.0))


@functools.lru_cache(maxsize=None)
def _orbit():
    return pwsdyn.find_periodic_orbit(IO, [-0.7, 0.0], params={"sigma": -0.5, "eps": 0.1,
                                                              "omega": 2.8})


@functools.lru_cache(maxsize=None)
def _pd_point():
    """The period doubling of the one-impact orbit at omega = 4.32 (a short branch to it)."""
    from _orbit_cases import io_orbit

    br = pwsdyn.continue_orbit(IO, io_orbit("stable"), "omega", span=(2.8, 4.34), ds=0.05)
    return br.special("PD")[0]


@functools.lru_cache(maxsize=None)
def _branch():
    return pwsdyn.continue_orbit(IO, _orbit(), "omega", span=(2.7, 2.9), max_points=3)


#: A fold x' = p - x^2 (closed-form equilibria sqrt(p)).
FOLD = {"name": "fold", "states": ["x"], "parameters": {"p": 1.0},
        "modes": {"m": {"x": "p - x**2"}}}


@functools.lru_cache(maxsize=None)
def _variational_trajectory():
    return pwsdyn.simulate(IO, [0.0, -0.5], (0.0, 3.0), variational=True)


# --------------------------------------------------------------------------------------
# entry points: a valid cheap call, the arguments fuzzed, the type of a result
# --------------------------------------------------------------------------------------

_BUDGET = dict(max_steps=3000, max_events=500)

Entry = collections.namedtuple("Entry", "name function args kwargs fuzzed restricted result")


def _entries():
    sim_opts = ["rtol", "atol", "first_step", "max_step", "max_steps", "max_events",
                "chatter_ratio", "chatter_velocity", "sliding", "sliding_gain", "mode", "method",
                "exact", "chatter", "variational", "dense", "throw"]
    dist = ["workers", "store", "out", "scheduler"]
    return [
        Entry("simulate", pwsdyn.simulate, ("model", "x0", "t_span"),
              dict(model=IO, x0=[0.0, -0.5], t_span=(0.0, 1.0), params=None, **_BUDGET),
              ["model", "x0", "t_span", "params"] + sim_opts, [], Trajectory),
        Entry("find_periodic_orbit", pwsdyn.find_periodic_orbit, ("model", "x0"),
              dict(model=IO, x0=[0.0, -0.5], max_steps=20000),
              ["model", "x0", "params", "period", "t0", "periods", "mode", "nodes", "phase",
               "tol", "max_iter", "lock_tol", "max_nodes", "rtol", "atol", "max_steps"], [],
              PeriodicOrbit),
        Entry("PeriodicOrbit.from_trajectory", PeriodicOrbit.from_trajectory, ("traj",),
              dict(traj="TRAJ", refine=False),
              ["traj", "t0", "period", "periods", "refine", "recurrence_tol", "tol"], [],
              PeriodicOrbit),
        Entry("poincare_map", pwsdyn.poincare_map, ("model", "x0", "section"),
              dict(model=IO, x0=[0.0, -0.5], section="impact", **_BUDGET),
              ["model", "x0", "section", "params", "t0", "returns", "side", "mode", "t_max",
               "dense", "rtol", "max_steps"], [], PoincareResult),
        Entry("floquet_multipliers", pwsdyn.floquet_multipliers, ("monodromy",),
              dict(monodromy=np.diag([0.5, 0.25])),
              ["monodromy", "flow_direction", "section_normal"], [], np.ndarray),
        Entry("monodromy", monodromy, ("traj",), dict(traj="VTRAJ", form="full"),
              ["traj", "form"], [], np.ndarray),
        Entry("sweep(map)", pwsdyn.sweep, ("model", "param", "values", "x0"),
              dict(model=MAP, param="mu", values=[0.01, 0.02], x0=[0.0], params={"lam": 0.1},
                   transient=5, samples=8, workers=1, progress=False),
              ["model", "param", "values", "x0", "transient", "samples", "section",
               "direction", "params", "phase", "period", "max_points", "max_period",
               "period_tol", "bound", "lyapunov", "chunk_size", "warmup", "progress"],
              dist, xr.Dataset),
        Entry("sweep(flow)", pwsdyn.sweep, ("model", "param", "values", "x0"),
              dict(model=IO, param="omega", values=[2.4, 2.5], x0=[0.0, -0.5], transient=1,
                   samples=2, workers=1, progress=False, **_BUDGET),
              ["param", "values", "x0", "transient", "samples", "section", "params", "phase",
               "period", "max_points", "max_period", "period_tol", "bound", "warmup",
               "rtol", "max_steps", "mode"], dist, xr.Dataset),
        Entry("basins(map)", pwsdyn.basins, ("model", "grid"),
              dict(model=MAP, grid={"x": [-0.1, 0.1]}, params={"mu": 0.1, "lam": 0.1},
                   transient=5, samples=8, workers=1, progress=False),
              ["model", "grid", "x0", "params", "transient", "samples", "section", "phase",
               "period", "max_period", "period_tol", "match_tol", "bound", "chunk_size",
               "progress"], dist, xr.Dataset),
        Entry("basins(flow)", pwsdyn.basins, ("model", "grid"),
              dict(model=IO, grid={"x": [-0.5, 0.0]}, x0=[0.0, -0.5], transient=1, samples=2,
                   workers=1, progress=False, **_BUDGET),
              ["grid", "x0", "transient", "samples", "section", "phase", "period",
               "max_period", "period_tol", "match_tol", "bound", "atol", "sliding_gain"],
              dist, xr.Dataset),
        Entry("lyapunov_spectrum(flow)", pwsdyn.lyapunov_spectrum, ("model", "x0"),
              dict(model=IO, x0=[0.0, -0.5], transient=1, duration=2, **_BUDGET),
              ["model", "x0", "params", "transient", "duration", "segment", "t0", "bound",
               "rtol", "max_step", "chatter"], [], LyapunovSpectrum),
        Entry("lyapunov_spectrum(map)", pwsdyn.lyapunov_spectrum, ("model", "x0"),
              dict(model=MAP, x0=[0.0], transient=5, duration=50),
              ["x0", "params", "transient", "duration", "segment", "t0", "bound"], [],
              LyapunovSpectrum),
        Entry("continue_orbit", pwsdyn.continue_orbit, ("model", "orbit", "param"),
              dict(model=IO, orbit="ORBIT", param="omega", span=(2.7, 2.9), max_points=3),
              ["model", "orbit", "param", "span", "ds", "max_points", "params", "on_dib",
               "ds_min", "ds_max", "tol", "max_iter", "target_iter", "max_angle", "locate",
               "locate_tol", "predictor", "max_arclength", "rtol", "direction"], [], Branch),
        # a branch resumed: its own model, or another (refused), every argument fuzzed
        Entry("continue_orbit(branch)", pwsdyn.continue_orbit, ("model", "orbit", "param"),
              dict(model=IO, orbit="BRANCH", param="omega", span=(2.7, 2.95), max_points=3),
              ["model", "orbit", "param", "span", "ds", "max_points", "on_dib", "direction",
               "rtol"], [], Branch),
        Entry("continue_bifurcation", pwsdyn.continue_bifurcation,
              ("model", "special_point", "params"),
              dict(model=IO, special_point="PDPOINT", params=("sigma", "omega"),
                   span=(-0.55, -0.45), max_points=3),
              ["model", "special_point", "params", "span", "span2", "ds", "max_points",
               "direction", "ds_min", "ds_max", "tol", "rtol"], [], Branch),
        Entry("continue_equilibrium", pwsdyn.continue_equilibrium, ("model", "x0", "param"),
              dict(model=FOLD, x0=[1.0], param="p", span=(0.5, 1.5), max_points=4),
              ["model", "x0", "param", "span", "ds", "max_points", "params", "mode",
               "ds_min", "ds_max", "tol", "locate"], [], Branch),
        Entry("iterate", iterate, ("model", "x0", "n"),
              dict(model=MAP, x0=[0.1], n=5, params={"mu": 0.2, "lam": 0.3}),
              ["model", "x0", "n", "params", "transient", "bound"], [], tuple),
    ]


ENTRIES = _entries()
ENTRY_NAMES = [e.name for e in ENTRIES]
_BY_NAME = {e.name: e for e in ENTRIES}

#: (entry name, outcome) -> number of calls; outcome 'ArgumentError', another PwsdynError's
#: class name, or 'accepted'.
COUNTS: collections.Counter = collections.Counter()


def _resolve(value):
    if isinstance(value, str) and value == "TRAJ":
        return _trajectory()
    if isinstance(value, str) and value == "VTRAJ":
        return _variational_trajectory()
    if isinstance(value, str) and value == "ORBIT":
        return _orbit()
    if isinstance(value, str) and value == "BRANCH":
        return _branch()
    if isinstance(value, str) and value == "PDPOINT":
        return _pd_point()
    return value


def call_with(entry: Entry, bad: dict):
    """Call ``entry`` with its base arguments, ``bad`` replacing some. Returns the outcome
    ('ArgumentError', the name of another PwsdynError, or 'accepted'); any other exception
    propagates (a failure of the fuzzer's property)."""
    kw = {k: _resolve(v) for k, v in entry.kwargs.items()}
    kw.update(bad)
    args = [kw.pop(k) for k in entry.args]
    try:
        with mock.patch("distributed.Client.__init__", side_effect=AssertionError(
                "the fuzzer must not start a Dask client")):
            res = entry.function(*args, **kw)
    except ArgumentError:
        outcome = "ArgumentError"
    except PwsdynError as exc:
        outcome = type(exc).__name__
    else:
        assert isinstance(res, entry.result), (entry.name, bad, type(res))
        _check_sane(res)
        outcome = "accepted"
    COUNTS[(entry.name, outcome)] += 1
    return outcome


def _check_sane(res) -> None:
    """Light sanity of an accepted result (no garbage of the wrong shape or type)."""
    if isinstance(res, Trajectory):
        assert np.all(np.isfinite(res.t)) and res.t[-1] >= res.t[0]
    elif isinstance(res, PeriodicOrbit):
        assert math.isfinite(res.period) and res.period > 0
    elif isinstance(res, PoincareResult):
        assert res.jacobian.shape == (len(res.x0), len(res.x0))
    elif isinstance(res, LyapunovSpectrum):
        assert res.exponents.ndim == 1
    elif isinstance(res, tuple):
        xs, pieces = res
        assert xs.shape[0] == pieces.shape[0]


@st.composite
def bad_call(draw, entry_name: str):
    entry = _BY_NAME[entry_name]
    k = draw(st.sampled_from([1, 1, 1, 2]))
    names = draw(st.lists(st.sampled_from(entry.fuzzed + entry.restricted), min_size=k,
                          max_size=k, unique=True))
    bad = {}
    for name in names:
        if name in entry.restricted:
            bad[name] = draw(st.sampled_from(_NEVER_VALID))
        else:
            bad[name] = draw(bad_values())
    return bad


def _fuzz(entry_name: str, bad: dict) -> str:
    return call_with(_BY_NAME[entry_name], bad)


_COMMON = dict(deadline=None, database=None,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                      HealthCheck.filter_too_much])


def fuzz_entry(entry_name: str, n: int, **options) -> collections.Counter:
    """``n`` bad calls of one entry point; their outcomes counted."""
    counts: collections.Counter = collections.Counter()

    @settings(max_examples=n, **options, **_COMMON)
    @given(data=st.data())
    def run(data):
        counts[_fuzz(entry_name, data.draw(bad_call(entry_name)))] += 1

    run()
    return counts


def _check_counts(entry_name: str, counts: collections.Counter, n: int, summary) -> None:
    """Print the counts of one entry point, and check that the calls were made and that most
    of them were refused with ArgumentError (values drawn to be invalid: the few accepted
    happen to be valid)."""
    total = sum(counts.values())
    summary(f"API fuzzer, {entry_name}: {total} calls: " + ", ".join(
        f"{v} {o}" for o, v in sorted(counts.items())))
    assert total >= 2 * n // 3
    assert counts["ArgumentError"] >= total // 2


@pytest.mark.parametrize("entry_name", ENTRY_NAMES)
def test_bad_arguments_raise_pwsdyn_errors(entry_name, summary):
    counts = fuzz_entry(entry_name, N_EXAMPLES, derandomize=True)
    _check_counts(entry_name, counts, N_EXAMPLES, summary)


@pytest.mark.slow
@pytest.mark.parametrize("entry_name", ENTRY_NAMES)
def test_bad_arguments_raise_pwsdyn_errors_many(entry_name, summary):
    counts = fuzz_entry(entry_name, N_EXAMPLES_SLOW)
    _check_counts(entry_name, counts, N_EXAMPLES_SLOW, summary)


def report(counts=None) -> str:
    """A table of the calls per entry point and outcome, and totals per class."""
    counts = COUNTS if counts is None else counts
    outcomes = sorted({o for _, o in counts}, key=lambda o: (o != "ArgumentError",
                                                             o == "accepted", o))
    lines = [f"{'entry point':<28}" + "".join(f"{o:>24}" for o in outcomes) + f"{'total':>8}"]
    for name in ENTRY_NAMES:
        row = [counts.get((name, o), 0) for o in outcomes]
        if sum(row):
            lines.append(f"{name:<28}" + "".join(f"{v:>24}" for v in row) + f"{sum(row):>8}")
    tot = [sum(v for (_, o), v in counts.items() if o == oc) for oc in outcomes]
    lines.append(f"{'all':<28}" + "".join(f"{v:>24}" for v in tot) + f"{sum(tot):>8}")
    arg = sum(v for (_, o), v in counts.items() if o == "ArgumentError")
    acc = sum(v for (_, o), v in counts.items() if o == "accepted")
    other = sum(counts.values()) - arg - acc
    lines.append(f"{sum(counts.values())} calls: {arg} refused with ArgumentError, {other} "
                 f"with another PwsdynError, {acc} accepted (values that happen to be valid); "
                 "no other exception")
    return "\n".join(lines)


def main(argv=None) -> None:
    """``python tests/test_api_fuzz.py [examples per entry point]``: run the fuzzer outside
    pytest and print the counts per class."""
    argv = sys.argv[1:] if argv is None else argv
    n = int(argv[0]) if argv else N_EXAMPLES
    for name in ENTRY_NAMES:
        fuzz_entry(name, n)
    print(report())


if __name__ == "__main__":
    main()


@pytest.mark.parametrize("bad", _FIXED + ["ORBIT"], ids=lambda v: type(v).__name__)
def test_discontinuity_map_refuses_what_is_not_a_graze(bad):
    with pytest.raises(ArgumentError, match="GR special point"):
        pwsdyn.discontinuity_map(_resolve(bad))
