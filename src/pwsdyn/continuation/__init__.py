"""Continuation: follow equilibria and hybrid periodic orbits in a parameter, locate their
bifurcations and switch branches.

The engine (:mod:`~pwsdyn.continuation.engine`) follows any problem ``F(u, lam) = 0`` with
its Jacobians by pseudo-arclength continuation; the problems
(:mod:`~pwsdyn.continuation.problems`) say what is continued; :class:`~pwsdyn.Branch` holds the
result.
"""

from .api import continue_bifurcation, continue_equilibrium, continue_orbit, load_branch
from .branch import KINDS, Branch, BranchPoint, SpecialPoint
from .engine import Continuation, ContinuationError, ContinuationSettings, Point
from .problems import (BifurcationCurveProblem, EquilibriumProblem, OrbitBranchProblem,
                       PseudoEquilibriumProblem)

__all__ = ["BifurcationCurveProblem", "Branch", "BranchPoint", "Continuation", "ContinuationError",
           "ContinuationSettings", "EquilibriumProblem", "KINDS", "OrbitBranchProblem", "Point",
           "PseudoEquilibriumProblem", "SpecialPoint", "continue_bifurcation",
           "continue_equilibrium", "continue_orbit", "load_branch"]
