"""The iteration loops of map models, compiled once for all maps (numba, cached on disk).

They take a map's generated ``step`` function as a first-class numba function of one fixed
signature (:data:`pwsdyn.model._map_step.MAP_STEP_TYPE`). Kept apart from :mod:`pwsdyn.model.maps`
so that loading a model (``pwsdyn models``, ``load_model``) does not load or compile them:
``pwsdyn.model.maps.orbit_kernel`` and ``lyapunov_kernel`` import this module on first use.
``nogil``: a sweep runs its chunks on threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from ._map_step import MAP_DIVERGED, MAP_NO_PIECE, MAP_NONFINITE, MAP_OK, MAP_STEP_TYPE

_f1 = types.float64[::1]
_f2 = types.float64[:, ::1]
_i1 = types.int64[::1]


@njit(cache=True, nogil=True)
def _step_status(y, bound):
    """The status after an iterate ``y``: non-finite, beyond ``bound``, or fine (the last
    offending component decides, as the loops always did)."""
    status = MAP_OK
    for i in range(y.shape[0]):
        if not np.isfinite(y[i]):
            status = MAP_NONFINITE
        elif abs(y[i]) > bound:
            status = MAP_DIVERGED
    return status


@njit(types.Tuple((types.int64, _f2, _i1, _f1, types.int64))(
    MAP_STEP_TYPE, _f1, _f1, types.int64, types.int64, types.float64), cache=True, nogil=True)
def orbit_kernel(step, x0, p, n_transient, n_samples, bound):
    """Iterate ``n_transient`` times, then record ``n_samples`` iterates.

    Returns (status, states (n_samples, n), piece applied to each recorded state, final
    state, iterations done); the status is the value of a :class:`pwsdyn.Status`. A state
    with a component beyond ``bound`` in magnitude ends the run with ``MAP_DIVERGED``; a
    state no piece claims with ``MAP_NO_PIECE``.
    """
    n = x0.shape[0]
    x = x0.copy()
    y = np.zeros(n)
    jac = np.zeros(n * n)
    xs = np.full((n_samples, n), np.nan)
    pieces = np.full(n_samples, -1, dtype=np.int64)
    status = MAP_OK
    total = n_transient + n_samples
    k = 0
    while k < total:
        pc = step(x, p, y, jac, 0)
        if k >= n_transient:
            for i in range(n):
                xs[k - n_transient, i] = x[i]
            pieces[k - n_transient] = pc
        if pc < 0:
            status = MAP_NO_PIECE
            break
        status = _step_status(y, bound)
        if status != MAP_OK:
            break
        for i in range(n):
            x[i] = y[i]
        k += 1
    return status, xs, pieces, x, k


@njit(types.Tuple((types.int64, _f1, _f1, types.int64))(
    MAP_STEP_TYPE, _f1, _f1, types.int64, types.int64, types.float64), cache=True, nogil=True)
def lyapunov_kernel(step, x0, p, n_transient, n_iter, bound):
    """Lyapunov spectrum of a map by QR (modified Gram-Schmidt) re-orthonormalisation of the
    tangent vectors after every iterate: ``lambda_i = (1/N) sum log |R_ii|``.

    Returns (status, exponents in Gram-Schmidt order, final state, iterations averaged).
    """
    n = x0.shape[0]
    x = x0.copy()
    y = np.zeros(n)
    jac = np.zeros(n * n)
    Q = np.eye(n)
    V = np.zeros((n, n))
    sums = np.zeros(n)
    status = MAP_OK
    k = 0
    while k < n_transient + n_iter:
        pc = step(x, p, y, jac, 1)
        if pc < 0:
            status = MAP_NO_PIECE
            break
        status = _step_status(y, bound)
        if status != MAP_OK:
            break
        if k >= n_transient:
            # V = J Q, then Gram-Schmidt: V = Q' R
            for i in range(n):
                for c in range(n):
                    s = 0.0
                    for m in range(n):
                        s += jac[i * n + m] * Q[m, c]
                    V[i, c] = s
            for c in range(n):
                for c2 in range(c):
                    d = 0.0
                    for i in range(n):
                        d += Q[i, c2] * V[i, c]
                    for i in range(n):
                        V[i, c] -= d * Q[i, c2]
                nrm = 0.0
                for i in range(n):
                    nrm += V[i, c] * V[i, c]
                nrm = np.sqrt(nrm)
                sums[c] += np.log(nrm)
                for i in range(n):
                    Q[i, c] = V[i, c] / nrm if nrm > 0.0 else (1.0 if i == c else 0.0)
        for i in range(n):
            x[i] = y[i]
        k += 1
    done = max(k - n_transient, 0)
    ex = np.full(n, np.nan)
    if done > 0:
        for i in range(n):
            ex[i] = sums[i] / done
    return status, ex, x, done
