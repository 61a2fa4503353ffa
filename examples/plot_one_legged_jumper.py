"""
One-legged jumper: a hopping gait and its Floquet multipliers
=============================================================

The one-legged jumper of Dankowicz & Piiroinen as the slides present it (zoo
``one-legged-jumper``): a body and a foot joined by a leg spring, on ground that moves as
``L + A (sin(omega t) + cos(omega t))``. Each forcing period the foot takes off, lands,
chatters, sticks to the ground and is released again. The gait is found by Newton shooting
from a settled run (:meth:`pwsdyn.PeriodicOrbit.from_trajectory`); its Floquet multipliers come
from the monodromy matrix with the saltation matrices of every impact, of the
complete-chattering map and of the sticking phase, and lie inside the unit circle: the gait
is stable.
"""

import numpy as np

import pwsdyn
from pwsdyn.plot import plot_orbit

MODEL = "one-legged-jumper"
period = 2 * np.pi / 0.8          # the forcing period 2 pi / omega at the default omega

# %%
# Settle on the gait, then solve for it
# -------------------------------------
# Sixty forcing periods from the model's default start bring the motion close to the gait;
# Newton shooting then solves for the orbit to round-off.
traj = pwsdyn.simulate(MODEL, {"y1": 1.5, "v1": 0.0, "y2": 10.5, "v2": 0.0},
                       (0, 60 * period))
orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
print(orbit.signature)
print("period / forcing period:", orbit.period / period)
print("Floquet multipliers:", np.round(orbit.multipliers, 6))
print("stable:", orbit.stable)

# %%
# One period of the gait
# ----------------------
# The time series of the foot and the body with the impacts, the complete-chattering
# accumulation point and the sticking phase marked, the phase plane of the foot, and the
# multipliers in the complex plane with the unit circle.
fig = plot_orbit(orbit, states=["y1", "y2"], phase=("y1", "v1"))
fig
