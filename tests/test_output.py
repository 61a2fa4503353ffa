"""Output files and terminal output of the CLI and the API.

- one overwrite policy: an existing file is refused (``OutputExistsError``; CLI: exit 1,
  the message names the file and ``--force``) unless ``overwrite=True`` / ``--force``;
- every output path of a command is checked before any work starts;
- a figure that cannot be written at the end does not cost the data;
- model-provided text never reaches the terminal with control characters in it;
- pwsdyn's own errors are one ``Error:`` line, never a traceback.
"""

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import pwsdyn
from pwsdyn.cli import _safe, main
from pwsdyn.errors import ArgumentError, ModelError, OutputExistsError, PwsdynError
from pwsdyn.io import atomic_write, load_trajectory, save_dataset

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
OLD = b"old content, must survive"

# cheap invocations of every command that writes files (tiny spans, one worker)
SIMULATE = ["simulate", "bouncing-ball", "--x0", "0.5,0", "--t-end", "0.3"]
ORBIT = ["orbit", "impact-oscillator", "-p", "eps=0.1", "-p", "sigma=-0.5", "-p", "omega=2.8",
         "--x0", "-0.7,0"]
SWEEP = ["sweep", "sqrt-map", "--param", "mu", "--from", "0.005", "--to", "0.05", "--num", "3",
         "--set", "lam=0.8", "--transient", "10", "--samples", "20", "--workers", "1",
         "--no-progress"]
BASINS = ["basins", "sqrt-map", "--x", "x", "--x-from", "-0.5", "--x-to", "0.5", "--x-num", "3",
          "--set", "mu=0.1", "--set", "lam=0.1", "--transient", "10", "--samples", "8",
          "--workers", "1", "--no-progress"]
COMMANDS = {"simulate": SIMULATE, "orbit": ORBIT, "sweep": SWEEP, "basins": BASINS}

#: Escape sequences that click's own ANSI stripping does not remove: an OSC title change, a
#: full terminal reset, the C1 form of CSI, and the right-to-left override.
EVIL = "\x1b]0;pwned\x07|\x1bc|\x9b2J|\u202e"
RAW = ("\x1b", "\x07", "\x9b", "\u202e")


class _Result:
    def __init__(self, res):
        self.exit_code = res.exit_code
        self.stdout = res.stdout
        self.stderr = res.stderr
        self.output = res.stdout + res.stderr


def _run(args, color=False):
    try:
        runner = CliRunner(mix_stderr=False)
    except TypeError:  # click >= 8.2 keeps stdout and stderr apart anyway
        runner = CliRunner()
    return _Result(runner.invoke(main, [str(a) for a in args], catch_exceptions=False,
                                 color=color))


def _error_line(res) -> str:
    assert "Traceback" not in res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1, res.output
    return lines[0]


def _forbid_work(monkeypatch):
    """Make every computation of the CLI fail loudly: the checks must come first."""
    def boom(*args, **kwargs):
        raise AssertionError("the work started before the output paths were checked")

    import pwsdyn.orbits

    for name in ("simulate", "sweep", "basins"):
        monkeypatch.setattr(pwsdyn, name, boom)
    monkeypatch.setattr(pwsdyn.orbits, "find_periodic_orbit", boom)


def _is_png(path: Path) -> bool:
    return path.read_bytes()[:8] == PNG_MAGIC


def _is_netcdf(path: Path) -> bool:
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return "pwsdyn_version" in ds.attrs or "model" in ds.attrs


# ======================================================================================
# the API: save and figure functions refuse to overwrite unless overwrite=True
# ======================================================================================

@pytest.fixture(scope="module")
def traj():
    return pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0.0, 0.3))


def test_output_exists_error_is_a_pwsdyn_and_a_file_exists_error():
    assert issubclass(OutputExistsError, PwsdynError)
    assert issubclass(OutputExistsError, FileExistsError)
    assert pwsdyn.OutputExistsError is OutputExistsError


def test_trajectory_save_refuses_then_overwrite_replaces(traj, tmp_path):
    path = tmp_path / "run.nc"
    assert traj.save(path) == path
    before = path.read_bytes()
    with pytest.raises(OutputExistsError, match="run.nc.*overwrite=True"):
        traj.save(path)
    assert path.read_bytes() == before
    other = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0.0, 0.2))
    other.save(path, overwrite=True)
    assert load_trajectory(path).x[0].tolist() == [1.0, 0.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.nc"]  # no temporary left


def test_periodic_orbit_save_refuses_then_overwrite_replaces(tmp_path):
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.7, 0.0],
                                       params={"eps": 0.1, "sigma": -0.5, "omega": 2.8})
    path = tmp_path / "orbit.nc"
    path.write_bytes(OLD)
    with pytest.raises(OutputExistsError, match="orbit.nc"):
        orbit.save(path)
    assert path.read_bytes() == OLD
    assert orbit.save(path, overwrite=True) == path and _is_netcdf(path)


