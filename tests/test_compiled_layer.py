"""The compiled-model layer (``pwsdyn.integrate.compiled``): the one door into the kernel.

Claims checked here:

* its run entry point gives what :func:`pwsdyn.simulate` gives, bit for bit (end time and
  state, discrete state, every event column), on an impact, a Filippov sliding and a dry
  friction model: ``simulate`` is built on it;
* its named point evaluations are the derivatives they name (central differences, relative
  error ~1e-9 for steps ~1e-5 of smooth functions of order one) and its normal velocity is
  ``h_t + h_x f`` to rounding;
* its saltation matrix is the one the kernel applies (to 1e-12) and the jump of the flow's
  Jacobian across an impact (central differences of the flow, 1e-6);
* its stop conditions stop where they say (the n-th event of a name or kind, a time);
* nothing above the layer reaches the kernel another way.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import pwsdyn
from pwsdyn.errors import ArgumentError, Status
from pwsdyn.integrate.compiled import AfterEvents, AtTime, KernelState, ModelContext, RunResult
from pwsdyn.integrate.options import integrator_options

SRC = Path(pwsdyn.__file__).resolve().parent

#: (model, x0, t_end): an impact, a Filippov sliding, a dry-friction (sliding) model
CASES = [("impact-oscillator", (-0.5, 0.0), 40.0),
         ("relay-feedback", (0.0, -0.001, -0.02), 12.0),
         ("stick-slip-oscillator", (0.0, 0.0), 40.0),
         ("friction-impact-oscillator", (0.0, 0.0), 30.0)]


def _central(fn, x, h=1e-6):
    """Central differences of ``fn`` (array-valued) at ``x``, one column per entry."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((np.atleast_1d(fn(x + e)) - np.atleast_1d(fn(x - e))) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("name, x0, t_end", CASES)
def test_the_lean_run_is_what_simulate_gives(name, x0, t_end):
    ctx = ModelContext(name)
    opts = integrator_options({}, "test")
    res = ctx.run(np.array(x0), None, 0.0, t_end, opts)
    traj = pwsdyn.simulate(name, x0, (0.0, t_end))
    assert isinstance(res, RunResult) and res.status == traj.status == Status.SUCCESS
    assert res.n_events == len(traj.events) > 0
    assert res.t == traj.t_final
    np.testing.assert_array_equal(res.x, traj.x_final)
    assert res.final_discrete_state == traj.final_discrete_state
    log = traj.events
    np.testing.assert_array_equal(res.event_t, log.t)
    np.testing.assert_array_equal(res.event_t_after, log.t_after)
    np.testing.assert_array_equal(res.event_kind, log.kind_code)
    np.testing.assert_array_equal(res.event_ref, log.ref)
    np.testing.assert_array_equal(res.event_x_before, log.x_before)
    np.testing.assert_array_equal(res.event_x_after, log.x_after)
    np.testing.assert_array_equal(res.event_state_after, log.state_after)
    assert list(res.event_kinds()) == [e.kind for e in log]
    # and the Trajectory made from the lean result is simulate's
    made = res.trajectory(ctx.model, opts, 0.0, t_end)
    np.testing.assert_array_equal(made.t, traj.t)
    np.testing.assert_array_equal(made.x, traj.x)
    assert list(made.state) == list(traj.state)


def test_variational_run_and_samples_are_simulate_s():
    name, x0, T = "impact-oscillator", np.array([-0.5, 0.0]), 2 * np.pi / 2.5
    ctx = ModelContext(name)
    opts = integrator_options({}, "test")
    res = ctx.run(x0, None, 0.0, 3 * T, opts, variational=True, sample=(0.0, T))
    traj = pwsdyn.simulate(name, x0, (0.0, 3 * T), variational=True)
    np.testing.assert_array_equal(res.jacobian, traj.jacobian)
    assert len(res.transfer_matrices) == len(traj.transfer_matrices)
    for a, b in zip(res.transfer_matrices, traj.transfer_matrices):
        np.testing.assert_array_equal(a, b)
    # samples at 0, T, 2T, 3T on the dense output: the trajectory's own evaluation there
    assert len(res.samples_t) >= 3
    np.testing.assert_allclose(res.samples_x, np.array([traj(t) for t in res.samples_t]),
                               rtol=0, atol=1e-9)


# --------------------------------------------------------------------------------------
# named point evaluations
# --------------------------------------------------------------------------------------

