"""PeriodicOrbit.from_trajectory checks the recurrence of the run before refining (events issue,
item 7).

The zoo's impact oscillator (Budd & Dux; eps = 0, sigma = 0, r = 0.8) at omega = 3 settles on
a period-2 orbit (one impact per forcing period, two alternating impact velocities; see the
model file). From the model's default run (x0 = (-0.5, 0), t_end = 250) ``from_trajectory``
used to refine the one-forcing-period guess and returned, without a word, the unstable
period-1 orbit near it (multipliers -5.565 and -0.115). Now:

* by default the period is the smallest number of forcing periods after which the run recurs
  (here 2), with a :class:`RecurrenceWarning` saying so;
* an explicit ``periods=1`` is respected (the unstable period-1 orbit is a legitimate thing to
  ask for), with a :class:`RecurrenceWarning` naming the period the run recurs at;
* a settled period-1 run gives exactly the orbit it gave before, without a warning;
* a run that has not settled is refined with the one-period guess as before, with a warning.
"""

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import pwsdyn
from pwsdyn import ArgumentError, PeriodicOrbit, find_periodic_orbit
from pwsdyn.orbits._orbit import Recurrence, RecurrenceWarning

sys.path.insert(0, str(Path(__file__).parent))
from _orbit_cases import IO, io_closed_form  # noqa: E402

OMEGA2 = 3.0                    # period-2 attractor of the zoo model (eps = 0, sigma = 0)
TF2 = 2 * np.pi / OMEGA2
TIGHT = dict(method="DOP853", rtol=1e-12, atol=1e-12)

# the same oscillator in phase-extended autonomous form (theta' = 1, theta reset each forcing
# period): its period is found from the recurrence of events, not of forcing periods
IO_EXTENDED = {
    "name": "impact-oscillator-extended", "states": ["x", "v", "theta"],
    "parameters": dict(eps=0.0, sigma=0.0, omega=OMEGA2, r=0.8),
    "modes": {"free": {"x": "v", "v": "sin(omega*theta) - eps*v - x", "theta": "1"}},
    "events": [
        {"name": "impact", "kind": "impact", "surface": "sigma - x", "reset": {"v": "-r*v"}},
        {"name": "phase", "kind": "transition", "surface": "theta - 2*pi/omega", "direction": 1,
         "reset": {"theta": "theta - 2*pi/omega"}},
    ],
}


@pytest.fixture(scope="module")
def doubled_run():
    """The model's default run at omega = 3 (default integrator options)."""
    return pwsdyn.simulate("impact-oscillator", [-0.5, 0.0], (0.0, 250.0),
                           params={"omega": OMEGA2})


def _old_path(traj, periods=1):
    """What from_trajectory computed before the recurrence check (the guess one forcing period
    before the end, refined by find_periodic_orbit)."""
    Tf = traj.model.forcing_period_value(traj.params)
    t0 = float(traj.t[-1]) - periods * Tf
    return find_periodic_orbit(traj.model, traj(t0, side="right"), params=traj.params,
                               period=periods * Tf, t0=t0, mode=str(traj.state[-1]))


# ======================================================================================
# period-doubled run
# ======================================================================================

def test_period_doubled_run_gives_the_period_2_orbit(doubled_run):
    """Default arguments: the period-2 orbit (2 forcing periods, 2 impacts), stable, with a
    warning that says so. Without damping the monodromy's determinant is r**4 (two impacts,
    divergence-free flow), so the complex pair has modulus r**2 = 0.64 exactly."""
    with pytest.warns(RecurrenceWarning, match="does after 2 .*has period 2"):
        orbit = PeriodicOrbit.from_trajectory(doubled_run)
    assert orbit.converged and orbit.periods == 2
    assert orbit.period == pytest.approx(2 * TF2, rel=1e-14)
    assert [e.kind for e in orbit.events] == ["impact", "impact"]
    assert orbit.stable and np.all(np.abs(orbit.multipliers) < 1)
    np.testing.assert_allclose(np.abs(orbit.multipliers), [0.64, 0.64], rtol=1e-8)
    rec = orbit.recurrence
    assert isinstance(rec, Recurrence) and rec.settled
    assert rec.periods == 2 and rec.used == 2 and rec.requested is None
    assert rec.distances[0] > 0.1 and rec.distances[1] < 1e-9 and all(rec.same_state)
    assert "recur" in rec.message
    # the period-1 orbit it used to return silently is not this one
    assert not np.any(np.isclose(np.abs(orbit.multipliers), 5.565, rtol=1e-3))


