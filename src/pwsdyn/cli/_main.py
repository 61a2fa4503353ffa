"""The command group ``pwsdyn`` and its one command that runs no model, ``models``."""

from __future__ import annotations

import warnings

import click

from ._output import _echo, _fail, _fmt, _oneline, _safe, _show_warning


class _Group(click.Group):
    """The command group: every pwsdyn error is one clean ``Error:`` line, click's own
    messages and warnings are sanitised (they may quote model-provided names)."""

    def invoke(self, ctx):
        from ..errors import PwsdynError

        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            try:
                return super().invoke(ctx)
            except click.ClickException as exc:
                exc.message = _safe(exc.message)
                raise
            except PwsdynError as exc:
                _fail(exc)


@click.group(cls=_Group, invoke_without_command=True,
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="pwsdyn", prog_name="pwsdyn")
@click.pass_context
def main(ctx):
    """Numerical analysis of piecewise-smooth dynamical systems.

    Impacts, dry friction, Filippov sliding and chattering: simulate a built-in model or a
    model file (TOML) and write the trajectory and a figure.
    """
    if ctx.invoked_subcommand is None:
        click.echo(ctx.get_help())


# ======================================================================================
# pwsdyn models
# ======================================================================================

#: The longest summary of a model's description that ``models`` prints: as many whole
#: clauses as fit (the first one always, however long).
SUMMARY_WIDTH = 160


def _clauses(text: str) -> list:
    """The first sentence of ``text`` as its clauses, each with the mark that ends it: split
    after ``:`` and ``;`` followed by a blank, outside brackets (an equation's ``f(x; p)``
    stays whole); the sentence ends at a full stop followed by a capital or the end."""
    text = " ".join(text.split())
    out, depth, start, i = [], 0, 0, 0
    while i < len(text):
        ch = text[i]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth = max(depth - 1, 0)
        elif depth == 0 and ch in ":;" and text[i + 1:i + 2] == " ":
            out.append((text[start:i + 1], ch))
            start = i + 2
        elif depth == 0 and ch == "." and (i + 1 == len(text) or (
                text[i + 1] == " " and text[i + 2:i + 3].isupper())):
            out.append((text[start:i + 1], "."))
            return out
        i += 1
    if start < len(text):
        out.append((text[start:], "."))
    return out


def summary(description: str, width: int = SUMMARY_WIDTH) -> str:
    """A one-line summary of a model's ``description``: its first sentence, or as many of
    the sentence's leading clauses as fit in ``width`` characters (the first clause always),
    so that the summary keeps the model's name for itself and, where it fits, the equation
    after it ("Harmonically forced linear oscillator ...: x'' + eps x' + x = sin(omega t)
    while x < sigma"), and never stops inside a clause."""
    out = ""
    for text, mark in _clauses(description):
        longer = f"{out} {text}" if out else text
        if out and len(longer) > width:
            break
        out = longer
        if mark == ".":
            break
    return out.rstrip(":;")


@main.command("models")
def models_cmd():
    """List the built-in models with a summary of each, its states, parameters and modes."""
    import pwsdyn

    failed = 0
    for name in pwsdyn.zoo_names():
        try:
            model = pwsdyn.load_model(name)
        except Exception as exc:  # list the rest of the zoo even if one file is broken
            _echo(f"{name}\n  failed to load: {_oneline(exc)}\n", err=True)
            failed += 1
            continue
        # sanitised before styling: the bold escape sequence is ours, nothing in it is the model's
        click.echo(click.style(_safe(model.name), bold=True))
        text = summary(model.description)
        if text:
            # one line, not wrapped: a line break inside an equation would cut it in two
            _echo(f"  {text}")
        _echo(f"  states:     {', '.join(model.states)}")
        params = ", ".join(f"{k}={_fmt(v)}" for k, v in model.parameters.items())
        _echo(f"  parameters: {params or '(none)'}")
        _echo(f"  modes:      {', '.join(model.mode_names)}")
        _echo("")
    if failed:
        raise SystemExit(1)
