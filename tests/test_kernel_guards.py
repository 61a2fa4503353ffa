"""Guards of the compiled kernel.

1. Non-finite input (time, state, step size, sampling period/phase, a field, surface or reset
   that evaluates to NaN or inf) ends a run with ``Status.NONFINITE``: before, a NaN step size
   was neither accepted nor rejected for good and the kernel spun at 100% CPU, deaf to
   ``max_steps`` and Ctrl-C.
2. No jump moves time past ``t_end``: a complete-chattering jump whose accumulation point lies
   beyond ``t_end`` is not taken; the impacts before ``t_end`` are integrated instead.

Most runs here go through ``_simulate_compiled`` (what ``simulate`` and the sweeps call after
validating their arguments), so the kernel's own guards are tested, not the argument checks
in front of them. Every expected number comes from a closed form, none from pwsdyn.
"""

import importlib
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pwsdyn
from pwsdyn import SolveError, Status
from pwsdyn.errors import PwsdynError
from pwsdyn.integrate.simulate import DEFAULTS, _simulate_compiled
from pwsdyn.model import compile_model, load_model

NAN, INF = math.nan, math.inf
G, E = 9.81, 0.8  # the bouncing ball's defaults (its table, amplitude A, is at rest: A = 0)
BALL = "bouncing-ball"
# the module (pwsdyn.integrate.simulate is also the name of the function it exports)
simulate_module = importlib.import_module("pwsdyn.integrate.simulate")


def _run(model, x, t0, t_end, params=None, p=None, sample=None, **options):
    """A kernel run behind ``simulate``'s argument checks; ``p`` replaces the parameter
    vector (unchecked, so it may hold NaN)."""
    m = load_model(model)
    cm = compile_model(m)
    pv = m.parameter_vector(params) if p is None else np.asarray(p, dtype=float)
    opts = {**DEFAULTS, **options, "throw": False}
    # the option checks in front of the kernel refuse non-finite steps: switched off here
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(simulate_module, "_check_options", lambda o: None)
        return _simulate_compiled(cm, np.asarray(x, dtype=float), t0, t_end, pv, opts,
                                  sample=sample)


def _ball_p(**values):
    m = load_model(BALL)
    p = m.parameter_vector({"A": 0.0}).copy()
    for name, v in values.items():
        p[list(m.parameters).index(name)] = v
    return p


def _assert_within(err, tol):
    """|err| <= tol element-wise, ``tol`` broadcast over the rows of ``err``."""
    err = np.abs(np.asarray(err))
    bad = err > tol
    assert not np.any(bad), f"errors {err[bad]} exceed the tolerance {tol}"


def _model(field, states=("x",), params=None):
    spec = {"name": "nonfinite-probe", "states": list(states),
            "modes": {"m": dict(zip(states, field))}}
    if params:
        spec["parameters"] = params
    return spec


# --------------------------------------------------------------------------------------
# 1. non-finite input: NONFINITE at once, never a hang
# --------------------------------------------------------------------------------------

# Each case looped forever in the kernel before the fix. Run in a child process with a
# timeout (generous: a fresh process may compile the kernel), so a regression fails instead of
# hanging the suite; the status of each case is checked in-process below as well.
_HANG_SCRIPT = textwrap.dedent("""
    import math, sys
    import numpy as np
    import pwsdyn
    from pwsdyn.integrate.simulate import DEFAULTS, _simulate_compiled
    from pwsdyn.model import compile_model, load_model
    case = sys.argv[1]
    nan = math.nan
    if case == "field":    # x' = x/a with a = 0 is NaN at the start: the first step was NaN
        r = pwsdyn.simulate({"name": "div", "states": ["x"], "parameters": {"a": 0.0},
                             "modes": {"m": {"x": "x/a"}}}, {"x": 1.0}, (0, 1), throw=False)
    elif case == "first_step":  # simulate refuses first_step = NaN; the kernel must not rely on it
        import pwsdyn.integrate.simulate  # noqa: F401 -- the module, not the function
        sys.modules["pwsdyn.integrate.simulate"]._check_options = lambda o: None
        m = load_model("bouncing-ball")
        r = _simulate_compiled(compile_model(m), np.array([1.0, 0.0]), 0.0, 1.0,
                               m.parameter_vector(None),
                               {**DEFAULTS, "throw": False, "first_step": nan})
    else:                  # t0 = NaN, as a sweep with phase or period NaN passes it on
        m = load_model("bouncing-ball")
        r = _simulate_compiled(compile_model(m), np.array([1.0, 0.0]), nan, 1.0,
                               m.parameter_vector(None), {**DEFAULTS, "throw": False},
                               sample=(nan, nan))
    print(r.status.name)
""")


