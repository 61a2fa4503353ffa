"""Benchmark: a Filippov system (stick-slip on a moving belt), pwsdyn against scipy.

Model (the zoo's ``stick-slip-oscillator``, written with ``sign()`` as in a paper)::

    m x'' + k x = -Fs sign(v - V) / (1 + delta |v - V|)

a block on a spring dragged by a belt moving at speed ``V``, with dry friction that decreases
with the slip speed. Its attractor is a stick-slip cycle: the block sticks to the belt
(Filippov sliding on ``v = V``) until the spring force reaches ``Fs``, slips back, and sticks
again. Three ways to compute it:

* ``pwsdyn.simulate`` on the model file as written (the loader turns ``sign`` into a Filippov
  switch; the kernel locates arrivals, slides with the convex combination and locates the
  exits), with ``dense=False`` and ``dense=True``;
* scipy "event restarts", the code an expert user writes by hand for a Filippov system: one
  ``solve_ivp`` per phase with a Python right-hand side for the current friction direction,
  a terminal event on ``v - V`` in slip phases, the stick condition ``|k x| <= Fs`` checked
  by hand at each arrival, and a stick phase ``x' = V, v' = 0`` integrated until the event
  ``k x = Fs`` (or ``-Fs``);
* scipy "smoothing", the code most users write: ``sign`` replaced by ``tanh((v - V)/eps)``
  and the stiff result given to ``solve_ivp(method="LSODA")`` (or Radau) at the same
  tolerance. Its error is of the order of ``eps``, and it is measured.

Timings are reported, never asserted. ``import pwsdyn`` (kernel load) and the first
``simulate`` (model load) are timed separately and excluded. Accuracy is checked: the run
exits with status 2 if pwsdyn and the scipy event restarts disagree on the times of the
stick phases by more than ``1e4 * rtol``.

Run::

    python benchmarks/bench_filippov.py [--periods N] [--rtol R] [--eps E] [--save]
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

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

_t_import = time.perf_counter()
import pwsdyn  # noqa: E402

IMPORT_S = time.perf_counter() - _t_import
HERE = Path(__file__).resolve().parent
MODEL = "stick-slip-oscillator"
X0 = (0.0, 0.0)


class Timer:
    """Best wall-clock and CPU time of a callable over its repeats, with its last result."""

    def __init__(self, fn):
        self.fn, self.wall, self.cpu, self.result, self.n = fn, math.inf, math.inf, None, 0

    def run(self):
        w0, c0 = time.perf_counter(), time.process_time()
        self.result = self.fn()
        self.wall = min(self.wall, time.perf_counter() - w0)
        self.cpu = min(self.cpu, time.process_time() - c0)
        self.n += 1


def interleaved(timers_repeats):
    for r in range(max(n for _, n in timers_repeats)):
        for timer, n in timers_repeats:
            if r < n:
                timer.run()


# ------------------------------------------------------------------------------------------
# pwsdyn
# ------------------------------------------------------------------------------------------
def pwsdyn_run(model, params, t_end, rtol, atol, dense):
    # RK45, the pair the results in benchmarks/README.md were measured with (the default
    # method is now 'auto': DOP853 below rtol 1e-7; bench_defaults.py measures it)
    return pwsdyn.simulate(model, X0, (0.0, t_end), params=params, rtol=rtol, atol=atol,
                           dense=dense, max_steps=100_000_000, max_events=10_000_000,
                           method="RK45")


def pwsdyn_sticks(traj):
    """(start, end) times of the stick phases (sliding on v = V)."""
    return [(a, b) for a, b, _ in traj.sliding_intervals()]


# ------------------------------------------------------------------------------------------
# scipy, event restarts: a hand-written Filippov simulation of this model
# ------------------------------------------------------------------------------------------
def scipy_restarts(p, t_end, rtol, atol):
    """Slip phases with the friction direction fixed, stick phases x' = V; events restart
    solve_ivp. Returns (stick intervals, nfev, final state)."""
    m, k, V, Fs, delta = p["m"], p["k"], p["V"], p["Fs"], p["delta"]

    def slip(direction):
        def rhs(t, u):
            x, v = u
            return [v, (-k * x - direction * Fs / (1.0 + delta * abs(v - V))) / m]
        return rhs

    def stick_rhs(t, u):
        return [V, 0.0]

    def belt(t, u):
        return u[1] - V

    def release_hi(t, u):
        return k * u[0] - Fs

    def release_lo(t, u):
        return k * u[0] + Fs

    belt.terminal = True
    release_hi.terminal = release_lo.terminal = True
    release_hi.direction, release_lo.direction = 1, -1

    t, u = 0.0, np.array(X0, dtype=float)
    # the phase at the start: slipping backwards (v < V) from rest with V > 0
    phase = -1 if u[1] < V else 1
    sticks, nfev = [], 0
    while t < t_end:
        if phase == 0:
            sol = solve_ivp(stick_rhs, (t, t_end), u, method="RK45", rtol=rtol, atol=atol,
                            events=(release_hi, release_lo))
            nfev += sol.nfev
            if sol.status == 1:
                hit = 0 if sol.t_events[0].size else 1
                te = sol.t_events[hit][0]
                sticks.append((t, te))
                t, u = te, sol.y_events[hit][0].copy()
                u[1] = V
                # released: the spring drives the block backwards (hi) or forwards (lo)
                phase = -1 if hit == 0 else 1
                continue
            sticks.append((t, sol.t[-1]))
            t, u = sol.t[-1], sol.y[:, -1]
            break
        belt.direction = -1 if phase == 1 else 1
        sol = solve_ivp(slip(phase), (t, t_end), u, method="RK45", rtol=rtol, atol=atol,
                        events=belt)
        nfev += sol.nfev
        if sol.status == 1:
            te, ue = sol.t_events[0][0], sol.y_events[0][0].copy()
            if te - t <= 1e-12 * max(1.0, t):
                # the restart found the event it started on: nudge past it
                s2 = solve_ivp(slip(phase), (t, t + 1e-9), u, method="RK45", rtol=rtol,
                               atol=atol)
                t, u = s2.t[-1], s2.y[:, -1]
                continue
            ue[1] = V
            t, u = te, ue
            # Filippov: stick if the friction can hold the spring force, else cross
            phase = 0 if abs(k * ue[0]) <= Fs else -phase
            continue
        t, u = sol.t[-1], sol.y[:, -1]
        break
    return sticks, nfev, u


# ------------------------------------------------------------------------------------------
# scipy, smoothing: sign -> tanh((v - V)/eps), stiff solver
# ------------------------------------------------------------------------------------------
def scipy_smoothed(p, t_end, rtol, atol, eps, method, t_eval):
    m, k, V, Fs, delta = p["m"], p["k"], p["V"], p["Fs"], p["delta"]

    def rhs(t, u):
        x, v = u
        return [v, (-k * x - Fs * math.tanh((v - V) / eps) / (1.0 + delta * abs(v - V))) / m]

    def jac(t, u):
        x, v = u
        s = (v - V) / eps
        sech2 = 0.0 if abs(s) > 350 else 1.0 / math.cosh(s) ** 2
        d = 1.0 + delta * abs(v - V)
        dv = -Fs * (sech2 / eps) / d + Fs * math.tanh(s) * delta * np.sign(v - V) / d ** 2
        return [[0.0, 1.0], [-k / m, dv / m]]

    sol = solve_ivp(rhs, (0.0, t_end), X0, method=method, rtol=rtol, atol=atol, jac=jac,
                    t_eval=t_eval)
    if sol.status != 0:
        raise RuntimeError(f"smoothed solve_ivp failed: {sol.message}")
    return sol


# ------------------------------------------------------------------------------------------
def two_contacts(params, period, cycles, rtol, atol, repeats):
    """Sliding on an intersection: two such blocks on two belts in one model (the second with
    other parameters), so that both often stick at once (``slide_multi``, the bilinear
    sliding field of Dieci & Lopez), against the one block over the same time: cost per
    step and per time unit as ratios of CPU time, and the share of the time both stick."""
    p = params
    two = {"name": "two-blocks", "states": ["x1", "v1", "x2", "v2"],
           "parameters": {"m": p["m"], "k1": p["k"], "Fs1": p["Fs"], "V1": p["V"],
                          "d1": p["delta"], "k2": 1.5 * p["k"], "Fs2": 0.8 * p["Fs"],
                          "V2": 1.5 * p["V"], "d2": 2.0 / 3.0 * p["delta"]},
           "definitions": {"vrel1": "v1 - V1", "vrel2": "v2 - V2"},
           "modes": {"block": {
               "x1": "v1", "v1": "(-k1*x1 - Fs1*sign(vrel1)/(1 + d1*abs(vrel1)))/m",
               "x2": "v2", "v2": "(-k2*x2 - Fs2*sign(vrel2)/(1 + d2*abs(vrel2)))/m"}}}
    t_end = cycles * period
    model2 = pwsdyn.load_model(two)
    pwsdyn.simulate(model2, [0.0] * 4, (0.0, period), rtol=rtol, atol=atol, method="RK45")
    one = Timer(lambda: pwsdyn_run(MODEL, params, t_end, rtol, atol, False))
    both = Timer(lambda: pwsdyn.simulate(model2, [0.0] * 4, (0.0, t_end), rtol=rtol,
                                         atol=atol, dense=False, method="RK45",
                                         max_steps=100_000_000, max_events=10_000_000))
    interleaved([(one, repeats), (both, repeats)])
    s1, s2 = one.result.stats, both.result.stats
    multi = sum(b - a for a, b, name in both.result.sliding_intervals() if "&" in name)
    # CPU time: on a shared machine the wall clock of these millisecond runs is mostly
    # waiting
    per_step = (both.cpu / s2["steps"]) / (one.cpu / s1["steps"])
    per_time = both.cpu / one.cpu
    print(f"two contacts ({cycles} cycles of the first): {s2['steps']} steps, "
          f"{s2['events']} events vs {s1['steps']} steps, {s1['events']} events for one block; "
          f"both stuck {100 * multi / t_end:.0f}% of the time; CPU cost ratio two/one per "
          f"step {per_step:.2f}, per time unit {per_time:.2f}")
    # the sliding steps alone: both blocks stuck to a slow belt (x' = V, v = V) for a long
    # time, steps limited so that the run is made of them, against one block stuck alone
    slow = dict(two["parameters"], V1=1e-3, V2=1e-3)
    model2s = pwsdyn.load_model(dict(two, parameters=slow))
    run_kw = dict(rtol=rtol, atol=atol, method="RK45", dense=False, max_step=0.05,
                  max_steps=100_000_000)
    stuck_one = Timer(lambda: pwsdyn.simulate(MODEL, [0.0, 1e-3], (0.0, 500.0),
                                              params=dict(params, V=1e-3), **run_kw))
    stuck_two = Timer(lambda: pwsdyn.simulate(model2s, [0.0, 1e-3, 0.0, 1e-3], (0.0, 500.0),
                                              **run_kw))
    interleaved([(stuck_one, repeats), (stuck_two, repeats)])
    assert str(stuck_two.result.state[-1]).startswith("slide_multi:")
    per_slide_step = ((stuck_two.cpu / stuck_two.result.stats["steps"])
                      / (stuck_one.cpu / stuck_one.result.stats["steps"]))
    print(f"sliding steps: slide_multi (2 contacts) / slide (1 contact) CPU per step "
          f"{per_slide_step:.1f} ({1e6 * stuck_one.cpu / stuck_one.result.stats['steps']:.2f} "
          f"us per slide step)")
    return dict(cycles=cycles, steps_one=s1["steps"], steps_two=s2["steps"],
                ratio_slide_multi_step=per_slide_step,
                events_one=s1["events"], events_two=s2["events"],
                share_both_stuck=multi / t_end, ratio_per_step=per_step,
                ratio_per_time=per_time)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--periods", type=int, default=200, help="stick-slip cycles (200)")
    ap.add_argument("--rtol", type=float, default=1e-10, help="relative tolerance (1e-10)")
    ap.add_argument("--atol", type=float, default=None, help="absolute tolerance (rtol*1e-2)")
    ap.add_argument("--scipy-periods", type=int, default=20,
                    help="cycles for the scipy event restarts, extrapolated (20)")
    ap.add_argument("--smooth-periods", type=int, default=5,
                    help="cycles for the smoothed scipy run, extrapolated (5)")
    ap.add_argument("--eps", type=float, default=1e-4, help="tanh smoothing width (1e-4)")
    ap.add_argument("--smooth-method", choices=("LSODA", "Radau", "BDF"), default="LSODA")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scipy-repeats", type=int, default=3)
    ap.add_argument("--save", action="store_true", help="write results/filippov.json")
    args = ap.parse_args(argv)
    rtol = args.rtol
    atol = args.atol if args.atol is not None else rtol * 1e-2

    model = pwsdyn.load_model(MODEL)
    params = dict(model.parameters)
    # the cycle's period, from a short pwsdyn run (checked against scipy below)
    w0 = time.perf_counter()
    probe = pwsdyn_run(model, params, 100.0, rtol, atol, True)
    first_s = time.perf_counter() - w0
    ends = probe.event_times("slide_end")
    period = float(ends[-1] - ends[-2])
    t_end = args.periods * period
    t_sc = args.scipy_periods * period
    t_sm = args.smooth_periods * period

    p_dense0 = Timer(lambda: pwsdyn_run(model, params, t_end, rtol, atol, False))
    p_dense1 = Timer(lambda: pwsdyn_run(model, params, t_end, rtol, atol, True))
    s_rest = Timer(lambda: scipy_restarts(params, t_sc, rtol, atol))
    t_eval = np.linspace(0.0, t_sm, 2001)
    s_smooth = Timer(lambda: scipy_smoothed(params, t_sm, rtol, atol, args.eps,
                                            args.smooth_method, t_eval))
    interleaved([(p_dense0, args.repeats), (p_dense1, args.repeats),
                 (s_rest, args.scipy_repeats), (s_smooth, 1)])

    traj = p_dense1.result
    sticks_p = pwsdyn_sticks(traj)
    sticks_s, nfev_s, _ = s_rest.result
    n = min(len(sticks_s), len([s for s in sticks_p if s[0] < t_sc]))
    # the last scipy stick phase is cut at its window's end
    n_cmp = n - 1
    d_start = max(abs(sticks_p[i][0] - sticks_s[i][0]) for i in range(n_cmp))
    d_end = max(abs(sticks_p[i][1] - sticks_s[i][1]) for i in range(n_cmp))
    smooth = s_smooth.result
    x_p = traj(t_eval)
    err_smooth = float(np.max(np.abs(smooth.y.T - x_p)))

    rows = [
        ("pwsdyn dense=False", args.periods, p_dense0.wall, p_dense0.cpu),
        ("pwsdyn dense=True", args.periods, p_dense1.wall, p_dense1.cpu),
        ("scipy RK45 event restarts", args.scipy_periods, s_rest.wall, s_rest.cpu),
        (f"scipy {args.smooth_method} tanh eps={args.eps:g}", args.smooth_periods,
         s_smooth.wall, s_smooth.cpu),
    ]
    base_w = p_dense0.wall / args.periods
    base_c = p_dense0.cpu / args.periods
    print(f"model {MODEL}: stick-slip cycle of period {period:.10f}; rtol {rtol:g}, "
          f"atol {atol:g}")
    print(f"import pwsdyn {IMPORT_S:.2f} s, first simulate {first_s:.2f} s (excluded)")
    print(f"{'method':34s} {'cycles':>6s} {'wall s':>8s} {'us/cycle':>10s} {'CPU us/cyc':>10s} "
          f"{'ratio wall':>10s} {'ratio CPU':>9s}")
    out_rows = []
    for name, cyc, w, c in rows:
        print(f"{name:34s} {cyc:6d} {w:8.3f} {1e6 * w / cyc:10.0f} {1e6 * c / cyc:10.0f} "
              f"{w / cyc / base_w:10.1f} {c / cyc / base_c:9.1f}")
        out_rows.append(dict(method=name, cycles=cyc, wall_s=w, cpu_s=c,
                             ratio_wall=w / cyc / base_w, ratio_cpu=c / cyc / base_c))
    st = traj.stats
    print(f"pwsdyn work: {st['steps']} steps, {st['rejected_steps']} rejected, {st['nfev']} "
          f"evaluations, {st['events']} events for {args.periods} cycles "
          f"({st['steps'] / args.periods:.0f} steps/cycle); scipy restarts: {nfev_s} "
          f"evaluations for {args.scipy_periods} cycles ({nfev_s / args.scipy_periods:.0f}/cycle); "
          f"smoothed: {smooth.nfev} evaluations, {smooth.njev} Jacobians for "
          f"{args.smooth_periods} cycles")
    print(f"agreement pwsdyn vs scipy restarts over {n_cmp} stick phases: max |d t_stick| "
          f"{d_start:.2e}, max |d t_slip| {d_end:.2e}")
    print(f"smoothed (eps={args.eps:g}) vs pwsdyn: max |dx| over {args.smooth_periods} cycles "
          f"{err_smooth:.2e}")
    codim2 = two_contacts(params, period, min(args.periods, 50), rtol, atol, args.repeats)
    ok = d_start <= 1e4 * rtol and d_end <= 1e4 * rtol
    if args.save:
        res = dict(benchmark="filippov", date=datetime.now(timezone.utc).isoformat(),
                   machine=dict(platform=platform.platform(), python=platform.python_version(),
                                numpy=np.__version__, scipy=scipy.__version__,
                                pwsdyn=pwsdyn.__version__, cores=os.cpu_count(),
                                loadavg=" ".join(f"{x:.2f}" for x in os.getloadavg())),
                   model=MODEL, params=params, period=period, rtol=rtol, atol=atol,
                   eps=args.eps, rows=out_rows, pwsdyn_stats=st, scipy_nfev=nfev_s,
                   agreement=dict(stick_start=d_start, stick_end=d_end, phases=n_cmp),
                   smoothed_error=err_smooth, import_s=IMPORT_S, first_simulate_s=first_s,
                   codim2=codim2)
        (HERE / "results").mkdir(exist_ok=True)
        (HERE / "results" / "filippov.json").write_text(json.dumps(res, indent=2))
        print("wrote", HERE / "results" / "filippov.json")
    if not ok:
        print("FAILED: pwsdyn and the scipy event restarts disagree", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
