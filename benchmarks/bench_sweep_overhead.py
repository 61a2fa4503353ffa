"""Benchmark: what a sweep costs around the integration it does.

The sweep of issue 24: the built-in ``impact-oscillator`` with damping ``eps = 2 zeta = 0.1``
and the stop at ``sigma = 0`` (``r = 0.8``), ``--values`` (400) values of omega in
[2.4, 3.4], ``--periods`` (400) forcing periods per value (3/4 transient, the last quarter
recorded at the stroboscopic section), one direction, the exact path (``exact=True``: the free
flight is affine with harmonic forcing, propagated by its exact flow). Rows, CPU time per
forcing period (``time.process_time``, best of ``--repeats`` interleaved runs):

* ``sweep, one chunk``: ``pwsdyn.sweep(..., workers=1, chunk_size=values)``: the sequential
  sweep, the middle alone (no chunk borders);
* ``sweep, default chunks``: ``workers=1`` with the default chunking (16 chunks): the guesses,
  and the stitching of the chunks into the sequential sweep (its cost: the dataset's
  ``stitch_values``);
* ``simulate``: one ``pwsdyn.simulate(..., dense=False, exact=True)`` of the same number of
  periods per value, continuing the final state from value to value (the sweep's path);
* ``closed form``: a hand-written sweep in numba with the closed-form flow between impacts
  (homogeneous + particular solution of ``x'' + eps x' + x = sin(omega t)``), impacts found by
  stepping ``T / 32`` (one evaluation per step) and Newton's method on the closed form, the
  same section and continuation; no chattering handling (a value with more than 2000
  impacts in one period is cut there and restarted from x0, as a stuck value).

Ratios: sweep (one chunk) / simulate (target 1.2) and sweep (one chunk) / closed form
(target 1.5). Accuracy check: at the values where both find period 1 or 2, the section
points of the sweep and the closed-form sweep agree to 1e-6 (exit status 2 otherwise).
``--base PATH`` times another source tree's sweeps (one chunk, default chunks; a previous
version's ``src``) in a worker process alternating with this checkout's, so before and after
come from one run.

Run::

    python benchmarks/bench_sweep_overhead.py [--values 400] [--periods 400] [--base PATH]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numba  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
X0 = (-0.5, 0.0)
PARAMS = {"eps": 0.1, "sigma": 0.0, "r": 0.8}


@numba.njit(cache=True)
def _state(c1, c2, zeta, wd, a, b, w, t0, t):
    """x, v at t of the free flight from t0 (homogeneous part c1, c2 at t0)."""
    s = t - t0
    e = math.exp(-zeta * s)
    cs, sn = math.cos(wd * s), math.sin(wd * s)
    xh = e * (c1 * cs + c2 * sn)
    vh = e * ((-zeta * c1 + wd * c2) * cs + (-zeta * c2 - wd * c1) * sn)
    return (xh + a * math.sin(w * t) + b * math.cos(w * t),
            vh + a * w * math.cos(w * t) - b * w * math.sin(w * t))


@numba.njit(cache=True)
def closed_form_sweep(omegas, n_tr, n_s, eps, sigma, r, x0, v0):
    """Section points (values x n_s x 2) of the sequential sweep with the closed-form flow."""
    zeta = 0.5 * eps
    wd = math.sqrt(1.0 - zeta * zeta)
    out = np.full((len(omegas), n_s, 2), np.nan)
    x, v = x0, v0
    for i in range(len(omegas)):
        w = omegas[i]
        T = 2 * math.pi / w
        D = (1 - w * w) ** 2 + (eps * w) ** 2
        a, b = (1 - w * w) / D, -eps * w / D
        t0 = 0.0
        # homogeneous part at t0
        c1 = x - b
        c2 = (v - a * w + zeta * c1) / wd
        dt = T / 32
        stuck = False
        for k in range(n_tr + n_s):
            t_end = (k + 1) * T
            t = t0 if t0 > k * T else k * T
            n_imp = 0
            xa, _ = _state(c1, c2, zeta, wd, a, b, w, t0, t)
            while t < t_end:
                t_next = min(t + dt, t_end)
                xb, _ = _state(c1, c2, zeta, wd, a, b, w, t0, t_next)
                if xa < sigma and xb >= sigma:
                    # Newton on x(t) = sigma, kept inside [t, t_next]
                    lo, hi, tt = t, t_next, t_next
                    for _ in range(40):
                        xx, vv = _state(c1, c2, zeta, wd, a, b, w, t0, tt)
                        if xx >= sigma:
                            hi = tt
                        else:
                            lo = tt
                        step = (xx - sigma) / vv if vv != 0 else 0.0
                        tn = tt - step
                        if not (lo < tn < hi):
                            tn = 0.5 * (lo + hi)
                        if abs(tn - tt) <= 1e-14 * (1 + abs(tt)):
                            tt = tn
                            break
                        tt = tn
                    xx, vv = _state(c1, c2, zeta, wd, a, b, w, t0, tt)
                    # impact: x = sigma, v -> -r v; restart the closed form there
                    t0 = tt
                    x, v = sigma, -r * vv
                    pa = a * math.sin(w * t0) + b * math.cos(w * t0)
                    pv = a * w * math.cos(w * t0) - b * w * math.sin(w * t0)
                    c1 = x - pa
                    c2 = (v - pv + zeta * c1) / wd
                    t = tt
                    xa = x
                    n_imp += 1
                    if n_imp > 2000:
                        stuck = True
                        break
                    continue
                t = t_next
                xa = xb
            if stuck:
                break
            x, v = _state(c1, c2, zeta, wd, a, b, w, t0, t_end)
            if k >= n_tr:
                out[i, k - n_tr, 0] = x
                out[i, k - n_tr, 1] = v
        if stuck:
            x, v = x0, v0
        # the next value starts at its own t = 0 from this state
        else:
            x, v = _state(c1, c2, zeta, wd, a, b, w, t0, (n_tr + n_s) * T)
    return out


def _timed_sweep(model, omegas, kw, **extra):
    import pwsdyn

    t0 = time.process_time()
    ds = pwsdyn.sweep(model, "omega", omegas, X0, workers=1, **kw, **extra)
    return time.process_time() - t0, ds


def _timed_simulate(model, omegas, periods):
    import pwsdyn

    t0 = time.process_time()
    x = np.array(X0)
    for w in omegas:
        tr = pwsdyn.simulate(model, x, (0.0, periods * 2 * np.pi / w),
                             params={**PARAMS, "omega": float(w)}, dense=False, exact=True)
        x = tr.x_final if tr.success else np.array(X0)
    return time.process_time() - t0


_WORKER = r"""
import sys, time, json, numpy as np
sys.path.insert(0, sys.argv[1])
import pwsdyn
a = json.loads(sys.argv[2])
om = np.linspace(a["start"], a["stop"], a["values"])
kw = dict(transient=a["transient"], samples=a["samples"], direction="up", progress=False,
          exact=True, params=a["params"])
