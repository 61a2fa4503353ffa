"""The continuation functions of the public API: ``continue_orbit``, ``continue_equilibrium``,
``load_branch``."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from .. import _validate as V
from ..errors import ArgumentError, Status
from ..integrate.options import integrator_options
from ..model.spec import as_model
from .branch import (CONTENT_COVERS, CONTENT_HASH, Branch, SpecialPoint, content_hash,
                     special_data_from_text)
from .engine import (STEP_FAILURES, Continuation, ContinuationError, ContinuationSettings,
                     _failure_text, _span, null_space)
from .problems import (CURVE_KINDS, DIB_KINDS, BifurcationCurveProblem,
                       OrbitBranchProblem, curve_locate, curve_stop_at, equilibrium_problem)

_SETTING_NAMES = {f.name for f in dataclasses.fields(ContinuationSettings)}


def _split_options(options: dict, span, ds, max_points):
    """Continuation settings and the remaining (integrator) options, every value checked
    (an :class:`~pwsdyn.ArgumentError` naming it) before any work."""
    st = {k: options.pop(k) for k in list(options) if k in _SETTING_NAMES}
    lo, hi = _span(span)
    ds = V.number("ds", ds, allow_none=True)
    max_points = V.integer("max_points", max_points, lo=1)
    if ds is None:
        width = hi - lo if math.isfinite(hi - lo) else 10.0
        ds = min(0.02, 0.01 * width)
    if "locate" in st:
        loc = st["locate"]
        loc = (loc,) if isinstance(loc, str) else loc
        if not isinstance(loc, (tuple, list)) or not all(isinstance(k, str) for k in loc):
            raise V.fail("locate", "a sequence of kinds of special points", st["locate"])
        st["locate"] = tuple(loc)
    for name in ("stop_at",):
        if name in st:
            raise ArgumentError(f"`{name}` is set by `on_dib`, not by hand")
    if "ds_max" in st:
        st["ds_max"] = V.positive("ds_max", st["ds_max"])
    if "ds_min" in st:
        st["ds_min"] = V.positive("ds_min", st["ds_min"])
    st.setdefault("ds_max", max(abs(ds), 0.2))
    st.setdefault("ds_min", min(1e-7, abs(ds)) if ds else 1e-7)
    return ContinuationSettings(ds=ds, span=(lo, hi), max_points=max_points, **st), options


#: Which way a branch goes from its start: both sides of it, or one (the parameter up or
#: down at the start).
DIRECTIONS = ("both", "up", "down")


def _direction(direction, ds, span, lam0, name):
    """The sides to follow from ``lam0``: ``direction`` if given, else the sign of an
    explicit ``ds`` (one side), else both. A start outside ``span`` is refused (its special
    points would lie outside it); on the span's boundary only the side inside remains."""
    if direction is not None:
        direction = V.choice("direction", direction, DIRECTIONS)
        if ds is not None and direction != "both" and (ds > 0) != (direction == "up"):
            raise ArgumentError(f"`ds` = {ds} goes {'up' if ds > 0 else 'down'} but "
                                f"direction = {direction!r}")
    elif ds is not None:
        direction = "up" if ds > 0 else "down"
    else:
        direction = "both"
    lo, hi = span
    if not lo <= lam0 <= hi:
        raise ArgumentError(f"the start lies outside `span`: {name} = {lam0:.10g} is not in "
                            f"({lo:.10g}, {hi:.10g})")
    if direction == "both" and lam0 >= hi:
        return "down"
    if direction == "both" and lam0 <= lo:
        return "up"
    return direction


