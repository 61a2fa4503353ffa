"""Grazing analysis: the discontinuity map, the persistence test and the control of a graze.

Nordmark's discontinuity map at a grazing orbit and the persistence test of the grazing
bifurcation (thesis eq. 2.30-2.35), and the design of its low-cost control (Paper B); the
friction impact oscillator of Papers D and E (condition 5.1, its stick-position map, law 5.3
and its robustness)."""

from .control import ControlDesign, design_control
from .discontinuity import SCENARIOS, DiscontinuityMap, discontinuity_map
from .friction_impact import ControlGains, FrictionImpact, controlled_model

__all__ = ["ControlDesign", "ControlGains", "DiscontinuityMap", "FrictionImpact", "SCENARIOS",
           "controlled_model", "design_control", "discontinuity_map"]
