"""NetCDF round trips of trajectories (pwsdyn.io).

A saved and reloaded trajectory must be the same trajectory: the same nodes, event log,
status and provenance, and a dense output that evaluates to the same bits at any time.
"""

import json
import math

import numpy as np
import pytest
import sympy as sp
import xarray as xr

import pwsdyn
from pwsdyn import Status
from pwsdyn.integrate import DiscreteState
from pwsdyn.io import (load_trajectory, open_dataset, save_dataset, trajectory_from_dataset,
                       trajectory_to_dataset)

VIBRATING = dict(params={"A": 0.05, "omega": 10.0, "e": 0.5})

#: A dry-friction oscillator on a belt, as a Filippov switch: it slides on v = vb.
BELT = {
    "name": "belt-test",
    "states": ["x", "v"],
    "parameters": {"k": 1.0, "vb": 0.2, "mu": 1.0},
    "modes": {"slow": {"x": "v", "v": "-k*x + mu"}, "fast": {"x": "v", "v": "-k*x - mu"}},
    "switches": [{"name": "belt", "surface": "v - vb", "above": "fast", "below": "slow"}],
}

#: x' = x^2 blows up at t = 1 / x0: a run that fails, with one state and no events.
BLOWUP = {"name": "blowup", "states": ["x"], "modes": {"m": {"x": "x**2"}}}


def _vibrating(**options):
    return pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0.0, 5.0),
                           **VIBRATING, **options)


@pytest.fixture(scope="module")
def trajectories():
    """Trajectories covering every field: impacts, chattering, sticking, sliding, the
    variational part, no dense output, DOP853, a failed run without events."""
    return {
        "vibrating": _vibrating(),
        "variational": _vibrating(variational=True),
        "nodense": _vibrating(dense=False),
        "dop853": _vibrating(method="DOP853", max_step=0.05),
        "belt": pwsdyn.simulate(BELT, {"x": 2.0, "v": 0.0}, (0.0, 20.0)),
        "failed": pwsdyn.simulate(BLOWUP, [1.0], (0.0, 2.0), throw=False),
    }


def _roundtrip(traj, tmp_path, name="traj.nc"):
    path = tmp_path / name
    save_dataset(trajectory_to_dataset(traj), path)
    return load_trajectory(path)


def _assert_same_events(a, b):
    assert len(a.events) == len(b.events)
    for ea, eb in zip(a.events, b.events):
        assert ea.t == eb.t
        assert ea.t_after == eb.t_after
        assert ea.name == eb.name and type(eb.name) is str
        assert ea.kind == eb.kind and type(eb.kind) is str
        # discrete states are DiscreteState values (a str), never numpy strings or bytes
        assert ea.mode_before == eb.mode_before and type(eb.mode_before) is DiscreteState
        assert ea.mode_after == eb.mode_after and type(eb.mode_after) is DiscreteState
        np.testing.assert_array_equal(ea.x_before, eb.x_before)
        np.testing.assert_array_equal(ea.x_after, eb.x_after)


@pytest.mark.parametrize("key", ["vibrating", "variational", "nodense", "dop853", "belt",
                                 "failed"])
def test_roundtrip_preserves_everything(trajectories, tmp_path, key):
    a = trajectories[key]
    b = _roundtrip(a, tmp_path)
    np.testing.assert_array_equal(b.t, a.t)
    np.testing.assert_array_equal(b.x, a.x)
    np.testing.assert_array_equal(b._y, a._y)
    assert b.state.dtype.kind == "U"
    np.testing.assert_array_equal(b.state, a.state)
    np.testing.assert_array_equal(b._ikind, a._ikind)
    if a._dense is None:
        assert b._dense is None
    else:
        np.testing.assert_array_equal(b._dense, a._dense)
    if a.jacobian is None:
        assert b.jacobian is None
    else:
        np.testing.assert_array_equal(b.jacobian, a.jacobian)
    _assert_same_events(a, b)
    assert b.status is a.status
    assert b.message == a.message
    assert b.stats == a.stats
    assert b.params == a.params
    assert b.options == a.options  # includes max_step = inf and first_step = None
    assert (b.t0, b.t_end) == (a.t0, a.t_end)
    assert b.provenance == a.provenance
    assert b.model.name == a.model.name
    assert b.model.hash == a.model.hash
    assert b.model.states == a.model.states


