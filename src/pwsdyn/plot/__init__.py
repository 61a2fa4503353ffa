"""Figures of simulation results (matplotlib).

Figures are built on :class:`matplotlib.figure.Figure` directly, without ``pyplot``: no global
figure state, nothing is shown, no GUI backend is needed, and the user's backend choice is left
alone. A returned figure displays in a notebook and can be saved with ``fig.savefig``.

A figure written through the ``path`` argument of the functions here never replaces an
existing file unless ``overwrite=True`` (:class:`~pwsdyn.OutputExistsError` otherwise); the
path (directory, format, existing file) is checked before the figure is drawn.

One module per family of figures: trajectories (:func:`plot_trajectory`), periodic orbits
(:func:`plot_orbit`), continued branches (:func:`plot_branch`), sweeps, basins and response
metrics (:func:`plot_bifurcation`, :func:`plot_lyapunov`, :func:`plot_basins`,
:func:`plot_metrics`), period maps of two-parameter scans (:func:`plot_scan`), crises located from the geometry
(:func:`plot_crisis`); what they
share (names typeset, legends, files) in one more. Every name is importable from
``pwsdyn.plot``.

This package only reads result objects; the numerical code never imports it.
"""

from matplotlib.axes import Axes as Axes
from matplotlib.figure import Figure as Figure
from matplotlib.lines import Line2D as Line2D

from ._branches import BRANCH_STYLES as BRANCH_STYLES
from ._branches import SPECIAL_MARKERS as SPECIAL_MARKERS
from ._branches import _branch_y as _branch_y
from ._branches import plot_branch as plot_branch
from ._common import GREEK_SPELLINGS as GREEK_SPELLINGS
from ._common import _latex_name as _latex_name
from ._common import _number as _number
from ._common import _tex as _tex
from ._common import _values_text as _values_text
from ._common import figure_formats as figure_formats
from ._manifolds import CRISIS_COLORS as CRISIS_COLORS
from ._manifolds import plot_crisis as plot_crisis
from ._orbits import plot_orbit as plot_orbit
from ._scans import PERIOD_COLORS as PERIOD_COLORS
from ._scans import SCAN_SPECIAL_COLORS as SCAN_SPECIAL_COLORS
from ._scans import plot_scan as plot_scan
from ._scans import scan_classes as scan_classes
from ._sweeps import BASIN_COLORS as BASIN_COLORS
from ._sweeps import BASIN_SPECIAL_COLORS as BASIN_SPECIAL_COLORS
from ._sweeps import DEFAULT_METRICS as DEFAULT_METRICS
from ._sweeps import SWEEP_COLORS as SWEEP_COLORS
from ._sweeps import SWEEP_MARKERS as SWEEP_MARKERS
from ._sweeps import VARIANT_COLORS as VARIANT_COLORS
from ._sweeps import plot_basins as plot_basins
from ._sweeps import plot_bifurcation as plot_bifurcation
from ._sweeps import plot_lyapunov as plot_lyapunov
from ._sweeps import plot_metrics as plot_metrics
from ._trajectories import CONSTRAINED_STYLES as CONSTRAINED_STYLES
from ._trajectories import EVENT_STYLES as EVENT_STYLES
from ._trajectories import SURFACE_COLOR as SURFACE_COLOR
from ._trajectories import TRAJECTORY_COLOR as TRAJECTORY_COLOR
from ._trajectories import plot_trajectory as plot_trajectory

__all__ = ["BASIN_COLORS", "BASIN_SPECIAL_COLORS", "BRANCH_STYLES", "CONSTRAINED_STYLES",
           "CRISIS_COLORS", "DEFAULT_METRICS", "EVENT_STYLES", "GREEK_SPELLINGS",
           "PERIOD_COLORS", "SCAN_SPECIAL_COLORS", "SPECIAL_MARKERS", "SURFACE_COLOR",
           "SWEEP_COLORS", "SWEEP_MARKERS", "TRAJECTORY_COLOR", "VARIANT_COLORS",
           "figure_formats", "plot_basins", "plot_bifurcation", "plot_branch", "plot_crisis",
           "plot_lyapunov", "plot_metrics", "plot_orbit", "plot_scan", "plot_trajectory",
           "scan_classes"]
