r"""Burridge-Knopoff chains: ``n`` blocks in a row on a moving plate, each with its own friction
contact.

The model of :func:`pwsdyn.burridge_knopoff` (Burridge & Knopoff 1967; with velocity-weakening
friction, Carlson & Langer 1989), in the frame of the blocks' rest positions: block :math:`i` at
:math:`x_i` with velocity :math:`v_i` is tied to its neighbours by springs :math:`k_c`, to the
fixed frame by a spring :math:`k_p` (the leaf springs to the driver plate of the earthquake
model, seen from the plate), and rubs on a belt moving at :math:`V`:

.. math::

    m \ddot x_i = k_c (x_{i+1} - 2 x_i + x_{i-1}) - k_p x_i - F_i(v_i - V),\qquad
    F_i(w) = \operatorname{sign}(w)\Bigl(F_{d,i} + \frac{F_{s,i} - F_{d,i}}{1 + \delta |w|}\Bigr),

with free ends (block 1 and block ``n`` have one neighbour each). For ``n = 1`` it is the zoo's
``stick-slip-oscillator`` with a dynamic friction floor ``Fd``; for ``n = 2`` the zoo's
``two-block-belt`` with equal blocks. Each ``sign()`` is a Filippov switch on :math:`v_i = V`:
a block sticks to the belt while the spring force on it stays within its static friction,
contact by contact, several at once on the intersection of their surfaces.

The loader splits a mode written with ``sign()`` into one variant per combination of sides,
:math:`2^n` for ``n`` contacts, and records them as one sign family
(:class:`~pwsdyn.model.elements.SignFamily`): the generated code is one field of the sides,
decoded from the variant's index (3.3, 6.9, 11.3, 16.5 thousand characters for 1 to 4
blocks; before, one body per variant: 3.4, 10.3, 28.2, 77.2). While several contacts stick
the kernel solves their stick forces from that field (the sides of the stuck contacts by
Newton's method) instead of summing the :math:`2^k` corner fields. The loader evaluates
each component of the field once per side of the contacts it depends on (two values for a
block's friction force, not :math:`2^n`), so loading and hashing the chain costs little.
What bounds the chain is that the variants are still listed one by one (names, switches,
tables of the kernel): at most ``MAX_FAMILY_MODES`` (1024, one per side of each of the ten
surfaces a mode may have) of them (:mod:`pwsdyn.model.discontinuities`), and the kernel slides
on intersections of at most ``MULTI_MAX`` (10) surfaces, so chains of up to ``MAX_BLOCKS`` = 10
blocks, all ten able to stick at once. Compile times and the cost per contact are measured in
``benchmarks/bench_contacts.py``. Chains of 20 blocks need the variants as indices only (a
mode as a sign vector, never listed; switches as bit flips), which is not done.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..errors import ArgumentError
from .discontinuities import MAX_FAMILY_MODES
from .spec import Model, load_model

#: Most blocks :func:`pwsdyn.burridge_knopoff` builds: the ``2**n`` variants of its field are
#: listed one by one (at most ``MAX_FAMILY_MODES`` = 1024) and every contact may stick at once
#: (the kernel slides on intersections of up to ``MULTI_MAX`` = 10 surfaces).
MAX_BLOCKS = 10


def _per_block(name: str, value, n: int) -> list[float]:
    """``value`` for each of the ``n`` blocks: a number for all, or a sequence of ``n``."""
    if isinstance(value, Sequence) and not isinstance(value, str):
        values = list(value)
        if len(values) != n:
            raise ArgumentError(f"burridge_knopoff: {name} has {len(values)} values for "
                                f"{n} blocks")
    else:
        values = [value] * n
    try:
        out = [float(v) for v in values]
    except (TypeError, ValueError):
        raise ArgumentError(f"burridge_knopoff: {name} must be a number or a sequence of "
                            f"numbers, not {value!r}") from None
    if not all(math.isfinite(v) for v in out):
        raise ArgumentError(f"burridge_knopoff: {name} must be finite, not {value!r}")
    return out


def burridge_knopoff(n: int, *, m: float = 1.0, kc: float = 1.0, kp: float = 1.0,
                     V: float = 0.2, Fs: float | Sequence[float] | None = None,
                     Fd: float | Sequence[float] | None = None, delta: float = 3.0,
                     t_end: float = 100.0) -> Model:
    r"""A Burridge-Knopoff chain of ``n`` blocks, each with its own friction contact.

    Parameters
    ----------
    n : int
        Number of blocks, 1 to ``MAX_BLOCKS`` (10: the :math:`2^n` variants of the ``sign()``
        terms are listed one by one, and the kernel slides on at most ten surfaces at once;
        see the module's notes).
    m, kc, kp : float
        Mass of each block, stiffness of the springs between neighbours and of each block's
        spring to the frame.
    V : float
        Velocity of the belt (the driver plate).
    Fs, Fd : float or sequence of float, optional
        Static and dynamic friction of each block (one number for all, or ``n``). Default:
        ``Fs = 1, 1.1, 1.2, ...`` (distinct, so that the blocks do not move in step) and
        ``Fd = Fs / 2``.
    delta : float
        Velocity-weakening coefficient: the friction falls from ``Fs`` at zero slip towards
        ``Fd`` as :math:`1/(1 + \delta |v_i - V|)`; ``delta = 0`` is Coulomb friction ``Fs``.
    t_end : float
        The model's default end time.

    Returns
    -------
    Model
        Named ``burridge-knopoff-<n>``, states ``x1, v1, ..., xn, vn``, parameters ``m, kc,
        kp, V, delta`` and ``Fs1, Fd1, ..., Fsn, Fdn`` (every value can be overridden per run
        with ``params=``), one mode written with ``sign()`` (split into :math:`2^n` variants by
        the loader), the default start with every block at rest (slipping backwards on the
        belt), and units and descriptions of every quantity (nondimensional).

    Raises
    ------
    ArgumentError
        ``n`` not an integer from 1 to ``MAX_BLOCKS``, or a per-block value of the wrong
        length.
    """
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_BLOCKS:
        raise ArgumentError(f"burridge_knopoff: n must be an integer from 1 to {MAX_BLOCKS} "
                            f"(the 2**n variants of more blocks exceed the limit of "
                            f"{MAX_FAMILY_MODES} modes), not {n!r}")
    fs = _per_block("Fs", [1.0 + 0.1 * i for i in range(n)] if Fs is None else Fs, n)
    fd = _per_block("Fd", [f / 2 for f in fs] if Fd is None else Fd, n)
    params: dict[str, float] = {"m": float(m), "kc": float(kc), "kp": float(kp),
                                "V": float(V), "delta": float(delta)}
    units = {"t": "1", **dict.fromkeys(params, "1")}
    descriptions = {"t": "time (nondimensional)", "m": "mass of each block",
                    "kc": "stiffness of the springs between neighbouring blocks",
                    "kp": "stiffness of each block's spring to the driver plate",
                    "V": "velocity of the belt (the driver plate)",
                    "delta": "velocity-weakening coefficient of the friction law"}
    mode: dict[str, str] = {}
    states: list[str] = []
    definitions: dict[str, str] = {}
    for i in range(1, n + 1):
        params[f"Fs{i}"], params[f"Fd{i}"] = fs[i - 1], fd[i - 1]
        x, v, w = f"x{i}", f"v{i}", f"w{i}"
        states += [x, v]
        definitions[w] = f"{v} - V"
        # free ends: the chain's end blocks have a single coupling spring
        coupling = " + ".join(f"kc*(x{j} - {x})" for j in (i - 1, i + 1) if 1 <= j <= n)
        spring = f"-kp*{x}" + (f" + {coupling}" if coupling else "")
        mode[x] = v
        mode[v] = (f"({spring} - sign({w})*(Fd{i} + (Fs{i} - Fd{i})/(1 + delta*abs({w}))))/m")
        units.update({x: "1", v: "1", f"Fs{i}": "1", f"Fd{i}": "1"})
        descriptions.update({x: f"position of block {i}", v: f"velocity of block {i}",
                             f"Fs{i}": f"static friction force on block {i}",
                             f"Fd{i}": f"dynamic friction force on block {i} (approached at "
                                       "high slip speed)"})
    data = {
        "name": f"burridge-knopoff-{n}",
        "description": (f"Burridge-Knopoff chain of {n} block{'s' if n > 1 else ''} on a belt "
                        "moving at V: m x_i'' = kc (x_(i+1) - 2 x_i + x_(i-1)) - kp x_i - "
                        "F_i(v_i - V), F_i(w) = sign(w) (Fd_i + (Fs_i - Fd_i)/(1 + delta |w|)), "
                        "free ends; each block sticks to the belt while the spring force on it "
                        "stays within its static friction."),
        "source": ("R. Burridge and L. Knopoff, Model and theoretical seismicity, Bull. Seismol. "
                   "Soc. Am. 57(3) (1967) 341-371; velocity-weakening friction: J. M. Carlson "
                   "and J. S. Langer, Mechanical model of an earthquake fault, Phys. Rev. A 40 "
                   "(1989) 6470; built by pwsdyn.burridge_knopoff"),
        "states": states,
        "parameters": params,
        "definitions": definitions,
        "modes": {"chain": mode},
        "defaults": {"x0": {s: 0.0 for s in states}, "t_end": float(t_end)},
        "units": units,
        "descriptions": descriptions,
    }
    return load_model(data)
