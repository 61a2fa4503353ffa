"""`pwsdyn manifold`: the files it writes are the API's results, bad input is a clean error."""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import pwsdyn
from pwsdyn.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

#: The border-collision normal form with a saddle in L at (-mu, mu/2) = (-1, 0.5), multipliers
#: (5 +- sqrt(17)) / 4 (tests/test_manifolds.py derives them), as a model file.
BCNF = """
name = "bcnf"
kind = "map"
states = ["x", "y"]
[parameters]
tL = 2.5
dL = 0.5
tR = -0.5
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

SQRT = ["sqrt-map", "-p", "mu=0.2", "-p", "lam=0.3", "--x0", "0.03", "--arclength", "0.1"]


def _run(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _read(path) -> xr.Dataset:
    with xr.open_dataset(path) as ds:
        return ds.load()


#: Attributes that say when the file was made, not what is in it.
_WHEN = {"date_created", "history"}


def _assert_same(path, m):
    """The file at ``path`` holds ``m.to_dataset()``: every variable bit for bit, every
    attribute but the time stamps."""
    got, want = _read(path), m.to_dataset()
    xr.testing.assert_equal(got, want)
    for name in want.data_vars:
        assert np.array_equal(got[name].values, want[name].values), name
    strip = lambda a: {k: v for k, v in a.items() if k not in _WHEN}  # noqa: E731
    assert strip(got.attrs).keys() == strip(want.attrs).keys()
    for k, v in strip(want.attrs).items():
        assert np.all(got.attrs[k] == v), k


@pytest.fixture
def bcnf_file(tmp_path):
    path = tmp_path / "bcnf.toml"
    path.write_text(BCNF)
    return path


def test_a_maps_unstable_manifold_is_the_apis(tmp_path):
    out, plot = tmp_path / "w.nc", tmp_path / "w.png"
    res = _run(["manifold", *SQRT, "--out", out, "--plot", plot])
    assert res.exit_code == 0, res.output
    assert f"wrote       {out}" in res.output and f"wrote       {plot}" in res.output
    m = pwsdyn.manifold("sqrt-map", [0.03], params={"mu": 0.2, "lam": 0.3}, arclength=0.1)
    _assert_same(out, m)
    # the saddle against its closed form: x = mu - sqrt(x), sqrt(x) = (-1 + sqrt(1 + 4 mu)) / 2;
    # 1e-12: Newton's residual tolerance (find_periodic_point's tol) on a value of order 0.03
    root = (-1.0 + math.sqrt(1.8)) / 2.0
    assert abs(float(_read(out)["saddle"].values[0]) - root ** 2) < 1e-12
    assert plot.read_bytes().startswith(PNG_MAGIC)


def test_both_manifolds_go_to_two_files(bcnf_file, tmp_path):
    out = tmp_path / "w.nc"
    res = _run(["manifold", bcnf_file, "--x0", "-0.5,0", "--kind", "both", "--arclength", "2",
                "--tol", "1e-8", "--out", out])
    assert res.exit_code == 0, res.output
    stable = tmp_path / "w-stable.nc"
    assert f"wrote       {stable}" in res.output
    pt = pwsdyn.find_periodic_point(pwsdyn.load_model(bcnf_file), [-0.5, 0.0])
    for path, kind in ((out, "unstable"), (stable, "stable")):
        m = pwsdyn.manifold(pwsdyn.load_model(bcnf_file), pt, kind, arclength=2.0, tol=1e-8)
        _assert_same(path, m)
        assert _read(path).attrs["manifold_kind"] == kind
    # the saddle (-1, 0.5) and its multipliers (5 +- sqrt(17)) / 4, derived by hand; 1e-12:
    # rounding in a linear solve and a 2x2 eigenvalue problem of order-one numbers
    ds = _read(out)
    assert np.allclose(ds["saddle"].values, [-1.0, 0.5], rtol=0, atol=1e-12)
    assert np.allclose(sorted(ds["multiplier_real"].values),
                       [(5 - math.sqrt(17)) / 4, (5 + math.sqrt(17)) / 4], rtol=0, atol=1e-12)
    # an existing file is not replaced without --force, before any work; with it, it is
    res = _run(["manifold", bcnf_file, "--x0", "-0.5,0", "--kind", "both", "--out", out])
    assert res.exit_code == 1 and "--force" in res.output, res.output
    res = _run(["manifold", bcnf_file, "--x0", "-0.5,0", "--kind", "stable", "--arclength",
                "2", "--tol", "1e-8", "--out", out, "--force"])
    assert res.exit_code == 0, res.output
    assert _read(out).attrs["manifold_kind"] == "stable"


def test_a_forced_flows_saddle_orbit_is_found_as_orbit_finds_it(tmp_path):
    # omega = 2.8: the impact oscillator's period-1 orbit is a flip saddle
    # (tests/test_manifolds.py); shooting from the same guess, then the same manifold
    out = tmp_path / "w.nc"
    res = _run(["manifold", "impact-oscillator", "-p", "omega=2.8", "--x0", "-0.29,-0.58",
                "--arclength", "0.05", "--out", out])
    assert res.exit_code == 0, res.output
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.29, -0.58],
                                       params={"omega": 2.8})
    m = pwsdyn.manifold("impact-oscillator", orbit, arclength=0.05)
    _assert_same(out, m)
    assert _read(out).attrs["section"] == "stroboscopic"


def test_a_figure_that_fails_costs_neither_manifold(bcnf_file, tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(pwsdyn.Manifold, "plot", broken)
    res = _run(["manifold", bcnf_file, "--x0", "-0.5,0", "--kind", "both", "--arclength", "1",
                "--plot", "fig.png"])
    assert res.exit_code == 1, res.output
    assert "disk full" in res.output and "fig.nc" in res.output
    assert "fig-stable.nc" in res.output
    assert _read(tmp_path / "fig.nc").attrs["manifold_kind"] == "unstable"
    assert _read(tmp_path / "fig-stable.nc").attrs["manifold_kind"] == "stable"
    assert not (tmp_path / "fig.png").exists()


@pytest.mark.parametrize("args, words", [
    (["--kind", "sideways"], ["--kind", "sideways"]),
    (["--arclength", "-1"], ["--arclength", "positive"]),
    (["--tol", "0"], ["--tol", "positive"]),
    (["--max-points", "2"], ["--max-points", "at least 3"]),
    (["--period", "0"], ["--period", "positive"]),
    (["--x0", "0.03,1"], ["--x0", "1 states"]),
    (["-p", "nosuch=1"], ["--param", "nosuch"]),
    (["--rtol", "1e-8"], ["--rtol", "map", "flows only"]),
    (["--t0", "1"], ["--t0", "flows only"]),
    (["--out", "w.txt"], ["--out", "NetCDF"]),
])
def test_bad_arguments_exit_with_2(args, words):
    res = _run(["manifold", *SQRT, *args])
    assert res.exit_code == 2, res.output
    for w in words:
        assert w in res.output, (w, res.output)
    assert "Traceback" not in res.output


def test_a_point_that_is_no_saddle_is_one_error_line(bcnf_file):
    # the fixed point of R is a stable focus: no unstable multiplier (exit 1, one line)
    res = _run(["manifold", bcnf_file, "--x0", "0.6,-0.2"])
    assert res.exit_code == 1, res.output
    assert "Error:" in res.output and "exactly one unstable multiplier" in res.output
    assert "Traceback" not in res.output
    res = _run(["manifold", bcnf_file])        # no [defaults] x0 and no --x0
    assert res.exit_code == 2 and "--x0" in res.output, res.output
    res = _run(["manifold", "relay-feedback"])        # autonomous: no stroboscopic section
    assert res.exit_code == 1 and "autonomous" in res.output, res.output


def test_help_lists_the_options():
    res = _run(["manifold", "--help"])
    assert res.exit_code == 0
    for flag in ("--kind", "--arclength", "--max-points", "--tol", "--period", "--x0", "--out",
                 "--plot", "--force"):
        assert flag in res.output, flag
    assert "manifold" in _run(["--help"]).output