def test_surface_reset_and_normal_velocity_evaluations():
    """``h_x``, ``h_t``, ``g_x``, ``g_t`` against central differences of ``h`` and ``g``;
    ``hdot = h_t + h_x f`` and its gradient, rate and the acceleration along the field."""
    ctx = ModelContext("bouncing-ball", {"A": 0.3, "omega": 5.0})
    j = ctx.event_index("impact")
    k = ctx.surface_of("impact", "impact")
    mode = ctx.model.events[j].modes[0]
    t, x = 0.37, np.array([0.2, -1.3])
    tol = dict(rtol=1e-7, atol=1e-8)
    np.testing.assert_allclose(ctx.h_x(k, t, x), _central(lambda y: ctx.h(k, t, y), x)[0],
                               **tol)
    np.testing.assert_allclose(ctx.h_t(k, t, x),
                               (ctx.h(k, t + 1e-6, x) - ctx.h(k, t - 1e-6, x)) / 2e-6, **tol)
    np.testing.assert_allclose(ctx.g_x(j, t, x), _central(lambda y: ctx.g(j, t, y), x), **tol)
    np.testing.assert_allclose(ctx.g_t(j, t, x),
                               (ctx.g(j, t + 1e-6, x) - ctx.g(j, t - 1e-6, x)) / 2e-6, **tol)
    f = ctx.mode_field(mode, t, x)
    hd = ctx.h_t(k, t, x) + ctx.h_x(k, t, x) @ f
    assert ctx.hdot(k, mode, t, x) == pytest.approx(hd, rel=1e-14, abs=1e-14)
    np.testing.assert_allclose(ctx.hdot_x(k, mode, t, x),
                               _central(lambda y: ctx.hdot(k, mode, t, y), x)[0], **tol)
    np.testing.assert_allclose(ctx.hdot_t(k, mode, t, x),
                               (ctx.hdot(k, mode, t + 1e-6, x)
                                - ctx.hdot(k, mode, t - 1e-6, x)) / 2e-6, **tol)
    # the acceleration: d/ds hdot(t + s, x + s f) at s = 0
    acc = (ctx.hdot(k, mode, t + 1e-6, x + 1e-6 * f)
           - ctx.hdot(k, mode, t - 1e-6, x - 1e-6 * f)) / 2e-6
    np.testing.assert_allclose(ctx.acceleration(k, mode, t, x), acc, **tol)
    np.testing.assert_allclose(ctx.hdot_rate(k, mode, t, x, f), acc, **tol)
    assert ctx.guard(j, t, x) is True
    # the field of a regular discrete state is the mode's
    np.testing.assert_array_equal(ctx.field(t, x, KernelState(0, -1, mode)), f)


def test_sliding_field_is_tangent_to_the_switch():
    """The sliding state's field (the kernel's) keeps ``h`` constant: ``h_t + h_x f = 0``."""
    ctx = ModelContext("relay-feedback")
    j = 0
    k = ctx.model.switches[j].surface
    x = np.array([0.0, 0.3, -0.2])                 # on the surface x1 = 0
    assert ctx.h(k, 0.0, x) == 0.0
    f = ctx.field(0.0, x, ctx.sliding_state(j))
    assert abs(ctx.h_t(k, 0.0, x) + ctx.h_x(k, 0.0, x) @ f) <= 1e-14 * max(1.0, abs(f).max())


def test_saltation_is_the_kernel_s_and_the_jump_of_the_flow_jacobian():
    """Across one impact of the impact oscillator, ``Phi(t1) = Phi_1 S Phi_0``: the layer's
    saltation matrix equals the kernel's (1e-12) and ``Phi_1 S Phi_0`` the central differences
    of the end state in ``x0`` (1e-6; step 1e-7, the impact time moves with ``x0``)."""
    ctx = ModelContext("impact-oscillator")
    opts = integrator_options({}, "test")
    x0 = np.array([-0.5, 0.0])
    first = ctx.run(x0, None, 0.0, 20.0, opts, stop=AfterEvents(1, name="impact"))
    te = first.event_t[0]
    t_end = te + 0.3                               # one impact inside [0, t_end]
    res = ctx.run(x0, None, 0.0, t_end, opts, variational=True)
    assert res.n_events == 1 and res.event_kinds()[0] == "impact"
    Phi0, S_kernel, Phi1 = res.transfer_matrices
    before = KernelState(*res.event_state_before[0])
    after = KernelState(*res.event_state_after[0])
    full, proj = ctx.saltation("impact", "impact", te, res.event_x_before[0],
                               res.event_x_after[0], before, after)
    np.testing.assert_allclose(full, S_kernel, rtol=1e-12, atol=1e-12)
    # the projected form kills the field before the event
    f_in = ctx.field(te, res.event_x_before[0], before)
    np.testing.assert_allclose(proj @ f_in, 0.0, atol=1e-12)

    def end(y):
        return ctx.run(y, None, 0.0, t_end, opts).x

    np.testing.assert_allclose(Phi1 @ full @ Phi0, _central(end, x0, 1e-7), rtol=1e-6,
                               atol=1e-6)


