"""Periodic orbits: Newton shooting, Floquet multipliers, signatures, failures, CLI (issue 4).

Numbers are checked against closed forms (``tests/_orbit_cases.py``: one-impact orbits of the
impact oscillator from the linear flow between impacts; the linear forced oscillator), against
scipy (stick-slip period), and against finite differences of the flow.
"""

import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import pwsdyn
from pwsdyn import OrbitError, PeriodicOrbit, find_periodic_orbit

sys.path.insert(0, str(Path(__file__).parent))
from _orbit_cases import BASE, IO, base_closed_form, io_closed_form, io_orbit  # noqa: E402

# The impact oscillator in phase-extended autonomous form, as COCO's hspo impact demo writes
# it: theta' = 1, the forcing sin(omega theta), and a `phase` transition theta -> theta - T.
IO_EXTENDED = {
    "name": "impact-oscillator-extended", "states": ["x", "v", "theta"],
    "parameters": dict(IO),
    "modes": {"free": {"x": "v", "v": "sin(omega*theta) - eps*v - x", "theta": "1"}},
    "events": [
        {"name": "impact", "kind": "impact", "surface": "sigma - x", "reset": {"v": "-r*v"}},
        {"name": "phase", "kind": "transition", "surface": "theta - 2*pi/omega", "direction": 1,
         "reset": {"theta": "theta - 2*pi/omega"}},
    ],
}

# Van der Pol against a wall: an autonomous impacting limit cycle.
VDP_WALL = {
    "name": "vdp-wall", "states": ["x", "v"],
    "parameters": {"mu": 1.0, "sigma": 1.5, "r": 0.7},
    "modes": {"free": {"x": "v", "v": "mu*(1 - x**2)*v - x"}},
    "events": [{"name": "wall", "kind": "impact", "surface": "sigma - x", "reset": {"v": "-r*v"}}],
}

# Stick-slip on a belt with Coulomb friction and negative viscous damping (energy input while
# slipping), defined inline so the test does not depend on the zoo model's parameters.
BELT = {
    "name": "belt-negative-damping", "states": ["x", "v"],
    "parameters": {"k": 1.0, "c": -0.1, "mu": 1.0, "vb": 0.5},
    "modes": {"above": {"x": "v", "v": "-k*x - c*v - mu"},
              "below": {"x": "v", "v": "-k*x - c*v + mu"}},
    "switches": [{"name": "slip", "surface": "v - vb", "above": "above", "below": "below"}],
}


def _phase_mod(t, T):
    """Distance of t from 0 modulo T."""
    d = np.mod(t, T)
    return min(d, T - d)


# ======================================================================================
# closed forms
# ======================================================================================

@pytest.mark.parametrize("model", ["impact-oscillator", "impact-oscillator-base"])
@pytest.mark.parametrize("which", ["stable", "unstable"])
def test_impact_oscillator_one_impact_orbits_match_closed_form(which, model):
    """Impact phase and velocity to 1e-8, multipliers to 1e-6 (measured: ~4e-13, ~1e-10),
    for the Budd & Dux oscillator and the base-excited one of thesis eq. 3.2."""
    if model == "impact-oscillator":
        cf, r, omega = io_closed_form()[which], IO["r"], IO["omega"]
    else:
        cf, r, omega = base_closed_form()[which], BASE["e"], BASE["omega"]
    assert cf["admissible"]
    orbit = io_orbit(which, model)
    T = 2 * np.pi / omega
    assert orbit.converged and orbit.period == pytest.approx(T, rel=1e-15)
    assert [e.kind for e in orbit.events] == ["impact"]
    ev = orbit.events[0]
    assert _phase_mod(ev.t - cf["t0"], T) < 1e-8
    assert abs(ev.x_before[1] - cf["v"]) < 1e-8
    assert abs(ev.x_after[1] + r * cf["v"]) < 1e-8
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers), np.sort_complex(cf["mu"]),
                               rtol=0, atol=1e-6)
    assert orbit.stable == (which == "stable")
    assert orbit.closure < 1e-9


