r"""The friction impact oscillator of thesis Papers D and E: the grazing of its stick set, the
one-dimensional stick-position map, and the low-cost control law 5.3 with its robustness.

The model is the zoo's ``friction-impact-oscillator`` (thesis eq. 3.3-3.5, 5.4): a mass on a
spring, :math:`m q'' + k q = F` with dry friction :math:`F`, forced only by impacts with a
constraint at :math:`q = -b + a \sin(\omega t)` (restitution :math:`e` on the relative
velocity). Papers D and E take one friction level :math:`F_f` (``Fs = Fd``); section 5.3.1 of
the thesis a static level :math:`F_s` above the dynamic one :math:`F_d`. Everything here is
written in the thesis's scaled variables

.. math::

    x = \frac{k q}{F_d}, \quad \tau = \sqrt{k/m}\, t, \quad \tilde a = \frac{k a}{F_d}, \quad
    \tilde b = \frac{k b}{F_d}, \quad \Omega = \omega \sqrt{m/k},

in which slipping up is :math:`x'' + x = -1` (ellipses about -1 in the plane
:math:`(x, dx/d\tau)`), slipping down :math:`x'' + x = +1` (ellipses about +1), and the mass
sticks where :math:`|x| \le F_s/F_d`.

Grazing (thesis Fig. 5.1). A resting mass at :math:`x` is reached by the constraint only where
:math:`x < \tilde a - \tilde b`: at :math:`\tilde a^* = \tilde b + 1` (:math:`a^* = b + F_d/k`)
the top of the constraint touches the edge :math:`x = 1` of the stick set and the stick
solutions at the edge start to be hit. With :math:`F_s > F_d` stick solutions remain up to
:math:`a^{**} = b + F_s/k` (section 5.3.1).

The stick-position map (Paper E; thesis Fig. 5.2). Let the mass rest at :math:`x` and the
constraint reach it on its rising branch, at :math:`\tilde a \sin\theta = x + \tilde b`. After
the impact (3.5) it moves up with the velocity :math:`v_+ = (1 + e) \tilde a \Omega \cos\theta`,
so that, exactly,

.. math::
    :label: fi-impact-velocity

    v_+^2 = (1 + e)^2 \Omega^2 \left(\tilde a^2 - (x + \tilde b)^2\right).

It slips up on the ellipse about -1 to :math:`x_{max}`,
:math:`(x_{max} + 1)^2 = (x + 1)^2 + v_+^2`, stops there if :math:`x_{max} \le F_s/F_d`, and
otherwise reverses and slips down on the ellipse about +1 to :math:`x' = 2 - x_{max}`, where it
comes to rest (for :math:`x_{max}` near 1). As long as the constraint does not touch the mass
again during this excursion and has fallen away before the mass is at rest (the thesis's
restriction to driving frequencies below twice the natural one: the down-slip takes half a
natural period), the map from one stick position to the next, :math:`P^2` of the thesis (two
crossings of :math:`S = \{dx/d\tau = 0\}`), is therefore in closed form:

.. math::
    :label: fi-stick-map

    x' = 3 - \sqrt{(x + 1)^2 + (1 + e)^2 \Omega^2 \left(\tilde a^2 - (x + \tilde b)^2\right)}.

To lowest order about the graze (:math:`x = 1 - \xi`, :math:`\tilde a = \tilde a^* + \Delta`,
:math:`\xi, \Delta` small),
:math:`v_+^2 = (1 + e)^2 \Omega^2 (\Delta + \xi)(2 \tilde a^* + \Delta - \xi)` and
:math:`x_{max} - 1 = -\xi + v_+^2 / 4 + O(2)`, so

.. math::
    :label: fi-linear-map

    x' - 1 &= (\gamma - 1)(x - 1) - \gamma (\tilde a - \tilde a^*)
              + O\left(|x - 1| + |\tilde a - \tilde a^*|\right)^2, \\
    \gamma &= \frac{(1 + e)^2 \Omega^2 \tilde a^*}{2}
            = \frac{m a^* \omega^2 (1 + e)^2}{2 F_f} \qquad \text{(thesis 5.1).}

The multiplier is :math:`\gamma - 1`: the grazing stick solution is stable, and a branch of
impacting period-one orbits with the stick position
:math:`x^* = 1 - \gamma (\tilde a - \tilde a^*) / (2 - \gamma)` grows from it for
:math:`a > a^*` (persistence), iff :math:`\gamma < 2` (condition 5.1). For :math:`\gamma > 2`
the impacting branch is unstable and lies on the other side, :math:`a < a^*` (loss of the local
attractor). The error of :eq:`fi-linear-map` is of second order: its fixed point is off that of
:eq:`fi-stick-map` by :math:`O(\tilde a - \tilde a^*)^2`. Two caveats the closed form checks
(:meth:`~pwsdyn.grazing.FrictionImpact.stick_map` with ``exact=True`` raises where they
fail): for :math:`\gamma < 1` the mass does not clear the top of the constraint
(:math:`x_{max} - 1 - (\tilde a - \tilde b - 1) = (\gamma - 1)(\xi + \Delta)` to lowest order)
and is hit again during the excursion, so :eq:`fi-stick-map` and :eq:`fi-linear-map` apply for
:math:`1 < \gamma` only; and the down-slip must end before the constraint comes back.

Control (thesis eq. 5.3, 5.5, 5.11). The constraint's neutral position is reset where the mass
comes to rest, from the stick position :math:`x` and the amplitude:

.. math::

    \tilde b = \tilde a^* - 1
        + (1 - c_a)\left((1 + \varepsilon_1)(\tilde a - \tilde a^*) + \delta_1\right)
        + \left(1 - \frac{2 c_x}{\gamma}\right)\left((1 + \varepsilon_2)(1 - x) + \delta_2\right),

with :math:`\varepsilon_1, \varepsilon_2` multiplicative (5.5) and :math:`\delta_1, \delta_2`
additive (5.11) measurement errors (all 0: law 5.3; :math:`c_a = 1, c_x = \gamma / 2`: no
control). With it the top of the constraint is at :math:`\tilde a - \tilde b - 1` above the
edge, and :eq:`fi-linear-map` becomes (thesis 5.6 and 5.12)

.. math::
    :label: fi-controlled-map

    x' - 1 &= \mu (x - 1)
              - \gamma \left(c_a + (c_a - 1) \varepsilon_1\right)(\tilde a - \tilde a^*)
              - \gamma (c_a - 1) \delta_1 + (\gamma - 2 c_x) \delta_2, \\
    \mu &= 2 c_x - 1 + (2 c_x - \gamma) \varepsilon_2,

stable iff :math:`|\mu| < 1` (5.7); at :math:`c_x = 1/2` iff
:math:`|\varepsilon_2| < 1 / |1 - \gamma|` (5.8). The law acts at the crossings of :math:`S`
that start a stick (events ``stop_neg``, ``stop_pos``): the :math:`x` of the map. The crossing
in between, where the mass reverses at :math:`x_{max}`, would give a value overwritten at the
stop before the next impact, and would move the constraint while its top is within
:math:`O(a - a^*)` of the mass.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError

#: The zoo model this module describes.
MODEL = "friction-impact-oscillator"

#: The events at which the control law acts, the crossings of ``S = {v = 0}`` that start a
#: stick (the ``x`` of the thesis's map ``P^2``).
CONTROL_EVENTS = ("stop_neg", "stop_pos")

#: Parameters of :func:`~pwsdyn.grazing.controlled_model`'s law, with their values for no errors.
LAW_PARAMETERS = ("c_x", "c_a", "a_star", "eps_1", "eps_2", "delta_1", "delta_2")

_NAMES = ("m", "k", "Fs", "Fd", "a", "b", "omega", "e")


def _finite(what: str, compute):
    """``compute()``, refused with an :class:`~pwsdyn.ArgumentError` where it overflows or is
    not a finite number (parameters or gains too large for the formulas of the thesis to
    be evaluated in floating point)."""
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            value = compute()
    except (OverflowError, ZeroDivisionError, FloatingPointError, ValueError) as exc:
        raise ArgumentError(f"{what} cannot be evaluated at these parameters and gains "
                            f"({exc})") from None
    vals = np.atleast_1d(np.asarray(value, dtype=float))
    if not np.all(np.isfinite(vals)):
        raise ArgumentError(f"{what} is not a finite number at these parameters and gains "
                            f"(they overflow the formulas): got {value}")
    return value


@dataclass(frozen=True)
class ControlGains:
    """Gains and measurement errors of the control law (thesis eq. 5.3, 5.5, 5.11).

    Attributes
    ----------
    c_x, c_a : float
        Control parameters of eq. 5.3 (``0 < c_x < 1``, ``c_a > 0`` in the thesis).
    eps_1, eps_2 : float
        Multiplicative errors on the measured ``a~ - a~*`` and ``1 - x`` (eq. 5.5).
    delta_1, delta_2 : float
        Additive errors on them (eq. 5.11), in the scaled units ``k q / Fd``.
    """

    c_x: float
    c_a: float
    eps_1: float = 0.0
    eps_2: float = 0.0
    delta_1: float = 0.0
    delta_2: float = 0.0

    def __post_init__(self):
        for name in ("c_x", "c_a", "eps_1", "eps_2", "delta_1", "delta_2"):
            object.__setattr__(self, name, V.number(name, getattr(self, name)))


@dataclass(frozen=True)
class FrictionImpact:
    """The thesis's quantities of the friction impact oscillator at one set of parameters.

    Build it with :meth:`from_params` (the zoo model's values with yours over them). Lengths
    are the model's (``q``); ``x`` arguments and results of the maps are scaled, ``k q / Fd``.

    Attributes
    ----------
    m, k, Fs, Fd, a, b, omega, e : float
        The model's parameters.
    a_ref : float
        The grazing amplitude the control law refers to (its ``a*``; default the uncontrolled
        one, ``b + Fd/k``).
    """

    m: float
    k: float
    Fs: float
    Fd: float
    a: float
    b: float
    omega: float
    e: float
    a_ref: float

    @classmethod
    def from_params(cls, params: Mapping[str, float] | None = None, *,
                    a_ref: float | None = None) -> FrictionImpact:
        """The zoo model's parameters with ``params`` over them.

        Parameters
        ----------
        params : dict, optional
            Values of ``m, k, Fs, Fd, a, b, omega, e`` (others are refused).
        a_ref : float, optional
            The control law's grazing amplitude ``a*`` (default ``b + Fd/k``).
        """
        from ..model import load_model

        given = V.mapping("params", params)
        extra = sorted(set(given) - set(_NAMES))
        if extra:
            raise ArgumentError(f"unknown parameter(s) {extra} of {MODEL!r}; its parameters: "
                                f"{list(_NAMES)}")
        p = dict(load_model(MODEL).parameters)
        p.update(given)
        vals = {n: V.number(f"params[{n!r}]", p[n]) for n in _NAMES}
        for n in ("m", "k", "Fd", "omega"):
            V.positive(f"params[{n!r}]", vals[n])
        V.number("params['e']", vals["e"], lo=0.0, hi=1.0)
        if vals["Fs"] < vals["Fd"]:
            raise ArgumentError(f"static friction Fs = {vals['Fs']:g} must be at least the "
                                f"dynamic one Fd = {vals['Fd']:g} (thesis eq. 5.4)")
        ref = vals["b"] + vals["Fd"] / vals["k"] if a_ref is None else V.number("a_ref", a_ref)
        obj = cls(a_ref=ref, **vals)
        for name in ("scale", "Omega", "sigma", "a_star", "a_star_star", "gamma", "a_scaled"):
            _finite(name, lambda: getattr(obj, name))
        return obj

    # -- scaling ------------------------------------------------------------------------
    @property
    def scale(self) -> float:
        """``Fd / k``: the length of one unit of the scaled position ``x``."""
        return self.Fd / self.k

    @property
    def Omega(self) -> float:
        """The driving frequency over the natural one, ``omega sqrt(m / k)``."""
        return self.omega * math.sqrt(self.m / self.k)

    @property
    def sigma(self) -> float:
        """``Fs / Fd``: the edge of the stick set in ``x`` (1 where ``Fs = Fd``)."""
        return self.Fs / self.Fd

    # -- thesis quantities --------------------------------------------------------------
    @property
    def a_star(self) -> float:
        """The grazing amplitude ``a* = b + Fd/k`` (thesis Fig. 5.1, section 5.3.1)."""
        return self.b + self.Fd / self.k

    @property
    def a_star_star(self) -> float:
        """``a** = b + Fs/k`` (section 5.3.1): the amplitude up to which stick solutions exist
        when ``Fs > Fd``."""
        return self.b + self.Fs / self.k

    @property
    def gamma(self) -> float:
        """``gamma = m a* omega^2 (1 + e)^2 / (2 F_f)`` (eq. 5.1 and 5.3), at the law's ``a*``
        (:attr:`a_ref`)."""
        return self.m * self.a_ref * self.omega**2 * (1 + self.e)**2 / (2 * self.Fd)

    @property
    def persistent(self) -> bool:
        """Condition 5.1, ``gamma < 2``: a local attractor persists through the graze."""
        return self.gamma < 2.0

    def scaled(self, q: float) -> float:
        """``x = k q / Fd``."""
        return q / self.scale

    # -- control -------------------------------------------------------------------------
    def law_b(self, x: float, gains: ControlGains | None) -> float:
        """The constraint position ``b`` (model units) the law sets at the stick position
        ``x`` (scaled); ``gains=None``: the uncontrolled ``b``."""
        if gains is None:
            return self.b
        g = gains
        d = self.k * (self.a - self.a_ref) / self.Fd

        def b():
            bt = (self.k * self.a_ref / self.Fd - 1
                  + (1 - g.c_a) * ((1 + g.eps_1) * d + g.delta_1)
                  + (1 - 2 * g.c_x / self.gamma) * ((1 + g.eps_2) * (1 - x) + g.delta_2))
            return bt * self.scale

        return _finite("the law's constraint position b", b)

    # -- the stick-position map ----------------------------------------------------------
    def stick_map(self, x, *, exact: bool = False, gains: ControlGains | None = None):
        """One step of the stick-position map ``P^2``: the next stick position.

        Parameters
        ----------
        x : float or array
            Scaled stick position ``k q / Fd``.
        exact : bool
            ``False``: the lowest-order linear map (3) / (4) of the module docstring (thesis
            eq. 5.6, 5.12). ``True``: the closed form (2) from the analytic solution, with
            the assumptions behind it checked (:meth:`excursion`).
        gains : ControlGains, optional
            With the control law (5.3 / 5.5 / 5.11) resetting ``b`` at ``x``.
        """
        if not exact:
            mu, c = self.linear_map(gains)
            return _finite("the stick map", lambda: 1 + mu * (np.asarray(x, float) - 1) + c)
        xs = np.atleast_1d(np.asarray(x, float))
        out = np.array([self.excursion(xi, gains)["x_next"] for xi in xs])
        return out if np.ndim(x) else float(out[0])

    def linear_map(self, gains: ControlGains | None = None) -> tuple[float, float]:
        """``(mu, c)`` of the lowest-order map ``x' - 1 = mu (x - 1) + c``: eq. (3) without
        control, (4) (thesis 5.6 with 5.12) with it."""
        gam = self.gamma
        d = self.k * (self.a - self.a_ref) / self.Fd
        if gains is None:
            # uncontrolled: the law with c_a = 1, c_x = gamma / 2 leaves b alone -- but the
            # uncontrolled map is about its own a*, not the law's reference
            d0 = self.k * (self.a - self.a_star) / self.Fd
            g0 = self.m * self.a_star * self.omega**2 * (1 + self.e)**2 / (2 * self.Fd)
            return g0 - 1, -g0 * d0
        g = gains
        return _finite("the linear map (mu, c)", lambda: (
            2 * g.c_x - 1 + (2 * g.c_x - gam) * g.eps_2,
            (-gam * (g.c_a + (g.c_a - 1) * g.eps_1) * d - gam * (g.c_a - 1) * g.delta_1
             + (gam - 2 * g.c_x) * g.delta_2)))

    def fixed_point(self, *, exact: bool = False,
                    gains: ControlGains | None = None) -> tuple[float, float]:
        """The period-one stick position ``x*`` (scaled) and its multiplier.

        ``exact=False``: of the lowest-order map, ``x* = 1 + c / (1 - mu)``, multiplier
        ``mu`` (``gamma - 1`` without control, eq. 5.7's ``2 c_x - 1 + (2 c_x - gamma) eps_2``
        with it). ``exact=True``: of the closed form (2), whose fixed points solve a quadratic
        (below), the root nearest the edge of the stick set; the multiplier is the derivative
        of (2) there. Raises :class:`~pwsdyn.ArgumentError` where there is none (no impacting orbit
        near the graze: the loss side, ``gamma > 2`` and ``a > a*``, for the linear map).
        """
        mu, c = self.linear_map(gains)
        if not exact:
            if mu == 1.0:
                raise ArgumentError("the lowest-order map has multiplier 1: no isolated fixed "
                                    "point")
            xs = _finite("the fixed point", lambda: 1 + c / (1 - mu))
            if xs > self.sigma or self.a_scaled - self._bt(xs, gains) <= xs:
                raise ArgumentError(f"the lowest-order map's fixed point x = {xs:.6g} is not "
                                    f"an impacting stick position (a = {self.a:g})")
            return xs, mu
        # x = 3 - sqrt((x+1)^2 + K (a~^2 - (x + b~(x))^2)), K = (1+e)^2 Omega^2, with the
        # reversal (x_max > 1) and b~(x) = B0 + B1 x affine in x (the law), squares to
        # (3 - x)^2 = (x + 1)^2 + K (a~^2 - ((1 + B1) x + B0)^2):
        #   K (1 + B1)^2 x^2 + (2 K (1 + B1) B0 - 8) x + K B0^2 + 8 - K a~^2 = 0.
        K = _finite("(1 + e)^2 Omega^2", lambda: (1 + self.e)**2 * self.Omega**2)
        B0 = self._bt(0.0, gains)
        B1 = _finite("the law's slope", lambda: self._bt(1.0, gains) - B0)
        coef = _finite("the fixed-point quadratic", lambda: np.array(
            [K * (1 + B1)**2, 2 * K * (1 + B1) * B0 - 8, K * B0**2 + 8 - K * self.a_scaled**2]))
        roots = np.roots(coef)
        roots = np.sort_complex(roots)
        real = [r.real for r in roots if abs(r.imag) < 1e-12 and r.real < 1.0]
        if not real:
            raise ArgumentError(f"the closed-form map has no fixed point below the edge of the "
                                f"stick set at a = {self.a:g}")
        xs = max(real)
        ex = self.excursion(xs, gains)
        if not ex["reversed"]:
            raise ArgumentError(f"the closed-form fixed point x = {xs:.6g} does not reverse "
                                f"(x_max = {ex['x_max']:.6g} <= Fs/Fd): not an orbit of (2)")
        xm = ex["x_max"]
        # d x'/dx = -((x + 1) - K (x + b~)(1 + B1)) / (x_max + 1), from (2)
        mult = -((xs + 1) - K * (xs + self._bt(xs, gains)) * (1 + B1)) / (xm + 1)
        return xs, mult

    @property
    def a_scaled(self) -> float:
        """``a~ = k a / Fd``."""
        return self.k * self.a / self.Fd

    def _bt(self, x: float, gains) -> float:
        return self.law_b(x, gains) / self.scale

    def excursion(self, x: float, gains: ControlGains | None = None, *,
                  samples: int = 2000) -> dict:
        """The motion from rest at ``x`` (scaled) to the next rest, from the analytic solution:
        the impact, the slips and the stop (module docstring, eq. (1)-(2)).

        Returns a dict with ``theta`` (the impact phase ``omega t`` mod 2 pi), ``v_plus`` (the
        scaled velocity after the impact, per unit ``tau``), ``x_max``, ``x_next`` (the next
        stick position), ``duration`` (of the excursion, in ``tau``) and ``reversed``
        (the mass reversed at ``x_max``). A mass the constraint does not reach (``x >= a~ -
        b~``) stays: ``x_next = x``.

        Raises :class:`~pwsdyn.ArgumentError` where the closed form is not the model's motion: the
        constraint touches the mass again before it is at rest (the gap is sampled at
        ``samples`` points per slip), or the mass leaves the neighbourhood of the stick set
        (it reverses twice).
        """
        x = V.number("x", x)
        s = self.sigma
        if abs(x) > s:
            raise ArgumentError(f"x = {x:g} is not in the stick set |x| <= Fs/Fd = {s:g}")
        bt, at, Om, e = self._bt(x, gains), self.a_scaled, self.Omega, self.e
        if x + bt >= at:
            return {"theta": math.nan, "v_plus": 0.0, "x_max": x, "x_next": x,
                    "duration": 0.0, "reversed": False}
        if not x + bt > -at:
            raise ArgumentError(f"at x = {x:g} the constraint (b~ = {bt:.6g}, a~ = {at:.6g}) "
                                f"never leaves the mass: the closed-form map does not apply")
        theta = math.asin((x + bt) / at)          # rising branch: cos(theta) > 0
        vp = _finite("the impact velocity",        # eq. 3.5 with the mass at rest
                     lambda: (1 + e) * at * Om * math.cos(theta))
        R = _finite("the slip amplitude", lambda: math.hypot(x + 1, vp))  # ellipse about -1
        xm = R - 1
        phi0 = math.atan2(vp, x + 1)              # its angle: x + 1 = R cos(phi0 - tau)
        ts_up = np.linspace(0.0, phi0, samples + 1)[1:]
        q_up = -1 + R * np.cos(phi0 - ts_up)
        if xm <= s:
            t_end, x_next, rev = phi0, xm, False
            ts, qs = ts_up, q_up
        else:
            x_next = 2 - xm                       # the down-slip ellipse about +1
            if x_next < -s:
                raise ArgumentError(f"from x = {x:g} the mass reverses twice (x_max = {xm:g}):"
                                    f" far from the stick set, outside the map")
            ts_dn = np.linspace(0.0, math.pi, samples + 1)[1:]
            ts = np.concatenate([ts_up, phi0 + ts_dn])
            qs = np.concatenate([q_up, 1 + (xm - 1) * np.cos(ts_dn)])
            t_end, rev = phi0 + math.pi, True
        # the constraint over the excursion, in tau from the impact (b~ held: the law acts at
        # the stop only)
        c = -bt + at * np.sin(theta + Om * ts)
        gap = qs - c
        # the gap must stay open up to and including the stop; the mass then rests at
        # x_next until the constraint rises to it again: the next step of the map
        if np.min(gap) <= 0.0:
            i = int(np.argmin(gap))
            raise ArgumentError(f"from x = {x:g} the constraint touches the mass again at tau "
                                f"= {ts[i]:.6g} after the impact, before it comes to rest: the "
                                f"closed-form map does not apply (gamma = {self.gamma:.4g}, "
                                f"Omega = {Om:.4g}; near the graze it needs gamma > 1)")
        return {"theta": theta, "v_plus": vp, "x_max": xm, "x_next": x_next,
                "duration": t_end, "reversed": rev}

    # -- thesis 5.8-5.13 -----------------------------------------------------------------
    def eps2_bound(self) -> float:
        """The largest ``|eps_2|`` keeping the controlled fixed point stable at ``c_x = 1/2``,
        ``1 / |1 - gamma|`` (eq. 5.8; from 5.7)."""
        return math.inf if self.gamma == 1.0 else 1 / abs(1 - self.gamma)

    def residual_error(self, gains: ControlGains, *, first_order: bool = True) -> float:
        """``|1 - gamma c_a (a~ - a~*) - x*|``: the controlled stick position's offset from the
        one without measurement errors, at ``c_x = 1/2``.

        ``first_order=True``: the thesis's expressions, eq. 5.10 (multiplicative errors, first
        order in them) plus eq. 5.13 (additive errors). ``False``: from the fixed point of the
        lowest-order map (4), exact in the errors.
        """
        if gains.c_x != 0.5:
            raise ArgumentError(f"eq. 5.9-5.13 are for c_x = 1/2, got {gains.c_x:g}")
        gam = self.gamma
        d = self.k * (self.a - self.a_ref) / self.Fd
        if not first_order:
            xs, _ = self.fixed_point(gains=gains)
            return _finite("the residual error", lambda: abs(1 - gam * gains.c_a * d - xs))
        g = gains

        def first():
            mult = gam * (g.c_a + (g.c_a - 1) * g.eps_1 + g.c_a * (1 - gam) * g.eps_2) * d
            add = gam * (g.c_a - 1) * g.delta_1 + (1 - gam) * g.delta_2
            # 5.9 and 5.12 at c_x = 1/2: x* - 1 = -mult - add (to first order in the errors)
            return abs(mult - gam * g.c_a * d + add)

        return _finite("the residual error", first)

    # -- models --------------------------------------------------------------------------
    def params(self) -> dict:
        """The model's parameters (for :func:`pwsdyn.simulate` and the rest)."""
        return {n: getattr(self, n) for n in _NAMES}

    def law_params(self, gains: ControlGains) -> dict:
        """The values of the parameters of :func:`~pwsdyn.grazing.controlled_model`'s law."""
        return {"c_x": gains.c_x, "c_a": gains.c_a, "a_star": self.a_ref,
                "eps_1": gains.eps_1, "eps_2": gains.eps_2, "delta_1": gains.delta_1,
                "delta_2": gains.delta_2}


