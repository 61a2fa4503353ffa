"""Boundary and interior crises of piecewise-smooth maps, and tangencies of their manifolds,
located from the geometry.

One-dimensional maps
--------------------

An attractor of a 1-D map is bounded by iterates of its border points (where the piece
changes) and of its smooth pieces' critical points: its edges are ``F^k(c)``. Its basin is
bounded by repelling periodic points and their preimages (the 1-D stable sets of the saddles).
A boundary crisis is the parameter at which an edge first touches such a point (Grebogi, Ott
& Yorke 1983); an interior crisis the one at which it touches a repelling point inside its
basin, beyond which the attractor suddenly widens (as two symmetric attractors merge when
they reach the fixed point between them). Either way the contact function
``g(p) = s(p) - F^k(c(p))`` (signed so that it is positive before the crisis) changes sign
there and is root-found by ``scipy.optimize.brentq``. Escape (or a jump in the extent) is
only used to bracket the value on a coarse sweep; the value itself never comes from escape
times, whose scaling near a crisis makes them a poor measure of it.

Two-dimensional maps
--------------------
The attractor is the closure of a saddle's unstable manifold within it and its basin is bounded
by the stable manifold of a saddle: a boundary crisis is the first contact of the two curves,
a heteroclinic tangency (a homoclinic one when the boundary saddle's own unstable manifold
bounds the attractor; Grebogi, Ott & Yorke 1983). After the bracketing sweep the saddles of
the given periods around the attractor are found, and for every pair (``P``, ``S``), ``S`` off
the attractor, the signed contact function of ``W^u(P)`` and ``W^s(S)``
(``pwsdyn.manifolds._tangency``) is tried; the crisis is the root nearest the sweep's last
bounded value among those that change sign in the bracket.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import brentq
from scipy.spatial import cKDTree

from .. import _validate as V
from ..errors import ArgumentError
from ..model.spec import as_model
from ._points import (ManifoldError, PeriodicPoint, find_periodic_point, multiplier_variables,
                      section_point)
from ._sections import MapSection, StroboscopicSection
from ._tangency import Contact, as_point, root as contact_root

if TYPE_CHECKING:
    from pathlib import Path

    import xarray as xr

    from .._typing import PathLike


@dataclass(eq=False)
class Crisis:
    """A crisis of an attractor, located in one parameter.

    Attributes
    ----------
    model : MapModel
    param : str
        The parameter varied.
    value : float
        The parameter at which the attractor's edge touches the saddle's stable set.
    kind : str
        ``"boundary"`` (the attractor is destroyed beyond ``value``: its orbit leaves),
        ``"interior"`` (it suddenly widens: its extent jumps), or ``"tangency"`` (from
        :func:`pwsdyn.locate_tangency`: a homoclinic or heteroclinic tangency, no attractor
        followed).
    saddle : PeriodicPoint
        The saddle (the repelling periodic point of a 1-D map) whose stable set is touched, at
        ``value``, with its multipliers.
    point : numpy.ndarray, shape (n,)
        Where they touch: the point of the saddle's stable set (the saddle itself or one of its
        preimages) met by the attractor's edge, at ``value``; for a planar map the vertex of
        one manifold that reaches the other.
    bracket : tuple of float
        The sweep's value before the crisis was seen and the one at which it was (the orbit
        left, or the extent jumped); the ``span`` of a tangency.
    edge : tuple or None
        1-D maps: ``(k, c)``, the edge is the ``k``-th image of the border or critical point
        ``c`` (at ``value``).
    preimage : int or None
        1-D maps: ``0`` when the edge touches the saddle itself, ``1`` when it touches a
        preimage of it.
    history : list of tuple
        ``(parameter, contact)`` of every evaluation of the contact function.
    unstable : PeriodicPoint or None
        Planar maps: the saddle whose unstable manifold touches ``saddle``'s stable manifold
        (``saddle`` itself for a homoclinic tangency).
    manifolds : tuple
        Planar maps: the :class:`~pwsdyn.Manifold` objects ``(W^u(unstable), W^s(saddle))``
        at ``value``.
    """

    model: object
    param: str
    value: float
    kind: str
    saddle: PeriodicPoint
    point: np.ndarray
    bracket: tuple
    edge: tuple | None = None
    preimage: int | None = None
    history: list = field(default_factory=list)
    unstable: PeriodicPoint | None = None
    manifolds: tuple = ()

    def __repr__(self):
        return (f"Crisis({self.model.name!r}, {self.kind}, {self.param}={self.value:.12g}, "
                f"point={self.point.tolist()}, saddle period {self.saddle.period})")

    def to_dataset(self) -> "xr.Dataset":
        """The crisis as an :class:`xarray.Dataset`: the contact ``point``, the ``saddle``
        (its cycle and multipliers), the contact function's evaluations (``history_param``,
        ``history_contact``), for a planar map the other saddle (``unstable_saddle``) and the
        two manifolds' points at ``value`` (``unstable_x``, ``stable_x`` with their
        ``*_piece`` index, all pieces one after the other); the value, kind, bracket and
        parameters in the attributes with the provenance of every pwsdyn result (model
        text, versions)."""
        import xarray as xr

        from .._netcdf import cf_global_attrs, json_text, state_coords

        mult = np.atleast_1d(np.asarray(self.saddle.multipliers, dtype=complex))
        hist = np.array(self.history, dtype=float).reshape(-1, 2)
        data = {
            "point": (("state",), np.asarray(self.point, dtype=float),
                      {"long_name": "where the attractor (or unstable manifold) touches the "
                                    "saddle's stable set"}),
            "saddle": (("state",), np.asarray(self.saddle.x, dtype=float),
                       {"long_name": "the saddle whose stable set is touched"}),
            "saddle_cycle": (("cycle", "state"), np.asarray(self.saddle.cycle, dtype=float),
                             {"long_name": "the points of the saddle's cycle"}),
            **multiplier_variables(mult),
            "history_param": (("evaluation",), hist[:, 0],
                              {"long_name": f"{self.param} at each evaluation of the contact "
                                            "function"}),
            "history_contact": (("evaluation",), hist[:, 1],
                                {"long_name": "the contact function (positive before the "
                                              "crisis)"}),
        }
        if self.unstable is not None:
            data["unstable_saddle"] = (("state",), np.asarray(self.unstable.x, dtype=float),
                                       {"long_name": "the saddle whose unstable manifold "
                                                     "touches"})
        for m, name in zip(self.manifolds, ("unstable", "stable")):
            pieces = m.pieces
            data[f"{name}_x"] = ((f"{name}_point", "state"), np.concatenate(pieces),
                                 {"long_name": f"point of the {name} manifold at the crisis"})
            data[f"{name}_piece"] = ((f"{name}_point",), np.concatenate(
                [np.full(len(q), k, dtype=np.int64) for k, q in enumerate(pieces)]),
                {"long_name": "piece index (a polyline each)"})
        ds = xr.Dataset(data, coords=state_coords(self.model))
        ds.attrs.update(cf_global_attrs(
            self.model, "crisis", f"pwsdyn {self.kind} crisis of model {self.model.name}",
            "located from the geometry: the root of a contact function between the attractor "
            "and a saddle's stable set (pwsdyn.locate_crisis, pwsdyn.locate_tangency)"))
        ds.attrs.update({
            "crisis_kind": self.kind, "param": self.param, "value": float(self.value),
            "bracket": json_text([float(v) for v in self.bracket]),
            "parameters": json_text({k: float(v) for k, v in self.saddle.params.items()}),
            "saddle_period": int(self.saddle.period),
            "saddle_pieces": json_text(list(self.saddle.pieces)),
        })
        if self.unstable is not None:
            ds.attrs["unstable_period"] = int(self.unstable.period)
        if self.edge is not None:
            ds.attrs["edge"] = json_text([int(self.edge[0]), float(self.edge[1])])
        if self.preimage is not None:
            ds.attrs["preimage"] = int(self.preimage)
        return ds

    def save(self, path: PathLike, overwrite: bool = False) -> Path:
        """Write :meth:`to_dataset` to a NetCDF file; an existing file is refused
        (:class:`~pwsdyn.OutputExistsError`) unless ``overwrite=True``."""
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)


def _check_flow(model, caller, options=None):
    """A flow is taken through its stroboscopic section: it must be forced (a section map)
    with two states (a planar map). Integrator ``options`` are for a flow's runs; a map has
    none."""
    if getattr(model, "is_map", False):
        if options:
            raise ArgumentError(f"{caller}: integrator options ({', '.join(sorted(options))}) "
                                f"apply to flows; {model.name!r} is a map")
        return
    if model.forcing_period is None or model.n_states != 2:
        raise ArgumentError(f"{caller}: a flow is taken through its stroboscopic section, a "
                            "planar map: it needs a forcing period and two states; "
                            f"{model.name!r} has {model.n_states} states and "
                            f"{'a' if model.forcing_period is not None else 'no'} forcing "
                            "period")


def _attractor(sec: MapSection, x, transient: int, iterations: int, escape: float):
    """Iterate; the recorded samples, or ``None`` when the orbit leaves (no piece applies,
    not finite, beyond ``escape``)."""
    x = np.array(x, dtype=float)
    out = np.empty(iterations)
    for i in range(transient + iterations):
        x, sig, _ = sec.evaluate(x)
        if sig is None or abs(x[0]) > escape:
            return None
        if i >= transient:
            out[i - transient] = x[0]
    return out


def _repelling(pt) -> bool:
    """Every multiplier outside the unit circle: in one dimension, a point of a basin's
    boundary (its stable set is itself and its preimages)."""
    return bool(np.all(np.abs(pt.multipliers) > 1 + 1e-9))


def _piece(sec, x) -> int:
    _, sig, _ = sec.evaluate(np.array([x]))
    return -1 if sig is None else sig[0]


def _special_points(sec, samples) -> list:
    """Border points (bisection, to adjacent floats, between samples in different pieces) and
    critical points (a sign change of the derivative inside one piece) among the samples."""
    xs = np.unique(samples)
    pieces = [_piece(sec, x) for x in xs]
    out = []
    for a, b, pa, pb in zip(xs[:-1], xs[1:], pieces[:-1], pieces[1:]):
        if pa != pb:
            out.append(("border", _border(sec, a, b)))
        else:
            da = sec.evaluate(np.array([a]), True)[2][0, 0]
            db = sec.evaluate(np.array([b]), True)[2][0, 0]
            if da * db < 0:
                out.append(("critical", _critical(sec, a, b)))
    return out


def _border(sec, a, b) -> float:
    pa = _piece(sec, a)
    for _ in range(200):
        m = 0.5 * (a + b)
        if m in (a, b):
            break
        if _piece(sec, m) == pa:
            a = m
        else:
            b = m
    return a


def _critical(sec, a, b) -> float:
    return brentq(lambda x: sec.evaluate(np.array([x]), True)[2][0, 0], a, b, xtol=1e-15)


def _edge(sec, c, k) -> float:
    y = np.array([c], dtype=float)
    for _ in range(k):
        y, sig, _ = sec.evaluate(y)
        if sig is None:
            return np.nan
    return float(y[0])


def _preimage(sec, target, x, piece, tol=1e-14, max_iter=60):
    """A preimage of ``target`` by Newton on ``F(x) - target`` from ``x``, required to stay on
    ``piece``; ``None`` otherwise."""
    x = float(x)
    for _ in range(max_iter):
        y, sig, J = sec.evaluate(np.array([x]), True)
        if sig is None or sig[0] != piece or J[0, 0] == 0:
            return None
        r = y[0] - target
        if abs(r) <= tol * (1 + abs(target)):
            return x
        x -= r / J[0, 0]
    return None


class _Contact:
    """One candidate contact: edge ``F^k(c)`` against the saddle (``pre = -1``) or its
    preimage on piece ``pre``; continued in the parameter from the nearest evaluated value."""

    def __init__(self, k, kind_c, side, period, pre):
        self.k, self.kind_c, self.side, self.period, self.pre = k, kind_c, side, period, pre
        self.known = {}    # parameter -> (c, saddle x, point)

    def evaluate(self, ctx, p):
        near = min(self.known, key=lambda q: abs(q - p))
        c0, s0, pt0 = self.known[near]
        sec = ctx.section(p)
        try:
            sad = find_periodic_point(sec.model, [s0], self.period, params=sec.params)
        except ManifoldError:
            return np.nan, None
        if not _repelling(sad):
            return np.nan, None
        if self.kind_c == "border":
            d = 1e-6 * (1 + abs(c0))
            a, b = c0 - d, c0 + d
            while _piece(sec, a) == _piece(sec, b):
                d *= 4
                if d > 1e3 * (1 + abs(c0)):
                    return np.nan, None      # the border is gone: no contact to follow
                a, b = c0 - d, c0 + d
            c = _border(sec, a, b)
        else:
            def slope(x):
                return sec.evaluate(np.array([x]), True)[2][0, 0]

            d = 1e-3 * (1 + abs(c0))
            while slope(c0 - d) * slope(c0 + d) > 0:
                d *= 2
                if d > 1e3 * (1 + abs(c0)):
                    return np.nan, None
            c = _critical(sec, c0 - d, c0 + d)
        point = sad.x[0] if self.pre < 0 else _preimage(sec, sad.x[0], pt0, self.pre)
        if point is None:
            return np.nan, None
        e = _edge(sec, c, self.k)
        self.known[p] = (c, sad.x[0], point)
        return self.side * (point - e), (sad, point, c)


class _Context:
    def __init__(self, model, param, params, t0: float = 0.0, options=None):
        self.model, self.param, self.params = model, param, dict(params or {})
        self.is_map = bool(getattr(model, "is_map", False))
        self.t0 = t0
        self.options = dict(options or {})    # a flow's integrator options

    def section(self, p):
        prm = {**self.params, self.param: float(p)}
        if self.is_map:
            return MapSection(self.model, prm, 1)
        # a forced flow: its stroboscopic map at phase t0, over the forcing period at p
        T = self.model.forcing_period_value(prm)
        return StroboscopicSection(self.model, prm, self.t0, float(T), 1, self.options)


def _periodic(sec, x, period):
    """A periodic point of the section's map from ``x``: a map model's, or a point of a flow's
    stroboscopic map at the section's phase."""
    if sec.is_map:
        return find_periodic_point(sec.model, x, period, params=sec.params)
    return section_point(sec.model, x, period, params=sec.params, t0=sec.t0,
                         options=sec.options)