def test_unstable_orbit_is_not_reached_by_simulation():
    """The saddle (multiplier 2.95) is left by direct simulation: started 1e-7 from it, the
    motion drifts away within 25 periods (to the stable orbit), while Newton found it from
    a guess 1e-2 away; single and multiple shooting agree."""
    orbit = io_orbit("unstable")
    T = orbit.period
    tr = pwsdyn.simulate("impact-oscillator", orbit.x0 + np.array([1e-7, 0.0]),
                         (orbit.t0, orbit.t0 + 60 * T), params=IO, dense=False)
    v = np.array([e.x_before[1] for e in tr.events_of("impact")])
    assert abs(v[24] - io_closed_form()["unstable"]["v"]) > 1e-2
    assert abs(v[-1] - io_closed_form()["stable"]["v"]) < 1e-3
    multi = find_periodic_orbit("impact-oscillator", orbit.x0 + 0.01, params=IO, t0=orbit.t0,
                                nodes=3)
    assert len(multi.nodes) == 3
    assert np.max(np.abs(multi.x0 - orbit.x0)) < 1e-9
    np.testing.assert_allclose(multi.multipliers, orbit.multipliers, atol=1e-8)


def test_linear_forced_oscillator_multipliers_are_exp_lambda_T():
    """Without impacts (wall far away) the orbit is the forced response of the linear
    oscillator, whose multipliers are exp(lambda_i T), lambda = -eps/2 +- i sqrt(1 - eps^2/4),
    to 1e-10."""
    p = dict(IO, sigma=5.0)
    orbit = find_periodic_orbit("impact-oscillator", [0.3, 0.0], params=p)
    assert orbit.events == []
    lam = np.array([-0.05 + 1j * np.sqrt(1 - 0.05**2), -0.05 - 1j * np.sqrt(1 - 0.05**2)])
    expected = np.exp(lam * orbit.period)
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers), np.sort_complex(expected),
                               rtol=0, atol=1e-10)
    np.testing.assert_allclose(orbit.monodromy,
                               expm(np.array([[0.0, 1.0], [-1.0, -0.1]]) * orbit.period),
                               atol=1e-10)


# ======================================================================================
# autonomous orbits: trivial multiplier, phase condition, Poincaré projection
# ======================================================================================

@pytest.mark.parametrize("which", ["stable", "unstable"])
def test_phase_extended_impact_oscillator(which):
    """The autonomous, phase-extended impact oscillator (COCO's hspo formulation): Newton on
    (x, T) with a phase condition from a guess 1% off in period; the full monodromy has the
    trivial multiplier 1 (to 1e-8), the projected Poincaré Jacobian (eq. 2.25) 0 in its place,
    and the nontrivial multipliers are the forced orbit's closed-form ones (1e-6)."""
    cf = io_closed_form()[which]
    T = cf["T"]
    x0 = [IO["sigma"] - 0.01, -IO["r"] * cf["v"] + 0.02, cf["t0"] + 0.01]
    orbit = find_periodic_orbit(IO_EXTENDED, x0, period=1.01 * T)
    assert orbit.autonomous and orbit.converged
    assert abs(orbit.period - T) < 1e-10
    assert sorted(e.name for e in orbit.events) == ["impact", "phase"]
    assert abs(orbit.trivial_multiplier - 1) < 1e-8
    ev = np.linalg.eigvals(orbit.poincare_jacobian)
    ev = ev[np.argsort(np.abs(ev))]
    assert abs(ev[0]) < 1e-8
    np.testing.assert_allclose(np.sort_complex(ev[1:]), np.sort_complex(orbit.multipliers),
                               atol=1e-10)
    np.testing.assert_allclose(np.sort_complex(orbit.multipliers), np.sort_complex(cf["mu"]),
                               atol=1e-6)
    # the eigenvector of the trivial multiplier is the vector field at x0
    f0 = np.array([orbit.x0[1], np.sin(IO["omega"] * orbit.x0[2]) - 0.1 * orbit.x0[1]
                   - orbit.x0[0], 1.0])
    np.testing.assert_allclose(orbit.monodromy @ f0, f0, atol=1e-8)


def test_vdp_wall_trivial_multiplier_and_fd_monodromy():
    """A nonlinear autonomous impacting cycle: trivial multiplier 1 to 1e-8 (measured ~2e-11);
    the monodromy agrees with central differences of the scipy flow over one period."""
    from _hybrid_reference import central_fd, impacting_flow, rel_err

    tr = pwsdyn.simulate(VDP_WALL, [0.1, 0.0], (0, 60))
    orbit = PeriodicOrbit.from_trajectory(tr)
    assert orbit.autonomous and orbit.converged
    assert abs(orbit.trivial_multiplier - 1) < 1e-8
    assert len(orbit.multipliers) == 1
    assert abs(np.linalg.det(orbit.poincare_jacobian)) < 1e-10

    def flow(x):
        return impacting_flow(lambda t, y: [y[1], (1 - y[0] ** 2) * y[1] - y[0]],
                              lambda t, y: 1.5 - y[0], lambda t, y: np.array([y[0], -0.7 * y[1]]),
                              x, 0.0, orbit.period)[0]

    assert rel_err(orbit.monodromy, central_fd(flow, orbit.x0, 1e-5)) < 1e-6