@pytest.mark.parametrize("case", ["field", "first_step", "t0"])
def test_nonfinite_input_does_not_hang(case):
    root = os.path.dirname(os.path.dirname(pwsdyn.__file__))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    try:
        res = subprocess.run([sys.executable, "-c", _HANG_SCRIPT, case], env=env,
                             capture_output=True, text=True, timeout=300)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the kernel did not return for non-finite input ({case})")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == "NONFINITE"


@pytest.mark.parametrize("field, x0", [
    ("x/a", 1.0),                       # inf: a = 0 (a constant x/0 is refused at load)
    ("log(x)", 0.0),                    # -inf
    ("sqrt(x)", -1.0),                  # NaN
    ("exp(x) - exp(2*x)", 1000.0),      # inf - inf
    ("log(x) - log(2*x)", 0.0),         # -inf - -inf
    # numba raises ZeroDivisionError for 0.0**-k whatever the error model: the generated code
    # writes 1.0/x**k
    ("x**-2", 0.0),
    ("(x - a)**(-3) + 1", 0.0),
], ids=["div0", "log0", "sqrt-neg", "inf-inf", "log0-log0", "pow-neg", "pow-neg-shift"])
def test_nonfinite_field_at_start(field, x0):
    model = _model([field], params={"a": 0.0} if "a" in field else None)
    traj = _run(model, [x0], 0.0, 1.0)
    assert traj.status is Status.NONFINITE
    assert traj.t[-1] == 0.0 and traj.stats["steps"] == 0
    # and through the public entry point, raised with time and state
    with pytest.raises(SolveError) as err:
        pwsdyn.simulate(model, {"x": x0}, (0, 1))
    assert err.value.status is Status.NONFINITE
    assert err.value.t == 0.0 and "t=0 " in str(err.value)


@pytest.mark.parametrize("what", ["t0", "t_end", "x0", "first_step", "max_step", "sample_t0",
                                  "sample_dt"])
@pytest.mark.parametrize("bad", [NAN, INF, -INF])
def test_nonfinite_run_arguments(what, bad):
    if what == "max_step" and bad != bad:
        pass
    elif what == "max_step":
        pytest.skip("max_step = inf means no limit, -inf is a negative step (simulate refuses "
                    "it; the kernel ends with STEP_TOO_SMALL)")
    if what == "sample_dt" and bad == -INF:
        pytest.skip("a negative sampling period turns sampling off")
    args = dict(model=BALL, x=[1.0, 0.0], t0=0.0, t_end=1.0, p=_ball_p())
    opts = {}
    if what == "max_step":
        # an unforced model: for a forced one simulate replaces a non-finite max_step by a
        # quarter forcing period
        args.update(model=_model(["-x"]), x=[1.0], p=None)
    if what in ("t0", "t_end"):
        args[what] = bad
    elif what == "x0":
        args["x"] = [1.0, bad]
    elif what in ("first_step", "max_step"):
        opts[what] = bad
    else:
        args["sample"] = (bad, 0.25) if what == "sample_t0" else (0.0, bad)
    if what in ("max_step", "first_step"):
        # the Python layer refuses a non-finite step; the kernel must not rely on that
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(simulate_module, "_check_options", lambda o: None)
            traj = _run(**args, **opts)
    else:
        traj = _run(**args, **opts)
    assert traj.status is Status.NONFINITE
    assert traj.stats["steps"] == 0 and traj.stats["events"] == 0


