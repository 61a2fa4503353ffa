"""Grazing analysis: Nordmark's discontinuity map at a grazing orbit and the persistence test
of the grazing bifurcation (thesis eq. 2.30-2.35)."""

from .discontinuity import SCENARIOS, DiscontinuityMap, discontinuity_map

__all__ = ["DiscontinuityMap", "SCENARIOS", "discontinuity_map"]