def test_newton_converges_quadratically_from_a_short_simulation():
    """Guesses off short simulations (5 forcing periods; 25 time units of an autonomous
    cycle): the residuals fall quadratically, log(r_{k+1}) / log(r_k) ~ 2 (between 1.6 and
    3 while above the round-off floor 1e-12; measured e.g. 1.71, 3.1, 1.94)."""
    tr = pwsdyn.simulate("impact-oscillator", [-0.7, 0.0], (0, 5 * 2 * np.pi / IO["omega"]),
                         params=IO)
    forced = PeriodicOrbit.from_trajectory(tr)
    tr = pwsdyn.simulate(VDP_WALL, [0.1, 0.0], (0, 25))
    autonomous = find_periodic_orbit(VDP_WALL, tr.x_final, period=4.9, t0=tr.t_final)
    for orbit in (forced, autonomous):
        r = np.array(orbit.history)
        assert orbit.converged and r[-1] <= 1e-10
        assert r[0] > 1e-4, "the guess must be rough enough to show the convergence"
        ratios = [np.log(r[k + 1]) / np.log(r[k]) for k in range(len(r) - 1)
                  if r[k] < 0.1 and r[k + 1] > 1e-12]
        assert ratios, r
        assert all(1.6 < q < 3.5 for q in ratios), (r, ratios)


# ======================================================================================
# the seeds' pieces: jumper gait, stick-slip
# ======================================================================================

def test_one_legged_jumper_hopping_gait():
    """The jumper's period-1 gait (slides: one-legged jumper): landing, a chattering sequence
    ending in the complete-chattering map, sticking, release. Sticking removes two directions,
    so two multipliers are 0; the other two agree with central differences of pwsdyn's own
    stroboscopic map (1e-6) and are inside the unit circle."""
    m = pwsdyn.load_model("one-legged-jumper")
    Tf = 2 * np.pi / m.parameters["omega"]
    tr = pwsdyn.simulate(m, [1.5, 0, 10.5, 0], (0, 60 * Tf))
    orbit = PeriodicOrbit.from_trajectory(tr)
    assert orbit.converged and orbit.period == pytest.approx(Tf, rel=1e-15)
    kinds = [e.kind for e in orbit.events]
    assert kinds.count("chatter") == 1 and kinds.count("stick") == 1
    assert kinds.count("release") == 1 and kinds.count("impact") >= 5
    mu = orbit.multipliers
    assert np.all(np.abs(mu[2:]) < 1e-6) and np.all(np.abs(mu[:2]) > 0.1)
    assert orbit.stable
    opts = dict(method="DOP853", rtol=1e-12, atol=1e-12, dense=False, mode=orbit.state0)

    def strob(x):
        return pwsdyn.simulate(m, x, (orbit.t0, orbit.t0 + Tf), **opts).x_final

    x0 = orbit.x0
    J = np.column_stack([(strob(x0 + h * e) - strob(x0 - h * e)) / (2 * h)
                         for e, h in zip(np.eye(4), [1e-6] * 4)])
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(J))[[0, 1]],
                               np.sort_complex(mu[:2]), atol=1e-6)


def test_stick_slip_orbit_zero_multiplier_and_period():
    """Stick-slip on a belt (inline model): sliding (sticking to the belt) from the entry point
    to x = (mu - c vb)/k, where the below field's normal velocity vanishes, then a slip arc.
    The period from scipy (slip arc integrated to v = vb, plus the sticking time at speed
    vb) to 1e-8; the sliding segment makes the nontrivial multiplier 0 (to 1e-8), the trivial
    one is 1 (to 1e-8)."""
    tr = pwsdyn.simulate(BELT, [0.0, 0.0], (0, 100))
    orbit = PeriodicOrbit.from_trajectory(tr)
    assert [e.kind for e in orbit.events] == ["slide_start", "slide_end"]
    p = BELT["parameters"]
    x_exit = (p["mu"] - p["c"] * p["vb"]) / p["k"]

    def back(t, y):
        return y[1] - p["vb"]
    back.terminal, back.direction = True, 1
    sol = solve_ivp(lambda t, y: [y[1], -p["k"] * y[0] - p["c"] * y[1] + p["mu"]], (0, 50),
                    [x_exit, p["vb"] - 1e-14], method="DOP853", rtol=1e-13, atol=1e-13,
                    events=[back])
    t_slip, x_entry = sol.t_events[0][0], sol.y_events[0][0][0]
    period = t_slip + (x_exit - x_entry) / p["vb"]
    assert abs(orbit.period - period) < 1e-8
    assert abs(orbit.multipliers[0]) < 1e-8
    assert abs(orbit.trivial_multiplier - 1) < 1e-8


