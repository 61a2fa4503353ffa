"""One vocabulary of outcomes, one discrete-state type, one event-log type, one direction of
imports.

* every status a run, a sweep, basins, a Lyapunov spectrum, a map iteration or an orbit solve
  can report is a distinct member of :class:`pwsdyn.Status` with a message, and every file's
  ``status`` flags are made from it; a map state that no piece claims is ``NO_PIECE_APPLIES``
  (its code used to be that of ``MAX_STEPS``), and files written with the old map codes still
  decode by their own flags;
* the discrete states of a run are :class:`DiscreteState` values, equal to the text they have
  always been;
* ``Trajectory.events`` is an :class:`EventLog` whatever made the trajectory, a file included;
* the model layer imports no integrator, argument checks import no model, the trajectory
  imports no ``pwsdyn.io``.
"""

from __future__ import annotations

import ast
import pickle
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import pwsdyn
from pwsdyn import Status
from pwsdyn.errors import ORBIT_FAILURES
from pwsdyn.integrate import DiscreteState, EventLog
from pwsdyn.io import decode_status, load_trajectory, open_dataset, run_status_codes
from pwsdyn.orbits import OrbitError

SRC = Path(pwsdyn.__file__).resolve().parent
DATA = Path(__file__).parent / "data"

#: A map whose only piece claims x <= 0: from x > 0 no piece applies.
HALF_MAP = {"name": "half-map", "kind": "map", "states": ["x"], "parameters": {"a": 0.5},
            "pieces": [{"name": "left", "condition": "x <= 0", "map": {"x": "a*x + 1"}}]}


# ======================================================================================
# one status vocabulary
# ======================================================================================

def test_every_outcome_is_a_distinct_member_with_a_message():
    values = [int(s) for s in Status]
    assert len(set(values)) == len(values)
    assert len({s.meaning for s in Status}) == len(Status)
    for s in Status:
        assert isinstance(s.message, str) and s.message.strip(), s
        assert Status.from_meaning(s.meaning) is s
    # the integrator's codes keep the values files have always held
    assert [s.name for s in Status.integrator_outcomes()] == [
        "SUCCESS", "TERMINAL_EVENT", "MAX_STEPS", "MAX_EVENTS", "STEP_TOO_SMALL", "NONFINITE",
        "SURFACE_INTERSECTION", "ZENO"]
    assert int(Status.DIVERGED) == -1 and int(Status.SECTION_MISSED) == -3
    # the analyses' own outcomes can never be read as the integrator's
    analysis = {Status.DIVERGED, Status.SECTION_MISSED, Status.NO_PIECE_APPLIES,
                *ORBIT_FAILURES}
    assert not analysis & set(Status.integrator_outcomes())


@pytest.mark.parametrize("is_map", [False, True])
@pytest.mark.parametrize("section_missed", [False, True])
def test_file_flags_are_made_of_members(is_map, section_missed):
    codes = run_status_codes(is_map=is_map, section_missed=section_missed)
    for value, meaning in codes.items():
        assert Status(value).meaning == meaning
    assert codes[int(Status.DIVERGED)] == "diverged"
    if is_map:
        assert codes[int(Status.NO_PIECE_APPLIES)] == "no_piece_applies"
        assert int(Status.MAX_STEPS) not in codes


def test_orbit_error_reason_and_status():
    reasons = {"singular", "phase", "equilibrium", "signature", "budget", "no_progress",
               "diverged", "simulation"}
    assert {s.reason for s in ORBIT_FAILURES} == reasons
    for reason in reasons:
        err = OrbitError(reason, "message")
        assert err.reason == reason and err.status in ORBIT_FAILURES
        assert OrbitError(err.status, "message").reason == reason
    assert OrbitError("diverged", "m").status is Status.NEWTON_DIVERGED
    with pytest.raises(ValueError, match="unknown orbit failure"):
        OrbitError("no such reason", "m")


def test_an_orbit_failure_carries_its_status():
    with pytest.raises(OrbitError) as info:
        pwsdyn.find_periodic_orbit("impact-oscillator", [-0.7, 0.0], max_iter=1,
                                   params={"eps": 0.1, "sigma": -0.5, "omega": 2.8})
    assert info.value.status is Status.of_orbit(info.value.reason)
    assert info.value.status.failed


def test_a_map_with_no_applicable_piece_is_not_max_steps():
    model = pwsdyn.load_model(HALF_MAP)
    ds = pwsdyn.sweep(model, "a", [0.5, 0.6], [1.0], transient=2, samples=4, workers=1,
                      progress=False, lyapunov=True)
    assert (ds["status"].values == int(Status.NO_PIECE_APPLIES)).all()
    assert all(s is Status.NO_PIECE_APPLIES for s in decode_status(ds["status"]).ravel())
    res = pwsdyn.lyapunov_spectrum(model, [1.0], duration=10)
    assert res.status is Status.NO_PIECE_APPLIES
    # basins: a start whose orbit no piece claims has failed; it has not diverged (-1)
    b = pwsdyn.basins(model, {"x": [-0.5, 0.5]}, transient=2, samples=4, workers=1,
                      progress=False)
    assert (b["label"].values == -2).all()