def test_save_dataset_refuses_then_overwrite_replaces(tmp_path):
    path = tmp_path / "a.nc"
    save_dataset(xr.Dataset({"a": ("x", np.arange(3.0))}), path)
    with pytest.raises(FileExistsError, match="a.nc"):
        save_dataset(xr.Dataset({"a": ("x", np.arange(4.0))}), path)
    save_dataset(xr.Dataset({"a": ("x", np.arange(5.0))}), path, overwrite=True)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.sizes["x"] == 5


def test_a_file_that_appears_during_the_write_is_not_replaced(tmp_path):
    path = tmp_path / "a.txt"

    def write(tmp):
        Path(tmp).write_text("mine")
        path.write_text("someone else's")  # created between the check and the move

    with pytest.raises(OutputExistsError):
        atomic_write(path, write)
    assert path.read_text() == "someone else's"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_plot_functions_refuse_to_overwrite(traj, tmp_path):
    from pwsdyn.plot import plot_basins, plot_bifurcation, plot_lyapunov, plot_trajectory

    ds = pwsdyn.sweep("sqrt-map", "mu", [0.01, 0.02], [0.0], params={"lam": 0.8},
                      transient=10, samples=20, lyapunov=True, workers=1, progress=False)
    b = pwsdyn.basins("sqrt-map", {"x": np.linspace(-0.5, 0.5, 3)},
                      params={"mu": 0.1, "lam": 0.1}, transient=10, samples=8, workers=1,
                      progress=False)
    calls = {"trajectory": lambda p, **kw: plot_trajectory(traj, path=p, **kw),
             "bifurcation": lambda p, **kw: plot_bifurcation(ds, path=p, **kw),
             "lyapunov": lambda p, **kw: plot_lyapunov(ds, path=p, **kw),
             "basins": lambda p, **kw: plot_basins(b, path=p, **kw)}
    for name, call in calls.items():
        path = tmp_path / f"{name}.png"
        path.write_bytes(OLD)
        with pytest.raises(OutputExistsError, match=f"{name}.png"):
            call(path)
        assert path.read_bytes() == OLD, name
        call(path, overwrite=True)
        assert _is_png(path), name
        with pytest.raises(ArgumentError, match=r"\.xyz.*png"):
            call(tmp_path / f"{name}.xyz")
        assert not (tmp_path / f"{name}.xyz").exists()


# ======================================================================================
# the CLI: every file-writing option refuses, --force replaces
# ======================================================================================

OUTPUTS = [  # (command, the options naming its files, the file that must be refused)
    ("simulate", ["--out", "o.nc"], "o.nc"),
    ("simulate", ["--plot", "o.png"], "o.png"),
    ("orbit", ["--out", "o.nc"], "o.nc"),
    ("orbit", ["--plot", "o.png"], "o.png"),
    ("sweep", ["--out", "o.nc"], "o.nc"),
    ("sweep", ["--plot", "o.png"], "o.png"),
    ("sweep", ["--lyapunov", "--plot", "o.png"], "o-lyapunov.png"),
    ("basins", ["--out", "o.nc"], "o.nc"),
    ("basins", ["--plot", "o.png"], "o.png"),
]


@pytest.mark.parametrize("command, options, existing", OUTPUTS)
def test_cli_refuses_to_overwrite_before_any_work(command, options, existing, tmp_path,
                                                  monkeypatch):
    monkeypatch.chdir(tmp_path)
    _forbid_work(monkeypatch)
    (tmp_path / existing).write_bytes(OLD)
    res = _run(COMMANDS[command] + options)
    assert res.exit_code == 1, res.output
    line = _error_line(res)
    assert existing in line and "--force" in line and "exists" in line
    assert (tmp_path / existing).read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == [existing]  # nothing else written


