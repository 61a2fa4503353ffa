"""Response metrics of a forced piecewise-smooth system: comfort and rattle space.

The measures by which a vehicle suspension is judged (thesis section 3 and Paper C), in a
form that applies to any model with an impact constraint:

* **comfort**: the RMS and the peak of an acceleration -- the time derivative of a velocity
  state (the body's ``vs`` in the quarter-car) -- over a time window;
* **rattle space**: the range of a travel -- any expression in the states, parameters and
  ``t`` (the suspension's ``zs - zu``) -- and the impacts on a constraint (the bumpstop):
  their number and largest normal velocity, and the impulse they transmit.

The acceleration is the velocity's component of the model's vector field (not a derivative
of the numerical solution), evaluated in the discrete state the trajectory is in (a mode,
sticking on a constraint, sliding). At an impact the velocity jumps: its derivative holds a
Dirac impulse, which an RMS cannot take. It is therefore split off: the **smooth** part of
the acceleration (the field, between the jumps) gives the RMS and the peak, and each impact
contributes its **impulse** ``|v+ - v-|`` (per unit mass: a velocity change) to a separate
sum, with the number of impacts. A chattering sequence (infinitely many impacts, jumped over
by the simulator's complete-chattering map, :func:`pwsdyn.simulate`) counts once in
``chatter`` and contributes the velocity change of the jump less what the smooth field gives
over the sequence's duration (the field is integrated across it along the straight line the
trajectory stores there), so that for any window

    v(t_to) - v(t_from) = integral of the smooth acceleration + sum of the signed impulses.

:func:`~pwsdyn.explore.response_metrics` evaluates the metrics of one trajectory (Gauss-Legendre
quadrature of the squared acceleration on each step of the dense output, exact for the polynomial
there up to degree ``2 nodes - 1``); :func:`~pwsdyn.explore.metrics_sweep` evaluates them over a
range of a parameter for several variants of a model -- a fixed and a controlled bumpstop
(:func:`pwsdyn.with_discrete_control`) -- continuing the state from value to value as a
brute-force bifurcation diagram does, and returns an :class:`xarray.Dataset`;
:func:`pwsdyn.plot.plot_metrics` draws it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import sympy as sp

from .. import _validate as V
from ..errors import ArgumentError

#: The metrics, in the order of :meth:`~pwsdyn.explore.ResponseMetrics.as_dict`, with their
#: descriptions.
METRICS = {
    "rms_acceleration": "RMS of the smooth acceleration over the window",
    "peak_acceleration": "largest magnitude of the smooth acceleration over the window",
    "travel_min": "smallest value of the travel over the window",
    "travel_max": "largest value of the travel over the window",
    "travel_range": "travel_max - travel_min",
    "impacts": "impacts on the constraint in the window",
    "chatter": "chattering sequences on the constraint in the window",
    "impact_velocity_max": "largest normal velocity of an impact (or of the first impact of "
                           "a chattering sequence) in the window",
    "impulse": "sum of the velocity jumps |v+ - v-| of the impacts and chattering sequences "
               "in the window (impulse per unit mass)",
    "stick_time": "time spent sticking on the constraint in the window",
}


@dataclass(frozen=True)
class ResponseMetrics:
    """Comfort and rattle-space metrics of a trajectory over a window (module docstring).

    Attributes
    ----------
    t_from, t_to : float
        The window.
    rms_acceleration, peak_acceleration : float
        RMS and largest magnitude of the smooth acceleration (impulses excluded).
    travel_min, travel_max : float
        Extremes of the travel (NaN without a travel).
    impacts : int
        Impacts on the constraint (its impact events; chattering sequences not included).
    chatter : int
        Chattering sequences on the constraint.
    impact_velocity_max : float
        Largest normal velocity ``|h_t + h_x f|`` just before an impact or a chattering
        sequence (0 without any).
    impulse : float
        Sum of the velocity jumps ``|v+ - v-|`` of the impacts and chattering sequences.
    stick_time : float
        Time spent sticking on the constraint.
    """

    t_from: float
    t_to: float
    rms_acceleration: float
    peak_acceleration: float
    travel_min: float
    travel_max: float
    impacts: int
    chatter: int
    impact_velocity_max: float
    impulse: float
    stick_time: float

    @property
    def duration(self) -> float:
        return self.t_to - self.t_from

    @property
    def travel_range(self) -> float:
        return self.travel_max - self.travel_min

    def as_dict(self) -> dict:
        """The metrics of :data:`~pwsdyn.explore.metrics.METRICS` by name."""
        return {k: getattr(self, k) for k in METRICS}


# ======================================================================================
# arguments
# ======================================================================================
def _velocity_index(model, velocity) -> int:
    if not isinstance(velocity, str) or velocity not in model.states:
        raise V.fail("velocity", f"a state of model {model.name!r} {list(model.states)} (the "
                     f"state whose time derivative is the acceleration measured)", velocity)
    return list(model.states).index(velocity)


def _impact_events(model, event) -> list:
    """Indices of the impact events measured: ``event`` by name, or every impact event."""
    impacts = [j for j, e in enumerate(model.events) if e.kind == "impact"]
    if event is None:
        return impacts
    names = [model.events[j].name for j in impacts]
    if not isinstance(event, str) or event not in names:
        raise V.fail("event", f"None or an impact event of model {model.name!r} {names}",
                     event)
    return [impacts[names.index(event)]]


def _travel_function(model, travel):
    """The travel expression as a function of ``(t, x, p)`` rows (or None)."""
    if travel is None:
        return None
    from ..model.expressions import parse_expression
    from ..model.spec import TIME

    if not isinstance(travel, str):
        raise V.fail("travel", "None or an expression in the states, parameters and t (a "
                     "string, e.g. 'zs - zu')", travel)
    t = sp.Symbol(TIME, real=True)
    xs = model.state_symbols
    ps = model.parameter_symbols
    names = {TIME: t, **{str(s): s for s in xs}, **{str(s): s for s in ps}}
    names.update(getattr(model, "definitions", {}) or {})
    expr = parse_expression(travel, names, field="travel")
    # the parsed tree holds only whitelisted functions and known symbols (never user text)
    f = sp.lambdify((t, xs, ps), expr, modules="numpy")

    def rows(ts, X, p):
        out = f(ts, X.T, p)
        return np.broadcast_to(np.asarray(out, dtype=float), ts.shape)
    return rows


def _linear_unit(model, expr) -> str | None:
    """The unit of ``expr`` where it is a linear combination (numeric coefficients, plus a
    constant) of states and parameters that all have one unit (``zs - zu``, the bumpstop's
    ``zs - zu + delta``); None otherwise."""
    expr = sp.sympify(expr)
    syms = sorted(expr.free_symbols, key=str)
    if not syms or any(str(s) == "t" for s in syms):
        return None
    try:
        poly = sp.Poly(expr, *syms)
    except sp.PolynomialError:
        return None
    if poly.total_degree() > 1:
        return None
    units = {model.unit(str(s)) for s in syms}
    return units.pop() if len(units) == 1 and None not in units else None


# ======================================================================================
# one trajectory
# ======================================================================================
def response_metrics(traj, velocity: str, *, travel: str | None = None,
                     event: str | None = None, t_from: float | None = None,
                     t_to: float | None = None, nodes: int = 4) -> ResponseMetrics:
    """Comfort and rattle-space metrics of a trajectory over a window.

    Parameters
    ----------
    traj : Trajectory
        A simulated trajectory with its dense output (:func:`pwsdyn.simulate`, the default
        ``dense=True``).
    velocity : str
        The state whose time derivative is the acceleration measured (the quarter-car's
        body velocity ``"vs"``).
    travel : str, optional
        An expression in the states, parameters, definitions and ``t`` whose range is the
        rattle space (``"zs - zu"``); without it the travel metrics are NaN.
    event : str, optional
        The impact event counted (``"bumpstop"``); default every impact event of the model.
    t_from, t_to : float, optional
        The window (default the whole trajectory): a settled part, after the transient.
    nodes : int
        Gauss-Legendre nodes per step of the quadrature of the squared acceleration
        (default 4: exact for a polynomial acceleration of degree 3 on a step). The peak and
        the travel extremes are taken over these nodes and both ends of every step (the
        nodes of the trajectory, which include both sides of every event).

    Returns
    -------
    ResponseMetrics

    Raises
    ------
    ArgumentError
        A trajectory without dense output, a window outside it, an unknown state, event or
        name in ``travel``.

    Examples
    --------
    >>> import pwsdyn
    >>> from pwsdyn.explore.metrics import response_metrics
    >>> traj = pwsdyn.simulate("bouncing-ball", {"y": 1.0, "v": 0.0}, (0, 3),
    ...                        params={"A": 0.0, "e": 0.5})
    >>> m = response_metrics(traj, "v", travel="y")
    >>> round(m.rms_acceleration / 9.81, 3), round(m.travel_range, 9)   # in flight 1.35 s of 3
    (0.672, 1.0)
    """
    from ..integrate.trajectory import DiscreteState, Trajectory
    from ..integrate.compiled import ModelContext

    if not isinstance(traj, Trajectory):
        raise V.fail("traj", "a Trajectory (pwsdyn.simulate)", traj)
    if traj.dense is None:
        raise ArgumentError("`traj` has no dense output (simulated with dense=False): the "
                            "metrics integrate along it")
    model = traj.model
    iv = _velocity_index(model, velocity)
    evs = _impact_events(model, event)
    trav = _travel_function(model, travel)
    nodes = V.integer("nodes", nodes, lo=1, hi=20)
    T0, T1 = float(traj.t[0]), float(traj.t[-1])
    a = T0 if t_from is None else V.number("t_from", t_from, lo=T0, hi=T1)
    b = T1 if t_to is None else V.number("t_to", t_to, lo=T0, hi=T1)
    if not b > a:
        raise ArgumentError(f"the window must have t_to > t_from, got [{a}, {b}]")

    ctx = ModelContext(model, traj.params)
    p = ctx.p
    t = np.asarray(traj.t, dtype=float)
    X = np.asarray(traj.x, dtype=float)
    nint = len(t) - 1
    lo = np.maximum(t[:-1], a)
    hi = np.minimum(t[1:], b)
    live = np.nonzero(hi > lo)[0]                   # steps (positive length) in the window
    gx, gw = np.polynomial.legendre.leggauss(nodes)
    # the quadrature nodes of every live step, evaluated on the dense output in one call
    # (strictly inside the steps: no side of a jump is ambiguous)
    half = 0.5 * (hi[live] - lo[live])
    mid = 0.5 * (hi[live] + lo[live])
    tq = (mid[:, None] + half[:, None] * gx[None, :]).ravel()
    wq = (half[:, None] * gw[None, :]).ravel()
    Xq = np.asarray(traj(tq), dtype=float).reshape(len(tq), -1) if len(tq) else \
        np.zeros((0, model.n_states))
    # the ends of the steps: the stored nodes where the step is whole, else the dense output
    tl, th = lo[live], hi[live]
    Xl = np.where((tl == t[live])[:, None], X[live],
                  traj(tl, side="right") if len(tl) else X[live])
    Xh = np.where((th == t[live + 1])[:, None], X[live + 1],
                  traj(th, side="left") if len(th) else X[live + 1])

    # the discrete state of each live step (its left node's), with the regular mode a
    # sticking state constrains (the last mode before it)
    states = []
    last_mode = None
    parsed: dict = {}
    for i in range(nint):
        text = str(traj.state[i])
        st = parsed.get(text)
        if st is None:
            st = parsed[text] = DiscreteState.parse(text)
        if st.kind == "mode":
            last_mode = st.name
        states.append((st, last_mode))
    stick_names = {f"stick:{model.events[j].name}" for j in evs}

    acc_q = np.empty(len(tq))
    acc_ends = np.empty(2 * len(live))
    int_acc = np.zeros(nint)                # integral of the smooth acceleration per step
    stick_time = 0.0
    for k, i in enumerate(live):
        st, mode_name = states[i]
        if st.kind == "mode":
            mi = model.mode_index(st.name)

            def f(tt, xx, mi=mi):
                return ctx.mode_field(mi, tt, xx)[iv]
        else:
            ks = ctx.state(st, mode_hint=mode_name)

            def f(tt, xx, ks=ks):
                return ctx.field(tt, xx, ks)[iv]
            if str(st) in stick_names:
                stick_time += th[k] - tl[k]
        sl = slice(k * nodes, (k + 1) * nodes)
        for q in range(k * nodes, (k + 1) * nodes):
            acc_q[q] = f(tq[q], Xq[q])
        acc_ends[2 * k] = f(tl[k], Xl[k])
        acc_ends[2 * k + 1] = f(th[k], Xh[k])
        int_acc[i] = float(wq[sl] @ acc_q[sl])
    dur = b - a
    rms = float(np.sqrt(np.sum(wq * acc_q**2) / dur))
    peak = float(max(np.max(np.abs(acc_q), initial=0.0), np.max(np.abs(acc_ends), initial=0.0)))
    if trav is not None:
        TT = np.concatenate([tq, tl, th])
        XX = np.vstack([Xq, Xl, Xh])
        vals = trav(TT, XX, p)
        tmin, tmax = float(np.min(vals)), float(np.max(vals))
    else:
        tmin = tmax = float("nan")

    # impacts and chattering sequences on the measured constraint(s) in [a, b)
    names = {model.events[j].name: j for j in evs}
    impacts = chatter = 0
    vmax = 0.0
    impulse = 0.0
    kinds = traj.events.kind
    enames = traj.events.name
    for n_e in range(len(traj.events)):
        kind = kinds[n_e]
        if kind not in ("impact", "chatter") or enames[n_e] not in names:
            continue
        e = traj.events[n_e]
        if not a <= e.t < b:
            continue
        j = names[e.name]
        k_s = model.events[j].surface
        before = DiscreteState.parse(str(e.mode_before))
        xb = np.asarray(e.x_before, dtype=float)
        if before.kind == "mode":
            fb = ctx.mode_field(model.mode_index(before.name), e.t, xb)
            vn = float(ctx.h_t(k_s, e.t, xb) + ctx.h_x(k_s, e.t, xb) @ fb)
            vmax = max(vmax, abs(vn))
        dv = float(e.x_after[iv] - e.x_before[iv])
        if kind == "impact":
            impacts += 1
        else:
            chatter += 1
            # the jump over the sequence less the smooth field's share over its duration
            # (the step from t to t_after that the trajectory stores as a straight line)
            i = int(np.searchsorted(t, e.t, side="left"))
            while i < nint and t[i] == e.t and t[i + 1] != e.t_after:
                i += 1
            if i < nint and t[i] == e.t and t[i + 1] == e.t_after:
                dv -= int_acc[i]
        impulse += abs(dv)
    return ResponseMetrics(t_from=a, t_to=b, rms_acceleration=rms, peak_acceleration=peak,
                           travel_min=tmin, travel_max=tmax, impacts=impacts, chatter=chatter,
                           impact_velocity_max=vmax, impulse=float(impulse),
                           stick_time=float(stick_time))


# ======================================================================================
# over a parameter range, for variants of a model
# ======================================================================================
def _variants(variants, param) -> dict:
    from ..model.spec import as_model

    if not isinstance(variants, Mapping) or not variants:
        raise V.fail("variants", "a non-empty mapping of names to models (or to dicts with "
                     "'model' and optionally 'params' and 'x0')", variants)
    out = {}
    for name, v in variants.items():
        if not isinstance(name, str) or not name:
            raise V.fail("variants", "a mapping with non-empty string names", name)
        if isinstance(v, Mapping) and "model" in v:
            extra = set(v) - {"model", "params", "x0"}
            if extra:
                raise ArgumentError(f"variant {name!r}: unknown keys {sorted(extra)} (allowed: "
                                    f"'model', 'params', 'x0')")
            model, params, x0 = v["model"], V.mapping("params", v.get("params")), v.get("x0")
        else:
            model, params, x0 = v, {}, None
        model = as_model(model, kind="flow", caller="metrics_sweep()")
        if param not in model.parameters:
            raise ArgumentError(f"variant {name!r}: model {model.name!r} has no parameter "
                                f"{param!r}")
        if param in params:
            raise ArgumentError(f"variant {name!r}: `params` must not set the swept parameter "
                                f"{param!r}")
        if model.forcing_period is None:
            raise ArgumentError(f"variant {name!r}: model {model.name!r} is autonomous; the "
                                f"transient and the window are counted in forcing periods")
        model.parameter_vector(params)            # names and values checked
        if x0 is None:
            x0 = model.defaults.get("x0")
            if x0 is None:
                raise ArgumentError(f"variant {name!r}: give 'x0' (model {model.name!r} has "
                                    f"no [defaults] x0)")
        out[name] = (model, dict(params), V.state_vector(model, x0, name=f"x0 of {name!r}"))
    return out


def metrics_sweep(variants, param: str, values, *, velocity: str, travel: str | None = None,
                  event: str | None = None, transient: int = 50, periods: int = 20,
                  direction: str = "up", nodes: int = 4, **options):
    """Comfort and rattle-space metrics over a range of a parameter, for variants of a model.

    For each variant and each direction, the values are visited in order (``"up"``:
    increasing; ``"down"``: decreasing) and the state is carried from one value to the next
    in its discrete state (sticking included), as in a brute-force bifurcation diagram, so
    that coexisting attractors show as a difference between the directions. At each value
    ``transient`` forcing periods are run and discarded, then ``periods`` are recorded and
    measured by :func:`response_metrics`.

    Parameters
    ----------
    variants : mapping
        Names (``"fixed"``, ``"controlled"``) to a model, or to a dict with ``"model"`` and
        optionally ``"params"`` (other parameter values) and ``"x0"`` (the first state;
        default the model's ``[defaults] x0``). Every model must have the parameter and a
        forcing period.
    param : str
        The parameter swept (the road amplitude ``"A"``).
    values : sequence of float
        Its values (distinct, finite; sorted here).
    velocity, travel, event, nodes :
        As in :func:`response_metrics`.
    transient, periods : int
        Forcing periods discarded, then measured, at each value.
    direction : {'up', 'down', 'both'}
    **options
        Integrator options of :func:`pwsdyn.simulate`.

    Returns
    -------
    xarray.Dataset
        Dimensions ``variant``, ``direction`` and the parameter (named ``param``); one
        variable per metric of :data:`~pwsdyn.explore.metrics.METRICS`, with ``impacts``,
        ``chatter``, ``impulse`` and ``stick_time`` per forcing period (``impacts_per_period``,
        ...), and ``status`` (0 where the run succeeded; the :class:`pwsdyn.Status` value of a
        failed run, whose metrics are NaN, the next value starting again from ``x0``).

    Examples
    --------
    >>> import numpy as np
    >>> from pwsdyn.explore.metrics import metrics_sweep
    >>> ds = metrics_sweep({"ball": "bouncing-ball"}, "A", [0.01, 0.02], velocity="v",
    ...                    travel="y", transient=5, periods=5)
    >>> ds.rms_acceleration.dims
    ('variant', 'direction', 'A')
    """
    import xarray as xr

    from .._netcdf import cf_global_attrs, quantity_attrs, time_units
    from ..integrate.simulate import simulate

    if not isinstance(param, str):
        raise V.fail("param", "a parameter name (a string)", param)
    vs = _variants(variants, param)
    if V.is_real(values) or isinstance(values, (str, bytes)) or values is None:
        raise V.fail("values", "a non-empty sequence of numbers", values)
    vals = np.sort(V.vector("values", values))
    if vals.size == 0 or np.any(np.diff(vals) == 0):
        raise V.fail("values", "a non-empty sequence of distinct numbers", values)
    transient = V.integer("transient", transient, lo=0)
    periods = V.integer("periods", periods, lo=1)
    direction = V.choice("direction", direction, ("up", "down", "both"))
    dirs = ["up", "down"] if direction == "both" else [direction]
    for model, _, _ in vs.values():            # arguments checked before any run
        _velocity_index(model, velocity)
        _impact_events(model, event)
        _travel_function(model, travel)
    per_period = ("impacts", "chatter", "impulse", "stick_time")
    names = [k if k not in per_period else f"{k}_per_period" for k in METRICS]
    shape = (len(vs), len(dirs), len(vals))
    data = {k: np.full(shape, np.nan) for k in names}
    status = np.zeros(shape, dtype=np.int64)
    opts = {**options, "throw": False}
    for a_i, (vname, (model, params, x0)) in enumerate(vs.items()):
        for d_i, d in enumerate(dirs):
            order = range(len(vals)) if d == "up" else range(len(vals) - 1, -1, -1)
            prev = None
            for j in order:
                prm = {**params, param: float(vals[j])}
                T = model.forcing_period_value(prm)
                start = prev if prev is not None else x0
                t0 = prev.t_final if prev is not None else 0.0
                tr = None
                if transient:
                    tr = simulate(model, start, (t0, t0 + transient * T), params=prm,
                                  dense=False, **opts)
                    start, t0 = tr, tr.t_final
                if tr is None or tr.success:
                    tr = simulate(model, start, (t0, t0 + periods * T), params=prm, **opts)
                if not tr.success:
                    status[a_i, d_i, j] = int(tr.status.value)
                    prev = None
                    continue
                m = response_metrics(tr, velocity, travel=travel, event=event,
                                     nodes=nodes).as_dict()
                for k, v in m.items():
                    key = k if k not in per_period else f"{k}_per_period"
                    data[key][a_i, d_i, j] = v / periods if k in per_period else v
                prev = tr
    first = next(iter(vs.values()))[0]
    tu = time_units(first)
    vu = first.unit(velocity)
    acc_u = f"{vu} {tu}-1" if vu and tu and tu.isidentifier() else None
    travel_u = None
    if travel is not None:
        from ..model.expressions import parse_expression
        from ..model.spec import TIME

        known = {TIME: sp.Symbol(TIME, real=True)}
        known.update({str(q): q for q in first.state_symbols + first.parameter_symbols})
        known.update(getattr(first, "definitions", {}) or {})
        travel_u = _linear_unit(first, parse_expression(travel, known, field="travel"))
    surf = [first.surfaces[first.events[j].surface].expr for j in _impact_events(first, event)]
    hu = {_linear_unit(first, e) for e in surf}
    hu = hu.pop() if len(hu) == 1 else None
    units = {"rms_acceleration": acc_u, "peak_acceleration": acc_u,
             "travel_min": travel_u, "travel_max": travel_u, "travel_range": travel_u,
             "impact_velocity_max": f"{hu} {tu}-1" if hu and tu and tu.isidentifier()
             else None, "impulse_per_period": vu,
             "stick_time_per_period": tu, "impacts_per_period": "1",
             "chatter_per_period": "1"}
    dims = ("variant", "direction", param)
    out = {}
    for k in names:
        base = k.replace("_per_period", "")
        attrs = {"long_name": METRICS[base] + (", per forcing period" if k != base else "")}
        u = units.get(k)
        if u:
            attrs["units"] = u
        out[k] = (dims, data[k], attrs)
    out["status"] = (dims, status, {"long_name": "status of the run (0: success; "
                                                 "pwsdyn.Status values)"})
    coords = {"variant": ("variant", list(vs), {"long_name": "variant of the model"}),
              "direction": ("direction", dirs,
                            {"long_name": "direction of the sweep (up: increasing values)"}),
              param: (param, vals, {**quantity_attrs(first, param),
                                    "comment": "the swept parameter"})}
    attrs = {**cf_global_attrs(first, "metrics",
                               f"pwsdyn response metrics of model {first.name} in {param}",
                               "comfort and rattle-space metrics over a parameter sweep "
                               "(pwsdyn.explore.metrics.metrics_sweep)"),
             "kind": "metrics", "parameter": param, "velocity": velocity,
             "travel": travel or "", "event": event or "",
             "transient": transient, "periods": periods,
             "variants": ", ".join(f"{k}: model {m.name}" for k, (m, _, _) in vs.items())}
    return xr.Dataset(out, coords=coords, attrs=attrs)