def test_sweep_and_lyapunov_statuses_decode():
    ds = pwsdyn.sweep("bouncing-ball", "A", [0.2, 0.25], {"y": 1.5, "v": 0.0}, transient=5,
                      samples=8, workers=1, progress=False)
    assert all(s is Status.SUCCESS for s in decode_status(ds["status"]).ravel())
    res = pwsdyn.lyapunov_spectrum("sqrt-map", [0.0], {"mu": 0.02}, duration=100, bound=1e-3)
    assert res.status is Status.DIVERGED and isinstance(res.status, Status)


def test_old_map_codes_decode_by_their_flags():
    """A map sweep written before the codes were members of Status: 2 meant no piece applies
    and 3 non-finite (the values of MAX_STEPS and MAX_EVENTS)."""
    old = xr.DataArray(np.array([0, 2, 3, -1], dtype=np.int64), dims="mu",
                       attrs={"flag_values": np.array([-1, 0, 2, 3], dtype=np.int64),
                              "flag_meanings": "diverged success no_piece_applies nonfinite"})
    assert list(decode_status(old)) == [Status.SUCCESS, Status.NO_PIECE_APPLIES,
                                        Status.NONFINITE, Status.DIVERGED]
    # files without flags hold the values of the members
    sweep = open_dataset(DATA / "pre_cf" / "sweep.nc")
    assert all(isinstance(s, Status) for s in decode_status(sweep["status"]).ravel())


# ======================================================================================
# one discrete-state type
# ======================================================================================

def test_discrete_state_value():
    s = DiscreteState("stick", "impact")
    assert s == "stick:impact" and str(s) == "stick:impact" and type(str(s)) is str
    assert hash(s) == hash("stick:impact") and {s: 1}["stick:impact"] == 1
    assert (s.kind, s.name, s.code, s.is_mode) == ("stick", "impact", 1, False)
    assert DiscreteState.parse("stick:impact") == s and DiscreteState.parse(s) is s
    m = DiscreteState.parse("flight")
    assert (m.kind, m.name, m.code, m.is_mode) == ("mode", "flight", 0, True)
    assert DiscreteState.parse("slide:belt") == DiscreteState("slide", "belt")
    back = pickle.loads(pickle.dumps(s))
    assert back == s and type(back) is DiscreteState and back.kind == "stick"
    assert sorted([DiscreteState.parse("b"), DiscreteState.parse("a")]) == ["a", "b"]
    with pytest.raises(AttributeError):
        s.kind = "mode"
    for bad in ("stuck:impact", "stick:", 3):
        with pytest.raises(ValueError):
            DiscreteState.parse(bad)
    with pytest.raises(ValueError):
        DiscreteState("hover", "x")


def test_event_states_are_discrete_states_equal_to_their_text():
    traj = pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0.0, 5.0),
                           params={"A": 0.05, "omega": 10.0, "e": 0.5})
    kinds = set()
    for e in traj.events:
        for st in (e.mode_before, e.mode_after):
            assert isinstance(st, DiscreteState)
            assert st == str(st) and DiscreteState.parse(str(st)) == st
            kinds.add(st.kind)
    assert "stick" in kinds and "mode" in kinds
    assert all(DiscreteState.parse(s).kind in ("mode", "stick") for s in set(traj.state))


# ======================================================================================
# EventLog always
# ======================================================================================

def _same_log(a: EventLog, b: EventLog):
    assert isinstance(a, EventLog) and isinstance(b, EventLog)
    assert len(a) == len(b)
    for ea, eb in zip(a, b):
        assert (ea.t, ea.t_after, ea.name, ea.kind, ea.mode_before, ea.mode_after) == \
            (eb.t, eb.t_after, eb.name, eb.kind, eb.mode_before, eb.mode_after)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.t_after, b.t_after)
    np.testing.assert_array_equal(a.kind_code, b.kind_code)
    np.testing.assert_array_equal(a.ref, b.ref)
    assert list(a.kind) == list(b.kind) and list(a.name) == list(b.name)
    np.testing.assert_array_equal(a.state_after[:, :2], b.state_after[:, :2])
    np.testing.assert_array_equal(a.x_before, b.x_before)
    np.testing.assert_array_equal(a.x_after, b.x_after)


