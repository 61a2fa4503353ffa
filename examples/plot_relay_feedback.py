"""
Relay feedback: a periodic orbit with sliding segments
======================================================

The third-order relay feedback system of di Bernardo, Johansson & Vasca, the test case of
Piiroinen & Kuznetsov's event-driven simulation of Filippov systems (zoo ``relay-feedback``):
``x' = A x + B u`` with ``u = -sign(x1)``. The model is written with ``sign``; pwsdyn splits it
into the two modes on either side of ``x1 = 0`` and a Filippov switching surface between
them. The attracting periodic orbit slides along the surface many times per period; the
sliding intervals of the run (:meth:`pwsdyn.Trajectory.sliding_intervals`) are highlighted.
"""

import numpy as np

import pwsdyn

traj = pwsdyn.simulate("relay-feedback", {"x1": 0.0, "x2": -0.001, "x3": -0.02}, (0.0, 60.0))
slides = traj.sliding_intervals()

# %%
# The period is the time between two long sliding segments of the same sign; the orbit is
# symmetric (``x -> -x`` after half a period), so long segments alternate in sign.
long_starts = [a for a, b, _ in slides if b - a > 0.5]
T = long_starts[-1] - long_starts[-3]
t0 = long_starts[-3]
n_slides = sum(1 for a, _, _ in slides if t0 <= a < t0 + T)
print(f"period {T:.4f}, {n_slides} sliding segments per period")

# %%
# The last period of the run: ``x1`` (the relay's input) with the sliding segments on
# ``x1 = 0`` drawn thick, and the orbit in the ``(x2, x3)`` plane, sliding parts in colour.
import matplotlib.pyplot as plt

t = np.linspace(t0, t0 + T, 6000)
X = traj(t)
sliding = np.zeros(t.shape, dtype=bool)
for a, b, _ in slides:
    sliding |= (t >= a) & (t <= b)

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.8), layout="constrained")
ax1.plot(t - t0, X[:, 0], color="0.3", lw=0.8, label="crossing / free")
ax1.plot(np.where(sliding, t - t0, np.nan), np.where(sliding, X[:, 0], np.nan), color="C3",
         lw=3, label="sliding on $x_1 = 0$")
ax1.set_xlabel("$t - t_0$")
ax1.set_ylabel("$x_1$")
ax1.legend(fontsize=8)
ax2.plot(X[:, 1], X[:, 2], color="0.3", lw=0.8)
ax2.plot(np.where(sliding, X[:, 1], np.nan), np.where(sliding, X[:, 2], np.nan), color="C3",
         lw=2.5)
ax2.set_xlabel("$x_2$")
ax2.set_ylabel("$x_3$")
fig.suptitle(f"relay feedback: period {T:.4f}, {n_slides} sliding segments per period")
fig

# %%
# The same orbit by Newton shooting, and its Floquet multipliers (the trivial multiplier 1 of
# an autonomous flow left out). Entering a sliding segment collapses the direction across the
# surface (the saltation matrix there has rank ``n - 1``), so the monodromy matrix is
# singular: one multiplier is zero, and the orbit is strongly attracting.
orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
print("period:", orbit.period)
print("multipliers:", np.round(orbit.multipliers, 8))
