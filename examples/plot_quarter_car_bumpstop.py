r"""
Quarter-car with a controlled bumpstop: comfort and rattle space
================================================================

The quarter-car of thesis Paper C (zoo ``quarter-car``: body and wheel, bilinear damper,
wheel hop, a rigid bumpstop at :math:`\delta = 5` cm of compression) on a road
:math:`z_r = A \sin(\omega t)`. As the road amplitude :math:`A` grows, the periodic motion of
the suspension first touches the bumpstop at a graze. With soft dampers (compression and
expansion damping ``cc = 250`` and ``ce = 750`` N s/m) and the road at 1.27 Hz, just above the
body resonance, the graze loses the local attractor: the motion jumps to a violent one that
chatters on the bumpstop every cycle, and stays there when :math:`A` is lowered again
(hysteresis). The low-cost control of thesis eq. 5.2 moves the bumpstop once per road period,
away from impact, by
:math:`\delta \to \delta^* + c \cdot (x - x^*) + c_0 (\delta - \delta^*)`; designed at the
graze (:func:`pwsdyn.design_control`) it makes the bifurcation persistent, and the comfort and
rattle-space metrics (:mod:`pwsdyn.explore.metrics`) change gradually through it.
"""

import math

import numpy as np
from matplotlib.figure import Figure

import pwsdyn
from pwsdyn.explore.metrics import metrics_sweep
from pwsdyn.plot import plot_bifurcation, plot_metrics

params = {"omega": 8.0, "cc": 250.0, "ce": 750.0, "r": 0.5}
T = 2 * math.pi / params["omega"]
x0 = {"zs": 0.0, "vs": 0.0, "zu": 0.0, "vu": 0.0}

# %%
# The graze
# ---------
# The non-impacting orbit at a small amplitude, continued in ``A`` until it touches the
# bumpstop. The bumpstop's normal velocity is the damper's argument ``vr = vs - vu``, so the
# graze lies on the damper's kink, an event point of the orbit: continuation reports it as a
# corner collision (``CC``), where the field is continuous and Nordmark's discontinuity map
# applies. Its persistence sequence (thesis eq. 2.35) changes sign at once: a loss.
traj = pwsdyn.simulate("quarter-car", x0, (0.0, 60 * T), params={**params, "A": 0.01})
orbit = pwsdyn.PeriodicOrbit.from_trajectory(traj)
branch = pwsdyn.continue_orbit("quarter-car", orbit, "A", span=(0.01, 0.05), ds=0.002,
                               on_dib="stop")
graze = branch.special("CC")[0]
A_star = graze.value
dmap = pwsdyn.discontinuity_map(graze)
print(f"graze at A* = {A_star:.6f} m; a* = {dmap.a_star:.4f} m/s^2; "
      f"multipliers {np.round(graze.multipliers[:2], 4)}")
print("persistence sequence:", np.array2string(dmap.persistence(6), precision=4),
      "->", dmap.scenario)

# %%
# The control
# -----------
# :func:`pwsdyn.design_control` needs the graze on a branch continued in the controlled
# parameter: the orbit at ``A*`` with the stop further away, continued in ``delta``, grazes
# at ``delta = 5 cm``. The control section is a quarter of the way through the expansion
# that follows the graze; the gains are bounded by 0.05 (5 cm of stop travel per metre, or
# per m/s, of deviation from the grazing orbit).
orbit = pwsdyn.find_periodic_orbit("quarter-car", graze.orbit.x0, t0=graze.orbit.t0,
                                   params={**params, "A": A_star, "delta": 0.06})
branch = pwsdyn.continue_orbit("quarter-car", orbit, "delta", span=(0.04, 0.06), ds=-0.002,
                               on_dib="stop")
graze_delta = branch.special("CC")[0]
t_graze = graze_delta.monitor.t
segments = graze_delta.problem.orbit_problem.evaluate(graze_delta.point.u,
                                                      np.array([graze_delta.value])).segs
expansion = segments[(graze_delta.monitor.segment + 1) % len(segments)]
design = pwsdyn.design_control(graze_delta, t_c=(t_graze + 0.25 * expansion.T) % T,
                               max_gain=0.05)
print(f"c0 = {design.c0:.2f}, c = {design.c}")
print("controlled persistence sequence:", np.array2string(design.sequence[:6], precision=4))
controlled = pwsdyn.with_discrete_control("quarter-car", "delta")
variants = {"fixed": {"model": "quarter-car", "params": params},
            "controlled": {"model": controlled, "params": {**params, **design.params()}}}

# %%
# Comfort and rattle space over the road amplitude
# ------------------------------------------------
# Up and down in ``A`` (each value continues the last), 40 road periods of transient and 10
# measured: the RMS of the body acceleration (its smooth part; the bumpstop's impulses are
# counted apart), the range of the suspension travel ``zs - zu``, and the largest impact
# velocity on the bumpstop. Without control the up sweep jumps at ``A*`` and the down sweep
# stays on the chattering motion down to 0.82 ``A*``; with control both sweeps follow one
# curve that bends up gently past ``A*``. The controlled stop moves with the motion, so the
# suspension compresses beyond 5 cm past the graze: the rattle space is the price of the
# comfort (as Paper C found).
values = np.linspace(0.8, 1.2, 21) * A_star
metrics = metrics_sweep(variants, "A", values, velocity="vs", travel="zs - zu",
                        event="bumpstop", transient=40, periods=10, direction="both")
fig = Figure(figsize=(7.0, 7.5), layout="constrained")
plot_metrics(metrics, ["rms_acceleration", "travel_range", "impact_velocity_max"],
             ax=fig.subplots(3, 1, sharex=True))
fig

# %%
# Bifurcation diagrams
# --------------------
# Brute-force sweeps (:func:`pwsdyn.sweep`, stroboscopic section of the body displacement,
# one chunk per direction so that each value continues the last): the fixed bumpstop's
# hysteresis loop, and its absence with the control.
start = pwsdyn.simulate("quarter-car", x0, (0.0, 80 * T),
                        params={**params, "A": values[0]}).x_final
fig = Figure(figsize=(10.0, 5.5), layout="constrained")
panels = fig.subplots(2, 2, sharex=True, height_ratios=(3, 1))
for col, (name, v) in enumerate(variants.items()):
    first = list(start) + ([0.05] if name == "controlled" else [])
    ds = pwsdyn.sweep(v["model"], "A", values, first, params=v["params"], transient=100,
                      samples=20, direction="both", chunk_size=len(values), workers=1,
                      progress=False)
    plot_bifurcation(ds, "zs", ax=panels[:, col])
    panels[0, col].set_title(f"{name} bumpstop", fontsize="medium")
fig
