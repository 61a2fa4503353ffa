"""Floquet multipliers from a monodromy matrix."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


def _sorted(values) -> np.ndarray:
    values = np.asarray(values)
    # by decreasing modulus; ties (complex pairs) by decreasing imaginary part, so the order is
    # reproducible
    order = np.lexsort((-np.imag(values), -np.abs(values)))
    values = values[order]
    if np.all(np.abs(np.imag(values)) == 0):
        values = np.real(values)
    return values


def section_basis(normal) -> np.ndarray:
    """An orthonormal basis (columns) of the hyperplane ``normal . dx = 0``."""
    nv = np.asarray(normal, dtype=float).reshape(-1)
    nrm = np.linalg.norm(nv)
    if not (np.isfinite(nrm) and nrm > 0):
        raise ArgumentError("the section normal must be a nonzero finite vector")
    q, _ = np.linalg.qr(np.column_stack([nv / nrm, np.eye(len(nv))]))
    return q[:, 1:len(nv)]


def floquet_multipliers(monodromy: ArrayLike, *, flow_direction: ArrayLike | None = None,
                        section_normal: ArrayLike | None = None) -> np.ndarray:
    r"""Nontrivial Floquet multipliers, sorted by decreasing modulus.

    Parameters
    ----------
    monodromy : array_like, shape (n, n)
        Jacobian of the one-period map with full saltation matrices
        (``PeriodicOrbit.monodromy``, ``Trajectory.jacobian``).
    flow_direction : array_like, shape (n,), optional
        For an autonomous orbit: the vector field at the base point, eigenvector of the
        trivial multiplier 1. Without it every eigenvalue is returned (a forced system's
        time-``T`` map has no trivial multiplier).
    section_normal : array_like, shape (n,), optional
        Normal of the Poincaré section through the base point (default: ``flow_direction``).

    Returns
    -------
    numpy.ndarray
        ``n`` multipliers, or ``n - 1`` for an autonomous orbit: the eigenvalues of the
        Poincaré-map Jacobian of thesis eq. 2.25, :math:`(I - f h_x / (h_x f)) M`, restricted
        to the section's tangent space (where its eigenvalue 0 along :math:`f` is absent).
    """
    M = V.matrix("monodromy", monodromy)
    n = M.shape[0]
    if flow_direction is None:
        if section_normal is not None:
            raise ArgumentError("`section_normal` needs `flow_direction` (an autonomous orbit's "
                                "vector field at the base point)")
        return _sorted(np.linalg.eigvals(M))
    f = V.vector("flow_direction", flow_direction, size=n)
    nv = f if section_normal is None else V.vector("section_normal", section_normal, size=n)
    if not np.any(f) or not np.any(nv):
        raise ArgumentError("`flow_direction` and `section_normal` must be nonzero vectors")
    with np.errstate(over="ignore", invalid="ignore"):
        den = nv @ f
    if not (np.isfinite(den) and abs(den) > 1e-14 * np.linalg.norm(nv) * np.linalg.norm(f)):
        raise ArgumentError("the section is tangent to the flow (`section_normal` . "
                            "`flow_direction` = 0): no Poincaré map")
    P = M - np.outer(f, nv @ M) / den
    Q = section_basis(nv)
    return _sorted(np.linalg.eigvals(Q.T @ P @ Q))