pwsdyn.sweep("impact-oscillator", "omega", om[:2], a["x0"], workers=1,
             **{**kw, "transient": 2, "samples": 2})
for cs in (len(om), None):
    t0 = time.process_time()
    pwsdyn.sweep("impact-oscillator", "omega", om, a["x0"], workers=1, chunk_size=cs, **kw)
    print(time.process_time() - t0)
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--values", type=int, default=400)
    ap.add_argument("--periods", type=int, default=400)
    ap.add_argument("--from", dest="start", type=float, default=2.4)
    ap.add_argument("--to", dest="stop", type=float, default=3.4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--base", help="another source tree's src, timed alternately")
    ap.add_argument("--save", action="store_true", help="write results/sweep_overhead.json")
    args = ap.parse_args(argv)
    import pwsdyn

    model = pwsdyn.load_model("impact-oscillator")
    omegas = np.linspace(args.start, args.stop, args.values)
    n_tr = args.periods * 3 // 4
    n_s = args.periods - n_tr
    kw = dict(transient=n_tr, samples=n_s, direction="up", progress=False, exact=True,
              params=PARAMS)
    # warm-up: compile the closed form, load the model and the kernel
    closed_form_sweep(omegas[:2], 2, 2, PARAMS["eps"], PARAMS["sigma"], PARAMS["r"], *X0)
    pwsdyn.sweep(model, "omega", omegas[:2], X0, workers=1, **{**kw, "transient": 2,
                                                                  "samples": 2})
    rows = {"sweep_one_chunk": [], "sweep_default_chunks": [], "simulate": [],
            "closed_form": [], "base_sweep_one_chunk": [], "base_sweep_default_chunks": []}
    one = dflt = cf = None
    for _ in range(args.repeats):
        t, one = _timed_sweep(model, omegas, kw, chunk_size=len(omegas))
        rows["sweep_one_chunk"].append(t)
        t, dflt = _timed_sweep(model, omegas, kw)
        rows["sweep_default_chunks"].append(t)
        rows["simulate"].append(_timed_simulate(model, omegas, args.periods))
        t0 = time.process_time()
        cf = closed_form_sweep(omegas, n_tr, n_s, PARAMS["eps"], PARAMS["sigma"], PARAMS["r"],
                               *X0)
        rows["closed_form"].append(time.process_time() - t0)
        if args.base:
            spec = json.dumps({"start": args.start, "stop": args.stop, "values": args.values,
                               "transient": n_tr, "samples": n_s, "params": PARAMS,
                               "x0": list(X0)})
            got = subprocess.run([sys.executable, "-c", _WORKER, args.base, spec],
                                 capture_output=True, text=True, check=True)
            rows["base_sweep_one_chunk"].append(float(got.stdout.split()[-2]))
            rows["base_sweep_default_chunks"].append(float(got.stdout.split()[-1]))
    total = args.values * args.periods
    best = {k: 1e6 * min(v) / total for k, v in rows.items() if v}
    print(f"impact oscillator, eps 0.1, sigma 0: {args.values} values x {args.periods} "
          f"periods, exact path; CPU us per period (best of {args.repeats}):")
    for k, v in best.items():
        print(f"  {k:22s} {v:7.2f}")
    ratios = {"sweep_vs_simulate": best["sweep_one_chunk"] / best["simulate"],
              "sweep_vs_closed_form": best["sweep_one_chunk"] / best["closed_form"],
              "default_chunks_vs_one_chunk": (best["sweep_default_chunks"]
                                              / best["sweep_one_chunk"])}
    if args.base:
        ratios["base_vs_this_one_chunk"] = best["base_sweep_one_chunk"] / best["sweep_one_chunk"]
        ratios["base_default_chunks_vs_simulate"] = (best["base_sweep_default_chunks"]
                                                     / best["simulate"])
        ratios["default_chunks_vs_simulate"] = best["sweep_default_chunks"] / best["simulate"]
    for k, v in ratios.items():
        print(f"  {k:30s} {v:5.2f}x")
    print(f"  stitching of the default chunks: {dflt.attrs['stitch_values']} values "
          f"integrated again ({dflt.attrs['stitch_reruns']} chunks rerun of "
          f"{dflt.attrs['stitch_borders']} borders)")
    per = one.period.values[0]
    ok = True
    errs = []
    for i in np.flatnonzero((per >= 1) & (per <= 2)):
        k = int(per[i])
        a, b = one.section.values[0, i, -k:], cf[i, -k:]
        if not np.all(np.isfinite(b)):
            continue
        d = np.max(np.abs(a[:, None, :] - b[None, :, :]), axis=2)
        errs.append(max(d.min(axis=0).max(), d.min(axis=1).max()))
    if errs:
        # values where the codes settle on different coexisting orbits differ by O(1):
        # reported as a count, the rest must agree to 1e-6
        same = np.array(errs) <= 1e-6
        ok = bool(same.mean() >= 0.9)
        print(f"  cycles of period 1-2: {int(same.sum())} of {len(errs)} values agree with "
              f"the closed form to 1e-6 (max difference there "
              f"{max(e for e in errs if e <= 1e-6) if same.any() else float('nan'):.1e})")
    res = {"benchmark": "sweep_overhead", "values": args.values, "periods": args.periods,
           "us_per_period": best, "ratios": ratios,
           "stitch": {k: int(dflt.attrs[k]) for k in ("stitch_borders", "stitch_reruns",
                                                      "stitch_values")}}
    if args.save:
        out = HERE / "results" / "sweep_overhead.json"
        out.write_text(json.dumps(res, indent=1))
        print(f"wrote {out}")
    return 0 if ok else 2


if __name__ == "__main__":
    sys.exit(main())
