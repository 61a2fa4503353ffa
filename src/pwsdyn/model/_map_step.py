"""The interface between a map's generated ``step`` function and the iteration loops: the
one signature of every ``step`` and the outcome codes of the loops.

Its own module so that the loops (:mod:`pwsdyn.model._map_kernels`) and the map models
(:mod:`pwsdyn.model.maps`) both read it from below, and neither imports the other to get it.
"""

from __future__ import annotations

from numba import types

from ..errors import Status

#: Signature of a generated map function: step(x, p, out, jac, want_jac) -> piece.
MAP_STEP_SIGNATURE = types.int64(types.float64[::1], types.float64[::1], types.float64[::1],
                                 types.float64[::1], types.int64)
MAP_STEP_TYPE = types.FunctionType(MAP_STEP_SIGNATURE)

#: Outcomes of the iteration loops: the values of members of :class:`pwsdyn.Status` (plain
#: ints, as the compiled loops need), so that a status read from a loop means the same
#: wherever it is reported (before, "no piece applies" had the value of MAX_STEPS).
MAP_OK = int(Status.SUCCESS)
MAP_DIVERGED = int(Status.DIVERGED)
MAP_NO_PIECE = int(Status.NO_PIECE_APPLIES)
MAP_NONFINITE = int(Status.NONFINITE)
