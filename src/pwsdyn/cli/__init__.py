"""The ``pwsdyn`` command line.

``pwsdyn models`` lists the built-in models; ``pwsdyn simulate MODEL`` simulates a built-in
model or a model file and writes the trajectory (NetCDF) and a figure (PNG); ``pwsdyn sweep``,
``pwsdyn scan`` and ``pwsdyn basins`` compute bifurcation diagrams, two-parameter period maps
and basins of attraction (parallel on threads or Dask, resumable) and write their datasets and
figures; ``pwsdyn orbit MODEL``
finds a periodic orbit by Newton shooting and prints its period, signature and Floquet
multipliers; ``pwsdyn continue`` follows it in a parameter and ``pwsdyn grazing`` to its
first graze, where it prints Nordmark's discontinuity map; ``pwsdyn manifold`` finds a saddle
(a map's periodic point, a forced flow's periodic orbit) and grows its stable and unstable
manifolds.

One name for one thing in every command that runs a model (``pwsdyn.cli._common``, whose
``prepare`` is the preamble they all share):

* ``-p/--param NAME=VALUE`` sets a parameter (repeatable); ``-s/--set NAME=VALUE`` is a
  synonym (hidden; ``sweep`` and ``basins`` used it first). In ``sweep`` the swept parameter
  is ``--sweep NAME``; ``--param NAME`` without ``=VALUE`` still names it (the spelling
  before ``--sweep``), and in ``continue`` and ``grazing`` it names the continued parameter:
  an argument with ``=`` sets a value, one without names a parameter.
* ``--x0``, ``--rtol``, ``--atol``, ``--method``, ``--sliding``, ``--out``, ``--plot`` and
  ``--force`` are in every one of them and mean the same; ``--exact`` in those that
  simulate (``simulate``, ``sweep``, ``basins``: shooting integrates the variational
  equations, which the exact propagator does not carry); ``--no-progress`` where there is a
  progress bar (``sweep``, ``basins``, ``continue``, ``grazing``); ``--workers`` and
  ``--scheduler`` where the work is parallel (``sweep``, ``basins``).

Defaults are the library's: a model's ``[defaults]`` table (``params``, ``x0``, ``t0``,
``t_end``) is applied by :func:`pwsdyn.simulate`, :func:`pwsdyn.sweep`, :func:`pwsdyn.basins`,
:func:`pwsdyn.lyapunov_spectrum` and :func:`pwsdyn.find_periodic_orbit` exactly as here
(:func:`pwsdyn.model.spec.run_defaults`; the parameters through ``model.parameters``), and the
option defaults equal the API's (``sweep --direction both`` as ``pwsdyn.sweep(direction=
"both")``, ``--transient``, ``--samples``, tolerances, methods; tests/test_defaults.py keeps
them equal). Integrator options not given are not passed on, so the library's defaults
apply: those of a simulation, or the tighter ones of shooting in ``orbit``, ``continue`` and
``grazing`` (``--rtol 1e-12``, ``--method DOP853``; each help text says why).

Every file a command writes is listed on stdout (``wrote PATH``; a kept ``--store`` as
``store PATH``), the second figure ``<plot>-lyapunov.<ext>`` of ``sweep --lyapunov --plot``
included.

Errors in the arguments or the model, and failed simulations, are reported as one line
``Error: ...`` without a traceback: exit code 2 for a bad argument (click's convention for
usage errors), 1 for a model that cannot be loaded or a simulation that fails. Every error of
pwsdyn's own (:class:`pwsdyn.PwsdynError`) is reported that way (exit code 1); any other
exception is a bug and shows its traceback.

Output files (``--out``, ``--plot`` and the second figure ``<plot>-lyapunov.<ext>`` of
``sweep --lyapunov --plot``) are checked before any work starts: the directory must exist
and be writable, the suffix must be one the writer knows (NetCDF: ``.nc`` ...; figures: the
formats matplotlib writes, e.g. ``.png``, ``.pdf``, ``.svg``) and an existing file is never
replaced unless ``--force`` is given (exit code 2 for a wrong suffix, 1 for the others). The
data are written before the figure; if the figure still cannot be written at the end and no
``--out`` was given, the data are saved next to it as ``<plot stem>.nc`` (``-1``, ``-2``...
if that exists) and the error message says where. A sweep store (``--store``) is a resumable
directory: it is resumed, never replaced.

Text that comes from a model or a file (names, descriptions, messages) is printed through one
sanitiser, ``_safe``: control characters (C0, C1, ESC, DEL) and Unicode bidirectional
controls are shown as escapes (``\\x1b``, ``\\u202e``), so a model cannot drive the terminal.

The package: ``_output`` (terminal output, output files), ``_common`` (the shared options
and the preamble), ``_main`` (the group and ``models``) and one module per family of commands
(``_simulate``, ``_explore``, ``_scan``, ``_orbits``, ``_manifold``, ``_crisis``), each
registering its commands on ``main``.
"""

from __future__ import annotations

from . import _crisis, _explore, _manifold, _orbits, _scan, _simulate  # noqa: F401  (commands)
from ._common import FALLBACK_T_END
from ._main import main
from ._output import NETCDF_SUFFIXES, _safe  # noqa: F401  (_safe: the one sanitiser)

__all__ = ["FALLBACK_T_END", "NETCDF_SUFFIXES", "main"]
