"""Periodic orbits of hybrid models: Newton single and multiple shooting over the segments of
the orbit, with Floquet multipliers from the saltation-corrected monodromy matrix; orbits on a
fixed signature as problems ``F(u, p) = 0`` with exact Jacobians
(:class:`~pwsdyn.orbits.OrbitProblem`), and the monitors of their discontinuity-induced
bifurcations (:mod:`pwsdyn.orbits.monitors`, built on the point evaluations of
:mod:`pwsdyn.orbits.surfaces`)."""

from ._orbit import (PeriodicOrbit as PeriodicOrbit, Recurrence as Recurrence,
                     RecurrenceWarning as RecurrenceWarning)
from ._base import OrbitError as OrbitError
from ._shooting import find_periodic_orbit as find_periodic_orbit
from .monitors import Monitor as Monitor, MonitorKey as MonitorKey
from .problem import (Admissibility as Admissibility, OrbitProblem as OrbitProblem,
                      OrbitSensitivity as OrbitSensitivity,
                      ProblemEvaluation as ProblemEvaluation, SegmentFailed as SegmentFailed)
from .signature import Signature as Signature, SignatureEvent as SignatureEvent