def _sides(side, settings, direction):
    """The branch from ``side(ds, max_points)`` (a :class:`Branch` from the start with the
    step ``ds``, its sign the side) on the side(s) ``direction`` asks for; on both, the two
    joined through the start in the order of arclength, ``max_points`` shared."""
    step = abs(settings.ds)
    if direction != "both":
        return side(step if direction == "up" else -step, settings.max_points)
    down = side(-step, max(1, (settings.max_points + 1) // 2))
    up = side(step, max(1, settings.max_points - len(down) + 1))
    return _joined(down, up, settings)


def _joined(down: Branch, up: Branch, settings) -> Branch:
    """One branch from the two halves that leave the same start: the far end of ``down``
    first, arclength increasing through the start (at the arclength it has in ``up``), the
    tangents along that order; the start once."""
    dpts = [p.to_point() for p in down.points]
    upts = [p.to_point() for p in up.points]
    s0 = upts[0].arclength
    for p in dpts:
        p.arclength = 2.0 * s0 - p.arclength
        p.tangent = -p.tangent
    nd = len(down.problems)
    for p in upts:
        if p.signature_index:
            p.signature_index += nd - 1
    problems = list(down.problems) + list(up.problems[1:])
    failed = [b for b in (down, up) if b.stop_status is not None and b.stop_status.failed]
    last = failed[0] if failed else up
    reason = f"down: {down.stop_reason}; up: {up.stop_reason}"
    return Branch(down.problem, dpts[:0:-1] + upts, stop_reason=reason,
                  stop_status=last.stop_status, settings=settings, model=up.model,
                  problems=problems, origin=up.origin)


def _oriented(tangent, ds):
    """``tangent`` turned so that the parameter moves the way the sign of ``ds`` says
    (negative: to smaller values); where the parameter does not move along it (a fold),
    along the direction it had, turned by the sign."""
    t = np.asarray(tangent, dtype=float)
    if abs(t[-1]) > 1e-9 * np.linalg.norm(t):
        return t if (t[-1] > 0) == (ds > 0) else -t
    return t * np.sign(ds)


#: Kinds of discontinuity-induced bifurcations at which an orbit branch changes signature.
ON_DIB = ("switch", "stop", "continue")


def _run(problem, u0, lam0, settings, *, tangent=None, correct_start=True, progress=False,
         model=None, start_kind="", on_dib="continue", options=None, origin="",
         arclength0=0.0):
    """Follow a branch; on an orbit branch with ``on_dib="switch"`` go on past each graze
    with the orbit's new signature, ``"stop"`` end there, ``"continue"`` keep the signature
    (points past the graze are not admissible)."""
    orbit = getattr(problem, "kind", "") == "orbit" and hasattr(problem, "orbit_problem")
    st = settings
    if orbit and on_dib in ("switch", "stop"):
        st = dataclasses.replace(settings, stop_at=tuple(settings.stop_at) + DIB_KINDS)
    cont = Continuation(problem, u0, lam0, st, tangent=tangent, correct_start=correct_start,
                        progress=progress, start_kind=start_kind, arclength0=arclength0)
    cont.run()
    points, problems = list(cont.points), [problem]
    reason, status = cont.stop_reason, cont.stop_status
    while (orbit and on_dib == "switch" and cont.stop_point is not None
           and len(points) < settings.max_points):
        try:
            nxt = _after_graze(problems[-1], cont.stop_point, st, options or {}, points)
        except STEP_FAILURES as exc:
            # the branch so far is kept: the failure is its end, not the caller's exception
            nxt = f"the orbit past the graze could not be built ({_failure_text(exc)})"
        if isinstance(nxt, str):
            reason, status = f"{reason}; {nxt}", Status.SWITCH_FAILED
            break
        prob2, u1, lam1, ds = nxt
        problems.append(prob2)
        st2 = dataclasses.replace(st, ds=ds, max_points=settings.max_points - len(points))
        try:
            cont = Continuation(prob2, u1, lam1, st2, progress=progress,
                                arclength0=points[-1].arclength)
            cont.run()
        except ContinuationError as exc:
            reason = f"{reason}; the orbit past the graze could not be followed: {exc}"
            status = Status.SWITCH_FAILED
            break
        for q in cont.points:
            q.signature_index = len(problems) - 1
        points += cont.points
        reason, status = cont.stop_reason, cont.stop_status
    if orbit:
        _singular_grazes(points)
    return Branch(problem, points, stop_reason=reason, stop_status=status, settings=settings,
                  model=model, problems=problems, origin=origin)


#: Why a graze seen from the impacting side has no multipliers.
GRAZE_SINGULAR = ("an impact at zero normal velocity: its saltation matrix is unbounded "
                  "(its entries grow like the inverse of the velocity), so the orbit's "
                  "multipliers are not defined at the graze seen from the impacting side")


def _singular_grazes(points) -> None:
    """A graze located by an impact's velocity monitor (``GR/<surface>@<segment>``: the
    impacting side) states its singularity: the multipliers there are NaN, and
    ``data["singular"]`` says why (numerically they were of order 1e12, a value of the
    round-off in the vanishing velocity)."""
    for p in points:
        key = str(p.data.get("located", ""))
        if p.special == "GR" and "@" in key:
            mu = np.asarray(p.data.get("multipliers", ()), dtype=complex)
            p.data["multipliers"] = np.full(mu.shape, complex(np.nan, np.nan))
            p.data["singular"] = GRAZE_SINGULAR


def _after_graze(bp, pt, settings, options, points=()):
    """The orbit just past the graze ``pt`` (a point of ``bp``) with the signature it has
    there (:func:`pwsdyn.continuation.dib.past_graze`): ``(problem, u, lam, ds)``, or why
    there is none. The restart is a short step ``delta`` from the graze: far enough for the
    new orbit's Newton to be regular (its new impact's velocity grows like ``sqrt(delta)``),
    near enough to lose nothing of the branch that matters; past it in the direction of
    travel, or back where a non-smooth fold turns the branch
    (:func:`pwsdyn.continuation.dib.restart`, which marks the graze point so)."""
    from .dib import restart

    op = bp.orbit_problem
    key = pt.data.get("located", "")
    # past the graze is away from where the branch came from (not along the tangent: where a
    # sliding segment shrinks to nothing the old branch folds back at the graze itself)
    tiny = 1e-9 * (1.0 + abs(pt.lam))
    came = next((q.lam for q in reversed(points) if abs(q.lam - pt.lam) > tiny), None)
    direction = (float(np.sign(pt.lam - came)) if came is not None else
                 float(np.sign(pt.tangent[-1])) or float(np.sign(settings.ds)) or 1.0)
    # the new signature's orbit that connects there, on either side (a non-smooth fold turns
    # back), the offset shrunk past a second bifurcation closer than it
    made = restart(op, key, pt.u, pt.lam, direction, settings.span, 1e-4 * (1.0 + abs(pt.lam)))
    if isinstance(made, str):
        return made
    prob1, u1, lam1, direction, fold = made
    if fold:
        pt.data["nonsmooth_fold"] = True
    u1 = _reduce_phase(prob1, u1)
    return OrbitBranchProblem(prob1), u1, lam1, direction * abs(settings.ds)


def continue_orbit(model, orbit, param: str, *, span=None, ds: float | None = None,
                   max_points: int = 200, params=None, on_dib: str = "switch",
                   direction: str | None = None, progress: bool = False,
                   **options) -> Branch:
    """Follow a periodic orbit in a parameter by pseudo-arclength continuation.

    Folds (``LP``), period doublings (``PD``), Neimark-Sacker points (``NS``), branch points
    (``BP``) and grazings (``GR``: a segment touching an impact or switching surface, or an
    impact whose velocity goes to zero) are located on the way. At a graze the orbit's
    signature (its sequence of events) changes: by default the branch goes on with the new
    one (``on_dib="switch"``: an impact added or removed), or it ends there (``"stop"``), or
    it keeps the old signature (``"continue"``), whose points past the graze are not orbits
    of the hybrid model and are marked ``admissible = False`` with the reason.

    Parameters
    ----------
    model : Model, str, path or dict
        The model (the orbit's).
    orbit : PeriodicOrbit, SpecialPoint or Branch
        Where to start: a converged orbit (:func:`pwsdyn.find_periodic_orbit`); a special
        point of an orbit branch -- a ``PD`` starts the period-doubled branch born there, a
        ``BP`` the other branch through it, a discontinuity-induced bifurcation (``GR``,
        ``GS``, ``SS``) the orbit with its new event sequence past it (in the direction the
        branch was going), any other kind the same branch from there; or a branch (from a
        file too), continued from its last point.
    param : str
        The parameter continued.
    span : (float, float), optional
        The parameter's range; the branch ends on its boundary. The start must lie in it.
    ds : float, optional
        First step in arclength. Given, its sign chooses one side of the start (negative:
        towards smaller parameter values; from a branch or a special point of the same branch,
        too). Default ``min(0.02, 0.01 (hi - lo))``, on both sides.
    max_points : int
        Most points (the start and the special points included; a hard bound).
    params : dict, optional
        Other parameter values (default the orbit's).
    on_dib : {'switch', 'stop', 'continue'}
        What happens at a discontinuity-induced bifurcation (a graze).
    direction : {'both', 'up', 'down'}, optional
        From an orbit: follow the branch on both sides of the start (the default without
        ``ds``; the branch ordered by arclength through the start, ``max_points`` shared), or
        on one, the parameter going up or down. A start on the boundary of ``span`` goes into
        it. From a branch (resumed from its last point) or a special point of the same
        branch, the branch goes on in its direction of travel unless ``ds`` or ``"up"`` /
        ``"down"`` say otherwise.
    progress : bool
        Show a progress bar.
    **options
        :class:`~pwsdyn.continuation.ContinuationSettings` fields (``ds_min``, ``ds_max``,
        ``tol``, ``locate``, ``locate_tol``, ``max_angle``, ``predictor``, ...), and
        integrator options of the orbit problem (``rtol``, ``atol``, ``method``, ...).

    Returns
    -------
    Branch

    Examples
    --------
    >>> import pwsdyn
    >>> orb = pwsdyn.find_periodic_orbit("impact-oscillator", [0.0, -0.5])
    >>> br = pwsdyn.continue_orbit("impact-oscillator", orb, "omega", span=(2.3, 2.7))
    """
    from ..orbits.problem import OrbitProblem

    model = as_model(model, kind="flow", caller="continue_orbit()")
    param = _parameter(model, param)
    on_dib = V.choice("on_dib", on_dib, ON_DIB)
    if direction is not None:
        V.choice("direction", direction, DIRECTIONS)
    if params is not None:
        model.parameter_vector(params)          # names and values checked
    settings, options = _split_options(dict(options), span, ds, max_points)
    ds = None if ds is None else settings.ds
    if options:
        integrator_options(options, "continue_orbit()")
    if isinstance(orbit, Branch):
        return _resume(orbit, model, param, settings, progress, ds=ds, direction=direction,
                       on_dib=on_dib, options=options)
    if isinstance(orbit, SpecialPoint):
        _same_model(orbit.branch, model, "the special point")
        return _from_special(orbit, model, param, settings, progress, params, options, on_dib,
                             ds=ds, direction=direction)
    from ..orbits import PeriodicOrbit

    if not isinstance(orbit, PeriodicOrbit):
        raise ArgumentError(f"`orbit` must be a PeriodicOrbit, a SpecialPoint or a Branch, got "
                            f"{type(orbit).__name__}")
    if orbit.model.name != model.name:
        raise ArgumentError(f"the orbit is of model {orbit.model.name!r}, not {model.name!r}")
    prob, u = OrbitProblem.from_orbit(orbit, parameters=[param], params=params)
    if options:
        prob = _with_options(prob, options)
    u = _reduce_phase(prob, u)
    lam0 = float(prob.p0[0])
    way = _direction(direction, ds, settings.span, lam0, param)
    bp = OrbitBranchProblem(prob)

    def side(step, n):
        return _run(bp, u, lam0, dataclasses.replace(settings, ds=step, max_points=n),
                    progress=progress, model=model, on_dib=on_dib, options=options)

    return _sides(side, settings, way)


def _same_model(branch, model, what):
    """A branch or special point continued with another model than its own is refused (its
    unknowns mean nothing there)."""
    own = getattr(branch, "model", None)
    if own is not None and getattr(own, "hash", None) != model.hash:
        raise ArgumentError(f"{what} is of model {own.name!r} (hash {own.hash}), not of "
                            f"{model.name!r} (hash {model.hash}): continue it with its own "
                            f"model")


def _reduce_phase(prob, u):
    """A forced orbit's start time ``t_0`` brought into ``[0, P)`` (``P`` its period, a
    multiple of the forcing period: the same orbit). An orbit found after a long transient
    starts at a large ``t_0``, whose derivative in the parameter (``k dP/dp`` for ``k``
    periods) would dominate the arclength and shrink every step in the parameter."""
    if not (prob.forced and prob.m):
        return u
    P = prob.period_value()
    k = math.floor(u[0] / P)
    if k:
        u = np.array(u, dtype=float)
        u[0] -= k * P
    return u


def _parameter(model, param):
    if not isinstance(param, str) or param not in model.parameters:
        raise ArgumentError(f"model {model.name!r} has no parameter {param!r}; its parameters: "
                            f"{list(model.parameters)}")
    return param


def _with_options(prob, options):
    """The problem with integrator options changed (those given to continue_orbit)."""
    from ..integrate.simulate import DEFAULTS

    return prob.replace(**{k: v for k, v in options.items() if k in DEFAULTS and k not in
                           ("variational", "dense", "throw", "mode", "sliding")})


def _from_special(sp: SpecialPoint, model, param, settings, progress, params, options,
                  on_dib="switch", *, ds=None, direction=None):
    br = sp.branch
    if br.kind != "orbit":
        raise ArgumentError(f"continue_orbit needs a special point of an orbit branch, got one "
                            f"of a {br.kind} branch")
    base: OrbitBranchProblem = sp.problem
    op = base.orbit_problem
    pt = sp.point
    all_params = dict(op.params)
    all_params[base.parameter] = pt.lam
    if params:
        all_params.update(params)
    if param != base.parameter or params:
        # the same orbit, another parameter (or other values): a new problem, corrected there
        prob = op.replace(params=all_params, parameters=[param])
        if options:
            prob = _with_options(prob, options)
        way = _direction(direction, ds, settings.span, all_params[param], param)
        bp = OrbitBranchProblem(prob)

        def side(step, n):
            return _run(bp, pt.u, all_params[param],
                        dataclasses.replace(settings, ds=step, max_points=n),
                        progress=progress, model=model, on_dib=on_dib, options=options)

        return _sides(side, settings, way)
    _direction("up" if direction == "both" else direction, ds, settings.span, pt.lam, param)
    if sp.kind == "PD":
        return _switch_period_doubling(sp, model, settings, progress, options, on_dib)
    if sp.kind in DIB_KINDS:
        # from a discontinuity-induced bifurcation: on with the orbit's new event sequence
        st = dataclasses.replace(settings, ds=math.copysign(settings.ds, pt.tangent[-1] or 1.0)
                                 if settings.ds > 0 else settings.ds)
        nxt = _after_graze(base, pt, st, options)
        if isinstance(nxt, str):
            raise ContinuationError(nxt, Status.SWITCH_FAILED)
        prob1, u1, lam1, ds1 = nxt
        return _run(prob1, u1, lam1, dataclasses.replace(settings, ds=ds1),
                    progress=progress, model=model, on_dib=on_dib, options=options,
                    origin=sp.kind)
    if sp.kind == "BP":
        J = np.column_stack(base.evaluate(pt.u, pt.lam)[1:])
        return _switch_branch_point(base, pt, J, model, settings, progress, on_dib)
    # the same branch from the point: on in its direction of travel, or the way ds or
    # direction says (negative: to smaller values, not back along the branch)
    way = ds if ds is not None else {"up": 1.0, "down": -1.0}.get(direction)
    tangent = pt.tangent if way is None else _oriented(pt.tangent, way)
    return _run(base, pt.u, pt.lam, dataclasses.replace(settings, ds=abs(settings.ds)),
                tangent=tangent, correct_start=False,
                progress=progress, model=model, start_kind=sp.kind, on_dib=on_dib,
                options=options, origin=sp.kind)


def _switch_period_doubling(sp, model, settings, progress, options, on_dib="switch"):
    """The period-doubled branch born at a period doubling: the orbit run twice solves the
    problem of the doubled signature, whose Jacobian ``F_u`` is singular there (the
    multiplier -1 of one period is +1 of two); the new branch leaves along its null vector,
    the flip ``+w`` on the first period, ``-w`` on the second, at fixed parameter (a
    pitchfork of the doubled problem; Kuznetsov, section 10.3.2)."""
    base = sp.problem
    op = base.orbit_problem
    pt = sp.point
    params = dict(op.params)
    params[base.parameter] = pt.lam
    prob2 = op.replace(signature=op.signature.doubled(), params=params,
                       periods=2 * op.periods)
    if options:
        prob2 = _with_options(prob2, options)
    t0, xs, Ts = op.unpack(pt.u)
    u2 = prob2.pack(t0, list(xs) + list(xs), list(Ts) + list(Ts))
    bp2 = OrbitBranchProblem(prob2)
    # the doubled problem's [F_u F_lam] has a two-dimensional null space at the point: the
    # tangent of the period-1 branch run twice, and the flip direction (w, -w); the new
    # branch leaves along the null vector orthogonal to the period-1 branch, so that the
    # corrector does not fall back onto it
    dt0, dxs, dTs = op.unpack(pt.tangent[:-1])
    t1 = np.append(prob2.pack(dt0, list(dxs) + list(dxs), list(dTs) + list(dTs)),
                   pt.tangent[-1])
    t1 /= np.linalg.norm(t1)
    _, F_u, F_lam = bp2.evaluate(u2, pt.lam)
    N = null_space(np.column_stack([F_u, F_lam]), 2)
    cand = [n - (n @ t1) * t1 for n in N]
    v = max(cand, key=np.linalg.norm)
    v /= np.linalg.norm(v)
    return _run(bp2, u2, pt.lam, dataclasses.replace(settings, ds=abs(settings.ds)),
                tangent=v, correct_start=False, progress=progress, model=model,
                start_kind="BP", on_dib=on_dib, options=options, origin="PD")


def _switch_branch_point(problem, pt, J, model, settings, progress, on_dib="continue"):
    """The other branch through a branch point: ``[F_u F_lam]`` has a two-dimensional null
    space there, spanned by the branch's tangent and the other branch's; leave along the
    null vector orthogonal to the tangent (Allgower & Georg, section 8.2)."""
    N = null_space(J, 2)
    v = pt.tangent
    cand = [n - (n @ v) * v for n in N]
    w = max(cand, key=np.linalg.norm)
    w = w / np.linalg.norm(w)
    if settings.ds < 0:
        w = -w
    return _run(problem, pt.u, pt.lam, dataclasses.replace(settings, ds=abs(settings.ds)),
                tangent=w, correct_start=False, progress=progress, model=model,
                start_kind="BP", on_dib=on_dib, origin="BP")


def _resume(branch: Branch, model, param, settings, progress, *, ds=None, direction=None,
            on_dib="switch", options=None):
    """The branch continued from its last point, with its own problem (the integrator
    options given replace its own), ``on_dib`` as asked, on in its direction of travel or the
    way ``ds`` / ``direction`` say. The branch must be of ``model`` and its last point must
    solve its problem (a file is checked when it is read; a branch in memory may have been
    changed)."""
    if param != branch.parameter:
        raise ArgumentError(f"the branch continues {branch.parameter!r}, not {param!r}")
    _same_model(branch, model, "the branch")
    if not len(branch):
        raise ArgumentError("the branch has no points to continue from")
    last = branch.points[-1].to_point()
    problem = branch.problem_of(last)
    if options and hasattr(problem, "orbit_problem") and not getattr(problem, "curve", ""):
        problem = OrbitBranchProblem(_with_options(problem.orbit_problem, options))
    _check_solves(problem, last, settings)
    way = ds if ds is not None else {"up": 1.0, "down": -1.0}.get(direction)
    lo, hi = settings.span
    if not lo <= last.lam <= hi:
        raise ArgumentError(f"the branch's last point lies outside `span`: {param} = "
                            f"{last.lam:.10g} is not in ({lo:.10g}, {hi:.10g})")
    tangent = last.tangent if way is None else _oriented(last.tangent, way)
    step = max(abs(last.ds), settings.ds_min) if last.ds else abs(settings.ds)
    st = dataclasses.replace(settings, ds=min(step, settings.ds_max))
    new = _run(problem, last.u, last.lam, st, tangent=tangent, correct_start=False,
               progress=progress, model=model, on_dib=on_dib, options=options,
               arclength0=last.arclength, origin=branch.origin)
    problems = list(branch.problems)
    if problem is branch.problem_of(last):
        first = last.signature_index
    else:
        # other integrator options: the points from here on solve the new problem
        problems.append(problem)
        first = len(problems) - 1
    base = len(problems) - 1
    problems += list(new.problems[1:])
    pts = [p.to_point() for p in new.points]
    for q in pts:
        q.signature_index = first if q.signature_index == 0 else base + q.signature_index
    return Branch(branch.problem, [p.to_point() for p in branch.points][:-1] + pts,
                  stop_reason=new.stop_reason, stop_status=new.stop_status, settings=st,
                  model=model, problems=problems, origin=branch.origin)


def _check_solves(problem, point, settings):
    """Refuse a point that does not solve ``problem`` to the corrector's tolerance (times a
    margin for integrator options other than those it was computed with): a branch changed
    after it was computed, or one of another problem."""
    try:
        F = np.asarray(problem.evaluate(point.u, point.lam)[0], dtype=float)
    except STEP_FAILURES as exc:
        raise ArgumentError(f"the branch's last point cannot be evaluated with its problem "
                            f"({_failure_text(exc)})") from None
    scale = 1.0 + max(float(np.max(np.abs(point.u), initial=0.0)), abs(point.lam))
    res = float(np.max(np.abs(F), initial=0.0)) / scale
    if not res <= 1e3 * settings.tol:
        raise ArgumentError(f"the branch's last point does not solve its problem (residual "
                            f"{res:.3g} > {1e3 * settings.tol:.3g}): the branch was changed "
                            f"or belongs to another problem")


def continue_equilibrium(model, x0, param: str, *, span=None, ds: float | None = None,
                         max_points: int = 200, params=None, mode: str | None = None,
                         progress: bool = False, **options) -> Branch:
    """Follow an equilibrium of one mode of an autonomous model, or a pseudo-equilibrium of a
    Filippov switch, in a parameter.

    Folds (``LP``), Hopf points (``HB``) and branch points (``BP``) are located on the way.

    Parameters
    ----------
    model : Model, str, path or dict
    x0 : sequence, dict or SpecialPoint
        A guess of the equilibrium (corrected first); or a special point of an equilibrium
        branch: at a ``BP`` the other branch through it is followed, from any other kind the
        same branch.
    param : str
    span, ds, max_points, params, progress, **options
        As :func:`continue_orbit`.
    mode : str, optional
        The mode whose field vanishes (default the model's initial mode); ``"slide:<switch>"``
        for pseudo-equilibria of a Filippov switch (the sliding field vanishes on the surface;
        not admissible where the point leaves the sliding region).

    Returns
    -------
    Branch
    """
    model = as_model(model, kind="flow", caller="continue_equilibrium()")
    param = _parameter(model, param)
    if params is not None:
        model.parameter_vector(params)
    if mode is not None and not isinstance(mode, str):
        raise V.fail("mode", "a mode name, 'slide:<switch>' or None", mode)
    settings, options = _split_options(dict(options), span, ds, max_points)
    if options:
        raise ArgumentError(f"unknown options for continue_equilibrium(): {sorted(options)}")
    if isinstance(x0, SpecialPoint):
        br = x0.branch
        if br.kind == "orbit" or param != br.parameter:
            raise ArgumentError(f"continue_equilibrium from a special point needs one of an "
                                f"equilibrium branch in {param!r}")
        pt = x0.point
        if x0.kind == "BP":
            J = np.column_stack(br.problem.evaluate(pt.u, pt.lam)[1:])
            return _switch_branch_point(br.problem, pt, J, model, settings, progress)
        return _run(br.problem, pt.u, pt.lam, dataclasses.replace(settings, ds=abs(settings.ds)),
                    tangent=pt.tangent * np.sign(settings.ds), correct_start=False,
                    progress=progress, model=model, start_kind=x0.kind)
    prob = equilibrium_problem(model, param, params=params, mode=mode)
    x = V.state_vector(model, x0)
    if prob.kind == "pseudo-equilibrium":
        # alpha from the fields at the guess (corrected with x)
        fp, fm, _, _, _, hx = prob._fields(x, prob.params[param])
        g = hx[:model.n_states]
        den = g @ (fm - fp)
        x = np.append(x, (g @ fm) / den if den != 0 else 0.5)
    return _run(prob, x, prob.params[param], settings, progress=progress, model=model)


def load_branch(path) -> Branch:
    """Read a branch written by :meth:`Branch.save`: its points, special points and the
    problem, so that it can be plotted, inspected and continued further
    (``continue_orbit(model, branch, param)``).

    The file's content hash (``content_sha256``, written by :meth:`Branch.save`) is checked
    first: a file changed after it was written, truncated, or missing what a branch needs is
    refused with an :class:`~pwsdyn.ArgumentError` naming the file and what is wrong. A file
    without a hash (written by an earlier pwsdyn) is read with a warning."""
    from .._netcdf import open_dataset

    try:
        ds = open_dataset(path)
    except FileNotFoundError:
        raise
    except Exception as exc:   # h5py/netCDF4 raise OSError, KeyError, ValueError... alike
        raise ArgumentError(f"{str(path)!r} is not a readable NetCDF file "
                            f"({type(exc).__name__}: {exc})") from None
    if ds.attrs.get("pwsdyn_type") != "branch":
        raise ArgumentError(f"{str(path)!r} is not a branch file (pwsdyn_type = "
                            f"{ds.attrs.get('pwsdyn_type')!r})")
    stored = ds.attrs.get(CONTENT_HASH)
    if stored is None:
        import warnings

        warnings.warn(f"{str(path)!r} carries no content hash (written by pwsdyn "
                      f"{ds.attrs.get('pwsdyn_version', '?')}): its content is not checked",
                      stacklevel=2)
    try:
        if stored is not None:
            if str(stored) != content_hash(ds):
                raise ArgumentError(f"{str(path)!r} was changed after it was written: its "
                                    f"content does not match its content hash "
                                    f"(content_sha256)")
            # only what the hash covers is read (a file may carry more: the discontinuity
            # map `pwsdyn grazing --out` adds)
            covered = set(json.loads(ds.attrs.get(CONTENT_COVERS, "[]")))
            ds = ds.drop_vars([k for k in ds.data_vars if k not in covered])
        return _branch_of_dataset(ds)
    except ArgumentError as exc:
        if str(path) in str(exc):
            raise
        raise ArgumentError(f"{str(path)!r} is not a complete branch file ({exc})") from None
    except Exception as exc:   # noqa: BLE001 -- any gap of the file is said as one error
        raise ArgumentError(f"{str(path)!r} is not a complete branch file "
                            f"({type(exc).__name__}: {exc})") from None


def _branch_of_dataset(ds) -> Branch:
    from ..model import load_model
    from ..orbits.problem import OrbitProblem
    from .engine import Point

    model = load_model(json.loads(ds.attrs["model_spec"]))
    param = ds.attrs["parameter"]
    params = json.loads(ds.attrs["params"])
    st = json.loads(ds.attrs.get("settings", "{}"))
    st = {k: (tuple(float(x) for x in v) if isinstance(v, list) and k == "span" else
              tuple(v) if isinstance(v, list) else float(v) if v in ("inf", "-inf") else v)
          for k, v in st.items()}
    settings = ContinuationSettings(**st) if st else None
    if ds.attrs["kind"] == "orbit":
        opts = json.loads(ds.attrs.get("options", "{}"))
        curve = ds.attrs.get("curve", "")
        from ..integrate.simulate import DEFAULTS
        opts = {k: v for k, v in opts.items() if k in DEFAULTS and
                k not in ("variational", "dense", "throw", "mode", "sliding")}
        names = [param, ds.attrs["parameter2"]] if curve else [param]
        sigs = json.loads(ds.attrs.get("signatures", json.dumps([ds.attrs["signature"]])))
        pers = json.loads(ds.attrs.get("periods_of_signatures",
                                       json.dumps([int(ds.attrs.get("periods", 1))])))
        trefs = json.loads(ds.attrs.get("t_refs", json.dumps([0.0] * len(sigs))))
        states0 = json.loads(ds.attrs.get("states0", json.dumps([None] * len(sigs))))
        problems = []
        for sig, per, tref, st0 in zip(sigs, pers, trefs, states0):
            kw = {} if sig.strip() and sig != "()" else {"state": st0}
            op = OrbitProblem(model, sig if sig != "()" else (), params=params,
                              parameters=names, periods=per, t_ref=tref, **kw, **opts)
            problems.append(BifurcationCurveProblem(op, curve) if curve
                            else OrbitBranchProblem(op))
        problem = problems[0]
    else:
        problem = equilibrium_problem(model, param, params=params, mode=ds.attrs["mode"])
        problems = [problem]
    spectrum = "multipliers" if problem.kind == "orbit" else "eigenvalues"
    points = []
    sig_index = (ds["signature_index"].values if "signature_index" in ds
                 else np.zeros(ds.sizes["point"], dtype=int))
    for i in range(ds.sizes["point"]):
        k = int(sig_index[i])
        size = problems[k].size
        u = np.asarray(ds["u"].values[i][:size], dtype=float)
        lam = float(ds[param].values[i])
        z = ds[f"{spectrum}_real"].values[i] + 1j * ds[f"{spectrum}_imag"].values[i]
        data = {spectrum: z[np.isfinite(z)], "stable": bool(ds["stable"].values[i]),
                "admissible": bool(ds["admissible"].values[i]),
                "reason": str(ds["reason"].values[i])}
        if "period" in ds:
            data["period"] = float(ds["period"].values[i])
        if "special_data" in ds:
            data.update(special_data_from_text(str(ds["special_data"].values[i])))
        if getattr(problem, "parameter2", None):
            data[problem.parameter2] = float(ds[problem.parameter2].values[i])
        tests = {k[5:].replace(":", "/"): float(ds[k].values[i]) for k in ds.data_vars
                 if k.startswith("test_") and np.isfinite(ds[k].values[i])}
        points.append(Point(u=u, lam=lam, tangent=np.asarray(ds["tangent"].values[i][:size + 1]),
                            ds=float(ds["ds"].values[i]),
                            iterations=int(ds["iterations"].values[i]),
                            arclength=float(ds["arclength"].values[i]), data=data,
                            tests=tests, special=str(ds["special"].values[i]),
                            signature_index=k))
    # files written before branches kept their status hold the text only: the member is then
    # read from its words (Status.of_branch_stop)
    word = str(ds.attrs.get("stop_status", ""))
    return Branch(problem, points, stop_reason=ds.attrs.get("stop_reason", ""),
                  stop_status=Status.from_meaning(word) if word else None,
                  settings=settings, model=model, problems=problems,
                  origin=str(ds.attrs.get("origin", "")))


def continue_bifurcation(model, special_point: SpecialPoint, params, *, span=None, span2=None,
                         ds: float | None = None, max_points: int = 200,
                         direction: str | None = None, progress: bool = False,
                         **options) -> Branch:
    """Follow a fold (``LP``), period doubling (``PD``), Neimark-Sacker point (``NS``), or a
    discontinuity-induced bifurcation (graze ``GR``, grazing-, switching- or adding-sliding
    ``GS``, ``SS``, ``AS``) of a periodic orbit in two parameters: the curve of that bifurcation in the
    parameter plane.

    Each point is an orbit at which the bifurcation's test function (of the multipliers, or
    the grazing monitor) vanishes (the orbit problem bordered by the defining condition;
    :class:`~pwsdyn.continuation.problems.BifurcationCurveProblem`).

    Parameters
    ----------
    model : Model, str, path or dict
    special_point : SpecialPoint
        A located ``LP``, ``PD``, ``NS``, ``GR``, ``GS``, ``SS`` or ``AS`` of an orbit branch
        (:attr:`Branch.special_points`).
    params : (str, str)
        The two parameters; the branch's parameter must be one of them. The first is the
        continuation parameter of the curve (``Branch.values``), the second is solved for
        along it (``Branch.values_of(name)``).
    span : (float, float), optional
        Range of the first parameter; the curve ends on its boundary. The start must lie in
        it.
    span2 : (float, float), optional
        Range of the second; the curve stops when it leaves it. The start must lie in it.
    ds, max_points, direction, progress, **options
        As :func:`continue_orbit`: by default the curve is followed on both sides of the
        special point (in the first parameter), ordered by arclength through it.

    Returns
    -------
    Branch
        ``kind`` ``"orbit"``, ``curve`` the bifurcation's kind.
    """
    model = as_model(model, kind="flow", caller="continue_bifurcation()")
    if not isinstance(special_point, SpecialPoint):
        raise ArgumentError(f"`special_point` must be a SpecialPoint of an orbit branch, got "
                            f"{type(special_point).__name__}")
    sp = special_point
    if sp.branch.kind != "orbit" or sp.kind not in CURVE_KINDS:
        raise ArgumentError(f"two-parameter continuation follows {list(CURVE_KINDS)} points "
                            f"of orbit branches, got {sp.kind!r} of a {sp.branch.kind} branch")
    try:
        p1, p2 = params
    except (TypeError, ValueError):
        raise ArgumentError(f"`params` must be two parameter names, got {params!r}") from None
    p1, p2 = _parameter(model, p1), _parameter(model, p2)
    if p1 == p2:
        raise ArgumentError("`params` must be two different parameters")
    base = sp.problem
    if base.parameter not in (p1, p2):
        raise ArgumentError(f"the special point lies on a branch in {base.parameter!r}; it must "
                            f"be one of `params` {params!r}")
    _same_model(sp.branch, model, "the special point")
    if direction is not None:
        V.choice("direction", direction, DIRECTIONS)
    try:
        lo2, hi2 = _span(span2)
    except ArgumentError as exc:
        raise ArgumentError(str(exc).replace("`span`", "`span2`").replace(
            "span[", "span2[")) from None
    settings, options = _split_options(dict(options), span, ds, max_points)
    ds = None if ds is None else settings.ds
    if options:
        integrator_options(options, "continue_bifurcation()")
    # the codimension-two points of the curve (and the DIBs met on it); a Neimark-Sacker
    # curve ends where it turns into neutral saddles
    settings = dataclasses.replace(settings, locate=curve_locate(sp.kind),
                                   stop_at=curve_stop_at(sp.kind))
    op = base.orbit_problem
    all_params = dict(op.params)
    all_params[base.parameter] = sp.value
    prob = op.replace(params=all_params, parameters=[p1, p2])
    if options:
        prob = _with_options(prob, options)
    curve = BifurcationCurveProblem(prob, sp.kind,
                                    key=sp.key if sp.kind in DIB_KINDS else "")
    U0 = np.append(sp.point.u, all_params[p2])
    if not lo2 <= all_params[p2] <= hi2:
        raise ArgumentError(f"the start lies outside `span2`: {p2} = {all_params[p2]:.10g} is "
                            f"not in ({lo2:.10g}, {hi2:.10g})")
    way = _direction(direction, ds, settings.span, all_params[p1], p1)

    def side(step, n):
        st = dataclasses.replace(settings, ds=step, max_points=n)
        cont = Continuation(curve, U0, all_params[p1], st, progress=progress)
        for pt in cont:
            if not lo2 <= pt.u[-1] <= hi2:
                cont._stop(Status.SPAN2_LEFT, f"{p2} left span2 ({lo2:.10g}, {hi2:.10g})")
                break
        return Branch(curve, cont.points, stop_reason=cont.stop_reason,
                      stop_status=cont.stop_status, settings=st, model=model)

    return _sides(side, settings, way)
