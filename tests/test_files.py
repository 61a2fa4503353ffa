"""Self-describing files: units and descriptions in the model format, and the CF attributes
of every kind of NetCDF file pwsdyn writes (pwsdyn.io, "Self-describing files").

Every file is written into pytest's temporary directory. No CF checker runs here (the
packages need the UDUNITS library and the CF tables from the network); the attributes the
checker reads are checked one by one instead.
"""

from __future__ import annotations

import json
import re
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import pwsdyn
from pwsdyn import ModelError, OutputExistsError
from pwsdyn.cli import main
from pwsdyn.io import load_trajectory, open_dataset, save_dataset
from pwsdyn.model.spec import MAX_DESCRIPTION_LENGTH, MAX_UNIT_LENGTH, zoo_path

DATA = Path(__file__).parent / "data"
ISO_UTC = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ\Z")
PACKAGES = ("pwsdyn", "numpy", "scipy", "numba", "xarray", "sympy")

#: A ball on a fixed floor with units and descriptions (a file, so errors name lines).
BALL = """\
name = "units-ball"
states = ["y", "v"]

[parameters]
g = 9.81
e = 0.8

[modes.flight]
y = "v"
v = "-g"

[[events]]
name = "floor"
kind = "impact"
surface = "y"
reset = { v = "-e*v" }

[units]
t = "s"
y = "m"
v = "m s-1"
g = "m s-2"

[descriptions]
y = "height above the floor"
e = "coefficient of restitution"
"""


