"""Branches that never lose work, go the direction asked, and files and resumes that can be
relied on.

* a failure inside a continuation step (the model refusing a predicted parameter, a segment
  that cannot be integrated, a singular system) rejects the step and shrinks it; at ``ds_min``
  the branch ends with its points and a reason, never with the caller's exception; the CLI
  writes what it has and exits non-zero with the reason;
* a branch file carries a content hash: a changed, truncated or incomplete file is refused with
  pwsdyn's own error naming the file; a resumed branch or special point is checked against the
  model it is continued with;
* ``max_points`` is a hard bound; every argument of ``continue_bifurcation`` is checked.

The branches in closed form are one-dimensional equilibria (``x' = p - x`` and
``x' = p - x^2``: ``x = p`` and ``x = sqrt(p)``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pwsdyn
from pwsdyn import ArgumentError, Status
from pwsdyn.continuation import Continuation, ContinuationSettings, load_branch
from pwsdyn.newton import TrialRejected
from pwsdyn.orbits import SegmentFailed


def _flow(name, fields, params):
    return {"name": name, "states": list(fields), "parameters": params,
            "modes": {"m": dict(fields)}}


FOLD = _flow("fold", {"x": "p - x**2"}, {"p": 1.0})
LINE = _flow("line", {"x": "p - x"}, {"p": 1.0})


# ======================================================================================
# item 1: no computed point is ever lost
# ======================================================================================

class _Refusing:
    """``F(u, lam) = u - lam`` (the branch ``u = lam``) whose evaluation fails below
    ``lam = 0.5`` with ``error`` (what a model, an integrator or a linear solve raises
    there)."""

    size = 1
    kind = "equilibrium"
    parameter = "p"

    def __init__(self, error, where="evaluate"):
        self.error = error
        self.where = where

    def _check(self, lam, where):
        if lam < 0.5 and where == self.where:
            raise self.error

    def evaluate(self, u, lam):
        self._check(lam, "evaluate")
        return np.array([u[0] - lam]), np.eye(1), np.array([-1.0])

    def analyse(self, u, lam, evaluation=None):
        self._check(lam, "analyse")
        return {"stable": True, "admissible": True}

    def test_functions(self, data):
        return {}


FAILURES = [ArgumentError("the forcing period must be positive"),
            TrialRejected("segment 0 could not be integrated", "simulation"),
            SegmentFailed(0, "the kernel stopped"),
            np.linalg.LinAlgError("Singular matrix"),
            FloatingPointError("overflow")]


@pytest.mark.parametrize("where", ["evaluate", "analyse"])
@pytest.mark.parametrize("error", FAILURES, ids=lambda e: type(e).__name__)
def test_a_failure_inside_a_step_keeps_the_branch(error, where):
    """Before, the exception left the engine and every point was lost; now the step is retaken
    shorter until ``ds_min``, and the branch ends there with its points, a member and the
    failure in words."""
    st = ContinuationSettings(ds=-0.1, ds_max=0.1, ds_min=1e-4, span=(0.0, 2.0), locate=())
    cont = Continuation(_Refusing(error, where), [1.0], 1.0, st)
    pts = cont.run()
    lam = np.array([p.lam for p in pts])
    # every point on the branch u = lam, down to within ds_min of the refusing region
    assert np.allclose([p.u[0] for p in pts], lam, atol=1e-12)
    assert lam.min() >= 0.5 and lam.min() < 0.5 + 2e-4 * 4
    assert cont.stop_status is Status.STEP_BELOW_DS_MIN
    assert str(error) in cont.stop_reason


@pytest.mark.slow
def test_impact_oscillator_down_in_omega_reaches_the_span_end(tmp_path):
    """The issue's reproduction: `pwsdyn continue impact-oscillator --param omega --from 2.5
    --to 2.0` (defaults). Before: the corrector's first Newton step moved omega to -0.95, the
    model refused the forcing period there, and the command wrote nothing. Now the step is
    retaken shorter and the branch reaches the end of the span; the file is written."""
    from click.testing import CliRunner

    from pwsdyn.cli import main

    out = tmp_path / "b.nc"
    res = CliRunner().invoke(main, ["continue", "impact-oscillator", "--param", "omega",
                                    "--from", "2.5", "--to", "2.0", "--no-progress",
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    br = load_branch(out)
    assert br.stop_status is Status.SPAN_END
    assert abs(br.values.min() - 2.0) < 1e-12 and abs(br.values.max() - 2.5) < 1e-12


@pytest.mark.slow
def test_stick_slip_down_in_fs_passes_its_sliding_bifurcations():
    """The issue's second reproduction: the zoo's stick-slip cycle continued down in Fs with
    ds from 0.02 to 0.2 died at its first sliding bifurcation with a TypeError (the forcing
    period of an autonomous model asked for where a segment is merged). Now it goes on past
    the switching-sliding and the crossing-sliding points to the end of the span."""
    from click.testing import CliRunner

    from pwsdyn.cli import main

    for ds in ("0.02", "0.2"):
        res = CliRunner().invoke(main, ["continue", "stick-slip-oscillator", "--param", "Fs",
                                        "--from", "1", "--to", "0.001", "--ds", ds,
                                        "--no-progress"])
        assert res.exit_code == 0, res.output
        assert "SPAN_END" in res.output
        assert res.output.count("\nSS ") == 1 and res.output.count("\nCS ") == 1


def test_cli_writes_a_failed_branch_and_exits_nonzero(tmp_path, monkeypatch):
    """A branch that ends before its span (here: the equilibrium problem refuses p < 0.5, as a
    model refuses a parameter outside its domain) is written, drawn and reported, and the
    command exits 1 with the reason."""
    from click.testing import CliRunner

    from pwsdyn.cli import main
    from pwsdyn.continuation import problems

    real = problems.EquilibriumProblem.evaluate

    def refusing(self, u, lam):
        if lam < 0.5:
            raise ArgumentError("p must be at least 0.5 here")
        return real(self, u, lam)

    monkeypatch.setattr(problems.EquilibriumProblem, "evaluate", refusing)
    path = tmp_path / "line.toml"
    path.write_text('name = "line"\nstates = ["x"]\n[parameters]\np = 1.0\n'
                    '[modes.m]\nx = "p - x"\n')
    out, png = tmp_path / "b.nc", tmp_path / "b.png"
    res = CliRunner().invoke(main, ["continue", str(path), "--param", "p", "--from", "1",
                                    "--to", "0", "--equilibrium", "--x0", "1",
                                    "--no-progress", "--out", str(out), "--plot", str(png)])
    assert res.exit_code == 1, res.output
    assert "STEP_BELOW_DS_MIN" in res.output and "p must be at least 0.5" in res.output
    br = load_branch(out)
    assert br.stop_status is Status.STEP_BELOW_DS_MIN and br.values.min() < 0.51
    assert png.read_bytes()[:4] == b"\x89PNG"


# ======================================================================================
# item 8: branch files carry a content hash
# ======================================================================================

@pytest.fixture(scope="module")
def fold_file(tmp_path_factory):
    br = pwsdyn.continue_equilibrium(FOLD, [1.0], "p", span=(-1, 2), ds=-0.05, max_points=12)
    return br, br.save(tmp_path_factory.mktemp("b") / "fold.nc")


def test_a_branch_file_round_trips_with_its_hash(fold_file):
    br, path = fold_file
    back = load_branch(path)
    assert np.array_equal(back.values, br.values)
    ds = br.to_dataset()
    assert len(ds.attrs["content_sha256"]) == 64


def _rewritten(path, tmp_path, change):
    from pwsdyn.io import open_dataset, save_dataset

    ds = open_dataset(path)
    change(ds)
    out = tmp_path / "changed.nc"
    save_dataset(ds, out, overwrite=True)
    return out


@pytest.mark.parametrize("change", [
    lambda ds: ds.attrs.update(params=ds.attrs["params"].replace("1.0", "1.5")),
    lambda ds: ds["p"].values.__setitem__(3, 0.123),
    lambda ds: ds["u"].values.__setitem__((2, 0), 7.0),
    lambda ds: ds["special"].values.__setitem__(1, "PD"),
    lambda ds: ds.attrs.update(stop_reason="edited"),
], ids=["params", "parameter", "unknowns", "special", "stop_reason"])
def test_a_changed_branch_file_is_refused(fold_file, tmp_path, change):
    """Before, a file whose parameters were edited after writing was accepted (and a resume
    from it jumped to another branch without a word)."""
    _, path = fold_file
    bad = _rewritten(path, tmp_path, change)
    with pytest.raises(ArgumentError, match="changed after it was written") as exc:
        load_branch(bad)
    assert "changed.nc" in str(exc.value)


def test_a_truncated_or_incomplete_branch_file_is_refused(fold_file, tmp_path):
    _, path = fold_file
    data = path.read_bytes()
    short = tmp_path / "short.nc"
    short.write_bytes(data[:len(data) // 2])
    with pytest.raises(ArgumentError, match="short.nc"):
        load_branch(short)
    # a variable missing, the hash rewritten to match: the file is incomplete
    from pwsdyn.continuation.branch import content_hash

    def drop(ds):
        import json

        del ds["tangent"]
        ds.attrs["content_sha256_variables"] = json.dumps(sorted(map(str, ds.variables)))
        ds.attrs["content_sha256"] = content_hash(ds)

    with pytest.raises(ArgumentError, match="not a complete branch file"):
        load_branch(_rewritten(path, tmp_path, drop))


def test_mutated_branch_files_fuzz(fold_file, tmp_path):
    """Bit flips and truncations anywhere in the file: each is read back equal to the
    original, or refused with pwsdyn's error (or warned about, where the flip hit the hash's
    own name) -- never an internal exception, never a changed branch accepted silently."""
    import warnings

    br, path = fold_file
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(23)
    internal, accepted_changed = [], 0
    for trial in range(120):
        buf = bytearray(data)
        if trial % 4 == 0:
            buf = buf[:int(rng.integers(0, len(buf)))]
        else:
            for _ in range(int(rng.integers(1, 4))):
                i = int(rng.integers(0, len(buf)))
                buf[i] ^= 1 << int(rng.integers(0, 8))
        f = tmp_path / f"m{trial}.nc"
        f.write_bytes(bytes(buf))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                back = load_branch(f)
            except ArgumentError:
                continue
            except Exception as exc:  # noqa: BLE001 -- counted
                internal.append(f"{type(exc).__name__}: {exc}")
                continue
        same = (len(back) == len(br) and np.array_equal(back.values, br.values)
                and all(np.array_equal(a.u, b.u) for a, b in zip(back.points, br.points))
                and [p.special for p in back.points] == [p.special for p in br.points])
        if not same and not caught:
            accepted_changed += 1
    assert internal == [] and accepted_changed == 0


# ======================================================================================
# item 8: max_points is a bound
# ======================================================================================

def test_max_points_is_a_hard_bound():
    """The fold of x' = p - x^2 at p = 0 is the 9th point of this branch: with max_points = 9
    it is located in the step that reaches the bound, and the step's own point joined the
    branch past it before (10 points)."""
    for n in range(2, 24):
        br = pwsdyn.continue_equilibrium(FOLD, [1.0], "p", span=(-1, 2), ds=-0.2, ds_max=0.4,
                                         max_points=n)
        assert len(br) <= n, n
        if n >= 9:
            assert [p.kind for p in br.special_points][0] == "LP"


# ======================================================================================
# items 4, 5: direction
# ======================================================================================

IO_MODEL = "impact-oscillator"


def _io_start():
    from _orbit_cases import io_orbit

    return io_orbit("stable")       # the one-impact orbit at omega = 2.8


def _increasing(br):
    s = np.array([p.arclength for p in br.points])
    return bool(np.all(np.diff(s) > 0))


@pytest.fixture(scope="module")
def io_both():
    """From omega = 2.8 inside (2.6, 3.0), no ds: both sides."""
    return pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(2.6, 3.0))


def test_both_sides_by_default(io_both):
    """Before: one side (up), the other half of the span never visited."""
    br = io_both
    assert abs(br.values.min() - 2.6) < 1e-12 and abs(br.values.max() - 3.0) < 1e-12
    # one branch through the start, ordered by arclength, the start once
    assert _increasing(br)
    assert np.sum(np.abs(br.values - 2.8) < 1e-12) == 1
    assert np.all(np.diff(br.values) > 0)          # no fold in (2.6, 3.0)
    assert [p.kind for p in br.special_points] == ["EP", "EP"]
    # every point on the closed-form one-impact orbit (tests/_orbit_cases.py)
    from test_continuation import _io_state_error

    assert _io_state_error(br) < 1e-8


@pytest.mark.parametrize("kw, lo, hi", [({"direction": "up"}, 2.8, 3.0),
                                        ({"direction": "down"}, 2.6, 2.8),
                                        ({"ds": -0.02}, 2.6, 2.8),
                                        ({"ds": 0.02}, 2.8, 3.0)])
def test_one_side_when_asked(kw, lo, hi):
    br = pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(2.6, 3.0),
                               max_points=40, **kw)
    assert abs(br.values.min() - lo) < 1e-12 and abs(br.values.max() - hi) < 1e-12


def test_a_start_on_the_boundary_goes_into_the_span():
    """The issue's case: from omega = 2.5 with span (2.0, 2.5) and no ds, two points and
    "reached the end of span" before."""
    orb = pwsdyn.find_periodic_orbit(IO_MODEL, [0.0, -0.5], params={"omega": 2.5})
    br = pwsdyn.continue_orbit(IO_MODEL, orb, "omega", span=(2.0, 2.5))
    assert abs(br.values.min() - 2.0) < 1e-12 and len(br) > 10


def test_a_start_outside_the_span_is_refused():
    """Before: accepted, special points outside the span reported."""
    with pytest.raises(ArgumentError, match="outside `span`"):
        pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(3.0, 3.5))
    with pytest.raises(ArgumentError, match="direction"):
        pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(2.6, 3.0), ds=-0.02,
                              direction="up")
    with pytest.raises(ArgumentError, match="direction"):
        pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(2.6, 3.0),
                              direction="sideways")


def test_a_resumed_branch_goes_where_ds_says(io_both):
    """Resumed from its last point (omega = 3.0, travelling up): a negative ds goes to smaller
    values -- before it retraced the branch, which goes up there -- and the default goes on
    up; the branch stays ordered by arclength."""
    down = pwsdyn.continue_orbit(IO_MODEL, pwsdyn.continue_orbit(
        IO_MODEL, _io_start(), "omega", span=(2.7, 2.8), direction="down"), "omega",
        span=(2.5, 2.8), ds=-0.02)
    assert abs(down.values.min() - 2.5) < 1e-12 and _increasing(down)
    assert np.all(np.diff(down.values) < 0)
    on = pwsdyn.continue_orbit(IO_MODEL, io_both, "omega", span=(2.6, 3.1), max_points=60)
    assert abs(on.values.max() - 3.1) < 1e-12 and _increasing(on)


def test_a_resume_or_special_point_of_another_model_is_refused(io_both):
    """Before: continued with the other model, labelled with it, holding the first's data."""
    spec = dict(pwsdyn.load_model(IO_MODEL).spec)
    spec["parameters"] = {**spec["parameters"], "r": 0.5}
    spec["name"] = "impact-oscillator-r05"
    with pytest.raises(ArgumentError, match="continue it with its own model"):
        pwsdyn.continue_orbit(spec, io_both, "omega", span=(2.6, 3.1))
    with pytest.raises(ArgumentError, match="continue it with its own model"):
        pwsdyn.continue_orbit(spec, io_both.special_points[-1], "omega", span=(2.6, 3.1))
    changed = Branch_copy(io_both)
    changed.points[-1].u = changed.points[-1].u + 1e-3
    with pytest.raises(ArgumentError, match="does not solve its problem"):
        pwsdyn.continue_orbit(IO_MODEL, changed, "omega", span=(2.6, 3.1))


def Branch_copy(br):
    from pwsdyn.continuation import Branch

    return Branch(br.problem, [p.to_point() for p in br.points], stop_reason=br.stop_reason,
                  stop_status=br.stop_status, settings=br.settings, model=br.model,
                  problems=br.problems)


# ======================================================================================
# item 8: continue_bifurcation checks every argument
# ======================================================================================

@pytest.fixture(scope="module")
def fake_pd():
    """A special point to hand to continue_bifurcation (the arguments are checked before any
    work; what the point is does not matter)."""
    br = pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(2.7, 2.9), max_points=1)
    br.points[0].special = "PD"
    return br.special("PD")[0]


@pytest.mark.parametrize("kw, match", [
    ({"span2": "ab"}, "span2"),
    ({"span2": (1.0, 0.0)}, "span2"),
    ({"span2": (math.nan, 1.0)}, "span2"),
    ({"span2": (0.0, 0.1)}, "outside `span2`"),
    ({"span": (3.0, 3.5)}, "outside `span`"),
    ({"span": "ab"}, "span"),
    ({"ds": math.nan}, "ds"),
    ({"max_points": 0}, "max_points"),
    ({"direction": "left"}, "direction"),
    ({"rtol": -1.0}, "rtol"),
    ({"no_such_option": 1}, "no_such_option"),
])
def test_continue_bifurcation_checks_its_arguments(fake_pd, kw, match):
    """Before: a string span2 gave numpy's UFuncTypeError, a reversed or NaN one a one-point
    curve; a start outside span a one-point curve "reached the end of span"."""
    with pytest.raises(ArgumentError, match=match):
        pwsdyn.continue_bifurcation(IO_MODEL, fake_pd, ("omega", "sigma"), **kw)


# ======================================================================================
# item 8: the grazing API refuses what overflows
# ======================================================================================

def test_grazing_api_refuses_overflowing_parameters_and_gains():
    """Parameters and gains of the friction impact oscillator's control design from 1e-300 to
    1e308 in every combination drawn: each call returns finite numbers or refuses with
    pwsdyn's error. Before: OverflowError (``omega**2``), ``math domain error`` (an arcsine
    of a constraint that never leaves the mass) and silent NaN (``inf - inf`` in the law)."""
    from pwsdyn.grazing.friction_impact import ControlGains, FrictionImpact

    vals = [1e-300, 1e-8, 0.5, 1.0, 3.0, 1e8, 1e154, 1e200, 1e308, -1e308, -1e200]
    names = ["m", "k", "Fs", "Fd", "a", "b", "omega", "e"]
    rng = np.random.default_rng(8)
    internal, nonfinite = [], []
    for _ in range(400):
        params = {str(k): float(rng.choice(vals))
                  for k in rng.choice(names, size=int(rng.integers(0, 3)), replace=False)}
        g = {k: float(rng.choice(vals)) for k in ["c_x", "c_a", "eps_1", "eps_2", "delta_1",
                                                   "delta_2"]}
        try:
            fi = FrictionImpact.from_params(params)
            gains = ControlGains(**g)
        except ArgumentError:
            continue
        calls = [lambda: fi.linear_map(gains), lambda: fi.law_b(0.5, gains),
                 lambda: fi.stick_map(0.5, gains=gains), lambda: fi.fixed_point(gains=gains),
                 lambda: fi.fixed_point(exact=True, gains=gains),
                 lambda: fi.excursion(0.5, gains), lambda: fi.fixed_point(),
                 lambda: fi.residual_error(ControlGains(**{**g, "c_x": 0.5})),
                 lambda: fi.stick_map(0.3, exact=True, gains=gains)]
        for call in calls:
            try:
                out = call()
            except ArgumentError:
                continue
            except Exception as exc:  # noqa: BLE001 -- counted
                internal.append(f"{type(exc).__name__}: {exc}")
                continue
            nums = ([v for k, v in out.items() if k != "theta" and not isinstance(v, bool)]
                    if isinstance(out, dict) else out)
            if not np.all(np.isfinite(np.asarray(nums, dtype=float))):
                nonfinite.append((params, g, out))
    assert internal == [] and nonfinite == []


def test_one_label_per_special_point_at_one_parameter_value():
    """A fold and a branch point located at the parameter value of a discontinuity-induced
    bifurcation (the relay's cycle: LP, BP and AS at one value) are its consequences: the
    DIB's label alone remains, whichever order they were located in. Before, only one of
    them lost its label."""
    from pwsdyn.continuation.engine import Point

    def pt(lam, kind):
        return Point(u=np.zeros(1), lam=lam, tangent=np.array([0.0, 1.0]), special=kind)

    for order in (["LP", "BP", "AS"], ["AS", "LP", "BP"], ["LP", "AS", "BP"]):
        cont = Continuation(_Refusing(ArgumentError("-")), [1.0], 1.0)
        cont.points = [pt(0.9, "")]
        for k, kind in enumerate(order):
            p = pt(1.0 + 1e-12 * k, kind)
            cont._fold_at_special(p)
            cont.points.append(p)
        assert [p.special for p in cont.points if p.special] == ["AS"], order


# ======================================================================================
# item 9: the graze from the impacting side; the diagram's default measure
# ======================================================================================

@pytest.fixture(scope="module")
def impacting_to_graze():
    """The one-impact orbit (omega = 2.8, eps = 0.1, r = 0.8) followed up in sigma until its
    impact velocity vanishes: the graze at the free motion's amplitude."""
    from _orbit_cases import io_orbit

    return pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "sigma", span=(-0.6, 0.4),
                                 ds=0.05, on_dib="stop")


def test_a_graze_from_the_impacting_side_states_its_singularity(impacting_to_graze):
    """Before: finite multipliers of order 1e12 at the graze (the saltation matrix's 1/v).
    Its place: the free motion x'' + eps x' + x = sin(omega t) (the zoo model's forcing) has
    amplitude R = 1 / sqrt((1 - omega^2)^2 + (eps omega)^2), where the stop grazes."""
    br = impacting_to_graze
    gr = br.special("GR")[0]
    omega, eps = 2.8, 0.1
    R = 1.0 / math.hypot(1 - omega**2, eps * omega)
    assert abs(gr.value - R) < 1e-8
    assert "@" in gr.key
    assert gr.multipliers.size and np.all(np.isnan(gr.multipliers))
    assert "saltation" in gr.point.data["singular"]
    others = [p for p in br.points if p.special != "GR"]
    assert all(np.all(np.isfinite(p.data["multipliers"])) for p in others)


def test_the_default_diagram_is_continuous_through_a_graze():
    """The README's branch in sigma through the graze (the stop moving into the free motion,
    the impacting orbit born there): the section state jumps at the graze (the branch was
    drawn as two pieces); the default measure, the largest x over the orbit, is continuous:
    it equals min(sigma, R) up to the graze (the orbit touches the stop), then R."""
    import matplotlib
    matplotlib.use("Agg")
    from pwsdyn.plot._branches import _branch_y

    params = {"eps": 0.1, "omega": 2.8, "sigma": 0.45}
    orbit = pwsdyn.find_periodic_orbit(IO_MODEL, [-0.006, -0.41], t0=0.0, params=params)
    br = pwsdyn.continue_orbit(IO_MODEL, orbit, "sigma", span=(0.0, 0.45), ds=-0.02,
                               max_points=40)
    assert len(br.signatures) == 2
    y, label = _branch_y(br, None)
    assert label.startswith("max")
    R = 1.0 / math.hypot(1 - 2.8**2, 0.1 * 2.8)
    # sampled at 400 points per orbit: the maximum to ~(pi / 400)^2 / 2 of the amplitude
    assert np.allclose(y, np.minimum(br.values, R), atol=5e-5 * R)
    fig = br.plot()
    assert fig.axes[0].get_ylabel().startswith("max")


# ======================================================================================
# every special point exactly once, for ds over a 40x range, in both directions
# ======================================================================================

@pytest.mark.slow
@pytest.mark.parametrize("ds", [0.005, 0.01, 0.02, 0.05, 0.2])
def test_each_special_point_once_for_any_step_either_way(ds):
    """The one-impact orbit's period doubling (going up, and coming back down from the end of
    the span as a resumed branch) and its fold (going down): each exactly once, at its closed
    form (tests/_orbit_cases.py) to 1e-8, for first steps from 0.005 to 0.2."""
    from scipy.optimize import brentq

    from _orbit_cases import io_one_impact
    from test_continuation import _pd_value

    w_pd = _pd_value(lambda w: io_one_impact(w, 1)[2], 4.2, 4.4)
    w_lp = brentq(lambda w: io_one_impact(w, 1)[3], 2.1, 2.3, xtol=1e-15)
    up = pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(2.8, 4.6), ds=ds,
                               max_points=400)
    kinds = [p.kind for p in up.special_points]
    assert kinds == ["PD", "EP"], kinds
    assert abs(up.special("PD")[0].value - w_pd) < 1e-8
    back = pwsdyn.continue_orbit(IO_MODEL, up, "omega", span=(2.8, 4.6), ds=-ds,
                                 max_points=800)
    new = [p.kind for p in back.special_points if p.index >= len(up) - 1]
    assert new == ["PD", "EP"], new
    assert all(abs(p.value - w_pd) < 1e-8 for p in back.special("PD"))
    down = pwsdyn.continue_orbit(IO_MODEL, _io_start(), "omega", span=(1.9, 2.8), ds=-ds,
                                 max_points=400)
    lp = down.special("LP")
    assert len(lp) == 1 and abs(lp[0].value - w_lp) < 1e-8
    assert [p.kind for p in down.special_points if p.kind not in ("LP", "EP")] == []


@pytest.mark.slow
def test_grazing_command_says_when_its_orbit_is_unstable_or_of_period_k():
    """The README's grazing example without its --x0: the settling run finds the period-2
    attractor, and the orbit followed to the graze is unstable. Before, the command stated a
    scenario "of a local attractor" about it; now it says what the orbit is."""
    from click.testing import CliRunner

    from pwsdyn.cli import main

    res = CliRunner().invoke(main, ["grazing", "impact-oscillator", "--param", "sigma",
                                    "--from", "0.45", "--to", "0.0", "-p", "omega=2.8",
                                    "-p", "eps=0.1", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert "of a local attractor" not in res.output
    note = [ln for ln in res.output.splitlines() if ln.startswith("note")]
    assert note and "unstable" in note[0] and "period 2" in note[0]


def test_a_resumed_branch_honours_on_dib_and_integrator_options():
    """Before: a resumed branch ran through the graze onto points that are not orbits of the
    model (on_dib ignored) and dropped the integrator options given."""
    from _orbit_cases import io_orbit

    first = pwsdyn.continue_orbit(IO_MODEL, io_orbit("stable"), "sigma", span=(-0.6, 0.0),
                                  ds=0.05)
    more = pwsdyn.continue_orbit(IO_MODEL, first, "sigma", span=(-0.6, 0.4), on_dib="stop",
                                 rtol=1e-11)
    assert more.stop_status is Status.STOP_AT_SPECIAL_POINT
    assert more.special_points[-1].kind == "GR" and more.admissible.all()
    R = 1.0 / math.hypot(1 - 2.8**2, 0.1 * 2.8)
    assert abs(more.special_points[-1].value - R) < 1e-8
    last = more.points[-1]
    assert more.problem_of(last).orbit_problem.opts["rtol"] == 1e-11
    assert _increasing(more) and len(more) > len(first)
