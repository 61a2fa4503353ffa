"""Models as data: loading, validation, safe expressions, symbolic derivatives, code cache, zoo.

Every numerical check compares with something computed independently of the code under test:
closed-form solutions, central finite differences of the generated functions, or SymPy's own
``lambdify`` of the model's expressions (not the generated module).
"""

from __future__ import annotations

import builtins
import json
import math
import os
import subprocess
import sys
import textwrap
import time
import tomllib
import uuid
import zlib
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.linalg import expm
from scipy.optimize import fsolve

import pwsdyn
from pwsdyn import ExpressionError, ModelError
from pwsdyn.model.codegen import (W_F, W_FT, W_FX, W_G, W_GT, W_GX, W_H, W_HD, W_HDT, W_HDX,
                                  W_HT, W_HX)
from pwsdyn.model.expressions import parse_expression
from pwsdyn.model.spec import zoo_path

# The bouncing-ball model exactly as the issue gives it. It must load as written.
ISSUE_BOUNCING_BALL = '''\
name = "bouncing-ball"
description = "Ball bouncing on a sinusoidally vibrating table (Newton restitution)"
source = "Classic test case of impacting systems; sticking and release as in Nordmark & Piiroinen, Nonlinear Dyn. 58 (2009) 85-106"
states = ["y", "v"]
forcing_period = "2*pi/omega"

[parameters]
g = 9.81
e = 0.8
A = 0.0
omega = 1.0

[definitions]
s = "A*sin(omega*t)"
sdot = "A*omega*cos(omega*t)"

[modes.flight]
y = "v"
v = "-g"

[[events]]
name = "impact"
kind = "impact"
surface = "y - s"
direction = -1
reset = { v = "sdot - e*(v - sdot)" }
'''

# flows only: the zoo's piecewise-smooth maps (kind = "map") are tested in test_explore.py
ZOO = [n for n in pwsdyn.zoo_names() if not getattr(pwsdyn.load_model(n), "is_map", False)]
#: zoo models with impact events (the Filippov ones, relay and belt, have none)
ZOO_IMPACTING = [n for n in ZOO if any(e.kind == "impact" for e in pwsdyn.load_model(n).events)]


def _sym(name):
    return sp.Symbol(name, real=True)


def _bb_dict(**changes):
    """The issue's bouncing ball as a dict, with top-level changes."""
    d = tomllib.loads(ISSUE_BOUNCING_BALL)
    d.update(changes)
    return d


def _bb_event(**changes):
    ev = dict(name="impact", kind="impact", surface="y - s", direction=-1,
              reset={"v": "sdot - e*(v - sdot)"})
    ev.update(changes)
    return ev


# ======================================================================================
# loading
# ======================================================================================

def test_issue_bouncing_ball_loads_as_written():
    m = pwsdyn.load_model(ISSUE_BOUNCING_BALL)
    assert m.name == "bouncing-ball"
    assert m.states == ("y", "v")
    assert m.parameters == {"g": 9.81, "e": 0.8, "A": 0.0, "omega": 1.0}
    assert m.mode_names == ("flight",)
    assert "Nordmark & Piiroinen" in m.reference
    t, y, v, g, e, A, w = map(_sym, ["t", "y", "v", "g", "e", "A", "omega"])
    assert m.modes[0].rhs == (v, -g)
    (ev,) = m.events
    assert (ev.name, ev.kind, ev.direction, ev.target, ev.terminal) == (
        "impact", "impact", -1, None, False)
    assert sp.simplify(m.surfaces[ev.surface].expr - (y - A * sp.sin(w * t))) == 0
    sdot = A * w * sp.cos(w * t)
    assert ev.reset[0] == y  # position unchanged by the impact
    assert sp.simplify(ev.reset[1] - (sdot - e * (v - sdot))) == 0
    assert m.forcing_period_value() == pytest.approx(2 * math.pi, rel=1e-15)
    # the zoo file is the issue's text plus comments and [defaults]: the same compiled model
    assert m.hash == pwsdyn.load_model("bouncing-ball").hash


def test_all_sources_give_the_same_model(tmp_path):
    path = tmp_path / "ball.toml"
    path.write_text(ISSUE_BOUNCING_BALL)
    models = [pwsdyn.load_model(str(path)), pwsdyn.load_model(path),
              pwsdyn.load_model("bouncing-ball"), pwsdyn.load_model(ISSUE_BOUNCING_BALL),
              pwsdyn.load_model(tomllib.loads(ISSUE_BOUNCING_BALL)),
              pwsdyn.load_model(zoo_path("bouncing-ball"))]
    assert len({m.hash for m in models}) == 1
    assert pwsdyn.load_model(models[0]) is models[0]
    assert models[0].origin == str(path)
    # the hash is not blind: a different impact law gives a different hash
    other = _bb_dict(events=[_bb_event(reset={"v": "sdot - e*e*(v - sdot)"})])
    assert pwsdyn.load_model(other).hash != models[0].hash


def test_zoo_is_complete():
    for name in ("bouncing-ball", "impact-oscillator", "impact-oscillator-base",
                 "one-legged-jumper"):
        assert name in ZOO
    for name in ZOO:
        m = pwsdyn.load_model(name)
        assert m.description and m.reference, name
        d = m.spec["defaults"]
        assert set(d["x0"]) == set(m.states) and d["t_end"] > 0, name


