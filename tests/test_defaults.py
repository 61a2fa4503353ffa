"""One set of defaults and one set of flags for the API and the command line.

- the model's ``[defaults]`` table (params, x0, t0, t_end) is applied by the API exactly as by
  the CLI (one rule: ``pwsdyn.model.spec.run_defaults`` and ``model.parameters``);
- every option default of a command equals the default of the API function it calls (a test
  of the signatures against the click options, so they cannot drift apart);
- ``-p/--param NAME=VALUE`` sets a parameter in every command (``-s/--set`` is a synonym),
  ``sweep --sweep NAME`` names the swept parameter (``--param NAME`` still does), ``orbit``
  takes ``--sliding``, and every file a command writes is listed.
"""

from __future__ import annotations

import inspect
import json
import math
import re
import warnings

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import pwsdyn
from pwsdyn import OutputExistsError
from pwsdyn.cli import FALLBACK_T_END, main
from pwsdyn.integrate.simulate import DEFAULTS
from pwsdyn.io import load_trajectory, open_dataset, save_dataset
from pwsdyn.model.spec import FALLBACK_T_END as LIBRARY_FALLBACK_T_END
from pwsdyn.orbits._shooting import SHOOTING_DEFAULTS

#: A model with a full [defaults] table (t0 too) and no [units].
SPRING = """
name = "spring-defaults"
states = ["x", "v"]
forcing_period = "2*pi/w"
[parameters]
k = 1.0
w = 1.0
[modes.free]
x = "v"
v = "-k*x + cos(w*t)"
[defaults]
x0 = [0.5, 0.0]
t0 = 1.0
t_end = 4.0
params = { k = 4.0, w = 3.0 }
"""


