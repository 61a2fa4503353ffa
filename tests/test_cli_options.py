"""One vocabulary for the command line, checked on every command of ``pwsdyn``.

The commands are enumerated from the group itself (a new command is checked without being
listed here); those that run a model are the ones with a MODEL argument. For each:

- every option has a help text, and no help text names an option the command does not have;
- the shared options (``-p/--param``, ``--x0``, ``--rtol``, ``--method``, ``--out``...) are
  on every model-running command with the same spelling, type and received default;
- the options that apply only to some commands (``--exact``, ``--no-progress``,
  ``--workers``...) are on exactly those, the same wherever they are;
- every shared option's default is checked against the API's by tests/test_defaults.py
  (``SAME_DEFAULT``, ``LIBRARY_DEFAULT``), or is listed here as having none.
"""

from __future__ import annotations

import re

import click
import pytest
from test_defaults import LIBRARY_DEFAULT, SAME_DEFAULT

from pwsdyn.cli import main

#: Options every command that runs a model has, with one meaning.
SHARED = ("--param", "--set", "--x0", "--rtol", "--atol", "--method", "--sliding", "--out",
          "--plot", "--force")

#: Options that apply to some model-running commands only, and the commands they apply to.
#: ``--exact``: where the command simulates; shooting integrates the variational equations,
#: which the exact propagator does not carry (the kernel steps exactly only without them).
#: ``--no-progress``: where there is a progress bar (``orbit`` has none). ``--workers`` and
#: ``--scheduler``: where the work is parallel. ``--t0``: where a run starts at a time
#: (``sweep`` and ``basins`` start at the API's forcing ``phase``).
WHERE_THEY_APPLY = {
    "--exact": {"simulate", "sweep", "scan", "basins"},
    "--no-progress": {"sweep", "scan", "basins", "continue", "grazing"},
    "--workers": {"sweep", "scan", "basins"},
    "--scheduler": {"sweep", "scan", "basins"},
    "--t0": {"simulate", "orbit", "continue", "grazing", "manifold", "crisis"},
}

#: Shared options with no API default to compare with: not given means "nothing" (no value
#: over the model's defaults, no file), as tests/test_defaults.py checks for [defaults].
NO_API_DEFAULT = {"--param", "--set", "--x0", "--out", "--plot"}
#: Options of one command that are no argument of the API function it calls, and why.
NOT_AN_API_ARGUMENT = {
    # pwsdyn.simulate takes t0 inside t_span; both apply the model's [defaults] t0, else 0
    # (test_defaults.py: test_simulate_without_x0_and_t_span_is_the_commands_default_run)
    ("simulate", "--t0"),
    # a terminal shows the bar by default; continue_orbit(progress=False) is the library's
    # default for scripts and notebooks
    ("continue", "--no-progress"),
    ("grazing", "--no-progress"),
    # locate_crisis(t0=0.0) is the section's phase; the command takes the model's [defaults]
    # t0 when --t0 is not given, as every command with --t0 does (else 0)
    ("crisis", "--t0"),
}

_OPTION_IN_TEXT = re.compile(r"(?<![\w-])--[A-Za-z][A-Za-z0-9]*(?:-[A-Za-z0-9]+)*")


def _commands():
    return sorted(main.commands.items())


def _model_commands():
    return [name for name, cmd in _commands()
            if any(isinstance(p, click.Argument) and p.name == "model" for p in cmd.params)]


def _flags(cmd) -> set:
    return {o for p in cmd.params if isinstance(p, click.Option)
            for o in (*p.opts, *p.secondary_opts)} | {"--help"}


def _option(cmd, flag):
    found = [p for p in cmd.params if isinstance(p, click.Option)
             and flag in (*p.opts, *p.secondary_opts)]
    return found[0] if found else None


def _sample(param) -> str:
    """A value click parses for ``param`` (its type decides)."""
    if isinstance(param.type, click.Choice):
        return param.type.choices[0]
    return {"integer": "2", "float": "1"}.get(param.type.name, "x")


def _minimal(cmd) -> list:
    """The shortest command line of ``cmd``: its required arguments and options only."""
    args = []
    for p in cmd.params:
        if isinstance(p, click.Argument) and p.required:
            args.append("m")
        elif isinstance(p, click.Option) and p.required:
            args += [p.opts[0], _sample(p)]
    return args


