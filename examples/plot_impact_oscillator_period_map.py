r"""
Impact oscillator: period map in (omega, sigma) with the continued curves on top
================================================================================

The impact oscillator of Budd & Dux, ``x'' + eps x' + x = sin(omega t)`` with a rigid stop
at ``x = sigma`` and Newton's impact law ``v -> -r v``, scanned over the forcing frequency
``omega`` and the stop's position ``sigma`` (:func:`pwsdyn.scan`): each cell is coloured by
the period of the attractor, counted in impacts (``section="impact"``); white where the
motion does not reach the stop. On top, two curves continued in the same plane
(:func:`pwsdyn.continue_bifurcation`, drawn by :meth:`pwsdyn.Branch.plot`): the period
doubling (``PD``) of the one-impact orbit and the graze (``GR``) of the non-impacting orbit,
``sigma = R(omega)``, the amplitude of the forced response. They lie on the borders of the
period-one and period-two regions and, followed down in ``omega``, of the region without
impacts.
"""

import numpy as np

import pwsdyn
from pwsdyn.plot import plot_scan

MODEL = "impact-oscillator"
params = {"eps": 0.1, "r": 0.8}

# %%
# The scan
# --------
# Each row (one ``sigma``) is a sweep in ``omega`` from ``x = -1`` at rest, continuing the
# final state from each value to the next, up and down (``direction="both"``, the default);
# the rows run in parallel. Where attractors coexist the two maps differ: swept up, the
# one-impact orbit is followed past the graze of the non-impacting one, up to where it
# ends; swept down, the non-impacting orbit is followed until it grazes the stop.
omegas = np.linspace(2.5, 5.0, 40)
sigmas = np.linspace(-0.8, 0.3, 30)
scan = pwsdyn.scan(MODEL, {"omega": omegas, "sigma": sigmas}, {"x": -1.0, "v": 0.0},
                   params=params, section="impact", transient=120, samples=40,
                   progress=False)

# %%
# The curves
# ----------
# The period doubling: the one-impact orbit found from a settled run at ``omega = 2.8``,
# ``sigma = -0.5``, continued up in ``omega`` to its ``PD`` point, which is then followed in
# ``(omega, sigma)`` both ways. The graze: the non-impacting orbit (the forced response) at
# ``omega = 3.5`` continued down in ``sigma`` until it touches the stop (``GR``), then
# followed in ``(omega, sigma)``.
p1 = {**params, "sigma": -0.5, "omega": 2.8}
traj = pwsdyn.simulate(MODEL, {"x": -1.0, "v": 0.0}, (0, 100), params=p1)
orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
up = pwsdyn.continue_orbit(MODEL, orbit, "omega", span=(2.5, 5.0), ds=0.05)
span = dict(span=(2.5, 5.0), span2=(-0.8, 0.3))
pd = [pwsdyn.continue_bifurcation(MODEL, up.special("PD")[0], ("omega", "sigma"), ds=ds,
                                  **span) for ds in (0.05, -0.05)]

w = 3.5
X, Y = np.linalg.solve([[1 - w**2, -params["eps"] * w], [params["eps"] * w, 1 - w**2]],
                       [1.0, 0.0])
free = pwsdyn.find_periodic_orbit(MODEL, [Y, w * X], t0=0.0,
                                  params={**params, "omega": w, "sigma": 0.3})
down = pwsdyn.continue_orbit(MODEL, free, "sigma", span=(0.0, 0.3), ds=-0.02, on_dib="stop")
gr = [pwsdyn.continue_bifurcation(MODEL, down.special("GR")[0], ("omega", "sigma"), ds=ds,
                                  **span) for ds in (0.05, -0.05)]

# %%
# The maps
# --------
# ``omega`` across and ``sigma`` up, as the curves continued in ``(omega, sigma)`` are
# drawn. The period doubling lies on the border of the period-one and period-two regions in
# both maps. In the map swept up the one-impact orbit persists above the graze, where it
# coexists with the non-impacting orbit; in the map swept down the graze is the border of
# the region without impacts wherever a row reached the non-impacting orbit (each row starts
# with impacts at ``omega = 5``, and the lower rows stay on impacting orbits that coexist
# with it).
import matplotlib.pyplot as plt  # noqa: E402

fig, axes = plt.subplots(1, 2, figsize=(14, 5.6), layout="constrained")
for ax, direction in zip(axes, ("up", "down")):
    plot_scan(scan, ax=ax, direction=direction, legend=direction == "down")
    for curve in pd:
        curve.plot(ax=ax, color="k", label="PD curve")
    for curve in gr:
        curve.plot(ax=ax, color="#D55E00", label="GR curve")
    ax.set_xlim(omegas[0], omegas[-1])
    ax.set_ylim(sigmas[0], sigmas[-1])
    ax.set_title(f"rows swept {direction} in $\\omega$", fontsize="medium")
fig.suptitle("impact oscillator: period maps with the period doubling (PD) and grazing "
             "(GR) curves", fontsize="medium")
fig