def _run(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


# ======================================================================================
# the model's [defaults] in the API
# ======================================================================================

def test_defaults_params_are_the_models_parameters():
    ball = pwsdyn.load_model("bouncing-ball")
    assert ball.parameters["A"] == 0.224 and ball.parameters["omega"] == 2 * math.pi
    assert ball.spec["parameters"]["A"] == 0.0            # the file is not changed
    spring = pwsdyn.load_model(SPRING)
    assert spring.parameters == {"k": 4.0, "w": 3.0}
    assert spring.forcing_period_value() == pytest.approx(2 * math.pi / 3)
    # a map's [defaults] params too, checked like a flow's
    sq = {"name": "sq", "kind": "map", "states": ["x"], "parameters": {"mu": 0.1},
          "map": {"x": "mu - x"}}
    assert pwsdyn.load_model({**sq, "defaults": {"params": {"mu": 0.3}}}).parameters == \
        {"mu": 0.3}
    with pytest.raises(pwsdyn.ModelError, match="finite number"):
        pwsdyn.load_model({**sq, "defaults": {"params": {"mu": "x"}}})


def test_simulate_without_x0_and_t_span_is_the_commands_default_run(tmp_path):
    """`pwsdyn.simulate(model)` and `pwsdyn simulate MODEL` are the same run, to the bit."""
    api = pwsdyn.simulate(SPRING)
    assert api.t0 == 1.0 and api.t_end == 4.0
    np.testing.assert_array_equal(api.x[0], [0.5, 0.0])
    assert api.params == {"k": 4.0, "w": 3.0}
    model = tmp_path / "spring.toml"
    model.write_text(SPRING)
    res = _run(["simulate", model, "--out", tmp_path / "cli.nc"])
    assert res.exit_code == 0, res.output
    cli = load_trajectory(tmp_path / "cli.nc")
    np.testing.assert_array_equal(cli.t, api.t)
    np.testing.assert_array_equal(cli.x, api.x)
    # a single number is t_end from the model's t0
    assert pwsdyn.simulate(SPRING, t_span=2.0).t0 == 1.0
    # the zoo's ball: its [defaults] (1.5 m, A = 0.224, omega = 2 pi, 60 s) in both
    ball = pwsdyn.simulate("bouncing-ball", t_span=3.0)
    assert ball.params["A"] == 0.224 and ball.x[0].tolist() == [1.5, 0.0]


def test_simulate_fallbacks_warn_as_the_command_notes():
    spring = "\n".join(ln for ln in SPRING.splitlines()
                       if not ln.startswith(("x0", "t_end", "t0")))
    with pytest.warns(UserWarning) as rec:
        traj = pwsdyn.simulate(spring)
    text = " ".join(str(w.message) for w in rec)
    assert "no x0 given" in text and "x=0, v=0" in text and "no t_end given" in text
    assert traj.t_end == FALLBACK_T_END and traj.x[0].tolist() == [0.0, 0.0]
    assert FALLBACK_T_END == LIBRARY_FALLBACK_T_END
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pwsdyn.simulate(SPRING)                          # nothing to say


def test_explore_functions_apply_the_defaults():
    # the examples: the ball's sweep in A runs at omega = 2 pi (not 1), and its
    # Lyapunov spectrum at A = 0.2 is finite from the [defaults] start (no -inf)
    ds = pwsdyn.sweep("bouncing-ball", "A", [0.2], transient=2, samples=4, workers=1,
                      progress=False)
    settings = json.loads(ds.attrs["settings"])
    assert settings["params"]["omega"] == 2 * math.pi and settings["x0"] == [1.5, 0.0]
    assert list(ds.direction.values) == ["up", "down"]
    res = pwsdyn.lyapunov_spectrum("bouncing-ball", params={"A": 0.3}, transient=20,
                                   duration=40)
    assert np.all(np.isfinite(res.exponents)) and res.provenance["params"]["omega"] == \
        2 * math.pi
    orbit = pwsdyn.find_periodic_orbit(SPRING, [0.0, 0.0])
    assert orbit.converged and orbit.params["k"] == 4.0
    with pytest.raises(pwsdyn.ArgumentError, match="no \\[defaults\\] x0"):
        pwsdyn.lyapunov_spectrum({"name": "n", "states": ["x"], "modes": {"m": {"x": "-x"}}},
                                 segment=1.0)


# ======================================================================================
# option defaults: the API's signatures against the click options
# ======================================================================================

def _option(command: str, flag: str):
    for p in main.commands[command].params:
        if flag in getattr(p, "opts", ()):
            return p
    raise AssertionError(f"{command} has no option {flag}")


def _api_default(fn, name):
    return inspect.signature(fn).parameters[name].default


#: The shortest command line each command accepts (its required arguments and options only).
MINIMAL = {
    "simulate": ["m"],
    "orbit": ["m"],
    "sweep": ["m", "--from", "0", "--to", "1", "--num", "2"],
    "basins": ["m", "--x", "x", "--x-from", "0", "--x-to", "1", "--x-num", "2"],
    "scan": ["m", "--from", "0", "--to", "1", "--num", "2", "--param2", "b", "--from2", "0",
             "--to2", "1", "--num2", "2"],
    "continue": ["m", "--from", "0", "--to", "1"],
    "grazing": ["m", "--from", "0", "--to", "1"],
    "manifold": ["m"],
    "crisis": ["m", "--from", "0", "--to", "1"],
}


def _received(command: str) -> dict:
    """What the command function receives from its shortest command line: click's public
    parsing (``make_context``, which applies every default and runs no command), so the test
    sees what the command does, not how an option stores its default (click 8.3 reports a
    sentinel as the ``default`` of a flag declared without one)."""
    with main.commands[command].make_context(command, list(MINIMAL[command])) as ctx:
        return dict(ctx.params)


#: Options whose click default is the API's default itself.
SAME_DEFAULT = [
    ("sweep", "--transient", pwsdyn.sweep, "transient"),
    ("sweep", "--samples", pwsdyn.sweep, "samples"),
    ("sweep", "--section", pwsdyn.sweep, "section"),
    ("sweep", "--direction", pwsdyn.sweep, "direction"),
    ("sweep", "--lyapunov", pwsdyn.sweep, "lyapunov"),
    ("sweep", "--workers", pwsdyn.sweep, "workers"),
    ("sweep", "--scheduler", pwsdyn.sweep, "scheduler"),
    ("sweep", "--chunk-size", pwsdyn.sweep, "chunk_size"),
    ("sweep", "--store", pwsdyn.sweep, "store"),
    ("sweep", "--out", pwsdyn.sweep, "out"),
    ("sweep", "--force", pwsdyn.sweep, "overwrite"),
    *[("scan", flag, pwsdyn.scan, name) for flag, name in (
        ("--transient", "transient"), ("--samples", "samples"), ("--section", "section"),
        ("--direction", "direction"), ("--lyapunov", "lyapunov"), ("--workers", "workers"),
        ("--scheduler", "scheduler"), ("--store", "store"), ("--out", "out"),
        ("--force", "overwrite"), ("--no-progress", "progress"))],
    ("basins", "--transient", pwsdyn.basins, "transient"),
    ("basins", "--samples", pwsdyn.basins, "samples"),
    ("basins", "--section", pwsdyn.basins, "section"),
    ("basins", "--workers", pwsdyn.basins, "workers"),
    ("basins", "--scheduler", pwsdyn.basins, "scheduler"),
    ("basins", "--chunk-size", pwsdyn.basins, "chunk_size"),
    ("basins", "--store", pwsdyn.basins, "store"),
    ("basins", "--out", pwsdyn.basins, "out"),
    ("basins", "--force", pwsdyn.basins, "overwrite"),
    ("orbit", "--tol", pwsdyn.find_periodic_orbit, "tol"),
    ("orbit", "--nodes", pwsdyn.find_periodic_orbit, "nodes"),
    ("orbit", "--t0", pwsdyn.find_periodic_orbit, "t0"),
    ("orbit", "--mode", pwsdyn.find_periodic_orbit, "mode"),
    ("orbit", "--period", pwsdyn.find_periodic_orbit, "period"),
    ("simulate", "--mode", pwsdyn.simulate, None),         # integrator option: DEFAULTS
    ("simulate", "--force", pwsdyn.Trajectory.save, "overwrite"),
    ("orbit", "--force", pwsdyn.PeriodicOrbit.save, "overwrite"),
    ("continue", "--max-points", pwsdyn.continue_orbit, "max_points"),
    ("continue", "--ds", pwsdyn.continue_orbit, "ds"),
    ("continue", "--on-dib", pwsdyn.continue_orbit, "on_dib"),
    ("continue", "--t0", pwsdyn.find_periodic_orbit, "t0"),
    ("continue", "--period", pwsdyn.find_periodic_orbit, "period"),
    ("continue", "--force", pwsdyn.Branch.save, "overwrite"),
    ("grazing", "--t0", pwsdyn.find_periodic_orbit, "t0"),
    ("grazing", "--period", pwsdyn.find_periodic_orbit, "period"),
    ("grazing", "--force", save_dataset, "overwrite"),
    *[("manifold", flag, pwsdyn.manifold, name) for flag, name in (
        ("--kind", "kind"), ("--arclength", "arclength"), ("--max-points", "max_points"),
        ("--tol", "tol"), ("--period", "period"))],
    ("manifold", "--t0", pwsdyn.find_periodic_orbit, "t0"),
    ("manifold", "--force", pwsdyn.Manifold.save, "overwrite"),
    *[("crisis", flag, pwsdyn.locate_crisis, name) for flag, name in (
        ("--tol", "tol"), ("--steps", "steps"), ("--arclength", "arclength"))],
    ("crisis", "--force", pwsdyn.Crisis.save, "overwrite"),
    # the flag is the negation of the API's `progress` (see test_option_default_is_the_api's)
    ("sweep", "--no-progress", pwsdyn.sweep, "progress"),
    ("basins", "--no-progress", pwsdyn.basins, "progress"),
]


@pytest.mark.parametrize("command, flag, fn, name", SAME_DEFAULT,
                         ids=[f"{c} {f}" for c, f, _, _ in SAME_DEFAULT])
def test_option_default_is_the_api_default(command, flag, fn, name):
    got = _received(command)[_option(command, flag).name]
    api = DEFAULTS[flag.lstrip("-")] if name is None else _api_default(fn, name)
    if flag.startswith("--no-"):       # --no-progress: progress=False
        api = not api
    # the type too: a flag must give False, not 0 or None, where the API's default is False
    assert (type(got), got) == (type(api), api), (command, flag, got, api)


@pytest.mark.parametrize("command", sorted(MINIMAL))
def test_every_option_gives_a_plain_value_when_not_given(command):
    """No option passes click's internal placeholder for 'not given' to a command: each
    receives None, a bool, a number, a string or an empty tuple (multiple options)."""
    assert set(MINIMAL) == set(main.commands) - {"models"}
    for name, value in _received(command).items():
        assert value is None or isinstance(value, (bool, int, float, str, tuple)), \
            (command, name, value)
        if isinstance(value, tuple):
            assert value == (), (command, name, value)


#: Options whose click default is None, standing for the library's integrator default; the
#: help text names that value.
#: Shooting (orbit, continue, grazing) has its own integrator defaults, over a simulation's.
SHOOTING = {**DEFAULTS, **SHOOTING_DEFAULTS}
LIBRARY_DEFAULT = [(cmd, flag, DEFAULTS) for cmd in ("simulate", "sweep", "scan", "basins")
                   for flag in ("--rtol", "--atol", "--method", "--exact", "--sliding")] + \
                  [(cmd, flag, DEFAULTS)     # the section map's runs: pwsdyn.manifold's
                   for cmd in ("manifold", "crisis")
                   for flag in ("--rtol", "--atol", "--method", "--sliding")] + \
                  [(cmd, flag, SHOOTING) for cmd in ("orbit", "continue", "grazing")
                   for flag in ("--rtol", "--atol", "--method", "--sliding")]


@pytest.mark.parametrize("command, flag, table", LIBRARY_DEFAULT,
                         ids=[f"{c} {f}" for c, f, _ in LIBRARY_DEFAULT])
def test_integrator_option_help_names_the_library_default(command, flag, table):
    opt = _option(command, flag)
    assert _received(command)[opt.name] is None
    value = table[flag.lstrip("-")]
    shown = f"{value:g}" if isinstance(value, float) else str(value)
    # "(default 1e-12)", or "(default 1e-12, tighter ...: why)" where it differs
    assert re.search(rf"\(default {re.escape(shown)}[),:;]", opt.help), (opt.help, shown)


def test_shooting_defaults_are_the_apis(tmp_path):
    """The commands that shoot pass no tolerance or method unless given, so the API's
    shooting defaults apply (tests/test_cli.py checks the same of `grazing`'s file)."""
    out = tmp_path / "o.nc"
    res = _run(["orbit", "impact-oscillator", "--x0", "0,-0.5", "--out", out])
    assert res.exit_code == 0, res.output
    options = json.loads(open_dataset(out).attrs["options"])
    assert {k: options[k] for k in SHOOTING_DEFAULTS} == SHOOTING_DEFAULTS
    api = pwsdyn.find_periodic_orbit("impact-oscillator", [0.0, -0.5])
    assert {k: api.options[k] for k in SHOOTING_DEFAULTS} == SHOOTING_DEFAULTS


def test_every_model_running_command_has_the_same_shared_options():
    for command in ("simulate", "orbit", "sweep", "scan", "basins", "continue", "grazing",
                    "manifold", "crisis"):
        for flag in ("-p", "--param", "-s", "--set", "--x0", "--rtol", "--atol", "--method",
                     "--sliding", "--out", "--plot", "--force"):
            _option(command, flag)
        assert _option(command, "--set").hidden and not _option(command, "--param").hidden
    for command in ("orbit", "sweep", "scan", "basins", "continue", "grazing", "manifold"):
        assert _option("simulate", "--sliding").type.choices == \
            _option(command, "--sliding").type.choices


# ======================================================================================
# flags
# ======================================================================================

SQRT_SWEEP = ["sweep", "sqrt-map", "--from", "0.01", "--to", "0.05", "--num", "3",
              "--transient", "10", "--samples", "20", "--workers", "1", "--no-progress",
              "--direction", "up"]


@pytest.mark.parametrize("spelling", [
    ["--sweep", "mu", "-p", "lam=0.3"],
    ["--sweep", "mu", "--param", "lam=0.3"],
    ["--param", "mu", "--set", "lam=0.3"],                 # the spelling before --sweep
    ["-p", "lam=0.3", "-p", "mu"],
    ["--sweep", "mu", "-s", "lam=0.3"],
])
def test_sweep_spellings_agree(spelling, tmp_path):
    res = _run(SQRT_SWEEP + spelling + ["--out", tmp_path / "s.nc"])
    assert res.exit_code == 0, res.output
    settings = json.loads(open_dataset(tmp_path / "s.nc").attrs["settings"])
    assert settings["param"] == "mu" and settings["params"]["lam"] == 0.3


@pytest.mark.parametrize("args, code, words", [
    ([], 2, ["Missing option", "--sweep"]),
    (["--sweep", "mu", "--param", "lam"], 2, ["one swept parameter", "'mu'", "'lam'"]),
    (["--sweep", "nosuch"], 2, ["nosuch", "--sweep"]),
    (["--sweep", "mu", "-p", "zz=1"], 2, ["--param", "zz"]),
    (["--sweep", "mu", "-p", "lam=0.3", "-s", "lam=0.4"], 2, ["lam", "--param and --set"]),
])
def test_sweep_flag_errors(args, code, words):
    res = _run(SQRT_SWEEP + args)
    assert res.exit_code == code, res.output
    for w in words:
        assert w in res.output, (w, res.output)


def test_param_and_set_in_every_command(tmp_path):
    res = _run(["basins", "sqrt-map", "--x", "x", "--x-from", "-0.5", "--x-to", "0.5",
                "--x-num", "3", "-p", "mu=0.1", "-p", "lam=0.1", "--transient", "10",
                "--samples", "8", "--workers", "1", "--no-progress", "--out", tmp_path / "b.nc"])
    assert res.exit_code == 0, res.output
    assert json.loads(open_dataset(tmp_path / "b.nc").attrs["settings"])["params"] == \
        {"mu": 0.1, "lam": 0.1}
    res = _run(["simulate", "bouncing-ball", "-s", "A=0", "--set", "e=0.5", "--t-end", "0.5",
                "--out", tmp_path / "s.nc"])
    assert res.exit_code == 0, res.output
    params = load_trajectory(tmp_path / "s.nc").params
    assert params["A"] == 0.0 and params["e"] == 0.5 and params["omega"] == 2 * math.pi
    res = _run(["simulate", "bouncing-ball", "-s", "nosuch=1", "--t-end", "0.5"])
    assert res.exit_code == 2 and "--set" in res.output and "nosuch" in res.output


def test_orbit_takes_sliding(tmp_path):
    """The relay's orbit slides on x1 = 0; --sliding reaches the shooting (Utkin's control
    and the convex method agree on this affine field, so both converge to one period)."""
    periods = {}
    for sliding in ("convex", "utkin"):
        out = tmp_path / f"{sliding}.nc"
        res = _run(["orbit", "relay-feedback", "--sliding", sliding, "--out", out])
        assert res.exit_code == 0, res.output
        ds = open_dataset(out)
        assert json.loads(ds.attrs["options"])["sliding"] == sliding
        periods[sliding] = ds.attrs["period"]
    assert periods["convex"] == pytest.approx(periods["utkin"], rel=1e-8)


def test_every_file_written_is_listed(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _run(SQRT_SWEEP + ["--sweep", "mu", "-p", "lam=0.8", "--lyapunov", "--out", "d.nc",
                             "--plot", "d.png", "--store", "st"])
    assert res.exit_code == 0, res.output
    listed = [ln.split()[1] for ln in res.output.splitlines()
              if ln.startswith(("wrote", "store"))]
    assert sorted(listed) == ["d-lyapunov.png", "d.nc", "d.png", "st"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(listed)


# ======================================================================================
# one overwrite policy: sweep and basins refuse an existing `out` before any work
# ======================================================================================

def test_sweep_and_basins_out_refuse_then_overwrite(tmp_path, monkeypatch):
    out = tmp_path / "a.nc"
    out.write_bytes(b"old")
    kw = dict(transient=10, samples=8, workers=1, progress=False)

    def boom(*args, **kwargs):
        raise AssertionError("the work started before the output was checked")

    with monkeypatch.context() as m:
        m.setattr("pwsdyn.explore._sweep.run_chunks", boom)
        m.setattr("pwsdyn.explore._basins.run_chunks", boom)
        with pytest.raises(OutputExistsError, match="a.nc.*overwrite=True"):
            pwsdyn.sweep("sqrt-map", "mu", [0.01], [0.0], out=out, **kw)
        with pytest.raises(OutputExistsError, match="a.nc"):
            pwsdyn.basins("sqrt-map", {"x": [0.0, 0.1]}, out=out, **kw)
        with pytest.raises(FileNotFoundError, match="nodir"):
            pwsdyn.sweep("sqrt-map", "mu", [0.01], [0.0], out=tmp_path / "nodir" / "a.nc",
                         **kw)
    assert out.read_bytes() == b"old"
    ds = pwsdyn.sweep("sqrt-map", "mu", [0.01], [0.0], out=out, overwrite=True, **kw)
    xr.testing.assert_allclose(open_dataset(out)["section"], ds["section"])
    b = pwsdyn.basins("sqrt-map", {"x": [0.0, 0.1]}, out=out, overwrite=True, **kw)
    assert open_dataset(out).attrs["kind"] == "basins" and b.attrs["kind"] == "basins"