@pytest.mark.parametrize("key", ["vibrating", "variational", "dop853", "belt", "failed"])
def test_dense_output_identical_after_roundtrip(trajectories, tmp_path, key):
    a = trajectories[key]
    b = _roundtrip(a, tmp_path)
    # a fine grid plus the exact node and event times, where the sides differ
    ts = np.concatenate([np.linspace(a.t[0], a.t[-1], 20001), a.t,
                         [e.t for e in a.events], [e.t_after for e in a.events]])
    for side in ("left", "right"):
        np.testing.assert_array_equal(b(ts, side=side), a(ts, side=side))
    if a.jacobian is not None:
        np.testing.assert_array_equal(b(ts, variational=True), a(ts, variational=True))
    # and the sampled curve used by the plots
    for ua, ub in zip(a.sample(3000), b.sample(3000)):
        np.testing.assert_array_equal(ub, ua)


def test_roundtrip_in_memory(trajectories):
    a = trajectories["vibrating"]
    b = trajectory_from_dataset(a.to_dataset())
    np.testing.assert_array_equal(b.t, a.t)
    _assert_same_events(a, b)
    # the Trajectory methods delegate to pwsdyn.io
    c = pwsdyn.Trajectory.from_dataset(a.to_dataset())
    np.testing.assert_array_equal(c(2.5), a(2.5))


def test_dataset_layout(trajectories):
    a = trajectories["variational"]
    ds = trajectory_to_dataset(a)
    n, N, ne = 2, len(a.t), len(a.events)
    assert list(ds["state"].values) == ["y", "v"]
    assert ds["t"].dims == ("node",) and ds.sizes["node"] == N
    assert ds["x"].dims == ("node", "state")
    assert ds["y"].dims == ("node", "ycomp") and ds.sizes["ycomp"] == n + n * n
    assert ds["dense"].dims == ("interval", "ycomp", "power")
    assert ds.sizes["interval"] == N - 1
    assert ds["interval_kind"].dims == ("interval",)
    assert ds["jacobian"].dims == ("state", "state_in")
    assert ds.sizes["event"] == ne
    for var in ("event_t", "event_t_after", "event_name", "event_kind", "event_mode_before",
                "event_mode_after"):
        assert ds[var].dims == ("event",)
    assert ds["event_x_before"].dims == ("event", "state")
    assert ds["event_x_after"].dims == ("event", "state")
    assert list(ds["event_kind"].values) == [e.kind for e in a.events]
    assert list(ds["discrete_state"].values) == list(a.state)
    np.testing.assert_array_equal(ds["event_x_after"].values,
                                  np.array([e.x_after for e in a.events]))

    attrs = ds.attrs
    assert attrs["model"] == "bouncing-ball"
    assert attrs["model_hash"] == a.model.hash
    assert attrs["status"] == "SUCCESS"
    assert attrs["pwsdyn_version"] == pwsdyn.__version__
    assert (attrs["t0"], attrs["t_end"]) == (0.0, 5.0)

    def strict(text):
        # strict JSON: no Infinity/NaN tokens, which other JSON readers reject
        return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON {c}"))

    options = strict(attrs["options"])
    assert options["max_step"] == "inf"
    assert options["variational"] is True
    assert strict(attrs["params"]) == {"g": 9.81, "e": 0.5, "A": 0.05, "omega": 10.0}
    assert strict(attrs["stats"]) == a.stats
    # the stored definition rebuilds the same model
    assert pwsdyn.load_model(json.loads(attrs["model_spec"])).hash == a.model.hash


def test_optional_variables_omitted(trajectories):
    ds = trajectory_to_dataset(trajectories["nodense"])
    assert "dense" not in ds and "jacobian" not in ds
    failed = trajectory_to_dataset(trajectories["failed"])
    assert failed.sizes["event"] == 0
    assert failed.attrs["status"] == trajectories["failed"].status.name != "SUCCESS"


def test_failed_trajectory_keeps_status(trajectories, tmp_path):
    a = trajectories["failed"]
    assert a.status.failed
    b = _roundtrip(a, tmp_path)
    assert b.status is a.status and b.status.failed
    assert b.events == [] and b.success is False


def test_reloaded_model_simulates_the_same(trajectories, tmp_path):
    # the model, parameters and options in the file are enough to reproduce the run
    a = trajectories["vibrating"]
    b = _roundtrip(a, tmp_path)
    opts = {k: v for k, v in b.options.items()}
    c = pwsdyn.simulate(b.model, b.x[0], (b.t0, b.t_end), params=b.params, **opts)
    np.testing.assert_array_equal(c.t, a.t)
    np.testing.assert_array_equal(c.x, a.x)


