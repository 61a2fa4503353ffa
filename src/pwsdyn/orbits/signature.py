"""The signature of a hybrid periodic orbit as a value.

A periodic orbit of a hybrid model is a cycle of smooth segments, each in one discrete state
(a mode, sticking on an impact surface, or sliding on a Filippov switch) and ended by an
event. Its *signature* is that cycle written as the events of one period, each with the
discrete states on either side of it:
``(kind, name, state_before, state_after)`` -- the fields of
:class:`~pwsdyn.integrate.trajectory.EventRecord` that do not depend on where the orbit is.
The segment ended by event ``k`` runs in ``state_before`` of event ``k``, which is
``state_after`` of event ``k - 1`` (cyclically).

:class:`Signature` is a tuple of :class:`SignatureEvent` (named tuples), so it compares equal
to the plain tuples ``((kind, name, mode_before, mode_after), ...)`` that
``PeriodicOrbit.signature`` has always returned, is hashable and ordered like a tuple, and
adds what the orbit code needs: a readable ``str``, :meth:`~pwsdyn.orbits.Signature.doubled` (the
signature of the period-doubled orbit near a period-doubling),
:meth:`~pwsdyn.orbits.Signature.rotated`, :meth:`~pwsdyn.orbits.Signature.same_cycle` (equality up
to where the period starts), the segment states, and :meth:`~pwsdyn.orbits.Signature.parse` (the
inverse of ``str``).
"""

from __future__ import annotations

import re
from typing import NamedTuple

from ..integrate.trajectory import EVENT_KINDS, DiscreteState

#: Event kinds of a signature (those of the event log).
KINDS = EVENT_KINDS


class SignatureEvent(NamedTuple):
    """One event of a signature: its kind, the model event or switch it belongs to, and the
    discrete states before and after it (:class:`~pwsdyn.integrate.trajectory.DiscreteState`:
    a mode name, ``stick:<event>``, ``slide:<switch>``)."""

    kind: str
    name: str
    mode_before: str
    mode_after: str

    def __str__(self):
        return f"{self.kind}:{self.name}"


_TOKEN = re.compile(r"\(([^()]*)\)")


