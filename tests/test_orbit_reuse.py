"""What Newton shooting reuses, and that the reuse changes no bit (issue 22).

``find_periodic_orbit`` reads plain run results in its Newton iterations (end state, end
Jacobian, event columns), builds the orbit from the runs at the converged iterate instead of
integrating it again, and makes the orbit's dense trajectory only when it is read. Each claim
is checked against what the longer way computes: the full assembly of the variational
solution (``assemble_segments``), the orbit's own dense trajectory, the event log's array
columns. Counts of kernel runs, never timings.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import pwsdyn
from pwsdyn.integrate import compiled as C
from pwsdyn.integrate._load import kernel
from pwsdyn.orbits._base import shooting_options
from pwsdyn.orbits._orbit import DeferredTrajectory

from _orbit_cases import IO, closed_form_state, io_closed_form

#: the multi-event orbit of tests/test_orbits_multi.py (sticking, releases, two blocks)
BELT, KC = "two-block-belt", {"kc": 2.0}
BELT_GUESS = ([0.9596, -0.4364, 0.9704, -0.4544], 8.735)


def _guess(which="stable"):
    cf = io_closed_form()[which]
    t0 = cf["t0"] + 0.3 * cf["T"]
    return closed_form_state(cf, IO["sigma"], IO["r"], t0) + np.array([0.01, -0.01]), t0


@pytest.fixture
def kernel_runs(monkeypatch):
    """The number of kernel runs made so far (the kernel module's entry, counted)."""
    K = kernel()
    orig, calls = K.run_kernel, []

    def counting(*args):
        calls.append(1)
        return orig(*args)

    monkeypatch.setattr(K, "run_kernel", counting)
    return calls


def test_the_orbit_is_made_from_the_last_newton_runs(kernel_runs):
    """One run of the guess, one variational run per Newton iterate (the last one at the
    converged state, reused): ``len(history)`` of them; the trajectory's dense runs (one per
    shooting interval) only when it is read, once."""
    x0, t0 = _guess()
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", x0, params=IO, t0=t0)
    assert orbit.converged and len(orbit.nodes) == 1
    assert len(kernel_runs) == 1 + len(orbit.history)
    tr = orbit.trajectory
    assert len(kernel_runs) == 1 + len(orbit.history) + len(orbit.nodes)
    assert orbit.trajectory is tr
    assert len(kernel_runs) == 1 + len(orbit.history) + len(orbit.nodes)


@pytest.mark.parametrize("case", ["impact", "belt"])
def test_the_deferred_trajectory_agrees_with_the_orbit_bit_for_bit(case):
    """The monodromy, events and closure made from the Newton runs are those of the dense
    trajectory read later (the same integration with dense output): equal, not close."""
    if case == "impact":
        x0, t0 = _guess("unstable")
        orbit = pwsdyn.find_periodic_orbit("impact-oscillator", x0, params=IO, t0=t0, nodes=3)
    else:
        x, T = BELT_GUESS
        orbit = pwsdyn.find_periodic_orbit(BELT, x, period=T, params=KC)
    tr = orbit.trajectory
    assert np.array_equal(orbit.monodromy, tr.jacobian)
    assert len(orbit.events) == len(tr.events) > 0
    for a, b in zip(orbit.events, tr.events):
        assert (a.t, a.t_after, a.kind, a.name, a.mode_before, a.mode_after) == \
            (b.t, b.t_after, b.kind, b.name, b.mode_before, b.mode_after)
        assert np.array_equal(a.x_before, b.x_before) and np.array_equal(a.x_after, b.x_after)
    assert orbit.closure <= 1e-9
    assert np.array_equal(tr.x[0], orbit.x0) and tr.t[0] == orbit.t0
    assert tr.t[-1] == orbit.t0 + orbit.period


def test_an_orbit_with_a_deferred_trajectory_copies_with_it():
    """A copy (and a pickle, which goes through the same ``__getstate__``) makes the
    deferred trajectory first: the solver's closure is not copied."""
    x0, t0 = _guess()
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", x0, params=IO, t0=t0)
    assert not isinstance(orbit.__getstate__()["_trajectory"], DeferredTrajectory)
    deep = copy.deepcopy(orbit)
    assert np.array_equal(deep.trajectory.x, orbit.trajectory.x)
    assert np.array_equal(deep.monodromy, orbit.monodromy)
    # an orbit given a trajectory keeps it as given
    orbit.trajectory = None
    assert orbit.trajectory is None


@pytest.mark.parametrize("case", ["impact", "belt", "smooth"])
def test_jacobian_only_runs_give_the_assembled_jacobian_bit_for_bit(case):
    """``run_compiled(jacobian_only=True)`` makes the same products as the full assembly of
    the per-segment variational solution: one, several (sticking, releases) and no events."""
    if case == "belt":
        model, params = pwsdyn.load_model(BELT), KC
        x, t0, t1 = np.array(BELT_GUESS[0]), 0.0, BELT_GUESS[1]
    else:
        model, params = pwsdyn.load_model("impact-oscillator"), IO
        x, t0 = _guess()
        t1 = t0 + (io_closed_form()["stable"]["T"] if case == "impact" else 0.1)
    ctx = C.ModelContext(model, params)
    opts = dict(shooting_options({}), variational=True, dense=False, throw=False)
    full = C.run_compiled(ctx.cm, x, t0, t1, ctx.p, opts)
    lean = C.run_compiled(ctx.cm, x, t0, t1, ctx.p, opts, jacobian_only=True)
    assert (case == "smooth") == (len(full.event_t) == 0)
    assert np.array_equal(full.jacobian, lean.jacobian)
    assert np.array_equal(full.x, lean.x) and np.array_equal(full.event_t, lean.event_t)
    assert np.array_equal(full.event_x_before, lean.event_x_before)
    assert lean.transfer_matrices is None
    # the Jacobian is the product of the full assembly's transfer matrices
    P = np.eye(model.n_states)
    for M in full.transfer_matrices:
        P = M @ P
    np.testing.assert_allclose(lean.jacobian, P, rtol=1e-13, atol=1e-13)   # (order of sums)


def test_event_records_are_the_log_columns():
    """The records made from a kernel log name the kinds and events of its array columns
    (``EventLog.kind``, ``EventLog.name``): impacts and transitions on events, the start
    and end of sliding on switches."""
    checked = set()
    for name, x0, t_end, params in [
            ("two-block-belt", BELT_GUESS[0], 20.0, KC),
            ("stick-slip-oscillator", None, 30.0, None),
            ("relay-feedback", None, 20.0, None),
            ("bouncing-ball", None, 5.0, None),
            ("friction-impact-oscillator", None, 30.0, None)]:
        tr = pwsdyn.simulate(name, x0, t_end, params=params)
        log = tr.events
        kinds, names = list(log.kind), list(log.name)
        assert len(log) > 0
        assert [e.kind for e in log] == kinds and [e.name for e in log] == names
        checked |= set(kinds)
    assert {"impact", "transition", "slide_start", "slide_end"} <= checked