def _candidates(ctx, p, samples, periods, seeds) -> list:
    sec = ctx.section(p)
    lo, hi = float(samples.min()), float(samples.max())
    width = max(hi - lo, 1e-12)
    specials = _special_points(sec, samples)
    edges = []
    for kind_c, c in specials:
        for k in range(1, 7):
            e = _edge(sec, c, k)
            if np.isfinite(e):
                edges.append((k, kind_c, c, e))
    if edges:
        # the attractor's hull is that of its edges (exact), which a short record of its
        # orbit may not have reached: a point inside it is not on the basin's boundary
        lo = min(lo, min(e for *_, e in edges))
        hi = max(hi, max(e for *_, e in edges))
    saddles = []
    starts = np.linspace(lo - seeds * width, hi + seeds * width, 41)
    for period in periods:
        for s in starts:
            try:
                pt = find_periodic_point(sec.model, [s], period, params=sec.params)
            except ManifoldError:
                continue
            if not _repelling(pt):
                continue
            # a point of a shorter cycle dividing the period is that cycle, already found
            if any(period % q.period == 0 and np.min(np.abs(q.cycle[:, 0] - pt.x[0]))
                   < 1e-9 * (1 + abs(pt.x[0])) for q in saddles):
                continue
            saddles.append(pt)
    out = []
    for sad in saddles:
        targets = [(-1, sad.x[0])]
        for s in starts:
            pc = _piece(sec, s)
            x = _preimage(sec, sad.x[0], s, pc)
            if x is not None and abs(x - sad.x[0]) > 1e-9 * (1 + abs(x)) and all(
                    abs(x - t) > 1e-9 * (1 + abs(x)) for _, t in targets):
                targets.append((pc, x))
        for pre, t in targets:
            if lo < t < hi:
                continue       # inside the attractor: not on its basin's boundary
            side = 1.0 if t > hi else -1.0
            for k, kind_c, c, e in edges:
                cand = _Contact(k, kind_c, side, sad.period, pre)
                cand.known[p] = (c, sad.x[0], t)
                out.append((side * (t - e), cand))
    return out


