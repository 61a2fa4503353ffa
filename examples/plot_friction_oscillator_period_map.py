r"""
Friction impact oscillator: period map in (a, omega)
====================================================

The impact oscillator with dry friction of the thesis (zoo model
``friction-impact-oscillator``: a mass on a spring, static friction :math:`F_s = 1.2 F_d`,
driven only through impacts with a constraint :math:`-b + a \sin(\omega t)`), scanned over the
constraint's amplitude :math:`a` and frequency :math:`\omega` (:func:`pwsdyn.scan`). Left:
the period of the attractor at the stroboscopic section. Right: the events per forcing
period (impacts and the slip reversals and stops on :math:`v = 0`), which tell apart orbits
of the same period with different event sequences: below :math:`a^\ast = b + F_d/k`, where
the constraint's top reaches the edge of the dynamic stick set, the mass rests and is never
hit (period one, no event); above it every forcing period has its impact, and at low
frequencies chattering sequences. The dashed lines mark :math:`a^\ast` and
:math:`a^{\ast\ast} = b + F_s/k`, the edge of the static stick set (thesis section 5.3.1).
"""

import matplotlib.pyplot as plt
import numpy as np

import pwsdyn
from pwsdyn.plot import plot_scan

MODEL = "friction-impact-oscillator"

# %%
# The scan
# --------
# Each row (one :math:`\omega`) is a sweep up in :math:`a` from rest at :math:`q = 1`,
# continuing the final state from each amplitude to the next; the rows run in parallel.
amplitudes = np.linspace(1.6, 3.0, 36)
omegas = np.linspace(0.4, 1.6, 30)
scan = pwsdyn.scan(MODEL, {"a": amplitudes, "omega": omegas}, {"q": 1.0, "v": 0.0},
                   direction="up", transient=60, samples=24, progress=False)

# %%
# The map
# -------
model = pwsdyn.load_model(MODEL)
p = model.parameters
a_star, a_star2 = p["b"] + p["Fd"] / p["k"], p["b"] + p["Fs"] / p["k"]
fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5.2), layout="constrained")
plot_scan(scan, ax=left)
events = scan.events_per_period.sel(direction="up")
# chattering sequences at low frequency count tens of events: the scale stops at 8
mesh = right.pcolormesh(amplitudes, omegas, events.values.T, shading="nearest",
                        cmap="viridis", vmin=0, vmax=8, rasterized=True)
fig.colorbar(mesh, ax=right, label="events per forcing period", extend="max")
right.set_xlabel("$a$")
right.set_ylabel("$\\omega$")
right.set_title("events per period", fontsize="medium")
for ax in (left, right):
    for a, name in ((a_star, "$a^\\ast$"), (a_star2, "$a^{\\ast\\ast}$")):
        ax.axvline(a, color="k", ls="--", lw=1)
        ax.annotate(name, (a, omegas[-1]), xytext=(3, -12), textcoords="offset points")
fig
