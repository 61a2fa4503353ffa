"""Assembly of the variational equations integrated per segment by the kernel.

With ``variational=True`` the kernel runs in its per-segment mode (``_kernel.VAR_SEGMENTS``):
between two events it integrates ``Phi' = J Phi`` from the identity, and at each event it
logs the segment's ``Phi`` (variational part of ``x_before``) and the full saltation matrix
``S`` of the event (variational part of ``x_after``), then restarts ``Phi`` at the identity.
This keeps every transfer matrix of a hybrid orbit apart -- the composition COCO's ``hspo``
toolbox uses, ``P_i = S_i Phi_i`` -- so a monodromy matrix is their ordered product and its
factors stay available (for projections, period doubling, grazing monitors).

:func:`assemble_segments` turns that output into the transfer-matrix list and, in place, into
the global ``Phi(t) = dx(t)/dx0`` that :class:`~pwsdyn.integrate.Trajectory` stores at its
nodes, in its dense output and in its events, so a trajectory looks the same as if ``Phi`` had
been integrated through every event.
"""

from __future__ import annotations

import numpy as np


#: Read-only identity matrices by size (the runs of one model all need the same one).
_EYES: dict = {}


def _eye(n: int) -> np.ndarray:
    e = _EYES.get(n)
    if e is None:
        e = np.eye(n)
        e.flags.writeable = False
        if len(_EYES) < 64:
            _EYES[n] = e
    return e


def segments_jacobian(n: int, ev_info: np.ndarray, ev_xb: np.ndarray, ev_xa: np.ndarray,
                      y_fin: np.ndarray) -> np.ndarray:
    """``dx(t_end)/dx0`` of a per-segment variational run alone: the Jacobian
    :func:`assemble_segments` returns, by the same products in the same order (so the same
    bits), without the transfer-matrix list and without globalising ``Phi`` in the outputs
    (which are left as the kernel wrote them). For runs whose end Jacobian is all that is
    read (the Newton iterations of shooting)."""
    m = len(ev_info)
    nn = n * n
    if not m:
        return y_fin[n:n + nn].reshape(n, n).copy() @ _eye(n)
    P = np.empty((m + 1, n, n))
    P[0] = _eye(n)
    for r in range(m):
        P[r + 1] = (ev_xa[r, n:n + nn].reshape(n, n).copy()
                    @ (ev_xb[r, n:n + nn].reshape(n, n).copy() @ P[r]))
    return y_fin[n:n + nn].reshape(n, n).copy() @ P[m]


def assemble_segments(n: int, nodes_y: np.ndarray, dense: np.ndarray, ev_info: np.ndarray,
                      ev_xb: np.ndarray, ev_xa: np.ndarray, y_fin: np.ndarray):
    """Transfer matrices of a per-segment variational run; globalise ``Phi`` in place.

    Parameters
    ----------
    n : int
        Number of states.
    nodes_y, dense, ev_info, ev_xb, ev_xa, y_fin : numpy.ndarray
        Kernel outputs (see :func:`pwsdyn.integrate._kernel.run_kernel`); column 8 of
        ``ev_info`` is the index of the node just after each event. ``nodes_y``, ``dense``,
        ``ev_xb``, ``ev_xa`` are modified in place: their variational parts become the global
        ``Phi``.

    Returns
    -------
    transfer : list of numpy.ndarray
        ``[Phi_0, S_1, Phi_1, ..., S_m, Phi_m]`` for ``m`` events: ``Phi_k`` is the Jacobian of
        the smooth flow over segment ``k`` (from event ``k``, or the start, to event ``k + 1``,
        or the end), ``S_k`` the full saltation matrix of event ``k`` (``Phi+ = S Phi-``), so
        ``jacobian = Phi_m S_m ... S_1 Phi_0``.
    jacobian : numpy.ndarray, shape (n, n)
        ``dx(t_end)/dx0``.
    """
    m = len(ev_info)
    nn = n * n
    if not m:
        # one segment (an orbit problem's segment runs): Phi is global already -- the
        # products with P[0] = I below leave finite nodes and dense output as they are
        # (up to the sign of a zero); the Jacobian is the same product as below
        phi = y_fin[n:n + nn].reshape(n, n).copy()
        return [phi], phi @ np.eye(n)
    phis = [ev_xb[r, n:n + nn].reshape(n, n).copy() for r in range(m)]
    phis.append(y_fin[n:n + nn].reshape(n, n).copy())
    salts = [ev_xa[r, n:n + nn].reshape(n, n).copy() for r in range(m)]
    transfer = [phis[0]]
    for r in range(m):
        transfer += [salts[r], phis[r + 1]]
    # P[k]: Jacobian from the start to just after the k-th event (P[0] = I)
    P = np.empty((m + 1, n, n))
    P[0] = np.eye(n)
    for r in range(m):
        P[r + 1] = salts[r] @ (phis[r] @ P[r])
    jacobian = phis[m] @ P[m]
    if m:
        ev_xb[:, n:n + nn] = np.matmul(np.array(phis[:m]), P[:m]).reshape(m, nn)
        ev_xa[:, n:n + nn] = P[1:].reshape(m, nn)
    # segment index of each node: the number of events whose post-event node is at or before it
    N = nodes_y.shape[0]
    post = np.asarray(ev_info[:, 8], dtype=np.int64) if m else np.zeros(0, dtype=np.int64)
    seg = np.searchsorted(post, np.arange(N), side="right")
    V = nodes_y[:, n:n + nn].reshape(N, n, n)
    nodes_y[:, n:n + nn] = np.matmul(V, P[seg]).reshape(N, nn)
    nint = dense.shape[0]
    if nint:
        deg = dense.shape[2]
        D = dense[:, n:n + nn, :].reshape(nint, n, n, deg)
        dense[:, n:n + nn, :] = np.einsum("iabk,ibc->iack", D, P[seg[:nint]]).reshape(
            nint, nn, deg)
    return transfer, jacobian