def test_parameter_overrides_against_free_fall():
    """Ball on a fixed table (A = 0) dropped from y0: the first impact is at sqrt(2 y0 / g) with
    velocity -sqrt(2 g y0); Newton's law gives e sqrt(2 g y0) after it."""
    m = pwsdyn.load_model("bouncing-ball")
    g, e, y0 = 1.62, 0.5, 2.0
    # the defaults: [parameters] with the zoo file's [defaults] params (A, omega) over them
    np.testing.assert_array_equal(m.parameter_vector(), [9.81, 0.8, 0.224, 2 * math.pi])
    p = m.parameter_vector({"g": g, "e": e, "A": 0.0})
    np.testing.assert_array_equal(p, [g, e, 0.0, 2 * math.pi])
    assert m.parameters["g"] == 9.81  # the defaults are not modified
    assert m.forcing_period_value({"omega": 4.0}) == pytest.approx(math.pi / 2, rel=1e-15)
    traj = pwsdyn.simulate(m, {"y": y0, "v": 0.0}, (0, 4.0), params={"g": g, "e": e, "A": 0})
    assert traj.params["g"] == g and traj.params["e"] == e
    first = traj.events[0]
    assert first.t == pytest.approx(math.sqrt(2 * y0 / g), rel=1e-11)
    assert first.x_before[1] == pytest.approx(-math.sqrt(2 * g * y0), rel=1e-9)
    assert first.x_after[1] == pytest.approx(e * math.sqrt(2 * g * y0), rel=1e-9)
    # the next impact is a full ballistic flight later: 2 v+ / g
    assert traj.events[1].t - first.t == pytest.approx(2 * e * math.sqrt(2 * y0 / g), rel=1e-9)


# ======================================================================================
# bad input: each a specific error naming what is wrong
# ======================================================================================

def test_malformed_toml_names_file_and_line(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('name = "x"\nstates = ["y"]\n[parameters]\ng = \n')
    with pytest.raises(ModelError, match=r"broken\.toml:4: malformed TOML") as info:
        pwsdyn.load_model(path)
    assert info.value.line == 4 and info.value.source == str(path)
    with pytest.raises(ModelError, match=r"<string>:2: malformed TOML"):
        pwsdyn.load_model('name = "x"\nstates = ["y"\n')


def test_unknown_name_names_file_field_line_and_name(tmp_path):
    text = ISSUE_BOUNCING_BALL.replace('v = "-g"', 'v = "-g*q"')
    path = tmp_path / "ball.toml"
    path.write_text(text)
    line = text.splitlines().index('v = "-g*q"') + 1
    with pytest.raises(ExpressionError, match=rf"ball\.toml:{line}, field `modes\.flight\.v`: "
                                              rf"unknown name 'q'"):
        pwsdyn.load_model(path)
    with pytest.raises(ExpressionError, match=r"field `events\[0\]\.reset\.v`.*unknown name 'vv'"):
        pwsdyn.load_model(_bb_dict(events=[_bb_event(reset={"v": "-e*vv"})]))


SMUGGLE = ["__import__('os').system('ls')", "x.__class__", "lambda: 1", "[i for i in ()]",
           "'a'*3", "open('f')", "y.__class__.__bases__[0].__subclasses__()",
           "getattr(y, 'real')", "eval('1')", "exec('1')", "sin.__globals__",
           "(lambda: __import__('os'))()"]


@pytest.mark.parametrize("text", SMUGGLE)
def test_code_in_expressions_is_rejected_and_never_run(text, tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(os, "system", lambda *a: calls.append(("system", a)) or 0)
    real_open = builtins.open
    monkeypatch.setattr(builtins, "open",
                        lambda *a, **k: calls.append(("open", a)) or real_open(*a, **k))
    names = {"x": _sym("x"), "y": _sym("y")}
    with pytest.raises(ExpressionError):
        parse_expression(text, names, field="modes.flight.v")
    # through the loader, in every place an expression can appear
    for model in (_bb_dict(modes={"flight": {"y": "v", "v": text}}),
                  _bb_dict(events=[_bb_event(surface=text)]),
                  _bb_dict(events=[_bb_event(guard=text)]),
                  _bb_dict(definitions={"s": text, "sdot": "0"}),
                  _bb_dict(forcing_period=text)):
        with pytest.raises(ExpressionError):
            pwsdyn.load_model(model)
    assert calls == []


def test_rejected_code_does_not_create_files(tmp_path):
    marker = tmp_path / "marker"
    for text in (f"open({str(marker)!r}, 'w')", f"__import__('pathlib').Path({str(marker)!r})"
                 ".touch()"):
        with pytest.raises(ExpressionError):
            pwsdyn.load_model(_bb_dict(modes={"flight": {"y": "v", "v": text}}))
    assert not marker.exists()


@pytest.mark.parametrize("text, match", [
    ("9**9**9", "exponent larger than"),            # would make SymPy compute 9**387420489
    ("-" * 10000 + "1", "nested too deeply"),       # CPython's parser runs out of stack
    ("x" + "**x" * 3000, "nested too deeply"),
    ("1e400", "not finite"),
    ("sqrt(x, 2)", "'sqrt' takes 1 argument"),      # sqrt's 2nd argument is SymPy's `evaluate`
    ("Max()", "'Max' takes at least 1"),
    ("sin(*x)", "starred"),
    ("x if x else 1", "IfExp"),
    ("x // 2", "BinOp"),
])
def test_hostile_or_wrong_expressions(text, match):
    t0 = time.perf_counter()
    with pytest.raises(ExpressionError, match=match):
        parse_expression(text, {"x": _sym("x")}, field="f")
    assert time.perf_counter() - t0 < 10.0  # rejected, not computed


def test_valid_expressions_parse_to_the_right_sympy():
    x, y = _sym("x"), _sym("y")
    names = {"x": x, "y": y}
    assert parse_expression("x^2 + 2**10", names) == x**2 + 1024
    assert parse_expression("atan2(y, x) + log(x, 2)", names) == sp.atan2(y, x) + sp.log(x, 2)
    long_sum = " + ".join(f"{k}*x" for k in range(1, 501))       # a left spine 500 deep
    assert parse_expression(long_sum, names) == 125250 * x
    guard = parse_expression("x < 0 and not y >= 1", names, boolean=True)
    assert guard == sp.And(x < 0, sp.Not(y >= 1))


def test_x0_errors_from_simulate():
    with pytest.raises(ValueError, match=r"`x0` must have 2 entries \(states \['y', 'v'\]\), "
                                         r"got 3"):
        pwsdyn.simulate("bouncing-ball", [1.0, 0.0, 0.0], (0, 1))
    with pytest.raises(ValueError, match=r"unknown state\(s\) \['w'\]"):
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "w": 0.0}, (0, 1))
    with pytest.raises(ValueError, match=r"missing state\(s\) \['v'\]"):
        pwsdyn.simulate("bouncing-ball", {"y": 1.0}, (0, 1))