def _jumped(before, after, jump) -> bool:
    """The attractor's extent grew by more than the factor ``jump`` and by more than a tenth
    of its size (so that a period doubling from a point, width zero, is not a widening)."""
    w0 = float(before.max() - before.min())
    w1 = float(after.max() - after.min())
    scale = max(float(np.max(np.abs(after))), 1e-300)
    return w1 > jump * w0 and w1 - w0 > 0.1 * scale


def _locate(ctx, bounded, p_hi, periods, tol, back: int = 4):
    """The contact root between one of the last bounded values of the sweep and ``p_hi``: the
    last one first, then up to ``back`` earlier ones (an attractor whose orbit has not left
    yet within the iterations can already be past the crisis)."""
    for p_lo, samples in bounded[::-1][:back + 1]:
        cands = _candidates(ctx, p_lo, samples, periods, 1.0)
        cands.sort(key=lambda t: t[0])
        best = None
        for g_lo, cand in cands:
            if g_lo < 0:
                continue
            g_hi, _ = cand.evaluate(ctx, p_hi)
            if not np.isfinite(g_hi) or g_hi > 0:
                continue
            history = []

            def g(q, cand=cand, history=history):
                v, _ = cand.evaluate(ctx, q)
                history.append((q, v))
                return v

            try:
                root = brentq(g, p_lo, p_hi, xtol=tol)
            except (ValueError, RuntimeError):
                continue
            if best is None or abs(root - p_lo) < abs(best[0] - p_lo):
                best = (root, cand, history, p_lo)
        if best is not None:
            return best
    return None