def test_events_are_an_event_log_after_a_file_round_trip(tmp_path):
    traj = pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0.0, 5.0),
                           params={"A": 0.05, "omega": 10.0, "e": 0.5})
    assert isinstance(traj.events, EventLog) and len(traj.events) > 0
    back = load_trajectory(traj.save(tmp_path / "run.nc"))
    _same_log(traj.events, back.events)
    assert all(isinstance(e.mode_after, DiscreteState) for e in back.events)
    assert back.sliding_intervals() == traj.sliding_intervals()
    # the dataset was made from public attributes and reads back through the constructor
    np.testing.assert_array_equal(back.y, traj.y)
    np.testing.assert_array_equal(back.interval_kind, traj.interval_kind)
    np.testing.assert_array_equal(np.asarray(back.dense), np.asarray(traj.dense))
    old = load_trajectory(DATA / "pre_cf" / "trajectory.nc")
    assert isinstance(old.events, EventLog) and len(old.events) > 0


def test_a_list_of_records_becomes_an_event_log():
    traj = pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0.0, 2.0))
    copy = pwsdyn.Trajectory.from_parts(
        t=traj.t, x=traj.x, state=traj.state, events=list(traj.events), status=traj.status,
        message=traj.message, stats=traj.stats, model=traj.model, params=traj.params,
        options=traj.options, t0=traj.t0, t_end=traj.t_end, dense=traj.dense,
        interval_kind=traj.interval_kind, y=traj.y)
    _same_log(traj.events, copy.events)
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.7, 0.0],
                                       params={"eps": 0.1, "sigma": -0.5, "omega": 2.8})
    assert isinstance(orbit.trajectory.events, EventLog)


# ======================================================================================
# dependencies one way
# ======================================================================================

def _imports(path: Path) -> set:
    """Every pwsdyn module ``path`` imports, at module level or inside a function."""
    mod = ".".join(("pwsdyn",) + path.relative_to(SRC).with_suffix("").parts)
    pkg = mod.removesuffix(".__init__") if path.name == "__init__.py" else mod.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return {m for m in out if m.startswith("pwsdyn")}


@pytest.mark.parametrize("files, forbidden", [
    ("model/*.py", ("pwsdyn.integrate", "pwsdyn.stability", "pwsdyn.orbits", "pwsdyn.explore",
                    "pwsdyn.io", "pwsdyn._netcdf")),
    ("_validate.py", ("pwsdyn.model", "pwsdyn.integrate")),
    ("_netcdf.py", ("pwsdyn.model", "pwsdyn.integrate", "pwsdyn.orbits", "pwsdyn.explore",
                    "pwsdyn.io")),
    # the kernel, the options and the compiled-model layer below every analysis
    ("integrate/*.py", ("pwsdyn.io", "pwsdyn.stability", "pwsdyn.orbits", "pwsdyn.explore",
                        "pwsdyn.continuation", "pwsdyn.grazing", "pwsdyn.plot", "pwsdyn.cli")),
    ("orbits/_base.py", ("pwsdyn.orbits._orbit", "pwsdyn.orbits._shooting",
                         "pwsdyn.orbits.problem")),
    ("orbits/problem.py", ("pwsdyn.orbits._shooting",)),
    ("model/discontinuities.py", ("pwsdyn.model.spec",)),
    ("model/elements.py", ("pwsdyn.model.spec", "pwsdyn.model.discontinuities")),
    ("model/maps.py", ("pwsdyn.model.codegen",)),
    ("model/_map_kernels.py", ("pwsdyn.model.maps",)),
])
def test_imports_run_one_way(files, forbidden):
    bad = {(str(p.relative_to(SRC)), m) for p in SRC.glob(files) for m in _imports(p)
           if m.startswith(forbidden)}
    assert bad == set()


def _reachable(module: str) -> set:
    """Every pwsdyn module ``module`` loads, directly or through the modules it imports, at
    module level or inside a function (the package ``pwsdyn`` itself, which loads everything
    on purpose, left out)."""
    def path(mod):
        p = SRC.joinpath(*mod.split(".")[1:])
        return p.with_suffix(".py") if p.with_suffix(".py").exists() else (
            p / "__init__.py" if (p / "__init__.py").exists() else None)

    seen, todo = set(), [module]
    while todo:
        m = todo.pop()
        if m in seen or m == "pwsdyn" or path(m) is None:
            continue
        seen.add(m)
        todo.extend(_imports(path(m)))
    return seen


def test_trajectory_file_layout_is_a_lower_layer():
    """The trajectory's file layout reaches no result type and no ``pwsdyn.io``, even through
    function-local imports, so the trajectory's ``to_dataset``/``from_dataset``/``save``
    calling it close no circle; ``pwsdyn.io`` reaches the layout through the trajectory."""
    below = _reachable("pwsdyn._trajectory_file")
    assert "pwsdyn._netcdf" in below and "pwsdyn.model" in below
    assert not {m for m in below if m.startswith(("pwsdyn.integrate", "pwsdyn.io",
                                                  "pwsdyn.stability", "pwsdyn.orbits",
                                                  "pwsdyn.explore", "pwsdyn.continuation"))}
    assert "pwsdyn._trajectory_file" in _imports(SRC / "integrate" / "trajectory.py")
    assert {"pwsdyn.integrate.trajectory", "pwsdyn._trajectory_file"} <= _reachable("pwsdyn.io")