def test_parameter_errors():
    with pytest.raises(ValueError, match=r"parameter\(s\) g of model 'bouncing-ball' must be "
                                         r"finite"):
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 1),
                        params={"g": float("nan")})
    with pytest.raises(ValueError, match=r"unknown parameter 'gravity'"):
        pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 1),
                        params={"gravity": 9.81})
    with pytest.raises(ValueError, match=r"parameter 'e' must be a number"):
        pwsdyn.load_model("bouncing-ball").parameter_vector({"e": "high"})
    for bad in ("nan", "inf", "-inf"):
        text = ISSUE_BOUNCING_BALL.replace("g = 9.81", f"g = {bad}")
        line = text.splitlines().index(f"g = {bad}") + 1
        with pytest.raises(ModelError, match=rf"<string>:{line}, field `parameters\.g`: "
                                             rf"parameter 'g' must be finite"):
            pwsdyn.load_model(text)
    with pytest.raises(ModelError, match=r"parameter 'g' must have a numeric default"):
        pwsdyn.load_model(_bb_dict(parameters={"g": "9.81", "e": 0.8, "A": 0.0, "omega": 1.0}))


@pytest.mark.parametrize("change, exc, match", [
    (dict(colour="red"), ModelError, r"unknown top-level key\(s\) \['colour'\]"),
    (dict(events=[_bb_event(reset=None)]), ModelError, r"`reset` must be a table"),
    (dict(events=[{k: v for k, v in _bb_event().items() if k != "reset"}]), ModelError,
     r"field `events\[0\]\.reset`: an impact event needs a `reset`"),
    (dict(events=[_bb_event(direction=2)]), ModelError,
     r"field `events\[0\]\.direction`: `direction` must be -1, 0 or 1, got 2"),
    (dict(events=[_bb_event(direction=True)]), ModelError, r"`direction` must be -1, 0 or 1"),
    (dict(events=[_bb_event(direction=1)]), ModelError,
     r"an impact event must have direction -1"),
    (dict(events=[_bb_event(target="nowhere")]), ModelError,
     r"field `events\[0\]\.target`: unknown mode 'nowhere'; modes are \['flight'\]"),
    (dict(events=[_bb_event(modes=["air"])]), ModelError, r"unknown mode 'air'"),
    (dict(events=[_bb_event(kind="bounce")]), ModelError, r"event kind must be one of"),
    (dict(events=[_bb_event(reset={"w": "0"})]), ModelError,
     r"reset of unknown state\(s\) \['w'\]"),
    (dict(events=[_bb_event(guard="v")]), ExpressionError, r"a guard must be a condition"),
    (dict(events=[_bb_event(surface="y < s")]), ExpressionError,
     r"field `events\[0\]\.surface`: construct Compare is not allowed"),
    (dict(modes={"flight": {"y": "v"}}), ModelError, r"no derivative for state\(s\) \['v'\]"),
    (dict(states=["y", "t"]), ModelError, r"invalid state name 't'"),
    (dict(initial_mode="ground"), ModelError, r"field `initial_mode`: unknown mode 'ground'"),
    (dict(forcing_period="2*pi/omega + t"), ExpressionError, r"unknown name 't'"),
    (dict(defaults={"x0": {"y": 1.0, "w": 0.0}, "t_end": 5.0}), ModelError,
     r"`defaults\.x0` names unknown state\(s\) \['w'\]"),
    (dict(defaults={"x0": [1.0], "t_end": 5.0}), ModelError, r"`defaults\.x0` must have 2"),
    (dict(defaults={"x0": [1.0, 0.0], "t_end": -5.0}), ModelError,
     r"`defaults\.t_end` must be a number after t0 = 0\.0, got -5\.0"),
    (dict(defaults={"x0": [1.0, 0.0], "t0": 6.0, "t_end": 5.0}), ModelError,
     r"`defaults\.t_end` must be a number after t0 = 6\.0"),
    (dict(defaults={"x0": [1.0, 0.0], "params": {"G": 1.0}}), ModelError,
     r"`defaults\.params` sets unknown parameter 'G'"),
    (dict(defaults={"x0": [1.0, 0.0], "tend": 1.0}), ModelError,
     r"unknown key\(s\) \['tend'\] in `defaults`"),
])
def test_bad_models_raise_specific_errors(change, exc, match):
    with pytest.raises(exc, match=match):
        pwsdyn.load_model(_bb_dict(**change))