@pytest.mark.parametrize("name", ["rtol", "atol"])
def test_nonfinite_tolerance(name):
    """A NaN tolerance made the error norm, then the step size, NaN."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(simulate_module, "_check_options", lambda o: None)
        traj = _run(BALL, [1.0, 0.0], 0.0, 1.0, p=_ball_p(), **{name: NAN})
    assert traj.status is Status.NONFINITE and traj.stats["steps"] == 0


def test_too_many_samples_end_on_the_step_budget():
    """A sampling period so small that the samples outnumber max_steps (here 5e300 of them)
    ends the run at once instead of sampling practically forever."""
    traj = _run(BALL, [1.0, 0.0], 0.0, 5.0, p=_ball_p(), sample=(0.0, 1e-300))
    assert traj.status is Status.MAX_STEPS and traj.stats["steps"] == 0
    ok = _run(BALL, [1.0, 0.0], 0.0, 5.0, p=_ball_p(), sample=(0.0, 0.5), max_steps=1000)
    assert ok.status is Status.SUCCESS and len(ok.samples[0]) == 11


def test_field_turning_nan_mid_run():
    """x' = -1, z' = sqrt(x) from x = 0.5: the field is NaN past t = 0.5. The run ends there
    with NONFINITE naming the time and the last finite state, z = (2/3) 0.5^1.5."""
    model = _model(["-1", "sqrt(x)"], states=("x", "z"))
    traj = _run(model, [0.5, 0.0], 0.0, 1.0)
    assert traj.status is Status.NONFINITE
    assert traj.t[-1] == pytest.approx(0.5, abs=1e-12)
    assert np.all(np.isfinite(traj.x))
    assert traj.x[-1, 1] == pytest.approx(2.0 / 3.0 * 0.5**1.5, rel=1e-8)
    # step counts stay bounded: each rejection shrinks the step 4x, down to 4 ulp of t
    assert traj.stats["rejected_steps"] < 500
    with pytest.raises(SolveError) as err:
        pwsdyn.simulate(model, {"x": 0.5, "z": 0.0}, (0, 1))
    assert err.value.status is Status.NONFINITE
    assert err.value.t == pytest.approx(0.5, abs=1e-12) and "t=0.49999" in str(err.value)


@pytest.mark.parametrize("name, where", [
    ("g", "field"),      # the field is NaN from the start
    ("A", "surface"),    # only the impact surface y - A sin(omega t) is NaN: before, the
    ("omega", "surface"),  # ball fell through the table silently, status SUCCESS
    ("e", "reset"),      # the reset is NaN: the run ends at the first impact
])
@pytest.mark.parametrize("bad", [NAN, INF])
def test_nonfinite_parameter(name, where, bad):
    traj = _run(BALL, [1.0, 0.0], 0.0, 5.0, p=_ball_p(**{name: bad}))
    assert traj.status is Status.NONFINITE
    if where == "reset":
        assert traj.t[-1] == pytest.approx(math.sqrt(2 / G), rel=1e-12)
    else:
        assert traj.t[-1] == 0.0


def test_max_steps_is_honoured():
    traj = _run(_model(["-1", "sqrt(x)"], states=("x", "z")), [0.5, 0.0], 0.0, 0.4,
                max_steps=7)
    assert traj.status is Status.MAX_STEPS and traj.stats["steps"] == 7


_BAD = st.sampled_from([NAN, INF, -INF])


@st.composite
def _nonfinite_run(draw):
    """Ball runs (or the log(a) x model) with at least one non-finite input."""
    y0 = draw(st.floats(0.1, 2.0))
    t_end = draw(st.floats(0.7, 8.0))  # past the first impact (t1 <= 0.64): e is used there
    kinds = draw(st.sets(st.sampled_from(["t0", "t_end", "y", "v", "first_step", "g", "e", "A",
                                          "omega", "log_param", "sample"]), min_size=1,
                         max_size=3))
    args = dict(model=BALL, x=[y0, 0.0], t0=0.0, t_end=t_end, params=None, p=None,
                sample=None)
    opts = {"method": draw(st.sampled_from(["RK45", "DOP853"]))}
    if "log_param" in kinds:
        # finite parameter, NaN (a < 0) or -inf (a = 0) field: x' = log(a) x
        a = draw(st.one_of(st.just(0.0), st.floats(-1e3, -1e-300)))
        args.update(model=_model(["log(a)*x"], params={"a": 1.0}), x=[1.0], p=[a])
    else:
        opts["exact"] = draw(st.booleans())
    pvals = {}
    for k in sorted(kinds):
        if k in ("t0", "t_end"):
            args[k] = draw(_BAD)
        elif k in ("y", "v"):
            args["x"][0 if k == "y" or len(args["x"]) == 1 else 1] = draw(_BAD)
        elif k == "first_step":
            opts["first_step"] = draw(_BAD)
        elif k == "sample":
            args["sample"] = draw(st.sampled_from([(NAN, 0.5), (0.0, NAN), (0.0, INF),
                                                    (INF, 0.5), (-INF, 0.5)]))
        elif k != "log_param":
            pvals[k] = draw(_BAD)
    if args["p"] is None:
        args["p"] = _ball_p(**pvals)
    return args, opts


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_nonfinite_run())
def test_property_nonfinite_input_ends_nonfinite(case):
    """Whatever non-finite input reaches the kernel, the run returns, with NONFINITE."""
    args, opts = case
    traj = _run(args.pop("model"), **args, **opts)
    assert traj.status is Status.NONFINITE


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(t0=st.one_of(st.just(0.0), _BAD), t_end=st.one_of(st.just(2.0), _BAD),
       y=st.one_of(st.floats(0.1, 2.0), _BAD), first_step=st.one_of(st.none(), _BAD),
       g=st.one_of(st.just(9.81), _BAD))
def test_property_public_entry_point(t0, t_end, y, first_step, g):
    """Through ``simulate``: refused before any work (a pwsdyn or argument error) or ended
    with NONFINITE; never a hang, never SUCCESS with a non-finite input."""
    finite = all(math.isfinite(v) for v in (t0, t_end, y, g)) and (
        first_step is None or math.isfinite(first_step))
    try:
        traj = pwsdyn.simulate(BALL, {"y": y, "v": 0.0}, (t0, t_end), params={"A": 0.0, "g": g},
                               first_step=first_step, throw=False)
    except (PwsdynError, ValueError, TypeError):
        assert not finite
        return
    assert traj.status is (Status.SUCCESS if finite else Status.NONFINITE)


# --------------------------------------------------------------------------------------
# 2. t_end is never passed: the bouncing ball against its closed form
# --------------------------------------------------------------------------------------

class Ball:
    """Ball dropped from rest at height y0 on a static floor (y'' = -g, impact at y = 0 with
    v -> -e v): first impact at t1 = sqrt(2 y0 / g) with speed v1 = g t1, then flights of
    2 e^k v1 / g, accumulating at t1 + 2 e v1 / (g (1 - e)), at rest after that."""

    def __init__(self, y0, rtol=DEFAULTS["rtol"], atol=DEFAULTS["atol"]):
        self.y0 = y0
        self.t1 = math.sqrt(2 * y0 / G)
        self.v1 = G * self.t1
        self.t_acc = self.t1 + 2 * E * self.v1 / (G * (1 - E))
        # impact times and incoming speeds
        self.times, self.speeds = [self.t1], [self.v1]
        while self.speeds[-1] > 1e-300 and len(self.times) < 4000:
            v = E * self.speeds[-1]
            self.times.append(self.times[-1] + 2 * v / G)
            self.speeds.append(v)
        # the kernel's velocity floor (option chatter_velocity's default): a bounce of speed
        # v rises v^2 / 2g; below sqrt(2 g (atol + rtol |x|)) it is not resolved, and the
        # state is taken on the chord to the accumulation state. t_floor: the first impact
        # with a speed below it; floor: the largest such speed
        self.t_floor = math.inf
        self.floor = 0.0
        for t, v in zip(self.times, self.speeds):
            fl = math.sqrt(2 * G * (atol + rtol * v))
            if v <= fl:
                self.t_floor, self.floor = t, fl
                break

    def __call__(self, t):
        if t < self.t1:
            return np.array([self.y0 - 0.5 * G * t * t, -G * t])
        if t >= self.t_acc:
            return np.zeros(2)
        k = np.searchsorted(self.times, t, side="right") - 1
        s = t - self.times[k]
        v = E * self.speeds[k]
        return np.array([v * s - 0.5 * G * s * s, v - G * s])


def _check_ball(ball, traj, t_end):
    """State at t_end and dense output before it against the closed form.

    Tolerance: 1e-8 of the scales y0 and v1. Flights are parabolas, which RK45 integrates
    exactly (zero error estimate), so the error is the round-off of the impact times, about
    ulp(t) each, i.e. g ulp(t) ~ 1e-14 in v, not growing (each impact scales it by e).
    1e-8 leaves room while a missed, extra or misplaced impact, or a jump to the wrong time,
    is far outside it (it changes v by the impact speed, > 1e-8 v1 until the floor regime).
    Past the first impact below the velocity floor the bounces are not resolved by design
    (their rise is below the position tolerance): there v is within 2 floors of the closed
    form (the true v lies in [-v_k, v_k], the kernel's on the chord from -v_k to 0)."""
    assert traj.status is Status.SUCCESS
    assert traj.t[-1] == t_end
    scale = np.array([ball.y0, ball.v1])
    tol = 1e-8 * scale
    if t_end >= ball.t_floor:
        tol = np.maximum(tol, [ball.floor**2 / G + 1e-12, 2.0 * ball.floor])
    _assert_within((traj.x[-1] - ball(t_end)), tol)
    # dense output (left limit at an impact) on a grid up to t_end, away from impacts and
    # before a chattering jump (its gap is drawn as a chord, by design)
    chatter = [ev.t for ev in traj.events_of("chatter")]
    grid = np.linspace(0.0, min([t_end, ball.t_floor] + chatter), 97)
    near = np.min(np.abs(grid[:, None] - np.array(ball.times)[None, :200]), axis=1) < 1e-9
    grid = grid[~near]
    got = traj(grid)
    ref = np.array([ball(t) for t in grid])
    _assert_within((got - ref), 1e-8 * scale)


def test_chatter_jump_beyond_t_end_is_not_taken():
    """The reported cases: the accumulation point (4.0637) lies beyond t_end = 4.0635; with
    chatter_ratio=2 the map applies at the first impact, with t_end = 3."""
    ball = Ball(1.0)
    assert ball.t_acc > 4.0635
    traj = pwsdyn.simulate(BALL, {"y": 1.0, "v": 0.0}, (0, 4.0635), params={"A": 0.0})
    _check_ball(ball, traj, 4.0635)
    assert traj.stats["chatter"] == 0
    traj = pwsdyn.simulate(BALL, {"y": 1.0, "v": 0.0}, (0, 3.0), params={"A": 0.0},
                           chatter_ratio=2)
    _check_ball(ball, traj, 3.0)
    np.testing.assert_allclose(traj(3.0), ball(3.0), rtol=0, atol=1e-8 * ball.v1)
    # the impacts before t_end are all there, at their closed-form times
    impacts = traj.event_times("impact")
    expected = [t for t in ball.times if t <= 3.0]
    np.testing.assert_allclose(impacts, expected, rtol=1e-12)
    # past the accumulation point the jump is still taken, and then the ball rests
    late = pwsdyn.simulate(BALL, {"y": 1.0, "v": 0.0}, (0, 5.0), params={"A": 0.0},
                           chatter_ratio=2)
    assert late.stats["chatter"] == 1 and late.t[-1] == 5.0
    assert late.events_of("chatter")[0].t_after == pytest.approx(ball.t_acc, rel=1e-12)
    _assert_within((late.x[-1]), 1e-12)


@pytest.mark.parametrize("options", [dict(exact=True), dict(method="DOP853"), dict(dense=False)])
def test_chatter_jump_beyond_t_end_other_integrators(options):
    ball = Ball(1.0)
    traj = pwsdyn.simulate(BALL, {"y": 1.0, "v": 0.0}, (0, 3.0), params={"A": 0.0},
                           chatter_ratio=2, **options)
    assert traj.status is Status.SUCCESS and traj.t[-1] == 3.0
    _assert_within((traj.x[-1] - ball(3.0)), 1e-8 * np.array([1.0, ball.v1]))


def test_stroboscopic_samples_not_past_t_end():
    """Samples on the dense output stop at t_end and are the closed-form states (before, the
    samples after the chattering jump's start were the chord of a jump past t_end)."""
    ball = Ball(1.0)
    traj = _run(BALL, [1.0, 0.0], 0.0, 3.0, p=_ball_p(), sample=(0.0, 0.25), chatter_ratio=2)
    assert traj.status is Status.SUCCESS and traj.t[-1] == 3.0
    ts, xs = traj.samples
    np.testing.assert_allclose(ts, np.arange(13) * 0.25, rtol=0, atol=0)
    ref = np.array([ball(t) for t in ts])
    _assert_within((xs - ref), 1e-8 * np.array([1.0, ball.v1]))


def test_end_of_step_is_t_end_exactly():
    """t + (t_end - t) may round past t_end; the last node is t_end exactly."""
    for t_end in (0.3, 0.7, 1.1, 2.9, 1e-3 * 3):
        traj = _run(_model(["-x"]), [1.0], 0.1, t_end + 0.1)
        assert traj.status is Status.SUCCESS and traj.t[-1] == t_end + 0.1
        assert traj.x[-1, 0] == pytest.approx(math.exp(-t_end), rel=1e-9)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(y0=st.floats(0.2, 2.0),
       offset=st.one_of(st.floats(-3.0, 1.0), st.floats(-1e-3, 1e-3),
                        st.integers(-5000, 5000).map(lambda k: k * 1e-15),
                        st.integers(1, 15).map(lambda k: -(10.0 ** -k))),
       ratio=st.one_of(st.sampled_from([1e-4, 0.01, 0.5, 1.0, 2.0]), st.floats(1e-6, 10.0)))
def test_property_t_end_near_accumulation(y0, offset, ratio):
    """t_end before, near and after the accumulation point, any chatter_ratio: the run ends at
    t_end exactly with the closed-form state (see ``_check_ball`` for the tolerance)."""
    ball = Ball(y0)
    t_end = ball.t_acc + offset
    if t_end <= 0.0:
        t_end = 0.5 * ball.t1
    traj = pwsdyn.simulate(BALL, {"y": y0, "v": 0.0}, (0, t_end), params={"A": 0.0},
                           chatter_ratio=ratio)
    _check_ball(ball, traj, t_end)
    if t_end < ball.t_acc:
        assert all(ev.t_after <= t_end for ev in traj.events)


def test_surface_and_jacobian_singular_at_the_start_time():
    """A surface ``atan(1/t)`` is pi/2 at t = 0 and its time derivative has ``t**-2`` terms
    (inf * 0 there): the run goes on (the surface never reaches zero) instead of raising
    ZeroDivisionError out of the kernel (found by the model fuzzer)."""
    model = {"name": "singular-surface", "states": ["x"], "modes": {"m": {"x": "1"}},
             "events": [{"name": "e", "surface": "atan(1/t)", "reset": {"x": "x"}}]}
    traj = pwsdyn.simulate(model, {"x": 0.5}, (0.0, 0.5))
    assert traj.status is Status.SUCCESS and len(traj.events) == 0
    assert abs(traj.x[-1, 0] - 1.0) < 1e-12


def test_map_with_a_negative_power_at_zero_stops_as_nonfinite():
    """The same guard in generated map code: ``x**-2`` at x = 0 is inf, and the iteration
    stops there (NaN afterwards) instead of raising ZeroDivisionError."""
    m = pwsdyn.load_model({"name": "pow-map", "kind": "map", "states": ["x"],
                           "pieces": [{"name": "a", "map": {"x": "x**-2"}}]})
    xs, pieces = pwsdyn.model.iterate(m, {"x": 0.0}, 3)
    assert np.isinf(xs[1, 0]) or np.isnan(xs[1:, 0]).all()