def test_zoo_stick_slip_oscillator():
    """The zoo's stick-slip oscillator (Filippov, velocity-weakening friction): its cycle has
    the zero multiplier of sliding and the trivial 1; period as documented in the model file
    (12.0010, checked there by simulation)."""
    if "stick-slip-oscillator" not in pwsdyn.zoo_names():
        pytest.skip("zoo model not available")
    tr = pwsdyn.simulate("stick-slip-oscillator", [0.0, 0.0], (0, 40))
    orbit = PeriodicOrbit.from_trajectory(tr)
    assert {"slide_start", "slide_end"} <= {e.kind for e in orbit.events}
    assert abs(orbit.period - 12.0010) < 1e-4
    assert abs(orbit.multipliers[0]) < 1e-8
    assert abs(orbit.trivial_multiplier - 1) < 1e-8


# ======================================================================================
# bad input: clear errors, never a hang or a wrong orbit reported as converged
# ======================================================================================

def test_guess_near_no_orbit():
    """A damped linear oscillator has no periodic orbit: Newton must fail, with the reason and
    the last (unconverged) iterate."""
    damped = {"name": "damped", "states": ["x", "v"], "parameters": {"c": 0.2},
              "modes": {"m": {"x": "v", "v": "-x - c*v"}}}
    with pytest.raises(OrbitError) as info:
        find_periodic_orbit(damped, [1.0, 0.0], period=6.0, max_iter=20)
    err = info.value
    # the only solution of the shooting equations here is the rest point x = 0 (it lies on
    # the phase-condition hyperplane through the guess): never reported as an orbit
    assert err.reason in ("equilibrium", "diverged", "no_progress", "budget", "singular")
    assert err.result is None or err.result.converged is False
    # a guess off the rest point's hyperplane: no solution at all
    with pytest.raises(OrbitError) as info:
        find_periodic_orbit(damped, [1.0, 0.5], period=6.0, max_iter=20,
                            phase=[1.0, 1.0])
    assert info.value.reason in ("diverged", "no_progress", "budget", "singular")
    assert info.value.history[-1] > 1e-6


def test_singular_phase_condition():
    with pytest.raises(OrbitError, match="singular phase condition") as info:
        find_periodic_orbit(VDP_WALL, [0.0, 0.0], period=5.0)       # an equilibrium
    assert info.value.reason == "phase"
    # a phase-condition normal orthogonal to the flow at the guess
    x0 = np.array([0.5, 1.0])
    f0 = np.array([1.0, (1 - 0.25) * 1.0 - 0.5])
    with pytest.raises(OrbitError, match="tangent to the flow"):
        find_periodic_orbit(VDP_WALL, x0, period=5.0, phase=[-f0[1], f0[0]])


def test_budget_and_argument_errors():
    with pytest.raises(OrbitError) as info:
        find_periodic_orbit("impact-oscillator", [-0.7, 0.0], params=IO, max_iter=1)
    assert info.value.reason == "budget" and len(info.value.history) == 2
    assert info.value.result is not None and not info.value.result.converged
    with pytest.raises(ValueError, match="multiple of its forcing period"):
        find_periodic_orbit("impact-oscillator", [-0.7, 0.0], params=IO, period=1.0)
    with pytest.raises(ValueError, match="give a guess of the period"):
        find_periodic_orbit(VDP_WALL, [0.1, 1.0])
    with pytest.raises(TypeError, match="variational"):
        find_periodic_orbit("impact-oscillator", [-0.7, 0.0], variational=True)
    with pytest.raises(TypeError, match="unexpected"):
        find_periodic_orbit("impact-oscillator", [-0.7, 0.0], rtoll=1e-3)