def locate_crisis(model, param: str, span, *, x0=None, params=None, tol: float = 1e-12,
                  steps: int = 41, transient: int = 2000, iterations: int = 2000,
                  periods=(1, 2), escape: float = 1e8, jump: float = 1.5,
                  arclength: float | None = None, manifold_tol: float = 1e-9,
                  seeds=None, t0: float = 0.0, **options) -> "Crisis":
    """A boundary or interior crisis of a one-dimensional map's attractor, or a boundary crisis
    of a planar map's attractor, located from the geometry.

    The attractor reached from ``x0`` is followed through ``span`` on ``steps`` values (each
    started from the last state of the previous one, as :func:`pwsdyn.sweep` does for maps);
    the first value at which the orbit leaves (diverges beyond ``escape`` or leaves the map's
    domain: a boundary crisis) or the attractor's extent grows by the factor ``jump`` (an
    interior crisis) brackets the crisis. There, the attractor's edges (images ``F^k(c)``,
    ``k <= 6``, of its border points ``c`` and its pieces' critical points, each found to
    adjacent floats) and its basin's boundary points (repelling periodic points of the given
    ``periods`` and their preimages) are found; the crisis is the root, by
    ``scipy.optimize.brentq`` to ``tol``, of the first contact function ``saddle point - edge``
    that changes sign in the bracket, each continued in the parameter by Newton. When none
    does (an orbit slow to find the way out leaves only well past the crisis), earlier values
    of the sweep are tried as the bracket's lower end.

    A planar map's attractor is followed in the same way (only its destruction, a boundary
    crisis, is bracketed). There, its saddles of the given ``periods`` are found (Newton from
    points of the attractor and of a grid around it), and for each pair ``(P, S)`` of them,
    ``S`` not on the attractor, the contact of ``W^u(P)`` with ``W^s(S)`` (both grown to
    ``arclength`` with :func:`pwsdyn.manifold`) is located as by
    :func:`pwsdyn.locate_tangency`; the crisis is the root nearest the bracket's lower end.

    Parameters
    ----------
    model : MapModel, Model, str, path or dict
        A one- or two-dimensional map model (``kind = "map"``), or a forced two-state flow,
        taken through its stroboscopic section ``x(0) -> x(T)`` (``T`` its forcing period at
        each parameter value): a planar map whose saddles are found by Newton with the runs'
        monodromy matrices and whose manifolds :func:`pwsdyn.manifold` grows.
    param : str
        The parameter varied.
    span : (float, float)
        Start and end values; the attractor at the start must be bounded.
    x0 : sequence or dict, optional
        Initial state (default: the model's ``[defaults] x0``).
    params : dict, optional
        The other parameters' values.
    tol : float
        Absolute tolerance on the located value.
    steps : int
        Values in the bracketing sweep.
    transient, iterations : int
        Iterations discarded, then recorded, at each value of the sweep.
    periods : sequence of int
        Periods of the saddles considered.
    escape : float
        An orbit with ``|x|`` beyond it has left.
    jump : float
        The growth factor of the attractor's extent between two values that is a sudden
        widening (also by more than a tenth of the attractor's magnitude, so that a period
        doubling is not one); a widening with no contact in its bracket (a period doubling, a
        window's end at a saddle of another period) is passed over.
    arclength : float, optional
        Planar maps: the length of each branch of the manifolds (default four times the
        attractor's diameter).
    manifold_tol : float
        Planar maps: the manifolds' ``tol`` (the deviation of their chords from the curves),
        which bounds the error of a smooth contact; a polygonal one (a piecewise-linear map's)
        is exact.
    seeds : sequence of array_like, optional
        Planar maps: more starting points for the saddles' Newton, besides the attractor and
        the grid around it (a boundary saddle far from the attractor, or one whose map
        expands so strongly that Newton needs a close guess).
    t0 : float
        Flows: the phase of the stroboscopic section, ``x(t0) -> x(t0 + T)``. A manifold
        that reaches an impact surface at the section's time ends there (its continuation
        past the reset is not followed): choose a phase at which the attractor's contact
        with the boundary saddle's stable manifold is away from the surfaces.
    **options
        Flows: integrator options of the section map's runs (``rtol``, ``atol``, ``method``,
        ... as for :func:`pwsdyn.manifold`); a map takes none.

    Returns
    -------
    Crisis

    Raises
    ------
    ManifoldError
        The attractor survives the whole span without widening, or no contact of an edge with
        a saddle's stable set changes sign in the bracket of its escape.

    Examples
    --------
    >>> c = locate_crisis("sqrt-map", "mu", (0.5, 0.125), params={"lam": 2.0})
    >>> c.kind, round(c.value, 9)   # mu_c = ((lam - 1) / lam)^2
    ('boundary', 0.25)
    >>> round(float(c.point[0]), 9)     # the edge mu - sqrt(mu) meets mu / (1 - lam)
    -0.25
    """
    model = as_model(model, caller="locate_crisis()")
    if model.n_states > 2:
        raise ArgumentError("locate_crisis(): one- and two-dimensional maps are handled so "
                            f"far, {model.name!r} has {model.n_states} states")
    _check_flow(model, "locate_crisis()", options)
    if param not in model.parameters:
        raise ArgumentError(f"locate_crisis(): {model.name!r} has no parameter {param!r}")
    tol = V.positive("tol", tol)
    steps = V.integer("steps", steps, lo=2)
    transient = V.integer("transient", transient, lo=0)
    iterations = V.integer("iterations", iterations, lo=2)
    if x0 is None:
        x0 = (model.spec.get("defaults") or {}).get("x0")
    x = V.state_vector(model, x0).astype(float)
    a, b = (float(v) for v in span)
    jump = V.positive("jump", jump)
    if arclength is not None:
        arclength = V.positive("arclength", arclength)
    if seeds is not None:
        seeds = np.array([V.state_vector(model, q).astype(float) for q in seeds])
    ctx = _Context(model, param, params, float(t0), options)
    if model.n_states == 2:
        return _locate_planar(ctx, a, b, x, tol, steps, transient, iterations, periods,
                              escape, arclength, manifold_tol, seeds=seeds)
    values = np.linspace(a, b, steps)
    bounded = []        # (value, samples) of the sweep so far
    for p in values:
        samples = _attractor(ctx.section(p), x, transient, iterations, escape)
        if samples is None:
            kind = "boundary"
        elif bounded and _jumped(bounded[-1][1], samples, jump):
            kind = "interior"
        else:
            bounded.append((float(p), samples))
            x = np.array([samples[-1]])
            continue
        if not bounded:
            raise ManifoldError(f"locate_crisis(): no bounded attractor at {param} = {a}")
        # an orbit leaving is certain to be past the crisis: every earlier value may be the
        # bracket's other end; a widening is only compared with the last few
        found = _locate(ctx, bounded, float(p), periods, tol,
                        back=len(bounded) if kind == "boundary" else 4)
        if found is not None:
            break
        if kind == "boundary":
            raise ManifoldError(f"locate_crisis(): the attractor leaves between {param} = "
                                f"{bounded[-1][0]} and {p}, but no edge meets a saddle's "
                                "stable set there")
        # a jump without a contact (a period doubling, a window's end far from any saddle
        # found): go on following the new attractor
        bounded.append((float(p), samples))
        x = np.array([samples[-1]])
    else:
        raise ManifoldError(f"locate_crisis(): no crisis found over {param} in [{a}, {b}] (the "
                            "attractor stays bounded without a sudden widening)")
    root, cand, history, p_lo = found
    _, (sad, point, c) = cand.evaluate(ctx, root)
    return Crisis(model=model, param=param, value=float(root), kind=kind, saddle=sad,
                  point=np.array([point]), bracket=(p_lo, float(p)), edge=(cand.k, c),
                  preimage=int(cand.pre >= 0), history=history)


