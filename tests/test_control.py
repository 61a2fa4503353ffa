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


def _sweep_jump(model, param, values, x0, params):
    """Largest difference between the up and the down sweep's section points (sorted) at one
    value: a jump between coexisting attractors (hysteresis) shows as a large one."""
    ds = pwsdyn.sweep(model, param, values, x0, params=params, transient=100, samples=10,
                      direction="both", workers=1, progress=False)
    sec = ds.section.sel(state="v")
    up = np.sort(sec.sel(direction="up").values, axis=1)
    down = np.sort(sec.sel(direction="down").values, axis=1)
    return float(np.nanmax(np.abs(up - down)))


def test_designed_control_turns_loss_into_persistence():
    """Paper B: at the impact oscillator's graze (omega = 2.8, eps = 0.1: loss of the local
    attractor, a jump of ~0.6 in the velocity between up and down sweeps) the linear law 5.2
    designed from the discontinuity map makes the persistence sequence positive. The
    controlled model, built and analysed independently of the design (its own graze, its own
    discontinuity map), shows the predicted sequence, and up and down sweeps through the
    graze stay on one local attractor."""
    from test_grazing import _grazing_point

    gr, R, (X, Y) = _grazing_point(OMEGA, EPS)
    assert pwsdyn.discontinuity_map(gr).scenario == "loss"
    design = pwsdyn.design_control(gr)
    assert design.feasible and design.margin > 0 and np.all(design.sequence > 0)
    m = with_discrete_control("impact-oscillator", "sigma")
    prm = {"omega": OMEGA, "eps": EPS, "r": 0.8, **design.params()}
    prm["delta_star"] = R + 0.2
    t0 = 0.3
    orb = pwsdyn.find_periodic_orbit(m, [*_xp(t0, X, Y), R + 0.2], t0=t0, params=prm)
    br = pwsdyn.continue_orbit(m, orb, "delta_star", span=(R - 0.2, R + 0.2), ds=-0.05,
                               on_dib="stop")
    g2 = [s for s in br.special("GR") if "@" not in s.key][0]
    assert abs(g2.value - R) < 1e-8                 # the control leaves the graze in place
    dm2 = pwsdyn.discontinuity_map(g2)
    assert dm2.scenario == "persistence"
    seq = dm2.persistence(len(design.sequence))
    assert np.allclose(seq, design.sequence, rtol=1e-6, atol=1e-9 * np.abs(seq).max())
    values = np.linspace(0.95 * R, 1.05 * R, 21)
    free = _sweep_jump("impact-oscillator", "sigma", values,
                       {"x": Y, "v": OMEGA * X}, {"omega": OMEGA, "eps": EPS, "r": 0.8})
    prm.pop("delta_star")
    ctrl = _sweep_jump(m, "delta_star", values, {"x": Y, "v": OMEGA * X, "sigma": 1.05 * R},
                       prm)
    assert free > 0.3 and ctrl < 0.1
