"""Grazing analysis: Nordmark's discontinuity map at a grazing orbit and the persistence test
of the grazing bifurcation (thesis eq. 2.30-2.35), and the design of its low-cost control
(Paper B)."""

from .control import ControlDesign, design_control
from .discontinuity import SCENARIOS, DiscontinuityMap, discontinuity_map

__all__ = ["ControlDesign", "DiscontinuityMap", "SCENARIOS", "design_control",
           "discontinuity_map"]
