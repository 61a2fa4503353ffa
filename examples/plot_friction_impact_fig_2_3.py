r"""
Grazing of the stick set: loss and persistence (thesis Fig. 2.3)
================================================================

The friction impact oscillator of the thesis's Papers D and E (zoo model
``friction-impact-oscillator`` with equal static and dynamic friction, :math:`F_s = F_d`): a
mass on a spring with dry friction, forced only by impacts with a constraint at
:math:`q = -b + a \sin(\omega t)`. For :math:`a < a^* = b + F_d/k` the mass can rest at the
edge of the stick set, out of reach of the constraint; at :math:`a^*` the constraint's top
grazes that rest. The figure shows, against the amplitude :math:`a`, the velocity of the mass
just after the impact (its largest velocity over the orbit; 0 for the stick solutions): the
branch of period-one impacting orbits continued by pseudo-arclength (stable solid, unstable
dashed, past its graze dotted), the stick solutions (green), and over them the points of
brute-force sweeps up (blue) and down (orange) in :math:`a`.

Condition 5.1 of the thesis decides the scenario: with
:math:`\gamma = m a^* \omega^2 (1 + e)^2 / (2 F_f)`, the stick-position map has the multiplier
:math:`\gamma - 1`. (a) :math:`\gamma = 2.5 > 2`: loss of the local attractor. The unstable
impacting branch leaves the graze at the non-smooth fold NSF towards smaller :math:`a`, turns
at a saddle-node SN (labelled LP, a fold of the branch, at
:math:`a^2 = (8 K (b + 1) - 16)/K^2`, :math:`K = (1 + e)^2 \omega^2`, from the closed-form map)
and comes back as the stable upper branch: sweeping up, the mass sticks up to :math:`a^*` and
jumps to the upper branch; sweeping down it stays there down to SN -- hysteresis, as the thesis
describes for Fig. 2.3 (a). (b) :math:`\gamma = 1.5 < 2`: persistence. A stable branch of
impacting orbits grows from the graze, its impact velocity rising like
:math:`\sqrt{a - a^*}`, and both sweeps follow it.
"""

import math

import matplotlib.pyplot as plt
import numpy as np

import pwsdyn
from pwsdyn.grazing import FrictionImpact

MODEL = "friction-impact-oscillator"
E, B = 0.8, 1.0


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
        # the state before each impact and its phase give the velocity after it (eq. 3.5)
        u = a * s.omega * np.cos(2 * np.pi * ds["phase"].values[i])
        v = (1 + E) * u - E * ds["section"].values[i, ..., 1]
        v = np.where(ds["n_points"].values[i][:, None] > 0, v, 0.0)  # at rest: 0
        aa = np.broadcast_to(a, v.shape)
        ax.plot(aa.ravel(), v.ravel(), m, color=c, ms=3.5, alpha=0.7, ls="none",
                label=f"sweep {d}")


def panel(ax, gamma, a_lo, a_hi, title):
    s = FrictionImpact.from_params({"Fs": 1.0, "Fd": 1.0, "b": B, "e": E, "a": a_hi,
                                    "omega": omega_for(gamma)})
    sweep_points(ax, s, np.linspace(a_lo, a_hi, 61))
    # the stick solutions: a resting mass the constraint never reaches
    ax.plot([a_lo, s.a_star], [0, 0], color="C2", lw=2.0,
            label="stick solutions")
    # the period-one impacting orbit at the top of the range, continued down to its graze
    x_star, _ = s.fixed_point(exact=True)
    orbit = pwsdyn.find_periodic_orbit(MODEL, [x_star * s.scale, 0.0], t0=0.0,
                                       params=s.params(), mode="stick")
    branch = pwsdyn.continue_orbit(MODEL, orbit, "a", span=(a_lo, a_hi), ds=-0.005)
    branch.plot(y=velocity_after_the_impact, ax=ax)
    ax.plot(s.a_star, 0, "ko", ms=5)
    # below the point: the branch labels its graze (GR) above it
    ax.annotate("NSF", (s.a_star, 0), textcoords="offset points", xytext=(6, -6), va="top")
    ax.set_title(f"{title}: $\\gamma$ = {s.gamma:.2g}")
    ax.set_xlabel("amplitude $a$")


fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
panel(axes[0], 2.5, 1.94, 2.04, "(a) loss")
panel(axes[1], 1.5, 1.96, 2.06, "(b) persistence")
axes[0].set_ylabel("velocity after the impact")
axes[1].legend(loc="upper left")
plt.show()
