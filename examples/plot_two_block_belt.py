"""
Two blocks on a belt: friction contacts that stick one at a time and both at once
=================================================================================

Two blocks on a belt moving at speed ``V``, tied to the ground and to each other by springs,
each with its own static and dynamic friction (zoo ``two-block-belt``, the two-block model of
Nussbaum & Ruina). Each ``sign()`` of the friction law is a Filippov switch on the block's
slip velocity ``w_i = v_i - V``: a block sticks to the belt (slides on ``w_i = 0``) while the
spring force on it stays within its static friction. With a stiff coupling spring (``kc = 2``)
the blocks also stick at the same time: the motion slides on the intersection of the two
surfaces, and each block releases where its own stick condition fails, the other sticking on.
"""

import numpy as np

import pwsdyn

params = {"kc": 2.0}
traj = pwsdyn.simulate("two-block-belt", None, (0.0, 300.0), params=params)
slides = traj.sliding_intervals()
both = [(a, b) for a, b, name in slides if "&" in name]
print(f"{len(slides)} sliding segments, {len(both)} with both blocks stuck")

# %%
# The last 40 time units: the slip velocity of each block, its sticking intervals drawn
# thick, and the intervals with both blocks stuck shaded.
import matplotlib.pyplot as plt

t = np.linspace(260.0, 300.0, 8000)
X = traj(t)
V = traj.params["V"]
fig, ax = plt.subplots(figsize=(9, 3.6), layout="constrained")
for i, (col, colour) in enumerate(((1, "C0"), (3, "C1")), start=1):
    w = X[:, col] - V
    stuck = np.abs(w) < 1e-9
    ax.plot(t, w, color=colour, lw=0.9, label=f"$w_{i} = v_{i} - V$")
    ax.plot(np.where(stuck, t, np.nan), np.where(stuck, w, np.nan), color=colour, lw=4,
            label=f"block {i} stuck")
for k, (a, b) in enumerate(x for x in both if x[1] > t[0]):
    ax.axvspan(max(a, t[0]), b, color="0.85", zorder=0,
               label="both stuck (on the intersection)" if k == 0 else None)
ax.set_xlabel("$t$")
ax.set_ylabel("slip velocity")
ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
ax.set_title("two-block belt, kc = 2")
fig

# %%
# A periodic orbit with a segment on the intersection, by Newton shooting from a state near
# it, and its Floquet multipliers (the trivial multiplier 1 left out). Sliding on a surface
# removes the direction across it, on the intersection both: one multiplier is left, and it
# is below -1 (the orbit is unstable; the run above wanders near it and its doubled period).
orbit = pwsdyn.find_periodic_orbit("two-block-belt", [0.9596, -0.4364, 0.9704, -0.4544],
                                   period=8.735, params=params)
print("period:", round(orbit.period, 6))
print("multipliers:", np.round(orbit.multipliers.real, 6))
print("signature:", orbit.signature)
