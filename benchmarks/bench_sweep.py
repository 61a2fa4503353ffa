"""Benchmark: a brute-force bifurcation diagram of the impact oscillator, pwsdyn (serial and
on a 2-worker Dask LocalCluster) against the scipy ``solve_ivp`` sweep a user writes.

The sweep (issue 5): the built-in ``impact-oscillator`` (Budd & Dux, eps = 0, sigma = 0,
r = 0.8), ``--values`` (400) values of omega in [2.4, 3.4], ``--periods`` (400) forcing periods
per value -- ``transient`` = 3/4 of them, the last quarter recorded at the stroboscopic
section -- continuing the final state into the next value, one direction (up).

Contenders (timings reported, never asserted):

* ``pwsdyn.sweep(..., workers=1)``: in-process, chunked as by default (16 chunks);
* ``pwsdyn.sweep(..., client=...)`` on a ``LocalCluster`` of 2 single-threaded worker
  processes started beforehand (start-up timed separately), and ``workers=2`` (cluster
  started and closed inside the call, what the CLI does);
* scipy: what a user writes today -- for every value and every forcing period,
  ``solve_ivp(rhs, (t, t_next), y, method="RK45", events=impact, rtol, atol)`` with a terminal
  impact event (direction -1), restarted after each impact with the reset ``v -> -r v``,
  the state at the period's end recorded. It is run on a subset (``--scipy-values`` values
  evenly spread over the range, ``--scipy-periods`` periods each, starting from the same state
  as pwsdyn) and **extrapolated** per forcing period to the full sweep. A chattering
  sequence (impacts accumulating, which a plain ``solve_ivp`` loop cannot pass) is cut after
  ``--scipy-max-impacts`` impacts in one period; that value is then reported as stuck.

Both codes are also run with the 8th-order Dormand-Prince pair (``DOP853``, same
tolerances): pwsdyn's full sweep serially, scipy's subset, extrapolated the same way.

Accuracy check: from the same start, ``--scipy-periods`` periods at each subset value with both
codes; the final states are compared at the values where the sweep found period 1 or 2 (on
chaotic values the two codes' trajectories separate, as any two integrators' do).

Run::

    python benchmarks/bench_sweep.py [--values 400] [--periods 400] [--save]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

HERE = Path(__file__).resolve().parent
X0 = (-0.5, 0.0)


def scipy_sweep(omegas, periods, record_from, p, rtol, atol, max_impacts, x0=X0,
                method="RK45"):
    """The user's sweep: per value and per period solve_ivp with a terminal impact event,
    restarted at each impact. Returns (stroboscopic points per value, final states, stuck
    flags, nfev)."""
    eps, r, sigma = p["eps"], p["r"], p["sigma"]
    y = np.array(x0, dtype=float)
    out, finals, stuck, nfev = [], [], [], 0
    for w in omegas:
        T = 2 * np.pi / w

        def rhs(t, u):
            return [u[1], np.sin(w * t) - eps * u[1] - u[0]]

        def impact(t, u):
            return sigma - u[0]

        impact.terminal = True
        impact.direction = -1
        pts, bad = [], False
        for k in range(periods):
            t, t_next = k * T, (k + 1) * T
            n_imp = 0
            while t < t_next and not bad:
                sol = solve_ivp(rhs, (t, t_next), y, method=method, events=impact, rtol=rtol,
                                atol=atol)
                nfev += sol.nfev
                if sol.status == 1:
                    y = sol.y_events[0][0].copy()
                    y[0] = sigma
                    y[1] = -r * y[1]
                    t = sol.t_events[0][0]
                    n_imp += 1
                    if n_imp > max_impacts:
                        bad = True
                else:
                    y = sol.y[:, -1].copy()
                    t = t_next
            if bad:
                break
            if k >= record_from:
                pts.append(y.copy())
        out.append(np.array(pts))
        finals.append(y.copy())
        stuck.append(bad)
        if bad:
            y = np.array(x0, dtype=float)
    return out, finals, stuck, nfev


def machine_info():
    import numba

    import pwsdyn
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        load = ""
    return {"cpu": cpu, "cores": os.cpu_count(), "loadavg": load,
            "platform": platform.platform(), "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
            "pwsdyn": pwsdyn.__version__}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--values", type=int, default=400, help="parameter values (400)")
    ap.add_argument("--periods", type=int, default=400, help="forcing periods per value (400)")
    ap.add_argument("--from", dest="start", type=float, default=2.4)
    ap.add_argument("--to", dest="stop", type=float, default=3.4)
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--atol", type=float, default=1e-12)
    ap.add_argument("--scipy-values", type=int, default=8)
    ap.add_argument("--scipy-periods", type=int, default=40)
    ap.add_argument("--scipy-max-impacts", type=int, default=200)
    ap.add_argument("--save", action="store_true", help="write results/sweep.json")
    args = ap.parse_args(argv)

    import pwsdyn
    from dask.distributed import Client, LocalCluster

    model = pwsdyn.load_model("impact-oscillator")
    p = {**model.parameters}
    omegas = np.linspace(args.start, args.stop, args.values)
    transient = args.periods * 3 // 4
    samples = args.periods - transient
    kw = dict(transient=transient, samples=samples, rtol=args.rtol, atol=args.atol,
              progress=False)
    info = machine_info()
    print(f"machine: {info['cpu']}, {info['cores']} cores, load {info['loadavg']}")
    print(f"impact-oscillator sweep: {args.values} values of omega in [{args.start}, "
          f"{args.stop}] x {args.periods} periods ({transient} transient + {samples} "
          f"recorded); RK45 rtol {args.rtol:g} atol {args.atol:g}")

    # warm-up: compile/load the model and its section copy in this process
    pwsdyn.sweep(model, "omega", omegas[:2], X0, workers=1, **{**kw, "transient": 2,
                                                                 "samples": 2})
    t0 = time.perf_counter()
    c0 = time.process_time()
    serial = pwsdyn.sweep(model, "omega", omegas, X0, workers=1, **kw)
    t_serial = time.perf_counter() - t0
    cpu_serial = time.process_time() - c0
    periods_total = args.values * args.periods
    print(f"pwsdyn serial:        {t_serial:8.2f} s wall ({cpu_serial:.2f} s CPU), "
          f"{1e6 * t_serial / periods_total:.1f} us/period")

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=":0")
    client = Client(cluster)
    # load pwsdyn and the compiled model on both workers (what the first task of a run does)
    client.run(lambda: __import__("pwsdyn.explore._common", fromlist=["x"]).ModelContext
               .get("impact-oscillator") and None)
    t_start = time.perf_counter() - t0
    t0 = time.perf_counter()
    par = pwsdyn.sweep(model, "omega", omegas, X0, client=client, **kw)
    t_par = time.perf_counter() - t0
    client.close()
    cluster.close()
    same = bool(serial.identical(par))
    t0 = time.perf_counter()
    par2 = pwsdyn.sweep(model, "omega", omegas, X0, workers=2, **kw)
    t_par_cold = time.perf_counter() - t0
    same2 = bool(serial.identical(par2))
    eff = t_serial / (2 * t_par)
    print(f"pwsdyn 2 workers:     {t_par:8.2f} s wall (cluster start-up {t_start:.2f} s "
          f"not included), parallel efficiency {100 * eff:.0f}%, identical to serial: {same}")
    print(f"pwsdyn workers=2:     {t_par_cold:8.2f} s wall (cluster started and closed inside "
          f"the call), identical to serial: {same2}")

    # scipy on a subset, extrapolated per period; pwsdyn with DOP853 too (same tolerances)
    sub = omegas[np.linspace(0, args.values - 1, args.scipy_values).round().astype(int)]
    ps = args.scipy_periods
    per = {float(w): int(serial.period.sel(direction="up", omega=w)) for w in sub}
    rows = {}
    for meth in ("RK45", "DOP853"):
        if meth == "RK45":
            t_pw, c_pw = t_serial, cpu_serial
        else:
            t0 = time.perf_counter()
            c0 = time.process_time()
            pwsdyn.sweep(model, "omega", omegas, X0, workers=1, method=meth, **kw)
            t_pw = time.perf_counter() - t0
            c_pw = time.process_time() - c0
        t0 = time.perf_counter()
        c0 = time.process_time()
        sp_finals, sp_stuck, nfev = [], [], 0
        for w in sub:  # each value from the same start, as in the accuracy check
            _, fin, st, nf = scipy_sweep([w], ps, ps, p, args.rtol, args.atol,
                                         args.scipy_max_impacts, method=meth)
            sp_finals.append(fin[0])
            sp_stuck.append(st[0])
            nfev += nf
        t_sp = time.perf_counter() - t0
        c_sp = time.process_time() - c0
        sp_per = t_sp / (len(sub) * ps)
        sp_full = sp_per * periods_total
        sp_full_cpu = c_sp / (len(sub) * ps) * periods_total
        # accuracy: same start, ps periods, final states at values with period 1 or 2
        diffs = []
        for w, fin, st in zip(sub, sp_finals, sp_stuck):
            if st or per[float(w)] not in (1, 2):
                continue
            tr = pwsdyn.simulate(model, X0, (0, ps * 2 * np.pi / w), {"omega": w},
                                 rtol=args.rtol, atol=args.atol, method=meth, dense=False)
            diffs.append(float(np.max(np.abs(tr.x_final - fin))))
        rows[meth] = {"pwsdyn_serial_s": t_pw, "pwsdyn_serial_cpu_s": c_pw,
                      "scipy_subset_s": t_sp, "scipy_subset_cpu_s": c_sp,
                      "scipy_extrapolated_cpu_s": sp_full_cpu,
                      "ratio_per_core_cpu": sp_full_cpu / c_pw,
                      "scipy_us_per_period": 1e6 * sp_per, "scipy_extrapolated_s": sp_full,
                      "scipy_evaluations_per_period": nfev / (len(sub) * ps),
                      "scipy_stuck_values": int(np.sum(sp_stuck)),
                      "ratio_per_core": sp_full / t_pw,
                      "accuracy_max_abs_diff": max(diffs) if diffs else None,
                      "accuracy_values": len(diffs)}
        print(f"{meth}: pwsdyn serial {t_pw:.2f} s ({1e6 * t_pw / periods_total:.1f} us/period); "
              f"scipy {t_sp:.2f} s for {len(sub)} values x {ps} periods "
              f"({1e6 * sp_per:.0f} us/period, {nfev / (len(sub) * ps):.0f} evaluations/period,"
              f" stuck at {int(np.sum(sp_stuck))} values), extrapolated {sp_full:.0f} s; "
              f"ratio per core {sp_full / t_pw:.0f}x wall, {sp_full_cpu / c_pw:.0f}x CPU; "
              f"pwsdyn vs scipy after {ps} periods at "
              f"{len(diffs)} periodic values: max |dx| = "
              f"{max(diffs) if diffs else float('nan'):.1e}")
    print(f"ratio scipy RK45 / pwsdyn RK45 on 2 workers: "
          f"{rows['RK45']['scipy_extrapolated_s'] / t_par:.0f}x")
    res = {"benchmark": "sweep", "machine": info, "values": args.values,
           "periods": args.periods, "transient": transient, "samples": samples,
           "rtol": args.rtol, "atol": args.atol, "omega": [args.start, args.stop],
           "pwsdyn_serial_s": t_serial, "pwsdyn_serial_cpu_s": cpu_serial,
           "pwsdyn_2workers_s": t_par, "cluster_startup_s": t_start,
           "pwsdyn_workers2_with_startup_s": t_par_cold, "parallel_efficiency": eff,
           "identical_serial_parallel": same and same2,
           "scipy_subset_values": len(sub), "scipy_subset_periods": ps, "methods": rows,
           "period_counts": {str(k): int(v) for k, v in zip(*np.unique(
               serial.period.values, return_counts=True))}}
    if args.save:
        out = HERE / "results" / "sweep.json"
        out.parent.mkdir(exist_ok=True)
        out.write_text(json.dumps(res, indent=1))
        print(f"wrote {out}")
    return 0 if (same and same2) else 2


if __name__ == "__main__":
    sys.exit(main())
