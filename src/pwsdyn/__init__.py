"""pwsdyn: numerical analysis of piecewise-smooth dynamical systems.

Impacts, dry friction, Filippov sliding, chattering and grazing: models as data, compiled
event-driven simulation, stability, periodic orbits and global analysis.

``import pwsdyn`` is cheap: the public names below are imported from their subpackages on
first use (``pwsdyn.simulate``, ``from pwsdyn import sweep``), and the compiled integrator is
loaded only when a run needs it (compiled once per machine, with a message on stderr; see
:mod:`pwsdyn._compiling`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from ._version import __version__ as __version__

from .errors import (ArgumentError as ArgumentError, ExpressionError as ExpressionError,
                     ModelError as ModelError, OutputExistsError as OutputExistsError,
                     PwsdynError as PwsdynError,
                     StoreError as StoreError,
                     SolveError as SolveError, Status as Status)

#: Public names imported on first access, by the subpackage that defines them.
_LAZY = {
    "EventRecord": "integrate", "Trajectory": "integrate", "simulate": "integrate",
    "Model": "model", "compile_model": "model", "load_model": "model", "zoo_names": "model",
    "with_discrete_control": "model", "burridge_knopoff": "model",
    "OrbitError": "orbits", "PeriodicOrbit": "orbits", "RecurrenceWarning": "orbits",
    "find_periodic_orbit": "orbits",
    "SectionNotReachedError": "stability", "floquet_multipliers": "stability",
    "monodromy": "stability", "poincare_map": "stability", "saltation_matrix": "stability",
    "basins": "explore", "lyapunov_spectrum": "explore", "scan": "explore", "sweep": "explore",
    "Branch": "continuation", "continue_bifurcation": "continuation",
    "continue_equilibrium": "continuation",
    "continue_orbit": "continuation", "load_branch": "continuation",
    "discontinuity_map": "grazing", "design_control": "grazing",
    "Manifold": "manifolds", "ManifoldError": "manifolds", "PeriodicPoint": "manifolds",
    "find_periodic_point": "manifolds", "manifold": "manifolds",
    "Crisis": "manifolds", "locate_crisis": "manifolds", "locate_tangency": "manifolds",
}

#: Public subpackages and modules, imported on first access too (``pwsdyn.io.load_trajectory``,
#: ``pwsdyn.plot.plot_scan`` after a bare ``import pwsdyn``).
_SUBMODULES = frozenset({"continuation", "errors", "explore", "grazing", "integrate", "io",
                         "manifolds", "model", "newton", "orbits", "plot", "stability"})

__all__ = ["ArgumentError", "ExpressionError", "ModelError", "OutputExistsError", "PwsdynError",
           "StoreError", "SolveError", "Status", *_LAZY]

if TYPE_CHECKING:  # what static checkers and IDEs see; at run time see __getattr__
    from .continuation import (Branch, continue_bifurcation, continue_equilibrium,
                               continue_orbit, load_branch)
    from .explore import basins, lyapunov_spectrum, scan, sweep
    from .grazing import design_control, discontinuity_map
    from .integrate import EventRecord, Trajectory, simulate
    from .manifolds import (Crisis, Manifold, ManifoldError, PeriodicPoint,
                            find_periodic_point, locate_crisis, locate_tangency,
                            manifold)
    from .model import (Model, burridge_knopoff, compile_model, load_model,
                        with_discrete_control, zoo_names)
    from .orbits import OrbitError, PeriodicOrbit, RecurrenceWarning, find_periodic_orbit
    from .stability import (SectionNotReachedError, floquet_multipliers, monodromy,
                            poincare_map, saltation_matrix)


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)  # binds it in globals() too
    sub = _LAZY.get(name)
    if sub is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{sub}", __name__), name)
    globals()[name] = value   # later accesses are plain attribute lookups
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__) | _SUBMODULES)
