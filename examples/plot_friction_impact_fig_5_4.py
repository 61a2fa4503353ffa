r"""
Static friction above dynamic friction: stick solutions up to a∗∗ (thesis Fig. 5.4)
===================================================================================

The friction impact oscillator (zoo model ``friction-impact-oscillator``) with the friction law
5.4 of the thesis: a resting mass sticks while the spring force is at most the static friction
:math:`F_s`, larger than the dynamic friction :math:`F_d` (here :math:`F_s = 1.2 F_d`). Stick
solutions then exist up to :math:`a^{\ast\ast} = b + F_s/k`, beyond the grazing amplitude
:math:`a^\ast = b + F_d/k` of Papers D and E (thesis section 5.3.1). The figure shows, against
the amplitude :math:`a`, the velocity of the mass just after the impact (0 at rest): the branch
of period-one impacting orbits that reverse above :math:`F_s/k` and come to rest below
:math:`F_d/k` (the thesis's :math:`\Phi_2` type), continued by pseudo-arclength (stable solid,
unstable dashed; dotted where it is not an orbit of the model because its reversal point has
fallen into the static stick set, where the mass would stay), the stick solutions (green),
and the points of brute-force sweeps up (blue) and down (orange).

(a) :math:`\gamma > 2` (the opposite of inequality 5.1): as in Fig. 2.3 (a) a saddle-node (LP)
ends the upper branch, but the unstable branch does not exist for an interval of :math:`a` near
:math:`a^*`, and the stick solutions last up to :math:`a^{**}`. (b) :math:`\gamma < 2` (5.1
holds): the stick solutions again last up to :math:`a^{**}`, and the stable impacting branch
has lost the interval where its reversal point lies below :math:`F_s/k`. As the thesis notes,
with :math:`F_s > F_d` the scenario shows a jump and hysteresis even when 5.1 is satisfied, over
a smaller interval than without it.
"""

import math

import matplotlib.pyplot as plt
import numpy as np

import pwsdyn
from pwsdyn.grazing import FrictionImpact

MODEL = "friction-impact-oscillator"
E, B, FS = 0.8, 1.0, 1.2


def omega_for(gamma):
    """The driving frequency giving ``gamma`` (eq. 5.1 with m = k = Fd = 1, a* = b + 1)."""
    return math.sqrt(2 * gamma / ((1 + E) ** 2 * (B + 1)))


def velocity_after_the_impact(orbit):
    """The velocity just after the orbit's impact (its largest over the period)."""
    return max(ev.x_after[1] for ev in orbit.events if ev.kind == "impact")


def sweep_points(ax, s, values):
    """Brute-force sweeps up and down: the velocity after each impact of the window."""
    p = s.params()
    p.pop("a")
    ds = pwsdyn.sweep(MODEL, "a", values, {"q": 1.0, "v": 0.0}, params=p, transient=60,
                      samples=8, section="impact_up", workers=1, progress=False,
                      chunk_size=len(values))
    a = ds["a"].values[:, None]
    for i, (d, c, m) in enumerate(zip(ds["direction"].values, ("C0", "C1"), ("^", "v"))):
        u = a * s.omega * np.cos(2 * np.pi * ds["phase"].values[i])
        v = (1 + E) * u - E * ds["section"].values[i, ..., 1]   # eq. 3.5
        v = np.where(ds["n_points"].values[i][:, None] > 0, v, 0.0)  # at rest: 0
        aa = np.broadcast_to(a, v.shape)
        ax.plot(aa.ravel(), v.ravel(), m, color=c, ms=3.5, alpha=0.7, ls="none",
                label=f"sweep {d}")


def panel(ax, gamma, a_lo, a_hi, title):
    s = FrictionImpact.from_params({"Fs": FS, "Fd": 1.0, "b": B, "e": E, "a": a_hi,
                                    "omega": omega_for(gamma)})
    # steps well below (a** - a)/(gamma - 1): each step's impact lifts the rest by about
    # (gamma - 1) times the step, which would knock it out of the stick set before a**
    sweep_points(ax, s, np.linspace(a_lo, a_hi, 161))
    ax.plot([a_lo, s.a_star_star], [0, 0], color="C2", lw=2.0,
            label="stick solutions")
    x_star, _ = s.fixed_point(exact=True)
    orbit = pwsdyn.find_periodic_orbit(MODEL, [x_star * s.scale, 0.0], t0=0.0,
                                       params=s.params(), mode="stick")
    branch = pwsdyn.continue_orbit(MODEL, orbit, "a", span=(a_lo, a_hi), ds=-0.005)
    branch.plot(y=velocity_after_the_impact, ax=ax)
    for val, name in ((s.a_star, "$a^*$"), (s.a_star_star, "$a^{**}$")):
        ax.axvline(val, color="0.6", lw=0.8)
        ax.annotate(name, (val, 1.0), xycoords=("data", "axes fraction"),
                    textcoords="offset points", xytext=(3, -12))
    ax.set_title(f"{title}: $\\gamma$ = {s.gamma:.2g}, $F_s$ = {FS:g} $F_d$")
    ax.set_xlabel("amplitude $a$")


fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
panel(axes[0], 2.5, 1.94, 2.3, "(a)")
panel(axes[1], 1.5, 1.96, 2.3, "(b)")
axes[0].set_ylabel("velocity after the impact")
axes[1].legend(loc="upper left")
plt.show()
