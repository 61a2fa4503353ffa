r"""Parameters as states: the model extended by ``p' = 0``.

For a parameter :math:`p` of a model :math:`x' = f(t, x, p)` with surfaces :math:`h(t, x, p)`
and resets :math:`g(t, x, p)`, the extended model has the state :math:`(x, p)` with
:math:`p' = 0` and the reset :math:`p \mapsto p`. Its variational solution is

.. math::

    \frac{\partial (x, p)(t)}{\partial (x, p)(t_0)}
        = \begin{pmatrix} \partial x / \partial x_0 & \partial x / \partial p \\
                          0 & I \end{pmatrix},

so the parameter sensitivities :math:`\partial x(t) / \partial p` of a hybrid trajectory are
the last columns of its Jacobian, and every derivative the code generator writes (``f_x``,
``h_x``, ``g_x``, the saltation matrices built from them) carries the parameter derivatives
``f_p``, ``h_p``, ``g_p`` symbolically, with no new code (the standard device of parameter
continuation codes; e.g. the "parameters as states" option of sensitivity solvers).

What carries over to simulation, checked by ``tests/test_orbit_problem.py``:

* smooth flow, impacts, transitions and Filippov crossings: exact (the saltation matrix of the
  extended model is that of the model bordered by the parameter columns
  ``g_p + (f_out - g_x f_in - g_t) h_p / (h_t + h_x f_in)``);
* the kernel's *projections* onto surfaces move the whole state along the extended gradient:
  the one Newton step onto a switching surface at sliding entry and the removal of round-off
  from the sliding field move a parameter ``p`` that ``h`` depends on at round-off level, and
  the projection of the complete-chattering map onto the sticking manifold moves it by the
  size of that projection (about ``v^2`` for the entry speed ``v`` of the chattering
  sequence). A run of the extended model with sliding or chattering on a surface that depends
  on one of the parameters is then not exactly a run of the model. The orbit problems of
  :mod:`pwsdyn.orbits.problem` do not use the kernel's projections (they integrate each
  segment with its own field and project on the model's states only), so they are exact.
* ``forcing_period``: kept when it does not depend on the parameters made states, dropped
  (``None``) otherwise; the default largest step of a forced model (a quarter period) is then
  gone, so pass ``max_step`` to :func:`pwsdyn.simulate`.
"""

from __future__ import annotations

import dataclasses

import sympy as sp

from ..errors import ArgumentError
from .spec import Event, Mode, Model, Switch, as_model


def with_parameters_as_states(model, names) -> Model:
    """The model with the parameters ``names`` turned into states with zero derivative.

    Parameters
    ----------
    model : Model, str, path or dict
        Anything :func:`pwsdyn.load_model` accepts (a flow).
    names : sequence of str
        Parameters of ``model``, in the order they are appended to the states.

    Returns
    -------
    Model
        States ``model.states + names`` (the parameters' defaults are their usual values);
        parameters: the others. Surfaces, guards and resets are the same expressions (the
        symbols are shared); resets keep each new state; Utkin families get a zero row.

    Examples
    --------
    >>> m = with_parameters_as_states("impact-oscillator", ["sigma"])
    >>> m.states, list(m.parameters)
    (('x', 'v', 'sigma'), ['eps', 'omega', 'r'])
    """
    from .. import _validate as V

    model = as_model(model, kind="flow", caller="with_parameters_as_states()")
    if isinstance(names, str) or not hasattr(names, "__iter__"):
        raise V.fail("names", "a sequence of parameter names", names)
    names = list(names)
    unknown = [k for k in names if not isinstance(k, str) or k not in model.parameters]
    if unknown:
        raise ArgumentError(f"`names` must be parameters of model {model.name!r} "
                            f"{list(model.parameters)}; unknown: {unknown}")
    if len(set(names)) != len(names):
        raise ArgumentError(f"`names` has duplicates: {names}")
    if not names:
        return model
    syms = [sp.Symbol(k, real=True) for k in names]
    zeros = (sp.Integer(0),) * len(names)
    modes = tuple(Mode(m.name, tuple(m.rhs) + zeros) for m in model.modes)
    events = tuple(Event(e.name, e.kind, e.surface, e.direction, e.modes, e.guard,
                         None if e.reset is None else tuple(e.reset) + tuple(syms), e.target,
                         e.terminal)
                   for e in model.events)
    switches = tuple(Switch(s.name, s.surface, s.above, s.below, s.kind,
                            None if s.family is None else tuple(s.family) + zeros)
                     for s in model.switches)
    families = tuple(dataclasses.replace(f, rhs=tuple(f.rhs) + zeros) for f in model.families)
    fp = model.forcing_period
    if fp is not None and any(sp.sympify(fp).has(s) for s in syms):
        fp = None
    suffix = "+" + ",".join(names)
    name = model.name[:128 - len(suffix)] + suffix if len(model.name + suffix) > 128 \
        else model.name + suffix
    return Model(name=name, states=tuple(model.states) + tuple(names),
                 parameters={k: v for k, v in model.parameters.items() if k not in names},
                 modes=modes, surfaces=model.surfaces, events=events, switches=switches,
                 families=families,
                 description=model.description, reference=model.reference,
                 definitions=dict(model.definitions), forcing_period=fp,
                 initial_mode=model.initial_mode, origin=model.origin, spec={})