def test_period_2_orbit_matches_the_stroboscopic_points_of_a_long_run(doubled_run):
    """Independent check: a long run at rtol = atol = 1e-12 (DOP853), 400 forcing periods from
    the same start, sampled at the orbit's phase, alternates between the orbit's two points
    x(t0) and x(t0 + T_f) to 1e-8 (measured 5e-12); the two points are far apart (period 2,
    not period 1)."""
    with pytest.warns(RecurrenceWarning):
        orbit = PeriodicOrbit.from_trajectory(doubled_run)
    a = orbit.x0
    b = orbit.trajectory(orbit.t0 + TF2, side="right")
    assert np.max(np.abs(a - b)) > 0.1
    long_run = pwsdyn.simulate("impact-oscillator", [-0.5, 0.0], (0.0, 400 * TF2),
                               params={"omega": OMEGA2}, **TIGHT)
    m0 = int(np.ceil((300 * TF2 - orbit.t0) / (2 * TF2)))
    times = orbit.t0 + (2 * m0 + np.arange(40)) * TF2
    assert times[-1] < long_run.t[-1]
    strob = long_run(times, side="right")
    even, odd = strob[0::2], strob[1::2]
    err = min(max(np.max(np.abs(even - a)), np.max(np.abs(odd - b))),
              max(np.max(np.abs(even - b)), np.max(np.abs(odd - a))))
    assert err < 1e-8, err


def test_explicit_period_requests_are_respected(doubled_run):
    """periods=1 asked for explicitly: the (unstable) period-1 orbit, as before, but with a
    warning naming the period the run recurs at. periods=2 or period=2*T_f: the attractor,
    without a warning."""
    with pytest.warns(RecurrenceWarning, match="asked for.*does after 2.*periods=2"):
        p1 = PeriodicOrbit.from_trajectory(doubled_run, periods=1)
    assert p1.converged and p1.periods == 1 and not p1.stable
    np.testing.assert_allclose(np.sort(p1.multipliers.real), [-5.565, -0.115], atol=1e-3)
    assert p1.recurrence.requested == 1 and p1.recurrence.used == 1
    assert p1.recurrence.periods == 2
    old = _old_path(doubled_run)
    np.testing.assert_array_equal(p1.x0, old.x0)
    np.testing.assert_array_equal(p1.multipliers, old.multipliers)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecurrenceWarning)
        p2 = PeriodicOrbit.from_trajectory(doubled_run, periods=2)
        p2b = PeriodicOrbit.from_trajectory(doubled_run, period=2 * TF2)
    assert p2.periods == p2b.periods == 2 and p2.stable
    np.testing.assert_allclose(p2b.multipliers, p2.multipliers, atol=1e-12)
    # refine=False follows the same rule (the period-2 guess closes as it is)
    with pytest.warns(RecurrenceWarning):
        rough = PeriodicOrbit.from_trajectory(doubled_run, refine=False)
    assert rough.periods == 2 and rough.converged


def test_cap_on_the_periods_searched(doubled_run):
    """max_periods=1: the recurrence at 2 is not searched for; the run counts as not settled,
    and the one-period guess is refined with a warning that says so."""
    with pytest.warns(RecurrenceWarning, match="does not recur within 1 forcing period"):
        orbit = PeriodicOrbit.from_trajectory(doubled_run, max_periods=1)
    assert orbit.periods == 1 and not orbit.recurrence.settled
    for bad in (0, -1, 1.5, "2", None):
        with pytest.raises(ArgumentError, match="`max_periods`"):
            PeriodicOrbit.from_trajectory(doubled_run, max_periods=bad)


