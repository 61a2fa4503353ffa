"""Global analysis: brute-force bifurcation diagrams (:func:`~pwsdyn.sweep`), two-parameter
period maps (:func:`~pwsdyn.scan`), basins of attraction (:func:`~pwsdyn.basins`) and Lyapunov spectra (:func:`~pwsdyn.lyapunov_spectrum`) of
piecewise-smooth flows and maps, chunked, parallel (threads by default, or Dask) and resumable from
a store on disk; comfort and rattle-space metrics of a response (:mod:`pwsdyn.explore.metrics`)."""

from ._lyapunov import LyapunovSpectrum as LyapunovSpectrum
from ._lyapunov import lyapunov_spectrum as lyapunov_spectrum
from ._store import StoreMismatchError as StoreMismatchError
from ._sweep import sweep as sweep
from ._scan import scan as scan
from ._basins import basin_fractions as basin_fractions
from ._basins import basins as basins
from .metrics import ResponseMetrics as ResponseMetrics
from .metrics import metrics_sweep as metrics_sweep
from .metrics import response_metrics as response_metrics
