"""Per-segment transfer matrices of a hybrid trajectory and their products.

A simulation with ``variational=True`` keeps the Jacobian of each smooth segment and the
saltation matrix of each event apart (``Trajectory.transfer_matrices``). :func:`segments` pairs
them with the event log -- one :class:`Segment` per smooth piece, with the event that ends it --
and :func:`monodromy` multiplies them in order, in the full or the projected (thesis eq. 2.36)
form; this is the composition of COCO's ``hspo`` toolbox, ``P_i = S_i Phi_i``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import reduce
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ArgumentError
from ._saltation import _check_form, _check_trajectory, event_saltations

if TYPE_CHECKING:
    from ..integrate.trajectory import Trajectory


@dataclass(frozen=True, eq=False)
class Segment:
    """One smooth piece of a hybrid trajectory and the event that ends it.

    Attributes
    ----------
    index : int
    t_start, t_end : float
        The piece runs over ``[t_start, t_end]`` (``t_start`` is the previous event's
        ``t_after``).
    state : str
        Discrete state: mode name, ``stick:<event>`` or ``slide:<switch>``.
    flow : numpy.ndarray, shape (n, n)
        Jacobian of the flow over the piece, ``Phi_k``.
    event : EventRecord or None
        The event at ``t_end`` (``None`` for the last piece).
    saltation : numpy.ndarray or None
        Full saltation matrix of that event (``Phi+ = S Phi-``).
    saltation_projected : numpy.ndarray or None
        Its projected form (thesis eq. 2.36), where defined.
    """

    index: int
    t_start: float
    t_end: float
    state: str
    flow: np.ndarray
    event: object
    saltation: np.ndarray | None
    saltation_projected: np.ndarray | None

    @property
    def transfer(self) -> np.ndarray:
        """``S_k Phi_k`` (full form), or ``Phi_k`` for the last piece."""
        return self.flow if self.saltation is None else self.saltation @ self.flow


def segments(traj) -> list:
    """The smooth pieces of a trajectory with their transfer matrices.

    Parameters
    ----------
    traj : Trajectory
        A run with ``variational=True``.

    Returns
    -------
    list of Segment
        ``len(traj.events) + 1`` pieces; ``traj.jacobian`` is the ordered product of their
        ``transfer`` matrices.
    """
    _check_trajectory(traj)
    tm = traj.transfer_matrices
    evs = list(traj.events)
    proj = event_saltations(traj, "projected") if evs else []
    out = []
    t_prev = float(traj.t[0])
    state = traj.state[0]
    for k in range(len(evs) + 1):
        e = evs[k] if k < len(evs) else None
        out.append(Segment(k, t_prev, float(e.t) if e is not None else float(traj.t[-1]), state,
                           tm[2 * k], e, tm[2 * k + 1] if e is not None else None,
                           proj[k] if e is not None else None))
        if e is not None:
            t_prev = float(e.t_after)
            state = e.mode_after
    return out


def monodromy(traj: Trajectory, form: str = "full") -> np.ndarray:
    r"""Ordered product of the transfer matrices of a trajectory.

    Parameters
    ----------
    traj : Trajectory
        A run with ``variational=True`` (over one period for a monodromy matrix).
    form : {'full', 'projected'}
        ``full``: :math:`\Phi_m S_m \cdots S_1 \Phi_0` with the full saltation matrices, equal to
        ``traj.jacobian``; for an autonomous periodic orbit it has the trivial multiplier 1.
        ``projected``: the same product with the saltation matrices of thesis eq. 2.36, whose
        eigenvalue 0 replaces the trivial 1 (needs every event to have a projected form).

    Returns
    -------
    numpy.ndarray, shape (n, n)
    """
    _check_form(form)
    _check_trajectory(traj)
    tm = traj.transfer_matrices
    if form == "full":
        return reduce(lambda acc, m: m @ acc, tm[1:], tm[0].copy())
    sp = event_saltations(traj, "projected")
    missing = [e for e, s in zip(traj.events, sp) if s is None]
    if missing:
        raise ArgumentError(f"the projected form is not defined for {missing[0].kind!r} events "
                         f"({missing[0]!r}); use form='full'")
    acc = tm[0].copy()
    for k, s in enumerate(sp):
        acc = tm[2 * k + 2] @ (s @ acc)
    return acc