# --------------------------------------------------------------------------------------
# stop conditions
# --------------------------------------------------------------------------------------

def test_stop_after_the_n_th_event_of_a_name_or_kind():
    ctx = ModelContext("friction-impact-oscillator")
    opts = integrator_options({}, "test")
    x0 = np.zeros(2)
    full = ctx.run(x0, None, 0.0, 100.0, opts)
    names = np.array([ctx.model.events[r].name for r in full.event_ref], dtype=object)
    kinds = full.event_kinds()
    for stop, hits in [(AfterEvents(3, name="impact_up"), names == "impact_up"),
                       (AfterEvents(2, kind="transition"), kinds == "transition"),
                       (AfterEvents(5), np.ones(len(kinds), bool))]:
        res = ctx.run(x0, None, 0.0, 100.0, opts, stop=stop)
        i = np.flatnonzero(hits)[stop.n - 1]
        assert res.status == Status.TERMINAL_EVENT
        assert res.n_events == i + 1
        assert res.event_t[-1] == full.event_t[i]
    # a time: the end of the span
    at = ctx.run(x0, None, 0.0, None, opts, stop=AtTime(10.0))
    assert at.status == Status.SUCCESS and at.t == 10.0
    np.testing.assert_array_equal(at.x, ctx.run(x0, None, 0.0, 10.0, opts).x)


def test_stop_codes_are_the_kernel_s_and_checked():
    m = pwsdyn.load_model("friction-impact-oscillator")
    assert AfterEvents(2).code(m) == ((1 << 8) - 1, -1, 2)
    mask, ref, n = AfterEvents(1, name="stop_pos").code(m)
    assert ref == m.event_index("stop_pos") and n == 1
    assert mask == sum(1 << k for k in range(5))   # impact .. release: an event's kinds
    assert AfterEvents(1, kind="impact", name="impact_up").code(m)[0] == 1
    with pytest.raises(ArgumentError, match="impact_sideways"):
        AfterEvents(1, name="impact_sideways").code(m)
    with pytest.raises(ArgumentError):
        AfterEvents(0)
    with pytest.raises(ArgumentError):
        AfterEvents(1, kind="bounce")


# --------------------------------------------------------------------------------------
# one door
# --------------------------------------------------------------------------------------

_PRIVATE = ("pwsdyn.integrate._load", "pwsdyn.integrate._start", "pwsdyn.integrate._codes",
            "pwsdyn.integrate._kernel", "pwsdyn.integrate._variational")


def _private_uses(path: Path):
    """Imports of the kernel's private modules, of ``_simulate_compiled``, and calls of a
    ``._eval`` method, in ``path``."""
    pkg = ".".join(("pwsdyn",) + path.relative_to(SRC).parent.parts)
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            names = {f"{base}.{a.name}" for a in node.names} | {base}
            out |= {n for n in names if n.startswith(_PRIVATE)
                    or n.endswith("._simulate_compiled")}
        elif isinstance(node, ast.Attribute) and node.attr == "_eval":
            if isinstance(node.value, ast.Name) and node.value.id == "ctx":
                out.add("ctx._eval")
    return out


def test_the_analyses_go_through_the_layer():
    bad = {}
    for path in SRC.rglob("*.py"):
        rel = str(path.relative_to(SRC))
        if rel.startswith("integrate/"):
            continue
        uses = _private_uses(path)
        if uses:
            bad[rel] = sorted(uses)
    assert bad == {}


def test_the_extending_guides_example_analysis_is_right():
    """docs/extending.md's example analysis (the first impact and the Jacobian of the state
    there, thesis eq. 2.25) run as printed: its Jacobian against central differences of the
    state at the impact (step 1e-6: truncation ~1e-12, rounding ~1e-10; measured 3e-10)."""
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "extending.md").read_text()
    block = re.search(r"A new analysis is a function.*?```python\n(.*?)```", text, re.S)
    assert block is not None
    ns: dict = {}
    exec(block.group(1), ns)
    impact_return = ns["impact_return"]
    x0 = np.array([-0.5, 0.3])
    t, xb, J = impact_return("impact-oscillator", x0)
    assert 0.0 < t < 2.0 and abs(xb[0]) < 1e-12          # on the wall x = sigma = 0
    h = 1e-6
    fd = np.column_stack([(impact_return("impact-oscillator", x0 + h * e)[1]
                           - impact_return("impact-oscillator", x0 - h * e)[1]) / (2 * h)
                          for e in np.eye(2)])
    np.testing.assert_allclose(J, fd, rtol=0, atol=1e-8)
