"""Global analysis: saddle periodic points of maps and their one-dimensional stable and
unstable manifolds.

* :func:`pwsdyn.find_periodic_point` and :class:`pwsdyn.PeriodicPoint`: fixed and period-``k`` points of a
  piecewise-smooth map model (``kind = "map"``) with their multipliers and the pieces applied;
* :func:`pwsdyn.manifold` and :class:`pwsdyn.Manifold`: the 1-D manifolds of a saddle of a map model, or of a
  forced flow's periodic orbit on its stroboscopic Poincaré section, cut into pieces where the
  map jumps and resolved where it folds or stretches (a border, grazing);
* :func:`pwsdyn.locate_crisis` and :class:`pwsdyn.Crisis`: a boundary or interior crisis of a
  1-D map's attractor, located where its edge touches a repelling point's stable set, and a
  boundary crisis of a planar map's attractor (a forced two-state flow's through its
  stroboscopic section), located where a saddle's unstable manifold first touches a boundary
  saddle's stable manifold;
* :func:`pwsdyn.locate_tangency`: a homoclinic or heteroclinic tangency of two saddles'
  manifolds of a planar map, in one parameter;
* :class:`pwsdyn.ManifoldError`.
"""

from ._crisis import Crisis, locate_crisis, locate_tangency
from ._manifold import Manifold, manifold
from ._points import ManifoldError, PeriodicPoint, find_periodic_point

__all__ = ["Crisis", "Manifold", "ManifoldError", "PeriodicPoint", "find_periodic_point",
           "locate_crisis", "locate_tangency", "manifold"]
