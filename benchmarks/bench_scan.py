"""Benchmark: a two-parameter scan (period map) of the impact oscillator on 2 cores.

The scan (issue 24): the built-in ``impact-oscillator`` with eps = 0.1, r = 0.8, a grid of
``--n1`` values of omega in [2.5, 5.0] by ``--n2`` values of sigma in [-0.8, 0.3] (default
100 x 100), 300 transient + 100 recorded forcing periods per point at the stroboscopic
section, rows swept up in omega (``direction="up"``), the map's usual region: period-one
impacting motion, period doubling, chaos, non-impacting motion above the graze.

Measured (timings reported, never asserted):

* the scan on 1 worker and on 2 workers (threads, the default scheduler): wall and CPU time
  (of the whole process, both threads), and the parallel efficiency ``t_1 / (2 t_2)`` (wall;
  meaningful only on an otherwise idle machine: compare the load averages recorded); the
  two datasets must be identical (exit status 2 otherwise);
* the cost per forcing period of the scan (its serial time over ``n1 * n2 * 400`` periods)
  against one :func:`pwsdyn.simulate` of the same length (400 periods, ``dense=False``, the
  same tolerances) at every point of ``--ref-rows`` rows spread over the grid, each started
  from the state the scan itself started that point from (``x0`` or the previous point's
  ``x_final``), so both do the same integration; their ratio is on the same points
  (the scan's time on those rows is measured by a scan of those rows alone); wall and CPU
  time (``time.process_time``: the process's own, robust to other load on the machine).

Run::

    python benchmarks/bench_scan.py [--n1 100] [--n2 100] [--save]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from bench_sweep import machine_info  # noqa: E402

HERE = Path(__file__).resolve().parent
MODEL = "impact-oscillator"
PARAMS = {"eps": 0.1, "r": 0.8}
X0 = {"x": -1.0, "v": 0.0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n1", type=int, default=100, help="values of omega (100)")
    ap.add_argument("--n2", type=int, default=100, help="values of sigma (100)")
    ap.add_argument("--transient", type=int, default=300)
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--ref-rows", type=int, default=5,
                    help="rows on which the scan is compared with simulate (5)")
    ap.add_argument("--save", action="store_true", help="write results/scan.json")
    args = ap.parse_args(argv)

    import pwsdyn

    model = pwsdyn.load_model(MODEL)
    omegas = np.linspace(2.5, 5.0, args.n1)
    sigmas = np.linspace(-0.8, 0.3, args.n2)
    kw = dict(params=PARAMS, transient=args.transient, samples=args.samples, direction="up",
              progress=False)
    periods = args.transient + args.samples
    # compile and load everything once (not timed)
    pwsdyn.scan(model, {"omega": omegas[:2], "sigma": sigmas[:2]}, X0, workers=2,
                **{**kw, "transient": 2, "samples": 2})

    t0 = time.perf_counter()
    c0 = time.process_time()
    ds2 = pwsdyn.scan(model, {"omega": omegas, "sigma": sigmas}, X0, workers=2, **kw)
    t2, c2 = time.perf_counter() - t0, time.process_time() - c0
    print(f"scan {args.n1} x {args.n2} on 2 workers: {t2:.2f} s")
    t0 = time.perf_counter()
    c0 = time.process_time()
    ds1 = pwsdyn.scan(model, {"omega": omegas, "sigma": sigmas}, X0, workers=1, **kw)
    t1, c1 = time.perf_counter() - t0, time.process_time() - c0
    print(f"scan {args.n1} x {args.n2} on 1 worker:  {t1:.2f} s")
    identical = bool(ds1.equals(ds2))
    n_periods = args.n1 * args.n2 * periods

    # the same points: scan of the reference rows alone, and simulate at each point
    rows = np.unique(np.linspace(0, args.n2 - 1, args.ref_rows).round().astype(int))
    sub = sigmas[rows]
    t0 = time.perf_counter()
    c0 = time.process_time()
    dsr = pwsdyn.scan(model, {"omega": omegas, "sigma": sub}, X0, workers=1, **kw)
    t_rows, c_rows = time.perf_counter() - t0, time.process_time() - c0
    t_sim = c_sim = 0.0
    for j, s in enumerate(sub):
        xf = dsr.x_final.sel(direction="up").isel(sigma=j).values
        x = np.array([X0["x"], X0["v"]])
        for i, w in enumerate(omegas):
            T = 2 * np.pi / w
            t0 = time.perf_counter()
            c0 = time.process_time()
            pwsdyn.simulate(model, x, (0.0, periods * T), params={**PARAMS, "omega": w,
                                                                   "sigma": s}, dense=False)
            t_sim += time.perf_counter() - t0
            c_sim += time.process_time() - c0
            ok = dsr.status.sel(direction="up").values[i, j] == 0
            x = xf[i] if ok else np.array([X0["x"], X0["v"]])
    n_ref = len(omegas) * len(sub) * periods
    per_scan = t_rows / n_ref
    per_sim = t_sim / n_ref
    res = {
        "benchmark": "scan", "machine": machine_info(), "n1": args.n1, "n2": args.n2,
        "omega": [2.5, 5.0], "sigma": [-0.8, 0.3], "params": PARAMS,
        "transient": args.transient, "samples": args.samples, "section": "stroboscopic",
        "direction": "up",
        "workers2_s": t2, "workers2_cpu_s": c2, "workers1_s": t1, "workers1_cpu_s": c1,
        "loadavg_after": machine_info()["loadavg"],
        "parallel_efficiency": t1 / (2 * t2), "identical_1_vs_2_workers": identical,
        "us_per_period_scan_2workers_wall": 1e6 * t2 / n_periods,
        "us_per_period_scan_serial": 1e6 * t1 / n_periods,
        "reference_rows": [float(s) for s in sub],
        "us_per_period_scan_reference_rows": 1e6 * per_scan,
        "us_per_period_simulate_reference_rows": 1e6 * per_sim,
        "ratio_scan_to_simulate": per_scan / per_sim,
        "cpu_us_per_period_scan_serial": 1e6 * c1 / n_periods,
        "cpu_us_per_period_scan_reference_rows": 1e6 * c_rows / n_ref,
        "cpu_us_per_period_simulate_reference_rows": 1e6 * c_sim / n_ref,
        "ratio_scan_to_simulate_cpu": c_rows / c_sim,
        "cpu_ratio_2workers_to_1": c2 / c1,
        "periods_found": {str(int(k)): int(np.sum(ds1.period.values == k))
                          for k in np.unique(ds1.period.values)},
    }
    print(json.dumps({k: v for k, v in res.items() if k not in ("machine",)}, indent=1))
    if args.save:
        out = HERE / "results" / "scan.json"
        out.write_text(json.dumps(res, indent=1))
        print("wrote", out)
    if not identical:
        raise SystemExit(2)


if __name__ == "__main__":
    main()