def test_unknown_top_level_key_in_file_names_file_and_line(tmp_path):
    lines = ISSUE_BOUNCING_BALL.splitlines()
    lines.insert(4, 'colour = "red"')  # top level: before the first table header
    path = tmp_path / "ball.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError, match=r"ball\.toml:5, field `colour`: unknown top-level "
                                         r"key\(s\) \['colour'\]"):
        pwsdyn.load_model(path)


# ======================================================================================
# symbolic derivatives against finite differences
# ======================================================================================

def _random_point(m, rng):
    defaults = np.array(list(m.parameters.values()))
    # perturb the parameters so that nothing vanishes by accident (A = 0 in the bouncing ball)
    p = np.where(defaults == 0.0, rng.uniform(0.2, 1.0, defaults.size),
                 defaults * rng.uniform(0.8, 1.2, defaults.size))
    x = rng.uniform(-2.0, 2.0, m.n_states)
    t = rng.uniform(0.0, 10.0)
    return t, x, p


def _evaluator(cm, n):
    out = np.zeros(n * n + 1)

    def ev(which, idx, t, x, p, size):
        out[:] = np.nan
        cm.evaluate(which, idx, float(t), np.ascontiguousarray(x, float), p, out)
        val = out[:size].copy()
        assert np.all(np.isfinite(val)), (which, idx)
        return val
    return ev


def _fd_x(fun, x):
    """Central differences with a state-scaled step; columns are d/dx_j."""
    cols = []
    for j in range(x.size):
        h = 1e-6 * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        cols.append((fun(xp) - fun(xm)) / (xp[j] - xm[j]))
    return np.array(cols).T


def _fd_t(fun, t):
    h = 1e-6 * max(1.0, abs(t))
    return (fun(t + h) - fun(t - h)) / (2 * h)


def _close(fd, exact, scale):
    """Central differences with step h ~ 1e-6 have truncation error ~ h^2 |f'''| ~ 1e-11 and
    round-off ~ eps |f| / h ~ 1e-10 |f|; 1e-7 relative to max(1, |f|, |f'|) leaves two orders of
    margin and still catches any wrong term (which errs by O(1))."""
    tol = 1e-7 * (1.0 + np.abs(exact) + scale)
    assert np.all(np.abs(fd - exact) <= tol), (fd, exact, np.abs(fd - exact) - tol)


# A model whose Jacobians are full and non-symmetric, with time in every quantity (the zoo's
# resets have diagonal Jacobians, so a transposed g_x would pass on them alone).
COUPLED = dict(
    name="coupled-test", states=["a", "b", "c"],
    parameters={"k": 1.3, "w": 2.1, "mu": 0.4},
    definitions={"s": "sin(w*t)"},
    modes={"one": {"a": "b*c + s", "b": "-k*a + mu*b**2*cos(c)", "c": "exp(-a*b)*t - c/3"},
           "two": {"a": "atan2(b, 1 + a**2)", "b": "sqrt(1 + a**2 + c**2)*s",
                   "c": "Max(a, b) + log(2 + c**2)"}},
    events=[dict(name="hit", kind="impact", surface="a - s*b + c**2/4",
                 reset={"b": "-mu*b + a*c*s", "c": "c + k*a*b"}, target="two"),
            dict(name="back", kind="transition", surface="b*t - a", direction=1,
                 modes=["two"], reset={"a": "a*cos(w*t) + b**3"}, target="one")])


@pytest.mark.parametrize("name", ZOO + ["<coupled>"])
def test_compiled_derivatives_match_finite_differences(name):
    m = pwsdyn.load_model(COUPLED if name == "<coupled>" else name)
    cm = pwsdyn.compile_model(m)
    n, nm = m.n_states, len(m.modes)
    ev = _evaluator(cm, n)
    args = (m.t, *m.state_symbols, *m.parameter_symbols)
    # a seed of the name that is the same in every process (str hashes are randomised)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    for _ in range(5):
        t, x, p = _random_point(m, rng)
        for i, mode in enumerate(m.modes):
            f = ev(W_F, i, t, x, p, n)
            # the generated code agrees with SymPy's own evaluation of the expressions
            ref = np.array([float(sp.lambdify(args, e, "math")(t, *x, *p)) for e in mode.rhs])
            np.testing.assert_allclose(f, ref, rtol=1e-13, atol=1e-13)
            fx = ev(W_FX, i, t, x, p, n * n).reshape(n, n)
            _close(_fd_x(lambda z: ev(W_F, i, t, z, p, n), x), fx, np.abs(f).max())
            _close(_fd_t(lambda s: ev(W_F, i, s, x, p, n), t), ev(W_FT, i, t, x, p, n),
                   np.abs(f).max())
        for k, surf in enumerate(m.surfaces):
            h = ev(W_H, k, t, x, p, 1)
            assert h[0] == pytest.approx(float(sp.lambdify(args, surf.expr, "math")(t, *x, *p)),
                                         rel=1e-13, abs=1e-13)
            hx = ev(W_HX, k, t, x, p, n)
            ht = ev(W_HT, k, t, x, p, 1)
            _close(_fd_x(lambda z: ev(W_H, k, t, z, p, 1), x)[0], hx, abs(h[0]))
            _close(_fd_t(lambda s: ev(W_H, k, s, x, p, 1), t), ht, abs(h[0]))
            for i in range(nm):
                f = ev(W_F, i, t, x, p, n)
                hd = ev(W_HD, k * nm + i, t, x, p, 1)
                # hdot is the rate of change of h along the flow: d/ds h(t + s, x + s f)
                along = _fd_t(lambda s: ev(W_H, k, t + s, x + s * f, p, 1), 0.0)
                _close(along, hd, abs(h[0]) + np.abs(f).max())
                _close(_fd_x(lambda z: ev(W_HD, k * nm + i, t, z, p, 1), x)[0],
                       ev(W_HDX, k * nm + i, t, x, p, n), abs(hd[0]))
                _close(_fd_t(lambda s: ev(W_HD, k * nm + i, s, x, p, 1), t),
                       ev(W_HDT, k * nm + i, t, x, p, 1), abs(hd[0]))
        for j, event in enumerate(m.events):
            g = ev(W_G, j, t, x, p, n)
            ref = np.array([float(sp.lambdify(args, e, "math")(t, *x, *p)) for e in event.reset])
            np.testing.assert_allclose(g, ref, rtol=1e-13, atol=1e-13)
            _close(_fd_x(lambda z: ev(W_G, j, t, z, p, n), x),
                   ev(W_GX, j, t, x, p, n * n).reshape(n, n), np.abs(g).max())
            _close(_fd_t(lambda s: ev(W_G, j, s, x, p, n), t), ev(W_GT, j, t, x, p, n),
                   np.abs(g).max())


