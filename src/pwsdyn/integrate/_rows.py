"""A generated model quantity evaluated at many points in one compiled loop.

The checks along a computed orbit (admissibility, the monitors of discontinuity-induced
bifurcations) evaluate a surface at hundreds of dense-output samples per segment; one call
of the compiled model per sample from Python costs more than the integration itself. Used by
the compiled-model layer only (:meth:`pwsdyn.integrate.compiled.ModelContext.h_rows`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types as nt

from ..model.codegen import EVALUATE_TYPE

_f1 = nt.float64[::1]


@njit(nt.void(EVALUATE_TYPE, nt.int64, nt.int64, _f1, nt.float64[:, ::1], _f1, _f1, _f1),
      cache=True)
def first_of_rows(ev, which, idx, ts, X, p, buf, out):
    """``out[i]`` = the first value of quantity ``(which, idx)`` at ``(ts[i], X[i])``."""
    for i in range(ts.shape[0]):
        ev(which, idx, ts[i], X[i], p, buf)
        out[i] = buf[0]


_i1 = nt.int64[::1]


@njit(nt.float64[:, ::1](_f1, nt.float64[:, ::1], _i1, nt.float64[:, :, ::1], _f1, _i1,
                         nt.boolean), cache=True)
def dense_rows(t, y, ikind, dense, ts, idx, right):
    """The dense output of a trajectory at the times ``ts``, ``idx`` the interval of each
    (:meth:`pwsdyn.integrate.Trajectory.__call__`, which finds them): the interval's
    polynomial in power form (Horner, from the highest coefficient) inside a Runge-Kutta step,
    the straight line between its nodes inside a jump or chattering gap, the node on the
    ``right`` (else left) side of an interval of no length. The operations, in their order,
    are those of the array code it replaces, so that the values are the same bit for bit."""
    ns = ts.shape[0]
    ny = y.shape[1]
    deg = dense.shape[2]
    out = np.empty((ns, ny))
    for i in range(ns):
        j = idx[i]
        t0 = t[j]
        length = t[j + 1] - t0
        th = (ts[i] - t0) / length if length > 0 else 0.0
        if th < 0.0:
            th = 0.0
        if th > 1.0:
            th = 1.0
        if length > 0 and ikind[j] == 0:
            for c in range(ny):
                acc = 0.0
                for k in range(deg - 1, -1, -1):
                    acc = (acc + dense[j, c, k]) * th
                out[i, c] = y[j, c] + acc
        elif length <= 0:
            for c in range(ny):
                out[i, c] = y[j + 1, c] if right else y[j, c]
        else:
            for c in range(ny):
                out[i, c] = (1.0 - th) * y[j, c] + th * y[j + 1, c]
    return out
