"""Periodic orbits of hybrid models: Newton single and multiple shooting over the segments of
the orbit, with Floquet multipliers from the saltation-corrected monodromy matrix."""

from ._orbit import (PeriodicOrbit as PeriodicOrbit, Recurrence as Recurrence,
                     RecurrenceWarning as RecurrenceWarning)
from ._shooting import OrbitError as OrbitError, find_periodic_orbit as find_periodic_orbit
