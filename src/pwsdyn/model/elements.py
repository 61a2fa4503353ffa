"""The parts a flow model is made of: modes, surfaces, events and switches (symbolic).

Values only, with no parsing: the model definition (:mod:`pwsdyn.model.spec`) builds them,
and the expansion of discontinuous fields (:mod:`pwsdyn.model.discontinuities`) makes more
of them, each reading them from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Mode:
    """A smooth mode: its name and vector field ``f(t, x, p)`` (one expression per state)."""

    name: str
    rhs: tuple


@dataclass(frozen=True)
class Surface:
    """A scalar event function ``h(t, x, p)``; its zero set is a discontinuity surface."""

    name: str
    expr: Any


@dataclass(frozen=True)
class Event:
    """A transition fired when ``h`` crosses zero in ``direction`` while in one of ``modes``.

    Attributes
    ----------
    name : str
    kind : {'impact', 'transition'}
    surface : int
        Index into ``Model.surfaces``.
    direction : int
        -1: ``h`` decreasing through zero; +1 increasing; 0 either.
    modes : tuple[int, ...]
        Modes in which the event is active.
    guard : sympy Boolean or None
        The event fires only where the guard holds.
    reset : tuple or None
        The new state ``g(t, x, p)``, one expression per state (identity where not given).
    target : int or None
        The mode after the event (``None``: the same mode).
    terminal : bool
        Stop the simulation after this event.
    """

    name: str
    kind: str
    surface: int
    direction: int
    modes: tuple
    guard: Any = None
    reset: tuple | None = None
    target: int | None = None
    terminal: bool = False


@dataclass(frozen=True)
class Switch:
    """A switching surface: mode ``above`` where ``h > 0``, ``below`` where ``h < 0``.

    Attributes
    ----------
    kind : {'filippov', 'continuous'}
        ``filippov``: the field jumps across the surface; the flow crosses or slides (thesis
        eq. 2.6-2.8). ``continuous``: only a derivative jumps (``Abs``, ``Max``, ``Min``); the
        crossing is located, there is no sliding.
    family : tuple or None
        The field ``f(t, x, u)`` with the switching term replaced by
        :data:`pwsdyn.model.discontinuities.U_SYMBOL` (``u = +1`` above, ``-1`` below), for
        Utkin's equivalent control; ``None``: ``(1 + u)/2 f_above + (1 - u)/2 f_below``.
    """

    name: str
    surface: int
    above: int
    below: int
    kind: str = "filippov"
    family: tuple | None = None


@dataclass(frozen=True)
class SignFamily:
    """The ``2**k`` variants of a mode split at ``k`` surfaces, as one field of their sides.

    The loader splits a mode with discontinuous terms into one variant per combination of
    sides (:mod:`pwsdyn.model.discontinuities`); where every term sits directly on a surface
    (no term nested in another's argument) the variants are also one field ``rhs`` in the
    side variables ``side_j`` (``+1`` above ``surfaces[j]``, ``-1`` below). The code generator
    then compiles that one field, and its derivatives, for all the variants, and decodes the
    sides from the variant's index, instead of ``2**k`` copies.

    Attributes
    ----------
    first : int
        Index of the first variant (above every surface). Variant ``first + c`` lies below
        ``surfaces[j]`` where bit ``k - 1 - j`` of ``c`` is set.
    surfaces : tuple[int, ...]
        Model surface of each side variable.
    rhs : tuple
        The field in the states, parameters, time and the side variables.
    switches : tuple[int, ...]
        Per surface, the index of the first of its ``2**(k-1)`` Filippov switches (ordered by
        the variant above them), or -1 where the surface is a kink (continuous switches).
    multilinear : bool
        Whether ``rhs`` is affine in each side on the surfaces (where each ``Abs`` term is
        zero): then on an intersection of the surfaces the multilinear extension of the
        variants' fields (the kernel's sliding rule) is ``rhs`` at the sides ``1 - 2 lambda``,
        and the kernel evaluates it so, with no sum over the ``2**k`` corners.
    """

    first: int
    surfaces: tuple
    rhs: tuple
    switches: tuple
    multilinear: bool = False

    @property
    def size(self) -> int:
        """The number of variants, ``2**k``."""
        return 1 << len(self.surfaces)