def test_state_and_parameter_names_cannot_shadow_generated_code(tmp_path, monkeypatch):
    """States and parameters named like the arguments of the generated function (x, p, out,
    t is reserved), its globals (math, numba) or CSE temporaries (_c0) compile and evaluate
    correctly."""
    monkeypatch.setenv("PWSDYN_CACHE_DIR", str(tmp_path))
    spec = dict(name=f"shadow-{uuid.uuid4().hex[:8]}", states=["x", "p", "out", "_c0"],
                parameters={"math": 2.0, "which": 3.0, "idx": 0.5, "numba": 1.5},
                modes={"m": {"x": "p*math", "p": "-x*which + cos(t)", "out": "idx*_c0 + numba",
                             "_c0": "sin(x*p)*sin(x*p) + out"}},
                events=[dict(name="wall", kind="impact", surface="1 - x", reset={"p": "-idx*p"})])
    m = pwsdyn.load_model(spec)
    cm = pwsdyn.compile_model(m)
    x = np.array([0.3, -0.7, 1.1, 0.2])
    p = np.array([2.0, 3.0, 0.5, 1.5])
    out = np.zeros(16)
    cm.evaluate(W_F, 0, 0.4, x, p, out)
    expect = [-0.7 * 2.0, -0.3 * 3.0 + math.cos(0.4), 0.5 * 0.2 + 1.5,
              math.sin(0.3 * -0.7) ** 2 + 1.1]
    np.testing.assert_allclose(out[:4], expect, rtol=1e-15)
    cm.evaluate(W_G, 0, 0.4, x, p, out)
    np.testing.assert_allclose(out[:4], [0.3, 0.35, 1.1, 0.2], rtol=1e-15)


# ======================================================================================
# the compiled module is cached on disk
# ======================================================================================

_COMPILE_SCRIPT = textwrap.dedent("""
    import json, sys
    import pwsdyn
    spec = json.loads(sys.argv[1])
    m = pwsdyn.load_model(spec)
    cm = pwsdyn.compile_model(m)
    print(json.dumps(dict(hash=m.hash, seconds=cm.compile_seconds, path=str(cm.source_path))))
""")


