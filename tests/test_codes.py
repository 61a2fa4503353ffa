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
    """Every name of an enumeration has the code of its position (a kind appended at the end
    gets the next code; nothing else moves)."""
    for names, prefix in ((C.EVENT_LOG_KINDS, "K_"), (C.MODEL_EVENT_KINDS, "EV_"),
                          (C.ACTIONS, "ACT_")):
        for code, name in enumerate(names):
            assert getattr(C, prefix + name.upper()) == code, (prefix, name)


def test_kernel_reads_the_shared_codes():
    from pwsdyn.integrate._load import kernel

    K = kernel()
    for name in dir(C):
        if name.isupper() and isinstance(getattr(C, name), int) and hasattr(K, name):
            assert getattr(K, name) == getattr(C, name), name


def test_kernel_options_fills_named_fields():
    o = C.kernel_options(mode0=2, n_modes=3, max_steps=10, max_events=5, method=1,
                         variational=C.VAR_SEGMENTS, chatter=False, save=C.SAVE_NODES,
                         stop=(1 << C.K_IMPACT, 0, 4), dkind0=C.STICK, didx0=1, exact=1,
                         order=8, rtol=1e-6, atol=1e-9, first_step=0.1, max_step=2.0,
                         chatter_ratio=-1e-3, chatter_velocity=-1.0, sliding_gain=0.5,
                         sample=(0.25, 0.5))
    assert o.dtype == C.KERNEL_OPTIONS and o.shape == (1,)
    assert {name: o[0][name].item() for name in C.KERNEL_OPTIONS.names} == dict(
        mode0=2, n_modes=3, max_steps=10, max_events=5, method=1, variational=C.VAR_SEGMENTS,
        chatter=0, save=C.SAVE_NODES, stop_mask=1, stop_ref=0, stop_count=4, dkind0=C.STICK,
        didx0=1, exact=1, order=8, rtol=1e-6, atol=1e-9, first_step=0.1, max_step=2.0,
        chatter_ratio=-1e-3, chatter_velocity=-1.0, sliding_gain=0.5, sample_t0=0.25,
        sample_dt=0.5)
    o = C.kernel_options(mode0=0, n_modes=1, max_steps=1, max_events=1, method=0,
                         rtol=1e-6, atol=1e-9, chatter_ratio=-1e-3)[0]
    assert (o["stop_mask"], o["didx0"], o["sample_dt"], o["max_step"]) == (0, -1, 0.0, np.inf)


def test_kernel_options_have_the_compiled_type():
    """Whatever the caller passes (numpy integers and floats, a bool, an integer tolerance),
    the options have the one type the kernel is compiled for: a value of another type would
    not match the kernel's signature. What is not a number is refused."""
    from numba import typeof

    from pwsdyn.integrate._kernel._base import OPTIONS_TYPE

    o = C.kernel_options(mode0=np.int32(1), n_modes=np.int64(2), max_steps=10,
                         max_events=np.uint8(5), method=True, chatter=np.bool_(True),
                         stop=(np.int16(1), -1, 2), rtol=1, atol=np.float32(1e-9),
                         first_step=0, chatter_ratio=np.float64(-1e-3), sample=(0, 1))
    assert typeof(o) == OPTIONS_TYPE
    assert o[0]["max_steps"] == 10 and o[0]["rtol"] == 1.0 and o[0]["stop_ref"] == -1
    base = dict(mode0=0, n_modes=1, max_steps=1, max_events=1, method=0, rtol=1e-6,
                atol=1e-9, chatter_ratio=-1e-3)
    for bad in (dict(rtol=None), dict(max_steps=1.5), dict(max_steps=10.0), dict(mode0="0")):
        with pytest.raises(TypeError):
            C.kernel_options(**{**base, **bad})


def test_kernel_tables_are_named_records_of_the_compiled_type():
    """The event and switch tables hold each column as a named field, with the values of the
    model (an impact from the region x < 1 into it, a Filippov switch between two modes
    whose second surface moves in time), and have the types the kernel is compiled for."""
    from numba import typeof

    from pwsdyn.integrate._kernel._base import EVENT_TABLE_TYPE, SWITCH_TABLE_TYPE
    from pwsdyn.integrate.compiled import ModelContext

    model = {"name": "tables", "states": ["x", "v"], "parameters": {"w": 2.0},
             "modes": {"up": {"x": "v", "v": "-1"}, "down": {"x": "v", "v": "1"}},
             "switches": [{"name": "sw", "surface": "v - sin(w*t)", "above": "up",
                           "below": "down"}],
             "events": [{"name": "wall", "kind": "impact", "surface": "1 - x",
                         "reset": {"v": "-0.5*v"}},
                        {"name": "mark", "kind": "transition", "surface": "x + 1",
                         "direction": 1, "target": "down", "terminal": True}]}
    ctx = ModelContext(model, sliding="utkin")
    etab, stab = ctx.etab, ctx.stab
    assert etab.dtype == C.EVENT_TABLE and stab.dtype == C.SWITCH_TABLE
    assert typeof(etab) == EVENT_TABLE_TYPE and typeof(stab) == SWITCH_TABLE_TYPE
    wall, mark = etab
    assert (wall["kind"], wall["terminal"], wall["has_reset"]) == (C.EV_IMPACT, 0, 1)
    assert (mark["kind"], mark["direction"], mark["terminal"]) == (C.EV_TRANSITION, 1, 1)
    assert mark["target"] == ctx.model.mode_index("down")
    assert wall["time_dependent"] == 0 and wall["surface"] != mark["surface"]
    (sw,) = stab
    assert (sw["above"], sw["below"]) == (ctx.model.mode_index("up"),
                                          ctx.model.mode_index("down"))
    assert (sw["kind"], sw["sliding"], sw["time_dependent"]) == (C.SW_FILIPPOV, C.SLIDE_UTKIN, 1)


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
