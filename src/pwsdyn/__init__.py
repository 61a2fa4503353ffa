"""pwsdyn: numerical analysis of piecewise-smooth dynamical systems.

Impacts, dry friction, Filippov sliding, chattering and grazing: models as data, compiled
event-driven simulation, stability, periodic orbits and global analysis.
"""

__version__ = "0.1.0"

from .errors import (ExpressionError as ExpressionError, ModelError as ModelError,
                     SolveError as SolveError, Status as Status)
from .integrate import EventRecord as EventRecord, Trajectory as Trajectory, simulate as simulate
from .model import Model as Model, compile_model as compile_model, load_model as load_model
from .model import zoo_names as zoo_names
