"""Errors and run status shared by every part of pwsdyn.

Misuse (a bad argument, a malformed model) raises at once with a message that names the
argument or the file, line and field. Numerical failure (a budget spent, a step size that
collapsed) is a :class:`Status` on the result; with ``throw=True`` (the default) it is raised as
:class:`SolveError`, which names the time, state and mode where the run stopped.
"""

from __future__ import annotations

import enum


class PwsdynError(Exception):
    """Base class of all pwsdyn errors."""


class ModelError(PwsdynError, ValueError):
    """A model definition is malformed.

    The message names the source (file or ``<dict>``), the line where known, and the field.
    """

    def __init__(self, message: str, *, source: str | None = None, field: str | None = None,
                 line: int | None = None):
        where = []
        if source:
            where.append(str(source) + (f":{line}" if line else ""))
        if field:
            where.append(f"field `{field}`")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.source = source
        self.field = field
        self.line = line
        self.reason = message


class ExpressionError(ModelError):
    """An expression uses an unknown name, a forbidden construct or is not valid syntax."""


class Status(enum.IntEnum):
    """How a simulation ended. The text of each member says what happened and what to do."""

    SUCCESS = 0
    TERMINAL_EVENT = 1
    MAX_STEPS = 2
    MAX_EVENTS = 3
    STEP_TOO_SMALL = 4
    NONFINITE = 5
    SURFACE_INTERSECTION = 6
    ZENO = 7

    @property
    def message(self) -> str:
        return _STATUS_MESSAGES[self]

    @property
    def failed(self) -> bool:
        return self not in (Status.SUCCESS, Status.TERMINAL_EVENT)


_STATUS_MESSAGES = {
    Status.SUCCESS: "The integration reached the end of the time span.",
    Status.TERMINAL_EVENT: "A terminal event occurred.",
    Status.MAX_STEPS: "The maximum number of steps was reached. Increase `max_steps` or shorten "
                      "the time span.",
    Status.MAX_EVENTS: "The maximum number of events was reached (a Zeno sequence of impacts "
                       "that does not converge to sticking, or too short `max_events`). Enable "
                       "chattering detection on `impact` events or increase `max_events`.",
    Status.STEP_TOO_SMALL: "The step size fell below the resolution of the time variable. The "
                           "vector field may be singular or the solution may blow up here.",
    Status.NONFINITE: "The state or vector field became NaN or infinite.",
    Status.SURFACE_INTERSECTION: "The trajectory reached the intersection of two switching "
                                 "surfaces while sliding; sliding on intersections is not "
                                 "supported.",
    Status.ZENO: "Events accumulate in finite time (Zeno) and no chattering map applies.",
}


class SolveError(PwsdynError, RuntimeError):
    """A simulation or solve could not proceed. Carries where it stopped.

    Attributes
    ----------
    status : Status
    t : float
    x : dict[str, float]
    mode : str
    result : object or None
        The partial result (for example the `Trajectory` up to the failure).
    """

    def __init__(self, status: Status, t: float, x: dict, mode: str, result=None,
                 detail: str = ""):
        state = ", ".join(f"{k}={v:.17g}" for k, v in x.items())
        msg = f"{status.message} Stopped at t={t:.17g} in mode '{mode}' with state ({state})."
        if detail:
            msg += " " + detail
        super().__init__(msg)
        self.status = status
        self.t = t
        self.x = x
        self.mode = mode
        self.result = result


class ArgumentError(PwsdynError, ValueError, TypeError):
    """An argument of a pwsdyn function is of the wrong type, out of range or not finite.

    Raised before any work is done; the message names the argument and what it must be. It is
    both a ``ValueError`` and a ``TypeError`` so that code catching either keeps working.
    """


class StoreError(PwsdynError, OSError):
    """A result store on disk cannot be used: locked by another run, corrupted, truncated or
    tampered with. The message names the file; nothing in the store is overwritten."""


class OutputExistsError(PwsdynError, FileExistsError):
    """An output file exists and replacing it was not asked for (``overwrite=True`` in the
    API, ``--force`` on the command line). The message names the file; nothing is written."""
