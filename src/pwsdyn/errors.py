"""Errors and run status shared by every part of pwsdyn.

Misuse (a bad argument, a malformed model) raises at once with a message that names the
argument or the file, line and field. Numerical failure (a budget spent, a step size that
collapsed) is a :class:`Status` on the result; with ``throw=True`` (the default) it is raised as
:class:`SolveError`, which names the time, state and mode where the run stopped.
"""

from __future__ import annotations

import enum

from ._codes import MULTI_MAX


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
    """How a run or an analysis ended: the one vocabulary of outcomes of pwsdyn.

    Every result with a status (a :class:`~pwsdyn.integrate.trajectory.Trajectory`, a Lyapunov
    spectrum, the ``status`` variables of sweeps and basins, an :class:`OrbitError`) and every
    file's ``status`` variable (its ``flag_values`` and ``flag_meanings``) uses these members.
    The text of each member says what happened and what to do (:attr:`message`).

    Values 0 to 7 are the outcomes of the compiled integrator and keep the values files have
    always held. The outcomes of the analyses built on it are negative, so that no code of an
    analysis can be read as an outcome of the integrator: -1 diverged, -3 section missed (the
    values sweeps and basins always wrote), -4 no applicable map piece, and from -10 down the
    ways a periodic-orbit solve fails (:attr:`reason` gives the text :class:`OrbitError` has
    always used), and from -20 down the ways a continued branch ends (a branch's
    ``stop_status``; :data:`pwsdyn.errors.BRANCH_ENDS`).
    """

    # the compiled integrator (pwsdyn.integrate._kernel returns these codes)
    SUCCESS = 0
    TERMINAL_EVENT = 1
    MAX_STEPS = 2
    MAX_EVENTS = 3
    STEP_TOO_SMALL = 4
    NONFINITE = 5
    SURFACE_INTERSECTION = 6
    ZENO = 7
    # sweeps, basins, Lyapunov spectra and map iteration
    DIVERGED = -1
    SECTION_MISSED = -3
    NO_PIECE_APPLIES = -4
    # periodic orbits (find_periodic_orbit, OrbitProblem)
    SINGULAR = -10
    PHASE = -11
    EQUILIBRIUM = -12
    SIGNATURE = -13
    BUDGET = -14
    NO_PROGRESS = -15
    NEWTON_DIVERGED = -16
    SIMULATION_FAILED = -17
    # continued branches (continue_orbit, continue_equilibrium, continue_bifurcation): why a
    # branch ended; the branch also keeps the text (stop_reason), which names the values
    MAX_POINTS = -20
    MAX_ARCLENGTH = -21
    STEP_BELOW_DS_MIN = -22
    SPAN_END = -23
    BRANCH_NONFINITE = -24
    STOP_AT_SPECIAL_POINT = -25
    SPAN2_LEFT = -26
    SWITCH_FAILED = -27
    START_FAILED = -28

    # An IntEnum prints as its value (``0``) since Python 3.11; a status is read by people
    # far more often than it is parsed, so it prints by name. The value is still the int
    # (``int(status)``, comparisons and arithmetic with ints, NumPy arrays, JSON).
    def __repr__(self):
        return f"Status.{self.name}"

    def __str__(self):
        return self.name

    def __format__(self, spec):
        # f"{status}" and f"{status:>12}" give the name; a numeric format ("d", "3d", "x")
        # the value, as for the int it is
        if spec and spec[-1] in "bcdoxXneEfFgG%":
            return int.__format__(int(self), spec)
        return format(self.name, spec)

    @property
    def message(self) -> str:
        return _STATUS_MESSAGES[self]

    @property
    def failed(self) -> bool:
        # a branch that ended where its settings said (a budget of points or arclength, the
        # end of a span, a special point it was told to stop at) did what was asked
        return self not in (Status.SUCCESS, Status.TERMINAL_EVENT, *_BRANCH_ENDS_ASKED)

    @property
    def meaning(self) -> str:
        """The member as a word of a file's ``flag_meanings`` (its name in lower case)."""
        return self.name.lower()

    @property
    def reason(self) -> str:
        """The short text of the outcome, :attr:`meaning`, except for the orbit failures,
        whose text is the ``reason`` :class:`OrbitError` has always carried (``'diverged'``,
        ``'simulation'``, ...)."""
        return _ORBIT_REASONS.get(self, self.meaning)

    @classmethod
    def of_orbit(cls, reason: "str | Status") -> "Status":
        """The member of an orbit failure from its :attr:`reason` text (or the member)."""
        if isinstance(reason, Status):
            return reason
        for member, text in _ORBIT_REASONS.items():
            if text == reason:
                return member
        raise ValueError(f"unknown orbit failure reason {reason!r}; reasons are "
                         f"{sorted(_ORBIT_REASONS.values())}")

    @classmethod
    def from_meaning(cls, word: str) -> "Status":
        """The member named by a word of a file's ``flag_meanings``."""
        return cls[word.upper()]

    @classmethod
    def of_branch_stop(cls, text: str) -> "Status | None":
        """The member of a branch's end from its ``stop_reason`` text (a file written before
        branches kept their status); ``None`` for an empty or unknown text. Where a switch past
        a graze failed the text is ``"<why the first part ended>; <why the switch failed>"``."""
        if not text:
            return None
        first = text.split("; ", 1)[0]
        for member, words in _BRANCH_STOP_WORDS:
            if words in first:
                # a switch is tried only from a special point the branch stopped at: what
                # follows it is why the switch failed
                if member is cls.STOP_AT_SPECIAL_POINT and "; " in text:
                    return cls.SWITCH_FAILED
                return member
        return None

    @classmethod
    def integrator_outcomes(cls) -> tuple:
        """The members the compiled integrator returns (a trajectory's status)."""
        return tuple(s for s in cls if s >= 0)


