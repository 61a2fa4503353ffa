"""Discrete control of a parameter (the constraint position): the low-cost control of the
thesis's Papers B-E as a model transformation.

At the moments the orbit crosses a control section ``C`` (the stroboscopic section
``t = t_c`` mod the forcing period, or any event surface) a parameter ``delta`` -- the
position of the impact surface -- is updated by a law, and held in between. The controlled
model carries ``delta`` as a state with ``delta' = 0`` and the update as the reset of a
transition event on ``C``, so that every analysis of the package (simulation, orbits and
their multipliers, sweeps, continuation, the discontinuity map) sees the controlled system.

The section can also be events of the model itself (``section="event:stop_neg"``): the
update is then added to those events' resets. This is the section of a law that acts where
the model already has an event and a surface section would be degenerate -- thesis eq. 5.3
updates the constraint of the friction impact oscillator at the crossings of ``{v = 0}``,
and ``v`` is identically 0 while the mass sticks, so the surface ``v`` is crossed only at
the events that end a slip (``stop_*`` / ``reverse_*`` of the zoo model).
The law is

* ``"linear"`` (thesis eq. 5.2): ``delta -> delta* + c . (x - x*) + c0 (delta - delta*)``, with
  parameters ``delta_star``, ``c0``, ``c_<state>`` and ``x_star_<state>`` added to the model
  (defaults: ``delta*`` the parameter's value, everything else 0: no control);
* or any expression in the states (``delta`` among them) and parameters.

With the linear law, where the smooth dynamics does not depend on ``delta`` (away from
impacts), the Jacobian of the controlled period map is block triangular,
``[[M, 0], [c^T ..., c0]]``: its multipliers are those of the uncontrolled orbit and ``c0``
(thesis section 5.2; checked by ``tests/test_control.py``).
"""

from __future__ import annotations

import copy

from ..errors import ArgumentError
from .spec import Model, as_model

#: Laws of :func:`~pwsdyn.with_discrete_control` known by name.
LAWS = ("linear",)


