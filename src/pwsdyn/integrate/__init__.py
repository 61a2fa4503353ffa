"""Event-driven simulation: compiled Runge-Kutta kernel, events, chattering, sticking, sliding.

:func:`simulate` is the user's entry point; :mod:`pwsdyn.integrate.compiled` (the compiled
model at parameter values, its point evaluations and its one run entry point) is the
analyses' way into the kernel."""

from .simulate import simulate as simulate
from .trajectory import (DiscreteState as DiscreteState, EventLog as EventLog,
                         EventRecord as EventRecord, Trajectory as Trajectory)