# ======================================================================================
# planar maps
# ======================================================================================

def _orbit(sec: MapSection, x, transient: int, iterations: int, escape: float):
    """Iterate; the recorded points ``(iterations, n)``, or ``None`` when the orbit leaves."""
    x = np.array(x, dtype=float)
    out = np.empty((iterations, len(x)))
    for i in range(transient + iterations):
        x, sig, _ = sec.evaluate(x)
        if sig is None or float(np.max(np.abs(x))) > escape:
            return None
        if i >= transient:
            out[i - transient] = x
    return out


def _saddles(sec, samples, periods, extra=None) -> list:
    """The saddles of the given periods found by Newton from points of the attractor and of a
    grid over its bounding box widened by its size on every side, each cycle once."""
    lo, hi = samples.min(axis=0), samples.max(axis=0)
    w = np.maximum(hi - lo, 1e-9 * (1 + np.abs(hi)))
    g = [np.linspace(l - wi, h + wi, 7) for l, h, wi in zip(lo, hi, w)]
    seeds = np.vstack([samples[:: max(1, len(samples) // 20)],
                       np.array(np.meshgrid(*g)).reshape(2, -1).T]
                      + ([] if extra is None else [extra]))
    found: list = []
    for period in periods:
        for s in seeds:
            try:
                pt = _periodic(sec, s, period)
            except ManifoldError:
                continue
            if not _is_saddle(pt):
                continue
            scale = 1e-8 * (1 + float(np.max(np.abs(pt.x))))
            if any(period % q.period == 0 and np.min(np.linalg.norm(
                    q.cycle - pt.x, axis=1)) < scale for q in found):
                continue
            found.append(pt)
    return found


def _is_saddle(pt) -> bool:
    m = np.asarray(pt.multipliers)
    if not np.all(np.isfinite(m)) or np.any(np.abs(m.imag) > 1e-12):
        return False
    a = np.abs(m)
    return bool(a[0] > 1 + 1e-9 and a[-1] < 1 - 1e-9)


def _locate_planar(ctx, a, b, x, tol, steps, transient, iterations, periods, escape,
                   arclength, manifold_tol, back: int = 4, seeds=None):
    """A planar map's boundary crisis: the sweep, then :func:`_first_contact`."""
    values = np.linspace(a, b, steps)
    bounded = []
    for p in values:
        samples = _orbit(ctx.section(p), x, transient, iterations, escape)
        if samples is None:
            break
        bounded.append((float(p), samples))
        x = samples[-1]
    else:
        raise ManifoldError(f"locate_crisis(): no crisis found over {ctx.param} in [{a}, {b}] "
                            "(the attractor stays bounded)")
    if not bounded:
        raise ManifoldError(f"locate_crisis(): no bounded attractor at {ctx.param} = {a}")
    p_hi = float(p)
    # an orbit slow to find the way out leaves only past the crisis, so the last bounded value
    # may be past it too (its manifolds already cross and the contact found there is a later
    # one): earlier values are tried until the first root found repeats
    best, previous = None, None
    for p_lo, samples in bounded[::-1][:back + 1]:
        found = _first_contact(ctx, p_lo, p_hi, samples, tol, periods, arclength,
                               manifold_tol, seeds)
        if found is None:
            if best is not None:
                break
            continue
        if best is None or abs(found[0] - a) < abs(best[0] - a):
            best = found + (p_lo,)
        if previous is not None and abs(found[0] - previous) <= 1e3 * tol:
            break
        previous = found[0]
    if best is None:
        raise ManifoldError(f"locate_crisis(): the attractor leaves between {ctx.param} = "
                            f"{bounded[-1][0]} and {p_hi}, but no saddle's unstable manifold "
                            "meets a boundary saddle's stable manifold there")
    r, contact, history, p_lo = best
    return _result(ctx.model, ctx.param, contact, r, "boundary", (p_lo, p_hi), history)


def _first_contact(ctx, p_lo, p_hi, samples, tol, periods, arclength, manifold_tol,
                   seeds=None):
    """The contact root between ``p_lo`` and ``p_hi`` nearest ``p_lo`` over the pairs
    ``(P, S)`` of saddles, ``S`` off the attractor (on its basin's boundary) and ``P`` on it
    or ``S`` itself; ``(root, contact, history)`` or ``None``."""
    sec = ctx.section(p_lo)
    diameter = float(np.linalg.norm(samples.max(axis=0) - samples.min(axis=0)))
    length = arclength if arclength is not None else 4.0 * max(diameter, 1e-9)
    saddles = _saddles(sec, samples, periods, seeds)
    # the recorded orbit's spacing: a saddle on the attractor is about as close to it as its
    # points are to each other, one on the basin's boundary is farther by far
    tree = cKDTree(samples)
    spacing = float(np.median(tree.query(samples, k=2)[0][:, 1]))
    on = [float(np.min(tree.query(q.cycle)[0])) < 10.0 * spacing for q in saddles]
    best = None
    for S, s_on in zip(saddles, on):
        if s_on:
            continue
        for P, p_on in zip(saddles, on):
            if not (p_on or P is S):
                continue     # W^u(P) is not in the attractor's closure
            contact = Contact(sec.model, ctx.param, ctx.params, P, S, arclength=length,
                              tol=manifold_tol, max_points=20_000, exclude=length / 10.0,
                              options=ctx.options)
            history: list = []
            try:
                g0 = contact.start(p_lo, P, S)
            except ManifoldError:
                continue
            history.append((p_lo, g0))
            r = contact_root(contact, p_lo, p_hi, tol, history)
            # the first contact met from the bracket's lower end
            if r is not None and (best is None or abs(r - p_lo) < abs(best[0] - p_lo)):
                best = (r, contact, history)
    return best


def _result(model, param, contact, root, kind, bracket, history):
    contact(root)
    p, g, point, Wu, Ws, P, S = contact.last
    return Crisis(model=model, param=param, value=float(root), kind=kind, saddle=S,
                  point=np.asarray(point, dtype=float), bracket=tuple(bracket),
                  history=history, unstable=P, manifolds=(Wu, Ws))


def locate_tangency(model, param: str, span, unstable, stable=None, *, params=None,
                    period: int = 1, tol: float = 1e-10, arclength: float = 10.0,
                    manifold_tol: float = 1e-9, max_points: int = 20_000,
                    exclude: float | None = None, **options):
    """The first homoclinic or heteroclinic tangency, in one parameter, of the unstable
    manifold of a saddle of a planar map with the stable manifold of a saddle.

    At ``span[0]`` the nearest approach of ``W^u(unstable)`` and ``W^s(stable)`` (grown to
    ``arclength`` with :func:`pwsdyn.manifold`) is found; the signed distance between them
    there (see ``pwsdyn.manifolds._tangency``), positive at ``span[0]``, is continued in the
    parameter and its root between ``span[0]`` and ``span[1]`` found by
    ``scipy.optimize.brentq`` to ``tol``.

    Parameters
    ----------
    model : MapModel, Model, str, path or dict
        A two-dimensional map model (``kind = "map"``), or a forced two-state flow through
        its stroboscopic section (saddles given as states are found on the section at phase
        0; a saddle given as a :class:`~pwsdyn.PeriodicPoint` keeps its own phase).
    param : str
        The parameter varied.
    span : (float, float)
        The manifolds must not meet near their nearest approach at ``span[0]`` and must
        cross at ``span[1]``.
    unstable : PeriodicPoint or sequence
        The saddle whose unstable manifold is followed (a state is refined by
        :func:`pwsdyn.find_periodic_point` with ``period``).
    stable : PeriodicPoint or sequence, optional
        The saddle whose stable manifold is followed; by default the same one (a homoclinic
        tangency).
    params : dict, optional
        The other parameters' values.
    period : int
        The period of a saddle given as a state.
    tol : float
        Absolute tolerance on the located value.
    arclength : float
        Length of each branch of both manifolds.
    manifold_tol : float
        The manifolds' ``tol``: the deviation of their chords, which bounds the error of a
        smooth (non-polygonal) contact.
    max_points : int
        Points per branch at most.
    exclude : float, optional
        For a homoclinic tangency, points within this distance of the saddle (where the
        manifolds cross) are not searched for the nearest approach (default ``arclength /
        10``).
    **options
        Flows: integrator options of the section map's runs, as for :func:`pwsdyn.manifold`;
        a map takes none.

    Returns
    -------
    Crisis
        With ``kind = "tangency"``: ``value``, ``saddle`` (the stable manifold's saddle),
        ``unstable`` (the other), ``point`` (the vertex that touches the other curve) and the
        two manifolds at ``value``.

    Raises
    ------
    ManifoldError
        A saddle is lost, or the contact does not change sign over ``span``, or changes it
        only by a jump (Brent's method closing in on a discontinuity, not a tangency: the
        secant slope of its last bracket a thousand times the whole span's).
    """
    model = as_model(model, caller="locate_tangency()")
    _check_flow(model, "locate_tangency()", options)
    if model.n_states != 2:
        raise ArgumentError("locate_tangency(): the manifolds must be curves that cut the "
                            f"plane: a two-dimensional map, {model.name!r} has "
                            f"{model.n_states} states")
    if param not in model.parameters:
        raise ArgumentError(f"locate_tangency(): {model.name!r} has no parameter {param!r}")
    tol = V.positive("tol", tol)
    arclength = V.positive("arclength", arclength)
    a, b = (float(v) for v in span)
    prm = {**dict(params or {}), param: a}
    P = as_point(model, unstable, prm, period, options=options)
    S = P if stable is None else as_point(model, stable, prm, period, options=options)
    exclude = arclength / 10.0 if exclude is None else V.positive("exclude", exclude)
    contact = Contact(model, param, params, P, S, arclength=arclength, tol=manifold_tol,
                       max_points=max_points, exclude=exclude, options=options)
    history: list = []
    g0 = contact.start(a, P, S)
    history.append((a, g0))
    root = contact_root(contact, a, b, tol, history)
    if root is None:
        raise ManifoldError(f"locate_tangency(): the manifolds' contact does not change sign "
                            f"between {param} = {a} and {b}, or only by a jump (no "
                            "tangency there)")
    return _result(model, param, contact, root, "tangency", (a, b), history)