def test_compiled_model_is_cached_across_processes(tmp_path):
    pname = f"q_{uuid.uuid4().hex[:12]}"  # a new parameter name: a hash never seen before
    spec = dict(name="cache-probe", states=["y", "v"], parameters={pname: 2.0, "e": 0.5},
                modes={"air": {"y": "v", "v": f"-{pname}*y - 0.1*v"}},
                events=[dict(name="hit", kind="impact", surface="y", reset={"v": "-e*v"})])
    env = dict(os.environ, PWSDYN_CACHE_DIR=str(tmp_path))
    # numba keeps its index next to the generated module unless told to use another folder
    env.pop("NUMBA_CACHE_DIR", None)

    def run():
        res = subprocess.run([sys.executable, "-c", _COMPILE_SCRIPT, json.dumps(spec)],
                             env=env, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr
        return json.loads(res.stdout.strip().splitlines()[-1])

    first, second = run(), run()
    print(f"\ncompile_seconds: first (new model) {first['seconds']:.3f} s, "
          f"second (fresh process, cached) {second['seconds']:.3f} s")
    assert first["hash"] == second["hash"] == pwsdyn.load_model(spec).hash
    assert first["path"] == second["path"]
    src = Path(first["path"])
    assert src.exists() and src.parent.parent == tmp_path
    assert pname in src.read_text()
    index = list(tmp_path.rglob(f"{src.stem}*.nbi"))
    assert index, f"no numba index for {src.name} under {tmp_path}"
    assert list(tmp_path.rglob(f"{src.stem}*.nbc"))


# ======================================================================================
# the zoo: each default run is admissible and matches closed forms where they exist
# ======================================================================================

def _run_defaults(name, t_end=None):
    m = pwsdyn.load_model(name)
    d = m.spec["defaults"]
    params = d.get("params", {})
    traj = pwsdyn.simulate(m, d["x0"], (0.0, t_end or d["t_end"]), params=params)
    return m, traj, params


def _h_function(m, params, event=0):
    """The event function h(t, x) evaluated by SymPy (not by the generated code)."""
    args = (m.t, *m.state_symbols, *m.parameter_symbols)
    h = sp.lambdify(args, m.surfaces[m.events[event].surface].expr, "numpy")
    p = m.parameter_vector(params)
    return lambda t, x: np.broadcast_to(h(t, *np.asarray(x).T, *p), np.shape(t))


@pytest.mark.parametrize("name", ZOO_IMPACTING)
def test_zoo_default_runs_stay_admissible(name):
    m, traj, params = _run_defaults(name)
    assert traj.success, traj.message
    assert traj.t[-1] == pytest.approx(m.spec["defaults"]["t_end"], rel=1e-14)
    impacts = traj.events_of("impact")
    assert len(impacts) >= 10
    h = _h_function(m, params)
    hn = h(traj.t, traj.x)
    assert hn.min() >= -1e-9, (name, hn.min(), traj.t[np.argmin(hn)])
    # impacts are located on the surface, approaching it
    for e in impacts:
        assert abs(h(e.t, e.x_before)) < 1e-9


def test_impact_oscillator_period_one_orbit_closed_form():
    """Budd & Dux oscillator with eps = 0, sigma = 0: between impacts
    x = a cos(s) + b sin(s) + K sin(omega (t0 + s)), K = 1/(1 - omega^2). The period-1 orbit
    solves x(T) = 0, v(T) = V for the impact phase phi and impact velocity V."""
    m, traj, params = _run_defaults("impact-oscillator")
    w, r = m.parameters["omega"], m.parameters["r"]
    assert m.parameters["eps"] == 0.0 and m.parameters["sigma"] == 0.0
    K, T = 1.0 / (1.0 - w * w), 2 * math.pi / w

    def residual(z):
        phi, V = z
        a, b = -K * math.sin(phi), -r * V - K * w * math.cos(phi)
        x = a * math.cos(T) + b * math.sin(T) + K * math.sin(phi)
        v = -a * math.sin(T) + b * math.cos(T) + K * w * math.cos(phi)
        return [x, v - V]

    last = traj.events[-1]
    (phi, V), *_ = fsolve(residual, [(w * last.t) % (2 * math.pi), last.x_before[1]],
                           xtol=1e-13, full_output=True)
    assert max(abs(f) for f in residual([phi, V])) < 1e-12
    # one impact per forcing period at the end
    times = traj.event_times("impact")
    assert np.all(np.abs(np.diff(times[-10:]) - T) < 1e-6)
    for e in traj.events[-5:]:
        assert e.x_before[1] == pytest.approx(V, rel=1e-6)
        assert e.x_after[1] == pytest.approx(-r * V, rel=1e-6)
        dphi = (w * e.t - phi + math.pi) % (2 * math.pi) - math.pi
        assert abs(dphi) < 1e-6


def test_impact_oscillator_base_period_one_orbit_closed_form():
    """Thesis eq. 3.2: z' = M z + forcing is linear; its periodic particular solution is
    Im(X e^{i w t}) with X = a (k + i d w) / (k - m w^2 + i d w). The period-1 impacting orbit
    starts at (delta, -e V) at t0 and returns to (delta, V) one period later."""
    m, traj, params = _run_defaults("impact-oscillator-base")
    P = m.parameters
    mass, k, d, a, w, delta, e = (P[s] for s in ("m", "k", "d", "a", "omega", "delta", "e"))
    X = a * (k + 1j * d * w) / (k - mass * w * w + 1j * d * w)
    M = np.array([[0.0, 1.0], [-k / mass, -d / mass]])
    T = 2 * math.pi / w
    E = expm(M * T)

    def zp(t):
        return np.array([(X * np.exp(1j * w * t)).imag, (1j * w * X * np.exp(1j * w * t)).imag])

    def residual(z):
        t0, V = z
        end = zp(t0 + T) + E @ (np.array([delta, -e * V]) - zp(t0))
        return [end[0] - delta, end[1] - V]

    last = traj.events[-1]
    (t0, V), *_ = fsolve(residual, [last.t, last.x_before[1]], xtol=1e-13, full_output=True)
    assert max(abs(f) for f in residual([t0, V])) < 1e-12
    times = traj.event_times("impact")
    assert np.all(np.abs(np.diff(times[-8:]) - T) < 1e-6)
    for ev in traj.events[-5:]:
        assert ev.x_before[0] == pytest.approx(delta, abs=1e-12)
        assert ev.x_before[1] == pytest.approx(V, rel=1e-6)
        assert ev.x_after[1] == pytest.approx(-e * V, rel=1e-6)
        dt = (ev.t - t0 + T / 2) % T - T / 2
        assert abs(dt) < 1e-6


def test_bouncing_ball_defaults_reach_period_one_bouncing():
    """Period-1 orbit on a table s = A sin(w t): the flight lasts one period T and is
    symmetric, so the ball hits at -g T / 2 and leaves at +g T / 2; Newton's law then fixes the
    table velocity at impact, A w cos(w t*) = g T (1 - e) / (2 (1 + e))."""
    m, traj, params = _run_defaults("bouncing-ball", t_end=150.0)
    g, e = m.parameters["g"], m.parameters["e"]
    A, w = params["A"], params["omega"]
    T = 2 * math.pi / w
    for ev in traj.events[-5:]:
        assert ev.kind == "impact"
        assert ev.x_before[1] == pytest.approx(-g * T / 2, rel=1e-8)
        assert ev.x_after[1] == pytest.approx(g * T / 2, rel=1e-8)
        assert A * w * math.cos(w * ev.t) == pytest.approx(g * T * (1 - e) / (2 * (1 + e)),
                                                           rel=1e-7)


def test_one_legged_jumper_defaults():
    m, traj, params = _run_defaults("one-legged-jumper")
    P = m.parameters
    w, r, g, A, L = P["omega"], P["r"], P["g"], P["A"], P["L"]
    T = 2 * math.pi / w

    def ground_velocity(t):
        return A * w * (math.cos(w * t) - math.sin(w * t))

    # the leg never inverts: the body stays above the foot
    assert np.min(traj.x[:, 2] - traj.x[:, 0]) > 0.5 * P["d0"]
    # impact law: Newton restitution on the velocity relative to the moving ground; the body
    # and both positions are not changed by the impact
    for ev in traj.events_of("impact"):
        gv = ground_velocity(ev.t)
        assert ev.x_after[1] - gv == pytest.approx(-r * (ev.x_before[1] - gv), rel=1e-12,
                                                   abs=1e-12)
        np.testing.assert_array_equal(ev.x_after[[0, 2, 3]], ev.x_before[[0, 2, 3]])
    # in flight the centre of mass falls freely: (v1 + v2)/2 decreases at rate g
    flight = np.array([s == "flight" for s in traj.state])
    i = np.flatnonzero(flight[:-1] & flight[1:] & (np.diff(traj.t) > 0))
    vcm = 0.5 * (traj.x[:, 1] + traj.x[:, 3])
    np.testing.assert_allclose(vcm[i + 1] - vcm[i], -g * (traj.t[i + 1] - traj.t[i]),
                               rtol=0, atol=1e-9)
    # while stuck, the foot moves with the ground
    stuck = np.array([s.startswith("stick") for s in traj.state])
    assert stuck.any()
    ground = L + A * (np.sin(w * traj.t[stuck]) + np.cos(w * traj.t[stuck]))
    np.testing.assert_allclose(traj.x[stuck, 0], ground, rtol=0, atol=1e-9)
    # periodic hopping: once per forcing period the foot takes off, lands, chatters and sticks
    t_end = traj.t[-1]
    for j in range(3):
        window = [ev.kind for ev in traj.events if t_end - (j + 1) * T <= ev.t < t_end - j * T]
        for kind in ("release", "chatter", "stick"):
            assert window.count(kind) == 1, (j, window)
    s0, s1 = traj(t_end - T - 1e-9), traj(t_end - 2 * T - 1e-9)
    np.testing.assert_allclose(s0, s1, rtol=0, atol=1e-3)


def test_generated_cases_with_the_same_expressions_share_one_body():
    """Cases whose expressions are the same are emitted once, behind one test of ``idx``
    (runs of indices as ranges), and every case still evaluates its own expressions; the
    split variants of a chain repeat most of their derivatives, which is what keeps the
    4-block Burridge-Knopoff chain's code under the generator's limit."""
    from pwsdyn.model.codegen import W_F, W_H, _generate_body, emit_evaluate
    x, a = sp.Symbol("x", real=True), sp.Symbol("a", real=True)
    cases = {(W_F, 0): [a * x], (W_F, 1): [a * x], (W_F, 2): [x + 1], (W_F, 3): [a * x],
             (W_F, 4): [a * x], (W_H, 0): [x]}
    src = emit_evaluate(cases, ("x",), ("a",))
    assert src.count("out[0] = p_a*s_x") == 1, src
    assert "if 0 <= idx <= 1 or 3 <= idx <= 4:" in src and "if idx == 2:" in src
    ns: dict = {}
    # (numba caches only functions of files: the text is compiled here as it is, uncached)
    exec(compile(src.replace("cache=True", "cache=False"), "<generated>", "exec"), ns)
    out = np.zeros(1)
    for idx, want in ((0, 6.0), (1, 6.0), (2, 4.0), (3, 6.0), (4, 6.0)):
        ns["evaluate"].py_func(W_F, idx, 0.0, np.array([3.0]), np.array([2.0]), out)
        assert out[0] == want, idx
    # the chains: a block's normal velocity depends on its own side only
    sizes = [len(_generate_body(pwsdyn.burridge_knopoff(n))) for n in (2, 3, 4)]
    assert sizes[-1] < 100_000 and sizes == sorted(sizes)


@pytest.mark.parametrize("case", ["chain", "relays", "mixed"])
def test_sign_family_is_every_variant(case):
    """The variants of a mode split at its sign() terms are compiled as one field of their
    sides (decoded from the variant's index): every variant's field, Jacobian, normal
    velocities and Utkin family, evaluated by the compiled code, against SymPy's own
    per-variant expressions (lambdified, differentiated independently), and their affine
    matrices (exact propagation) against each variant's own. Only rounding may differ:
    1e-13 relative. ``mixed`` has a Max kink, a Heaviside factor that never masks
    a non-finite term, an Abs and two sign terms on one surface."""
    from pwsdyn.model.codegen import W_FU, W_HDU, W_HDUD, compile_model
    from pwsdyn.model.discontinuities import U_SYMBOL
    if case == "chain":
        m = pwsdyn.burridge_knopoff(3, Fs=[1.0, 1.3, 0.8], Fd=[0.5, 0.7, 0.4])
    elif case == "relays":
        # affine variants: their exact-propagation matrices come from the family's too
        m = pwsdyn.load_model({
            "name": "family-relays", "states": ["x", "y", "z"], "parameters": {"a": 0.7},
            "modes": {"m": {"x": "y - sign(x)", "y": "-a*x - 2*sign(y) + sin(3*t)",
                            "z": "x + Abs(y) - Heaviside(z)"}}})
    else:
        m = pwsdyn.load_model({
            "name": "family-mixed", "states": ["x", "v", "y"],
            "parameters": {"a": 1.3, "b": 0.4},
            "modes": {"m": {"x": "v + b*Max(0, y - x)",
                            "v": "-a*x - b*sign(v)*(1 + Abs(v)) + Heaviside(y)",
                            "y": "-y + sign(v)*x - sign(x + y)"}}})
    assert len(m.families) == 1
    fam = m.families[0]
    assert fam.size == len(m.modes)
    cm = compile_model(m)
    src = cm.source_path.read_text()
    # one body per quantity for all the variants (field, Jacobian, f_t, the normal velocity
    # of each surface with its gradient, rate and (h, hdot) pair, ...), none per variant
    assert src.count("            _v = idx - ") >= 3 + 4 * len(m.surfaces)
    fields = src.split("    if which == 0:\n")[1].split("    if which == 1:")[0]
    assert fields.count("        if ") == 1, fields
    X = sp.Matrix(m.state_symbols)
    syms = [m.t, *m.state_symbols, *[sp.Symbol(q, real=True) for q in m.parameters]]
    rng = np.random.default_rng(7)
    n, nm = m.n_states, len(m.modes)
    out = np.zeros(n * n + 1)

    def ev(which, idx, t, x, p, size, u=None):
        out[:] = np.nan
        if u is not None:
            out[0] = u
        cm.evaluate(which, idx, t, x, p, out)
        return out[:size].copy()

    def close(got, want):
        want = np.asarray(want, float).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * (1 + np.abs(want).max()))

    # the affine matrices (exact propagation) of every variant, against the variant's own
    from pwsdyn.model.affine import affine_structure
    from pwsdyn.model.codegen import W_AFFINE
    aff = affine_structure(m)
    p0 = m.parameter_vector(None)
    nz = int(ev(W_AFFINE, -1, 0.0, np.zeros(n), p0, 1)[0])
    assert nz == (aff.dimension if aff.any else 0)
    out = np.zeros(max(n * n, nz * nz) + 1)
    subs = dict(zip(m.parameter_symbols, p0))
    for i, M in enumerate(aff.matrices):
        got = ev(W_AFFINE, i, 0.0, np.zeros(n), p0, 1 + nz * nz)
        if M is None:
            assert got[0] == 0.0, i
        else:
            assert got[0] == 1.0, i
            close(got[1:], np.array(M.xreplace(subs), dtype=float))
    for _ in range(5):
        t, x, p = _random_point(m, rng)
        vals = [t, *x, *p]
        for i, mode in enumerate(m.modes):
            f = sp.Matrix(mode.rhs)
            close(ev(W_F, i, t, x, p, n), sp.lambdify(syms, f)(*vals))
            close(ev(W_FX, i, t, x, p, n * n), sp.lambdify(syms, f.jacobian(X))(*vals))
            for k, surf in enumerate(m.surfaces):
                h = surf.expr
                hd = sp.diff(h, m.t) + (sp.Matrix([h]).jacobian(X) * f)[0]
                close(ev(W_HD, k * nm + i, t, x, p, 1), [sp.lambdify(syms, hd)(*vals)])
                close(ev(W_HDX, k * nm + i, t, x, p, n),
                      sp.lambdify(syms, sp.Matrix([hd]).jacobian(X))(*vals))
        for s, sw in enumerate(m.switches):
            if sw.kind != "filippov":
                continue
            fu = sp.Matrix(sw.family)
            h = m.surfaces[sw.surface].expr
            hdu = sp.diff(h, m.t) + (sp.Matrix([h]).jacobian(X) * fu)[0]
            for u in (-1.0, -0.3, 0.6, 1.0):
                close(ev(W_FU, s, t, x, p, n, u), sp.lambdify([*syms, U_SYMBOL], fu)(*vals, u))
                close(ev(W_HDU, s, t, x, p, 1, u),
                      [sp.lambdify([*syms, U_SYMBOL], hdu)(*vals, u)])
                close(ev(W_HDUD, s, t, x, p, 1, u),
                      [sp.lambdify([*syms, U_SYMBOL], sp.diff(hdu, U_SYMBOL))(*vals, u)])


def test_sign_family_code_grows_linearly_and_falls_back_where_a_side_masks_a_term():
    """A chain's code grows by about one block's worth per block (the 4-block chain needed
    77 247 characters as 16 variants), and a mode whose variant drops a term that may not be
    finite (``Heaviside(-x)*sqrt(-x)``: the family would compute ``0 * NaN``) keeps its
    per-variant code, and runs."""
    from pwsdyn.model.codegen import _generate_body
    sizes = [len(_generate_body(pwsdyn.burridge_knopoff(n))) for n in (1, 2, 3, 4)]
    steps = np.diff(sizes)
    assert sizes[-1] < 20_000 and steps.max() < 1.5 * steps.min(), sizes
    m = pwsdyn.load_model({"name": "masked", "states": ["x", "v"], "parameters": {"k": 1.0},
                           "modes": {"m": {"x": "v",
                                           "v": "k*Heaviside(-x)*sqrt(-x) - 0.1*sign(v)"}}})
    assert m.families == () and len(m.modes) == 4
    traj = pwsdyn.simulate(m, [0.5, 0.0], (0.0, 5.0))
    assert np.all(np.isfinite(traj.x)) and traj.t[-1] == 5.0