def _ball(tmp_path, text=BALL, name="ball.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


# ======================================================================================
# the model format
# ======================================================================================

def test_units_and_descriptions_are_read_and_stay_out_of_the_digest(tmp_path):
    m = pwsdyn.load_model(_ball(tmp_path))
    assert m.units == {"t": "s", "y": "m", "v": "m s-1", "g": "m s-2"}
    assert m.unit("y") == "m" and m.unit("e") is None
    assert m.describe("e") == "coefficient of restitution" and m.describe("v") is None
    assert m.text == BALL
    # the same model without the tables, or with other text in them: the same digest, so
    # compiled models and stores are shared
    bare = pwsdyn.load_model(BALL.split("[units]")[0])
    other = pwsdyn.load_model(BALL.replace('"m s-1"', '"km h-1"').replace("above", "over"))
    assert bare.digest == m.digest == other.digest
    assert bare.units == {} and bare.descriptions == {}


@pytest.mark.parametrize("edit, field, words", [
    (('y = "m"', 'z = "m"'), "units.z", ["unknown state or parameter 'z'", "states are"]),
    (('e = "coefficient', 'w = "coefficient'), "descriptions.w", ["unknown", "'w'"]),
    (('y = "m"', "y = 1.0"), "units.y", ["must be a string", "float"]),
    (('y = "m"', 'y = ""'), "units.y", ["non-empty"]),
    (('y = "m"', 'y = "   "'), "units.y", ["non-empty"]),
    (('y = "m"', 'y = "m\\u001b[2J"'), "units.y", ["non-printable", "U+001B"]),
    (('e = "coefficient', 'e = "\\u202ecoefficient'), "descriptions.e",
     ["non-printable", "U+202E"]),
    (('e = "coefficient of restitution"', 'e = "two\\nlines"'), "descriptions.e",
     ["non-printable", "U+000A"]),
    (('y = "m"', f'y = "{"m" * (MAX_UNIT_LENGTH + 1)}"'), "units.y",
     [f"{MAX_UNIT_LENGTH + 1} characters", f"at most {MAX_UNIT_LENGTH}"]),
    (('e = "coefficient of restitution"', f'e = "{"x" * (MAX_DESCRIPTION_LENGTH + 1)}"'),
     "descriptions.e", [f"at most {MAX_DESCRIPTION_LENGTH}"]),
])
def test_bad_units_and_descriptions_name_file_line_and_field(tmp_path, edit, field, words):
    text = BALL.replace(*edit)
    assert text != BALL
    path = _ball(tmp_path, text)
    with pytest.raises(ModelError) as info:
        pwsdyn.load_model(path)
    err = info.value
    assert err.source == str(path) and err.field == field
    key = field.split(".")[1]
    # the line of the entry itself, inside its table (not the state's line in a mode)
    table = text.splitlines().index(f"[{field.split('.')[0]}]") + 1
    assert err.line is not None and err.line > table
    assert text.splitlines()[err.line - 1].startswith(key)
    msg = str(err)
    assert f"{path}:{err.line}" in msg and f"field `{field}`" in msg
    for w in words:
        assert w in msg, (w, msg)


def test_units_table_must_be_a_table_and_maps_have_no_time():
    with pytest.raises(ModelError, match="`units` must be a table"):
        pwsdyn.load_model({"name": "m", "states": ["x"], "modes": {"a": {"x": "-x"}},
                           "units": "m"})
    sqrt_map = {"name": "sq", "kind": "map", "states": ["x"], "parameters": {"mu": 0.1},
                "map": {"x": "mu - x"}}
    m = pwsdyn.load_model({**sqrt_map, "units": {"x": "1", "mu": "1"},
                           "descriptions": {"x": "distance"}})
    assert m.units == {"x": "1", "mu": "1"} and m.describe("x") == "distance"
    with pytest.raises(ModelError, match="a map has no time"):
        pwsdyn.load_model({**sqrt_map, "units": {"t": "1"}})


@pytest.mark.parametrize("name", pwsdyn.zoo_names())
def test_zoo_models_document_every_quantity(name):
    m = pwsdyn.load_model(name)
    names = [*m.states, *m.parameters] + ([] if getattr(m, "is_map", False) else ["t"])
    assert set(m.units) == set(names) and set(m.descriptions) == set(names)
    assert m.text == zoo_path(name).read_text()


# ======================================================================================
# the attributes of every kind of file
# ======================================================================================

def _check_cf(ds: xr.Dataset, model, kind: str):
    """The attributes every pwsdyn file carries (pwsdyn.io, "Self-describing files")."""
    a = ds.attrs
    assert a["Conventions"] == "CF-1.10"
    assert a["pwsdyn_type"] == kind
    for key in ("title", "source", "history"):
        assert isinstance(a[key], str) and a[key].strip(), key
    assert a["source"].startswith(f"pwsdyn {pwsdyn.__version__}: ")
    assert ISO_UTC.match(a["date_created"]), a["date_created"]
    assert a["date_created"] in a["history"] and "pwsdyn" in a["history"]
    assert a["pwsdyn_version"] == pwsdyn.__version__
    for pkg in PACKAGES[1:]:
        assert a[f"{pkg}_version"] == metadata.version(pkg), pkg
    # the model: name, hash, definition and full text
    assert a["model"] == model.name and a["model_hash"] == model.hash
    assert pwsdyn.load_model(json.loads(a["model_spec"])).hash == model.hash
    if model.text:
        assert a["model_text_format"] == "toml" and a["model_text"] == model.text
    else:
        assert a["model_text_format"] == "json"
        assert pwsdyn.load_model(json.loads(a["model_text"])).hash == model.hash
    assert json.loads(a["model_units"]) == model.units
    assert json.loads(a["model_descriptions"]) == model.descriptions
    # every variable and coordinate says what it is; integer codes say what their values mean
    for name, var in ds.variables.items():
        assert isinstance(var.attrs.get("long_name"), str) and var.attrs["long_name"], name
        if "flag_values" in var.attrs:
            flags = np.atleast_1d(var.attrs["flag_values"])
            meanings = var.attrs["flag_meanings"].split()
            assert len(flags) == len(meanings) == len(set(flags.tolist())), name
            assert flags.dtype == var.dtype, name        # CF: the variable's own type
            assert np.isin(np.asarray(var.values), flags).all(), name
    for name in ("status", "interval_kind", "label"):
        if name in ds and ds[name].dtype.kind == "i":
            assert "flag_values" in ds[name].attrs, name
    # per-state units and descriptions where a variable spans states of several units
    if "state" in ds.coords:
        assert list(ds.state_units.values) == [model.unit(s) or "" for s in model.states]
        assert list(ds.state_long_name.values) == [model.describe(s) or s
                                                   for s in model.states]


def _ball_units(ds, model):
    """Units where the ball model gives them: time, states (mixed: no `units` on x)."""
    assert "units" not in ds["x"].attrs and "state_units" in ds["x"].attrs.get("comment", "")
    assert ds["t"].attrs["units"] == "s" and ds["event_t"].attrs["units"] == "s"
    assert ds["t"].attrs["long_name"] == "time"


def test_trajectory_file(tmp_path):
    model = pwsdyn.load_model("bouncing-ball")
    traj = pwsdyn.simulate(model, {"y": 0.5, "v": 0.0}, (0.0, 1.0))
    path = traj.save(tmp_path / "run.nc")
    ds = open_dataset(path)
    _check_cf(ds, model, "trajectory")
    _ball_units(ds, model)
    # time is a coordinate of the nodes (not an index: both sides of an event share it)
    assert "t" in ds.coords and ds["t"].dims == ("node",)
    np.testing.assert_array_equal(ds["t"].values, traj.t)
    assert int(ds["status"]) == 0 and ds["status"].attrs["flag_meanings"].startswith("success")
    assert json.loads(ds.attrs["params"]) == traj.params
    # the file reads back into the same trajectory, with the model's text
    back = load_trajectory(path)
    np.testing.assert_array_equal(back(0.7), traj(0.7))
    assert back.model.text == model.text and back.model.units == model.units


def test_trajectory_of_a_dict_model_carries_its_definition_as_json(tmp_path):
    spec = {"name": "spring", "states": ["x", "v"], "parameters": {"k": 2.0},
            "modes": {"free": {"x": "v", "v": "-k*x"}},
            "units": {"t": "s", "x": "m", "v": "m"}}
    model = pwsdyn.load_model(spec)
    traj = pwsdyn.simulate(model, [1.0, 0.0], 1.0)
    ds = open_dataset(traj.save(tmp_path / "spring.nc"))
    _check_cf(ds, model, "trajectory")
    assert ds["x"].attrs["units"] == "m"          # one unit for all states
    assert json.loads(ds.attrs["model_text"])["units"] == spec["units"]


def test_orbit_file(tmp_path):
    model = pwsdyn.load_model("impact-oscillator")
    orbit = pwsdyn.find_periodic_orbit(model, [-0.7, 0.0],
                                       params={"eps": 0.1, "sigma": -0.5, "omega": 2.8})
    ds = open_dataset(orbit.save(tmp_path / "orbit.nc"))
    _check_cf(ds, model, "periodic_orbit")
    assert ds["multiplier_real"].attrs["units"] == "1"
    assert ds["shooting_node"].attrs["units"] == "1"     # nondimensional time
    assert "Newton shooting" in ds.attrs["source"]


def test_sweep_and_store_files(tmp_path):
    model = pwsdyn.load_model("bouncing-ball")
    store, out = tmp_path / "store", tmp_path / "sweep.nc"
    ds = pwsdyn.sweep(model, "A", [0.2, 0.25], {"y": 1.5, "v": 0.0}, transient=5, samples=8,
                      lyapunov=True, workers=1, progress=False, store=store, out=out)
    for d in (ds, open_dataset(out)):
        assert d.attrs["kind"] == "sweep" and d.attrs["parameter"] == "A"
    f = open_dataset(out)
    _check_cf(f, model, "sweep")
    assert f["A"].attrs["units"] == "m" and f["A"].attrs["long_name"].startswith("amplitude")
    assert f["lyapunov"].attrs["units"] == "s-1"
    assert f["stick_time"].attrs["units"] == "s" and f["period"].attrs["units"] == "1"
    assert "section_missed" in f["status"].attrs["flag_meanings"]
    # the chunk files of the store describe themselves too (and still resume)
    chunks = sorted(store.glob("chunk-*.nc"))
    assert chunks
    for c in chunks:
        cds = open_dataset(c)
        assert cds.attrs["Conventions"] == "CF-1.10" and cds.attrs["model_text"] == model.text
        assert ISO_UTC.match(cds.attrs["date_created"])
        assert "flag_values" in cds["status"].attrs
        assert all("long_name" in v.attrs for v in cds.data_vars.values())
    again = pwsdyn.sweep(model, "A", [0.2, 0.25], {"y": 1.5, "v": 0.0}, transient=5,
                         samples=8, lyapunov=True, workers=1, progress=False, store=store)
    xr.testing.assert_identical(again, ds)


def test_map_sweep_basins_and_lyapunov_files(tmp_path):
    model = pwsdyn.load_model("sqrt-map")
    ds = pwsdyn.sweep(model, "mu", [0.01, 0.02], [0.0], transient=10, samples=20,
                      lyapunov=True, workers=1, progress=False, out=tmp_path / "s.nc")
    f = open_dataset(tmp_path / "s.nc")
    _check_cf(f, model, "sweep")
    assert f["lyapunov"].attrs["units"] == "1"           # per iteration
    assert "no_piece_applies" in f["status"].attrs["flag_meanings"]
    assert ds.attrs["model_kind"] == "map"

    b = pwsdyn.basins(model, {"x": np.linspace(-0.5, 0.5, 5)}, params={"mu": 0.1, "lam": 0.1},
                      transient=10, samples=8, workers=1, progress=False,
                      out=tmp_path / "b.nc", store=tmp_path / "bstore")
    f = open_dataset(tmp_path / "b.nc")
    _check_cf(f, model, "basins")
    assert f["x"].attrs["units"] == "1" and f["fraction"].attrs["units"] == "1"
    meanings = f["label"].attrs["flag_meanings"].split()
    assert meanings[:2] == ["failed", "diverged"] and len(meanings) == 2 + b.sizes["attractor"]
    for c in (tmp_path / "bstore").glob("chunk-*.nc"):
        assert open_dataset(c).attrs["pwsdyn_type"] == "basins_chunk"

    res = pwsdyn.lyapunov_spectrum(model, [0.0], {"mu": 0.02}, duration=500)
    f = open_dataset(res.save(tmp_path / "ly.nc"))
    _check_cf(f, model, "lyapunov_spectrum")
    np.testing.assert_array_equal(f["exponents"].values, res.exponents)
    assert f["exponents"].attrs["units"] == "1"


def test_flow_lyapunov_file(tmp_path):
    model = pwsdyn.load_model("bouncing-ball")
    res = pwsdyn.lyapunov_spectrum(model, transient=5, duration=10)
    f = open_dataset(res.save(tmp_path / "ly.nc"))
    _check_cf(f, model, "lyapunov_spectrum")
    assert f["exponents"].attrs["units"] == "s-1" and f["time"].attrs["units"] == "s"
    assert float(f["span"]) == res.span and int(f["status"]) == res.status
    with pytest.raises(OutputExistsError, match="ly.nc"):
        res.save(tmp_path / "ly.nc")
    res.save(tmp_path / "ly.nc", overwrite=True)


def test_files_written_by_the_command_line(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    res = runner.invoke(main, ["simulate", "quarter-car", "--t-end", "0.5", "--out", "q.nc"],
                        catch_exceptions=False)
    assert res.exit_code == 0, res.output
    ds = open_dataset("q.nc")
    _check_cf(ds, pwsdyn.load_model("quarter-car"), "trajectory")
    assert list(ds.state_units.values) == ["m", "m s-1", "m", "m s-1"]
    res = runner.invoke(main, ["orbit", "impact-oscillator", "-p", "eps=0.1", "-p", "sigma=-0.5",
                               "-p", "omega=2.8", "--x0", "-0.7,0", "--out", "o.nc"],
                        catch_exceptions=False)
    assert res.exit_code == 0, res.output
    _check_cf(open_dataset("o.nc"), pwsdyn.load_model("impact-oscillator"), "periodic_orbit")


def test_save_stamps_the_file_not_the_dataset(tmp_path):
    traj = pwsdyn.simulate("impact-oscillator", [0.0, 0.0], 1.0)
    ds = traj.to_dataset()
    assert "date_created" not in ds.attrs and "history" not in ds.attrs
    save_dataset(ds, tmp_path / "a.nc")
    assert "date_created" not in ds.attrs                # the caller's dataset is unchanged
    first = open_dataset(tmp_path / "a.nc")
    save_dataset(first, tmp_path / "b.nc")
    second = open_dataset(tmp_path / "b.nc")
    # a copy keeps the date the data were created and adds a line to the history
    assert second.attrs["date_created"] == first.attrs["date_created"]
    assert second.attrs["history"].startswith(first.attrs["history"] + "\n")
    assert len(second.attrs["history"].splitlines()) == 2


def test_time_units_are_not_decoded(tmp_path):
    """A model whose time unit xarray would decode ("seconds", "days since ...") still reads
    back as numbers."""
    text = BALL.replace('t = "s"', 't = "seconds"')
    traj = pwsdyn.simulate(text, [0.5, 0.0], 1.0)
    ds = open_dataset(traj.save(tmp_path / "a.nc"))
    assert ds["t"].dtype == np.float64 and ds["event_t"].dtype == np.float64
    np.testing.assert_array_equal(load_trajectory(tmp_path / "a.nc").t, traj.t)


# ======================================================================================
# files written before these attributes existed
# ======================================================================================

def test_files_of_the_previous_format_still_read(tmp_path):
    """tests/data/pre_cf: a trajectory, a sweep (both directions, Lyapunov exponents) and
    basins written by pwsdyn before the CF attributes (time a data variable, no units, no
    flags): they load, evaluate and plot as before."""
    from pwsdyn.plot import plot_basins, plot_bifurcation, plot_lyapunov, plot_trajectory

    old = DATA / "pre_cf"
    raw = open_dataset(old / "trajectory.nc")
    assert "Conventions" not in raw.attrs and "t" in raw.data_vars
    traj = load_trajectory(old / "trajectory.nc")
    assert traj.success and len(traj.events) > 0 and traj.model.name == "bouncing-ball"
    assert np.all(np.isfinite(traj(np.linspace(traj.t0, traj.t_end, 50))))
    plot_trajectory(traj, path=tmp_path / "t.png")
    # and is written again in the new format
    ds = open_dataset(save_dataset(traj, tmp_path / "t.nc"))
    assert ds.attrs["Conventions"] == "CF-1.10" and "t" in ds.coords

    sweep = open_dataset(old / "sweep.nc")
    assert sweep.attrs["kind"] == "sweep" and "flag_values" not in sweep["status"].attrs
    plot_bifurcation(sweep, path=tmp_path / "s.png")
    plot_lyapunov(sweep, path=tmp_path / "l.png")
    basins = open_dataset(old / "basins.nc")
    plot_basins(basins, path=tmp_path / "b.png")
    assert pwsdyn.explore.basin_fractions(basins)
