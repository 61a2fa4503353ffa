"""Pseudo-arclength continuation (pwsdyn.continue_orbit, continue_equilibrium), checked against
closed forms derived independently of pwsdyn (tests/_orbit_cases.py):

* the one-impact orbits of the impact oscillator (linear flow between impacts): every point of
  the branch, the fold (the discriminant of the impact-velocity quadratic vanishes), the
  period doubling (``det(M + I) = 0`` for the one-period matrix ``M = S E``) and the
  Neimark-Sacker point in the damping (``det M = r^2 exp(-eps T) = 1``);
* the ball on a vibrating table: the period doubling of the period-one impact map, and the
  period-two branch born there against direct simulation;
* equilibria: fold, transcritical branch point and Hopf point of normal forms.

Tolerances: the orbit problems integrate at rtol = atol = 1e-12 and Newton converges to 1e-10
of the residual, so states agree with the closed forms to ~1e-10; the claims (issue text) are
1e-8 for points and special points.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import pwsdyn
from pwsdyn.continuation import Branch, ContinuationSettings, load_branch
from pwsdyn.errors import ArgumentError

from _orbit_cases import IO, BALL, ball_period_one, io_one_impact, io_orbit

IO_MODEL = "impact-oscillator"


def _io_branch(span, ds, **kw):
    return pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "omega", span=span, ds=ds,
                                 **kw)


@pytest.fixture(scope="module")
def io_up():
    """The stable one-impact orbit followed up in omega from 2.8 through its period doubling."""
    return _io_branch((2.0, 4.6), 0.05)


@pytest.fixture(scope="module")
def io_down():
    """... and down through the fold onto the saddle branch."""
    return _io_branch((1.9, 3.2), -0.05)


def _io_state_error(branch):
    """Largest difference between a branch's section states (just after the impact) and the
    closed-form one-impact orbit on the nearer root (the branch crosses from one to the other
    at the fold). Near the fold ``v(omega)`` has a square-root singularity, so the distance
    measured there is ``sqrt|(v - v_+)(v - v_-)|`` (the quadratic's residual: the distance to
    the root pair, well conditioned through the fold); both are bounds on the distance of the
    point from the closed-form curve."""
    worst = 0.0
    for p, x in zip(branch.points, branch.states):
        vp, _, _, disc = io_one_impact(p.lam, 1)
        vm = io_one_impact(p.lam, -1)[0]
        if disc < 1e-12:
            # at the fold the closed form's own round-off (sqrt of a discriminant of
            # ~1e-15) is 1e-6: the fold point is checked against the fold's closed form
            assert p.special == "LP"
            continue
        v = -x[1] / IO["r"]
        err = min(abs(v - vp), abs(v - vm), math.sqrt(abs((v - vp) * (v - vm))))
        worst = max(worst, err, abs(x[0] - IO["sigma"]))
    return worst


def test_orbit_branch_points_match_the_closed_form(io_up, io_down):
    for br in (io_up, io_down):
        assert len(br) > 10
        assert _io_state_error(br) < 1e-8
        periods = np.array([p.data["period"] for p in br.points])
        assert np.allclose(periods, 2 * np.pi / br.values, rtol=1e-9, atol=0)
        assert br.admissible.all()


def test_fold_of_the_one_impact_orbit(io_down):
    lp = io_down.special("LP")
    assert len(lp) == 1
    w_fold = brentq(lambda w: io_one_impact(w, 1)[3], 2.1, 2.3, xtol=1e-15)
    assert abs(lp[0].value - w_fold) < 1e-8
    # the impact velocity there: the double root -qb / (2 qa) = the mean of the two roots
    v_fold = 0.5 * (io_one_impact(w_fold, 1)[0] + io_one_impact(w_fold, -1)[0])
    assert abs(-lp[0].state[1] / IO["r"] - v_fold) < 1e-8
    # a multiplier +1 there; stable on one side, a saddle on the other
    assert np.min(np.abs(lp[0].multipliers - 1.0)) < 1e-6
    i = lp[0].index
    assert io_down.stable[i - 1] != io_down.stable[i + 1]
    assert "LP" in io_down.stop_reason or io_down.values[-1] == pytest.approx(3.2)


def _pd_value(M_of, lo, hi):
    return brentq(lambda a: 1 + np.trace(M_of(a)) + np.linalg.det(M_of(a)), lo, hi, xtol=1e-15)


def test_period_doubling_of_the_one_impact_orbit(io_up):
    pd = io_up.special("PD")
    assert len(pd) == 1
    w_pd = _pd_value(lambda w: io_one_impact(w, 1)[2], 4.2, 4.4)
    assert abs(pd[0].value - w_pd) < 1e-8
    assert np.min(np.abs(pd[0].multipliers + 1.0)) < 1e-6
    assert io_up.stable[pd[0].index - 1] and not io_up.stable[pd[0].index + 1]


def test_neimark_sacker_in_the_damping():
    """det M = r^2 exp(-eps T) (the impact's saltation matrix has determinant r^2): the
    complex pair of the one-impact orbit reaches the unit circle at eps = omega ln(r) / pi."""
    orb = io_orbit("stable")
    br = pwsdyn.continue_orbit(IO_MODEL, orb, "eps", span=(-0.3, 0.1), ds=-0.02)
    ns = br.special("NS")
    assert len(ns) == 1
    eps_ns = IO["omega"] * math.log(IO["r"]) / math.pi
    assert abs(ns[0].value - eps_ns) < 1e-8
    mu = ns[0].multipliers
    assert np.all(np.abs(mu.imag) > 0.5) and np.allclose(np.abs(mu), 1.0, atol=1e-7)
    assert not br.special("PD") and not br.special("LP")


def test_branch_point_of_the_doubled_orbit_is_the_period_doubling(io_up):
    """The one-impact orbit seen as a period-2 orbit (doubled signature) has a branch point
    where the period-1 orbit doubles: the period-2 branch crosses it there."""
    w_pd = io_up.special("PD")[0].value
    p1 = io_up.points[2]
    orb1 = io_up.problem.orbit(p1.u, p1.lam)
    orb2 = pwsdyn.find_periodic_orbit(IO_MODEL, orb1.x0, t0=orb1.t0, periods=2,
                                      params={**IO, "omega": p1.lam})
    assert len(orb2.signature) == 2
    br = pwsdyn.continue_orbit(IO_MODEL, orb2, "omega", span=(p1.lam, 4.5), ds=0.05)
    bp = br.special("BP")
    assert len(bp) == 1 and abs(bp[0].value - w_pd) < 1e-8
    assert not br.special("PD")
    # switching there follows the period-2 branch; switching at the PD does too
    a = pwsdyn.continue_orbit(IO_MODEL, bp[0], "omega", span=(p1.lam, 4.5), ds=0.01,
                              max_points=15)
    b = pwsdyn.continue_orbit(IO_MODEL, io_up.special("PD")[0], "omega", span=(p1.lam, 4.5),
                              ds=0.01, max_points=15)
    for br2 in (a, b):
        x = br2.states
        half = x.shape[0]
        assert br2.points[0].special == "BP"
        # a genuine period-2 orbit: its two impacts differ
        u = br2.points[-1].u
        _, xs, _ = br2.problem.orbit_problem.unpack(u)
        assert abs(xs[0][1] - xs[1][1]) > 1e-3, half


def _ball_orbit(A=0.224):
    t, u, _ = ball_period_one(A)
    T = 2 * np.pi / BALL["omega"]
    tau = 0.3 * T
    x0 = [A * np.sin(BALL["omega"] * t) + u * tau - BALL["g"] * tau**2 / 2, u - BALL["g"] * tau]
    return pwsdyn.find_periodic_orbit("bouncing-ball", x0, t0=t + tau,
                                      params={"A": A, "omega": BALL["omega"]})


@pytest.fixture(scope="module")
def ball_branch():
    return pwsdyn.continue_orbit("bouncing-ball", _ball_orbit(), "A", span=(0.2, 0.32))


def test_ball_period_doubling_and_period_two_branch(ball_branch):
    pd = ball_branch.special("PD")
    assert len(pd) == 1
    A_pd = _pd_value(lambda a: ball_period_one(a)[2], 0.25, 0.3)
    assert abs(pd[0].value - A_pd) < 1e-8
    # every point: the closed-form period-one orbit (the state just after the impact)
    for p, x in zip(ball_branch.points, ball_branch.states):
        t, u, _ = ball_period_one(p.lam)
        ref = [p.lam * math.sin(BALL["omega"] * t), u]
        assert np.max(np.abs(x - ref)) < 1e-8
    br2 = pwsdyn.continue_orbit("bouncing-ball", pd[0], "A", span=(0.2, 0.32), max_points=12)
    assert br2.values.min() >= A_pd - 1e-12 and len(br2) == 12
    assert br2.stable[1:].all()       # supercritical: the period-2 orbit takes over
    op = br2.problem.orbit_problem
    for p in br2.points[3::4]:
        t0, xs, Ts = op.unpack(p.u)
        assert abs(xs[0][1] - xs[1][1]) > 1e-4    # two different impacts
        # direct simulation: from the middle of the first flight, over two table periods,
        # two impacts and back to the same state
        kw = dict(params={"A": p.lam, "omega": BALL["omega"]}, rtol=1e-12, atol=1e-12,
                  method="DOP853")
        tm = t0 + 0.5 * Ts[0]
        xm = pwsdyn.simulate("bouncing-ball", xs[0], (t0, tm), **kw).x[-1]
        tr = pwsdyn.simulate("bouncing-ball", xm, (tm, tm + 4 * np.pi / BALL["omega"]), **kw)
        assert len(tr.events) == 2
        assert np.max(np.abs(tr.x[-1] - xm)) < 1e-8


@pytest.mark.parametrize("ds", [0.005, 0.05, 0.2])
def test_special_points_once_whatever_the_step(ds):
    br = _io_branch((2.0, 4.6), ds, ds_max=max(ds, 0.05) * 2, max_points=400)
    kinds = [s.kind for s in br.special_points if s.kind != "EP"]
    assert kinds == ["PD"], kinds
    w_pd = _pd_value(lambda w: io_one_impact(w, 1)[2], 4.2, 4.4)
    assert abs(br.special("PD")[0].value - w_pd) < 1e-8


def test_branch_file_round_trip_and_resume(io_up, tmp_path):
    path = io_up.save(tmp_path / "branch.nc")
    back = load_branch(path)
    assert isinstance(back, Branch) and len(back) == len(io_up)
    assert np.array_equal(back.values, io_up.values)
    assert back.stop_status is io_up.stop_status is pwsdyn.Status.SPAN_END
    assert np.allclose(back.states, io_up.states, rtol=0, atol=0)
    assert [(s.kind, s.index) for s in back.special_points] == \
        [(s.kind, s.index) for s in io_up.special_points]
    assert np.allclose(back.special("PD")[0].multipliers, io_up.special("PD")[0].multipliers)
    ds = back.to_dataset()
    assert ds.attrs["pwsdyn_type"] == "branch" and ds.attrs["parameter"] == "omega"
    assert ds["omega"].attrs["long_name"]
    # continued further from the file: the same orbits as one run to the larger bound
    more = pwsdyn.continue_orbit(IO_MODEL, back, "omega", span=(2.0, 4.9))
    assert more.values.max() == pytest.approx(4.9) and len(more) > len(back)
    assert _io_state_error(more) < 1e-8
    with pytest.raises(pwsdyn.OutputExistsError):
        io_up.save(path)


def test_iterable_one_point_at_a_time():
    from pwsdyn.continuation import Continuation, OrbitBranchProblem
    from pwsdyn.orbits import OrbitProblem

    prob, u = OrbitProblem.from_orbit(io_orbit("stable"), parameters=["omega"])
    cont = Continuation(OrbitBranchProblem(prob), u, prob.p0[0],
                        ContinuationSettings(ds=0.05, span=(2.0, 4.0), max_points=5))
    seen = [p.lam for p in cont]
    assert len(seen) == 5 and seen == [p.lam for p in cont.points]
    assert "max_points" in cont.stop_reason


def test_plot(io_up, io_down, tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = io_down.plot(path=tmp_path / "b.png")
    assert (tmp_path / "b.png").stat().st_size > 1000
    ax = fig.axes[0]
    styles = {ln.get_linestyle() for ln in ax.get_lines()}
    assert {"-", "--"} <= styles       # stable and unstable parts
    assert any(t.get_text() == "LP" for t in ax.texts)
    own = Figure()
    a = own.subplots()
    assert io_up.plot(y="period", ax=a) is own

    # any measure of the orbit: here its impact velocity, read off its event log
    def impact_velocity(orbit):
        return orbit.events[0].x_before[1]
    b = Figure().subplots()
    io_up.plot(y=impact_velocity, ax=b)
    want = [impact_velocity(io_up.problem_of(p).orbit(p.u, p.lam)) for p in io_up.points]
    drawn = np.concatenate([ln.get_ydata() for ln in b.get_lines()
                            if ln.get_linestyle() in ("-", "--", ":")])
    assert b.get_ylabel() == "impact velocity"
    assert np.allclose(sorted(set(np.round(drawn, 12))), sorted(set(np.round(want, 12))))
    assert min(want) > 0


# ---- equilibria ------------------------------------------------------------------------

def _flow(name, fields, params):
    states = list(fields)
    return {"name": name, "states": states, "parameters": params,
            "modes": {"m": dict(fields)}}


def test_equilibrium_fold_branch_point_and_hopf():
    # fold: x' = p - x^2, x = sqrt(p); the branch turns at p = 0
    fold = pwsdyn.continue_equilibrium(_flow("fold", {"x": "p - x**2"}, {"p": 1.0}), [1.0],
                                       "p", span=(-1, 2), ds=-0.05)
    lp = fold.special("LP")
    assert len(lp) == 1 and abs(lp[0].value) < 1e-9 and abs(lp[0].state[0]) < 1e-5
    assert np.allclose(fold.states[:, 0] ** 2, fold.values, atol=1e-10)
    # transcritical: x' = p x - x^2, branches x = 0 and x = p cross at p = 0
    tc = _flow("transcritical", {"x": "p*x - x**2"}, {"p": -1.0})
    br = pwsdyn.continue_equilibrium(tc, [0.0], "p", span=(-1, 1), ds=0.05)
    bp = br.special("BP")
    assert len(bp) == 1 and abs(bp[0].value) < 1e-9
    assert np.allclose(br.states[:, 0], 0.0, atol=1e-12)
    other = pwsdyn.continue_equilibrium(tc, bp[0], "p", span=(-1, 1), ds=0.05)
    assert other.points[0].special == "BP" and len(other) > 5
    assert np.allclose(other.states[:, 0], other.values, atol=1e-10)     # the branch x = p
    assert abs(other.values[-1]) == pytest.approx(1.0)
    # Hopf: the normal form x' = p x - y - x r2, y' = x + p y - y r2 at p = 0
    hopf = _flow("hopf", {"x": "p*x - y - x*(x**2 + y**2)", "y": "x + p*y - y*(x**2 + y**2)"},
                 {"p": -1.0})
    br = pwsdyn.continue_equilibrium(hopf, [0.0, 0.0], "p", span=(-1, 1), ds=0.05)
    hb = br.special("HB")
    assert len(hb) == 1 and abs(hb[0].value) < 1e-9
    assert np.allclose(np.abs(hb[0].eigenvalues.imag), 1.0) and \
        np.allclose(hb[0].eigenvalues.real, 0.0, atol=1e-8)
    assert br.stable[0] and not br.stable[-1]


# ---- bad input ---------------------------------------------------------------------------

def test_bad_input_is_refused_clearly():
    orb = io_orbit("stable")
    with pytest.raises(ArgumentError, match="no parameter 'Omega'"):
        pwsdyn.continue_orbit(IO_MODEL, orb, "Omega")
    with pytest.raises(ArgumentError, match="PeriodicOrbit"):
        pwsdyn.continue_orbit(IO_MODEL, [0.0, 1.0], "omega")
    with pytest.raises(ArgumentError, match="span"):
        pwsdyn.continue_orbit(IO_MODEL, orb, "omega", span=(3.0, 2.0))
    with pytest.raises(ArgumentError, match="ds"):
        pwsdyn.continue_orbit(IO_MODEL, orb, "omega", ds=0.0)
    with pytest.raises(ArgumentError, match="not a solution"):
        pwsdyn.continue_equilibrium(_flow("noeq", {"x": "1 + x**2"}, {"p": 0.0}), [0.0], "p")


def test_a_singular_point_stops_the_branch_with_its_reason():
    """x' = sqrt(p) - x has no equilibria for p < 0 (the field is NaN): the branch stops at
    p = 0 with the reason, in bounded work."""
    br = pwsdyn.continue_equilibrium(_flow("sqrtp", {"x": "sqrt(p) - x"}, {"p": 1.0}), [1.0],
                                     "p", span=(-1, 2), ds=-0.05)
    assert br.values.min() >= 0.0 and br.values.min() < 1e-3
    assert "ds_min" in br.stop_reason


# ---- command line ------------------------------------------------------------------------

def test_cli_continue_finds_its_start_and_writes_the_branch(tmp_path):
    from click.testing import CliRunner

    from pwsdyn.cli import main

    out, png = tmp_path / "b.nc", tmp_path / "b.png"
    res = CliRunner().invoke(main, ["continue", "bouncing-ball", "--param", "A", "--from",
                                    "0.224", "--to", "0.32", "--out", str(out), "--plot",
                                    str(png), "--no-progress"])
    assert res.exit_code == 0, res.output
    assert "PD" in res.output and "0.26609237" in res.output
    br = load_branch(out)
    A_pd = _pd_value(lambda a: ball_period_one(a)[2], 0.25, 0.3)
    assert abs(br.special("PD")[0].value - A_pd) < 1e-8
    assert png.read_bytes()[:4] == b"\x89PNG"
    # the same defaults as the API: the same branch
    api = pwsdyn.continue_orbit("bouncing-ball", _ball_orbit(), "A", span=(0.224, 0.32),
                                ds=min(0.02, (0.32 - 0.224) / 100))
    assert abs(api.special("PD")[0].value - br.special("PD")[0].value) < 1e-9
    bad = CliRunner().invoke(main, ["continue", "bouncing-ball", "--param", "Q", "--from",
                                    "0", "--to", "1"])
    assert bad.exit_code != 0 and "unknown parameter 'Q'" in bad.output


# ---- two parameters ----------------------------------------------------------------------

def test_two_parameter_fold_and_period_doubling_curves(io_up, io_down, tmp_path):
    """The curves of the one-impact orbit's period doubling and fold in (sigma, omega),
    against the closed-form conditions det(M + I) = 0 and disc = 0 solved for omega at each
    sigma of the curve."""
    pd = pwsdyn.continue_bifurcation(IO_MODEL, io_up.special("PD")[0], ("sigma", "omega"),
                                     span=(-0.8, -0.2), ds=0.02, max_points=12)
    lp = pwsdyn.continue_bifurcation(IO_MODEL, io_down.special("LP")[0], ("sigma", "omega"),
                                     span=(-0.8, -0.3), ds=-0.02, max_points=12)
    for curve, kind in ((pd, "PD"), (lp, "LP")):
        assert curve.curve == kind and len(curve) >= 6
        sig, om = curve.values, curve.values_of("omega")
        assert np.ptp(sig) > 0.05          # the curve moves in both parameters
        for s_, w in zip(sig, om):
            if kind == "PD":
                ref = brentq(lambda x: (lambda M: 1 + np.trace(M) + np.linalg.det(M))(
                    io_one_impact(x, 1, sigma=s_)[2]), w - 0.05, w + 0.05, xtol=1e-15)
            else:
                ref = brentq(lambda x: io_one_impact(x, 1, sigma=s_)[3], w - 0.05, w + 0.05,
                             xtol=1e-15)
            assert abs(w - ref) < 1e-7, (kind, s_, w, ref)
    back = load_branch(pd.save(tmp_path / "pd.nc"))
    assert back.curve == "PD" and np.array_equal(back.values_of("omega"), pd.values_of("omega"))
    assert back.stop_status is pd.stop_status is not None
    with pytest.raises(ArgumentError, match="one of `params`"):
        pwsdyn.continue_bifurcation(IO_MODEL, io_up.special("PD")[0], ("sigma", "eps"))


def test_followed_in_the_stop_position_past_the_graze():
    """In sigma the impact velocity falls to zero where the wall reaches the amplitude R of the
    forced response (the graze); on the locked signature the branch goes on, reported not
    admissible beyond it, with the reason."""
    br = pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "sigma", span=(-0.6, 0.3),
                               ds=0.05, on_dib="continue")
    w, eps = IO["omega"], IO["eps"]
    R = 1.0 / math.hypot(1 - w**2, eps * w)
    sig = br.values
    assert sig.min() < R - 0.05 and sig.max() == pytest.approx(0.3)
    below, above = sig < R - 1e-3, sig > R + 1e-3
    assert below.sum() > 5 and above.sum() >= 2
    assert br.admissible[below].all() and not br.admissible[above].any()
    for p in np.array(br.points, dtype=object)[above]:
        assert "passes through the constraint" in p.data["reason"]
    for p, x in zip(br.points, br.states):
        if p.lam < R - 1e-3:
            vs = [io_one_impact(w, root, sigma=p.lam)[0] for root in (1, -1)]
            assert min(abs(-x[1] / IO["r"] - v) for v in vs) < 1e-8


def test_autonomous_limit_cycle_followed_in_a_parameter():
    """A Van der Pol oscillator against a wall (an impacting limit cycle, period unknown)
    followed in mu: every point is the orbit free-running shooting finds from it, period and
    multiplier to 1e-9."""
    vdp = {"name": "vdp-wall", "states": ["x", "v"],
           "parameters": {"mu": 1.0, "sigma": 1.5, "r": 0.7},
           "modes": {"free": {"x": "v", "v": "mu*(1 - x**2)*v - x"}},
           "events": [{"name": "wall", "kind": "impact", "surface": "sigma - x",
                       "reset": {"v": "-r*v"}}]}
    m = pwsdyn.load_model(vdp)
    orb = pwsdyn.PeriodicOrbit.from_trajectory(pwsdyn.simulate(m, [0.1, 0.0], (0, 40)))
    br = pwsdyn.continue_orbit(m, orb, "mu", span=(0.5, 2.0), ds=0.05)
    assert br.values.max() == pytest.approx(2.0) and len(br) > 5
    periods = [p.data["period"] for p in br.points]
    assert np.all(np.diff(periods) > 0)          # the cycle slows down as mu grows
    for i in (3, len(br) - 2):
        p = br.points[i]
        ref = pwsdyn.find_periodic_orbit(m, br.states[i], period=1.001 * p.data["period"],
                                         params={"mu": p.lam})
        assert abs(ref.period - p.data["period"]) < 1e-9
        assert abs(ref.multipliers[0] - p.data["multipliers"][0]) < 1e-9
        sp_orbit = br.problem.orbit(p.u, p.lam)
        assert abs(sp_orbit.period - p.data["period"]) < 1e-12


def test_special_point_carries_its_orbit(io_up):
    pd = io_up.special("PD")[0]
    orb = pd.orbit
    assert abs(orb.params["omega"] - pd.value) < 1e-15
    assert np.min(np.abs(orb.multipliers + 1.0)) < 1e-6


def test_a_start_that_is_not_an_orbit_is_refused():
    from pwsdyn.continuation import ContinuationError

    # the orbit at sigma = -0.5 taken as the guess at sigma = 5: no impacting orbit there
    with pytest.raises(ContinuationError, match="not a solution"):
        pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "sigma", params={"sigma": 5.0})


def test_pseudo_equilibria_of_a_filippov_switch_and_their_fold():
    """x' = -x^2 + p (1 + sign y)/2, y' = -sign y: both fields point into y = 0, alpha = 1/2
    and the sliding field is -x^2 + p/2: pseudo-equilibria x = +-sqrt(p/2), a fold at p = 0,
    stable (eigenvalue -2x on the surface) for x > 0."""
    m = pwsdyn.load_model({"name": "pseudo-fold", "states": ["x", "y"],
                           "parameters": {"p": 2.0},
                           "modes": {"m": {"x": "-x**2 + p*(1 + sign(y))/2",
                                           "y": "-sign(y)"}}})
    sw = m.switches[0].name
    br = pwsdyn.continue_equilibrium(m, [1.0, 0.0], "p", mode=f"slide:{sw}", span=(-1, 3),
                                     ds=-0.05)
    lp = br.special("LP")
    assert len(lp) == 1 and abs(lp[0].value) < 1e-9
    x = br.states
    assert np.allclose(x[:, 0] ** 2, br.values / 2, atol=1e-10) and np.allclose(x[:, 1], 0.0)
    assert all(abs(p.data["alpha"] - 0.5) < 1e-12 for p in br.points)
    ev = np.array([p.data["eigenvalues"][0].real for p in br.points])
    assert np.allclose(ev, -2 * x[:, 0], atol=1e-5)
    assert (br.stable == (x[:, 0] > 0)).sum() >= len(br) - 1    # all but the fold itself
    assert br.admissible.all()
    with pytest.raises(ArgumentError, match="no Filippov switch"):
        pwsdyn.continue_equilibrium(m, [1.0, 0.0], "p", mode="slide:nope")


def test_branch_drawn_over_a_sweep(io_up):
    import matplotlib
    matplotlib.use("Agg")

    sw = pwsdyn.sweep(IO_MODEL, "omega", np.linspace(3.0, 4.0, 5), {"x": -1.0, "v": 0.0},
                      params={k: v for k, v in IO.items() if k != "omega"}, transient=20,
                      samples=2, direction="up", workers=1,
                      progress=False)
    fig = io_up.plot(y="x", sweep=sw)
    ax = fig.axes[0]
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert any("sweep" in lb for lb in labels) and "stable" in labels


# ---- grazing -----------------------------------------------------------------------------

def _non_impacting_orbit(omega, sigma):
    """The forced response x_p = X sin(omega t) + Y cos(omega t) of the impact oscillator, a
    periodic orbit without impacts while sigma > R = sqrt(X^2 + Y^2)."""
    eps = IO["eps"]
    X, Y = np.linalg.solve(np.array([[1 - omega**2, -eps * omega],
                                     [eps * omega, 1 - omega**2]]), [1.0, 0.0])
    return pwsdyn.find_periodic_orbit(IO_MODEL, [Y, omega * X], t0=0.0,
                                      params={**IO, "omega": omega, "sigma": sigma})


@pytest.mark.parametrize("omega", [2.0, 2.8, 3.5])
def test_graze_of_the_non_impacting_orbit_and_the_impacting_branch_born_there(omega):
    """Followed down in the stop position, the non-impacting orbit grazes the stop where
    sigma equals the amplitude R of the forced response (closed form); the branch goes on
    with the one-impact orbit born there, whose points match its closed form."""
    R = 1.0 / math.hypot(1 - omega**2, IO["eps"] * omega)
    orb = _non_impacting_orbit(omega, R + 0.3)
    assert len(orb.signature) == 0
    br = pwsdyn.continue_orbit(IO_MODEL, orb, "sigma", span=(R - 0.3, R + 0.3), ds=-0.05)
    gr = br.special("GR")
    assert len(gr) == 1 and abs(gr[0].value - R) < 1e-10
    assert gr[0].key == "GR/impact/0" and abs(gr[0].monitor.x[0] - R) < 1e-10
    assert [len(s) for s in br.signatures] == [0, 1]
    assert br.admissible.all()
    new = [(p, x) for p, x in zip(br.points, br.states) if p.signature_index == 1]
    assert len(new) >= 4 and br.values.min() == pytest.approx(R - 0.3)
    for p, x in new:
        vs = [io_one_impact(omega, root, sigma=p.lam)[0] for root in (1, -1)]
        assert abs(x[0] - p.lam) < 1e-12
        assert min(abs(-x[1] / IO["r"] - v) for v in vs) < 1e-8


@pytest.mark.parametrize("ds", [0.01, 0.1])
def test_impact_velocity_to_zero_ends_the_impacting_branch_once(ds):
    """Up in sigma the one-impact orbit's impact velocity falls to zero at sigma = R: one
    graze, and the branch goes on without the impact (or stops there, on_dib="stop")."""
    w = IO["omega"]
    R = 1.0 / math.hypot(1 - w**2, IO["eps"] * w)
    br = pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "sigma", span=(-0.6, 0.4), ds=ds,
                               ds_max=10 * ds, max_points=400)
    gr = br.special("GR")
    assert len(gr) == 1 and abs(gr[0].value - R) < 1e-10 and gr[0].key == "GR/impact@0"
    assert [len(s) for s in br.signatures] == [1, 0]
    assert br.values.max() == pytest.approx(0.4) and br.admissible.all()
    stop = pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "sigma", span=(-0.6, 0.4),
                                 ds=ds, on_dib="stop")
    assert stop.points[-1].special == "GR" and "GR located" in stop.stop_reason
    assert stop.stop_status is pwsdyn.Status.STOP_AT_SPECIAL_POINT


def test_boundary_equilibrium_bifurcations():
    """x' = p - x - sign(x): the upper mode's equilibrium x = p - 1 reaches the switching
    surface at p = 1 (not admissible below), and the pseudo-equilibrium on x = 0 has
    alpha = (p + 1)/2, leaving the sliding region at p = 1 (alpha = 1) and p = -1 (alpha = 0):
    boundary equilibrium bifurcations, located to 1e-10."""
    m = pwsdyn.load_model({"name": "beb", "states": ["x"], "parameters": {"p": 2.0},
                           "modes": {"m": {"x": "p - x - sign(x)"}}})
    up = m.mode_names[m.switches[0].above]
    br = pwsdyn.continue_equilibrium(m, [1.0], "p", mode=up, span=(-2, 3), ds=-0.05)
    beb = br.special("BEB")
    assert len(beb) == 1 and abs(beb[0].value - 1.0) < 1e-10 and abs(beb[0].state[0]) < 1e-10
    assert np.allclose(br.states[:, 0], br.values - 1.0, atol=1e-12)
    assert (br.admissible == (br.values >= 1.0 - 1e-9)).all()
    slide = f"slide:{m.switches[0].name}"
    for ds in (0.05, -0.05):
        ps = pwsdyn.continue_equilibrium(m, [0.0], "p", mode=slide, params={"p": 0.0},
                                         span=(-2, 2), ds=ds)
        beb = ps.special("BEB")
        assert len(beb) == 1 and abs(abs(beb[0].value) - 1.0) < 1e-10
        assert beb[0].key == ("BEB/above" if ds > 0 else "BEB/below")
        alpha = np.array([p.data["alpha"] for p in ps.points])
        assert np.allclose(alpha, (ps.values + 1) / 2, atol=1e-12)
        assert (ps.admissible == (np.abs(ps.values) <= 1 + 1e-9)).all()


def test_plot_over_the_whole_orbit_is_continuous_across_a_graze():
    """y = "min:x" (the orbit's smallest x over a period) is the same on both sides of a
    graze, where the section state jumps."""
    import matplotlib
    matplotlib.use("Agg")
    from pwsdyn.plot import _branch_y

    params = {"eps": 0.1, "omega": 2.8, "sigma": 0.45}
    orbit = pwsdyn.find_periodic_orbit(IO_MODEL, [-0.006, -0.41], t0=0.0, params=params)
    br = pwsdyn.continue_orbit(IO_MODEL, orbit, "sigma", span=(0.0, 0.45), ds=-0.05)
    y, label = _branch_y(br, "min:x")
    k = next(i for i, p in enumerate(br.points) if p.signature_index == 1)
    assert "over the orbit" in label and abs(y[k] - y[k - 1]) < 1e-3
    assert abs(y[0] + 1.0 / math.hypot(1 - 2.8**2, 0.28)) < 1e-6     # -R: the free motion
    fig = br.plot(y="min:x")
    assert fig.axes[0].get_ylabel().startswith("min")