def test_change_of_signature():
    """Wall at sigma = 0.15 just above the linear response (amplitude 0.146): from a guess
    that impacts, Newton reaches the non-impacting orbit -- allowed while the residual is
    large -- but with the signature locked at once (lock_tol = 1) every step toward it changes
    the event sequence, and that is the error."""
    p = dict(IO, sigma=0.15)
    orbit = find_periodic_orbit("impact-oscillator", [0.0, 0.6], params=p)
    assert orbit.converged and orbit.events == []
    assert np.max(orbit.trajectory.x[:, 0]) < 0.15
    with pytest.raises(OrbitError, match="event sequence") as info:
        find_periodic_orbit("impact-oscillator", [0.0, 0.6], params=p, lock_tol=1.0)
    assert info.value.reason == "signature"
    assert "impact:impact" in str(info.value)


def test_singular_newton_matrix():
    """The undamped oscillator forced at resonance with its natural period: every solution
    has the monodromy I (all multipliers 1), so M - I is singular -- an error, not a step."""
    with pytest.raises(OrbitError, match="singular Newton matrix") as info:
        find_periodic_orbit("impact-oscillator", [0.0, 0.0], params=dict(eps=0.0, omega=1.0,
                                                                           sigma=100.0))
    assert info.value.reason == "singular"


def test_simulation_failure_is_reported():
    """A guess that blows up in finite time: a 'simulation' error naming the interval."""
    blowup = {"name": "blowup", "states": ["x"], "modes": {"m": {"x": "x**2"}}}
    with pytest.raises(OrbitError) as info:
        find_periodic_orbit(blowup, [1.0], period=2.0)
    assert info.value.reason == "simulation"


# ======================================================================================
# the result object, files, CLI
# ======================================================================================

def test_periodic_orbit_result_and_file(tmp_path):
    orbit = io_orbit("stable")
    tr = orbit.trajectory
    assert tr.t[0] == orbit.t0 and abs(tr.t[-1] - (orbit.t0 + orbit.period)) < 1e-12
    assert [e.t for e in orbit.events] == [e.t for e in tr.events]
    assert orbit.signature == (("impact", "impact", "free", "free"),)
    prod = np.linalg.multi_dot(orbit.transfer_matrices[::-1])
    np.testing.assert_allclose(prod, orbit.monodromy, atol=1e-14)
    assert "stable" in repr(orbit) and "period" in orbit.summary()
    path = orbit.save(tmp_path / "orbit.nc")
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["pwsdyn_type"] == "periodic_orbit"
        assert ds.attrs["period"] == orbit.period
        mult = ds["multiplier_real"].values + 1j * ds["multiplier_imag"].values
        np.testing.assert_array_equal(mult, orbit.multipliers)
        np.testing.assert_array_equal(ds["monodromy"].values, orbit.monodromy)


def test_cli_orbit(tmp_path):
    runner = CliRunner()
    out, png = tmp_path / "o.nc", tmp_path / "o.png"
    res = runner.invoke(_cli_main(),
                        ["orbit", "impact-oscillator", "-p", "eps=0.1", "-p", "sigma=-0.5",
                         "-p", "omega=2.8", "--x0", "-0.7,0", "--out", str(out), "--plot",
                         str(png)])
    assert res.exit_code == 0, res.output
    assert "period      2.24399475256414" in res.output
    assert "2.95062336" in res.output and "unstable" in res.output
    assert out.exists() and png.exists() and png.stat().st_size > 10_000
    res = runner.invoke(_cli_main(), ["orbit", "impact-oscillator", "--period", "1.0"])
    assert res.exit_code == 1 and "Error:" in res.output


def _cli_main():
    from pwsdyn.cli import main

    return main


def test_from_trajectory_without_refinement():
    """refine=False: one period from the end of a settled run, no Newton; on the stable orbit it
    closes to 1e-8 and its multipliers are the refined ones to 1e-6."""
    T = 2 * np.pi / IO["omega"]
    tr = pwsdyn.simulate("impact-oscillator", [-0.7, 0.0], (0, 80 * T), params=IO)
    rough = PeriodicOrbit.from_trajectory(tr, refine=False)
    assert rough.converged and rough.iterations == 0 and rough.residual < 1e-8
    np.testing.assert_allclose(np.sort_complex(rough.multipliers),
                               np.sort_complex(io_closed_form()["stable"]["mu"]), atol=1e-6)
