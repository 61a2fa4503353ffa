"""A continued branch: its points as columns (one array per attribute, the points views of
them), its special points, its NetCDF file and its figure."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError, Status

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
    # codimension-two points on two-parameter curves (Kuznetsov, Elements of Applied
    # Bifurcation Theory, 3rd ed., chapter 9; pwsdyn.continuation.codim2)
    "CP": "cusp: on a fold curve, the fold's normal-form coefficient vanishes",
    "LPPD": "fold-flip: a multiplier +1 and a multiplier -1",
    "LPNS": "fold-Neimark-Sacker: a multiplier +1 and a complex pair on the unit circle",
    "GPD": "generalized period doubling: on a period-doubling curve, the flip's normal-form "
           "coefficient vanishes (the period doubling turns from super- to subcritical)",
    "R1": "1:1 resonance: a double multiplier +1 (a Neimark-Sacker curve turns into neutral "
          "saddles)",
    "R2": "1:2 resonance: a double multiplier -1 (a Neimark-Sacker curve turns into neutral "
          "saddles)",
    "R3": "1:3 resonance: a Neimark-Sacker pair exp(+-2 pi i / 3)",
    "R4": "1:4 resonance: a Neimark-Sacker pair +-i",
    "CH": "Chenciner: on a Neimark-Sacker curve, the normal-form coefficient vanishes",
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
    def nonsmooth_fold(self) -> bool:
        """Whether the branch turned back at this discontinuity-induced bifurcation: the
        orbits with and without the changed event meet there from one side (a graze where
        the discontinuity map says the orbit is lost, with hysteresis), and the branch went
        on along the other of them, back the way it came in the parameter."""
        return bool(self.point.data.get("nonsmooth_fold", False))

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
        if self.nonsmooth_fold:
            extra += ", a non-smooth fold"
        return (f"SpecialPoint({self.kind} at {self.parameter} = {self.value:.12g}, "
                f"index {self.index}{extra})")


class _Columns:
    """The points of a branch, one column per attribute of a
    :class:`~pwsdyn.continuation.engine.Point`: the parameter, the step, the arclength, the
    Newton iterations and the signature index as arrays; ``u`` and the tangent as rows of
    two-dimensional arrays padded with NaN beyond each point's size (the problems of a branch
    that switched signature differ in size); the problem's data, the test functions and the
    special kind as lists (their entries are dicts and words). ``stable`` and ``admissible``
    are columns of their own, read from a point's data when it is stored.

    Arrays are allocated with room to spare and doubled when full, so that appending a point
    costs amortised constant time; the first ``n`` rows are the points."""

    __slots__ = ("n", "lam", "ds", "arclength", "iterations", "signature_index", "usize",
                 "u", "tangent", "data", "tests", "special", "stable", "admissible")

    def __init__(self, capacity: int = 0, width: int = 0):
        cap = max(int(capacity), 1)
        self.n = 0
        self.lam = np.empty(cap)
        self.ds = np.empty(cap)
        self.arclength = np.empty(cap)
        self.iterations = np.empty(cap, dtype=np.int64)
        self.signature_index = np.empty(cap, dtype=np.int64)
        self.usize = np.empty(cap, dtype=np.int64)
        self.u = np.full((cap, width), np.nan)
        self.tangent = np.full((cap, width + 1), np.nan)
        self.stable = np.empty(cap, dtype=bool)
        self.admissible = np.empty(cap, dtype=bool)
        self.data: list = []
        self.tests: list = []
        self.special: list = []

    @classmethod
    def of(cls, points) -> "_Columns":
        points = list(points)
        width = max((np.size(p.u) for p in points), default=0)
        out = cls(len(points), width)
        for p in points:
            out.append(p)
        return out

    def _room(self, width: int) -> None:
        """Room for one more row of ``width`` unknowns (doubling the rows when full)."""
        cap, w = self.lam.shape[0], self.u.shape[1]
        rows = cap if self.n < cap else 2 * cap
        if rows == cap and width <= w:
            return
        width = max(width, w)
        for name in ("lam", "ds", "arclength", "iterations", "signature_index", "usize",
                     "stable", "admissible"):
            old = getattr(self, name)
            new = np.empty(rows, dtype=old.dtype)
            new[:self.n] = old[:self.n]
            setattr(self, name, new)
        for name, extra in (("u", 0), ("tangent", 1)):
            old = getattr(self, name)
            new = np.full((rows, width + extra), np.nan)
            new[:self.n, :old.shape[1]] = old[:self.n]
            setattr(self, name, new)

    def append(self, p) -> None:
        u = np.asarray(p.u, dtype=float).reshape(-1)
        self._room(u.size)
        self.n += 1
        self.data.append(None)
        self.tests.append(None)
        self.special.append("")
        self.put(self.n - 1, p)

    def put(self, i: int, p) -> None:
        """Row ``i`` from the attributes of ``p`` (a Point or a view)."""
        u = np.asarray(p.u, dtype=float).reshape(-1)
        t = np.asarray(p.tangent, dtype=float).reshape(-1)
        if u.size > self.u.shape[1]:
            self._room(u.size)
        self.u[i] = np.nan
        self.u[i, :u.size] = u
        self.tangent[i] = np.nan
        self.tangent[i, :t.size] = t
        self.usize[i] = u.size
        self.lam[i] = p.lam
        self.ds[i] = p.ds
        self.arclength[i] = p.arclength
        self.iterations[i] = p.iterations
        self.signature_index[i] = getattr(p, "signature_index", 0)
        self.special[i] = p.special
        self.tests[i] = p.tests
        self.set_data(i, p.data)

    def set_data(self, i: int, data: dict) -> None:
        self.data[i] = data
        self.stable[i] = bool(data.get("stable", False))
        self.admissible[i] = bool(data.get("admissible", True))


class BranchPoint:
    """One point of a :class:`~pwsdyn.Branch`: a view of the branch's columns at one index,
    with the attributes of a :class:`~pwsdyn.continuation.engine.Point` (``u``, ``lam``,
    ``tangent``, ``ds``, ``iterations``, ``arclength``, ``data``, ``tests``, ``special``,
    ``signature_index``, ``X``). ``u`` and ``tangent`` are views of the columns; assigning an
    attribute writes the column (the branch sees it). ``copy.copy`` gives a detached
    :class:`~pwsdyn.continuation.engine.Point`."""

    __slots__ = ("_c", "_i")

    def __init__(self, columns: _Columns, index: int):
        self._c = columns
        self._i = index

    @property
    def u(self) -> np.ndarray:
        return self._c.u[self._i, :self._c.usize[self._i]]

    @property
    def tangent(self) -> np.ndarray:
        return self._c.tangent[self._i, :self._c.usize[self._i] + 1]

    @property
    def lam(self) -> float:
        return float(self._c.lam[self._i])

    @property
    def ds(self) -> float:
        return float(self._c.ds[self._i])

    @property
    def arclength(self) -> float:
        return float(self._c.arclength[self._i])

    @property
    def iterations(self) -> int:
        return int(self._c.iterations[self._i])

    @property
    def signature_index(self) -> int:
        return int(self._c.signature_index[self._i])

    @property
    def data(self) -> dict:
        return self._c.data[self._i]

    @property
    def tests(self) -> dict:
        return self._c.tests[self._i]

    @property
    def special(self) -> str:
        return self._c.special[self._i]

    @property
    def X(self) -> np.ndarray:
        return np.append(self.u, self.lam)

    def __setattr__(self, name, value):
        if name in ("_c", "_i"):
            object.__setattr__(self, name, value)
        elif name == "data":
            self._c.set_data(self._i, value)
        elif name in ("tests", "special"):
            getattr(self._c, name)[self._i] = value
        elif name in ("lam", "ds", "arclength", "iterations", "signature_index"):
            getattr(self._c, name)[self._i] = value
        elif name in ("u", "tangent"):
            p = self.to_point()
            setattr(p, name, np.asarray(value, dtype=float))
            self._c.put(self._i, p)
        else:
            raise AttributeError(f"a branch point has no attribute {name!r}")

    def to_point(self):
        """The point as a detached :class:`~pwsdyn.continuation.engine.Point` (its arrays
        copied; its data and tests the same dicts)."""
        from .engine import Point

        return Point(u=self.u.copy(), lam=self.lam, tangent=self.tangent.copy(), ds=self.ds,
                     iterations=self.iterations, arclength=self.arclength, data=self.data,
                     tests=self.tests, special=self.special,
                     signature_index=self.signature_index)

    __copy__ = to_point

    def __repr__(self):
        return (f"BranchPoint(index={self._i}, lam={self.lam!r}, special={self.special!r}, "
                f"arclength={self.arclength!r}, signature_index={self.signature_index})")


class BranchPoints(Sequence):
    """The points of a :class:`~pwsdyn.Branch` as a sequence of
    :class:`~pwsdyn.continuation.branch.BranchPoint` views (a slice is a list of them);
    assigning ``points[i] = point`` writes row ``i`` of the columns."""

    __slots__ = ("_c",)

    def __init__(self, columns: _Columns):
        self._c = columns

    def __len__(self):
        return self._c.n

    def __getitem__(self, i):
        n = self._c.n
        if isinstance(i, slice):
            return [BranchPoint(self._c, k) for k in range(*i.indices(n))]
        i = int(i)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError("branch point index out of range")
        return BranchPoint(self._c, i)

    def __setitem__(self, i, point):
        i = int(i)
        self._c.put(i + self._c.n if i < 0 else i, point)

    def __iter__(self):
        c = self._c
        return (BranchPoint(c, k) for k in range(c.n))

    def __add__(self, other):
        return list(self) + list(other)

    def __radd__(self, other):
        return list(other) + list(self)

    def __repr__(self):
        return repr(list(self))


class Branch:
    """A branch followed by :func:`pwsdyn.continue_orbit` or
    :func:`pwsdyn.continue_equilibrium`.

    The points are stored as columns (one array per attribute); ``points[i]`` and
    iteration give :class:`~pwsdyn.continuation.branch.BranchPoint` views of them with the
    attributes of a :class:`~pwsdyn.continuation.engine.Point`, and ``values``, ``stable``,
    ``admissible`` are the columns themselves (copies).

    Attributes
    ----------
    points : sequence of BranchPoint
        In the order of the arclength; located special points are points of their own.
        Assigning a list of points (``Point`` or views) stores them as the new columns.
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
        Why the branch ended, in words that name the values.
    stop_status : Status or None
        The same as a member of :class:`~pwsdyn.Status` (``MAX_POINTS``, ``SPAN_END``,
        ``STEP_BELOW_DS_MIN``, ... :data:`pwsdyn.errors.BRANCH_ENDS`); ``None`` where unknown.
    settings : ContinuationSettings
    origin : str
        For a branch switched from a special point of another branch, that point's kind
        (``"PD"`` for the period-doubled branch, whose first point is a branch point ``BP``
        of the doubled problem; ``"BP"``, ``"GR"``, ...); ``""`` for a branch started from a
        solution.
    """

    def __init__(self, problem, points, *, stop_reason="", settings=None, model=None,
                 problems=None, origin: str = "", stop_status: Status | None = None):
        self.problem = problem
        self.problems = list(problems) if problems else [problem]
        self.points = points
        self.parameter = problem.parameter
        self.kind = problem.kind
        self.stop_reason = stop_reason
        self.stop_status = (Status(stop_status) if stop_status is not None
                            else Status.of_branch_stop(stop_reason))
        self.settings = settings
        self.origin = str(origin)
        self.model = model if model is not None else getattr(
            getattr(problem, "orbit_problem", problem), "model", None)

    @property
    def points(self) -> BranchPoints:
        return BranchPoints(self._cols)

    @points.setter
    def points(self, points) -> None:
        # read every point before the columns are replaced (they may be views of them)
        self._cols = _Columns.of(points)

    def append(self, point) -> None:
        """Add a point at the end (amortised constant time: the columns grow by doubling)."""
        self._cols.append(point)

    def __len__(self):
        return self._cols.n

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
        c = self._cols
        return c.lam[:c.n].copy()

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
            c = self._cols
            return c.u[np.arange(c.n), c.usize[:c.n] - 1].copy()
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
        c = self._cols
        return c.stable[:c.n].copy()

    @property
    def admissible(self) -> np.ndarray:
        c = self._cols
        return c.admissible[:c.n].copy()

    @property
    def special_points(self) -> list[SpecialPoint]:
        c = self._cols
        return [SpecialPoint(k, i, float(c.lam[i]), self) for i, k in enumerate(c.special)
                if k]

    def special(self, kind: str) -> list[SpecialPoint]:
        """The special points of one kind."""
        return [s for s in self.special_points if s.kind == kind]

    # ---- files -----------------------------------------------------------------------
    def to_dataset(self):
        """The branch as an :class:`xarray.Dataset` (dimension ``point``)."""
        import xarray as xr

        from .._netcdf import string_array, cf_global_attrs, quantity_attrs, state_attrs, state_coords

        m = self.model
        names = list(self.problem.state_names)
        c = self._cols
        n = c.n
        spectrum = "multipliers" if self.kind == "orbit" else "eigenvalues"
        spectra = [np.asarray(d.get(spectrum, ()), dtype=complex) for d in c.data]
        nm = max((z.size for z in spectra), default=0)
        mu = np.full((n, nm), np.nan + 0j)
        for i, z in enumerate(spectra):
            mu[i, :z.size] = z
        nu = int(c.usize[:n].max()) if n else 0
        # the columns are padded with NaN to their widest problem: the file's to this branch's
        u_cols, t_cols = c.u[:n, :nu], c.tangent[:n, :nu + 1]
        kinds = sorted({k for t in c.tests for k in t})
        ds = xr.Dataset(
            {
                self.parameter: ("point", self.values, quantity_attrs(m, self.parameter)),
                "x": (("point", "state"), self.states if n else np.zeros((0, len(names))),
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
                "reason": ("point", string_array(d.get("reason", "") for d in c.data),
                           {"long_name": "why the point is not admissible (empty: it is)"}),
                "special": ("point", string_array(c.special),
                            {"long_name": "kind of special point (empty: regular)"}),
                "ds": ("point", c.ds[:n].copy(),
                       {"long_name": "arclength step that reached the point"}),
                "arclength": ("point", c.arclength[:n].copy()),
                "iterations": ("point", c.iterations[:n].astype(np.int32)),
                "u": (("point", "unknown"), u_cols.copy(),
                      {"long_name": "unknowns of the problem (NaN beyond its size)"}),
                "tangent": (("point", "unknown_and_parameter"),
                            t_cols.copy()),
                "signature_index": ("point", c.signature_index[:n].astype(np.int32),
                                    {"long_name": "index of the point's signature in the "
                                                  "signatures attribute"}),
            },
            coords={"point": np.arange(n), **state_coords(m)},
        )
        for k in kinds:
            # "GR/<surface>/<segment>": '/' is not allowed in a NetCDF name
            ds[f"test_{k.replace('/', ':')}"] = (
                "point", np.array([t.get(k, np.nan) for t in c.tests], dtype=float),
                {"long_name": KINDS.get(k.split("/")[0], k) + f" (test function {k})"})
        if self.kind == "orbit":
            ds["period"] = ("point", np.array([d.get("period", np.nan) for d in c.data],
                                              dtype=float))
        extra = [special_data_text(d) for d in c.data]
        if any(extra):
            ds["special_data"] = ("point", string_array(extra), {
                "long_name": "what a special point carries besides its kind (JSON: "
                             + ", ".join(SPECIAL_DATA) + "; empty: nothing)"})
        if self.curve:
            ds[self.parameter2] = ("point", self.values_of(self.parameter2),
                                   quantity_attrs(m, self.parameter2))
        attrs = {
            **cf_global_attrs(m, "branch", f"{self.kind} branch of {m.name} in "
                              f"{self.parameter}", "pseudo-arclength continuation"),
            "kind": self.kind,
            "parameter": self.parameter,
            "stop_reason": self.stop_reason,
            # the member's word (flag_meanings style); "" where unknown
            "stop_status": self.stop_status.meaning if self.stop_status is not None else "",
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
        # the variables the hash covers: those of the branch (a file may carry more, as
        # `pwsdyn grazing --out` adds the discontinuity map)
        ds.attrs[CONTENT_COVERS] = json.dumps(sorted(str(k) for k in ds.variables))
        ds.attrs[CONTENT_HASH] = content_hash(ds)
        return ds

    def save(self, path, *, overwrite: bool = False):
        """Write the branch to a NetCDF file (:func:`pwsdyn.load_branch` reads it back)."""
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)

    # ---- the figure ------------------------------------------------------------------
    def plot(self, y=None, *, ax=None, labels: bool = True, **kw):
        """Bifurcation diagram: the parameter against ``y`` (a state name, ``"period"``,
        ``"norm"``, ``"max:<state>"``, ``"min:<state>"`` or a function of the orbit at each
        point; see :func:`pwsdyn.plot.plot_branch`; default for orbits the largest value of
        the first state over the orbit, continuous through grazes), stable parts solid, unstable dashed,
        non-admissible dotted, special points marked and labelled."""
        from ..plot import plot_branch

        return plot_branch(self, y=y, ax=ax, labels=labels, **kw)


#: The global attribute holding :func:`content_hash` of a branch file.
CONTENT_HASH = "content_sha256"
#: The global attribute naming the variables the hash covers (JSON list; itself covered).
CONTENT_COVERS = "content_sha256_variables"
#: Global attributes covered by the content hash: every one that :func:`pwsdyn.load_branch`
#: rebuilds the branch, its model and its problems from (a file whose parameters were edited
#: after writing would resume on another branch without a word).
_HASHED_ATTRS = ("pwsdyn_type", "kind", "parameter", "parameter2", "curve", "params",
                 "settings", "stop_reason", "stop_status", "origin", "model_hash",
                 "model_spec", "signature", "signatures", "periods", "periods_of_signatures",
                 "t_refs", "states0", "options", "mode")


def content_hash(ds) -> str:
    """SHA-256 of what a branch dataset holds: each variable's name, shape and values (numbers
    as float64, every NaN the same; strings as UTF-8), then the attributes of
    ``_HASHED_ATTRS`` present; the variables those named by the ``content_sha256_variables``
    attribute (all where it is absent). The same before writing and after reading back (NetCDF keeps
    float64 and the integer flags exactly), so that any change to the file is seen."""
    import hashlib

    h = hashlib.sha256()
    covers = ds.attrs.get(CONTENT_COVERS)
    names = json.loads(covers) if covers is not None else sorted(str(k) for k in ds.variables)
    h.update(f"\0covers {covers}".encode())
    for name in names:
        a = np.asarray(ds[name].values)
        h.update(f"\0var {name} {a.shape}\0".encode())
        if a.dtype.kind in "biuf":
            b = np.array(a, dtype=np.float64)
            b[np.isnan(b)] = np.nan
            h.update(np.ascontiguousarray(b).tobytes())
        else:
            flat = [v.decode() if isinstance(v, bytes) else str(v) for v in a.ravel().tolist()]
            h.update("\x1f".join(flat).encode("utf-8", "surrogatepass"))
    for key in _HASHED_ATTRS:
        if key in ds.attrs:
            h.update(f"\0attr {key}\0{ds.attrs[key]}".encode("utf-8", "surrogatepass"))
    return h.hexdigest()


#: What a special point's data holds besides the point's own columns, kept in branch files
#: (variable ``special_data``): a graze that is a non-smooth fold, the normal-form
#: coefficient of a PD or NS point and whether it is super- or subcritical, the curves that
#: meet at a codimension-two point and the curve it lies on.
SPECIAL_DATA = ("nonsmooth_fold", "coefficient", "criticality", "meets", "curve")


def special_data_text(data: dict) -> str:
    """The ``SPECIAL_DATA`` entries of a point's data as JSON ("" when it has none)."""
    out = {}
    for k in SPECIAL_DATA:
        if k not in data:
            continue
        v = data[k]
        if isinstance(v, (bool, np.bool_)):
            out[k] = bool(v)
        elif isinstance(v, (tuple, list)):
            out[k] = [str(x) for x in v]
        elif isinstance(v, (int, float, np.number)):
            out[k] = float(v) if math.isfinite(float(v)) else str(float(v))
        else:
            out[k] = str(v)
    return json.dumps(out, sort_keys=True) if out else ""


def special_data_from_text(text: str) -> dict:
    """The inverse of :func:`special_data_text` (``meets`` as a tuple, numbers as floats)."""
    if not text:
        return {}
    raw = json.loads(text)
    if not isinstance(raw, dict) or not set(raw) <= set(SPECIAL_DATA):
        raise ValueError(f"special_data {text!r} is not an object of {SPECIAL_DATA}")
    out = {}
    for k, v in raw.items():
        if k == "meets":
            out[k] = tuple(str(x) for x in v)
        elif k == "nonsmooth_fold":
            out[k] = bool(v)
        elif k == "coefficient":
            out[k] = float(v)
        else:
            out[k] = str(v)
    return out


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
