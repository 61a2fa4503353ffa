"""pwsdyn: numerical analysis of piecewise-smooth dynamical systems.

Impacts, dry friction, Filippov sliding, chattering and grazing: models as data, compiled
event-driven simulation, stability, periodic orbits and global analysis.
"""

__version__ = "0.1.0"

from .errors import (ArgumentError as ArgumentError, ExpressionError as ExpressionError,
                     ModelError as ModelError, OutputExistsError as OutputExistsError,
                     PwsdynError as PwsdynError,
                     StoreError as StoreError,
                     SolveError as SolveError, Status as Status)
from .integrate import EventRecord as EventRecord, Trajectory as Trajectory, simulate as simulate
from .model import Model as Model, compile_model as compile_model, load_model as load_model
from .model import zoo_names as zoo_names
from .orbits import (OrbitError as OrbitError, PeriodicOrbit as PeriodicOrbit,
                     RecurrenceWarning as RecurrenceWarning,
                     find_periodic_orbit as find_periodic_orbit)
from .stability import (SectionNotReachedError as SectionNotReachedError,
                        floquet_multipliers as floquet_multipliers, monodromy as monodromy,
                        poincare_map as poincare_map, saltation_matrix as saltation_matrix)
from .explore import (basins as basins, lyapunov_spectrum as lyapunov_spectrum,
                      sweep as sweep)
