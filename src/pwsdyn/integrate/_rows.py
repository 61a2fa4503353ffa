"""A generated model quantity evaluated at many points in one compiled loop.

The checks along a computed orbit (admissibility, the monitors of discontinuity-induced
bifurcations) evaluate a surface at hundreds of dense-output samples per segment; one call
of the compiled model per sample from Python costs more than the integration itself. Used by
the compiled-model layer only (:meth:`pwsdyn.integrate.compiled.ModelContext.h_rows`).
"""

from __future__ import annotations

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
