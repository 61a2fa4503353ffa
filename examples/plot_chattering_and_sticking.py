"""
Chattering and sticking: a ball on a vibrating table
====================================================

The sequence the slides describe for a ball bouncing on a vibrating table (zoo
``bouncing-ball``): after a high bounce the impacts come faster and faster and accumulate in
finite time (a *chattering sequence*); at the accumulation point the ball has come to rest on
the table, which is jumped over at once by the complete-chattering map (Nordmark & Piiroinen).
The ball then *sticks*, carried by the table, until the table's deceleration exceeds gravity
(the contact force would turn negative) and the ball is *released* into free flight.
"""

import numpy as np

import pwsdyn
from pwsdyn.plot import plot_trajectory

# The table moves as A sin(omega t) at 1 Hz. The model's default amplitude, 0.224 m, gives a
# peak acceleration of 0.9 g: a ball at rest on the table would stay there. At A = 0.28 m
# (1.13 g) the table throws it off once per period.
traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0.0, 5.5), params={"A": 0.28})

# %%
# The event log
# -------------
# Each record has its time, kind and the states on either side of the jump.
kinds = [e.kind for e in traj.events]
print({k: kinds.count(k) for k in dict.fromkeys(kinds)})
for e in traj.events:
    if e.kind != "impact":
        print(f"t = {e.t:.5f}  {e.kind:8s}  v- = {e.x_before[1]: .5f}  v+ = {e.x_after[1]: .5f}")

# %%
# The impact velocities relative to the table fall geometrically in a chattering sequence
# (ratio close to the restitution coefficient ``e = 0.8`` once the table hardly moves between
# impacts), so the time between impacts shrinks geometrically too and the sum is finite.
impacts = [e for e in traj.events if e.kind == "impact"]
chatter = next(e.t for e in traj.events if e.kind == "chatter")
last = [e for e in impacts if e.t < chatter][-6:]
p = traj.params                  # the values the run used
A, w = p["A"], p["omega"]
rel = [e.x_before[1] - A * w * np.cos(w * e.t) for e in last]
print("relative impact velocities before the accumulation:", np.round(rel, 5))
print("ratios:", np.round(np.array(rel[1:]) / np.array(rel[:-1]), 4))

# %%
# While the ball sticks, the contact force is ``m (g + s'')`` with the table's acceleration
# ``s'' = -A omega^2 sin(omega t)``; it vanishes where ``sin(omega t) = g / (A omega^2)``,
# rising: the release comes at that phase of every period.
release = [e.t for e in traj.events if e.kind == "release"]
phase = np.arcsin(p["g"] / (A * w**2)) / w
print("release times mod the period:", np.round(np.mod(release, 2 * np.pi / w), 9))
print("closed form:                 ", round(phase, 9))

# %%
# The trajectory
# --------------
# Height and velocity with the table's motion (dashed), the impacts, the chattering
# accumulation point, the start of sticking and the release marked; sticking underlaid.
fig = plot_trajectory(traj)
fig
