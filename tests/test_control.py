"""Discrete control of the constraint position (thesis eq. 5.2) as a model transformation:
the controlled model, its reset against the law written out, and the multipliers of the
controlled orbit (the uncontrolled ones and c0, where the smooth dynamics does not depend on
the constraint)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn.errors import ArgumentError
from pwsdyn.model.control import with_discrete_control

OMEGA, EPS = 2.8, 0.1


def _forced_response():
    X, Y = np.linalg.solve(np.array([[1 - OMEGA**2, -EPS * OMEGA], [EPS * OMEGA,
                                                                      1 - OMEGA**2]]),
                           [1.0, 0.0])
    return X, Y, math.hypot(X, Y)


def _xp(t, X, Y):
    return np.array([X * math.sin(OMEGA * t) + Y * math.cos(OMEGA * t),
                     OMEGA * (X * math.cos(OMEGA * t) - Y * math.sin(OMEGA * t))])


def test_controlled_model_carries_the_parameter_as_a_state():
    m = with_discrete_control("impact-oscillator", "sigma")
    assert m.states == ("x", "v", "sigma") and "sigma" not in m.parameters
    assert {"delta_star", "c0", "c_x", "c_v", "x_star_x", "x_star_v", "t_c"} <= set(m.parameters)
    assert m.parameters["delta_star"] == pwsdyn.load_model("impact-oscillator").parameters["sigma"]
    assert [e.name for e in m.events] == ["impact", "control"]
    # its definition travels with it (files written from it can rebuild it)
    assert pwsdyn.load_model(m.spec).hash == m.hash
    with pytest.raises(ArgumentError, match="no parameter"):
        with_discrete_control("impact-oscillator", "delta")
    with pytest.raises(ArgumentError, match="autonomous"):
        with_discrete_control({"name": "a", "states": ["x"], "parameters": {"p": 1.0},
                               "modes": {"m": {"x": "-x"}}}, "p")


def test_the_reset_is_the_linear_law_at_the_section():
    """Off the reference, each crossing of t = t_c (mod T) sets
    sigma = delta* + c . (x - x*) + c0 (sigma - delta*)."""
    X, Y, R = _forced_response()
    m = with_discrete_control("impact-oscillator", "sigma")
    p = {"omega": OMEGA, "eps": EPS, "delta_star": R + 0.3, "c0": 0.5, "c_x": 0.2,
         "c_v": -0.1, "x_star_x": 0.01, "x_star_v": -0.02, "t_c": 0.5}
    x0 = [0.0, 0.1, R + 0.35]
    tr = pwsdyn.simulate(m, x0, (0.0, 5.0), params=p, rtol=1e-12, atol=1e-12)
    ctrl = [e for e in tr.events if e.name == "control"]
    T = 2 * math.pi / OMEGA
    assert len(ctrl) == 3
    assert all(abs(e.t - 0.5 - k * T) < 1e-11 for k, e in enumerate(ctrl))
    for e in ctrl:
        xb = e.x_before
        law = (p["delta_star"] + p["c_x"] * (xb[0] - p["x_star_x"])
               + p["c_v"] * (xb[1] - p["x_star_v"]) + p["c0"] * (xb[2] - p["delta_star"]))
        assert abs(e.x_after[2] - law) < 1e-14 and np.array_equal(e.x_after[:2], xb[:2])


@pytest.mark.parametrize("c0", [0.0, 0.4, -0.7])
def test_controlled_multipliers_are_the_uncontrolled_ones_and_c0(c0):
    """On a non-impacting reference orbit (the stop beyond the free motion) the smooth
    dynamics does not depend on sigma: the controlled multipliers are the uncontrolled ones
    and c0 (thesis section 5.2), to 1e-8."""
    X, Y, R = _forced_response()
    sigma = R + 0.3
    free = pwsdyn.find_periodic_orbit("impact-oscillator", list(_xp(0.0, X, Y)), t0=0.0,
                                      params={"omega": OMEGA, "eps": EPS, "sigma": sigma})
    m = with_discrete_control("impact-oscillator", "sigma")
    xs = _xp(0.0, X, Y)
    ctrl = {"omega": OMEGA, "eps": EPS, "delta_star": sigma, "c0": c0, "c_x": 0.3,
            "c_v": -0.2, "x_star_x": xs[0], "x_star_v": xs[1]}
    t0 = 0.3
    orb = pwsdyn.find_periodic_orbit(m, [*_xp(t0, X, Y), sigma], t0=t0, params=ctrl)
    assert [e.name for e in orb.events] == ["control"]
    want = np.sort_complex(np.append(free.multipliers, c0))
    got = np.sort_complex(orb.multipliers)
    assert np.max(np.abs(got - want)) < 1e-8