#: The law 5.3 / 5.5 / 5.11 in the model's units (b = (Fd/k) b~, x = k q / Fd), with gamma
#: of eq. 5.1 at the law's a* (the parameter a_star).
LAW = ("a_star - Fd/k + (1 - c_a)*((1 + eps_1)*(a - a_star) + delta_1*Fd/k)"
       " + (1 - 2*c_x/(m*a_star*omega**2*(1 + e)**2/(2*Fd)))"
       "*((1 + eps_2)*(Fd/k - q) + delta_2*Fd/k)")


def controlled_model(model=MODEL, *, gains: ControlGains | None = None,
                     a_star: float | None = None):
    """The friction impact oscillator with the constraint's neutral position ``b`` updated by
    the law 5.3 (with the errors of 5.5 and 5.11) each time the mass comes to rest.

    ``b`` becomes a state (:func:`pwsdyn.with_discrete_control` with
    ``section="event:stop_neg,stop_pos"``); the law's parameters
    :data:`~pwsdyn.grazing.friction_impact.LAW_PARAMETERS` (``c_x``, ``c_a``, ``a_star``,
    ``eps_1``, ``eps_2``, ``delta_1``, ``delta_2``) are parameters of the model, so they can be
    swept and continued.

    Parameters
    ----------
    model : Model, str, path or dict
        The friction impact oscillator (default the zoo's).
    gains : ControlGains, optional
        Default values of the law's parameters (default ``c_x = 1/2, c_a = 1``, no errors).
    a_star : float, optional
        Default of the law's reference amplitude (default ``b + Fd/k`` at the model's ``b``).
    """
    from ..model import with_discrete_control
    from ..model.spec import as_model

    base = as_model(model, kind="flow", caller="controlled_model()")
    p = base.parameters
    missing = [n for n in _NAMES if n not in p]
    if missing:
        raise ArgumentError(f"model {base.name!r} is not the friction impact oscillator: it "
                            f"lacks the parameter(s) {missing}")
    ref = p["b"] + p["Fd"] / p["k"] if a_star is None else V.number("a_star", a_star)
    g = ControlGains(0.5, 1.0) if gains is None else gains
    values = {"c_x": g.c_x, "c_a": g.c_a, "a_star": ref, "eps_1": g.eps_1, "eps_2": g.eps_2,
              "delta_1": g.delta_1, "delta_2": g.delta_2}
    return with_discrete_control(base, "b", section="event:" + ",".join(CONTROL_EVENTS),
                                 law=LAW, law_params=values,
                                 name=f"{base.name}+law5.3")
