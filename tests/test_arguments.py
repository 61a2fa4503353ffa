"""Argument validation of the public API: regression tests of the defects found by fuzzing
(tests/test_api_fuzz.py) and of the checks in :mod:`pwsdyn._validate`.

Each bad call raises :class:`pwsdyn.ArgumentError` (a ``ValueError`` and a ``TypeError``)
naming the argument, before any work.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn import ArgumentError, PeriodicOrbit
from pwsdyn import _validate as V
from pwsdyn.model.iteration import iterate

IO = "impact-oscillator"
X0 = [0.0, -0.5]
NAN, INF = float("nan"), float("inf")


def _sweep_map(**kw):
    args = dict(params={"lam": 0.1}, transient=10, samples=10, workers=1, progress=False)
    args.update(kw)
    return pwsdyn.sweep("sqrt-map", "mu", [0.01, 0.02, 0.03], [0.0], **args)


# --------------------------------------------------------------------------------------
# the exception
# --------------------------------------------------------------------------------------

def test_argument_error_is_value_and_type_error():
    assert issubclass(ArgumentError, pwsdyn.PwsdynError)
    assert issubclass(ArgumentError, ValueError) and issubclass(ArgumentError, TypeError)


# --------------------------------------------------------------------------------------
# defects: silent nonsense results
# --------------------------------------------------------------------------------------

def test_sweep_refuses_negative_period_tol_and_zero_max_period():
    # were: periods [0, 0, 0] with status 0
    with pytest.raises(ArgumentError, match="`period_tol` must be a number in the open "
                                            r"interval \(0, 1\), got -1"):
        _sweep_map(period_tol=-1)
    with pytest.raises(ArgumentError, match="`max_period` must be an integer in"):
        _sweep_map(max_period=0)
    with pytest.raises(ArgumentError, match="`period_tol`"):
        _sweep_map(period_tol=NAN)


def test_basins_refuses_negative_match_tol():
    # was: 9 "attractors" instead of 2 (every start its own)
    for bad in (-1, 0.0, NAN, INF):
        with pytest.raises(ArgumentError, match="`match_tol`"):
            pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.5, 0.5, 9)},
                          params={"mu": 0.1, "lam": 0.1}, match_tol=bad, workers=1,
                          progress=False)


def test_find_periodic_orbit_refuses_unresolvable_t0():
    # was: "converged" with multipliers [1, 1] (t0 + T == t0 in double precision)
    with pytest.raises(ArgumentError, match=r"`t0`: one period of the orbit .* not resolved"):
        pwsdyn.find_periodic_orbit(IO, X0, t0=1e300)
    with pytest.raises(ArgumentError, match="`t0` must be a finite number"):
        pwsdyn.find_periodic_orbit(IO, X0, t0=INF)


def test_simulate_refuses_unresolvable_span():
    # was: SUCCESS after 0 steps (the spacing of doubles at 1e16 is 2)
    with pytest.raises(ArgumentError, match=r"`t_span`: the span \(2 long.* not resolved"):
        pwsdyn.simulate(IO, X0, (1e16, 1e16 + 2))
    # the rule: at least 1024 units eps * max(1, |t|)
    need = V.TIME_RESOLUTION_ULPS * np.finfo(float).eps * 1e6
    with pytest.raises(ArgumentError, match="not resolved"):
        pwsdyn.simulate(IO, X0, (1e6, 1e6 + 0.5 * need))
    with pytest.raises(ArgumentError, match="not resolved"):
        pwsdyn.simulate(IO, X0, (0.0, 1e-14))
    traj = pwsdyn.simulate(IO, X0, (1e6, 1e6 + 1.0))       # resolved: integrates
    assert traj.stats["steps"] > 0 and traj.t_final == 1e6 + 1.0


def test_lyapunov_refuses_infinite_t0():
    # was: exponents [0, 0]
    for bad in (INF, -INF, NAN):
        with pytest.raises(ArgumentError, match="`t0` must be a finite number"):
            pwsdyn.lyapunov_spectrum(IO, X0, t0=bad, transient=1, duration=2)
    with pytest.raises(ArgumentError, match="`t0`: the run .* not resolved"):
        pwsdyn.lyapunov_spectrum(IO, X0, t0=1e17, transient=1, duration=2)


# --------------------------------------------------------------------------------------
# defects: raw Python errors
# --------------------------------------------------------------------------------------

def test_x0_with_none_entry():
    with pytest.raises(ArgumentError, match=r"`x0` must be .*entry 0 is None"):
        pwsdyn.simulate(IO, [None, 0.0], 1.0)
    with pytest.raises(ArgumentError, match=r"`x0\['x'\]` must be a finite number, got None"):
        pwsdyn.simulate(IO, {"x": None, "v": 0.0}, 1.0)
    for bad in ("0 0", 1.0, [True, 0.0], ["a", 0.0], [[0.0], [0.0]]):
        with pytest.raises(ArgumentError, match="`x0`"):
            pwsdyn.simulate(IO, bad, 1.0)


def test_params_must_be_a_mapping_of_numbers():
    with pytest.raises(ArgumentError, match="`params` must be a dict .* got 'g=1'"):
        pwsdyn.simulate(IO, X0, 1.0, params="g=1")
    with pytest.raises(ArgumentError, match="`params`"):
        pwsdyn.sweep("sqrt-map", "mu", [0.01], [0.0], params=[("lam", 0.1)], workers=1,
                     progress=False)
    for bad in (None, "1", True, [1.0], 10**400):
        with pytest.raises(ArgumentError, match="parameter 'omega' must be"):
            pwsdyn.simulate(IO, X0, 1.0, params={"omega": bad})


def test_mode_must_be_a_known_mode_name():
    with pytest.raises(ArgumentError, match="`mode` must be None or a mode name, got 5"):
        pwsdyn.simulate(IO, X0, 1.0, mode=5)
    with pytest.raises(ArgumentError, match="unknown mode 'flying'"):
        pwsdyn.simulate(IO, X0, 1.0, mode="flying")
    with pytest.raises(ArgumentError, match="`mode`"):
        pwsdyn.find_periodic_orbit(IO, X0, mode="stick:nothing")
    with pytest.raises(ArgumentError, match="`mode`"):
        pwsdyn.poincare_map(IO, X0, "impact", mode=3)
    with pytest.raises(ArgumentError, match="`mode`"):
        pwsdyn.lyapunov_spectrum(IO, X0, transient=1, duration=2, mode="flying")


def test_budgets_within_int64_and_cap():
    for bad in (10**20, 2**63, 0, -1, 1.5, True, "10"):
        with pytest.raises(ArgumentError, match="`max_steps` must be an integer"):
            pwsdyn.simulate(IO, X0, 1.0, max_steps=bad)
    with pytest.raises(ArgumentError, match="`max_events`"):
        pwsdyn.simulate(IO, X0, 1.0, max_events=10**20)


def test_orbits_and_sections_of_a_map_are_refused_clearly():
    for call in (lambda: pwsdyn.find_periodic_orbit("sqrt-map", [0.1]),
                 lambda: pwsdyn.poincare_map("sqrt-map", [0.1], "stroboscopic"),
                 lambda: pwsdyn.simulate("sqrt-map", [0.1], 1.0)):
        with pytest.raises(ArgumentError, match="'sqrt-map' is a map"):
            call()
    with pytest.raises(ArgumentError, match="`traj` must be a Trajectory"):
        PeriodicOrbit.from_trajectory(iterate("sqrt-map", [0.1], 5))
    with pytest.raises(ArgumentError, match="'impact-oscillator' is a flow"):
        iterate(IO, X0, 5)


def test_max_nodes_and_nodes():
    with pytest.raises(ArgumentError, match="`max_nodes` must be an integer in"):
        pwsdyn.find_periodic_orbit(IO, X0, max_nodes=0)
    for bad in (0, -1, "two", 1.5, 10**6):
        with pytest.raises(ArgumentError, match="`nodes`"):
            pwsdyn.find_periodic_orbit(IO, X0, nodes=bad)


def test_memory_is_bounded_before_allocation():
    # was: an attempt to allocate 15 GiB
    with pytest.raises(ArgumentError, match=r"duration=1000000000 would allocate about "
                                            r"[0-9.]+ GiB .* more than the limit"):
        pwsdyn.lyapunov_spectrum(IO, X0, duration=10**9)
    with pytest.raises(ArgumentError, match=r"iterate\(\) with n=.* would allocate"):
        iterate("sqrt-map", [0.1], 10**11)
    with pytest.raises(ArgumentError, match="would allocate"):
        _sweep_map(max_points=10**10)


def test_sweep_over_zero_forcing_frequency_is_refused_before_work():
    # was: an endless loop (the forcing period 2 pi / omega is undefined at omega = 0)
    with pytest.raises(ArgumentError, match=r"forcing period 2\*pi/omega .* must be a "
                                            r"positive finite number, got undefined .* at "
                                            r"omega = 0\.0"):
        pwsdyn.sweep(IO, "omega", [0.0, 1.0, 2.0], X0, transient=1, samples=2, workers=1,
                     progress=False)
    with pytest.raises(ArgumentError, match=r"at omega = -1\.0"):
        pwsdyn.sweep(IO, "omega", [-1.0, 1.0], X0, transient=1, samples=2, workers=1,
                     progress=False)
    # a period too short to resolve at the end of the window
    with pytest.raises(ArgumentError, match="omega = 1e\\+300"):
        pwsdyn.sweep(IO, "omega", [1.0, 1e300], X0, transient=1, samples=2, workers=1,
                     progress=False)
    # and through the other entry points
    with pytest.raises(ArgumentError, match="forcing period"):
        pwsdyn.find_periodic_orbit(IO, X0, params={"omega": 0.0})
    with pytest.raises(ArgumentError, match="forcing period"):
        pwsdyn.lyapunov_spectrum(IO, X0, params={"omega": 0.0}, duration=2)
    with pytest.raises(ArgumentError, match="forcing period"):
        pwsdyn.basins(IO, {"x": [0.0]}, params={"omega": 0.0}, transient=1, samples=2,
                      workers=1, progress=False)


def test_model_argument():
    for bad in (5, None, 1.5, [IO], b"impact-oscillator", ""):
        with pytest.raises(ArgumentError, match="`model`"):
            pwsdyn.simulate(bad, X0, 1.0)
    with pytest.raises(pwsdyn.ModelError):
        pwsdyn.simulate("no-such-model", X0, 1.0)


# --------------------------------------------------------------------------------------
# every numeric option of simulate
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("name,bad", [
    ("rtol", 0.0), ("rtol", -1e-6), ("rtol", NAN), ("rtol", 1.0), ("rtol", 1e-17),
    ("rtol", "1e-6"), ("atol", 0.0), ("atol", INF), ("atol", None),
    ("first_step", 0.0), ("first_step", -1.0), ("first_step", NAN),
    ("max_step", 0.0), ("max_step", NAN), ("max_step", -INF),
    ("chatter_ratio", 0.0), ("chatter_ratio", INF), ("chatter_ratio", NAN),
    ("chatter_velocity", -1.0), ("chatter_velocity", INF),
    ("sliding", "filippov"), ("sliding", 0), ("sliding_gain", -1.0), ("sliding_gain", NAN),
    ("method", None), ("method", "euler"), ("exact", 1), ("chatter", "yes"),
    ("variational", None), ("dense", 0), ("throw", "no"),
])
def test_simulate_option_refused(name, bad):
    with pytest.raises(ArgumentError, match=f"`{name}`"):
        pwsdyn.simulate(IO, X0, 1.0, **{name: bad})


@pytest.mark.parametrize("t_span", [(0.0, NAN), (NAN, 1.0), (0.0, INF), (1.0, 0.0), (1.0, 1.0),
                                    "1", (0.0,), (0.0, 1.0, 2.0), {"t0": 0}, (None, 1.0),
                                    (True, 2.0), 0.0, -1.0])
def test_simulate_t_span_refused(t_span):
    with pytest.raises(ArgumentError, match="`t_span`"):
        pwsdyn.simulate(IO, X0, t_span)


def test_options_checked_before_any_work_in_every_entry_point():
    calls = [
        lambda: pwsdyn.find_periodic_orbit(IO, X0, rtol=-1),
        lambda: pwsdyn.poincare_map(IO, X0, "impact", atol=NAN),
        lambda: pwsdyn.sweep(IO, "omega", [2.5], X0, workers=1, progress=False,
                             max_steps=10**20),
        lambda: pwsdyn.basins(IO, {"x": [0.0]}, workers=1, progress=False, chatter_ratio=-2),
        lambda: pwsdyn.lyapunov_spectrum(IO, X0, sliding_gain=-1),
    ]
    for call in calls:
        with pytest.raises(ArgumentError):
            call()


# --------------------------------------------------------------------------------------
# the other entry points
# --------------------------------------------------------------------------------------

def test_find_periodic_orbit_arguments():
    for kw, name in ((dict(tol=0.0), "tol"), (dict(tol=NAN), "tol"), (dict(tol=2.0), "tol"),
                     (dict(max_iter=0), "max_iter"), (dict(max_iter=2.0), "max_iter"),
                     (dict(lock_tol=-1.0), "lock_tol"), (dict(periods=0), "periods"),
                     (dict(periods=NAN), "periods"), (dict(period=-1.0), "period"),
                     (dict(period=INF), "period"), (dict(phase=[1.0]), "phase")):
        with pytest.raises(ArgumentError, match=f"`{name}`"):
            pwsdyn.find_periodic_orbit(IO, X0, **kw)


def test_from_trajectory_arguments():
    traj = pwsdyn.simulate(IO, X0, (0.0, 30.0))
    for kw, name in ((dict(t0=NAN), "t0"), (dict(t0=1e9), "t0"), (dict(period=0.0), "period"),
                     (dict(periods=-1), "periods"), (dict(refine="yes"), "refine"),
                     (dict(recurrence_tol=-1.0), "recurrence_tol")):
        with pytest.raises(ArgumentError, match=f"`{name}`"):
            PeriodicOrbit.from_trajectory(traj, **kw)
    with pytest.raises(ArgumentError, match="`traj`"):
        PeriodicOrbit.from_trajectory(None)


def test_poincare_map_arguments():
    for kw, name in ((dict(returns=0), "returns"), (dict(returns=10**20), "returns"),
                     (dict(side="middle"), "side"), (dict(t0=NAN), "t0"),
                     (dict(t_max=-1.0), "t_max"), (dict(t_max=NAN), "t_max"),
                     (dict(dense=None), "dense")):
        with pytest.raises(ArgumentError, match=f"`{name}`"):
            pwsdyn.poincare_map(IO, X0, "impact", **kw)
    with pytest.raises(ArgumentError, match="unknown section"):
        pwsdyn.poincare_map(IO, X0, None)


def test_floquet_and_monodromy_arguments():
    for bad in (None, "M", [[1.0, NAN], [0.0, 1.0]], [[1.0, 2.0]], np.zeros((0, 0)), 1.0,
                [["a"]], np.zeros((2, 2, 2))):
        with pytest.raises(ArgumentError, match="`monodromy`"):
            pwsdyn.floquet_multipliers(bad)
    M = np.eye(2)
    with pytest.raises(ArgumentError, match="`flow_direction`"):
        pwsdyn.floquet_multipliers(M, flow_direction=[1.0])
    with pytest.raises(ArgumentError, match="`section_normal`"):
        pwsdyn.floquet_multipliers(M, flow_direction=[1.0, 0.0], section_normal=[NAN, 1.0])
    with pytest.raises(ArgumentError, match="`traj`"):
        pwsdyn.monodromy(M)
    with pytest.raises(ArgumentError, match="`form`"):
        pwsdyn.monodromy(pwsdyn.simulate(IO, X0, 1.0, variational=True), form=None)


def test_sweep_and_basins_arguments():
    for kw, name in ((dict(transient=-1), "transient"), (dict(samples=0), "samples"),
                     (dict(samples=2.0), "samples"), (dict(phase=NAN), "phase"),
                     (dict(period=0.0), "period"), (dict(bound=NAN), "bound"),
                     (dict(bound=-1.0), "bound"), (dict(chunk_size=0), "chunk_size"),
                     (dict(warmup=-1), "warmup"), (dict(lyapunov="yes"), "lyapunov"),
                     (dict(progress=None), "progress"), (dict(max_points=0), "max_points"),
                     (dict(direction=None), "direction"), (dict(workers=0), "workers"),
                     (dict(out=5), "out"), (dict(store=[]), "store")):
        with pytest.raises(ArgumentError, match=f"`{name}`"):
            _sweep_map(**kw)
    for values in (None, "0.1", 0.1, [0.1, None], [[0.1, 0.2]], [True, False], {"a": 1}):
        with pytest.raises(ArgumentError, match="`values`"):
            _sweep_map(values=values) if False else pwsdyn.sweep(
                "sqrt-map", "mu", values, [0.0], workers=1, progress=False)
    with pytest.raises(ArgumentError, match="unknown parameter"):
        pwsdyn.sweep("sqrt-map", None, [0.1], [0.0], workers=1, progress=False)
    grid_ok = {"x": [-0.1, 0.1]}
    for kw, name in ((dict(grid=None), "grid"), (dict(grid={"x": "ab"}), "grid"),
                     (dict(grid={"x": [NAN]}), "grid"), (dict(grid={"x": 0.1}), "grid"),
                     (dict(grid={5: [0.1]}), "grid"), (dict(samples=1), "samples"),
                     (dict(max_period=0), "max_period")):
        kw = {"grid": grid_ok, **kw}
        with pytest.raises(ArgumentError, match=f"`{name}`|unknown state"):
            pwsdyn.basins("sqrt-map", params={"mu": 0.1, "lam": 0.1}, workers=1,
                          progress=False, **kw)


def test_lyapunov_and_iterate_arguments():
    for kw, name in ((dict(duration=0), "duration"), (dict(duration=2.5), "duration"),
                     (dict(transient=-1), "transient"), (dict(segment=0.0), "segment"),
                     (dict(segment=NAN), "segment"), (dict(bound=NAN), "bound")):
        with pytest.raises(ArgumentError, match=f"`{name}`"):
            pwsdyn.lyapunov_spectrum(IO, X0, **kw)
    for kw, name in ((dict(n=-1), "n"), (dict(n=10**20), "n"), (dict(n=2.0), "n"),
                     (dict(transient=-1), "transient"), (dict(transient=10**20), "transient"),
                     (dict(bound=0.0), "bound")):
        args = {"n": 5, **kw}
        with pytest.raises(ArgumentError, match=f"`{name}`"):
            iterate("sqrt-map", [0.1], **args)
    xs, pieces = iterate("sqrt-map", [0.1], 0)
    assert xs.shape == (0, 1) and pieces.shape == (0,)


# --------------------------------------------------------------------------------------
# the helpers
# --------------------------------------------------------------------------------------

def test_validate_helpers_refuse_nan_and_bools():
    for f in (lambda v: V.number("a", v), lambda v: V.positive("a", v),
              lambda v: V.tolerance("a", v), lambda v: V.nonnegative("a", v),
              lambda v: V.number("a", v, lo=0, hi=1)):
        for bad in (NAN, np.float64(NAN), True, None, "1", [1.0], 1j, INF):
            with pytest.raises(ArgumentError, match="`a` must be"):
                f(bad)
    assert V.number("a", np.int64(3)) == 3.0
    assert V.positive("a", INF, allow_inf=True) == INF
    assert V.integer("a", np.int32(4), lo=1) == 4
    for bad in (True, 1.0, -1, 10**13, "3", None):
        with pytest.raises(ArgumentError, match="`a` must be an integer"):
            V.integer("a", bad)
    with pytest.raises(ArgumentError, match="would allocate about 16 GiB"):
        V.memory("this call", 16 * 2**30)
    V.time_span("t", 0.0, 1.0)
    with pytest.raises(ArgumentError, match="not resolved"):
        V.time_window("t", 1e16, 2.0)
    assert math.isclose(V.resolution(1e6), 1e6 * np.finfo(float).eps)
    assert "..." in V.describe(list(range(1000)))
