r"""
A boundary crisis located from the geometry, confirmed by brute force
=====================================================================

:func:`pwsdyn.locate_crisis` follows a chaotic attractor of the border-collision normal form
(Nusse & Yorke 1992) through a parameter, brackets where its orbit leaves, and locates the
crisis where the attractor's tip, a fold of the unstable manifold of the saddle :math:`L^*`
on its basin's boundary, touches the stable manifold of the same saddle: a homoclinic
tangency (Grebogi, Ott & Yorke 1983). The value agrees with the contact derived in closed
form to 1e-10. Brute force on both sides confirms it: just below, every orbit started near
the attractor stays bounded; just above, every one leaves, after a transient that grows as
the crisis is approached.
"""

import matplotlib.pyplot as plt
import numpy as np

import pwsdyn
from pwsdyn.model.iteration import iterate
from pwsdyn.plot import plot_crisis

BCNF = {"name": "bcnf", "kind": "map", "states": ["x", "y"],
        "parameters": {"tL": 1.8, "dL": 0.3, "tR": -1.8, "dR": 0.3, "mu": 1.0},
        "pieces": [{"name": "L", "condition": "x <= 0",
                    "map": {"x": "tL*x + y + mu", "y": "-dL*x"}},
                   {"name": "R", "map": {"x": "tR*x + y + mu", "y": "-dR*x"}}]}

crisis = pwsdyn.locate_crisis(BCNF, "tL", (1.8, 2.0), x0=[0.1, 0.0], steps=11)
print(crisis)
print("closed form 1.8928425058, located", round(crisis.value, 10))

# %%
# Left: the attractor at the located value, the stable manifold of :math:`L^*` and the
# contact. Right: brute force, 200 initial conditions near the flip saddle of the right piece
# iterated 20000 times at :math:`\tau_L` just below and just above the crisis: the fraction
# still bounded after each number of iterations.
fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
attractor, _ = iterate(BCNF, [0.1, 0.0], 4000, params={"tL": crisis.value}, transient=1000)
plot_crisis(crisis, attractor=attractor, ax=axes[0])

rng = np.random.default_rng(0)
starts = rng.uniform(-0.3, 0.3, (200, 2)) + [0.3, -0.1]
n = 20000
for dt, color in ((-5e-3, "tab:blue"), (2e-2, "tab:red")):
    tL = crisis.value + dt
    escape = []
    for x0 in starts:
        xs, _ = iterate(BCNF, x0, n, params={"tL": tL}, bound=1e6)
        bad = np.flatnonzero(~np.isfinite(xs[:, 0]))
        # an orbit still bounded after n iterations has not escaped (not: at n)
        escape.append(bad[0] if len(bad) else np.inf)
    escape = np.sort(escape)
    k = np.arange(1, n + 1)
    alive = 1.0 - np.searchsorted(escape, k, side="right") / len(escape)
    axes[1].semilogx(k, alive, color=color, label=fr"$\tau_L = \tau_c {dt:+g}$")
    print(f"tL = crisis {dt:+g}: {np.mean(np.isinf(escape)):.2f} bounded after {n} iterations")
axes[1].set_xlabel("iterations")
axes[1].set_ylabel("fraction of orbits still bounded")
axes[1].set_ylim(-0.05, 1.05)
axes[1].legend(loc="lower left")
axes[1].set_title("brute force on both sides of the crisis", fontsize="medium")
plt.show()