def _received(name) -> dict:
    """What the command receives from its shortest command line (click's parsing, which
    applies every default and runs nothing; not ``Option.default``, which recent click
    reports as a sentinel for a flag)."""
    cmd = main.commands[name]
    with cmd.make_context(name, _minimal(cmd)) as ctx:
        return dict(ctx.params)


def _kind(param) -> tuple:
    """What makes two options the same option: spellings, type, arity, visibility."""
    choices = tuple(param.type.choices) if isinstance(param.type, click.Choice) else None
    return (tuple(param.opts), tuple(param.secondary_opts), param.name, param.type.name,
            choices, param.multiple, param.is_flag, param.hidden, param.metavar)


def test_the_model_running_commands_are_found():
    # every command but the listing runs a model (the check below applies to all of them)
    assert set(_model_commands()) == set(main.commands) - {"models"}
    assert len(_model_commands()) >= 6


@pytest.mark.parametrize("name", sorted(main.commands))
def test_every_option_has_help(name):
    for p in main.commands[name].params:
        if isinstance(p, click.Option):
            assert p.help and p.help.strip(), (name, p.opts)
    for p in main.params:
        if isinstance(p, click.Option):
            assert p.help and p.help.strip(), p.opts


@pytest.mark.parametrize("name", sorted(main.commands))
def test_help_names_only_options_the_command_has(name):
    cmd = main.commands[name]
    texts = [cmd.help or ""] + [p.help or "" for p in cmd.params if isinstance(p, click.Option)]
    named = {m for t in texts for m in _OPTION_IN_TEXT.findall(t)}
    assert named - _flags(cmd) == set(), (name, sorted(named - _flags(cmd)))
    # the group's own help names no option of a command
    assert set(_OPTION_IN_TEXT.findall(main.help or "")) <= _flags(main)


def test_the_check_of_named_options_finds_a_missing_one():
    """The pattern finds options in prose and in examples, and nothing else."""
    text = ("the same as --sweep NAME; --x-from/--x-to; --x0 1,0; pwsdyn continue --out b.nc "
            "x--y a-b --no-exact")
    assert _OPTION_IN_TEXT.findall(text) == ["--sweep", "--x-from", "--x-to", "--x0", "--out",
                                             "--no-exact"]


def test_shared_options_are_the_same_on_every_model_running_command():
    names = _model_commands()
    received = {n: _received(n) for n in names}
    for flag in SHARED + tuple(WHERE_THEY_APPLY):
        have = {n: _option(main.commands[n], flag) for n in names}
        have = {n: o for n, o in have.items() if o is not None}
        if flag in SHARED:
            assert set(have) == set(names), (flag, sorted(set(names) - set(have)))
        else:
            assert set(have) == WHERE_THEY_APPLY[flag], (flag, sorted(have))
        kinds = {n: _kind(o) for n, o in have.items()}
        assert len(set(kinds.values())) == 1, (flag, kinds)
        defaults = {n: received[n][o.name] for n, o in have.items()}
        assert len({(type(v), v) for v in defaults.values()}) == 1, (flag, defaults)
    # the short spellings and the hidden synonym
    for n in names:
        cmd = main.commands[n]
        assert _option(cmd, "-p") is _option(cmd, "--param")
        assert _option(cmd, "-s") is _option(cmd, "--set") and _option(cmd, "--set").hidden


def test_every_shared_default_is_compared_with_the_api():
    checked = {(c, f) for c, f, *_ in SAME_DEFAULT} | {(c, f) for c, f, _ in LIBRARY_DEFAULT}
    for n in _model_commands():
        cmd = main.commands[n]
        for flag in SHARED + tuple(WHERE_THEY_APPLY):
            if (_option(cmd, flag) is None or flag in NO_API_DEFAULT
                    or (n, flag) in NOT_AN_API_ARGUMENT):
                continue
            assert (n, flag) in checked, (n, flag)


def test_shooting_defaults_say_why():
    """Where a command's integrator default differs from a simulation's (shooting), its help
    says so and why; elsewhere it names the simulation's."""
    for n in _model_commands():
        cmd = main.commands[n]
        rtol, method = _option(cmd, "--rtol").help, _option(cmd, "--method").help
        if "(default 1e-12" in rtol:
            assert "shooting" in rtol and "tighter than a simulation's 1e-10" in rtol, n
            assert "(default DOP853" in method and "shooting" in method, n
        else:
            assert "(default 1e-10)" in rtol and "(default auto" in method, n
