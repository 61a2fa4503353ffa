"""The default options of ``simulate``: the method chosen for the tolerance, exact propagation
of the affine modes where there are any (``exact="auto"``), and the dense output rebuilt on
demand from the stored nodes (the same coefficients as storing them per step)."""

from __future__ import annotations

import copy
import math
import pickle
import tomllib

import numpy as np
import pytest

import pwsdyn
from pwsdyn.integrate.simulate import (AUTO_DOP853_BELOW, DEFAULTS, _simulate_compiled,
                                       integrator_options, state_vector)
from pwsdyn.integrate.trajectory import LazyDense
from pwsdyn.model import compile_model, load_model
from pwsdyn.model.spec import zoo_path

ZOO = ["bouncing-ball", "friction-impact-oscillator", "impact-oscillator", "one-legged-jumper",
       "quarter-car", "relay-feedback", "stick-slip-oscillator"]


def _zoo_run(name, t_end=None, **options):
    d = tomllib.loads(zoo_path(name).read_text())["defaults"]
    m = load_model(name)
    cm = compile_model(m)
    p = m.parameter_vector(d.get("params"))
    x = state_vector(m, d["x0"])
    opts = integrator_options(options, "test")
    te = d["t_end"] if t_end is None else t_end
    lazy = _simulate_compiled(cm, x, 0.0, te, p, opts)
    stored = _simulate_compiled(cm, x, 0.0, te, p, opts, store_dense=True)
    return lazy, stored


def test_defaults_are_auto():
    assert DEFAULTS["method"] == "auto" and DEFAULTS["exact"] == "auto"
    assert DEFAULTS["dense"] is True


@pytest.mark.parametrize("rtol, method", [(1e-4, "RK45"), (1e-6, "RK45"),
                                          (AUTO_DOP853_BELOW, "RK45"), (1e-8, "DOP853"),
                                          (1e-10, "DOP853"), (1e-13, "DOP853")])
def test_method_auto_follows_the_tolerance(rtol, method):
    """'auto' is DOP853 below AUTO_DOP853_BELOW, RK45 from it on; the trajectory records the
    pair that ran, and it is the run that pair gives when named."""
    m = {"name": "cubic", "states": ["x", "v"], "modes": {"m": {"x": "v", "v": "-x**3"}}}
    a = pwsdyn.simulate(m, [1.0, 0.0], 5.0, rtol=rtol, atol=rtol)
    b = pwsdyn.simulate(m, [1.0, 0.0], 5.0, rtol=rtol, atol=rtol, method=method)
    assert a.options["method"] == method
    np.testing.assert_array_equal(a.x, b.x)


def test_explicit_choices_still_hold():
    """method= names the pair of the non-affine parts; exact=False integrates every mode
    with it (the step counts of RK45 and DOP853 differ), exact=True refuses a model without
    an affine mode."""
    m = "impact-oscillator"
    rk = pwsdyn.simulate(m, [-0.5, 0.0], 30.0, method="RK45", exact=False)
    d8 = pwsdyn.simulate(m, [-0.5, 0.0], 30.0, method="DOP853", exact=False)
    ex = pwsdyn.simulate(m, [-0.5, 0.0], 30.0)
    assert rk.options["method"] == "RK45" and rk.options["exact"] is False
    assert rk.stats["steps"] > 2 * d8.stats["steps"] > 2 * ex.stats["steps"]
    # the same impacts to the tolerance
    k = min(len(rk.events), len(ex.events))
    np.testing.assert_allclose(rk.events.t[:k], ex.events.t[:k], atol=1e-8)
    with pytest.raises(pwsdyn.ArgumentError, match="'auto' or one of"):
        pwsdyn.simulate(m, [-0.5, 0.0], 1.0, method="Euler")


@pytest.mark.parametrize("name", ZOO)
@pytest.mark.parametrize("options", [{}, {"exact": False}, {"exact": False, "method": "RK45"}],
                         ids=["default", "DOP853", "RK45"])
