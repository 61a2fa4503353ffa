"""Global analysis: saddle periodic points of maps and their one-dimensional stable and
unstable manifolds.

* :func:`pwsdyn.find_periodic_point` and :class:`pwsdyn.PeriodicPoint`: fixed and period-``k`` points of a
  piecewise-smooth map model (``kind = "map"``) with their multipliers and the pieces applied;
* :func:`pwsdyn.manifold` and :class:`pwsdyn.Manifold`: the 1-D manifolds of a saddle of a map model, or of a
  forced flow's periodic orbit on its stroboscopic Poincaré section, cut into pieces where the
  map jumps and resolved where it folds or stretches (a border, grazing);
* :class:`pwsdyn.ManifoldError`.
"""

from ._manifold import Manifold, manifold
from ._points import ManifoldError, PeriodicPoint, find_periodic_point

__all__ = ["Manifold", "ManifoldError", "PeriodicPoint", "find_periodic_point", "manifold"]
