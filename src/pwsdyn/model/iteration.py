"""Iterating a piecewise-smooth map model: the orbit of one initial state.

Apart from :mod:`pwsdyn.model.maps` because it takes a model in any form
:func:`pwsdyn.load_model` accepts (a name, a file, a dict), which needs the loading code of
:mod:`pwsdyn.model.spec`, and the loading code needs the maps to read a map's file.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .. import _validate as V
from .maps import _map_kernel, compile_map
from .spec import as_model


def iterate(model, x0, n: int, params: Mapping[str, float] | None = None, transient: int = 0,
            bound: float = 1e12):
    """Iterate a map: ``transient`` iterations discarded, then ``n`` states recorded.

    Parameters
    ----------
    model : MapModel, str, path or dict
        A map model or anything :func:`pwsdyn.load_model` accepts that describes one.
    x0 : sequence or dict
        Initial state, in state order or by state name.
    n : int
        Number of states recorded (the first is the state after the transient).
    params : dict, optional
        Parameter values overriding the defaults.
    transient : int
        Iterations discarded first.
    bound : float
        Stop (status ``diverged``) when a component exceeds this magnitude.

    Returns
    -------
    states : numpy.ndarray, shape (n, n_states)
        NaN after an early stop.
    pieces : numpy.ndarray of int, shape (n,)
        Index of the piece applied to each recorded state (-1 after an early stop).

    Examples
    --------
    >>> xs, pieces = iterate("sqrt-map", [0.1], 5, params={"mu": 0.2, "lam": 0.3})
    >>> xs.shape
    (5, 1)
    """
    n = V.integer("n", n, lo=0)
    transient = V.integer("transient", transient, lo=0)
    bound = V.positive("bound", bound, allow_inf=True)
    model = as_model(model, kind="map", caller="iterate()")
    p = model.parameter_vector(params)
    x = V.state_vector(model, x0)
    V.memory(f"iterate() with n={n}", 8.0 * n * (model.n_states + 1))
    cm = compile_map(model)
    orbit_kernel = _map_kernel("orbit_kernel")
    _, xs, pieces, _, _ = orbit_kernel(cm.step, x, p if p.size else np.zeros(1),
                                       int(transient), int(n), float(bound))
    return xs, pieces
