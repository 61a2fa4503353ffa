"""
Basins of attraction of coexisting impacting orbits
===================================================

The impact oscillator (zoo ``impact-oscillator``) without damping, with the stop at the
unforced equilibrium and ``r = 0.8``, at ``omega = 3.05``: two period-two orbits coexist, one
with an impact every forcing period and one with two impacts per period (a brute-force sweep
up and down in ``omega`` lands on one or the other). :func:`pwsdyn.basins` runs every start
of a grid of initial states (at phase 0 of the forcing) for 200 forcing periods, records 32
more at the stroboscopic section, finds each run's period and matches the cycles to
attractors. The basins interleave in spirals around the orbits.
"""

import numpy as np

import pwsdyn
from pwsdyn.plot import plot_basins

MODEL = "impact-oscillator"
PARAMS = {"omega": 3.05}          # where the two period-two orbits coexist
X_RANGE, V_RANGE = (-1.5, 0.0), (-1.5, 1.5)

grid = {"x": np.linspace(*X_RANGE, 50), "v": np.linspace(*V_RANGE, 50)}
ds = pwsdyn.basins(MODEL, grid, params=PARAMS, transient=200, samples=32, progress=False)

# %%
# The attractor table and the basin fractions (``-2``: failed runs, ``-1``: divergence).
for k in ds["attractor"].values:
    a = ds.sel(attractor=k)
    print(f"attractor {k}: period {int(a.attractor_period)}, "
          f"impacts per forcing period {float(a.attractor_events_per_period):g}, "
          f"basin fraction {float(ds.fraction.sel(basin=k)):.3f}")
print("fractions sum to", float(ds.fraction.sum()))

# %%
# The basins, with each attractor's section points marked.
fig = plot_basins(ds)
fig
