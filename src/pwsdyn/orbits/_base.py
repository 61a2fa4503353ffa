"""What the orbit modules share: the error of a failed solve, the integrator options of the
shooting code and the limits of its arguments.

Kept apart so that the result (:mod:`._orbit`), the orbit problem (:mod:`.problem`) and
Newton shooting (:mod:`._shooting`) all read them from below instead of from each other.
"""

from __future__ import annotations

from ..errors import PwsdynError, Status
from ..integrate.simulate import integrator_options

#: Integrator options used by the shooting code unless given: tight tolerances, 8th order.
SHOOTING_DEFAULTS = dict(method="DOP853", rtol=1e-12, atol=1e-12, max_steps=500_000)
#: Integrator options the shooting code sets itself.
RESERVED_OPTIONS = frozenset({"variational", "dense", "throw", "mode"})
#: Largest number of shooting nodes (the Newton matrix has ``(nodes * n + 1)**2`` entries).
MAX_NODES = 1000
#: Largest Newton budget and number of forcing periods of one orbit.
MAX_ITER = 10_000
MAX_PERIODS = 1_000_000
#: Default of ``max_periods`` of :meth:`PeriodicOrbit.from_trajectory`: the most forcing
#: periods searched for a recurrence of the trajectory.
RECURRENCE_MAX_PERIODS = 16
#: Relative size below which a surface value, normal velocity or acceleration counts as zero
#: in the admissibility checks (the orbit is at a grazing, a sliding or sticking boundary).
ADMISSIBILITY_RTOL = 1e-8
#: An orbit is reported stable when every multiplier has modulus below ``1 - STABILITY_MARGIN``
#: (a multiplier on the unit circle within the accuracy of the monodromy is not asymptotic
#: stability).
STABILITY_MARGIN = 1e-8


class OrbitError(PwsdynError, RuntimeError):
    """Newton shooting did not find a periodic orbit.

    Attributes
    ----------
    status : Status
        Why, as a member of the one status vocabulary (:data:`pwsdyn.errors.ORBIT_FAILURES`),
        with its :attr:`~pwsdyn.Status.message`.
    reason : str
        The same as a short text (``status.reason``): ``'singular'`` (the Newton matrix is
        singular: a multiplier 1, or a phase condition tangent to the flow), ``'phase'`` (the
        phase condition is degenerate), ``'equilibrium'`` (an autonomous iteration converged
        to a rest point), ``'signature'`` (the event sequence changed after it had been
        locked), ``'budget'`` (``max_iter`` Newton steps), ``'no_progress'`` (no step reduced
        the residual), ``'diverged'`` (the Newton step or the period ran away: the guess is
        not near an orbit), ``'simulation'`` (an interval could not be integrated).
    result : PeriodicOrbit or None
        The last iterate, with ``converged = False``.
    history : list[float]
        Residual norms of the iterates.
    """

    def __init__(self, reason: str | Status, message: str, result=None, history=None):
        super().__init__(message)
        self.status = Status.of_orbit(reason)
        self.reason = self.status.reason
        self.result = result
        self.history = list(history or [])


def shooting_options(options: dict, caller: str = "find_periodic_orbit()") -> dict:
    """The integrator options of a shooting run: ``options`` checked (names, types, ranges;
    none of :data:`RESERVED_OPTIONS`) over :data:`SHOOTING_DEFAULTS`."""
    integrator_options(options, caller, RESERVED_OPTIONS)
    return {**integrator_options({}, caller), **SHOOTING_DEFAULTS, **options}
