"""The quarter-car with a controlled bumpstop (thesis Paper C): the graze of the bumpstop, its
discontinuity map against closed forms, the low-cost control of thesis eq. 5.2 designed
there, up and down sweeps of the road amplitude with a fixed and a controlled bumpstop, and
the comfort and rattle-space metrics (pwsdyn.explore.metrics) against closed forms.

The parameter set. The zoo's quarter-car (1 Hz body, 10 Hz wheel, cc = 500, ce = 1500 N s/m)
on a road at omega = 10 rad/s grazes its bumpstop at A = 0.0275 m with a persistence sequence
(eq. 2.35) that changes sign -- 2.35 does not guarantee persistence -- but its damping (about
a third of critical) makes the loss invisible: up and down sweeps of A agree, the impacting
motion grows continuously from the graze. With dampers half as strong (cc = 250, ce = 750
N s/m: 8 % of critical in compression, 24 % in expansion, a soft comfort setting) and the
road at omega = 8 rad/s (1.27 Hz, just above the body resonance, where the stiffening by the
stop bends the resonance towards the forcing), the graze at A* = 0.02153 m is a loss of the
local attractor in the plain sense of thesis section 2.6.1: the up sweep jumps from 8.6 cm
of suspension travel to 15 cm with a chattering sequence on the bumpstop each cycle at
0.64 m/s, and the down sweep stays on that motion down to 0.82 A* (hysteresis). That is
the set used here (restitution r = 0.5 and everything else as in the zoo).

Why the graze is a "CC" point. The bumpstop surface is h = zs - zu + delta, whose normal
velocity is h_x f = vs - vu = vr -- the argument of the bilinear damper's kink. The
minimum of h along an orbit is therefore always at a crossing of vr = 0, an event point, and
continuation locates the graze as that event point reaching the bumpstop (a corner
collision, CC). The field is continuous across the kink, so the discontinuity map of thesis
eq. 2.33-2.34 applies as at a graze inside a segment (pwsdyn.grazing.discontinuity).

Homogeneity. While the tyre is loaded and the stop is not reached, the model is positively
homogeneous of degree one in (states, A): the kinks max(vr, 0), min(vr, 0) scale, gravity
cancels against the static preload. So the non-impacting orbit at A is A/A0 times the orbit
at A0, its multipliers do not depend on A, and the graze with a stop at delta happens at
A* = delta A0 / (largest compression at A0) -- the closed forms of the graze used below.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn.errors import ArgumentError
from pwsdyn.explore.metrics import metrics_sweep, response_metrics

OMEGA, CC, CE, R = 8.0, 250.0, 750.0, 0.5
MS, MU, KS, KT, G, DELTA = 250.0, 40.0, 10000.0, 150000.0, 9.81, 0.05
PARAMS = {"omega": OMEGA, "cc": CC, "ce": CE, "r": R}
T = 2 * math.pi / OMEGA
A0 = 0.01
X0 = {"zs": 0.0, "vs": 0.0, "zu": 0.0, "vu": 0.0}


def _settled(params, periods=60):
    return pwsdyn.simulate("quarter-car", X0, (0.0, periods * T), params=params)


@pytest.fixture(scope="module")
def graze():
    """The graze of the non-impacting orbit continued in the road amplitude."""
    orb = pwsdyn.PeriodicOrbit.from_trajectory(_settled({**PARAMS, "A": A0}))
    assert [e.kind for e in orb.events] == ["crossing", "crossing"] and orb.stable
    br = pwsdyn.continue_orbit("quarter-car", orb, "A", span=(A0, 0.05), ds=0.002,
                               on_dib="stop")
    return br.special("CC")[0]


@pytest.fixture(scope="module")
def design(graze):
    """The graze continued in the bumpstop position at A*, and the control designed there
    (the section a quarter of the way through the expansion after the graze; gains up to
    0.05: the stop moves by at most 5 cm per metre, or per m/s, of deviation)."""
    A_star = graze.value
    orb = pwsdyn.find_periodic_orbit("quarter-car", graze.orbit.x0, t0=graze.orbit.t0,
                                     params={**PARAMS, "A": A_star, "delta": 0.06})
    br = pwsdyn.continue_orbit("quarter-car", orb, "delta", span=(0.04, 0.06), ds=-0.002,
                               on_dib="stop")
    gr = br.special("CC")[0]
    # the graze ends segment i (compression); the section lies in segment i + 1 (expansion)
    segs = gr.problem.orbit_problem.evaluate(gr.point.u, np.array([gr.value])).segs
    t_c = (gr.monitor.t + 0.25 * segs[(gr.monitor.segment + 1) % len(segs)].T) % T
    return gr, pwsdyn.design_control(gr, t_c=t_c, max_gain=0.05)


def test_graze_of_the_bumpstop_where_the_compression_reaches_delta(graze):
    """A* from continuation against the homogeneity closed form, the compression of the
    simulated orbit at A0 measured by response_metrics (to 1e-8: the orbit is computed to
    rtol 1e-10, the compression extreme is a stored event point, vr = 0)."""
    m = response_metrics(_settled({**PARAMS, "A": A0}), "vs", travel="zs - zu",
                         t_from=40 * T)
    assert m.impacts == 0 and m.travel_min < 0
    A_star = DELTA * A0 / -m.travel_min
    assert abs(graze.value - A_star) < 1e-8 * A_star
    # multipliers independent of A (homogeneity): those of the orbit at A0
    orb = pwsdyn.PeriodicOrbit.from_trajectory(_settled({**PARAMS, "A": A0}))
    assert np.allclose(np.sort_complex(graze.multipliers), np.sort_complex(orb.multipliers),
                       atol=1e-8)


def test_discontinuity_map_at_the_kink_matches_the_closed_form(graze):
    """At the graze vs = vu = v, zs - zu = -delta, and with M = ms + mu (module docstring of
    the zoo model: the impulse conserves ms vs + mu vu, vr -> -r vr):

        a*   = vr' = ks delta / ms + ks delta / mu - kt (zr - zu) / mu,
        beta = sqrt(2 / a*) (1 + r) (-f + a* / M (0, mu, 0, -ms, 0)),  f = (v, vs', v, vu', 1)

    (eq. 2.34 with h_turning = vr: G f = f + (1 + r) a* / M (0, -mu, 0, ms, 0) and
    h_turning,x G f = -r a*). To 1e-9 relative: the point is located to 1e-10 in A."""
    dm = pwsdyn.discontinuity_map(graze)
    zs, vs, zu, vu, t = dm.x_star
    A = graze.value
    assert dm.names == ("zs", "vs", "zu", "vu", "t")
    assert abs(zs - zu + DELTA) < 1e-12 and abs(vs - vu) < 1e-12
    zr = A * math.sin(OMEGA * t)
    acc_s = KS * DELTA / MS
    acc_u = (-KS * DELTA + KT * (zr - zu)) / MU
    a_star = acc_s - acc_u
    assert abs(dm.a_star - a_star) < 1e-9 * a_star
    f = np.array([vs, acc_s, vu, acc_u, 1.0])
    M = MS + MU
    beta = math.sqrt(2 / a_star) * (1 + R) * (-f + a_star / M * np.array([0, MU, 0, -MS, 0]))
    assert np.allclose(dm.beta, beta, rtol=1e-9, atol=1e-9 * np.abs(beta).max())
    # the smooth Poincare map carries the orbit's multipliers (and 0 across the section)
    eig = np.sort_complex(np.linalg.eigvals(dm.P))
    assert np.allclose(eig, np.sort_complex(np.append(graze.multipliers, 0.0)), atol=1e-8)
    # a complex leading pair: 2.35 fails at once (the first impact pushes the next pass
    # deeper), and the sweeps below show the loss
    seq = dm.persistence(10)
    assert seq[0] < 0 and dm.scenario == "loss"


def test_a_corner_collision_that_is_not_a_graze_is_refused(graze):
    """A CC point where the orbit meets the bumpstop with a normal velocity (here: the
    graze's point with the body 1 cm/s faster, so vr != 0 and the two sides of the kink have
    different fields), or a point of another kind, gets a clear error: no silent map of a
    transversal corner."""
    from pwsdyn.continuation.branch import SpecialPoint
    from pwsdyn.orbits.problem import Monitor

    mon = graze.monitor
    x = np.array(mon.x, dtype=float)
    x[1] += 0.01

    class Transversal(SpecialPoint):
        @property
        def monitor(self):
            return Monitor(mon.value, mon.segment, mon.surface, mon.t, x)

    with pytest.raises(ArgumentError, match="not a graze"):
        pwsdyn.discontinuity_map(Transversal("CC", graze.index, graze.value, graze.branch))
    with pytest.raises(ArgumentError, match="not a graze"):
        pwsdyn.design_control(Transversal("CC", graze.index, graze.value, graze.branch))
    with pytest.raises(ArgumentError, match="GR special point"):
        pwsdyn.discontinuity_map(SpecialPoint("EP", 0, A0, graze.branch))


def test_designed_control_keeps_the_graze_and_makes_it_persistent(graze, design):
    """Paper C: the control designed at the graze (eq. 5.2, gains by design_control) makes
    the persistence sequence positive. The controlled model, analysed independently of the
    design (its own orbit, graze and discontinuity map, continued in A), shows

    * on the non-impacting orbit the stop at delta* + (A / A* - 1) K, K = c.x* / (1 - c0)
      (the fixed point of the law with x = (A / A*) x*: homogeneity), to 1e-9;
    * its multipliers: the uncontrolled ones and c0 (thesis section 5.2), to 1e-8;
    * its graze at A* still (where (A / A*) delta* = the stop, as K < delta*), to 1e-8;
    * the predicted sequence (to 1e-6) and the scenario "persistence"."""
    gr, d = design
    A_star = graze.value
    assert abs(gr.value - DELTA) < 1e-9
    assert d.feasible and d.margin > 0 and np.all(d.sequence > 0)
    assert max(abs(v) for v in d.c.values()) <= 0.05 + 1e-12
    K = sum(d.c[s] * d.x_star[s] for s in d.c) / (1 - d.c0)
    assert 0 < K < DELTA
    m = pwsdyn.with_discrete_control("quarter-car", "delta")
    prm = {**PARAMS, **d.params()}
    A1 = 0.9 * A_star
    tr = pwsdyn.simulate(m, {**X0, "delta": DELTA}, (0.0, 60 * T), params={**prm, "A": A1})
    orb = pwsdyn.PeriodicOrbit.from_trajectory(tr)
    assert [e.name for e in orb.events if e.kind != "crossing"] == ["control"]
    delta_ss = d.delta_star + (A1 / A_star - 1) * K
    assert abs(orb.x0[-1] - delta_ss) < 1e-9
    want = np.sort_complex(np.append(graze.multipliers, d.c0))
    assert np.allclose(np.sort_complex(orb.multipliers), want, atol=1e-8)
    br = pwsdyn.continue_orbit(m, orb, "A", span=(A1, 1.1 * A_star), ds=0.0005,
                               on_dib="stop")
    g2 = br.special("CC")[0]
    assert abs(g2.value - A_star) < 1e-8 * A_star
    dm2 = pwsdyn.discontinuity_map(g2)
    assert dm2.scenario == "persistence"
    seq = dm2.persistence(len(d.sequence))
    assert np.allclose(seq, d.sequence, rtol=1e-6, atol=1e-9 * np.abs(seq).max())


def _variants(d):
    ctrl = pwsdyn.with_discrete_control("quarter-car", "delta")
    return {"fixed": {"model": "quarter-car", "params": PARAMS},
            "controlled": {"model": ctrl, "params": {**PARAMS, **d.params()}}}


def test_up_and_down_in_A_fixed_bumpstop_jumps_controlled_does_not(graze, design):
    """Three road amplitudes around A*, swept up and down: with the fixed bumpstop the down
    sweep stays on the chattering motion below A* (hysteresis: RMS acceleration 3 m/s^2
    above the up sweep's, 14 impacts per period), with the controlled one the sweeps agree
    and the motion above A* stays small (no impact below A*)."""
    A_star = graze.value
    vals = np.array([0.93, 0.98, 1.04]) * A_star
    ds = metrics_sweep(_variants(design[1]), "A", vals, velocity="vs", travel="zs - zu",
                       event="bumpstop", transient=40, periods=10, direction="both")
    assert int(np.abs(ds.status).max()) == 0
    rms = ds.rms_acceleration
    imp = ds.impacts_per_period
    fixed, ctrl = rms.sel(variant="fixed"), rms.sel(variant="controlled")
    # fixed: no impact below A* going up, impacts at every value coming down
    assert np.all(imp.sel(variant="fixed", direction="up").values[:2] == 0)
    assert np.all(imp.sel(variant="fixed", direction="down").values > 5)
    assert float((fixed.sel(direction="down") - fixed.sel(direction="up"))[1]) > 2.0
    # controlled: one attractor, the sweeps agree; small impacts only above A*
    assert np.all(imp.sel(variant="controlled").values[:, :2] == 0)
    assert float(np.abs(ctrl.sel(direction="up") - ctrl.sel(direction="down")).max()) < 0.05
    assert float(ctrl.sel(direction="up")[2]) < 0.5 * float(fixed.sel(direction="up")[2])


@pytest.mark.slow
def test_brute_force_sweeps_show_the_loss_and_its_suppression(graze, design):
    """Stroboscopic up and down sweeps (pwsdyn.sweep, one chunk per direction so each
    value continues the last) from 0.8 A* to 1.2 A*: the fixed bumpstop has coexisting
    attractors (events per period differ between the sweeps) over [0.82 A*, A*), the
    controlled one never; the body displacement at the section jumps by centimetres without
    control and not with it."""
    A_star = graze.value
    _, d = design
    vals = np.linspace(0.8, 1.2, 20) * A_star      # A* itself not among them
    x_lo = _settled({**PARAMS, "A": vals[0]}, periods=80).x_final
    out = {}
    for name, v in _variants(d).items():
        model = v["model"]
        x0 = list(x_lo) + ([DELTA] if name == "controlled" else [])
        ds = pwsdyn.sweep(model, "A", vals, x0, params=v["params"], transient=100,
                          samples=20, direction="both", workers=2, chunk_size=len(vals),
                          progress=False)
        epp = ds.events_per_period
        up = epp.sel(direction="up").values
        down = epp.sel(direction="down").values
        zs = np.abs(ds.section.sel(state="zs")).max("sample")
        out[name] = (up, down, float(np.abs(zs.sel(direction="up")
                                            - zs.sel(direction="down")).max()))
    up, down, jump = out["fixed"]
    below = vals < A_star
    assert np.any((up != down) & below) and jump > 0.03
    up, down, jump = out["controlled"]
    assert np.all(up[below] == down[below]) and jump < 0.005


# ======================================================================================
# the metrics against closed forms
# ======================================================================================
def test_metrics_of_the_linear_quarter_car_match_its_frequency_response():
    """With ce = cc = c and no impact the quarter-car is linear:

        ms zs'' = -ks (zs - zu) - c (vs - vu),
        mu zu'' =  ks (zs - zu) + c (vs - vu) + kt (A sin(w t) - zu)

    (the tyre loaded: gravity cancels the static preload). With z = Z e^{iwt},
    (K - w^2 M + i w C) Z = (0, kt A): the body acceleration is w^2 |Zs| sin(...), so over a
    whole number of periods its RMS is w^2 |Zs| / sqrt(2), its peak w^2 |Zs|, and the
    travel zs - zu spans +-|Zs - Zu|. RMS and travel to 1e-9 (quadrature exact to rounding
    on the dense output; the run to rtol 1e-10); the peak, the largest of ~6 samples per
    step (~40 steps per period), to 1e-4 (a sampled maximum of a sine is low by at most
    (pi h / T)^2 / 2 of it, h the longest step)."""
    c, A = 1000.0, 0.01
    M = np.diag([MS, MU])
    Kmat = np.array([[KS, -KS], [-KS, KS + KT]])
    C = np.array([[c, -c], [-c, c]])
    Z = np.linalg.solve(Kmat - OMEGA**2 * M + 1j * OMEGA * C, [0.0, KT * A])
    tr = _settled({"A": A, "omega": OMEGA, "ce": c, "cc": c})
    m = response_metrics(tr, "vs", travel="zs - zu", event="bumpstop", t_from=40 * T,
                         t_to=55 * T)
    amp = OMEGA**2 * abs(Z[0])
    assert abs(m.rms_acceleration - amp / math.sqrt(2)) < 1e-9 * amp
    assert amp * (1 - 1e-4) < m.peak_acceleration <= amp * (1 + 1e-9)
    assert abs(m.travel_max - abs(Z[0] - Z[1])) < 1e-9 * abs(Z[0] - Z[1])
    assert abs(m.travel_min + abs(Z[0] - Z[1])) < 1e-9 * abs(Z[0] - Z[1])
    assert (m.impacts, m.chatter, m.impulse, m.stick_time) == (0, 0, 0.0, 0.0)
    assert abs(m.duration - 15 * T) < 1e-12


def test_impacts_impulses_and_sticking_of_a_dropped_ball():
    """A ball dropped from y0 on a still table (restitution e): impact k at speed
    v_k = e^k v0, v0 = sqrt(2 g y0); the impulses sum to (1 + e) v0 / (1 - e) (the
    chattering sequence's share included: the jump over it less gravity's -g dt over its
    duration); flight ends at t_inf = sqrt(2 y0 / g) (1 + 2 e / (1 - e)), so the smooth
    acceleration (-g in flight, 0 sticking) has RMS g sqrt(t_inf / t_end). To 1e-10."""
    g, e, y0, t_end = 9.81, 0.5, 1.0, 3.0
    tr = pwsdyn.simulate("bouncing-ball", {"y": y0, "v": 0.0}, (0.0, t_end),
                         params={"A": 0.0, "e": e, "g": g})
    m = response_metrics(tr, "v", travel="y", event="impact")
    v0 = math.sqrt(2 * g * y0)
    t_inf = math.sqrt(2 * y0 / g) * (1 + 2 * e / (1 - e))
    assert m.chatter == 1 and m.impacts == len(tr.events_of("impact", "impact")) > 5
    assert abs(m.impact_velocity_max - v0) < 1e-10 * v0
    assert abs(m.impulse - (1 + e) * v0 / (1 - e)) < 1e-10 * v0
    assert abs(m.rms_acceleration - g * math.sqrt(t_inf / t_end)) < 1e-10 * g
    assert m.peak_acceleration == pytest.approx(g, rel=1e-14)
    assert abs(m.stick_time - (t_end - t_inf)) < 1e-10
    assert abs(m.travel_max - y0) < 1e-14 and abs(m.travel_min) < 1e-12
    # a window after the second impact: impacts from the third on, speeds from v0 e^2
    t2 = math.sqrt(2 * y0 / g) * (1 + 2 * e)
    w = response_metrics(tr, "v", t_from=t2 + 1e-9)
    assert abs(w.impact_velocity_max - v0 * e**2) < 1e-10 * v0
    assert abs(w.impulse - (1 + e) * v0 * e**2 / (1 - e)) < 1e-10 * v0
    assert math.isnan(w.travel_min)


def test_metric_arguments_are_checked():
    tr = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0.0, 1.0),
                         params={"A": 0.0})
    with pytest.raises(ArgumentError, match="velocity"):
        response_metrics(tr, "w")
    with pytest.raises(ArgumentError, match="event"):
        response_metrics(tr, "v", event="bumpstop")
    with pytest.raises(pwsdyn.ExpressionError):
        response_metrics(tr, "v", travel="y + __import__('os')")
    with pytest.raises(pwsdyn.ExpressionError):
        response_metrics(tr, "v", travel="zs - zu")
    with pytest.raises(ArgumentError, match="t_to > t_from"):
        response_metrics(tr, "v", t_from=0.5, t_to=0.5)
    with pytest.raises(ArgumentError, match="t_from"):
        response_metrics(tr, "v", t_from=-1.0)
    nodense = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0.0, 1.0),
                              params={"A": 0.0}, dense=False)
    with pytest.raises(ArgumentError, match="dense"):
        response_metrics(nodense, "v")
    with pytest.raises(ArgumentError, match="variants"):
        metrics_sweep({}, "A", [0.1], velocity="v")
    with pytest.raises(ArgumentError, match="no parameter"):
        metrics_sweep({"a": "bouncing-ball"}, "sigma", [0.1], velocity="v")
    with pytest.raises(ArgumentError, match="values"):
        metrics_sweep({"a": "bouncing-ball"}, "A", [0.1, 0.1], velocity="v")
    with pytest.raises(ArgumentError, match="swept parameter"):
        metrics_sweep({"a": {"model": "bouncing-ball", "params": {"A": 0.1}}}, "A", [0.1],
                      velocity="v")
    with pytest.raises(ArgumentError, match="velocity"):
        metrics_sweep({"a": "bouncing-ball"}, "A", [0.1], velocity="y2")


def test_metrics_sweep_dataset_and_plot():
    """A two-value sweep of the vibrating table: the dataset's layout, its values those of
    response_metrics on the same runs (the sweep is the loop of simulate and
    response_metrics it documents), and the figure into the caller's axes."""
    from matplotlib.figure import Figure

    from pwsdyn.plot import plot_metrics

    vals = [0.01, 0.02]
    ds = metrics_sweep({"ball": "bouncing-ball"}, "A", vals, velocity="v", travel="y",
                       transient=3, periods=4)
    assert ds.rms_acceleration.dims == ("variant", "direction", "A")
    assert ds.rms_acceleration.attrs["units"] == "m s-1 s-1"
    assert list(ds.variant.values) == ["ball"] and list(ds.direction.values) == ["up"]
    # the same runs by hand
    T1 = 1.0
    x0 = pwsdyn.load_model("bouncing-ball").defaults["x0"]
    tr = pwsdyn.simulate("bouncing-ball", x0, (0.0, 3 * T1), params={"A": 0.01}, dense=False)
    tr = pwsdyn.simulate("bouncing-ball", tr, (3 * T1, 7 * T1), params={"A": 0.01})
    m = response_metrics(tr, "v", travel="y")
    got = ds.sel(variant="ball", direction="up", A=0.01)
    assert float(got.rms_acceleration) == m.rms_acceleration
    assert float(got.impacts_per_period) == m.impacts / 4
    fig = Figure()
    axes = fig.subplots(2, 1)
    assert plot_metrics(ds, ["rms_acceleration", "travel_range"], ax=axes) is fig
    assert axes[0].get_lines() and axes[1].get_lines()
    with pytest.raises(ArgumentError, match="unknown metric"):
        plot_metrics(ds, ["comfort"])
    with pytest.raises(ArgumentError, match="one per metric"):
        plot_metrics(ds, ["rms_acceleration"], ax=axes)


def test_metric_units_follow_the_model():
    """Units from the model's [units]: the acceleration the velocity's per time unit, the
    travel a linear combination of quantities of one unit (m), the impact velocity the
    bumpstop surface's unit per time unit; none for a travel that mixes units."""
    from pwsdyn.explore.metrics import _linear_unit

    m = pwsdyn.load_model("quarter-car")
    assert _linear_unit(m, m.surfaces[m.events[0].surface].expr) == "m"
    ds = metrics_sweep({"q": {"model": m, "params": PARAMS}}, "A", [0.005], velocity="vs",
                       travel="zs - zu", event="bumpstop", transient=1, periods=1)
    assert ds.travel_range.attrs["units"] == "m"
    assert ds.impact_velocity_max.attrs["units"] == "m s-1"
    assert ds.rms_acceleration.attrs["units"] == "m s-1 s-1"
    ds = metrics_sweep({"q": {"model": m, "params": PARAMS}}, "A", [0.005], velocity="vs",
                       travel="zs*vs", transient=1, periods=1)
    assert "units" not in ds.travel_range.attrs


def test_cli_grazing_finds_the_graze_at_the_kink(graze):
    """``pwsdyn grazing`` takes a corner collision that is a graze (the bumpstop reached at
    the damper's kink) as it takes a graze inside a segment: the same A* as the API's and
    the loss the persistence test predicts."""
    from click.testing import CliRunner

    from pwsdyn.cli import main

    args = ["grazing", "quarter-car", "--param", "A", "--from", "0.015", "--to", "0.03"]
    args += [a for k, v in PARAMS.items() if k != "A" for a in ("-p", f"{k}={v}")]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    line = next(s for s in res.output.splitlines() if s.startswith("graze"))
    assert abs(float(line.split("=")[1].split(":")[0]) - graze.value) < 1e-9
    assert "scenario    loss" in res.output
