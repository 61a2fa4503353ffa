"""Stability of hybrid trajectories: saltation matrices, transfer matrices, Poincaré maps,
Floquet multipliers.

The variational equations are integrated by the compiled kernel (``simulate(...,
variational=True)``), per smooth segment, with the saltation matrix of every event; the
trajectory keeps them as ``transfer_matrices``. This package reads them: :func:`segments`,
:func:`~pwsdyn.monodromy`, the two forms of saltation matrix (:func:`~pwsdyn.saltation_matrix`,
full and projected, thesis eq. 2.36), Poincaré maps with Jacobians
(:func:`~pwsdyn.poincare_map`, thesis eq. 2.25) and :func:`~pwsdyn.floquet_multipliers`.
"""

from ._floquet import floquet_multipliers as floquet_multipliers
from ._poincare import (PoincareResult as PoincareResult,
                        SectionNotReachedError as SectionNotReachedError,
                        poincare_map as poincare_map)
from ._saltation import (event_saltations as event_saltations,
                         saltation_matrix as saltation_matrix)
from ._transfer import Segment as Segment, monodromy as monodromy, segments as segments
