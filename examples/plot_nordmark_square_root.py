r"""
Near-grazing impacts: the square-root growth of impact velocities
=================================================================

Thesis Paper A measures it on an experiment: close to a grazing bifurcation of an impact
oscillator, each impact velocity grows like the *square root* of the previous one,
:math:`v_{n+1} \sim C \sqrt{v_n}`. Nordmark's discontinuity map explains it (Nordmark 1991;
thesis eq. 2.33-2.34): at the grazing orbit, an orbit that penetrates the stop by a depth
:math:`d` is corrected by :math:`\beta \sqrt{d}`, and the smooth Poincaré map :math:`P` carries
the correction round to the next impact.

Here the impact oscillator (zoo ``impact-oscillator``) is followed in the stop position
:math:`\sigma` until its non-impacting orbit grazes the stop (:func:`pwsdyn.continue_orbit`
locates the graze, ``GR``); :func:`pwsdyn.discontinuity_map` gives :math:`a^*` (the relative
acceleration at the graze), :math:`\beta` and :math:`P`. The stop is then moved a depth
:math:`d_0` into the grazing orbit, so that the first impact has velocity
:math:`v_0 = \sqrt{2 a^* d_0}`, and the next impact velocity of a simulation is compared with
the map's prediction.
"""

import math

import matplotlib.pyplot as plt
import numpy as np

import pwsdyn

MODEL = "impact-oscillator"
omega, eps, r = 1.2, 1.5, 0.8

# %%
# The grazing orbit
# -----------------
# Without impacts the motion is the forced response ``X sin(omega t) + Y cos(omega t)`` of
# amplitude ``R``; it grazes a stop at ``sigma = R``.
X, Y = np.linalg.solve([[1 - omega**2, -eps * omega], [eps * omega, 1 - omega**2]], [1.0, 0.0])
R = math.hypot(X, Y)
params = {"omega": omega, "eps": eps, "r": r, "sigma": R + 0.3}
orbit = pwsdyn.find_periodic_orbit(MODEL, [Y, omega * X], t0=0.0, params=params)
branch = pwsdyn.continue_orbit(MODEL, orbit, "sigma", span=(R - 0.3, R + 0.3), ds=-0.05,
                               on_dib="stop")
graze = branch.special("GR")[0]
dmap = pwsdyn.discontinuity_map(graze)
print(f"graze at sigma = {graze.value:.10f} (closed form R = {R:.10f})")
print(f"a* = {dmap.a_star:.6f} (closed form omega^2 R = {omega**2 * R:.6f}), beta = {dmap.beta}")

# %%
# Simulated and predicted impact velocities
# -----------------------------------------
# With the stop at ``R - d0``, the run starts half a period before the graze on the grazing
# orbit. The discontinuity map kicks the state by ``beta sqrt(d0)``; the smooth map turns that
# into a change ``s1 sqrt(d0)`` of the next penetration depth, ``s1 = h_x P beta`` (the first
# term of the persistence sequence), so the next impact has velocity
# ``v1 = sqrt(2 a* (d0 - s1 sqrt(d0)))`` -- to lowest order ``sqrt(-s1) (2 a*)^(1/4) sqrt(v0)``.
a, tstar, P = dmap.a_star, dmap.x_star[2], 2 * math.pi / omega
s1 = dmap.persistence(1)[0]
C = math.sqrt(-s1) * (2 * a) ** 0.25
v0s = np.logspace(-5, -1.5, 8)
v1_sim, v1_map = [], []
for v0 in v0s:
    d0 = v0**2 / (2 * a)
    t0 = tstar - P / 2
    x0 = [X * math.sin(omega * t0) + Y * math.cos(omega * t0),
          omega * (X * math.cos(omega * t0) - Y * math.sin(omega * t0))]
    traj = pwsdyn.simulate(MODEL, x0, (t0, t0 + 1.9 * P), params={**params, "sigma": R - d0},
                           rtol=1e-13, atol=1e-15)
    v = [e.x_before[1] for e in traj.events if e.kind == "impact"]
    v1_sim.append(v[1])
    v1_map.append(math.sqrt(2 * a * (d0 - s1 * math.sqrt(d0))))
v1_sim, v1_map = np.array(v1_sim), np.array(v1_map)
for v0, vs, vm in zip(v0s, v1_sim, v1_map):
    print(f"v0 = {v0:.2e}   v1 simulated = {vs:.6e}   map = {vm:.6e}   "
          f"relative difference {abs(vs / vm - 1):.1e}")

# %%
# On logarithmic axes the square-root law is a line of slope 1/2: the simulated second
# impact velocities lie on the map's prediction, and approach ``C sqrt(v0)`` as
# ``v0 -> 0``.
fig, ax = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
ax.loglog(v0s, v1_sim, "o", label="simulation")
ax.loglog(v0s, v1_map, "-", label=r"discontinuity map: $\sqrt{2a^*(d_0 - s_1\sqrt{d_0})}$")
ax.loglog(v0s, C * np.sqrt(v0s), "--", label=rf"$C\sqrt{{v_0}}$, $C = {C:.3f}$")
ax.loglog(v0s, v0s, ":", color="0.5", label=r"$v_1 = v_0$")
ax.set_xlabel(r"impact velocity $v_0$")
ax.set_ylabel(r"next impact velocity $v_1$")
ax.set_title(rf"impact oscillator, $\omega = {omega}$, $\varepsilon = {eps}$, $r = {r}$")
ax.legend(fontsize=8)
ax.grid(True, which="both", lw=0.3)
fig
