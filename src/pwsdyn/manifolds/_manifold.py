"""The :class:`Manifold` result and :func:`manifold`, its one entry point."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError
from ..model.spec import as_model
from ..orbits import PeriodicOrbit
from ._grow import grow, preimage, preimage_guarded
from ._points import (ManifoldError, PeriodicPoint, find_periodic_point, multiplier_variables,
                      refind)
from ._sections import MapSection, StroboscopicSection, check_section

if TYPE_CHECKING:
    from pathlib import Path

    import xarray as xr

    from .._typing import PathLike

_KINDS = ("unstable", "stable")


@dataclass(eq=False)
class Manifold:
    """A one-dimensional stable or unstable manifold of a saddle of a map (a map model's
    periodic point, or a forced flow's periodic orbit on its stroboscopic section).

    Create one with :func:`pwsdyn.manifold`.

    Attributes
    ----------
    model : MapModel or Model
    params : dict
    kind : str
        ``"unstable"`` or ``"stable"``.
    saddle : numpy.ndarray, shape (n,)
        The saddle point (on the section for a flow).
    multipliers : numpy.ndarray
        All multipliers of the saddle (of ``D F^period`` or of the orbit's monodromy), by
        decreasing modulus; ``multiplier`` the one whose eigendirection ``eigenvector`` the
        manifold is tangent to at ``saddle``.
    period : int
        Iterations of the map (a map model) or forcing periods (a flow) of the saddle.
    section : str
        ``"map"`` or ``"stroboscopic"`` (with ``t0``, the section's phase, and
        ``section_period``, the time between two returns).
    branches : list of list of numpy.ndarray
        The two branches (along ``+eigenvector`` and ``-eigenvector``), each a list of pieces:
        ``(m, n)`` polylines in the state coordinates, cut where the map jumps.
    nodes : list of list of numpy.ndarray
        Per piece, which points are nodes: kinks at the images of a border and piece ends,
        computed as images (never interpolated).
    status : tuple of str
        Per branch, why it stopped: ``"arclength"`` (grown to ``arclength``),
        ``"max_points"``, ``"diverged"`` (beyond ``1e8 (1 + max|saddle|)``), ``"undefined"``
        (no piece of the map applies, a flow's state is beyond an impact constraint, or a
        preimage could not be found), ``"stalled"`` (the cursor caught up with the branch's
        end: the branch converges, to an attractor or a saddle).
    arclengths : tuple of float
        Per branch, the length grown (jumps not counted).
    evaluations : int
        Evaluations of the map, Newton and bisection included: iterations of a map model, or
        kernel runs of a flow (each over ``period`` forcing periods, two of them for the
        second iterate of a saddle with a negative multiplier).
    unresolved : int
        Points accepted at the smallest cursor step without meeting the density criteria.
    flickers : int
        Signature changes found at the cursor itself (a point on a border to rounding, where
        a grazing orbit's event detection may go either way), taken as continuous.
    options : dict
        ``tol``, ``max_step``, ``alpha_max``, ``delta``, ``arclength``, ``max_points``.
    """

    model: object
    params: dict
    kind: str
    saddle: np.ndarray
    multipliers: np.ndarray
    multiplier: complex
    eigenvector: np.ndarray
    period: int
    section: str
    branches: list
    nodes: list
    status: tuple
    arclengths: tuple
    evaluations: int
    unresolved: int
    options: dict = field(default_factory=dict)
    t0: float | None = None
    section_period: float | None = None
    flickers: int = 0

    @property
    def pieces(self) -> list:
        """Every piece of both branches, the ``+eigenvector`` branch first: a list of
        ``(m, n)`` arrays."""
        return [p for br in self.branches for p in br]

    @property
    def n_points(self) -> int:
        return sum(len(p) for p in self.pieces)

    def __repr__(self):
        return (f"Manifold({self.model.name!r}, kind={self.kind!r}, saddle="
                f"{np.round(self.saddle, 10).tolist()}, multiplier={self.multiplier:.6g}, "
                f"pieces={[len(br) for br in self.branches]}, points={self.n_points}, "
                f"status={list(self.status)})")

    def distance(self, points) -> np.ndarray:
        """The distance of each of ``points`` (shape ``(m, n)`` or ``(n,)``) to the manifold's
        polylines (every piece of both branches)."""
        P = np.atleast_2d(np.asarray(points, dtype=float))
        best = np.full(len(P), np.inf)
        for piece in self.pieces:
            if len(piece) == 1:
                best = np.minimum(best, np.linalg.norm(P - piece[0], axis=1))
                continue
            A, B = piece[:-1], piece[1:]
            AB = B - A
            L2 = np.einsum("ij,ij->i", AB, AB)
            L2[L2 == 0] = 1.0
            for k, x in enumerate(P):
                t = np.clip(np.einsum("ij,ij->i", x - A, AB) / L2, 0.0, 1.0)
                d = np.linalg.norm(A + t[:, None] * AB - x, axis=1)
                best[k] = min(best[k], float(d.min()))
        return best

    # ------------------------------------------------------------------------------------
    def to_dataset(self) -> "xr.Dataset":
        """The manifold as an :class:`xarray.Dataset`: ``x`` over ``(point, state)`` (all
        pieces one after the other), ``branch``, ``piece`` and ``node`` per point; the saddle,
        its multipliers and eigenvector; the provenance of every pwsdyn result (model text,
        versions) in the attributes."""
        import xarray as xr

        from .._netcdf import cf_global_attrs, state_coords

        rows, branch, piece, node = [], [], [], []
        k = 0
        for b, (br, nd) in enumerate(zip(self.branches, self.nodes)):
            for p, m in zip(br, nd):
                rows.append(p)
                branch.append(np.full(len(p), b))
                piece.append(np.full(len(p), k))
                node.append(m.astype(np.int8))
                k += 1
        n = len(self.model.states)
        X = np.concatenate(rows) if rows else np.zeros((0, n))
        mult = np.atleast_1d(np.asarray(self.multipliers, dtype=complex))
        ds = xr.Dataset(
            {
                "x": (("point", "state"), X, {"long_name": f"point of the {self.kind} "
                                                           "manifold"}),
                "branch": (("point",), np.concatenate(branch).astype(np.int64) if rows
                           else np.zeros(0, np.int64),
                           {"long_name": "branch (0: along +eigenvector, 1: along "
                                         "-eigenvector)"}),
                "piece": (("point",), np.concatenate(piece).astype(np.int64) if rows
                          else np.zeros(0, np.int64),
                          {"long_name": "piece index (the manifold is cut where the map "
                                        "jumps)"}),
                "node": (("point",), np.concatenate(node) if rows else np.zeros(0, np.int8),
                         {"long_name": "1 at a kink or a piece end (an exact image)"}),
                "saddle": (("state",), np.asarray(self.saddle, dtype=float),
                           {"long_name": "saddle point"}),
                "eigenvector": (("state",), np.asarray(self.eigenvector, dtype=float),
                                {"long_name": "eigendirection at the saddle"}),
                **multiplier_variables(mult),
            },
            coords=state_coords(self.model))
        how = ("Newton preimages on the forward map" if self.kind == "stable"
               else "images of the forward map")
        ds.attrs.update(cf_global_attrs(
            self.model, "manifold", f"pwsdyn {self.kind} manifold of model {self.model.name}",
            f"{how}, grown by arclength with distance and angle control "
            "(pwsdyn.manifold)"))
        ds.attrs.update({
            "manifold_kind": self.kind, "period": int(self.period),
            "section": self.section,
            "parameters": json.dumps({k: float(v) for k, v in self.params.items()}),
            "multiplier": float(np.real(self.multiplier)),
            "branch_status": json.dumps(list(self.status)),
            "branch_arclength": json.dumps([float(a) for a in self.arclengths]),
            "evaluations": int(self.evaluations), "unresolved": int(self.unresolved),
            "flickers": int(self.flickers),
            "options": json.dumps({k: float(v) for k, v in self.options.items()}),
        })
        if self.t0 is not None:
            ds.attrs["section_t0"] = float(self.t0)
            ds.attrs["section_period"] = float(self.section_period)
        return ds

    def save(self, path: PathLike, overwrite: bool = False) -> Path:
        """Write :meth:`to_dataset` to a NetCDF file; an existing file is refused
        (:class:`~pwsdyn.OutputExistsError`) unless ``overwrite=True``."""
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)

    def plot(self, ax=None, states=None, *, saddle: bool = True, **kwargs):
        """Draw the pieces in the plane of two states (``states``: two names or indices,
        default the first two; a one-state map is drawn against its own index) on ``ax`` (a
        new figure's axes if ``None``); ``kwargs`` go to ``Axes.plot``. Returns ``ax``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        names = list(self.model.states)
        if states is None:
            states = names[:2]
        idx = [names.index(s) if isinstance(s, str) else int(s) for s in states]
        style = {"color": "tab:red" if self.kind == "unstable" else "tab:blue", "lw": 1.0}
        style.update(kwargs)
        label = style.pop("label", f"{self.kind} manifold")
        for k, p in enumerate(self.pieces):
            if len(idx) >= 2:
                ax.plot(p[:, idx[0]], p[:, idx[1]], label=label if k == 0 else None, **style)
            else:
                ax.plot(p[:, idx[0]], np.zeros(len(p)), label=label if k == 0 else None,
                        **style)
        if saddle:
            s = self.saddle
            ax.plot([s[idx[0]]], [s[idx[1]] if len(idx) >= 2 else 0.0], "k+", ms=8)
        if len(idx) >= 2:
            ax.set_xlabel(names[idx[0]])
            ax.set_ylabel(names[idx[1]])
        return ax


def _real_direction(J, kind):
    """The one real multiplier outside (unstable) or inside (stable) the unit circle and its
    unit eigenvector; an error when there is not exactly one such multiplier."""
    w, V_ = np.linalg.eig(J)
    order = np.argsort(-np.abs(w), kind="stable")
    w, V_ = w[order], V_[:, order]
    mod = np.abs(w)
    sel = np.flatnonzero(mod > 1 + 1e-9) if kind == "unstable" else np.flatnonzero(
        mod < 1 - 1e-9)
    if len(sel) != 1:
        raise ManifoldError(
            f"manifold(): the saddle must have exactly one {kind} multiplier for a "
            f"one-dimensional {kind} manifold; its multipliers are "
            f"{[complex(m) for m in w]}")
    i = int(sel[0])
    if abs(w[i].imag) > 1e-12 * (1 + abs(w[i])):
        raise ManifoldError(f"manifold(): the {kind} multiplier {complex(w[i])} is not real")
    v = np.real(V_[:, i])
    return w, float(np.real(w[i])), v / np.linalg.norm(v)


def manifold(model, point, kind: str = "unstable", *, params=None, section=None,
             arclength: float = 1.0, max_points: int = 10_000, tol: float = 1e-6,
             max_step: float | None = None, delta: float | None = None, period: int = 1,
             **options) -> Manifold:
    """The stable or unstable manifold of a saddle with one unstable (or one stable) multiplier,
    both branches grown by arclength.

    Points are added as images (unstable) or Newton preimages (stable) of points of the branch
    computed so far, with the distance between consecutive points at most ``max_step`` and the
    angle ``alpha`` between consecutive chords small (``alpha <= 0.3`` and ``d alpha <= 8 tol``:
    a chord deviates from the curve by about ``d alpha / 8``). Where the map's signature (the
    pieces applied, or the events of a flow's orbit over the forcing period) changes, the border
    is located by bisection on the preimage polyline and never interpolated across: a kink, or
    for a jump of the map a new piece of the manifold. See ``pwsdyn.manifolds._grow`` for the
    method (Krauskopf & Osinga 1998; Hobson 1993).

    Parameters
    ----------
    model : MapModel, Model, str, path or dict
        The model (anything :func:`pwsdyn.load_model` accepts).
    point : PeriodicPoint, PeriodicOrbit or sequence
        The saddle: a :class:`~pwsdyn.PeriodicPoint` of a map model, a state of a map
        model's fixed or period-``period`` point (refined by
        :func:`~pwsdyn.find_periodic_point`), or a forced flow's
        :class:`~pwsdyn.PeriodicOrbit` (its stroboscopic Poincaré map at the orbit's ``t0``)
        or its :class:`~pwsdyn.PeriodicPoint` on that section (one with ``section_period``,
        as the saddles of :func:`pwsdyn.locate_crisis` of a flow).
    kind : {'unstable', 'stable'}
    params : dict, optional
        Parameter values (default: the point's, else the model's). A map's periodic point is
        found again at other values; a flow's orbit must be at these values.
    section : {None, 'stroboscopic'}
        A flow's section: only the stroboscopic one (every forcing period ``orbit.period``).
    arclength : float
        Length of each branch (jumps not counted).
    max_points : int
        Points per branch at most.
    tol : float
        Accuracy of the polyline: the largest deviation of a chord from the curve (``d alpha
        / 8``). Two images of a border's sides farther apart than ``max(tol, 1e-7) (1 + |y|)``
        are a jump (the manifold is cut there), closer ones a kink.
    max_step : float, optional
        Largest distance between consecutive points (default ``arclength / 200``).
    delta : float, optional
        Distance of the first point from the saddle along the eigenvector (default
        ``1e-6 (1 + max|saddle|)``).
    period : int
        The period of a map's periodic point given as a state.
    **options
        Integrator options of a flow's runs (as for :func:`pwsdyn.simulate`).

    Returns
    -------
    Manifold

    Raises
    ------
    ManifoldError
        The saddle has no single real unstable (stable) multiplier, or its periodic point is not
        found.

    Examples
    --------
    >>> m = manifold("sqrt-map", [0.03], params={"mu": 0.2, "lam": 0.3}, arclength=0.1)
    >>> m.multiplier < -1, m.status
    (True, ('arclength', 'arclength'))
    """
    if kind not in _KINDS:
        raise ArgumentError(f"manifold(): kind must be 'unstable' or 'stable', got {kind!r}")
    arclength = V.positive("arclength", arclength)
    max_points = V.integer("max_points", max_points, lo=3)
    tol = V.positive("tol", tol)
    t0 = section_period = None
    if isinstance(point, PeriodicOrbit):
        model = as_model(model, kind="flow", caller="manifold()")
        check_section(section, False)
        if point.model.hash != model.hash:
            raise ArgumentError("manifold(): the periodic orbit is of another model "
                                f"({point.model.name!r})")
        if point.autonomous:
            raise ArgumentError("manifold(): an autonomous orbit has no stroboscopic section; "
                                "only forced orbits are supported so far")
        if params is not None and {**point.params, **params} != dict(point.params):
            raise ArgumentError("manifold(): `params` differ from the periodic orbit's; find "
                                "the orbit at those parameters first")
        params = dict(point.params)
        sec = StroboscopicSection(model, params, point.t0, point.period, 1, options)
        p = np.array(point.x0, dtype=float)
        _, _, J = sec.evaluate(p, jacobian=True)
        per, sec_name = int(getattr(point, "periods", 1) or 1), "stroboscopic"
        t0, section_period = float(point.t0), float(point.period)
    elif isinstance(point, PeriodicPoint) and point.section_period is not None:
        # a forced flow's point on its stroboscopic section (pwsdyn.locate_crisis of a flow)
        model = as_model(model, kind="flow", caller="manifold()")
        check_section(section, False)
        if point.model.hash != model.hash:
            raise ArgumentError("manifold(): the periodic point is of another model "
                                f"({point.model.name!r})")
        if params is not None and {**point.params, **params} != dict(point.params):
            point = refind(model, point, {**point.params, **params})
        params = dict(point.params)
        t0, T = float(point.t0), float(point.section_period)
        sec = StroboscopicSection(model, params, t0, point.period * T, 1, options)
        p = np.array(point.x, dtype=float)
        J = point.jacobian
        per, sec_name, section_period = point.period, "stroboscopic", point.period * T
    else:
        model = as_model(model, kind="map", caller="manifold()")
        check_section(section, True)
        if options:
            raise ArgumentError(f"manifold(): unexpected keyword argument(s) {sorted(options)} "
                                "for a map model")
        if isinstance(point, PeriodicPoint):
            if point.model.hash != model.hash:
                raise ArgumentError("manifold(): the periodic point is of another model "
                                    f"({point.model.name!r})")
            params = dict(point.params) if params is None else params
            if params != point.params:
                point = find_periodic_point(model, point.x, point.period, params=params)
        else:
            point = find_periodic_point(model, point, period, params=params)
        params = point.params
        sec = MapSection(model, params, point.period)
        p = np.array(point.x, dtype=float)
        J = point.jacobian
        per, sec_name = point.period, "map"
    multipliers, lam, v = _real_direction(J, kind)
    scale = 1.0 + float(np.max(np.abs(p)))
    if max_step is None:
        max_step = arclength / 200.0
    max_step = V.positive("max_step", max_step)
    delta = 1e-6 * scale if delta is None else V.positive("delta", delta)
    # a negative multiplier swaps the branches at every iteration: each is invariant under the
    # second iterate, whose multiplier lam**2 is positive
    # the angle criterion is not applied to chords shorter than the error of the map's
    # evaluation: rounding for a map model, the integration tolerance for a flow
    if sec_name == "map":
        min_dist = 1e3 * np.finfo(float).eps * scale
    else:
        min_dist = 1e3 * max(sec.opts["rtol"], sec.opts["atol"]) * scale
    H = sec.iterate(2) if lam < 0 else sec
    Lam = lam * lam if lam < 0 else lam
    if kind == "unstable":
        def evaluate(x, guess):
            y, sig, _ = H.evaluate(x)
            return y, sig
    else:
        # Newton's residual can go no lower than the evaluation's error: rounding for a map,
        # the integration tolerance for a flow
        newton_tol = 1e-13 if sec_name == "map" else 10.0 * max(sec.opts["rtol"],
                                                                 sec.opts["atol"])

        def evaluate(x, guess, predicted=None):
            z, sig = preimage(H, x, guess, newton_tol)
            if sig is None and predicted is not None:
                # a fallback only, so that every preimage found by plain Newton is unchanged:
                # Newton with a line search, from the branch's prediction, then from the guess
                # (not in a bisection, which gets no prediction and locates a border or the
                # branch's end with plain Newton)
                for g in (predicted, guess):
                    if g is not None:
                        z, sig = preimage_guarded(H, x, g, newton_tol)
                        if sig is not None:
                            break
            return z, sig
    branches, nodes, status, lengths, unresolved, flickers = [], [], [], [], 0, 0
    for sign in (1.0, -1.0):
        q0 = p + sign * delta * v
        if kind == "unstable":
            q1, sig0 = evaluate(q0, None)
        else:
            # the preimage of q0, and the signature of the inverse's "evaluation" at q0: the
            # pieces the forward map applies at that preimage
            q1, sig0 = evaluate(q0, p + sign * delta / Lam * v)
            d0 = delta
            while sig0 is None and d0 > 1e-6 * delta:
                # the fundamental domain [q0, H(q0)] has length delta / Lam: for a strongly
                # contracting saddle (Lam ~ 1e-5) it reaches past a border close to the
                # saddle (a near-grazing impact), where the linear guess is on other pieces;
                # a start closer to the saddle keeps it on the saddle's own
                d0 *= 0.1
                q0 = p + sign * d0 * v
                q1, sig0 = evaluate(q0, p + sign * d0 / Lam * v)
        if sig0 is None:
            raise ManifoldError(f"manifold(): the map cannot be evaluated next to the saddle "
                                f"(at {q0.tolist()})")
        br = grow(evaluate, q0, q1, sig0, arclength=arclength, max_points=max_points,
                  max_step=max_step, tol=tol, jump_tol=max(tol, 1e-7),
                  bound=1e8 * scale, min_dist=min_dist, predict=kind == "stable")
        # the saddle itself begins the branch: the segment to q0 is the eigendirection
        pieces = br.pieces()
        pieces[0] = np.vstack([p[None, :], pieces[0]])
        branches.append(pieces)
        nd = np.concatenate([[True], br.nodes()])
        start, per_piece = 0, []
        for piece in branches[-1]:
            per_piece.append(nd[start:start + len(piece)])
            start += len(piece)
        nodes.append(per_piece)
        status.append(br.status)
        lengths.append(br.length)
        unresolved += br.unresolved
        flickers += br.flickers
    return Manifold(model=model, params=dict(sec.params), kind=kind, saddle=p,
                    multipliers=multipliers, multiplier=lam, eigenvector=v, period=per,
                    section=sec_name, branches=branches, nodes=nodes, status=tuple(status),
                    arclengths=tuple(lengths), evaluations=H.evaluations + sec.evaluations,
                    unresolved=unresolved,
                    options={"tol": tol, "max_step": max_step, "alpha_max": 0.3,
                             "delta": delta, "arclength": arclength,
                             "max_points": max_points},
                    t0=t0, section_period=section_period, flickers=flickers)
