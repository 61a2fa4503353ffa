"""The integer codes are defined once (pwsdyn.integrate._codes): the enumerations that other
modules still spell out as names agree with them, the kernel uses them, and the option
builder fills every slot the kernel reads."""

import numpy as np
import pytest

from pwsdyn import Status
from pwsdyn.integrate import _codes as C


def test_name_tuples_elsewhere_agree_with_the_codes():
    from pwsdyn.integrate import trajectory
    from pwsdyn.model import codegen, spec
    from pwsdyn.orbits import signature

    assert tuple(trajectory.EVENT_KINDS) == C.EVENT_LOG_KINDS
    assert tuple(signature.KINDS) == C.EVENT_LOG_KINDS
    assert tuple(trajectory.STATE_KINDS) == C.STATE_KINDS
    assert tuple(spec.EVENT_KINDS) == C.MODEL_EVENT_KINDS
    assert codegen.EVENT_KIND_CODES == {k: i for i, k in enumerate(C.MODEL_EVENT_KINDS)}
    # the integrator's outcomes are the non-negative members of the one status vocabulary
    assert [s.value for s in Status.integrator_outcomes()] == list(range(len(C.STATUSES)))


def test_codes_are_their_positions():
    assert (C.K_IMPACT, C.K_SLIDE_END) == (0, len(C.EVENT_LOG_KINDS) - 1)
    assert C.EVENT_LOG_KINDS[C.K_CHATTER] == "chatter"
    assert C.ACTIONS[C.ACT_RELEASE] == "release"
    assert C.INT_OPTIONS[C.IO_EXACT] == "exact" and C.IO_N == len(C.INT_OPTIONS)
    assert C.FLOAT_OPTIONS[C.FO_SAMPLE_DT] == "sample_dt" and C.FO_N == len(C.FLOAT_OPTIONS)


def test_kernel_reads_the_shared_codes():
    from pwsdyn.integrate._load import kernel

    K = kernel()
    for name in dir(C):
        if name.isupper() and isinstance(getattr(C, name), int) and hasattr(K, name):
            assert getattr(K, name) == getattr(C, name), name


def test_kernel_options_fills_named_slots():
    iopt, fopt = C.kernel_options(mode0=2, n_modes=3, max_steps=10, max_events=5, method=1,
                                  variational=C.VAR_SEGMENTS, chatter=False, save=C.SAVE_NODES,
                                  stop=(1 << C.K_IMPACT, 0, 4), dkind0=C.STICK, didx0=1,
                                  exact=1, order=8, rtol=1e-6, atol=1e-9, first_step=0.1,
                                  max_step=2.0,
                                  chatter_ratio=-1e-3, chatter_velocity=-1.0, sliding_gain=0.5,
                                  sample=(0.25, 0.5))
    assert iopt.dtype == np.int64 and fopt.dtype == float
    assert iopt.shape == (C.IO_N,) and fopt.shape == (C.FO_N,)
    assert list(iopt) == [2, 3, 10, 5, 1, C.VAR_SEGMENTS, 0, C.SAVE_NODES, 1, 0, 4, C.STICK, 1,
                          1, 8]
    assert list(fopt) == [1e-6, 1e-9, 0.1, 2.0, -1e-3, -1.0, 0.5, 0.25, 0.5]
    iopt, fopt = C.kernel_options(mode0=0, n_modes=1, max_steps=1, max_events=1, method=0,
                                  rtol=1e-6, atol=1e-9, chatter_ratio=-1e-3)
    assert iopt[C.IO_STOP_MASK] == 0 and iopt[C.IO_DIDX0] == -1
    assert fopt[C.FO_SAMPLE_DT] == 0.0 and fopt[C.FO_HMAX] == np.inf


def test_kernel_result_names_the_tuple():
    import pwsdyn

    model = {"name": "decay", "states": ["x"], "modes": {"m": {"x": "-x"}}}
    traj = pwsdyn.simulate(model, [1.0], (0, 1), exact=False)
    assert traj.status is Status.SUCCESS
    assert C.KernelResult._fields[-1] == "hstep" and len(C.KernelResult._fields) == 17
    assert set(traj.stats) == set(C.STATS)


@pytest.mark.parametrize("name", ["REGULAR", "STICK", "SLIDE"])
def test_start_uses_the_shared_states(name):
    from pwsdyn.integrate import _start

    assert getattr(_start, name) == getattr(C, name)