#: The orbit failures, with the ``reason`` text of :class:`~pwsdyn.OrbitError`.
ORBIT_FAILURES = (Status.SINGULAR, Status.PHASE, Status.EQUILIBRIUM, Status.SIGNATURE,
                  Status.BUDGET, Status.NO_PROGRESS, Status.NEWTON_DIVERGED,
                  Status.SIMULATION_FAILED)
_ORBIT_REASONS = {s: s.name.lower() for s in ORBIT_FAILURES}
_ORBIT_REASONS[Status.NEWTON_DIVERGED] = "diverged"
_ORBIT_REASONS[Status.SIMULATION_FAILED] = "simulation"

#: How a continued branch can end, in the order of their values (-20 down).
BRANCH_ENDS = (Status.MAX_POINTS, Status.MAX_ARCLENGTH, Status.STEP_BELOW_DS_MIN,
               Status.SPAN_END, Status.BRANCH_NONFINITE, Status.STOP_AT_SPECIAL_POINT,
               Status.SPAN2_LEFT, Status.SWITCH_FAILED, Status.START_FAILED)
_BRANCH_ENDS_ASKED = (Status.MAX_POINTS, Status.MAX_ARCLENGTH, Status.SPAN_END,
                      Status.STOP_AT_SPECIAL_POINT, Status.SPAN2_LEFT)
#: Words of the ``stop_reason`` text that name each end (the texts the engine has always
#: written; used only for files that hold the text without the status).
_BRANCH_STOP_WORDS = ((Status.MAX_POINTS, "max_points = "),
                      (Status.MAX_ARCLENGTH, "max_arclength = "),
                      (Status.STEP_BELOW_DS_MIN, "fell below ds_min"),
                      (Status.SPAN_END, "reached the end of span"),
                      (Status.BRANCH_NONFINITE, "left the finite numbers"),
                      (Status.SPAN2_LEFT, "left span2"),
                      (Status.STOP_AT_SPECIAL_POINT, " located at "))

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
    Status.SURFACE_INTERSECTION: "The trajectory reached the intersection of switching "
                                 "surfaces while sliding, where the motion can neither cross "
                                 "nor leave them and cannot slide on the intersection: it is "
                                 "not attracting (the multilinear sliding rule has no solution "
                                 "in [0, 1]^k), a corner mode is missing, or more than "
                                 f"{MULTI_MAX} surfaces meet; or a contact would stick on an "
                                 "impact surface while a switching surface is slid on, which "
                                 "no discrete state holds. The final state is the state that "
                                 "reached it, and the message names the surface reached and "
                                 "the cause.",
    Status.ZENO: "Events accumulate in finite time (Zeno) and no chattering map applies.",
    Status.DIVERGED: "A state component grew beyond `bound`: the run diverged. Raise `bound` "
                     "if the attractor is that large.",
    Status.SECTION_MISSED: "The section at the end of the window was not reached (the last "
                           "event was not logged); lengthen the window or choose another "
                           "section.",
    Status.NO_PIECE_APPLIES: "No piece of the map applies at the state (every condition is "
                             "false there): complete the map's pieces, or give the last one "
                             "no condition.",
    Status.SINGULAR: "The Newton matrix is singular (a multiplier 1, or a phase condition "
                     "tangent to the flow).",
    Status.PHASE: "The phase condition is degenerate (the vector field vanishes or is "
                  "tangent to it at the guess): choose another guess or phase condition.",
    Status.EQUILIBRIUM: "The iteration converged to an equilibrium, not a periodic orbit: "
                        "start from a guess on the orbit.",
    Status.SIGNATURE: "The event sequence changed after it had been locked: the orbit is near "
                      "a grazing or sliding bifurcation, or the guess is not near it.",
    Status.BUDGET: "No convergence within `max_iter` Newton iterations: raise it or improve "
                   "the guess.",
    Status.NO_PROGRESS: "No Newton step reduced the residual: improve the guess.",
    Status.NEWTON_DIVERGED: "The Newton step or the period ran away: the guess is not near a "
                            "periodic orbit.",
    Status.SIMULATION_FAILED: "An interval of the orbit could not be integrated (see the "
                              "integrator's status in the message).",
    Status.MAX_POINTS: "The branch holds `max_points` points: raise it to follow the branch "
                       "further (or continue from the branch).",
    Status.MAX_ARCLENGTH: "The branch reached `max_arclength`: raise it to follow the branch "
                          "further.",
    Status.STEP_BELOW_DS_MIN: "The step fell below `ds_min`: the corrector could not pass a "
                              "singular or nonsmooth point of the branch (a graze, a corner); "
                              "lower `ds_min`, or continue past it with another signature "
                              "(`on_dib`).",
    Status.SPAN_END: "The parameter reached the end of `span`: the last point lies on its "
                     "boundary.",
    Status.BRANCH_NONFINITE: "The branch left the finite numbers (a solution grew without "
                             "bound): narrow `span`.",
    Status.STOP_AT_SPECIAL_POINT: "A special point at which the branch was asked to end "
                                  "(`on_dib='stop'`) was located: it is the branch's last "
                                  "point; continue from it to go on.",
    Status.SPAN2_LEFT: "The second parameter of the curve left `span2`.",
    Status.SWITCH_FAILED: "The orbit past a discontinuity-induced bifurcation (its new event "
                          "sequence) could not be found or followed; the branch ends at the "
                          "bifurcation.",
    Status.START_FAILED: "The branch could not be started: the start is not a solution at the "
                         "parameter value, or the problem is singular there.",
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
