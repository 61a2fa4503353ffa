"""Benchmark: how shallow a graze each integration path still detects.

Cases (closed-form references, no pwsdyn code in them):

* ``harmonic``: ``x'' = -x`` (states ``x, v``) against a wall at ``W = 1 - delta``
  (impact surface ``h = W - x >= 0``, reset ``v -> -e v``), started on the unit circle at
  phase ``phi``: ``x(t) = sin(t + phi)`` dips ``delta`` into the wall, the impact is at
  ``t = asin(W / a) - atan2(x0, v0)`` (``a = |(x0, v0)|``, evaluated with mpmath at 40 digits
  from the rounded inputs, so the reference is exact for the numbers the run gets). The
  near miss puts the wall at ``1 + delta``: no event may be logged.
* ``ball``: the built-in ``bouncing-ball`` on a table ``s(t) = A sin(omega t)``
  (``A omega^2 = 2 g``, so the relative motion has a minimum where ``sin(omega t) > 1/2``):
  the parabola is made tangent to the table at ``t*`` and lowered by ``depth``; the impact
  is the first root of ``y(t) - s(t)`` (bracketed on a fine grid, ``brentq``); the near
  miss raises it by ``depth``.

Each case runs over ``--phases`` phases (``phi`` in ``[0, 1)``, ``omega t*`` in
``[pi/2 - 0.5, pi/2 + 0.5]``) for ``delta`` (or ``depth``) = 1e-4 ... 1e-10 with RK45, DOP853
and ``exact=True`` at pwsdyn's default tolerances (``rtol = 1e-10``, ``atol = 1e-12``). Per
row: how many phases logged the impact, the largest time error against the closed form, and
false events in the near misses. The deepest graze missed and the shallowest found at every
phase summarise the row. Exit status 2 if a graze of ``delta >= 100 x`` the position
tolerance (``atol + rtol``) is missed or a near miss logs an event.

Run::

    python benchmarks/bench_grazing.py [--phases 16] [--save]

(``--save`` writes ``results/grazing.json``.) Run it with ``PYTHONPATH`` pointing at another
checkout to tabulate that one ("before").
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import mpmath  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

import pwsdyn  # noqa: E402
from pwsdyn.integrate.simulate import DEFAULTS  # noqa: E402

HERE = Path(__file__).resolve().parent
G = 9.81
# (exact=False: the default exact="auto" would propagate the affine flights exactly)
PATHS = (("RK45", dict(method="RK45", exact=False)),
         ("DOP853", dict(method="DOP853", exact=False)),
         ("exact", dict(exact=True)))
DEPTHS = [10.0 ** -k for k in range(4, 11)]


def harmonic_model():
    return {"name": "harmonic-wall", "states": ["x", "v"], "parameters": {"W": 1.0, "e": 0.5},
            "modes": {"free": {"x": "v", "v": "-x"}},
            "events": [{"name": "wall", "kind": "impact", "surface": "W - x", "direction": -1,
                        "reset": {"v": "-e*v"}}]}


def harmonic_reference(x0, v0, wall):
    """First time ``a sin(t + phi) = wall`` (None if the orbit stays below the wall)."""
    with mpmath.workdps(40):
        a = mpmath.sqrt(mpmath.mpf(x0) ** 2 + mpmath.mpf(v0) ** 2)
        if mpmath.mpf(wall) >= a:
            return None
        return float(mpmath.asin(mpmath.mpf(wall) / a) - mpmath.atan2(x0, v0))


def harmonic_case(depth, phi, miss):
    x0, v0 = math.sin(phi), math.cos(phi)
    wall = 1.0 + depth if miss else 1.0 - depth
    return (harmonic_model(), [x0, v0], (0.0, 3.0), {"W": wall},
            harmonic_reference(x0, v0, wall))


def ball_case(depth, phase, miss, omega=2 * math.pi):
    """Ball tangent to the table at t* (omega t* = pi/2 + phase), lowered (or raised, for
    the near miss) by ``depth``; started 0.15 periods before t*, run to 0.1
    periods after it."""
    A = 2.0 * G / omega ** 2
    ts = (math.pi / 2 + phase) / omega
    s = A * math.sin(omega * ts)
    sd = A * omega * math.cos(omega * ts)
    ys = s + (depth if miss else -depth)
    t0 = ts - 0.15 * 2 * math.pi / omega
    y0 = ys - sd * (ts - t0) - 0.5 * G * (ts - t0) ** 2
    v0 = sd + G * (ts - t0)

    def gap(t):
        return y0 + v0 * (t - t0) - 0.5 * G * (t - t0) ** 2 - A * math.sin(omega * t)

    ref = None
    t1 = ts + 0.1 * 2 * math.pi / omega
    grid = np.linspace(t0, t1, 4001)
    vals = [gap(t) for t in grid]
    assert vals[0] > 0
    for k in range(len(grid) - 1):
        if vals[k + 1] <= 0.0:
            ref = brentq(gap, grid[k], grid[k + 1], xtol=1e-16, rtol=4 * np.finfo(float).eps)
            break
    if ref is None:
        # a crossing closer to the grid's resolution than the grid: look at the minimum
        tm = ts
        if gap(tm) <= 0.0:
            ref = brentq(gap, t0, tm, xtol=1e-16, rtol=4 * np.finfo(float).eps)
    return ("bouncing-ball", [y0, v0], (t0, t1),
            {"A": A, "omega": omega, "e": 0.5}, ref)


def run_row(case, path_opts, depth, phases, models):
    hits, worst, false_events, unit = 0, 0.0, 0, 0.0
    tol_x = DEFAULTS["atol"] + DEFAULTS["rtol"]
    for phi in phases:
        for miss in (False, True):
            spec, x0, span, params, ref = case(depth, phi, miss)
            key = json.dumps(spec, sort_keys=True) if isinstance(spec, dict) else spec
            if key not in models:
                models[key] = pwsdyn.load_model(spec)
            tr = pwsdyn.simulate(models[key], x0, span, params=params, dense=False,
                                 **path_opts)
            ev = tr.events
            impacts = ev.t[np.asarray(ev.kind) == "impact"]
            if miss:
                false_events += len(impacts)
                continue
            assert ref is not None
            if len(impacts) and abs(impacts[0] - ref) < 1e-3:
                hits += 1
                err = abs(impacts[0] - ref)
                worst = max(worst, err)
                # the time error in units of the position tolerance over the approach speed
                speed = math.sqrt(2 * depth) if isinstance(spec, dict) else None
                if speed:
                    unit = max(unit, err * speed / tol_x)
    return hits, worst, false_events, unit


def _tree() -> str:
    """Which pwsdyn ran, without this machine's paths: this checkout's ``src`` or another."""
    here = (HERE.parent / "src" / "pwsdyn").resolve()
    ran = Path(pwsdyn.__file__).resolve().parent
    return "this checkout's src" if ran == here else "another tree"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--phases", type=int, default=16, help="phases per depth (16)")
    ap.add_argument("--save", action="store_true", help="write results/grazing.json")
    args = ap.parse_args(argv)
    tol_x = DEFAULTS["atol"] + DEFAULTS["rtol"]
    cases = {"harmonic": (harmonic_case, np.linspace(0.0, 1.0, args.phases, endpoint=False)),
             "ball": (ball_case, np.linspace(-0.5, 0.5, args.phases))}
    rows, ok = [], True
    models = {}
    t_start = time.perf_counter()
    print(f"pwsdyn {pwsdyn.__version__} from {Path(pwsdyn.__file__).parent}; default rtol "
          f"{DEFAULTS['rtol']:g}, atol {DEFAULTS['atol']:g}; position tolerance {tol_x:.3g}; "
          f"{args.phases} phases per depth")
    for cname, (case, phases) in cases.items():
        print(f"\n{cname}: impacts found / {args.phases} (largest |t - t_ref|); false events in "
              f"the near misses")
        print(f"{'depth':>8} " + " ".join(f"{p:>24}" for p, _ in PATHS))
        for depth in DEPTHS:
            cells = []
            for pname, popts in PATHS:
                hits, worst, false_events, unit = run_row(case, popts, depth, phases, models)
                rows.append(dict(case=cname, depth=depth, path=pname, found=hits,
                                 phases=args.phases, max_time_error=worst,
                                 time_error_in_tol_over_speed=unit, false_events=false_events))
                cells.append(f"{hits:>2}/{args.phases} ({worst:.1e}) fp {false_events}")
                if false_events or (depth >= 100 * tol_x and hits < args.phases):
                    ok = False
            print(f"{depth:>8.0e} " + " ".join(f"{c:>24}" for c in cells))
    summary = {}
    for cname in cases:
        for pname, _ in PATHS:
            rs = [r for r in rows if r["case"] == cname and r["path"] == pname]
            full = [r["depth"] for r in rs if r["found"] == r["phases"]]
            missed = [r["depth"] for r in rs if r["found"] < r["phases"]]
            summary[f"{cname}/{pname}"] = dict(
                shallowest_found_at_all_phases=min(full) if full else None,
                deepest_missed=max(missed) if missed else None)
    print("\nsummary (depth): shallowest found at every phase / deepest missed at some phase")
    for k, v in summary.items():
        print(f"  {k:<18} {v['shallowest_found_at_all_phases']!s:>8} / {v['deepest_missed']!s}")
    print(f"({time.perf_counter() - t_start:.1f} s)")
    meta = dict(date=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                machine=platform.machine(), python=platform.python_version(),
                numpy=np.__version__, pwsdyn=pwsdyn.__version__,
                pwsdyn_tree=_tree(), rtol=DEFAULTS["rtol"],
                atol=DEFAULTS["atol"], phases=args.phases)
    if args.save:
        (HERE / "results").mkdir(exist_ok=True)
        with open(HERE / "results" / "grazing.json", "w") as fh:
            json.dump(dict(meta=meta, rows=rows, summary=summary), fh, indent=1, default=str)
    if not ok:
        print("detection check FAILED (a graze >= 100 x tolerance missed, or a near miss "
              "logged an event)", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
