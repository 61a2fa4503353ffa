"""The result of a simulation: a :class:`Trajectory` with dense output and its event log."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING
from dataclasses import dataclass, field

import numpy as np

from ..errors import ArgumentError, Status

if TYPE_CHECKING:
    from pathlib import Path

    import xarray as xr
    from numpy.typing import ArrayLike

    from .._typing import PathLike

from .._codes import EVENT_LOG_KINDS, STATE_KINDS as _STATE_KINDS

#: Event kinds of the log, indexed by the kernel's codes.
EVENT_KINDS = EVENT_LOG_KINDS
#: Discrete states of the kernel -- a regular mode, sticking on an impact surface, sliding.
STATE_KINDS = _STATE_KINDS


class DiscreteState(str):
    """A discrete state of a flow: a mode, sticking on an impact event, sliding on a switch or
    on the intersection of several switching surfaces.

    ``DiscreteState(kind, name)`` with ``kind`` one of
    :data:`~pwsdyn.integrate.trajectory.STATE_KINDS` (``"mode"``, ``"stick"``, ``"slide"``,
    ``"slide_multi"``) and ``name`` the mode, impact event or switch; for ``slide_multi`` the
    names of the surfaces slid on, joined by ``&`` (``slide_multi:v1&v2``; :attr:`surfaces`).
    It is the text the event log, the trajectory's ``state`` and every file have always used
    (the mode's name, ``stick:<event>``, ``slide:<switch>``) and a ``str``: it compares equal to
    that text, hashes like it and is written as it, so code that compares states with strings
    keeps working. :meth:`parse` is the one reader of that text.

    Examples
    --------
    >>> s = DiscreteState.parse("stick:impact")
    >>> s.kind, s.name, s == "stick:impact"
    ('stick', 'impact', True)
    """

    __slots__ = ()

    def __new__(cls, kind: str, name: str):
        if kind not in STATE_KINDS:
            raise ValueError(f"the kind of a discrete state is one of {STATE_KINDS}, got "
                             f"{kind!r}")
        if not isinstance(name, str) or not name or ":" in name:
            raise ValueError(f"the name of a discrete state is a non-empty name without ':', "
                             f"got {name!r}")
        return super().__new__(cls, name if kind == "mode" else f"{kind}:{name}")

    @classmethod
    def parse(cls, text) -> "DiscreteState":
        """The state written as ``text`` (a mode name, ``stick:<event>`` or
        ``slide:<switch>``); a :class:`ValueError` for any other text."""
        if isinstance(text, DiscreteState):
            return text
        if not isinstance(text, str):
            raise ValueError(f"a discrete state is written as a string, got "
                             f"{type(text).__name__}")
        kind, sep, name = str(text).partition(":")
        if not sep:
            return cls("mode", kind)
        if kind not in ("stick", "slide", "slide_multi"):
            raise ValueError(f"unknown discrete state {str(text)!r}: expected a mode name, "
                             "'stick:<event>' or 'slide:<switch>'")
        return cls(kind, name)

    @property
    def kind(self) -> str:
        """``"mode"``, ``"stick"``, ``"slide"`` or ``"slide_multi"``."""
        kind, sep, _ = self.partition(":")
        return kind if sep else "mode"

    @property
    def name(self) -> str:
        """The mode, impact event or switch."""
        _, sep, name = self.partition(":")
        return name if sep else str(self)

    @property
    def surfaces(self) -> tuple:
        """The surfaces slid on at once, for ``slide_multi`` (their names; empty otherwise)."""
        return tuple(self.name.split("&")) if self.kind == "slide_multi" else ()

    @property
    def code(self) -> int:
        """The kernel's code of :attr:`kind`: 0 a mode, 1 sticking, 2 sliding, 3 sliding on an
        intersection."""
        return STATE_KINDS.index(self.kind)

    @property
    def is_mode(self) -> bool:
        """True for a regular mode (not sticking, not sliding)."""
        return ":" not in self

    def __getnewargs__(self):
        return (self.kind, self.name)

    def __repr__(self):
        return f"DiscreteState({self.kind!r}, {self.name!r})"


@dataclass(slots=True, eq=False)
class EventRecord:
    """One event of a trajectory.

    Attributes
    ----------
    t : float
        Time of the event. For ``chatter`` the time the chattering sequence starts; the
        accumulation time is ``t_after``.
    name : str
        The model event (or switch) that fired; ``release``/``slide_end`` name the surface's
        event or switch.
    kind : str
        One of ``impact``, ``transition``, ``chatter``, ``stick``, ``release``, ``crossing``,
        ``slide_start``, ``slide_end``.
    x_before, x_after : numpy.ndarray
        State just before and just after the event.
    mode_before, mode_after : DiscreteState (a str)
        The discrete state before and after: a mode name, ``stick:<event>`` or
        ``slide:<switch>``.
    t_after : float
        Time after the event (differs from ``t`` only for ``chatter``).

    Notes
    -----
    Records are plain slotted objects (not frozen: a frozen dataclass costs five times as much
    to create, and sweeps create millions); treat them as read-only.
    """

    t: float
    name: str
    kind: str
    x_before: np.ndarray
    x_after: np.ndarray
    mode_before: str
    mode_after: str
    t_after: float

    def __repr__(self):
        return (f"EventRecord(t={self.t:.12g}, name={self.name!r}, kind={self.kind!r}, "
                f"{self.mode_before} -> {self.mode_after})")

    def __eq__(self, other):
        # field by field, the states as arrays (the generated __eq__ compares a tuple of
        # arrays, whose truth value numpy refuses)
        if not isinstance(other, EventRecord):
            return NotImplemented
        return (self.t == other.t and self.t_after == other.t_after
                and self.name == other.name and self.kind == other.kind
                and self.mode_before == other.mode_before
                and self.mode_after == other.mode_after
                and np.array_equal(self.x_before, other.x_before)
                and np.array_equal(self.x_after, other.x_after))

    __hash__ = None


#: Event kinds logged on a switching surface (their ``name`` is the switch's).
SWITCH_EVENT_KINDS = ("crossing", "slide_start", "slide_end")


class EventLog(Sequence):
    """The event log of a run: a read-only sequence of :class:`~pwsdyn.EventRecord` with its
    columns as arrays.

    The kernel returns the log as arrays; records are made only when the log is indexed or
    iterated (a sweep logs hundreds of events per parameter value and reads the columns
    only). The columns: ``t``, ``t_after``, ``kind_code`` (index into
    :data:`~pwsdyn.integrate.trajectory.EVENT_KINDS`), ``ref`` (event or switch index),
    ``x_before``, ``x_after``, ``state_before``/``state_after`` (kernel discrete states ``(kind,
    index, mode)``, kind 0 a mode, 1 sticking, 2 sliding) and the derived ``kind`` and ``name``.
    """

    __slots__ = ("model", "t", "t_after", "kind_code", "ref", "x_before", "x_after",
                 "state_before", "state_after", "_records", "_state_name")

    def __init__(self, model, t, t_after, info, x_before, x_after, state_name):
        self.model = model
        self.t = t
        self.t_after = t_after
        self.kind_code = info[:, 0]
        self.ref = info[:, 1]
        self.state_before = info[:, 2:5]
        self.state_after = info[:, 5:8]
        self.x_before = x_before
        self.x_after = x_after
        self._state_name = state_name
        self._records = None

    @classmethod
    def from_records(cls, model, records, n: int | None = None) -> "EventLog":
        """The log of ``records`` (:class:`~pwsdyn.EventRecord`, in time order), with its columns.

        For a log that does not come from the kernel: one read from a file, the events of a
        periodic orbit put together from its segments. Its records are the ones given (their
        discrete states as :class:`DiscreteState`); the kernel codes of the columns are
        derived from the names, the constrained mode of a sticking or sliding state being the
        last regular mode before it (-1 before any)."""
        records = list(records)
        m = len(records)
        if n is None:
            n = len(model.states) if model is not None else (
                len(records[0].x_before) if m else 0)
        ev_index = {e.name: j for j, e in enumerate(getattr(model, "events", ()))}
        sw_index = {s.name: j for j, s in enumerate(getattr(model, "switches", ()))}
        modes = {name: j for j, name in enumerate(getattr(model, "mode_names", ()))}
        info = np.full((m, 8), -1, dtype=np.int64)
        last_mode = -1

        def code(st: DiscreteState) -> tuple:
            nonlocal last_mode
            if st.kind == "mode":
                last_mode = modes.get(st.name, -1)
                return (0, -1, last_mode)
            table = ev_index if st.kind == "stick" else sw_index
            return (st.code, table.get(st.name, -1), last_mode)

        out = []
        for r, e in enumerate(records):
            before = DiscreteState.parse(e.mode_before)
            after = DiscreteState.parse(e.mode_after)
            on_switch = e.kind in SWITCH_EVENT_KINDS
            info[r, 0] = EVENT_KINDS.index(e.kind) if e.kind in EVENT_KINDS else -1
            info[r, 1] = (sw_index if on_switch else ev_index).get(e.name, -1)
            info[r, 2:5] = code(before)
            info[r, 5:8] = code(after)
            if before is not e.mode_before or after is not e.mode_after:
                e = EventRecord(e.t, e.name, e.kind, e.x_before, e.x_after, before, after,
                                e.t_after)
            out.append(e)

        def rows(attr):
            return np.array([np.asarray(getattr(e, attr), dtype=float)[:n] for e in out],
                            dtype=float).reshape(m, n)

        log = cls(model, np.array([e.t for e in out], dtype=float),
                  np.array([e.t_after for e in out], dtype=float), info, rows("x_before"),
                  rows("x_after"), None)
        log._records = out
        return log

    @property
    def kind(self) -> np.ndarray:
        if self._records is not None and self._state_name is None:
            return np.array([e.kind for e in self._records], dtype=object)
        return np.array(EVENT_KINDS, dtype=object)[self.kind_code]

    @property
    def name(self) -> np.ndarray:
        if self._records is not None and self._state_name is None:
            return np.array([e.name for e in self._records], dtype=object)
        return np.array(self._coded_names()[1], dtype=object)

    def _coded_names(self) -> tuple:
        """``(kinds, names)`` of the events, looked up from their codes (lists: for the few
        events of a shooting interval arrays cost more than the lookups): a switch's name for
        the kinds on a switching surface, an event's otherwise."""
        kinds = [EVENT_KINDS[c] for c in self.kind_code.tolist()]
        ev = [e.name for e in self.model.events] or [""]
        sw = [s.name for s in self.model.switches] or [""]
        return kinds, [sw[r] if k in SWITCH_EVENT_KINDS else ev[r]
                       for k, r in zip(kinds, self.ref.tolist())]

    def _materialize(self) -> list:
        if self._records is None:
            names: dict = {}

            def state(k, i, m):
                key = (k, i, m)
                if key not in names:
                    names[key] = self._state_name(self.model, k, i, m)
                return names[key]

            kinds, evn = self._coded_names()
            sb, sa = self.state_before.tolist(), self.state_after.tolist()
            t, t2 = self.t.tolist(), self.t_after.tolist()
            self._records = [EventRecord(t[r], evn[r], kinds[r], self.x_before[r],
                                         self.x_after[r], state(*sb[r]), state(*sa[r]), t2[r])
                             for r in range(len(t))]
        return self._records

    def __len__(self):
        return len(self.t)

    def __getitem__(self, i):
        return self._materialize()[i]

    def __iter__(self):
        return iter(self._materialize())

    def __eq__(self, other):
        if isinstance(other, Sequence):
            return list(self) == list(other)
        return NotImplemented

    def __repr__(self):
        return f"EventLog({len(self)} events)"


class LazyDense:
    """Dense output rebuilt on demand: the power-form coefficients of every interval,
    ``(n_intervals, n_y, degree)``, as a run with stored dense output has them, computed from
    the run's nodes and step lengths when they are read (``simulate``'s default: storing them
    per step doubled the cost of a run).

    ``rebuild(indices)`` returns the coefficients of the given intervals. Indexing with an
    integer array rebuilds those intervals only; ``numpy.asarray`` (or any other use as an
    array: saving, concatenating, pickling) builds and keeps the whole array."""

    __slots__ = ("shape", "_rebuild", "_full")

    #: Above this fraction of the intervals, an index rebuilds (and keeps) the whole array.
    FULL_FRACTION = 0.25

    def __init__(self, shape, rebuild):
        self.shape = tuple(int(v) for v in shape)
        self._rebuild = rebuild
        self._full = None

    ndim = 3
    dtype = np.dtype(float)

    def __len__(self):
        return self.shape[0]

    def materialize(self) -> np.ndarray:
        """The whole array (built once, then kept)."""
        if self._full is None:
            self._full = self._rebuild(np.arange(self.shape[0], dtype=np.int64))
        return self._full

    def __array__(self, dtype=None, copy=None):
        a = self.materialize()
        if dtype is not None and np.dtype(dtype) != a.dtype:
            return a.astype(dtype)
        return a.copy() if copy else a

    def __getitem__(self, index):
        if self._full is not None:
            return self._full[index]
        idx = np.asarray(index)
        if idx.dtype.kind not in "iu" or idx.ndim > 1:
            return self.materialize()[index]
        flat = np.atleast_1d(idx).astype(np.int64)
        flat = np.where(flat < 0, flat + self.shape[0], flat)
        if np.any((flat < 0) | (flat >= self.shape[0])):
            raise IndexError(f"interval index out of range for {self.shape[0]} intervals")
        uniq, inv = np.unique(flat, return_inverse=True)
        if len(uniq) > self.FULL_FRACTION * self.shape[0]:
            return self.materialize()[index]
        rows = self._rebuild(uniq)[inv]
        return rows[0] if idx.ndim == 0 else rows

    def __reduce__(self):
        # pickles (and deep copies) as the plain array
        return (np.asarray, (self.materialize(),))

    def __repr__(self):
        state = "built" if self._full is not None else "on demand"
        return f"LazyDense(shape={self.shape}, {state})"


@dataclass(eq=False)
class Trajectory:
    """A simulated hybrid trajectory.

    Attributes
    ----------
    t : numpy.ndarray, shape (N,)
        Times of the stored nodes (accepted steps, and both sides of every event: an event
        time appears twice, before and after the jump).
    x : numpy.ndarray, shape (N, n)
        States at those times.
    state : numpy.ndarray of str
        Discrete state (mode name, ``stick:<event>`` or ``slide:<switch>``) at each node;
        :meth:`~pwsdyn.integrate.DiscreteState.parse` reads an entry.
    events : EventLog
        The event log, in time order: a sequence of :class:`EventRecord` whose columns are
        also arrays. It is the hybrid orbit's segment signature. A list of records given to
        the constructor is made an :class:`~pwsdyn.integrate.EventLog`
        (:meth:`~pwsdyn.integrate.EventLog.from_records`).
    status : Status
    message : str
    stats : dict
        ``steps``, ``rejected_steps``, ``nfev``, ``events``, ``chatter``, ``landing_steps``.
    model : Model
    params : dict
        Parameter values used.
    options : dict
        Integrator options used.
    jacobian : numpy.ndarray or None
        With ``variational=True``: derivative of the final state with respect to the initial
        state (n x n), including every saltation matrix.
    transfer_matrices : list of numpy.ndarray or None
        With ``variational=True``: ``[Phi_0, S_1, Phi_1, ..., S_m, Phi_m]`` for the ``m``
        events of ``events``: ``Phi_k`` the Jacobian of the smooth flow over the ``k``-th
        segment, ``S_k`` the full saltation matrix of the ``k``-th event (``Phi+ = S Phi-``), so
        ``jacobian`` is their ordered product ``Phi_m S_m ... S_1 Phi_0`` (COCO's hspo
        composition). See :mod:`pwsdyn.stability` for projected forms. Not saved to files.
    samples : (numpy.ndarray, numpy.ndarray) or None
        Times and states recorded at regular times from the dense output (a stroboscopic
        section; the internal runner's ``sample=(t_first, dt)``).
    final_discrete_state : tuple of int or None
        The kernel's discrete state at the end, ``(kind, index, mode)`` (kind 0 a mode, 1
        sticking on event ``index``, 2 sliding on switch ``index``): a run continued from
        ``x_final`` starts in it (the ``dkind0``/``didx0``/``mode0`` of the internal runner).

    Notes
    -----
    A trajectory returned by a run makes ``state``, ``events``, ``stats``, ``params``,
    ``options``, ``provenance``, its dense output and, for a model given by name, its own
    copy of the model when each is first read, then keeps it: the values are those it
    would have been built with.
    """

    t: np.ndarray
    x: np.ndarray
    state: list
    events: list
    status: Status
    message: str
    stats: dict
    model: object
    params: dict
    options: dict
    t0: float
    t_end: float
    jacobian: np.ndarray | None = None
    transfer_matrices: list | None = field(default=None, repr=False)
    final_discrete_state: tuple | None = field(default=None, repr=False)
    samples: tuple | None = field(default=None, repr=False)
    # dense output: per interval between consecutive nodes (an array, or a LazyDense that
    # rebuilds it on demand)
    _dense: np.ndarray | LazyDense | None = field(default=None, repr=False)
    _ikind: np.ndarray | None = field(default=None, repr=False)
    _y: np.ndarray | None = field(default=None, repr=False)  # full nodes incl. variational part
    provenance: dict = field(default_factory=dict)

    def __post_init__(self):
        # one type of log whatever made the trajectory (the kernel, a file, an orbit's
        # segments): code reading the columns need not ask which
        if not isinstance(self.events, EventLog):
            self.events = EventLog.from_records(self.model, self.events,
                                                n=np.shape(self.x)[1] if np.ndim(self.x) == 2
                                                else None)

    def __getstate__(self):
        # a trajectory with deferred fields (see _Deferred) pickles and copies as one with
        # every field made: the function making them is the run's, not data
        d = self.__dict__
        if "_make" in d:
            for name in DEFERRED_FIELDS:
                getattr(self, name)
            d = {k: v for k, v in d.items() if k != "_make"}
        return d

    # ------------------------------------------------------------------------------------
    @property
    def success(self) -> bool:
        return not self.status.failed

    @property
    def y(self) -> np.ndarray:
        """The full node vectors -- the state, then (runs with ``variational=True``) the
        variational matrix, row-major; the states ``x`` when there is no variational part."""
        return self.x if self._y is None else self._y

    @property
    def dense(self) -> np.ndarray | LazyDense | None:
        """The dense output, per interval between consecutive nodes, the coefficients of
        ``y(t0 + theta h) = y0 + sum_k dense[k] theta^(k+1)``, shape ``(intervals, len(y),
        degree)``; ``None`` for a run with ``dense=False``."""
        return self._dense

    @property
    def interval_kind(self) -> np.ndarray | None:
        """How each interval between consecutive nodes is evaluated -- 0 the dense
        polynomial, 1 linear (a jump, or no dense output), 2 linear across a chattering gap."""
        return self._ikind

    @classmethod
    def from_parts(cls, *, dense=None, interval_kind=None, y=None, **fields) -> "Trajectory":
        """A trajectory from its fields (those of the class) and its dense output: ``dense``,
        ``interval_kind`` and the full node vectors ``y``, as :attr:`dense`,
        :attr:`interval_kind` and :attr:`y` give them back."""
        return cls(**fields, _dense=dense, _ikind=interval_kind, _y=y)

    @property
    def n_states(self) -> int:
        return self.x.shape[1]

    @property
    def state_names(self) -> tuple:
        return self.model.states

    @property
    def x_final(self) -> np.ndarray:
        return self.x[-1]

    @property
    def t_final(self) -> float:
        return float(self.t[-1])

    def __len__(self):
        return len(self.t)

    def __repr__(self):
        from .._display import num

        c = ", ".join(f"{k}={v}" for k, v in self.event_counts().items()) or "none"
        t_last = self.t_final if np.size(self.t) else self.t0
        return (f"Trajectory(model={getattr(self.model, 'name', '?')!r}, "
                f"t=[{num(self.t0)}, {num(t_last)}], nodes={np.size(self.t)}, events: {c}, "
                f"status={getattr(self.status, 'name', self.status)})")

    def _repr_html_(self):
        from .._display import counts_text, html_table, num, state_text

        status = self.status
        rows = [("model", getattr(self.model, "name", "?")),
                ("time", f"{num(self.t0)} to {num(self.t_final) if np.size(self.t) else '?'}"
                         f" (asked: {num(self.t_end)})"),
                ("nodes", np.size(self.t)),
                ("events", counts_text(self.event_counts())),
                ("status", f"{getattr(status, 'name', status)}: {self.message}")]
        if np.size(self.t):
            rows.append(("final state", state_text(getattr(self.model, "states", ()),
                                                   self.x_final)
                         + f" in {self.state[-1] if len(self.state) else '?'}"))
        if self.params:
            rows.append(("parameters", ", ".join(f"{k}={num(v)}"
                                                 for k, v in self.params.items())))
        return html_table("Trajectory", rows)

    def event_counts(self) -> dict:
        out: dict = {}
        for e in self.events:
            out[e.kind] = out.get(e.kind, 0) + 1
        return out

    def events_of(self, kind: str | None = None, name: str | None = None) -> list:
        """Events filtered by kind and/or name."""
        return [e for e in self.events
                if (kind is None or e.kind == kind) and (name is None or e.name == name)]

    def event_times(self, kind: str | None = None, name: str | None = None) -> np.ndarray:
        return np.array([e.t for e in self.events_of(kind, name)])

    def sliding_intervals(self) -> list:
        """The Filippov sliding segments: ``[(t_start, t_end, switch name), ...]``; sliding on
        an intersection is named by its surfaces joined by ``&`` (``"v1&v2"``).

        Read from the discrete state of the nodes, so a run that starts on a sliding surface
        (no ``slide_start`` event) or ends while sliding is included; consecutive segments on
        the same surface joined by the crossing of another surface (sliding continues) count
        as one.
        """
        out = []
        cur = None
        t = np.asarray(self.t)
        parsed: dict = {}
        for i in range(len(t)):
            text = str(self.state[i])
            st = parsed.get(text)
            if st is None:
                st = parsed[text] = DiscreteState.parse(text)
            if st.kind == "slide" or st.kind == "slide_multi":
                if cur is not None and cur[2] == st.name:
                    cur[1] = float(t[i])
                else:
                    if cur is not None:
                        out.append(tuple(cur))
                    cur = [float(t[i]), float(t[i]), st.name]
            elif cur is not None:
                out.append(tuple(cur))
                cur = None
        if cur is not None:
            out.append(tuple(cur))
        return out

    # ------------------------------------------------------------------------------------
    def __call__(self, t: ArrayLike, side: str = "left",
                 variational: bool = False) -> np.ndarray:
        """Evaluate the dense output at time(s) ``t``.

        Parameters
        ----------
        t : float or array_like
        side : {'left', 'right'}
            At an event time, the state before (``left``) or after (``right``) the jump.
        variational : bool
            Also return the variational part (only with ``variational=True`` simulations).

        Returns
        -------
        numpy.ndarray, shape (n,) for scalar ``t`` or (len(t), n)
        """
        if self._dense is None:
            raise ValueError("this trajectory has no dense output (simulated with "
                             "`dense=False`); only its nodes `t`, `x` are stored")
        if side not in ("left", "right"):
            raise ValueError(f"`side` must be 'left' or 'right', got {side!r}")
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        lo, hi = self.t[0], self.t[-1]
        if np.any((ts < lo - 1e-12 * max(1, abs(lo))) | (ts > hi + 1e-12 * max(1, abs(hi)))):
            raise ValueError(f"`t` outside the simulated interval [{lo}, {hi}]")
        ny = self._y.shape[1]
        nout = ny if variational else self.n_states
        nint = len(self._ikind)
        if nint == 0:
            return self._y[0, :nout].copy() if np.ndim(t) == 0 else np.tile(self._y[0, :nout],
                                                                             (len(ts), 1))
        # 'left': t[i] < t <= t[i+1]; 'right': t[i] <= t < t[i+1]. Either way the interval
        # found has positive length, so zero-length jump intervals are never interpolated.
        idx = np.searchsorted(self.t, ts, side=side) - 1
        # (numpy.clip of integers looks up their limits at every call)
        idx = np.minimum(np.maximum(idx, 0), nint - 1)
        dense = self._dense
        if isinstance(dense, np.ndarray) and dense.shape[:2] == (nint, ny) and ts.ndim == 1:
            # stored dense output (not rebuilt on demand): every time in one compiled loop,
            # the same operations as the array code below (a segment's ~200 samples cost
            # ~40 array operations there)
            from ._rows import dense_rows

            out = dense_rows(np.ascontiguousarray(self.t, dtype=float),
                             np.ascontiguousarray(self._y, dtype=float),
                             np.ascontiguousarray(self._ikind, dtype=np.int64),
                             np.ascontiguousarray(dense, dtype=float),
                             np.ascontiguousarray(ts),
                             np.ascontiguousarray(idx, dtype=np.int64), side == "right")
            out = out[:, :nout]
            return out[0] if np.ndim(t) == 0 else out
        t0 = self.t[idx]
        t1 = self.t[idx + 1]
        length = t1 - t0
        theta = np.divide(ts - t0, length, out=np.zeros_like(ts), where=length > 0)
        theta = np.clip(theta, 0.0, 1.0)
        y0 = self._y[idx]
        y1 = self._y[idx + 1]
        kind = self._ikind[idx]
        smooth = (kind == 0) & (length > 0)
        if len(ts) and smooth.all():
            # every time inside a step of positive length (the samples of a segment): the
            # polynomial alone, as below
            Q = self._dense[idx]
            th = theta[:, None]
            acc = np.zeros((Q.shape[0], ny))
            for k in range(Q.shape[2] - 1, -1, -1):
                acc = (acc + Q[:, :, k]) * th
            out = (y0 + acc)[:, :nout]
            return out[0] if np.ndim(t) == 0 else out
        # linear between nodes: chattering gaps and intervals stored without dense output
        out = (1.0 - theta)[:, None] * y0 + theta[:, None] * y1
        if np.any(smooth):
            Q = self._dense[idx[smooth]]
            th = theta[smooth][:, None]
            acc = np.zeros((Q.shape[0], ny))
            for k in range(Q.shape[2] - 1, -1, -1):
                acc = (acc + Q[:, :, k]) * th
            out[smooth] = y0[smooth] + acc
        zero = length <= 0
        if np.any(zero):
            out[zero] = np.where((side == "right"), y1[zero].T, y0[zero].T).T
        out = out[:, :nout]
        return out[0] if np.ndim(t) == 0 else out

    def sample(self, num: int = 2000) -> tuple[np.ndarray, np.ndarray]:
        """Times and states on a uniform grid plus both sides of every event (for plots)."""
        if self._dense is None:
            return self.t, self.x
        grid = np.linspace(self.t[0], self.t[-1], num)
        evt = np.array([e.t for e in self.events] + [e.t_after for e in self.events])
        evt = evt[(evt >= self.t[0]) & (evt <= self.t[-1])]
        ts = np.unique(np.concatenate([grid, evt]))
        left = self(ts, side="left")
        right = self(ts, side="right")
        T = np.repeat(ts, 2)
        X = np.empty((2 * len(ts), self.n_states))
        X[0::2] = left
        X[1::2] = right
        return T, X

    # ------------------------------------------------------------------------------------
    # The file layout is in pwsdyn._trajectory_file, a layer below this module that imports
    # no result type (pwsdyn.io -> this module -> pwsdyn._trajectory_file -> pwsdyn._netcdf,
    # pwsdyn.model): imported in the methods only so that a run does not load xarray.
    def to_dataset(self) -> xr.Dataset:
        """The trajectory as an :class:`xarray.Dataset` (nodes, events, dense output,
        provenance in attributes; the layout is described in :mod:`pwsdyn.io`). Inverse:
        :meth:`from_dataset`."""
        from .._trajectory_file import trajectory_dataset

        return trajectory_dataset(self)

    @classmethod
    def from_dataset(cls, ds: xr.Dataset, model=None) -> Trajectory:
        """The trajectory a dataset made by :meth:`to_dataset` holds; ``model`` as in
        :func:`pwsdyn.io.trajectory_from_dataset`."""
        from .._trajectory_file import dataset_fields

        fields, rows = dataset_fields(ds, model=model)
        n = fields["x"].shape[1]
        events = EventLog.from_records(fields["model"], (EventRecord(*r) for r in rows), n=n)
        return Trajectory.from_parts(events=events, **fields)

    def save(self, path: PathLike, overwrite: bool = False) -> Path:
        """Write the trajectory to a NetCDF file (atomically); returns the path.

        An existing file is refused with :class:`~pwsdyn.OutputExistsError` (nothing is
        written) unless ``overwrite=True``. Read it back with :func:`pwsdyn.io.load_trajectory`.
        """
        from .._netcdf import save_dataset

        return save_dataset(self.to_dataset(), path, overwrite=overwrite)


_NO_DEFAULT = object()


class _Deferred:
    """A field of :class:`Trajectory` made when first read, then kept in the instance.

    A trajectory from a run (:meth:`pwsdyn.integrate.compiled.RunResult.trajectory`) is
    created with its arrays only and a function ``_make(traj, name)`` in its ``__dict__``;
    the discrete state per node, the event log, the statistics, parameter and option dicts,
    the provenance, the dense output (and, for a model given by name, the model's own copy)
    are made by it on first access: ``simulate()`` of a short span cost more in building
    them than in integrating, and most callers read a few of them. A non-data descriptor: a
    value in the instance's ``__dict__`` (from ``__init__``, an assignment, or the first
    read) takes precedence, so a trajectory built by its constructor never comes here."""

    __slots__ = ("name", "default")

    def __init__(self, name, default):
        self.name = name
        self.default = default

    def __get__(self, obj, cls=None):
        if obj is None:
            if self.default is _NO_DEFAULT:
                raise AttributeError(self.name)
            return self.default
        make = obj.__dict__.get("_make")
        if make is None:
            raise AttributeError(f"'Trajectory' object has no attribute {self.name!r}")
        value = obj.__dict__[self.name] = make(obj, self.name)
        return value


#: The fields of :class:`Trajectory` that a run's trajectory makes when first read.
DEFERRED_FIELDS = ("state", "events", "stats", "model", "params", "options", "provenance",
                   "_dense")
for _name in DEFERRED_FIELDS:
    setattr(Trajectory, _name, _Deferred(_name, Trajectory.__dict__.get(_name, _NO_DEFAULT)))
del _name


def trajectory_to_dataset(traj) -> xr.Dataset:
    """The trajectory as an :class:`xarray.Dataset`, with the model and provenance attached.

    Parameters
    ----------
    traj : Trajectory
        A result of :func:`pwsdyn.simulate`.

    Returns
    -------
    xarray.Dataset
        See :mod:`pwsdyn.io` for the layout. ``dense`` is omitted when the trajectory has no
        dense output, ``jacobian`` when it has no variational part.

    Raises
    ------
    TypeError
        If ``traj`` is not a trajectory.
    """
    if not isinstance(traj, Trajectory):
        raise ArgumentError(f"`traj` must be a Trajectory, got {type(traj).__name__}")
    return traj.to_dataset()


def trajectory_from_dataset(ds: xr.Dataset, model=None) -> Trajectory:
    """Rebuild a :class:`~pwsdyn.Trajectory` from its dataset.

    Parameters
    ----------
    ds : xarray.Dataset
        A dataset made by :func:`trajectory_to_dataset` (or read from its NetCDF file).
    model : Model, str, path or dict, optional
        The model to attach. By default it is rebuilt from the ``model_spec`` attribute with
        :func:`pwsdyn.load_model`; a warning is issued if its hash differs from the stored
        ``model_hash`` (the file was written by a version of pwsdyn that read the model
        differently).

    Returns
    -------
    Trajectory
        With the same nodes, event log, status and dense output: ``traj(t)`` gives the same
        numbers as the trajectory that was saved.

    Raises
    ------
    ValueError
        If ``ds`` is not a pwsdyn trajectory dataset.
    """
    return Trajectory.from_dataset(ds, model=model)