def test_dense_output_on_demand_is_the_stored_one(name, options):
    """The dense output rebuilt from the nodes equals the one stored per step: bit for bit
    on Runge-Kutta steps (the same stages from the same numbers), to rounding on exact steps
    that land on an event (the stored one rescales the full step's Taylor terms)."""
    lazy, stored = _zoo_run(name, **options)
    assert isinstance(lazy._dense, LazyDense) and isinstance(stored._dense, np.ndarray)
    np.testing.assert_array_equal(lazy.t, stored.t)
    np.testing.assert_array_equal(lazy.x, stored.x)
    assert lazy._dense.shape == stored._dense.shape
    Q = np.asarray(lazy._dense)
    if "exact" in options:
        np.testing.assert_array_equal(Q, stored._dense)
    else:
        np.testing.assert_allclose(Q, stored._dense, rtol=0, atol=1e-15)
    ts = np.linspace(lazy.t[0], lazy.t[-1], 1001)
    for side in ("left", "right"):
        np.testing.assert_allclose(lazy(ts, side=side), stored(ts, side=side), rtol=0,
                                   atol=1e-14)


def test_lazy_dense_indexing_pickling_and_copies():
    """A few intervals are rebuilt alone; any use as an array (asarray, concatenation,
    pickling, deep copies) gives the whole plain array, built once."""
    traj = pwsdyn.simulate("impact-oscillator", [-0.5, 0.0], 60.0)
    lazy = traj._dense
    assert isinstance(lazy, LazyDense) and "on demand" in repr(lazy)
    idx = np.array([3, 1, 3, len(lazy) - 1])
    part = lazy[idx]
    assert lazy._full is None            # not built by a small index
    full = np.asarray(lazy)
    np.testing.assert_array_equal(part, full[idx])
    np.testing.assert_array_equal(lazy[2], full[2])
    assert np.asarray(lazy) is full       # kept
    assert np.concatenate([lazy, lazy]).shape == (2 * len(full),) + full.shape[1:]
    back = pickle.loads(pickle.dumps(lazy))
    assert isinstance(back, np.ndarray)
    np.testing.assert_array_equal(back, full)
    np.testing.assert_array_equal(copy.deepcopy(lazy), full)
    with pytest.raises(IndexError):
        lazy[np.array([len(lazy)])]


def test_exact_steps_of_a_stiff_spring_follow_its_frequency():
    """x'' = -k x with k = 1e6: ||M||_inf = k would limit exact steps to 1e-6; balanced, the
    bound is the frequency sqrt(k) = 1e3, so a period 2 pi / 1e3 takes a few steps, and the
    solution is cos(1000 t) to rounding."""
    k = 1e6
    m = {"name": "stiff", "states": ["x", "v"], "parameters": {"k": k},
         "modes": {"m": {"x": "v", "v": "-k*x"}}}
    w = math.sqrt(k)
    periods = 50
    t_end = periods * 2 * math.pi / w
    traj = pwsdyn.simulate(m, [1.0, 0.0], t_end, exact=True)
    assert traj.stats["steps"] <= 10 * periods
    ts = np.linspace(0.0, t_end, 501)
    np.testing.assert_allclose(traj(ts)[:, 0], np.cos(w * ts), rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj(ts)[:, 1], -w * np.sin(w * ts), rtol=0, atol=1e-9)


def test_balanced_exact_quarter_car_agrees_with_a_tight_runge_kutta_run():
    """The quarter car (tyre stiffness 150 kN/m on 40 kg: ||M|| ~ 4000, frequency ~ 63) takes
    fewer exact steps than DOP853 steps at the default tolerance, and its events agree with
    DOP853 at rtol 1e-13."""
    d = tomllib.loads(zoo_path("quarter-car").read_text())["defaults"]
    ex = pwsdyn.simulate("quarter-car", d["x0"], 1.0, exact=True)
    d8 = pwsdyn.simulate("quarter-car", d["x0"], 1.0, exact=False)
    ref = pwsdyn.simulate("quarter-car", d["x0"], 1.0, exact=False, rtol=1e-13, atol=1e-15)
    assert ex.stats["steps"] < d8.stats["steps"]
    # the same impacts, sticking phases and releases at the same times; a release onto the
    # damper's kink surface vr = 0 (held there while sticking) takes the side of vr > 0 at
    # once or through a crossing record at the same instant, as rounding has it
    solid = [(e.kind, e.name) for e in ex.events if e.kind != "crossing"]
    assert solid == [(e.kind, e.name) for e in ref.events if e.kind != "crossing"]
    for a, b in ((ex, ref), (ref, ex)):
        gaps = [np.min(np.abs(b.events.t - t)) for t in a.events.t]
        assert max(gaps) <= 1e-9
    np.testing.assert_allclose(ex.x_final, ref.x_final, rtol=0, atol=1e-8)