def test_autonomous_period_2_cycle_from_event_recurrence():
    """The phase-extended form of the same oscillator is autonomous: its period comes from the
    recurrence of events (the last event's post-event state recurs two `phase` transitions
    back, not one). The orbit has period 2 T_f and the forced period-2 orbit's multipliers."""
    tr = pwsdyn.simulate(IO_EXTENDED, [-0.5, 0.0, 0.0], (0.0, 250.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecurrenceWarning)
        orbit = PeriodicOrbit.from_trajectory(tr)
    assert orbit.autonomous and orbit.converged and orbit.periods is None
    assert orbit.period == pytest.approx(2 * TF2, abs=1e-8)
    assert orbit.recurrence.period == pytest.approx(2 * TF2, abs=1e-6)
    assert abs(orbit.trivial_multiplier - 1) < 1e-8
    np.testing.assert_allclose(np.abs(orbit.multipliers), [0.64, 0.64], rtol=1e-6)


# ======================================================================================
# period-1 runs: unchanged
# ======================================================================================

def test_settled_period_1_run_is_unchanged():
    """A run settled on the stable one-impact orbit (damped oscillator of tests/_orbit_cases):
    no warning, one forcing period, and bit for bit the orbit of the old code path; its
    multipliers are the closed form's."""
    T = 2 * np.pi / IO["omega"]
    tr = pwsdyn.simulate("impact-oscillator", [-0.7, 0.0], (0, 80 * T), params=IO)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecurrenceWarning)
        orbit = PeriodicOrbit.from_trajectory(tr)
    old = _old_path(tr)
    assert orbit.period == old.period == T and orbit.periods == 1 and orbit.t0 == old.t0
    np.testing.assert_array_equal(orbit.x0, old.x0)
    np.testing.assert_array_equal(orbit.monodromy, old.monodromy)
    np.testing.assert_array_equal(orbit.multipliers, old.multipliers)
    assert orbit.history == old.history
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers),
                               np.sort_complex(io_closed_form()["stable"]["mu"]), atol=1e-8)
    rec = orbit.recurrence
    assert rec.periods == 1 and rec.used == 1 and rec.message == "" and rec.distances[0] < 1e-9


@pytest.mark.parametrize("name, x0, t_end, params", [
    ("impact-oscillator", [-0.5, 0.0], 250.0, None),              # the zoo's default runs
    ("bouncing-ball", [1.5, 0.0], 60.0, dict(A=0.224, omega=2 * np.pi)),
])
def test_zoo_default_runs_are_period_1_without_warning(name, x0, t_end, params):
    tr = pwsdyn.simulate(name, x0, (0.0, t_end), params=params)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecurrenceWarning)
        orbit = PeriodicOrbit.from_trajectory(tr)
    assert orbit.converged and orbit.periods == 1 and orbit.stable


def test_unsettled_run_is_refined_as_before_with_a_warning():
    """Five forcing periods of a transient: no recurrence within 1e-3, so a warning; the
    one-period guess is refined exactly as before (Newton converges to the stable orbit)."""
    tr = pwsdyn.simulate("impact-oscillator", [-0.7, 0.0], (0, 5 * 2 * np.pi / IO["omega"]),
                         params=IO)
    with pytest.warns(RecurrenceWarning, match="has not settled"):
        orbit = PeriodicOrbit.from_trajectory(tr)
    old = _old_path(tr)
    assert orbit.converged and orbit.periods == 1 and not orbit.recurrence.settled
    np.testing.assert_array_equal(orbit.x0, old.x0)
    np.testing.assert_array_equal(orbit.multipliers, old.multipliers)
