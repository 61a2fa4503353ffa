"""A continued branch: its points as an xarray Dataset, its special points, its figure."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError

#: Kinds of special points, in words (the labels of AUTO, MatCont and BifurcationKit).
KINDS = {
    "LP": "fold (limit point): the branch turns back in the parameter",
    "BP": "branch point: another branch crosses this one",
    "PD": "period doubling: a Floquet multiplier passes through -1",
    "NS": "Neimark-Sacker: a complex pair of Floquet multipliers crosses the unit circle",
    "HB": "Hopf: a complex pair of eigenvalues crosses the imaginary axis",
    "GR": "grazing: the orbit touches a surface tangentially (a segment's interior minimum of "
          "h, or an impact's normal velocity, reaches zero)",
    "GS": "grazing-sliding: the orbit touches a Filippov surface where the field beyond it "
          "points back, and a sliding segment is born",
    "SS": "switching-sliding: the point where the orbit reaches a Filippov surface crosses the "
          "other boundary of the sliding region",
    "CS": "crossing-sliding: the point where the orbit crosses a Filippov surface reaches the "
          "boundary of the sliding region, and a sliding segment is born there (or, from the "
          "other side, a sliding segment shrinks to nothing)",
    "AS": "adding-sliding: the sliding flow touches the boundary of the sliding region (a "
          "cubic tangency of the field beyond), and a sliding segment splits in two",
    "CC": "corner collision: an event point of the orbit reaches another surface (the orbit "
          "passes through the intersection of two surfaces)",
    "BEB": "boundary equilibrium bifurcation: an equilibrium reaches the boundary of its "
           "mode's region, or a pseudo-equilibrium that of the sliding region",
    "EP": "end point of the branch",
}


@dataclass
class SpecialPoint:
    """A located special point of a :class:`~pwsdyn.Branch`.

    Attributes
    ----------
    kind : str
        ``"LP"``, ``"BP"``, ``"PD"``, ``"NS"``, ``"HB"`` or ``"EP"`` (see
        :data:`~pwsdyn.continuation.branch.KINDS`).
    index : int
        Its index among the branch's points.
    value : float
        The parameter value.
    branch : Branch
    """

    kind: str
    index: int
    value: float
    branch: "Branch"

    @property
    def point(self):
        return self.branch.points[self.index]

    @property
    def parameter(self) -> str:
        return self.branch.parameter

    @property
    def tests(self) -> dict:
        """Test-function values at the point (the located one is zero to the tolerance)."""
        return dict(self.point.tests)

    @property
    def multipliers(self) -> np.ndarray | None:
        return self.point.data.get("multipliers")

    @property
    def eigenvalues(self) -> np.ndarray | None:
        return self.point.data.get("eigenvalues")

    @property
    def key(self) -> str:
        """The test function located here (``"GR/<surface>/<segment>"`` for one monitor of
        several of a kind; the kind otherwise)."""
        return self.point.data.get("located", self.kind)

    @property
    def monitor(self):
        """The monitor located here for a discontinuity-induced bifurcation, with the
        segment, the surface and the point of tangency (``.t``, ``.x``); ``None`` otherwise."""
        return self.point.data.get("monitors", {}).get(self.key)

    @property
    def state(self) -> np.ndarray:
        """The state at the section (orbits) or the equilibrium."""
        return self.branch.problem_of(self.point).section_state(self.point.u)

    @property
    def problem(self):
        """The problem the point solves (its signature's, on a branch that switched)."""
        return self.branch.problem_of(self.point)

    @property
    def orbit(self):
        """The periodic orbit at the point (orbit branches)."""
        if self.branch.kind != "orbit":
            raise ArgumentError(f"a {self.branch.kind} branch has no orbit")
        return self.problem.orbit(self.point.u, self.point.lam)

    def __repr__(self):
        extra = ""
        if self.multipliers is not None:
            extra = ", multipliers=" + np.array2string(np.asarray(self.multipliers),
                                                       precision=6)
        return (f"SpecialPoint({self.kind} at {self.parameter} = {self.value:.12g}, "
                f"index {self.index}{extra})")


class Branch:
    """A branch followed by :func:`pwsdyn.continue_orbit` or
    :func:`pwsdyn.continue_equilibrium`.

    Attributes
    ----------
    points : list of Point
        In the order of the arclength; located special points are points of their own.
    parameter : str
    kind : str
        ``"orbit"`` or ``"equilibrium"``.
    problem : object
        What was continued first (an
        :class:`~pwsdyn.continuation.problems.OrbitBranchProblem`, an
        :class:`~pwsdyn.continuation.problems.EquilibriumProblem`, ...).
    problems : list
        Every problem of the branch: after a graze the branch goes on with the orbit's new
        signature (``Point.signature_index`` says which problem a point solves).
    stop_reason : str
        Why the branch ended.
    settings : ContinuationSettings
    origin : str
        For a branch switched from a special point of another branch, that point's kind
        (``"PD"`` for the period-doubled branch, whose first point is a branch point ``BP``
        of the doubled problem; ``"BP"``, ``"GR"``, ...); ``""`` for a branch started from a
        solution.
    """

    def __init__(self, problem, points, *, stop_reason="", settings=None, model=None,
                 problems=None, origin: str = ""):
        self.problem = problem
        self.problems = list(problems) if problems else [problem]
        self.points = list(points)
        self.parameter = problem.parameter
        self.kind = problem.kind
        self.stop_reason = stop_reason
        self.settings = settings
        self.origin = str(origin)
        self.model = model if model is not None else getattr(
            getattr(problem, "orbit_problem", problem), "model", None)

    def __len__(self):
        return len(self.points)

    def __repr__(self):
        sp = ", ".join(f"{p.kind} {p.value:.6g}" for p in self.special_points
                       if p.kind != "EP")
        lam = self.values
        span = f"[{lam.min():.6g}, {lam.max():.6g}]" if lam.size else "[]"
        return (f"Branch({self._what()}: {len(self)} points, {self.parameter} in "
                f"{span}{'; ' + sp if sp else ''}; {self.stop_reason})")

    def _what(self) -> str:
        name = getattr(self.model, "name", "?")
        return (f"{self.curve} curve of {name!r} in ({self.parameter}, {self.parameter2})"
                if self.curve else f"{self.kind} of {name!r} in {self.parameter}")

    def _repr_html_(self):
        from .._display import html_table, num

        lam = self.values
        rows = [("branch", self._what()),
                ("points", len(self)),
                (self.parameter, f"{num(lam.min())} to {num(lam.max())}" if lam.size else "?")]
        if lam.size and self.kind == "orbit":
            rows.append(("stable", f"{int(self.stable.sum())} of {len(self)} points"))
            if not self.admissible.all():
                rows.append(("admissible", f"{int(self.admissible.sum())} of {len(self)} "
                                           "points"))
            sigs = self.signatures
            if len(sigs) > 1 or (sigs and sigs[0]):
                rows.append(("signatures", "  ->  ".join(str(s) for s in sigs)))
        for p in self.special_points:
            rows.append((p.kind, f"{self.parameter} = {num(p.value, 10)} (point {p.index})"))
        rows.append(("stopped", self.stop_reason or "?"))
        return html_table("Branch", rows)

    # ---- the points as arrays --------------------------------------------------------
    @property
    def values(self) -> np.ndarray:
        """The parameter at each point."""
        return np.array([p.lam for p in self.points])

    @property
    def curve(self) -> str:
        """The bifurcation followed in two parameters (``""`` for a branch of solutions)."""
        return getattr(self.problem, "curve", "")

    @property
    def parameter2(self) -> str | None:
        """The second parameter of a two-parameter curve (``None`` otherwise)."""
        return getattr(self.problem, "parameter2", None)

    def values_of(self, name: str) -> np.ndarray:
        """The values of parameter ``name`` along the branch: the continued one, or the second
        parameter of a two-parameter curve."""
        if name == self.parameter:
            return self.values
        if name == self.parameter2:
            return np.array([p.u[-1] for p in self.points])
        raise ArgumentError(f"the branch varies {self.parameter!r}"
                            + (f" and {self.parameter2!r}" if self.parameter2 else "")
                            + f", not {name!r}")

    def problem_of(self, point):
        """The problem ``point`` solves."""
        return self.problems[getattr(point, "signature_index", 0)]

    @property
    def signatures(self) -> list:
        """The signature of each problem (orbit branches)."""
        return [p.orbit_problem.signature for p in self.problems
                if hasattr(p, "orbit_problem")]

    @property
    def states(self) -> np.ndarray:
        """The state at the section (orbits) or the equilibrium, one row per point."""
        return np.array([self.problem_of(p).section_state(p.u) for p in self.points])

    @property
    def stable(self) -> np.ndarray:
        return np.array([bool(p.data.get("stable", False)) for p in self.points])

    @property
    def admissible(self) -> np.ndarray:
        return np.array([bool(p.data.get("admissible", True)) for p in self.points])

    @property
    def special_points(self) -> list[SpecialPoint]:
        return [SpecialPoint(p.special, i, p.lam, self) for i, p in enumerate(self.points)
                if p.special]

    def special(self, kind: str) -> list[SpecialPoint]:
        """The special points of one kind."""
        return [s for s in self.special_points if s.kind == kind]

    # ---- files -----------------------------------------------------------------------
    def to_dataset(self):
        """The branch as an :class:`xarray.Dataset` (dimension ``point``)."""
        import xarray as xr

        from .._netcdf import _str_array, cf_global_attrs, quantity_attrs, state_attrs, state_coords

        m = self.model
        names = list(self.problem.state_names)
        pts = self.points
        spectrum = "multipliers" if self.kind == "orbit" else "eigenvalues"
        nm = max((len(p.data.get(spectrum, ())) for p in pts), default=0)
        mu = np.full((len(pts), nm), np.nan + 0j)
        for i, p in enumerate(pts):
            z = np.asarray(p.data.get(spectrum, ()), dtype=complex)
            mu[i, :z.size] = z
        nu = max((p.u.size for p in pts), default=0)

        def padded(vectors, size):
            out = np.full((len(vectors), size), np.nan)
            for i, v in enumerate(vectors):
                out[i, :v.size] = v
            return out
        kinds = sorted({k for p in pts for k in p.tests})
        ds = xr.Dataset(
            {
                self.parameter: ("point", self.values, quantity_attrs(m, self.parameter)),
                "x": (("point", "state"), self.states if pts else np.zeros((0, len(names))),
                      state_attrs(m, "state at the Poincare section (start of segment 0)"
                                  if self.kind == "orbit" else "equilibrium")),
                f"{spectrum}_real": (("point", "index"), mu.real),
                f"{spectrum}_imag": (("point", "index"), mu.imag),
                "stable": ("point", self.stable.astype(np.int8),
                           {"flag_values": np.array([0, 1], dtype=np.int8),
                            "flag_meanings": "unstable stable"}),
                "admissible": ("point", self.admissible.astype(np.int8),
                               {"flag_values": np.array([0, 1], dtype=np.int8),
                                "flag_meanings": "not_admissible admissible"}),
                "reason": ("point", _str_array(p.data.get("reason", "") for p in pts),
                           {"long_name": "why the point is not admissible (empty: it is)"}),
                "special": ("point", _str_array(p.special for p in pts),
                            {"long_name": "kind of special point (empty: regular)"}),
                "ds": ("point", np.array([p.ds for p in pts]),
                       {"long_name": "arclength step that reached the point"}),
                "arclength": ("point", np.array([p.arclength for p in pts])),
                "iterations": ("point", np.array([p.iterations for p in pts], dtype=np.int32)),
                "u": (("point", "unknown"), padded([p.u for p in pts], nu),
                      {"long_name": "unknowns of the problem (NaN beyond its size)"}),
                "tangent": (("point", "unknown_and_parameter"),
                            padded([p.tangent for p in pts], nu + 1)),
                "signature_index": ("point", np.array([p.signature_index for p in pts],
                                                      dtype=np.int32),
                                    {"long_name": "index of the point's signature in the "
                                                  "signatures attribute"}),
            },
            coords={"point": np.arange(len(pts)), **state_coords(m)},
        )
        for k in kinds:
            # "GR/<surface>/<segment>": '/' is not allowed in a NetCDF name
            ds[f"test_{k.replace('/', ':')}"] = (
                "point", np.array([p.tests.get(k, np.nan) for p in pts]),
                {"long_name": KINDS.get(k.split("/")[0], k) + f" (test function {k})"})
        if self.kind == "orbit":
            ds["period"] = ("point", np.array([p.data.get("period", np.nan) for p in pts]))
        if self.curve:
            ds[self.parameter2] = ("point", self.values_of(self.parameter2),
                                   quantity_attrs(m, self.parameter2))
        attrs = {
            **cf_global_attrs(m, "branch", f"{self.kind} branch of {m.name} in "
                              f"{self.parameter}", "pseudo-arclength continuation"),
            "kind": self.kind,
            "parameter": self.parameter,
            "stop_reason": self.stop_reason,
            "origin": self.origin,
            "params": json.dumps(getattr(self.problem, "params", None) or
                                 getattr(self.problem.orbit_problem, "params", {})),
        }
        if self.settings is not None:
            from dataclasses import asdict
            attrs["settings"] = json.dumps({k: (list(v) if isinstance(v, tuple) else v)
                                            for k, v in asdict(self.settings).items()},
                                           default=_json_float)
        if self.curve:
            attrs["curve"] = self.curve
            attrs["parameter2"] = self.parameter2
        if self.kind == "orbit":
            op = self.problem.orbit_problem
            attrs["signature"] = str(op.signature)
            attrs["signatures"] = json.dumps([str(q.orbit_problem.signature)
                                              for q in self.problems])
            attrs["periods"] = int(op.periods)
            attrs["periods_of_signatures"] = json.dumps([int(q.orbit_problem.periods)
                                                         for q in self.problems])
            # what an orbit problem needs besides its signature: the start time and discrete
            # state of an orbit without events
            attrs["t_refs"] = json.dumps([float(q.orbit_problem.t_ref) for q in self.problems])
            attrs["states0"] = json.dumps([str(q.orbit_problem.state_names[0])
                                           for q in self.problems])
            attrs["options"] = json.dumps(_plain(op.opts), default=_json_float)
        else:
            attrs["mode"] = self.problem.mode
        ds.attrs.update(attrs)
        return ds

    def save(self, path, *, overwrite: bool = False):
        """Write the branch to a NetCDF file (:func:`pwsdyn.load_branch` reads it back)."""
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)

    # ---- the figure ------------------------------------------------------------------
    def plot(self, y=None, *, ax=None, labels: bool = True, **kw):
        """Bifurcation diagram: the parameter against ``y`` (a state name, ``"period"``,
        ``"norm"``, ``"max:<state>"``, ``"min:<state>"`` or a function of the orbit at each
        point; see :func:`pwsdyn.plot.plot_branch`), stable parts solid, unstable dashed,
        non-admissible dotted, special points marked and labelled."""
        from ..plot import plot_branch

        return plot_branch(self, y=y, ax=ax, labels=labels, **kw)


def _json_float(v):
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _plain(d):
    return {k: v for k, v in dict(d).items() if isinstance(v, (int, float, str, bool, type(None)))}
