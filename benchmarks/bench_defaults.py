"""Benchmark: ``simulate`` with its default options against scipy, its other paths and a bare
numba Runge-Kutta loop, on a linear and a nonlinear impacting oscillator.

Models (both with a rigid stop ``x <= sigma`` and Newton's restitution ``v -> -r v``):

* ``impact``: the Budd & Dux impact oscillator of ``bench_impact_oscillator.py``,
  ``x'' + 0.1 x' + x = sin(2.2 t)``, ``sigma = 0.1``, ``r = 0.8``: its free flight is affine
  with harmonic forcing (the default ``exact="auto"`` propagates it by its exact flow);
* ``duffing``: a hardening Duffing oscillator ``x'' + c x' + k x + beta x^3 = A cos(omega t)``
  with ``c = 0.2, k = 1, beta = 1, A = 2, omega = 1.2``, ``sigma = 1``, ``r = 0.8``: nonlinear,
  so every path integrates it with a Runge-Kutta pair. From rest it settles on a stable
  period-one orbit with one impact per forcing period (impact speed ~0.66).

Rows, all at ``rtol = 1e-10``, ``atol = 1e-12`` (pwsdyn's defaults), timed in one process,
interleaved, best of ``--repeats``:

* ``default``: ``pwsdyn.simulate(model, x0, (0, N T))`` -- no option at all (method
  ``"auto"``: DOP853 at this tolerance; ``exact="auto"``; dense output stored, rebuilt on
  demand);
* the explicit paths: ``method=RK45 / DOP853`` with ``exact=False``, ``exact=True``, each with
  ``dense=True`` and ``dense=False``; ``RK45 dense=True exact=False`` is what the defaults ran
  before;
* scipy ``solve_ivp`` (RK45, its default, and DOP853) with a terminal event function,
  restarted after each impact -- what a user writes; measured on ``--scipy-periods`` and
  extrapolated per period.

Accuracy: impact times and post-impact velocities over the first ``--compare-impacts``
impacts against a tight reference, scipy DOP853 at ``rtol = 1e-13``, ``atol = 1e-15``
restarted at every impact (and, for ``impact``, the closed form of
``bench_impact_oscillator.py``); the default path's dense output against the reference's on
a grid over the scipy window.

Cost per Runge-Kutta step: a bare numba loop with the same tableau (``pwsdyn``'s RK45 or
DOP853 arrays), the same error norm and step-size control and the model's generated
``evaluate`` called through the same first-class function type as the kernel, no events, over
the same time span, against the kernel's time per step (accepted + rejected) on the model
(with its stop) and on the same model without the stop.

``--tolerance-scan``: RK45 against DOP853 (``exact=False``) per forcing period from
``rtol = 1e-4`` to ``1e-12``: where the default method switches.

``--base PATH``: the non-default paths before and after, in one run: worker processes with
``PYTHONPATH=PATH`` (the previous version's ``src``) and with this checkout's ``src``,
alternating for ``--rounds`` rounds, best per path.

Timings are reported, never asserted. Run::

    python benchmarks/bench_defaults.py [--periods 1000] [--save] [--base /path/to/old/src]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from bench_impact_oscillator import (  # noqa: E402
    DEFAULT_PARAMS as IMPACT_PARAMS, ExactImpactOscillator, Timer, machine_info,
    make_model as impact_model, time_interleaved)
import pwsdyn  # noqa: E402
from pwsdyn.model import compile_model, load_model  # noqa: E402

RTOL, ATOL = 1e-10, 1e-12
X0 = (0.0, 0.0)
DUFFING_PARAMS = {"c": 0.2, "k": 1.0, "beta": 1.0, "A": 2.0, "omega": 1.2, "sigma": 1.0,
                  "r": 0.8}


def duffing_model(params=DUFFING_PARAMS, stop=True) -> dict:
    """The Duffing oscillator with a one-sided stop (without it: ``stop=False``)."""
    return {
        "name": "duffing-stop" if stop else "duffing",
        "description": "Hardening Duffing oscillator, harmonically forced, with a rigid stop",
        "states": ["x", "v"], "parameters": dict(params), "forcing_period": "2*pi/omega",
        "modes": {"free": {"x": "v", "v": "-c*v - k*x - beta*x**3 + A*cos(omega*t)"}},
        "events": ([{"name": "stop", "kind": "impact", "surface": "sigma - x", "direction": -1,
                     "reset": {"v": "-r*v"}}] if stop else []),
    }


def without_stop(model: dict) -> dict:
    return {**model, "name": model["name"] + "-free", "events": []}


def scipy_rhs(name, p):
    if name == "impact":
        eps, w = p["eps"], p["omega"]
        return lambda t, u: [u[1], -eps * u[1] - u[0] + math.sin(w * t)]
    c, k, b, A, w = p["c"], p["k"], p["beta"], p["A"], p["omega"]
    return lambda t, u: [u[1], -c * u[1] - k * u[0] - b * u[0] ** 3 + A * math.cos(w * t)]


MODELS = {
    "impact": dict(model=impact_model(IMPACT_PARAMS), params=IMPACT_PARAMS,
                   period=2 * math.pi / IMPACT_PARAMS["omega"], affine=True),
    "duffing": dict(model=duffing_model(), params=DUFFING_PARAMS,
                    period=2 * math.pi / DUFFING_PARAMS["omega"], affine=False),
}


# ------------------------------------------------------------------------------------------
# scipy: what a user writes, and the tight reference
# ------------------------------------------------------------------------------------------
def scipy_run(name, p, t_end, rtol, atol, method, dense=False):
    """solve_ivp with a terminal impact event, restarted from the reset state after each
    impact. Returns (impact times, post-impact velocities, dense segments or None)."""
    rhs = scipy_rhs(name, p)
    sigma, r = p["sigma"], p["r"]

    def impact(t, u):
        return sigma - u[0]

    impact.terminal = True
    impact.direction = -1
    t, u = 0.0, np.array(X0, dtype=float)
    times, vplus, segs = [], [], []
    while t < t_end:
        sol = solve_ivp(rhs, (t, t_end), u, method=method, events=impact, rtol=rtol, atol=atol,
                        dense_output=dense)
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp failed at t={sol.t[-1]}: {sol.message}")
        if dense:
            segs.append((t, sol.t[-1], sol.sol))
        if sol.status == 0:
            break
        te, ue = sol.t_events[0][0], sol.y_events[0][0].copy()
        ue[0] = sigma
        ue[1] = -r * ue[1]
        times.append(te)
        vplus.append(ue[1])
        t, u = te, ue
    return np.array(times), np.array(vplus), (segs if dense else None)


def eval_segments(segs, ts):
    out = np.empty((len(ts), 2))
    for i, t in enumerate(ts):
        for a, b, f in segs:
            if a <= t <= b:
                out[i] = f(t)
                break
    return out


def impacts_of(traj):
    ev = traj.events
    k = np.asarray(ev.kind) == "impact"
    return np.asarray(ev.t)[k], np.asarray(ev.x_after)[k, 1]


def maxdiff(a, b, k):
    k = min(k, len(a), len(b))
    return float(np.max(np.abs(a[:k] - b[:k]))) if k else float("nan")


# ------------------------------------------------------------------------------------------
# the bare loop: an adaptive embedded Runge-Kutta pair over the generated right-hand side
# ------------------------------------------------------------------------------------------
_BARE = None


def bare_loop():
    """``bare(ev, mode, t0, t_end, x0, p, A, C, E, s, method, rtol, atol, hmax)`` -> (steps,
    rejected, x_end): the kernel's stepping alone -- same tableau arrays, FSAL, error norms
    (RK45: RMS of ``h E K / sc``; DOP853: Hairer's combined 5th/3rd order estimate), step
    factor ``0.9 err^(-1/order)`` within [0.2, 10], largest step ``hmax`` -- and ``ev``
    called through the same first-class function type, no events, no dense output."""
    global _BARE
    if _BARE is not None:
        return _BARE
    import warnings

    from numba import njit, types as nt
    from numba.core.errors import NumbaExperimentalFeatureWarning

    from pwsdyn.model.codegen import EVALUATE_TYPE

    f1, f2 = nt.float64[::1], nt.float64[:, ::1]
    sig = nt.Tuple((nt.int64, nt.int64, f1))(EVALUATE_TYPE, nt.int64, nt.float64, nt.float64,
                                             f1, f1, f2, f1, f2, nt.int64, nt.int64, nt.float64,
                                             nt.float64, nt.float64)

    def bare(ev, mode, t0, t_end, x0, p, A, C, E, s, method, rtol, atol, hmax):
        n = x0.shape[0]
        K = np.zeros((s + 1, n))
        kst = np.zeros(n)    # stage into a vector, then into K (a row view K[st] as the
        y = x0.copy()        # argument costs two atomic reference-count updates)
        ytmp = np.zeros(n)
        t = t0
        ev(0, mode, t, y, p, kst)
        for i in range(n):
            K[0, i] = kst[i]
        order = 5.0 if method == 0 else 8.0
        # initial step as in the kernel (Hairer, Norsett & Wanner I, II.4)
        d0 = 0.0
        d1 = 0.0
        for i in range(n):
            sc = atol + rtol * abs(y[i])
            d0 += (y[i] / sc) ** 2
            d1 += (K[0, i] / sc) ** 2
        d0 = np.sqrt(d0 / n)
        d1 = np.sqrt(d1 / n)
        h = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        steps = 0
        rejected = 0
        while t < t_end:
            h = min(h, hmax, t_end - t)
            for st in range(1, s + 1):
                for i in range(n):
                    acc = 0.0
                    for m in range(st):
                        acc += A[st, m] * K[m, i]
                    ytmp[i] = y[i] + h * acc
                ev(0, mode, t + C[st] * h, ytmp, p, kst)
                for i in range(n):
                    K[st, i] = kst[i]
            if method == 0:
                acc = 0.0
                for i in range(n):
                    e = 0.0
                    for j in range(s + 1):
                        e += E[0, j] * K[j, i]
                    sc = atol + rtol * max(abs(y[i]), abs(ytmp[i]))
                    acc += (h * e / sc) ** 2
                err = np.sqrt(acc / n)
            else:
                e5 = 0.0
                e3 = 0.0
                for i in range(n):
                    a5 = 0.0
                    a3 = 0.0
                    for j in range(s + 1):
                        a5 += E[0, j] * K[j, i]
                        a3 += E[1, j] * K[j, i]
                    sc = atol + rtol * max(abs(y[i]), abs(ytmp[i]))
                    e5 += (a5 / sc) ** 2
                    e3 += (a3 / sc) ** 2
                err = 0.0 if e5 == 0.0 and e3 == 0.0 else abs(h) * e5 / np.sqrt(
                    (e5 + 0.01 * e3) * n)
            if err <= 1.0:
                t = t + h
                for i in range(n):
                    y[i] = ytmp[i]
                    K[0, i] = K[s, i]
                steps += 1
                fac = 10.0 if err == 0.0 else min(10.0, max(0.2, 0.9 * err ** (-1.0 / order)))
            else:
                rejected += 1
                fac = max(0.2, 0.9 * err ** (-1.0 / order))
            h *= fac
        return steps, rejected, y

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
        _BARE = njit(sig, nogil=True)(bare)
    return _BARE


def bare_runner(model: dict, method: str, t_end: float, hmax: float):
    from pwsdyn.integrate.tableaus import METHODS

    m = load_model(model)
    cm = compile_model(m)
    tab = METHODS[method]
    p = np.ascontiguousarray(m.parameter_vector(None), dtype=float)
    fn = bare_loop()
    x0 = np.array(X0, dtype=float)
    return lambda: fn(cm.evaluate, 0, 0.0, t_end, x0, p, tab.A, tab.C, tab.E, tab.n_stages,
                      tab.code, RTOL, ATOL, hmax)


# ------------------------------------------------------------------------------------------
# the measurements
# ------------------------------------------------------------------------------------------
def paths(affine: bool) -> dict:
    """The explicit (non-default) paths: name -> simulate options."""
    out = {}
    for meth in ("RK45", "DOP853"):
        for dense in (True, False):
            out[f"{meth} exact=False dense={dense}"] = dict(method=meth, exact=False,
                                                            dense=dense)
    if affine:
        for dense in (True, False):
            out[f"exact=True dense={dense}"] = dict(exact=True, dense=dense)
    return out


def run_sim(model, t_end, **opts):
    return pwsdyn.simulate(model, X0, (0.0, t_end), **opts)


def measure_model(name, N, Ns, repeats, scipy_repeats, K):
    spec = MODELS[name]
    model, p, T = spec["model"], spec["params"], spec["period"]
    print(f"\n=== {name}: {model['modes']['free']['v']}, stop {p['sigma']} (r = {p['r']}); "
          f"T = {T:.6f}; pwsdyn {N} periods, scipy {Ns} periods")
    rows = {"default": Timer(lambda: run_sim(model, N * T)),
            "default dense=False": Timer(lambda: run_sim(model, N * T, dense=False))}
    for label, o in paths(spec["affine"]).items():
        rows[label] = Timer(lambda o=o: run_sim(model, N * T, max_steps=10 ** 8, **o))
    sp = {"scipy RK45": Timer(lambda: scipy_run(name, p, Ns * T, RTOL, ATOL, "RK45")),
          "scipy DOP853": Timer(lambda: scipy_run(name, p, Ns * T, RTOL, ATOL, "DOP853"))}
    for tm in rows.values():     # first calls: model function load, dense-output compile
        tm.fn()
    time_interleaved([(tm, repeats) for tm in rows.values()]
                     + [(tm, scipy_repeats) for tm in sp.values()])
    # accuracy
    ref_t, ref_v, ref_segs = scipy_run(name, p, Ns * T, 1e-13, 1e-15, "DOP853", dense=True)
    refs = {"scipy DOP853 1e-13": (ref_t, ref_v)}
    if name == "impact":
        refs["closed form"] = ExactImpactOscillator(p).impacts(Ns * T)
    errs = {}
    for label, tm in {**rows, **sp}.items():
        ti, vp = impacts_of(tm.result) if label in rows else tm.result[:2]
        errs[label] = {r: {"dt": maxdiff(ti, rt, K), "dv": maxdiff(vp, rv, K)}
                       for r, (rt, rv) in refs.items()}
    # dense output of the default path against the reference's (first Ns periods)
    dflt = rows["default"].result
    ts = np.linspace(0.0, Ns * T, 2001)
    dense_err = float(np.max(np.abs(dflt(ts) - eval_segments(ref_segs, ts))))
    t0 = time.process_time()
    full = np.asarray(pwsdyn.simulate(model, X0, (0.0, N * T))._dense)
    build_cpu = time.process_time() - t0
    res = {"periods": N, "scipy_periods": Ns, "forcing_period": T, "params": p,
           "impacts_per_period": len(impacts_of(dflt)[0]) / N,
           "default_options": {k: dflt.options[k] for k in ("method", "exact", "dense")},
           "default_stats": dflt.stats, "rows": {}, "dense_output_max_error": dense_err,
           "dense_materialize_cpu_us_per_period": 1e6 * build_cpu / N,
           "dense_shape": list(full.shape)}
    ref_label = "closed form" if name == "impact" else "scipy DOP853 1e-13"
    print(f"{'path':<30}{'us/period':>10}{'CPU us/per':>11}{'scipy RK45/':>12}{'scipy D853/':>12}"
          f"{'steps/per':>10}{'|dt| ref':>10}{'|dv+| ref':>10}")
    sp_rk = 1e6 * sp["scipy RK45"].cpu / Ns
    sp_d8 = 1e6 * sp["scipy DOP853"].cpu / Ns
    for label, tm in {**rows, **sp}.items():
        n = N if label in rows else Ns
        us, cpu = 1e6 * tm.wall / n, 1e6 * tm.cpu / n
        steps = (tm.result.stats["steps"] / n) if label in rows else float("nan")
        e = errs[label][ref_label]
        res["rows"][label] = {"us_per_period": us, "cpu_us_per_period": cpu,
                              "scipy_rk45_over_this_cpu": sp_rk / cpu,
                              "scipy_dop853_over_this_cpu": sp_d8 / cpu,
                              "scipy_rk45_over_this_wall": (1e6 * sp["scipy RK45"].wall / Ns) / us,
                              "steps_per_period": steps, "errors": errs[label]}
        print(f"{label:<30}{us:>10.1f}{cpu:>11.1f}{sp_rk / cpu:>11.0f}x{sp_d8 / cpu:>11.0f}x"
              f"{steps:>10.1f}{e['dt']:>10.1e}{e['dv']:>10.1e}")
    print(f"errors: first {K} impacts against {ref_label}; ratios by CPU time (best of "
          f"{repeats} / {scipy_repeats} interleaved runs), scipy extrapolated per period")
    print(f"default path: options {res['default_options']}; dense output vs reference "
          f"(grid over {Ns} periods): {dense_err:.1e}; building all of it: "
          f"{res['dense_materialize_cpu_us_per_period']:.1f} us/period CPU")
    return res


def measure_steps(name, N, repeats):
    """Kernel cost per Runge-Kutta step against the bare loop (CPU time, best of repeats)."""
    spec = MODELS[name]
    model, T = spec["model"], spec["period"]
    free = without_stop(model)
    hmax = T / 4.0   # the kernel's default largest step for a forced model
    out = {}
    for meth in ("RK45", "DOP853"):
        timers = {
            "bare loop (no events)": Timer(bare_runner(free, meth, N * T, hmax)),
            "kernel, no stop, dense=False": Timer(
                lambda m=meth: run_sim(free, N * T, method=m, exact=False, dense=False,
                                       max_steps=10 ** 8)),
            "kernel, with stop, dense=False": Timer(
                lambda m=meth: run_sim(model, N * T, method=m, exact=False, dense=False,
                                       max_steps=10 ** 8)),
            "kernel, with stop, dense=True": Timer(
                lambda m=meth: run_sim(model, N * T, method=m, exact=False, dense=True,
                                       max_steps=10 ** 8)),
        }
        for tm in timers.values():
            tm.fn()
        time_interleaved([(tm, repeats) for tm in timers.values()])
        res = {}
        for label, tm in timers.items():
            if label.startswith("bare"):
                (st, rj, _), ld = tm.result, 0
            else:
                st, rj = tm.result.stats["steps"], tm.result.stats["rejected_steps"]
                ld = tm.result.stats["landing_steps"]
            res[label] = {"steps": int(st), "rejected": int(rj), "landing": int(ld),
                          "ns_per_step_cpu": 1e9 * tm.cpu / (st + rj),
                          "ns_per_step_wall": 1e9 * tm.wall / (st + rj),
                          "ns_per_rk_step_cpu": 1e9 * tm.cpu / (st + rj + ld)}
        base = res["bare loop (no events)"]["ns_per_step_cpu"]
        for v in res.values():
            v["ratio_to_bare_cpu"] = v["ns_per_step_cpu"] / base
            v["ratio_to_bare_cpu_all_rk_steps"] = v["ns_per_rk_step_cpu"] / base
        out[meth] = res
        print(f"\n{name} {meth}: CPU per step (accepted + rejected; in brackets also counting "
              f"the landing steps on events), best of {repeats}")
        for label, v in res.items():
            print(f"  {label:<32}{v['steps']:>8} steps {v['rejected']:>6} rej {v['landing']:>5} "
                  f"land {v['ns_per_step_cpu']:>6.0f} ns/step  {v['ratio_to_bare_cpu']:.2f}x bare "
                  f"({v['ratio_to_bare_cpu_all_rk_steps']:.2f}x)")
    return out


def tolerance_scan(N, repeats):
    out = {}
    print("\nRK45 vs DOP853 (exact=False, dense=True), CPU us per forcing period")
    for name in ("impact", "duffing"):
        spec = MODELS[name]
        model, T = spec["model"], spec["period"]
        out[name] = {}
        for rtol in (1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 1e-7, 1e-8, 1e-10, 1e-12):
            tms = {m: Timer(lambda m=m: run_sim(model, N * T, method=m, exact=False,
                                                rtol=rtol, atol=rtol * 1e-2,
                                                max_steps=10 ** 8))
                   for m in ("RK45", "DOP853")}
            for tm in tms.values():
                tm.fn()
            time_interleaved([(tm, repeats) for tm in tms.values()])
            us = {m: 1e6 * tm.cpu / N for m, tm in tms.items()}
            out[name][f"{rtol:g}"] = us
            print(f"  {name:<8} rtol {rtol:<6g} RK45 {us['RK45']:7.1f}  DOP853 "
                  f"{us['DOP853']:7.1f}  -> {'DOP853' if us['DOP853'] < us['RK45'] else 'RK45'}")
    # the built-in models, event-dense (sticking, chattering, sliding, kinks): whole default
    # runs, exact=False, and the defaults ('auto' method and exact flow)
    import tomllib

    from pwsdyn.model.spec import zoo_path
    print("\nBuilt-in models, their [defaults] run, CPU ms: RK45 / DOP853 (exact=False) / "
          "default options")
    zoo = ["bouncing-ball", "friction-impact-oscillator", "impact-oscillator",
           "one-legged-jumper", "quarter-car", "relay-feedback", "stick-slip-oscillator"]
    out["zoo_ms"] = {}
    for name in zoo:
        d = tomllib.loads(zoo_path(name).read_text())["defaults"]
        m = load_model(name)
        out["zoo_ms"][name] = {}
        for rtol in (1e-4, 1e-6, 1e-7, 1e-8, 1e-10):
            run = dict(x0=d["x0"], t=d["t_end"], pr=d.get("params"), tol=dict(
                rtol=rtol, atol=rtol * 1e-2, max_steps=10 ** 7))
            tms = {k: Timer(lambda o=o, r=run: pwsdyn.simulate(m, r["x0"], r["t"], r["pr"],
                                                                **r["tol"], **o))
                   for k, o in (("RK45", dict(method="RK45", exact=False)),
                                ("DOP853", dict(method="DOP853", exact=False)),
                                ("default", {}))}
            for tm in tms.values():
                tm.fn()
            time_interleaved([(tm, repeats) for tm in tms.values()])
            ms = {k: 1e3 * tm.cpu for k, tm in tms.items()}
            out["zoo_ms"][name][f"{rtol:g}"] = ms
            print(f"  {name:<28} rtol {rtol:<6g} {ms['RK45']:7.2f} {ms['DOP853']:7.2f} "
                  f"{ms['default']:7.2f}")
    return out


# ------------------------------------------------------------------------------------------
# before / after: worker processes on two versions of the package
# ------------------------------------------------------------------------------------------
def worker_paths():
    """Non-default paths, with every option explicit (the same run on both versions)."""
    out = {}
    for name in ("impact", "duffing"):
        for label, o in paths(MODELS[name]["affine"]).items():
            out[f"{name}: {label}"] = (name, o)
        out[f"{name}: RK45 exact=False variational=True"] = (
            name, dict(method="RK45", exact=False, variational=True, dense=False))
        out[f"{name}: DOP853 exact=False variational=True dense=True"] = (
            name, dict(method="DOP853", exact=False, variational=True, dense=True))
    return out


def worker(N, repeats):
    timers = {}
    for label, (name, o) in worker_paths().items():
        spec = MODELS[name]
        n = N // 10 if o.get("variational") else N
        timers[label] = (Timer(lambda m=spec["model"], t=n * spec["period"], o=o:
                               run_sim(m, t, max_steps=10 ** 8, **o)), n)
    for tm, _ in timers.values():
        tm.fn()
    time_interleaved([(tm, repeats) for tm, _ in timers.values()])
    print(json.dumps({label: {"cpu_us_per_period": 1e6 * tm.cpu / n,
                              "us_per_period": 1e6 * tm.wall / n,
                              "steps": tm.result.stats["steps"]}
                      for label, (tm, n) in timers.items()}))


def before_after(base_src, N, repeats, rounds):
    here_src = str(HERE.parent / "src")
    best = {"before": {}, "after": {}}
    for r in range(rounds):
        for which, src in (("before", base_src), ("after", here_src)):
            env = dict(os.environ, PYTHONPATH=src)
            out = subprocess.run([sys.executable, __file__, "--worker", "--periods", str(N),
                                  "--repeats", str(repeats)], env=env, capture_output=True,
                                 text=True)
            if out.returncode != 0:
                raise RuntimeError(f"worker ({which}) failed:\n{out.stderr[-3000:]}")
            res = json.loads(out.stdout.strip().splitlines()[-1])
            for label, v in res.items():
                b = best[which].setdefault(label, dict(v))
                for k in ("cpu_us_per_period", "us_per_period"):
                    b[k] = min(b[k], v[k])
    print(f"\nNon-default paths before (PYTHONPATH={base_src}) and after, CPU us per period, "
          f"best of {rounds} alternating worker runs x {repeats} repeats")
    table = {}
    for label in best["after"]:
        a, b = best["after"][label], best["before"].get(label)
        if b is None:
            continue
        ratio = a["cpu_us_per_period"] / b["cpu_us_per_period"]
        table[label] = {"before": b, "after": a, "after_over_before_cpu": ratio,
                        "after_over_before_wall": a["us_per_period"] / b["us_per_period"]}
        print(f"  {label:<58}{b['cpu_us_per_period']:>9.1f}{a['cpu_us_per_period']:>9.1f}"
              f"{ratio:>8.2f}x  (steps {b['steps']} -> {a['steps']})")
    return table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--periods", type=int, default=1000)
    ap.add_argument("--scipy-periods", type=int, default=40)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scipy-repeats", type=int, default=3)
    ap.add_argument("--compare-impacts", type=int, default=20)
    ap.add_argument("--tolerance-scan", action="store_true")
    ap.add_argument("--base", default=None, help="src directory of the version to compare with")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--save", action="store_true",
                    help="write benchmarks/results/defaults.json")
    args = ap.parse_args(argv)
    if args.worker:
        worker(args.periods, args.repeats)
        return 0
    info = machine_info()
    print(f"machine: {info['cpu']}, {info['cores']} cores, load {info['loadavg']}; Python "
          f"{info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, numba "
          f"{info['numba']}; rtol {RTOL:g}, atol {ATOL:g}")
    res = {"benchmark": "defaults", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
           "machine": info, "rtol": RTOL, "atol": ATOL, "models": {}, "per_step": {}}
    for name in ("impact", "duffing"):
        res["models"][name] = measure_model(name, args.periods, args.scipy_periods,
                                            args.repeats, args.scipy_repeats,
                                            args.compare_impacts)
    for name in ("duffing", "impact"):
        res["per_step"][name] = measure_steps(name, args.periods, args.repeats)
    if args.tolerance_scan:
        res["tolerance_scan"] = tolerance_scan(max(args.periods // 5, 50), args.repeats)
    if args.base:
        res["before_after"] = {"base": "the src given as --base", "rounds": args.rounds,
                               "paths": before_after(args.base, args.periods // 2,
                                                     args.repeats, args.rounds)}
    res["machine"]["loadavg_end"] = Path("/proc/loadavg").read_text().split()[:3]
    if args.save:
        out = HERE / "results" / "defaults.json"
        out.write_text(json.dumps(res, indent=2, default=float) + "\n")
        print(f"\nsaved {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
