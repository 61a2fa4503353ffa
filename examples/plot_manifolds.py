r"""
Stable and unstable manifolds of saddles: a border, a square root, an impact
============================================================================

:func:`pwsdyn.find_periodic_point` finds a saddle fixed point of a piecewise-smooth map and
:func:`pwsdyn.manifold` grows its one-dimensional manifolds by arclength (Krauskopf & Osinga
1998): each new point is the image (unstable) or a Newton preimage (stable) of a point of the
branch already computed, with the distance and the angle between consecutive points kept
small. Where the map changes pieces the border is located by bisection and the manifold gets a
corner there, or is cut where the map jumps.

Three saddles: the border-collision normal form (Nusse & Yorke 1992), piecewise-linear, whose
manifolds are polylines; the same form with the impacting side's linear term replaced by a
square root, Nordmark's square-root map of grazing in the plane, whose unstable manifold folds
with unbounded stretching at the border; and the impact oscillator's period-one orbit past its
period doubling at :math:`\omega = 2.8`, on its stroboscopic section; and at
:math:`\omega = 3.05` the stable manifold of a period-two saddle over the basins of the two
attractors it separates.
"""

import matplotlib.pyplot as plt
import numpy as np

import pwsdyn

BCNF = {"name": "bcnf", "kind": "map", "states": ["x", "y"],
        "parameters": {"tL": 2.5, "dL": 0.5, "tR": -0.5, "dR": 0.3, "mu": 1.0},
        "pieces": [{"name": "L", "condition": "x <= 0",
                    "map": {"x": "tL*x + y + mu", "y": "-dL*x"}},
                   {"name": "R", "map": {"x": "tR*x + y + mu", "y": "-dR*x"}}]}
NORDMARK = {"name": "nordmark2", "kind": "map", "states": ["x", "y"],
            "parameters": {"tau": 2.5, "delta": 0.5, "gamma": 1.0, "mu": 0.1},
            "pieces": [{"name": "no_impact", "condition": "x <= 0",
                        "map": {"x": "tau*x + y + mu", "y": "-delta*x"}},
                       {"name": "impact",
                        "map": {"x": "-gamma*sqrt(x) + y + mu", "y": "-delta*x"}}]}

fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))

# The border-collision normal form: a saddle in the left half-plane. Its unstable manifold is
# straight up to the first image of the border crossing, then bends at every further image and
# spirals onto the stable focus of the right piece.
saddle = pwsdyn.find_periodic_point(BCNF, [-1.0, 0.5])
print(saddle)
wu = pwsdyn.manifold(BCNF, saddle, arclength=5.0)
ws = pwsdyn.manifold(BCNF, saddle, "stable", arclength=5.0)
print(wu)
ax = axes[0]
ws.plot(ax=ax)
wu.plot(ax=ax)
ax.axvline(0, color="0.7", lw=0.8, zorder=0)
ax.set(xlim=(-3, 3), ylim=(-2, 2.5), title="border-collision normal form")
ax.legend(loc="upper right", fontsize=8)

# The square-root map: the unstable manifold crosses the border x = 0 and its image folds
# back with a square-root singularity; the points are refined there automatically.
saddle2 = pwsdyn.find_periodic_point(NORDMARK, [-0.1, 0.05])
wu2 = pwsdyn.manifold(NORDMARK, saddle2, arclength=3.0, tol=1e-7)
ws2 = pwsdyn.manifold(NORDMARK, saddle2, "stable", arclength=3.0, tol=1e-7)
print(wu2, wu2.evaluations, "map evaluations")
ax = axes[1]
ws2.plot(ax=ax)
wu2.plot(ax=ax)
ax.axvline(0, color="0.7", lw=0.8, zorder=0)
ax.set(xlim=(-1, 0.6), ylim=(-0.4, 0.6), title="square-root map")
ax.legend(loc="upper right", fontsize=8)

# The impact oscillator (zoo ``impact-oscillator``) at omega = 2.8: the period-one impacting
# orbit is a flip saddle (multipliers about -2.96 and -0.22). Its manifolds on the
# stroboscopic section, with the attractor the unstable manifold accumulates on (50 forcing
# periods of a simulation after a transient). The section's states lie on the admissible side
# of the stop, x <= 0: a branch ends where it reaches the stop.
orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.29, -0.58], params={"omega": 2.8})
print(orbit.multipliers)
wu3 = pwsdyn.manifold("impact-oscillator", orbit, arclength=2.0)
ws3 = pwsdyn.manifold("impact-oscillator", orbit, "stable", arclength=1.0)
traj = pwsdyn.simulate("impact-oscillator", orbit.x0 + [0.0, 1e-3],
                       (0.0, 300 * orbit.period), params={"omega": 2.8})
attractor = np.asarray(traj(np.arange(250, 300) * orbit.period))
ax = axes[2]
ws3.plot(ax=ax)
wu3.plot(ax=ax)
ax.plot(attractor[:, 0], attractor[:, 1], "o", ms=4, color="k", label="attractor")
ax.set(title=r"impact oscillator, $\omega = 2.8$")
ax.legend(loc="best", fontsize=8)
fig.tight_layout()

# %%
# A basin boundary: at omega = 3.05 the impact oscillator has two period-two attractors, and
# between them a period-two saddle with three impacts per orbit (multipliers about 4513 and
# 5.8e-5). On a grid around the saddle the boundary between the two basins is its stable
# manifold.
P = {"omega": 3.05}
orbit2 = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.26717145, -0.51828814],
                                    params=P, periods=2)
p, w = orbit2.x0, 3e-4
basins = pwsdyn.basins("impact-oscillator", {"x": p[0] + np.linspace(-w, w, 30),
                                            "v": p[1] + np.linspace(-w, w, 30)},
                       params=P, transient=300, samples=16, max_period=4, progress=False)
ws4 = pwsdyn.manifold("impact-oscillator", orbit2, "stable", arclength=2e-3, tol=1e-7)
print(ws4)
fig2, ax = plt.subplots(figsize=(5, 4.2))
ax.pcolormesh(basins["x"], basins["v"], basins["label"].T, cmap="Pastel1", shading="nearest")
ws4.plot(ax=ax)
ax.set(xlim=(p[0] - w, p[0] + w), ylim=(p[1] - w, p[1] + w),
       title=r"basins and $W^s$, $\omega = 3.05$")
ax.locator_params(nbins=4)
ax.legend(loc="upper right", fontsize=8)
fig2.tight_layout()