def with_discrete_control(model, parameter: str, *, section: str = "stroboscopic",
                          law: str = "linear", law_params=None,
                          name: str | None = None) -> Model:
    """The model with ``parameter`` updated by a discrete control law at a section.

    Parameters
    ----------
    model : Model, str, path or dict
        A flow model built from a definition (a zoo name, a file, a dict).
    parameter : str
        The controlled parameter (the constraint position): it becomes a state of the same
        name, constant between the control events.
    section : str
        ``"stroboscopic"`` (forced models: ``t = t_c`` modulo the forcing period, ``t_c`` a new
        parameter, default 0), the expression of a surface ``h(t, x, p)`` whose zeros (in
        either direction) are the control moments, or ``"event:<name>[,<name>...]"``: events
        of the model, whose resets then also set the parameter to the law. The law is then
        evaluated, like the rest of the event's reset, at the state just before the event,
        and acts exactly when (and only when) the event fires; no event is added.
    law : str
        ``"linear"`` (eq. 5.2, with its parameters added) or an expression of the new value in
        the states and parameters.
    law_params : dict, optional
        Parameters of an expression ``law`` added to the model with their default values
        (gains, references), so that one controlled model serves every value of them and
        they can be swept or continued. Their names must be new.
    name : str, optional
        The controlled model's name (default ``"<model>+control(<parameter>)"``).

    Returns
    -------
    Model
        With its definition (``model.spec``), so that results saved from it carry it.

    Examples
    --------
    >>> m = with_discrete_control("impact-oscillator", "sigma")
    >>> m.states
    ('x', 'v', 'sigma')
    """
    from .spec import load_model

    base = as_model(model, kind="flow", caller="with_discrete_control()")
    if not isinstance(parameter, str) or parameter not in base.parameters:
        raise ArgumentError(f"model {base.name!r} has no parameter {parameter!r}; its "
                            f"parameters: {list(base.parameters)}")
    spec = copy.deepcopy(dict(base.spec or {}))
    if not spec.get("modes"):
        raise ArgumentError(f"model {base.name!r} has no definition to extend (build it from a "
                            f"zoo name, a file or a dict)")
    states = list(spec["states"])
    params = dict(spec.get("parameters", {}))
    defaults = dict(spec.get("defaults", {}) or {})
    d_params = dict(defaults.get("params", {}) or {})
    value = float(base.parameters[parameter])
    params.pop(parameter, None)
    d_params.pop(parameter, None)
    states.append(parameter)
    modes = {}
    for mname, rhs in spec["modes"].items():
        rhs = dict(rhs)
        rhs[parameter] = "0"
        modes[mname] = rhs
    on_events: list[str] = []
    events = [dict(e) for e in spec.get("events", [])]
    if isinstance(section, str) and section.startswith("event:"):
        on_events = [n.strip() for n in section[len("event:"):].split(",")]
        known = [e.get("name") for e in events]
        bad = [n for n in on_events if n not in known]
        if not on_events or bad or len(set(on_events)) != len(on_events):
            raise ArgumentError(f"`section` {section!r} must name distinct events of model "
                                f"{base.name!r} after 'event:'; its events: {known}")
        surface = None
    elif section == "stroboscopic":
        if base.forcing_period is None:
            raise ArgumentError(f"model {base.name!r} is autonomous: a stroboscopic section "
                                f"needs a forcing period; give the section as a surface")
        if "t_c" in params or "t_c" in states:
            raise ArgumentError("the name t_c (the section's time) is taken")
        params["t_c"] = 0.0
        surface = f"sin(pi*(t - t_c)/({spec['forcing_period']}))"
    elif isinstance(section, str) and section.strip():
        surface = section
    else:
        raise ArgumentError(f"`section` must be 'stroboscopic', 'event:<name>' or a surface "
                            f"expression, got {section!r}")
    if law == "linear":
        new = {"delta_star": value, "c0": 0.0}
        for s in base.states:
            new[f"c_{s}"] = 0.0
            new[f"x_star_{s}"] = 0.0
        taken = [k for k in new if k in params or k in states]
        if taken:
            raise ArgumentError(f"the names {taken} of the linear law's parameters are taken")
        params.update(new)
        expr = " + ".join(["delta_star"] + [f"c_{s}*({s} - x_star_{s})" for s in base.states]
                          + [f"c0*({parameter} - delta_star)"])
    elif isinstance(law, str) and law.strip():
        expr = law
        from .. import _validate as V

        new = {k: V.number(f"law_params[{k!r}]", v)
               for k, v in V.mapping("law_params", law_params).items()}
        taken = [k for k in new if not isinstance(k, str) or k in params or k in states]
        if taken:
            raise ArgumentError(f"the names {taken} of `law_params` are taken")
        params.update(new)
    else:
        raise ArgumentError(f"`law` must be 'linear' or an expression, got {law!r}")
    if law_params and law == "linear":
        raise ArgumentError("`law_params` are for an expression law; the linear law has its "
                            "own parameters")
    if on_events:
        # the update composed with the event's own reset: both are evaluated at the state
        # before the event, so the law sees the same x the event does
        for ev in events:
            if ev.get("name") in on_events:
                ev["reset"] = {**dict(ev.get("reset") or {}), parameter: expr}
    else:
        events.append({"name": "control", "kind": "transition", "surface": surface,
                       "direction": 0, "reset": {parameter: expr}})
    x0 = dict(defaults.get("x0", {}) or {})
    if isinstance(defaults.get("x0"), dict):
        x0[parameter] = value
        defaults["x0"] = x0
    if d_params:
        defaults["params"] = d_params
    else:
        defaults.pop("params", None)
    if defaults:
        spec["defaults"] = defaults
    spec.update(name=name or f"{base.name}+control({parameter})", states=states,
                parameters=params, modes=modes, events=events)
    units = dict(spec.get("units", {}) or {})
    desc = dict(spec.get("descriptions", {}) or {})
    if law == "linear":
        for k in ("delta_star", "c0"):
            units.setdefault(k, units.get(parameter, "1") if k == "delta_star" else "1")
        desc.setdefault("delta_star", f"reference value of the controlled {parameter}")
        desc.setdefault("c0", f"gain on the deviation of {parameter} from delta_star")
        for s in base.states:
            desc.setdefault(f"c_{s}", f"control gain on {s}")
            desc.setdefault(f"x_star_{s}", f"reference value of {s} at the control section")
    if section == "stroboscopic":
        units.setdefault("t_c", units.get("t", "1"))
        desc.setdefault("t_c", "time of the control section (modulo the forcing period)")
    # units of new parameters whose unit follows from their meaning are left out
    spec["units"] = {k: v for k, v in units.items()
                     if k in ("t",) or k in states or k in params}
    spec["descriptions"] = {k: v for k, v in desc.items()
                            if k in ("t",) or k in states or k in params}
    return load_model(spec)
