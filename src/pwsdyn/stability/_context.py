"""Kept for the periodic-orbit modules until they import the compiled-model layer itself:
:class:`ModelContext` and the discrete-state helpers live in
:mod:`pwsdyn.integrate.compiled`."""

from ..integrate.compiled import (KernelState as KernelState,  # noqa: F401
                                  ModelContext as ModelContext,
                                  check_state_name as check_state_name,
                                  event_states as event_states,
                                  initial_state as initial_state,
                                  trajectory_start_state as trajectory_start_state)
