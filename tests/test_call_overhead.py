"""What ``simulate()`` and ``load_model`` keep between calls, and that nothing kept leaks.

A model file is parsed once while it is unchanged, but every load returns a model of its own;
an edited file is read again. ``simulate`` keeps per-model and per-option work, never the
parameter values or the caller's model: results stay those of a call with nothing kept.
(Timings are in ``benchmarks/bench_overhead.py``, never asserted here.)
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

import pwsdyn
from pwsdyn import ArgumentError
from pwsdyn.model import spec

MODEL = """
name = "osc"
states = ["x", "v"]
forcing_period = "2*pi/omega"

[parameters]
k = {k}
omega = 2.0

[modes.free]
x = "v"
v = "sin(omega*t) - k*x"

[[events]]
name = "stop"
kind = "impact"
surface = "1 - x"
direction = -1
reset = {{ v = "-0.5*v" }}

[defaults]
x0 = {{ x = 0.5, v = 0.0 }}
t_end = 3.0
"""

#: An old modification time: a file last modified this long ago may be cached
OLD = 1_600_000_000


@pytest.fixture
def parses(monkeypatch):
    """The number of times a model is built from parsed TOML."""
    calls = []
    build = spec.model_from_dict

    def counting(*args, **kwargs):
        calls.append(kwargs.get("origin"))
        return build(*args, **kwargs)

    monkeypatch.setattr(spec, "model_from_dict", counting)
    return calls


def _write(path, k, mtime):
    path.write_text(MODEL.format(k=k))
    os.utime(path, (mtime, mtime))


def test_a_model_by_name_is_parsed_once_and_each_load_is_its_own(parses):
    spec._LOADED.clear()
    first = pwsdyn.load_model("impact-oscillator")
    assert len(parses) == 1
    again = pwsdyn.load_model("impact-oscillator")
    assert len(parses) == 1                          # from the cache
    assert again is not first
    # a caller changing its model (every dict, nested ones too) changes no later load
    first.parameters["omega"] = 99.0
    first.spec["parameters"]["omega"] = 99.0
    first.spec["defaults"]["x0"]["x"] = 7.0
    first.units["x"] = "furlong"
    first.descriptions.clear()
    first.definitions["extra"] = 1
    third = pwsdyn.load_model("impact-oscillator")
    for m in (again, third):
        assert m.parameters["omega"] == 2.5
        assert m.spec["parameters"]["omega"] == 2.5
        assert m.defaults["x0"] == {"x": -0.5, "v": 0.0}
        assert m.units["x"] == "1" and m.descriptions and "extra" not in m.definitions
    assert third.digest == first.digest and third.hash == first.hash
    assert third.parameters is not again.parameters and third.spec is not again.spec


def test_a_map_by_name_is_copied_too(parses):
    spec._LOADED.clear()
    a = pwsdyn.load_model("sqrt-map")
    b = pwsdyn.load_model("sqrt-map")
    assert len(parses) == 1 and type(b) is type(a) and b.pieces == a.pieces
    a.parameters[next(iter(a.parameters))] = 123.0
    assert 123.0 not in pwsdyn.load_model("sqrt-map").parameters.values()


def test_an_edited_model_file_is_read_again(tmp_path, parses):
    path = tmp_path / "osc.toml"
    _write(path, 1.0, OLD)
    assert pwsdyn.load_model(path).parameters["k"] == 1.0
    assert pwsdyn.load_model(str(path)).parameters["k"] == 1.0
    n = len(parses)
    assert pwsdyn.load_model(path).parameters["k"] == 1.0
    assert len(parses) == n                          # unchanged: not parsed again
    # the same size and another modification time
    _write(path, 3.0, OLD + 10)
    assert pwsdyn.load_model(path).parameters["k"] == 3.0
    # another size and the same modification time
    _write(path, 3.25, OLD + 10)
    assert pwsdyn.load_model(path).parameters["k"] == 3.25
    # replaced by another file (another inode) with the same size and time
    other = tmp_path / "other.toml"
    _write(other, 4.25, OLD + 10)
    os.replace(other, path)
    assert pwsdyn.load_model(path).parameters["k"] == 4.25


def test_a_file_modified_just_now_is_not_cached(tmp_path, parses):
    # a second edit within the file system's timestamp resolution could keep its key
    path = tmp_path / "osc.toml"
    path.write_text(MODEL.format(k=1.0))
    pwsdyn.load_model(path)
    pwsdyn.load_model(path)
    assert len(parses) == 2


def test_load_errors_are_unchanged(tmp_path):
    with pytest.raises(pwsdyn.ModelError, match="no model file 'no-such-model'"):
        pwsdyn.load_model("no-such-model")
    path = tmp_path / "bad.toml"
    path.write_text("name = 'x'\nstates = [\n")
    os.utime(path, (OLD, OLD))
    for _ in range(2):
        with pytest.raises(pwsdyn.ModelError, match="malformed TOML"):
            pwsdyn.load_model(path)
    with pytest.raises(pwsdyn.ModelError, match="cannot read model file"):
        pwsdyn.load_model(tmp_path)


def _same(a, b):
    assert np.array_equal(a.t, b.t) and np.array_equal(a.x, b.x)
    assert np.array_equal(a.events.t, b.events.t) and list(a.state) == list(b.state)
    assert a.stats == b.stats and a.params == b.params
    ts = np.linspace(a.t[0], a.t[-1], 7)
    assert np.array_equal(a(ts), b(ts))


@pytest.mark.parametrize("dense", [True, False])
def test_by_name_and_by_object_compute_the_same_bits(dense):
    m = pwsdyn.load_model("impact-oscillator")
    T = 2 * math.pi / m.parameters["omega"]
    by_obj = pwsdyn.simulate(m, (-0.5, 0.0), (0.0, 3 * T), dense=dense)
    by_name = pwsdyn.simulate("impact-oscillator", (-0.5, 0.0), (0.0, 3 * T), dense=dense)
    if dense:
        _same(by_obj, by_name)
    assert np.array_equal(by_obj.x_final, by_name.x_final)
    assert np.array_equal(by_obj.events.t, by_name.events.t)
    assert len(by_obj.events) >= 2
    # the trajectory carries the caller's model, not one kept from an earlier call
    assert by_obj.model is m and by_name.model is not m


def test_a_model_changed_between_runs_runs_with_its_new_values(tmp_path):
    path = tmp_path / "osc.toml"
    _write(path, 1.0, OLD)
    m = pwsdyn.load_model(path)
    before = pwsdyn.simulate(m)
    m.parameters["k"] = 2.0                      # a run uses the model's values of the call
    changed = pwsdyn.simulate(m)
    reference = pwsdyn.simulate(pwsdyn.load_model(path), params={"k": 2.0})
    assert not np.array_equal(before.x_final, changed.x_final)
    _same(changed, reference)
    assert changed.params["k"] == 2.0
    # and from the file, once edited
    _write(path, 2.0, OLD + 5)
    _same(pwsdyn.simulate(str(path)), reference)


def test_option_errors_stay_after_good_calls():
    m = pwsdyn.load_model("impact-oscillator")
    for _ in range(2):
        pwsdyn.simulate(m, (-0.5, 0.0), 1.0, dense=True, rtol=1e-8)
        # equal values of another type are checked as the first time: 1 is not a bool
        with pytest.raises(ArgumentError, match="`dense`"):
            pwsdyn.simulate(m, (-0.5, 0.0), 1.0, dense=1)
        with pytest.raises(ArgumentError, match="`rtol`"):
            pwsdyn.simulate(m, (-0.5, 0.0), 1.0, rtol=float("nan"))
        with pytest.raises(ArgumentError, match="`first_step`"):
            pwsdyn.simulate(m, (-0.5, 0.0), 1.0, first_step=[1e-3])   # unhashable


def test_abs_max_is_numpys_max_of_abs():
    from pwsdyn.integrate._start import abs_max

    for v in ([-0.5, 0.0], [1e308, -1e308, 3.0], [np.nan, 1.0], [1.0, np.nan], [-np.inf, 2.0],
              [-0.0], [3.0, -7.25, 7.25]):
        a = np.array(v)
        want = float(np.max(np.abs(a)))
        got = abs_max(a)
        assert (math.isnan(got) and math.isnan(want)) or (got == want and type(got) is float)


def test_a_spec_marshal_cannot_write_is_copied_to_the_leaves():
    import datetime

    data = {"a": [1, {"b": datetime.date(2020, 1, 2)}], "c": {"d": 1.5}}
    assert spec._marshalled(data) is None
    assert spec._marshalled({"a": [1, {"b": "x"}]}) is not None
    copy = spec._copy_data(data)
    assert copy == data and copy["a"] is not data["a"] and copy["a"][1] is not data["a"][1]


def test_fast_argument_paths_agree_with_the_checks():
    m = pwsdyn.load_model("impact-oscillator")
    ref = pwsdyn.simulate(m, np.array([-0.5, 0.0]), np.array([0.0, 2.0]), dense=False)
    for x0 in ((-0.5, 0.0), [-0.5, 0.0], {"x": -0.5, "v": 0.0}):
        for span in ((0.0, 2.0), [0, 2], 2.0, (np.float64(0.0), 2)):
            tr = pwsdyn.simulate(m, x0, span, dense=False)
            assert np.array_equal(tr.x_final, ref.x_final) and tr.t0 == 0.0 and tr.t_end == 2.0
    for x0, what in (((-0.5, float("nan")), "finite"), ((-0.5,), "2 entries"),
                     ((-0.5, 0.0, 1.0), "2 entries")):
        with pytest.raises(ArgumentError, match=what):
            pwsdyn.simulate(m, x0, 1.0)
    with pytest.raises(ArgumentError, match="with finite numbers"):
        pwsdyn.simulate(m, (-0.5, 0.0), (0.0, float("inf")))
    with pytest.raises(ArgumentError, match="t_end > t0"):
        pwsdyn.simulate(m, (-0.5, 0.0), (2.0, 1.0))
