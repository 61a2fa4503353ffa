"""`pwsdyn crisis`: the file it writes is the API's result, the figure is drawn, bad input is
a clean error."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import pwsdyn
from pwsdyn.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

#: The border-collision normal form with a chaotic attractor destroyed near tL = 1.8928
#: (tests/test_crisis.py derives the value), as a model file.
BCNF = """
name = "bcnf"
kind = "map"
states = ["x", "y"]
[parameters]
tL = 1.8
dL = 0.3
tR = -1.8
dR = 0.3
mu = 1.0
[[pieces]]
name = "L"
condition = "x <= 0"
map = { x = "tL*x + y + mu", y = "-dL*x" }
[[pieces]]
name = "R"
map = { x = "tR*x + y + mu", y = "-dR*x" }
"""

#: Attributes that say when the file was made, not what is in it.
_WHEN = {"date_created", "history"}


def _run(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def bcnf_file(tmp_path):
    path = tmp_path / "bcnf.toml"
    path.write_text(BCNF)
    return path


@pytest.mark.slow   # ~10-20 s: among the long checks, run by CI
def test_a_planar_maps_crisis_file_is_the_apis_and_the_figure_is_drawn(bcnf_file, tmp_path):
    out, plot = tmp_path / "c.nc", tmp_path / "c.png"
    res = _run(["crisis", bcnf_file, "--param", "tL", "--from", 1.8, "--to", 2.0,
                "--x0", "0.1,0", "--steps", 11, "--out", out, "--plot", plot])
    assert res.exit_code == 0, res.output
    assert "crisis      boundary at tL = 1.8928" in res.output
    assert "homoclinic" in res.output
    assert plot.read_bytes()[:8] == PNG_MAGIC
    c = pwsdyn.locate_crisis(pwsdyn.load_model(bcnf_file), "tL", (1.8, 2.0), x0=[0.1, 0.0],
                             steps=11)
    with xr.open_dataset(out) as ds:
        got = ds.load()
    want = c.to_dataset()
    for name in want.data_vars:
        assert np.array_equal(got[name].values, want[name].values), name
    for k, v in want.attrs.items():
        if k not in _WHEN:
            assert np.all(got.attrs[k] == v), k


def test_a_one_state_maps_crisis_without_a_figure(tmp_path):
    out = tmp_path / "c.nc"
    res = _run(["crisis", "sqrt-map", "--param", "mu", "--from", 0.5, "--to", 0.125,
                "-p", "lam=2", "--out", out])
    assert res.exit_code == 0, res.output
    with xr.open_dataset(out) as ds:
        assert abs(ds.attrs["value"] - 0.25) < 1e-10 and ds.attrs["param"] == "mu"


@pytest.mark.parametrize("args, code, text", [
    (["sqrt-map", "--from", 0.5, "--to", 0.1], 2, "--param NAME"),
    (["sqrt-map", "--param", "nope", "--from", 0.5, "--to", 0.1], 2, "unknown parameter"),
    (["sqrt-map", "--param", "mu", "--from", 0.5, "--to", 0.1, "--steps", 1], 2, "at least 2"),
    (["sqrt-map", "--param", "mu", "--from", 0.5, "--to", 0.1, "--tol", -1], 2, "positive"),
    # a flow is taken through its stroboscopic section: an unforced three-state one has none
    (["relay-feedback", "--param", "zeta", "--from", 0.05, "--to", 0.1], 1, "is a flow"),
    (["sqrt-map", "--param", "mu", "--from", 0.5, "--to", 0.1, "--seed", "1,2"], 2,
     "expected 1 values"),
    (["sqrt-map", "--param", "mu", "--from", 0.5, "--to", 0.4, "-p", "lam=2", "--steps", 3],
     1, "no crisis"),
])
def test_bad_input_is_a_clean_error(args, code, text):
    res = _run(["crisis", *args])
    assert res.exit_code == code, res.output
    assert text in res.output and "Traceback" not in res.output


@pytest.mark.parametrize("extra, words", [
    (["--rtol", "1e-9"], ["--rtol", "map", "applies to flows only"]),
    (["--method", "RK45", "--atol", "1e-9"], ["--atol", "--method", "apply to flows only"]),
    (["--t0", "1"], ["--t0", "flows only"]),
])
def test_integrator_options_and_phase_are_refused_for_a_map(extra, words):
    """A map has no integrator and no section phase: the options that only a flow's runs take
    are refused by name before any work, not ignored."""
    res = CliRunner().invoke(main, ["crisis", "sqrt-map", "--param", "mu", "--from", "0.5",
                                    "--to", "0.125", "-p", "lam=2", *extra])
    assert res.exit_code == 2, res.output
    for w in words:
        assert w in res.output, (w, res.output)


def test_the_api_refuses_integrator_options_for_a_map():
    with pytest.raises(pwsdyn.errors.ArgumentError, match="apply to flows"):
        pwsdyn.locate_crisis("sqrt-map", "mu", (0.5, 0.125), params={"lam": 2.0}, rtol=1e-9)