class Signature(tuple):
    """The event sequence of one period of a hybrid periodic orbit (see the module docstring).

    Create one from events (``Signature.from_events(orbit.events)``), from tuples
    (``Signature([("impact", "impact", "free", "free")])``) or from its string
    (``Signature("(free) impact:impact (free)")``, the same as :meth:`parse`);
    ``PeriodicOrbit.signature`` returns one. It prints as that string, and its ``repr`` is the
    call that makes it again.

    Examples
    --------
    >>> sig = Signature([("impact", "impact", "free", "free")])
    >>> str(sig)
    '(free) impact:impact (free)'
    >>> sig
    Signature('(free) impact:impact (free)')
    >>> Signature(str(sig)) == sig
    True
    >>> sig == (("impact", "impact", "free", "free"),)
    True
    >>> len(sig.doubled())
    2
    """

    __slots__ = ()

    def __new__(cls, events=()):
        if isinstance(events, str):
            # the text str() writes: iterating it would give its characters
            return cls.parse(events)
        items = []
        for e in events:
            if isinstance(e, SignatureEvent):
                items.append(e)
                continue
            if hasattr(e, "kind") and hasattr(e, "mode_before"):   # an EventRecord
                items.append(SignatureEvent(str(e.kind), str(e.name), str(e.mode_before),
                                            str(e.mode_after)))
                continue
            t = tuple(e)
            if len(t) != 4 or not all(isinstance(v, str) for v in t):
                raise ValueError(f"a signature event is (kind, name, mode_before, mode_after) "
                                 f"as strings, got {e!r}")
            items.append(SignatureEvent(*t))
        for e in items:
            if e.kind not in KINDS:
                raise ValueError(f"unknown event kind {e.kind!r} in a signature; kinds are "
                                 f"{list(KINDS)}")
        # the states as values of the one discrete-state type (equal to their text)
        items = [e if isinstance(e.mode_before, DiscreteState)
                 and isinstance(e.mode_after, DiscreteState)
                 else e._replace(mode_before=DiscreteState.parse(e.mode_before),
                                 mode_after=DiscreteState.parse(e.mode_after))
                 for e in items]
        return super().__new__(cls, items)

    # ---- construction -------------------------------------------------------------------
    @classmethod
    def from_events(cls, events) -> "Signature":
        """The signature of a sequence of :class:`~pwsdyn.EventRecord` (one period of an orbit)."""
        return cls(events)

    @classmethod
    def parse(cls, text: str) -> "Signature":
        """The signature written by ``str``: ``"(s0) kind:name (s1) kind:name (s2) ..."``,
        the discrete states in parentheses between the events (the last is the first state
        again for a closed cycle)."""
        if not isinstance(text, str):
            raise ValueError(f"Signature.parse() needs a string, got {type(text).__name__}")
        text = text.strip()
        if text in ("", "()"):
            return cls()
        states = _TOKEN.findall(text)
        rest = [t for t in _TOKEN.split(text)]
        # split() alternates: text, state, text, state, ...; the events are the texts between
        events = [rest[i].strip() for i in range(2, len(rest) - 1, 2)]
        if len(states) != len(events) + 1 or rest[0].strip() or rest[-1].strip():
            raise ValueError(f"cannot parse signature {text!r}: expected "
                             "'(state) kind:name (state) ...'")
        out = []
        for k, ev in enumerate(events):
            kind, sep, name = ev.partition(":")
            if not sep:
                raise ValueError(f"cannot parse event {ev!r} of signature {text!r}: expected "
                                 "kind:name")
            out.append((kind, name, states[k], states[k + 1]))
        return cls(out)

    # ---- value behaviour ------------------------------------------------------------------
    def __str__(self):
        if not self:
            return "()"
        parts = [f"({self[0].mode_before})"]
        for e in self:
            parts += [f"{e.kind}:{e.name}", f"({e.mode_after})"]
        return " ".join(parts)

    def __repr__(self):
        return f"Signature({str(self)!r})" if self else "Signature()"

    def __add__(self, other):
        return Signature(tuple(self) + tuple(other))

    def __getitem__(self, i):
        out = super().__getitem__(i)
        return Signature(out) if isinstance(i, slice) else out

    # ---- structure --------------------------------------------------------------------------
    @property
    def kinds(self) -> tuple:
        """The kind of each event."""
        return tuple(e.kind for e in self)

    @property
    def states(self) -> tuple:
        """The discrete state of each segment -- ``states[k]`` is the state of the segment
        that event ``k`` ends (its ``mode_before``)."""
        return tuple(e.mode_before for e in self)

    @property
    def closed(self) -> bool:
        """Each event starts in the state the previous one ends in, cyclically (the
        signature of a periodic orbit)."""
        n = len(self)
        return all(self[k].mode_after == self[(k + 1) % n].mode_before for k in range(n))

    def count(self, kind) -> int:  # type: ignore[override]
        """Number of events of ``kind`` (a kind name), or of an event equal to ``kind``."""
        if isinstance(kind, str):
            return sum(1 for e in self if e.kind == kind)
        return super().count(kind)

    def doubled(self) -> "Signature":
        """The signature repeated twice: the orbit of twice the period that branches off at a
        period-doubling bifurcation starts with this event sequence."""
        return Signature(tuple(self) * 2)

    def rotated(self, k: int) -> "Signature":
        """The same cycle started ``k`` events later."""
        if not self:
            return self
        k %= len(self)
        return Signature(tuple(self[k:]) + tuple(self[:k]))

    def same_cycle(self, other) -> bool:
        """Equal up to a rotation (where the period starts)."""
        other = Signature(other)
        if len(other) != len(self):
            return False
        return any(self.rotated(k) == other for k in range(max(len(self), 1)))
