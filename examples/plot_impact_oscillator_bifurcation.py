"""
Impact oscillator: brute-force bifurcation diagram and continued branches
=========================================================================

The impact oscillator of Budd & Dux, ``x'' + eps x' + x = sin(omega t)`` with a rigid stop
at ``x = sigma`` and Newton's impact law ``v -> -r v``, swept in the forcing frequency
``omega`` (:func:`pwsdyn.sweep`, up and down), with the period-one impacting orbit continued
through the same range (:func:`pwsdyn.continue_orbit`) and drawn over the sweep by
:meth:`pwsdyn.Branch.plot`: stable parts solid, unstable parts dashed. Followed down, the
stable orbit meets a saddle in a fold (``LP``): below it the sweep leaves the branch for
irregular motion, and the sweeps up and down differ where both coexist. Followed up, it loses
stability in a period doubling (``PD``), where the period-two branch (red) starts, and the
sweep follows that one.
"""

import numpy as np

import pwsdyn

MODEL = "impact-oscillator"
params = {"eps": 0.1, "sigma": -0.5, "r": 0.8}

# %%
# The sweep
# ---------
# At each ``omega`` the run continues from the previous final state, discards 100 forcing
# periods and records the state just before each impact in the next 32 (an event section:
# ``section="impact"``). Up and down sweeps (``direction="both"``, the default) would differ
# where attractors coexist.
omegas = np.linspace(2.0, 4.6, 200)
sweep = pwsdyn.sweep(MODEL, "omega", omegas, {"x": -1.0, "v": 0.0}, params=params,
                     section="impact", transient=100, samples=32, progress=False)

# %%
# The branch
# ----------
# A periodic orbit found by Newton shooting from a settled run at ``omega = 2.8``, continued
# up and down in ``omega`` on its event sequence (one impact per period). The period
# doubling at ``omega = 4.32`` starts the period-two branch.
traj = pwsdyn.simulate(MODEL, {"x": -1.0, "v": 0.0}, (0, 100), params={**params, "omega": 2.8})
orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
up = pwsdyn.continue_orbit(MODEL, orbit, "omega", span=(2.0, 4.6), direction="up")
down = pwsdyn.continue_orbit(MODEL, orbit, "omega", span=(2.0, 4.6), ds=-0.01)
pd = up.special("PD")[0]
doubled = pwsdyn.continue_orbit(MODEL, pd, "omega", span=(2.0, 4.6))
print(up.special_points)
print(down.special_points, down.stop_reason)

# %%
# The diagram
# -----------
# A continued orbit is sectioned just after its impact (its first segment starts there), the
# sweep just before each impact: Newton's law ``v+ = -r v-`` maps one onto the other, so the
# sweep's impact velocities are drawn as post-impact velocities.
after = sweep.copy()
after["section"] = sweep["section"].where(sweep["state"] != "v", -params["r"] * sweep["section"])
fig = up.plot(y="v", sweep=after)
ax = fig.axes[0]
down.plot(y="v", ax=ax)
# the branches share one legend: each line style once, each branch by name and colour
doubled.plot(y="v", ax=ax, color="C3")
ax.set_ylabel("velocity $v$ just after an impact")
ax.set_title("impact oscillator: sweep in $\\omega$ and the period-one and period-two branches",
             fontsize="medium")
fig
