"""The `pwsdyn` command line: listing, simulating, files written, clean errors."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import pwsdyn
from pwsdyn.cli import main
from pwsdyn.io import load_trajectory

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
VIB_ARGS = ["-p", "A=0.05", "-p", "omega=10", "-p", "e=0.5", "--t-end", "5"]

#: A model file with a [defaults] table (x0 as a table).
DEFAULTS_MODEL = """
name = "ball-with-defaults"
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
[defaults]
x0 = { y = 0.5, v = 0.0 }
t_end = 2.0
params = { e = 0.5 }
"""

#: A model file without [defaults]; the zero state is a harmless equilibrium.
NO_DEFAULTS_MODEL = """
name = "spring"
states = ["x", "v"]
[parameters]
k = 1.0
[modes.free]
x = "v"
v = "-k*x"
"""


def _runner():
    # click < 8.2 mixes stderr into stdout unless told not to; 8.2 always keeps both
    try:
        return CliRunner(mix_stderr=False)
    except TypeError:
        return CliRunner()


class _Result:
    """What a run printed: ``stdout``, ``stderr`` and both together (``output``)."""

    def __init__(self, res):
        self.exit_code = res.exit_code
        self.stdout = res.stdout
        self.stderr = res.stderr
        self.output = res.stdout + res.stderr


def _run(args):
    return _Result(_runner().invoke(main, args, catch_exceptions=False))


def _assert_png(path: Path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 20_000  # a real figure, not an empty canvas
    import matplotlib.image

    img = matplotlib.image.imread(str(path))
    assert img.shape[0] > 400 and img.shape[1] > 800
    # more than a blank page: many distinct colours
    assert len(np.unique(img.reshape(-1, img.shape[-1]), axis=0)) > 50


def test_no_command_prints_help():
    res = _run([])
    assert res.exit_code == 0
    assert "Usage" in res.output and "simulate" in res.output and "models" in res.output


def test_version():
    res = _run(["--version"])
    assert res.exit_code == 0 and pwsdyn.__version__ in res.output


def test_models_lists_the_zoo():
    res = _run(["models"])
    assert res.exit_code == 0, res.output
    for name in pwsdyn.zoo_names():
        assert name in res.output
    ball = pwsdyn.load_model("bouncing-ball")
    assert "y, v" in res.output
    assert "omega=" in res.output and "g=9.81" in res.output
    assert ball.description.splitlines()[0][:40] in res.output


def _models_listing() -> dict:
    """``pwsdyn models`` by model: the lines under each name."""
    res = _run(["models"])
    assert res.exit_code == 0, res.output
    blocks, name = {}, None
    for line in res.stdout.splitlines():
        if line and not line.startswith(" "):
            name = line.strip()
            blocks[name] = []
        elif line.strip():
            blocks[name].append(line.strip())
    return blocks


def test_models_summaries_end_at_a_clause_and_keep_the_equation():
    """Each model's summary is its description's first clauses, whole: it ends where a
    clause of the description ends (":", ";" or the sentence's full stop), and it keeps the
    equation where it fits (the impact oscillator's, the square-root map's)."""
    from pwsdyn.cli._main import SUMMARY_WIDTH

    blocks = _models_listing()
    assert set(blocks) == set(pwsdyn.zoo_names())
    for name, lines in blocks.items():
        text = " ".join(pwsdyn.load_model(name).description.split())
        summary = lines[0]
        assert text.startswith(summary), (name, summary)
        rest = text[len(summary):]
        assert rest == "" or rest[0] in ":;" or summary.endswith("."), (name, summary, rest)
        # the first clause always, more only within the width
        assert len(summary) <= SUMMARY_WIDTH or ":" not in summary, (name, summary)
        assert lines[1].startswith("states:")
    assert blocks["impact-oscillator"][0].endswith(
        ": x'' + eps x' + x = sin(omega t) while x < sigma")
    assert "mu - sqrt(x) for x > 0" in blocks["sqrt-map"][0]


@pytest.mark.parametrize("description, summary", [
    ("Title (a: b; c): x' = f(x; p); more. Second sentence.",
     "Title (a: b; c): x' = f(x; p); more."),
    ("A model: " + "y" * 200 + "; tail.", "A model"),
    ("One sentence with e.g. lower case after a stop. Next.",
     "One sentence with e.g. lower case after a stop."),
    ("A long first clause " + "z" * 200 + ": eq.", "A long first clause " + "z" * 200),
    ("", ""),
])
def test_model_summary_rule(description, summary):
    from pwsdyn.cli._main import summary as summarise

    assert summarise(description) == summary


def test_simulate_writes_data_and_plot(tmp_path):
    out, png = tmp_path / "run.nc", tmp_path / "run.png"
    res = _run(["simulate", "bouncing-ball", "--x0", "y=0.5", "--x0", "v=0", *VIB_ARGS,
                "--out", str(out), "--plot", str(png)])
    assert res.exit_code == 0, res.output
    for text in ("bouncing-ball", "impact", "chatter", "stick", "SUCCESS", "y=", "v="):
        assert text in res.output
    _assert_png(png)
    # the file holds the same trajectory as the Python API gives
    ref = pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0, 5),
                          params={"A": 0.05, "omega": 10, "e": 0.5})
    got = load_trajectory(out)
    np.testing.assert_array_equal(got.t, ref.t)
    np.testing.assert_array_equal(got.x, ref.x)
    assert [e.kind for e in got.events] == [e.kind for e in ref.events]
    assert got.params == ref.params


def test_x0_forms_agree(tmp_path):
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    assert _run(["simulate", "bouncing-ball", "--x0", "0.5,0", *VIB_ARGS, "--out", str(a)]
                ).exit_code == 0
    assert _run(["simulate", "bouncing-ball", "--x0", "v=0,y=0.5", *VIB_ARGS, "--out", str(b)]
                ).exit_code == 0
    np.testing.assert_array_equal(load_trajectory(a).x, load_trajectory(b).x)


def test_options_reach_the_simulation(tmp_path):
    out = tmp_path / "a.nc"
    res = _run(["simulate", "bouncing-ball", "--x0", "0.5,0", *VIB_ARGS, "--t0", "1",
                "--rtol", "1e-8", "--atol", "1e-10", "--method", "DOP853", "--mode", "flight",
                "--out", str(out)])
    assert res.exit_code == 0, res.output
    traj = load_trajectory(out)
    assert traj.t0 == 1.0 and traj.t_end == 5.0
    assert traj.options["rtol"] == 1e-8 and traj.options["atol"] == 1e-10
    assert traj.options["method"] == "DOP853" and traj.options["mode"] == "flight"


def test_nothing_written_without_out_or_plot(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _run(["simulate", "bouncing-ball", "--x0", "0.5,0", *VIB_ARGS])
    assert res.exit_code == 0, res.output
    assert list(tmp_path.iterdir()) == []


def test_defaults_table_is_used(tmp_path):
    model = tmp_path / "ball.toml"
    model.write_text(DEFAULTS_MODEL)
    out = tmp_path / "a.nc"
    res = _run(["simulate", str(model), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "note:" not in res.output
    traj = load_trajectory(out)
    np.testing.assert_array_equal(traj.x[0], [0.5, 0.0])
    assert traj.t_end == 2.0 and traj.params["e"] == 0.5
    # the command line wins over the defaults (--force: the first run's file is replaced)
    res = _run(["simulate", str(model), "--x0", "1,0", "-p", "e=0.9", "--t-end", "1",
                "--out", str(out), "--force"])
    assert res.exit_code == 0, res.output
    traj = load_trajectory(out)
    np.testing.assert_array_equal(traj.x[0], [1.0, 0.0])
    assert traj.t_end == 1.0 and traj.params["e"] == 0.9


def test_defaults_x0_as_list(tmp_path):
    model = tmp_path / "ball.toml"
    model.write_text(DEFAULTS_MODEL.replace("x0 = { y = 0.5, v = 0.0 }", "x0 = [0.25, 0.0]"))
    out = tmp_path / "a.nc"
    assert _run(["simulate", str(model), "--out", str(out)]).exit_code == 0
    np.testing.assert_array_equal(load_trajectory(out).x[0], [0.25, 0.0])


def test_missing_defaults_fall_back_with_a_note(tmp_path):
    model = tmp_path / "spring.toml"
    model.write_text(NO_DEFAULTS_MODEL)
    out = tmp_path / "a.nc"
    res = _run(["simulate", str(model), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "no --x0" in res.stderr and "x=0, v=0" in res.stderr
    assert "no --t-end" in res.stderr
    traj = load_trajectory(out)
    np.testing.assert_array_equal(traj.x[0], [0.0, 0.0])
    assert traj.t_end == 10.0


def test_readme_main_job(tmp_path, monkeypatch):
    """`pwsdyn simulate bouncing-ball --out run.nc --plot run.png` with nothing else."""
    if "defaults" not in pwsdyn.load_model("bouncing-ball").spec:
        pytest.skip("the zoo's bouncing-ball has no [defaults] table")
    monkeypatch.chdir(tmp_path)
    res = _run(["simulate", "bouncing-ball", "--out", "run.nc", "--plot", "run.png"])
    assert res.exit_code == 0, res.output
    assert "SUCCESS" in res.output
    _assert_png(tmp_path / "run.png")
    assert load_trajectory(tmp_path / "run.nc").success


@pytest.mark.parametrize("args, words", [
    (["-p", "nosuch=1"], ["--param", "nosuch"]),
    (["-p", "A=abc"], ["--param", "'A'", "abc", "not a number"]),
    (["-p", "A"], ["--param", "NAME=VALUE"]),
    (["-p", "A=inf"], ["--param", "finite"]),
    (["--x0", "1,2,3"], ["--x0", "2 states", "3"]),
    (["--x0", "1,abc"], ["--x0", "abc", "not a number"]),
    (["--x0", "y=1", "--x0", "w=0"], ["--x0", "unknown state", "w"]),
    (["--x0", "y=1"], ["--x0", "missing", "v"]),
    (["--x0", "y=1,0"], ["--x0", "not both"]),
    (["--x0", "y=1,y=2"], ["--x0", "given twice"]),
])
def test_bad_arguments_are_named(args, words):
    res = _run(["simulate", "bouncing-ball", "--t-end", "1", *args])
    assert res.exit_code == 2
    assert "Traceback" not in res.output
    err_lines = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(err_lines) == 1
    for w in words:
        assert w in err_lines[0], (w, err_lines[0])


@pytest.mark.parametrize("args, words", [
    (["--t-end", "-1"], ["t_end"]),
    (["--rtol", "-1"], ["rtol"]),
    (["--mode", "nope"], ["mode", "nope"]),
])
def test_bad_values_give_one_error_line(args, words):
    res = _run(["simulate", "bouncing-ball", "--x0", "1,0", *args])
    assert res.exit_code == 1
    assert res.stderr.strip().splitlines()[-1].startswith("Error:")
    assert "Traceback" not in res.output
    for w in words:
        assert w in res.stderr


def test_unknown_model_and_bad_file(tmp_path):
    res = _run(["simulate", "no-such-model"])
    assert res.exit_code == 1
    assert "Error:" in res.stderr and "no-such-model" in res.stderr
    assert "bouncing-ball" in res.stderr  # the message lists what exists
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nstates = ["x"]\n[modes.m]\nx = "x +* 2"\n')
    res = _run(["simulate", str(bad)])
    assert res.exit_code == 1
    assert "bad.toml" in res.stderr and "modes.m.x" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_failed_simulation_still_writes_then_errors(tmp_path):
    model = tmp_path / "blowup.toml"
    model.write_text('name = "blowup"\nstates = ["x"]\n[modes.m]\nx = "x**2"\n')
    out, png = tmp_path / "a.nc", tmp_path / "a.png"
    res = _run(["simulate", str(model), "--x0", "1", "--t-end", "2", "--out", str(out),
                "--plot", str(png)])
    assert res.exit_code == 1
    assert "Error:" in res.stderr and "stopped early" in res.stderr
    traj = load_trajectory(out)  # the partial run shows where it stopped
    assert traj.status.failed and traj.t_final < 1.0 + 1e-6
    _assert_png(png)


def _console_script() -> str:
    # the script sits beside the interpreter in a virtual environment; else on PATH
    here = Path(sys.executable).parent / ("pwsdyn.exe" if os.name == "nt" else "pwsdyn")
    found = str(here) if here.exists() else shutil.which("pwsdyn")
    assert found, "the `pwsdyn` console script is not installed (pip install -e .)"
    return found


def test_console_script(tmp_path):
    exe = _console_script()
    out, png = tmp_path / "run.nc", tmp_path / "run.png"
    proc = subprocess.run([exe, "simulate", "bouncing-ball", "--x0", "0.5,0", *VIB_ARGS,
                           "--out", str(out), "--plot", str(png)],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "SUCCESS" in proc.stdout
    assert len(load_trajectory(out).events) > 3
    _assert_png(png)

    proc = subprocess.run([exe, "simulate", "bouncing-ball", "-p", "A=x"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "not a number" in proc.stderr


# --------------------------------------------------------------------------------------
# the figure behind --plot
# --------------------------------------------------------------------------------------

def _dashed(ax):
    return [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]


def test_plot_draws_the_moving_table_and_the_fixed_floor(tmp_path):
    from pwsdyn.plot import plot_trajectory

    A, omega = 0.05, 10.0
    traj = pwsdyn.simulate("bouncing-ball", {"y": 0.5, "v": 0.0}, (0, 5),
                           params={"A": A, "omega": omega, "e": 0.5})
    fig = plot_trajectory(traj, path=tmp_path / "vib.png")
    _assert_png(tmp_path / "vib.png")
    ax_y, ax_v, ax_phase = fig.axes
    # the table y = A sin(omega t) is dashed in the y panel only
    (table,) = _dashed(ax_y)
    tt = np.asarray(table.get_xdata())
    np.testing.assert_allclose(table.get_ydata(), A * np.sin(omega * tt), rtol=0, atol=1e-15)
    assert _dashed(ax_v) == []
    # a moving table is no fixed curve of the phase plane
    assert ax_phase.collections and not [c for c in ax_phase.collections
                                         if type(c).__name__ == "QuadContourSet"]
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    for text in ("impact", "sticking", "chattering sequence", "stick"):
        assert text in legend

    floor = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 5), {"A": 0.0})
    fig = plot_trajectory(floor)
    ax_y, ax_v, ax_phase = fig.axes
    np.testing.assert_array_equal(_dashed(ax_y)[0].get_ydata(), 0.0)
    # with A = 0 the floor y = 0 is drawn in the phase plane as the line y = 0
    contours = [c for c in ax_phase.collections if type(c).__name__ == "QuadContourSet"]
    assert len(contours) == 1
    verts = np.concatenate([p.vertices for p in contours[0].get_paths()])
    np.testing.assert_allclose(verts[:, 0], 0.0, atol=1e-12)


def test_plot_marks_each_event_and_breaks_lines_at_jumps():
    from pwsdyn.plot import plot_trajectory

    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 2),
                           params={"e": 0.8, "A": 0.0})
    fig = plot_trajectory(traj, states=["v"], phase=("v", "y"))
    ax_v, ax_phase = fig.axes
    assert ax_v.get_ylabel() == "$v$" and ax_phase.get_xlabel() == "$v$"
    impacts = traj.events_of("impact")
    marks = [c for c in ax_v.collections if len(c.get_offsets()) == len(impacts)]
    assert marks
    np.testing.assert_array_equal(marks[0].get_offsets()[:, 0], [e.t for e in impacts])
    # the velocity line is broken at every impact: no segment joins v- to v+
    line = [ln for ln in ax_v.get_lines() if ln.get_linestyle() == "-"][0]
    assert np.isnan(np.asarray(line.get_ydata(), dtype=float)).sum() == len(impacts)


def test_plot_arguments_are_checked():
    from pwsdyn.plot import plot_trajectory

    traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 1))
    with pytest.raises(ValueError, match="unknown state 'z'"):
        plot_trajectory(traj, states=["z"])
    with pytest.raises(ValueError, match="two different states"):
        plot_trajectory(traj, phase=("y", "y"))
    with pytest.raises(ValueError, match="out of range"):
        plot_trajectory(traj, phase=(0, 5))


# --------------------------------------------------------------------------------------
# grazing and continue: the shared options
# --------------------------------------------------------------------------------------

GRAZING = ["grazing", "impact-oscillator", "--param", "sigma", "--from", "0.45", "--to", "0.0",
           "-p", "omega=2.8", "-p", "eps=0.1", "--x0", "x=-0.006,v=-0.41", "--t0", "0",
           "--no-progress"]


def _field(output: str, label: str) -> str:
    return next(ln[len(label):].strip() for ln in output.splitlines() if ln.startswith(label))


def test_grazing_writes_the_branch_and_the_map(tmp_path):
    """`grazing --out` is the branch up to the graze (load_branch reads it) with the map
    printed: the graze at sigma = R = 1/|1 - omega^2 + i eps omega| (the forced response's
    amplitude), a*, x* and the persistence sequence as printed; `--plot` the grazing orbit."""
    import json
    import math

    from pwsdyn.io import open_dataset
    from pwsdyn.orbits._base import SHOOTING_DEFAULTS

    out, png = tmp_path / "g.nc", tmp_path / "g.png"
    res = _run(GRAZING + ["--terms", "6", "--out", str(out), "--plot", str(png)])
    assert res.exit_code == 0, res.output
    listed = [ln.split()[1] for ln in res.stdout.splitlines() if ln.startswith("wrote")]
    assert listed == [str(out), str(png)]
    _assert_png(png)
    ds = open_dataset(out)
    R = 1.0 / math.hypot(1 - 2.8**2, 0.1 * 2.8)
    assert abs(ds.attrs["graze_value"] - R) < 1e-7
    assert ds.attrs["graze_kind"] == "GR" and ds.attrs["graze_scenario"] == "loss"
    assert f"{ds.attrs['graze_a_star']:.10g}" == _field(res.stdout, "a*")
    names = json.loads(ds.attrs["graze_coordinates"])
    assert names == ["x", "v", "t"]
    assert ", ".join(f"{n}={v:.10g}" for n, v in zip(names, ds["graze_x_star"].values)) == \
        _field(res.stdout, "x*")
    seq = ds["graze_persistence"].values
    assert seq.shape == (6,) and " ".join(f"{v:.3e}" for v in seq) == \
        _field(res.stdout, "h_x P^n beta")
    # h_x P^n beta from the matrices in the file
    P, beta, h_x = ds["graze_P"].values, ds["graze_beta"].values, ds["graze_h_x"].values
    np.testing.assert_allclose(h_x @ np.linalg.matrix_power(P, 3) @ beta, seq[2], rtol=1e-12)
    # the shooting's own defaults, as pwsdyn.find_periodic_orbit has them
    options = json.loads(ds.attrs["options"])
    assert {k: options[k] for k in SHOOTING_DEFAULTS} == SHOOTING_DEFAULTS
    br = pwsdyn.load_branch(out)
    assert br.special("GR")[0].value == pytest.approx(ds.attrs["graze_value"], abs=1e-12)
    # an existing file is refused before any work, and replaced with --force
    again = _run(GRAZING + ["--out", str(out)])
    assert again.exit_code == 1 and "--force" in again.stderr


def test_grazing_integrator_options_reach_the_branch(tmp_path):
    out = tmp_path / "g.nc"
    res = _run(GRAZING + ["--rtol", "1e-11", "--method", "rk45", "--out", str(out)])
    assert res.exit_code == 0, res.output
    import json

    from pwsdyn.io import open_dataset

    options = json.loads(open_dataset(out).attrs["options"])
    assert options["rtol"] == 1e-11 and options["method"] == "RK45"


@pytest.mark.parametrize("command", ["continue", "grazing"])
def test_continue_and_grazing_refuse_an_existing_file_before_any_work(command, tmp_path):
    out = tmp_path / "b.nc"
    out.write_bytes(b"old")
    res = _run([command, "no-such-model", "--param", "A", "--from", "0", "--to", "1",
                "--out", str(out)])
    assert res.exit_code == 1 and "b.nc" in res.stderr and "--force" in res.stderr
    assert out.read_bytes() == b"old"
    res = _run([command, "bouncing-ball", "--param", "A", "--from", "0", "--to", "1",
                "--plot", str(tmp_path / "b.xyz")])
    assert res.exit_code == 2 and "unknown figure format" in res.stderr


def test_continue_equilibrium_refuses_integrator_options():
    res = _run(["continue", "bouncing-ball", "--param", "A", "--from", "0", "--to", "1",
                "--equilibrium", "--rtol", "1e-8", "--sliding", "utkin"])
    assert res.exit_code == 2
    assert "--rtol, --sliding" in res.stderr and "without integrating" in res.stderr


def test_continue_sliding_reaches_the_branch(tmp_path):
    """--sliding chooses the starting orbit's sliding field, which the branch keeps (the
    relay's orbit slides on x1 = 0)."""
    import json

    from pwsdyn.io import open_dataset

    out = tmp_path / "r.nc"
    res = _run(["continue", "relay-feedback", "--param", "sigma", "--from", "1", "--to", "1.02",
                "--max-points", "2", "--sliding", "UTKIN", "--no-progress", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads(open_dataset(out).attrs["options"])["sliding"] == "utkin"