def test_sympy_model_definition_roundtrip(tmp_path):
    """A model given as SymPy expressions is stored as parser-readable text, losslessly."""
    y, v, A = (sp.Symbol(s, real=True) for s in ("y", "v", "A"))
    spec = {
        "name": "sympy-ball", "states": ["y", "v"], "parameters": {"A": 0.1},
        "modes": {"m": {"y": v, "v": -9.81 - sp.Rational(1, 3) * v + 0.1 * sp.E * y}},
        "events": [{"name": "floor", "kind": "impact", "surface": y - A * sp.sin(sp.pi * y),
                    "reset": {"v": -sp.Float(0.1234567890123456789) * v},
                    "guard": sp.And(v < 0, y > -1)}],
    }
    a = pwsdyn.simulate(spec, {"y": 1.0, "v": 0.0}, (0.0, 1.0))
    b = _roundtrip(a, tmp_path)
    assert b.model.hash == a.model.hash
    np.testing.assert_array_equal(b(np.linspace(0, 1, 101)), a(np.linspace(0, 1, 101)))


def test_model_read_differently_warns(tmp_path):
    # the expression parser reads literals as doubles, so a 70-bit SymPy Float cannot come back
    # exactly: the reloaded model differs, and the user is told so
    v = sp.Symbol("v", real=True)
    spec = {"name": "hp", "states": ["y", "v"],
            "modes": {"m": {"y": v, "v": -sp.Float("9.8100000000000000001", 21)}}}
    a = pwsdyn.simulate(spec, [1.0, 0.0], (0.0, 0.1))
    with pytest.warns(UserWarning, match="hash"):
        b = _roundtrip(a, tmp_path)
    np.testing.assert_array_equal(b.t, a.t)


def test_save_overwrites_atomically(trajectories, tmp_path):
    path = tmp_path / "run.nc"
    save_dataset(trajectories["vibrating"], path)  # a Trajectory is accepted too
    with pytest.raises(FileExistsError, match="run.nc"):  # only when asked to
        save_dataset(trajectories["belt"].to_dataset(), path)
    assert load_trajectory(path).model.name != "belt-test"
    save_dataset(trajectories["belt"].to_dataset(), path, overwrite=True)
    assert load_trajectory(path).model.name == "belt-test"
    before = path.read_bytes()

    bad = trajectories["vibrating"].to_dataset()
    bad.attrs["not_storable"] = {"a": 1}  # NetCDF attributes cannot be dicts
    with pytest.raises(Exception):
        save_dataset(bad, path, overwrite=True)
    # the old file is intact and no temporary file is left behind
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.nc"]


def test_save_errors_name_the_path(trajectories, tmp_path):
    with pytest.raises(FileNotFoundError, match="no-such-dir"):
        save_dataset(trajectories["vibrating"].to_dataset(), tmp_path / "no-such-dir" / "a.nc")
    with pytest.raises(TypeError, match="Dataset or a Trajectory"):
        save_dataset([1, 2], tmp_path / "a.nc")
    with pytest.raises(FileNotFoundError, match="missing.nc"):
        load_trajectory(tmp_path / "missing.nc")


def test_foreign_dataset_is_rejected(tmp_path):
    path = tmp_path / "other.nc"
    save_dataset(xr.Dataset({"a": ("x", np.arange(3.0))}), path)
    ds = open_dataset(path)
    np.testing.assert_array_equal(ds["a"].values, np.arange(3.0))
    with pytest.raises(ValueError, match="not a pwsdyn trajectory"):
        load_trajectory(path)


def test_open_dataset_lazy_and_eager(trajectories, tmp_path):
    path = tmp_path / "run.nc"
    trajectories["vibrating"].save(path)
    eager = open_dataset(path)
    path.unlink()  # an eager dataset no longer needs the file
    np.testing.assert_array_equal(eager["t"].values, trajectories["vibrating"].t)
    trajectories["vibrating"].save(path)
    with open_dataset(path, lazy=True) as lazy:
        assert lazy.sizes["node"] == len(trajectories["vibrating"].t)


def test_status_and_inf_options_restored(trajectories, tmp_path):
    b = _roundtrip(trajectories["vibrating"], tmp_path)
    assert isinstance(b.status, Status)
    assert b.options["max_step"] == math.inf and isinstance(b.options["max_step"], float)
    assert b.options["first_step"] is None
    # the pair that ran: the default method "auto" is DOP853 at rtol 1e-10
    assert b.options["method"] == "DOP853" and b.options["exact"] == "auto"