@pytest.mark.parametrize("command", list(COMMANDS))
def test_cli_force_replaces_every_output(command, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    extra = ["--lyapunov"] if command == "sweep" else []
    files = ["o.nc", "o.png"] + (["o-lyapunov.png"] if command == "sweep" else [])
    for name in files:
        (tmp_path / name).write_bytes(OLD)
    res = _run(COMMANDS[command] + extra + ["--out", "o.nc", "--plot", "o.png", "--force"])
    assert res.exit_code == 0, res.output
    for name in files:
        assert f"wrote       {name}" in res.output
        path = tmp_path / name
        assert _is_png(path) if name.endswith(".png") else _is_netcdf(path), name
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(files)  # store removed


def test_every_command_that_writes_files_has_force():
    for command in COMMANDS:
        res = _run([command, "--help"])
        assert "--force" in res.output and "--out" in res.output and "--plot" in res.output


# ======================================================================================
# the CLI: output paths are checked before the work
# ======================================================================================

@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("where, words", [
    ("missing/fig.png", ["missing", "does not exist"]),
    ("somefile.txt/fig.png", ["somefile.txt", "not a directory"]),
])
def test_cli_unwritable_plot_directory_fails_first(command, where, words, tmp_path,
                                                   monkeypatch):
    monkeypatch.chdir(tmp_path)
    _forbid_work(monkeypatch)
    (tmp_path / "somefile.txt").write_text("a regular file")
    res = _run(COMMANDS[command] + ["--out", "o.nc", "--plot", where])
    assert res.exit_code == 1, res.output
    line = _error_line(res)
    assert "--plot" in line and where in line
    for w in words:
        assert w in line
    # no data, no store: nothing was started
    assert sorted(p.name for p in tmp_path.iterdir()) == ["somefile.txt"]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root ignores directory permissions")
def test_cli_read_only_directory_fails_first(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _forbid_work(monkeypatch)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        res = _run(SWEEP + ["--plot", "ro/fig.png"])
        assert res.exit_code == 1, res.output
        line = _error_line(res)
        assert "ro/fig.png" in line and "not writable" in line
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_cli_unknown_figure_format_is_refused_first(command, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _forbid_work(monkeypatch)
    res = _run(COMMANDS[command] + ["--plot", "fig.xyz"])
    assert res.exit_code == 2, res.output
    line = _error_line(res)
    assert "--plot" in line and "fig.xyz" in line and ".png" in line and ".pdf" in line
    assert list(tmp_path.iterdir()) == []


def test_cli_data_file_needs_a_netcdf_suffix(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _forbid_work(monkeypatch)
    for command in COMMANDS:
        res = _run(COMMANDS[command] + ["--out", "run.png"])  # --out and --plot swapped
        assert res.exit_code == 2, res.output
        line = _error_line(res)
        assert "--out" in line and "run.png" in line and ".nc" in line
    assert list(tmp_path.iterdir()) == []


# ======================================================================================
# the CLI: a figure that fails at the end does not cost the data
# ======================================================================================

def _broken_plot(monkeypatch, name, exc):
    import pwsdyn.plot

    def broken(*args, **kwargs):
        raise exc

    monkeypatch.setattr(pwsdyn.plot, name, broken)


def test_simulate_figure_failure_saves_the_data_next_to_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _broken_plot(monkeypatch, "plot_trajectory", OSError("disk full"))
    (tmp_path / "fig.nc").write_bytes(OLD)  # taken: the data go to fig-1.nc
    res = _run(SIMULATE + ["--plot", "fig.png"])
    assert res.exit_code == 1
    line = _error_line(res)
    assert "fig.png" in line and "disk full" in line and "fig-1.nc" in line
    assert load_trajectory(tmp_path / "fig-1.nc").t_end == 0.3
    assert (tmp_path / "fig.nc").read_bytes() == OLD


def test_sweep_figure_failure_with_out_keeps_out(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _broken_plot(monkeypatch, "plot_bifurcation", ValueError("cannot draw"))
    res = _run(SWEEP + ["--out", "d.nc", "--plot", "d.png"])
    assert res.exit_code == 1
    line = _error_line(res)
    assert "cannot draw" in line and "'d.nc'" in line
    assert _is_netcdf(tmp_path / "d.nc")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.nc"]


def test_sweep_second_figure_failure_is_named_and_saves_the_data(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _broken_plot(monkeypatch, "plot_lyapunov", OSError("no space left"))
    res = _run(SWEEP + ["--lyapunov", "--plot", "d.png"])
    assert res.exit_code == 1
    line = _error_line(res)
    assert "'d-lyapunov.png'" in line and "no space left" in line and "'d.nc'" in line
    assert "wrote       d.png" in res.stdout and _is_png(tmp_path / "d.png")
    with xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf") as ds:
        assert "lyapunov" in ds


def test_sweep_unexpected_figure_failure_still_saves_the_data(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _broken_plot(monkeypatch, "plot_bifurcation", RuntimeError("a bug"))
    with pytest.raises(RuntimeError, match="a bug"):  # a bug keeps its traceback...
        _run(SWEEP + ["--plot", "d.png"])
    with xr.open_dataset(tmp_path / "d.nc", engine="h5netcdf") as ds:  # ...not the data
        assert ds.attrs["parameter"] == "mu"


# ======================================================================================
# the CLI: model-provided text is sanitised
# ======================================================================================

EVIL_MODEL = f"""
name = "evil{EVIL}"
description = "first line {EVIL}"
states = ["x"]
[parameters]
k = 1.0
[modes.free]
x = "-k*x"
[defaults]
x0 = [1.0]
t_end = 0.5
""".replace("\x1b", "\\u001b").replace("\x07", "\\u0007").replace("\x9b", "\\u009b") \
   .replace("\u202e", "\\u202e")


def _assert_clean(text):
    for ch in RAW:
        assert ch not in text, (ch, text)
    assert "\\x1b]0;pwned\\x07" in text and "\\x9b" in text and "\\u202e" in text


def _evil_model(tmp_path, monkeypatch):
    """The model file above, loaded with the load-time check of its name switched off (it
    refuses control characters): the CLI must be safe on its own, for any text a model or a
    saved file carries."""
    path = tmp_path / "evil.toml"
    path.write_text(EVIL_MODEL)
    with pytest.raises(ModelError, match="non-printable"):
        pwsdyn.load_model(path)
    monkeypatch.setattr(pwsdyn.model.spec, "check_model_name", lambda name, W: name)
    return path, pwsdyn.load_model(path)


def test_safe_escapes_controls_and_keeps_text():
    assert _safe("ω = 2π, naïve") == "ω = 2π, naïve"
    assert _safe("a\x1b[2Jb") == "a\\x1b[2Jb"
    assert _safe("\x00\x7f\x85\x9b") == "\\x00\\x7f\\x85\\x9b"
    assert _safe("\u202e\u2066\u200f\u2028") == "\\u202e\\u2066\\u200f\\u2028"
    assert _safe("a\nb\tc\r") == "a\\nb\\tc\\r"
    assert _safe("\ud800") == "\\ud800"


def test_simulate_summary_is_sanitised(tmp_path, monkeypatch):
    path, model = _evil_model(tmp_path, monkeypatch)
    res = _run(["simulate", path], color=True)  # color: click strips nothing itself
    assert res.exit_code == 0, res.output
    _assert_clean(res.output)


def test_error_messages_are_sanitised(tmp_path, monkeypatch):
    path, model = _evil_model(tmp_path, monkeypatch)
    res = _run(["simulate", path, "--x0", "1,2"], color=True)  # click's own message
    assert res.exit_code == 2
    _assert_clean(res.output)
    res = _run(["simulate", path, "--mode", EVIL], color=True)  # the library's message
    assert res.exit_code == 1
    for ch in RAW:
        assert ch not in res.output


def test_models_listing_is_sanitised(tmp_path, monkeypatch):
    path, model = _evil_model(tmp_path, monkeypatch)

    def load(name, **kwargs):
        if name == "broken":
            raise ModelError(f"cannot read {EVIL}")
        return model

    monkeypatch.setattr(pwsdyn, "zoo_names", lambda: ["evil", "broken"])
    monkeypatch.setattr(pwsdyn, "load_model", load)
    res = _run(["models"])
    assert res.exit_code == 1  # one model failed to load
    _assert_clean(res.stdout)  # the name and the description
    _assert_clean(res.stderr)  # the load error


def test_warnings_are_sanitised(tmp_path, monkeypatch):
    real = pwsdyn.simulate

    def simulate(*args, **kwargs):
        warnings.warn(f"model says {EVIL}", UserWarning)
        return real(*args, **kwargs)

    monkeypatch.setattr(pwsdyn, "simulate", simulate)
    res = _run(SIMULATE, color=True)
    assert res.exit_code == 0, res.output
    assert "warning: model says" in res.stderr
    _assert_clean(res.stderr)


# ======================================================================================
# the CLI: pwsdyn's own errors are one line, never a traceback
# ======================================================================================

class _NewError(PwsdynError):
    """A pwsdyn error the CLI has never heard of."""


@pytest.mark.parametrize("command, target", [
    ("simulate", "simulate"), ("sweep", "sweep"), ("basins", "basins"),
    ("orbit", "find_periodic_orbit"),
])
@pytest.mark.parametrize("error", [_NewError, pwsdyn.StoreError, pwsdyn.ArgumentError,
                                   pwsdyn.SectionNotReachedError])
def test_pwsdyn_errors_are_one_clean_line(command, target, error, tmp_path, monkeypatch):
    import pwsdyn.orbits

    monkeypatch.chdir(tmp_path)

    def fail(*args, **kwargs):
        raise error(f"it went wrong {EVIL}")

    monkeypatch.setattr(pwsdyn.orbits if target == "find_periodic_orbit" else pwsdyn,
                        target, fail)
    res = _run(COMMANDS[command], color=True)
    assert res.exit_code == 1, res.output
    assert "it went wrong" in _error_line(res)
    for ch in RAW:
        assert ch not in res.output
