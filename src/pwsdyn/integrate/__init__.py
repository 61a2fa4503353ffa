"""Event-driven simulation: compiled Runge-Kutta kernel, events, chattering, sticking, sliding."""

from .simulate import simulate as simulate
from .trajectory import (DiscreteState as DiscreteState, EventLog as EventLog,
                         EventRecord as EventRecord, Trajectory as Trajectory)
