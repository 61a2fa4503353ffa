"""Benchmark: the Budd & Dux impact oscillator, pwsdyn against scipy and the exact solution.

Model (a harmonically forced, damped oscillator hitting a rigid stop)::

    x'' + eps*x' + x = sin(omega*t),    x <= sigma,
    impact at x = sigma:  v -> -r*v

Three event-driven solutions of the same initial value problem are compared:

* ``pwsdyn.simulate`` (compiled numba kernel, Dormand-Prince 5(4) or, with ``--method
  DOP853``, 8(5,3), events located inside the kernel), with ``dense=False`` (event log + end state, what sweeps use) and with the
  default ``dense=True`` (every step stored with its dense output);
* the code a typical user writes today: ``scipy.integrate.solve_ivp`` (same method) with a
  terminal event function and a plain Python right-hand side, restarted after every impact
  from the reset state;
* an "exact" reference: between impacts the flow is linear with a closed-form solution
  (homogeneous + particular), impact times are bracketed by fine sampling and refined with
  ``scipy.optimize.brentq`` to ~1e-15 in the local time.

Timings are reported, never asserted. ``import pwsdyn`` loads (or compiles) the numba kernel
and the first ``simulate`` call loads the model's generated function; both are timed
separately and excluded from the per-period figures. With the default settings the cold-start costs are also
measured in subprocesses with empty caches (``--skip-cold`` to skip them).

Run::

    python benchmarks/bench_impact_oscillator.py [--periods N] [--rtol R] [--save]

Exit status: 0, or 2 if the methods disagree beyond the accuracy expected from ``rtol``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import textwrap
import time
from datetime import datetime, timezone
from pathlib import Path

# both contenders single-threaded: no BLAS/OpenMP/numba thread pools (set before numpy loads)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

_t_import = time.perf_counter()
import pwsdyn  # noqa: E402  (loads, or compiles, the numba kernel: it has a signature)
from pwsdyn.model import compile_model, load_model  # noqa: E402

IMPORT_S = time.perf_counter() - _t_import
HERE = Path(__file__).resolve().parent

#: Name of the displacement state, as in the slides. (pwsdyn's generated model code prefixes
#: user names since codegen v2; with codegen v1 a state called ``x`` shadowed the state array
#: argument of the generated ``evaluate`` and the model failed to compile: set ``STATE = "y"``
#: there.)
STATE = "x"

#: Default parameters: a stable period-one orbit with one impact per forcing period
#: (checked at run time: impacts per period are reported and phases compared).
DEFAULT_PARAMS = {"eps": 0.1, "r": 0.8, "sigma": 0.1, "omega": 2.2}

X0 = (0.0, 0.0)  # (y, v) at t = 0: at rest, below the stop


def make_model(params: dict) -> dict:
    """The impact oscillator as a pwsdyn model dict (same structure as a TOML model file)."""
    y = STATE
    return {
        "name": "budd-dux-impact-oscillator",
        "description": "Forced damped linear oscillator with a rigid stop (Budd & Dux)",
        "states": [y, "v"],
        "parameters": dict(params),
        "forcing_period": "2*pi/omega",
        "modes": {"free": {y: "v", "v": f"-eps*v - {y} + sin(omega*t)"}},
        "events": [{"name": "impact", "kind": "impact", "surface": f"sigma - {y}",
                    "direction": -1, "reset": {"v": "-r*v"}}],
    }


# ------------------------------------------------------------------------------------------
# pwsdyn
# ------------------------------------------------------------------------------------------
def pwsdyn_run(model, t_end, rtol, atol, dense, method="RK45", exact=False):
    return pwsdyn.simulate(model, X0, (0.0, t_end), method=method, rtol=rtol, atol=atol,
                           dense=dense, max_steps=100_000_000, exact=exact)


def pwsdyn_impacts(traj):
    """(times, post-impact velocities, pre-impact velocities) of the impact events."""
    ev = [e for e in traj.events if e.kind == "impact"]
    return (np.array([e.t for e in ev]), np.array([e.x_after[1] for e in ev]),
            np.array([e.x_before[1] for e in ev]))


class Timer:
    """Best wall-clock (``time.perf_counter``) and CPU (``time.process_time``) time of a
    callable over the repeats it is given, with its last result."""

    def __init__(self, fn):
        self.fn, self.wall, self.cpu, self.result, self.n = fn, math.inf, math.inf, None, 0

    def run(self):
        w0, c0 = time.perf_counter(), time.process_time()
        self.result = self.fn()
        self.wall = min(self.wall, time.perf_counter() - w0)
        self.cpu = min(self.cpu, time.process_time() - c0)
        self.n += 1


def time_interleaved(timers_repeats):
    """Run [(timer, repeats), ...] round-robin, so that all see the same background load."""
    for r in range(max(n for _, n in timers_repeats)):
        for timer, n in timers_repeats:
            if r < n:
                timer.run()


# ------------------------------------------------------------------------------------------
# scipy baseline: what a typical user writes
# ------------------------------------------------------------------------------------------
def scipy_run(p, t_end, rtol, atol, method="RK45"):
    """solve_ivp(method) with a terminal event, restarted from the reset state after each impact.

    Returns (impact times, post-impact velocities, total nfev, number of nudges, final state).
    """
    eps, r, sigma, omega = p["eps"], p["r"], p["sigma"], p["omega"]

    def rhs(t, u):
        y, v = u
        return [v, -eps * v - y + np.sin(omega * t)]

    def impact(t, u):
        return sigma - u[0]

    impact.terminal = True
    impact.direction = -1

    t, u = 0.0, np.array(X0, dtype=float)
    times, vplus = [], []
    nfev = nudges = 0
    while t < t_end:
        sol = solve_ivp(rhs, (t, t_end), u, method=method, events=impact, rtol=rtol, atol=atol)
        nfev += sol.nfev
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp failed at t={sol.t[-1]}: {sol.message}")
        if sol.status == 0:  # reached t_end
            t, u = sol.t[-1], sol.y[:, -1]
            break
        te, ue = sol.t_events[0][0], sol.y_events[0][0].copy()
        if te - t <= 1e-12 * max(1.0, abs(t)):
            # the event re-triggered at the restart time: step a little past it without
            # events and go on (does not happen here, since v < 0 after every reset)
            nudges += 1
            h = 1e-9 * max(1.0, abs(t))
            s2 = solve_ivp(rhs, (t, min(t + h, t_end)), u, method=method, rtol=rtol, atol=atol)
            nfev += s2.nfev
            t, u = s2.t[-1], s2.y[:, -1]
            continue
        ue[0] = sigma  # on the stop
        ue[1] = -r * ue[1]
        times.append(te)
        vplus.append(ue[1])
        t, u = te, ue
    return np.array(times), np.array(vplus), nfev, nudges, np.asarray(u)


# ------------------------------------------------------------------------------------------
# exact reference: closed-form flow between impacts
# ------------------------------------------------------------------------------------------
class ExactImpactOscillator:
    """Closed-form solution of y'' + eps y' + y = sin(omega t) between impacts (0 < eps < 2)."""

    def __init__(self, p):
        self.eps, self.r, self.sigma, self.omega = p["eps"], p["r"], p["sigma"], p["omega"]
        w, e = self.omega, self.eps
        d = (1.0 - w * w) ** 2 + (e * w) ** 2
        self.A = (1.0 - w * w) / d  # particular solution A sin(wt) + B cos(wt)
        self.B = -e * w / d
        self.a = 0.5 * e  # decay rate of the homogeneous part
        self.wd = math.sqrt(1.0 - 0.25 * e * e)  # its frequency
        # sampling step for bracketing: far below every time scale of the flow
        self.dt = min(2 * math.pi / w, 2 * math.pi / self.wd) / 400.0

    def particular(self, t):
        w = self.omega
        s, c = np.sin(w * t), np.cos(w * t)
        return self.A * s + self.B * c, w * (self.A * c - self.B * s)

    def segment(self, t0, y0, v0):
        """Coefficients (C1, C2) of the homogeneous part for the segment starting at t0."""
        yp, vp = self.particular(t0)
        c1 = y0 - yp
        c2 = (v0 - vp + self.a * c1) / self.wd
        return c1, c2

    def state(self, t0, c, s):
        """(y, v) at local time s = t - t0 of the segment with coefficients c."""
        c1, c2 = c
        ea = np.exp(-self.a * s)
        cs, sn = np.cos(self.wd * s), np.sin(self.wd * s)
        yp, vp = self.particular(t0 + s)
        y = ea * (c1 * cs + c2 * sn) + yp
        v = ea * ((-self.a * c1 + self.wd * c2) * cs + (-self.a * c2 - self.wd * c1) * sn) + vp
        return y, v

    def next_impact(self, t0, y0, v0, t_end):
        """First s > 0 at which y crosses sigma upwards, or None before t_end."""
        c = self.segment(t0, y0, v0)
        g = lambda s: self.state(t0, c, s)[0] - self.sigma  # noqa: E731
        vel = lambda s: self.state(t0, c, s)[1]  # noqa: E731
        root = lambda f, lo, hi: brentq(f, lo, hi, xtol=1e-16, rtol=4 * np.finfo(float).eps,  # noqa: E731
                                        maxiter=200)
        chunk = 512
        k0 = 0 if y0 < self.sigma else 1  # on the stop: start sampling one step after it
        if k0 == 1 and not (v0 < 0 and g(self.dt) < 0):
            raise RuntimeError(f"exact reference: segment at t={t0} starts on the stop without "
                               f"leaving it (v={v0}); not a regime it handles")
        while t0 + k0 * self.dt < t_end:
            s = self.dt * np.arange(k0, k0 + chunk + 1)  # overlaps the previous chunk by one
            y, v = self.state(t0, c, s)
            gs = y - self.sigma
            below = gs[:-1] < 0
            cross = below & (gs[1:] >= 0)
            peak = below & (gs[1:] < 0) & (v[:-1] > 0) & (v[1:] < 0)
            for i in np.flatnonzero(cross | peak):
                if cross[i]:
                    return root(g, s[i], s[i + 1])
                # a maximum between two samples below the stop: is a crossing hidden there?
                sm = root(vel, s[i], s[i + 1])
                if g(sm) >= 0.0:
                    return root(g, s[i], sm)
            k0 += chunk
        return None

    def impacts(self, t_end, max_impacts=None):
        """Impact times and post-impact velocities from X0 up to t_end."""
        t, y, v = 0.0, X0[0], X0[1]
        times, vplus = [], []
        while max_impacts is None or len(times) < max_impacts:
            s = self.next_impact(t, y, v, t_end)
            if s is None or t + s > t_end:
                break
            c = self.segment(t, y, v)
            _, vm = self.state(t, c, s)
            t, y, v = t + s, self.sigma, -self.r * float(vm)
            times.append(t)
            vplus.append(v)
        return np.array(times), np.array(vplus)


# ------------------------------------------------------------------------------------------
# cold start, measured in subprocesses with empty caches
# ------------------------------------------------------------------------------------------
_COLD_SCRIPT = textwrap.dedent("""
    import json, sys, time
    t0 = time.perf_counter()
    import pwsdyn
    from pwsdyn.model import compile_model, load_model
    t_import = time.perf_counter() - t0
    model = json.loads(sys.argv[1])
    m = load_model(model)
    t0 = time.perf_counter()
    cm = compile_model(m)
    t_model = time.perf_counter() - t0
    T = m.forcing_period_value()
    t0 = time.perf_counter()
    pwsdyn.simulate(model, [0.0, 0.0], (0.0, T), dense=False)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    pwsdyn.simulate(model, [0.0, 0.0], (0.0, T), dense=False)
    t_second = time.perf_counter() - t0
    print(json.dumps(dict(import_s=t_import, model_compile_s=t_model,
                          first_simulate_s=t_first, second_simulate_s=t_second)))
""")


def cold_start(model, fresh_numba_cache: bool):
    """Import + model compilation + first simulate in a fresh process with empty caches.

    ``PWSDYN_CACHE_DIR`` is always a new empty directory (so the model's generated function is
    generated and compiled); with ``fresh_numba_cache`` ``NUMBA_CACHE_DIR`` is too, so the
    integrator kernel is compiled from scratch rather than loaded from the package's
    ``__pycache__`` (which is left untouched).
    """
    with tempfile.TemporaryDirectory(prefix="pwsdyn-bench-") as tmp:
        env = dict(os.environ, PWSDYN_CACHE_DIR=str(Path(tmp) / "pwsdyn"))
        if fresh_numba_cache:
            env["NUMBA_CACHE_DIR"] = str(Path(tmp) / "numba")
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-c", _COLD_SCRIPT, json.dumps(model)], env=env,
                             capture_output=True, text=True)
        wall = time.perf_counter() - t0
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr else "failed"}
    res = json.loads(out.stdout.strip().splitlines()[-1])
    res["process_wall_s"] = wall
    return res


# ------------------------------------------------------------------------------------------
def machine_info():
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import numba
    try:
        load = Path("/proc/loadavg").read_text().split()[:3]
    except OSError:
        load = []
    return {"cpu": cpu, "cores": os.cpu_count(), "loadavg": " ".join(load),
            "platform": platform.platform(),
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__,
            "pwsdyn": pwsdyn.__version__}


def max_abs_diff(a, b, k):
    k = min(k, len(a), len(b))
    return float(np.max(np.abs(a[:k] - b[:k]))) if k else float("nan"), k


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--periods", type=int, default=1000,
                    help="forcing periods simulated by pwsdyn (default 1000)")
    ap.add_argument("--method", choices=("RK45", "DOP853"), default="RK45",
                    help="Runge-Kutta pair, the same for pwsdyn and scipy (RK45)")
    ap.add_argument("--rtol", type=float, default=1e-10, help="relative tolerance (1e-10)")
    ap.add_argument("--atol", type=float, default=None, help="absolute tolerance (rtol*1e-2)")
    ap.add_argument("--scipy-periods", type=int, default=None,
                    help="periods for the (slow) scipy baseline; its cost is extrapolated per "
                         "period (default min(periods, 50))")
    ap.add_argument("--repeats", type=int, default=5, help="pwsdyn repeats, best taken (5)")
    ap.add_argument("--scipy-repeats", type=int, default=3, help="scipy repeats, best taken (3)")
    ap.add_argument("--compare-impacts", type=int, default=20,
                    help="impacts compared against the exact solution (20)")
    for k, v in DEFAULT_PARAMS.items():
        ap.add_argument(f"--{k}", type=float, default=v, help=f"parameter {k} ({v})")
    ap.add_argument("--skip-cold", action="store_true",
                    help="skip the cold-start measurements in subprocesses (~1 min)")
    ap.add_argument("--save", action="store_true",
                    help="write the results to benchmarks/results/impact_oscillator.json")
    args = ap.parse_args(argv)

    rtol = args.rtol
    atol = args.atol if args.atol is not None else rtol * 1e-2
    params = {k: getattr(args, k) for k in DEFAULT_PARAMS}
    model = make_model(params)
    T = 2 * math.pi / params["omega"]
    N = args.periods
    Ns = args.scipy_periods or min(N, 50)
    K = args.compare_impacts
    meth = args.method
    print(f"Impact oscillator x'' + {params['eps']} x' + x = sin({params['omega']} t), "
          f"x <= {params['sigma']}, v -> -{params['r']} v;  (x, v)(0) = {X0}, T = {T:.6f}")
    print(f"{meth}, rtol = {rtol:g}, atol = {atol:g}; pwsdyn {N} periods, scipy {Ns} periods")
    info = machine_info()
    print(f"machine: {info['cpu']}, {info['cores']} cores; Python {info['python']}, "
          f"numpy {info['numpy']}, scipy {info['scipy']}, numba {info['numba']}; "
          f"load average at start {info['loadavg']}")

    # --- pwsdyn: first call (cache load / compile), then best of repeats ------------------
    t0 = time.perf_counter()
    pwsdyn_run(model, T, rtol, atol, False, meth)
    first_call = time.perf_counter() - t0
    cm = compile_model(load_model(model))
    # pwsdyn (both modes) and scipy timed round-robin; the exact reference once
    tm_nd = Timer(lambda: pwsdyn_run(model, N * T, rtol, atol, False, meth))
    tm_d = Timer(lambda: pwsdyn_run(model, N * T, rtol, atol, True, meth))
    tm_sp = Timer(lambda: scipy_run(params, Ns * T, rtol, atol, meth))
    # the 8th-order pair at the same tolerances: what a user gets by switching `method`
    pwsdyn_run(model, T, rtol, atol, False, "DOP853")
    tm_8 = Timer(lambda: pwsdyn_run(model, N * T, rtol, atol, False, "DOP853"))
    # exact propagation of the affine free flight (exp(h M) of the forced system)
    pwsdyn_run(model, T, rtol, atol, False, exact=True)
    tm_xp = Timer(lambda: pwsdyn_run(model, N * T, rtol, atol, False, exact=True))
    time_interleaved([(tm_nd, args.repeats), (tm_d, args.repeats), (tm_8, args.repeats),
                      (tm_xp, args.repeats), (tm_sp, args.scipy_repeats)])
    exact = ExactImpactOscillator(params)
    tm_ex = Timer(lambda: exact.impacts(Ns * T))
    tm_ex.run()
    traj_nd, traj_d = tm_nd.result, tm_d.result
    ti_sp, vp_sp, nfev_sp, nudges, _ = tm_sp.result
    ti_ex, vp_ex = tm_ex.result
    ti_nd, vp_nd, vm_nd = pwsdyn_impacts(traj_nd)
    ti_d, vp_d, _ = pwsdyn_impacts(traj_d)
    ti_8, vp_8, _ = pwsdyn_impacts(tm_8.result)
    ti_xp, vp_xp, _ = pwsdyn_impacts(tm_xp.result)
    other = sorted({e.kind for e in traj_nd.events if e.kind != "impact"})
    dense_same = len(ti_d) == len(ti_nd) and bool(np.all(ti_d == ti_nd) and np.all(vp_d == vp_nd))

    # impacts per period, and periodicity of the settled orbit (last half of the run)
    per_period = len(ti_nd) / N
    late = ti_nd > N * T / 2
    phase = np.mod(ti_nd[late], T)
    phase = np.minimum(phase, T - phase) if phase.size and np.ptp(phase) > T / 2 else phase
    phase_spread = float(np.ptp(phase)) if phase.size else float("nan")
    late_per_period = late.sum() / (N - N // 2) if N > 1 else float("nan")
    print(f"\npwsdyn: {len(ti_nd)} impacts in {N} periods ({per_period:.3f}/period; "
          f"{late_per_period:.3f}/period over the second half, impact phase spread there "
          f"{phase_spread:.1e}); smallest impact speed {np.min(np.abs(vm_nd)):.3f}; "
          f"other events: {other or 'none'}")
    print(f"pwsdyn stats (dense=False): {traj_nd.stats}")
    print(f"dense=True and dense=False give identical impacts: {dense_same}")

    print(f"scipy: {len(ti_sp)} impacts in {Ns} periods, {nfev_sp} rhs evaluations, "
          f"{nudges} restart nudges")


    # --- agreement ----------------------------------------------------------------------
    n_sp = len(ti_sp)
    in_window = ti_nd[ti_nd <= Ns * T]
    count_ok = len(in_window) == n_sp == len(ti_ex)
    d_t_ps, k_ps = max_abs_diff(ti_nd, ti_sp, n_sp)
    d_v_ps, _ = max_abs_diff(vp_nd, vp_sp, n_sp)
    err = {}
    for name, (ti, vp) in {"pwsdyn": (ti_nd, vp_nd), "scipy": (ti_sp, vp_sp),
                           "pwsdyn_dop853": (ti_8, vp_8),
                           "pwsdyn_exact": (ti_xp, vp_xp)}.items():
        et, k_ex = max_abs_diff(ti, ti_ex, K)
        ev, _ = max_abs_diff(vp, vp_ex, K)
        et_all, _ = max_abs_diff(ti, ti_ex, len(ti_ex))
        ev_all, _ = max_abs_diff(vp, vp_ex, len(ti_ex))
        err[name] = dict(t=et, v=ev, t_window=et_all, v_window=ev_all, impacts=k_ex)
    tol = 1e3 * rtol  # agreement expected from the local tolerance
    agree = (count_ok and d_t_ps <= tol and d_v_ps <= tol
             and all(e["t"] <= tol and e["v"] <= tol for e in err.values()))
    print(f"\nimpact counts in the first {Ns} periods: pwsdyn {len(in_window)}, scipy {n_sp}, "
          f"exact {len(ti_ex)}")
    print(f"pwsdyn vs scipy over {k_ps} impacts: max |dt| = {d_t_ps:.2e}, "
          f"max |dv+| = {d_v_ps:.2e}")
    for name, e in err.items():
        print(f"{name} vs exact, first {e['impacts']} impacts: max |dt| = {e['t']:.2e}, "
              f"max |dv+| = {e['v']:.2e}  (all {len(ti_ex)} in the window: "
              f"{e['t_window']:.2e}, {e['v_window']:.2e})")
    print(f"agreement within {tol:.0e}: {'OK' if agree else 'FAILED'}")

    # --- table --------------------------------------------------------------------------
    us = lambda sec, n: 1e6 * sec / n  # noqa: E731
    rows = [
        ("pwsdyn dense=False", N, tm_nd, err["pwsdyn"]),
        ("pwsdyn dense=True", N, tm_d, err["pwsdyn"]),
        ("pwsdyn DOP853 dense=F", N, tm_8, err["pwsdyn_dop853"]),
        ("pwsdyn exact dense=F", N, tm_xp, err["pwsdyn_exact"]),
        (f"scipy solve_ivp {meth}*", Ns, tm_sp, err["scipy"]),
        ("exact (closed form)", Ns, tm_ex, None),
    ]
    base, base_cpu = us(tm_nd.wall, N), us(tm_nd.cpu, N)
    print(f"\n{'method':<24}{'periods':>8}{'wall s':>9}{'us/period':>11}{'ratio':>8}"
          f"{'CPU us/per':>12}{'ratio':>8}{'max|dt| exact':>15}{'max|dv+| exact':>16}")
    for name, n, tm, e in rows:
        et = "(reference)" if e is None else f"{e['t']:.2e}"
        ev = "" if e is None else f"{e['v']:.2e}"
        u, uc = us(tm.wall, n), us(tm.cpu, n)
        print(f"{name:<24}{n:>8}{tm.wall:>9.3f}{u:>11.1f}{u / base:>8.1f}{uc:>12.1f}"
              f"{uc / base_cpu:>8.1f}{et:>15}{ev:>16}")
    ratio_nd = us(tm_sp.wall, Ns) / base
    ratio_d = us(tm_sp.wall, Ns) / us(tm_d.wall, N)
    ratio_cpu = us(tm_sp.cpu, Ns) / base_cpu
    print(f"Best of {args.repeats} (pwsdyn) / {args.scipy_repeats} (scipy) interleaved runs; "
          f"ratio = per-period time / pwsdyn dense=False. * scipy measured on {Ns} periods,\n"
          f"extrapolated per period. Errors vs exact over the first {err['pwsdyn']['impacts']} "
          f"impacts. All "
          f"single-threaded.")
    print(f"scipy / pwsdyn per period: {ratio_nd:.0f}x (dense=False), {ratio_d:.0f}x "
          f"(dense=True); by CPU time {ratio_cpu:.0f}x (dense=False). Target >= 300x.")
    ratio_8 = us(tm_sp.wall, Ns) / us(tm_8.wall, N)
    print(f"scipy {meth} / pwsdyn DOP853 at the same rtol/atol (dense=False): {ratio_8:.0f}x, "
          f"with errors vs exact {err['pwsdyn_dop853']['t']:.1e} (scipy "
          f"{err['scipy']['t']:.1e})")
    ratio_xp = us(tm_sp.wall, Ns) / us(tm_xp.wall, N)
    print(f"scipy {meth} / pwsdyn exact=True (dense=False): {ratio_xp:.0f}x, with errors vs "
          f"exact {err['pwsdyn_exact']['t']:.1e} (scipy {err['scipy']['t']:.1e})")
    print(f"pwsdyn start-up in this process (excluded above): import {IMPORT_S:.2f} s (loads the "
          f"kernel from numba's cache), first simulate {first_call:.2f} s (of which loading the "
          f"model's generated function {cm.compile_seconds:.2f} s)")

    cold = {}
    if not args.skip_cold:
        cold["fresh_model_cache"] = cold_start(model, fresh_numba_cache=False)
        cold["fresh_model_and_numba_cache"] = cold_start(model, fresh_numba_cache=True)
        for k, c in cold.items():
            if "error" in c:
                print(f"cold start ({k}): failed: {c['error']}")
                continue
            print(f"cold start, {k.replace('_', ' ')}: import {c['import_s']:.2f} s, model "
                  f"codegen+compile {c['model_compile_s']:.2f} s, first simulate (1 period) "
                  f"{c['first_simulate_s'] * 1e3:.1f} ms, second {c['second_simulate_s'] * 1e3:.1f} ms")
        a, b = cold["fresh_model_cache"], cold["fresh_model_and_numba_cache"]
        if "error" not in a and "error" not in b:
            cold["kernel_compile_s_estimate"] = b["import_s"] - a["import_s"]
            print(f"=> numba compilation of the integrator kernel (once per installation): "
                  f"~{cold['kernel_compile_s_estimate']:.0f} s; of a new model's function: "
                  f"~{a['model_compile_s']:.1f} s")

    if args.save:
        res = {
            "benchmark": "impact_oscillator",
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "machine": info,
            "model": model, "x0": list(X0), "forcing_period": T,
            "method": meth, "rtol": rtol, "atol": atol,
            "impacts_per_period": per_period, "impacts_per_period_settled": late_per_period,
            "settled_phase_spread": phase_spread,
            "pwsdyn": {"periods": N, "repeats": args.repeats, "import_s": IMPORT_S,
                       "first_call_s": first_call,
                       "model_function_load_s": cm.compile_seconds,
                       "dense_false": {"seconds": tm_nd.wall, "us_per_period": us(tm_nd.wall, N),
                                       "cpu_us_per_period": us(tm_nd.cpu, N)},
                       "dense_true": {"seconds": tm_d.wall, "us_per_period": us(tm_d.wall, N),
                                      "cpu_us_per_period": us(tm_d.cpu, N)},
                       "dop853_dense_false": {"seconds": tm_8.wall,
                                              "us_per_period": us(tm_8.wall, N)},
                       "exact_dense_false": {"seconds": tm_xp.wall,
                                             "us_per_period": us(tm_xp.wall, N),
                                             "stats": tm_xp.result.stats},
                       "stats": traj_nd.stats, "dense_identical_impacts": dense_same},
            "scipy": {"periods": Ns, "repeats": args.scipy_repeats, "seconds": tm_sp.wall,
                      "us_per_period": us(tm_sp.wall, Ns), "cpu_us_per_period": us(tm_sp.cpu, Ns),
                      "nfev": nfev_sp, "nudges": nudges,
                      "extrapolated": Ns < N},
            "exact": {"periods": Ns, "seconds": tm_ex.wall, "us_per_period": us(tm_ex.wall, Ns),
                      "impacts": len(ti_ex)},
            "ratio_scipy_over_pwsdyn": {"dense_false": ratio_nd, "dense_true": ratio_d,
                                        "pwsdyn_dop853_dense_false": ratio_8,
                                        "pwsdyn_exact_dense_false": ratio_xp,
                                        "dense_false_cpu_time": ratio_cpu},
            "agreement": {"tolerance": tol, "ok": agree, "impact_counts_match": count_ok,
                          "pwsdyn_vs_scipy": {"impacts": k_ps, "max_dt": d_t_ps,
                                              "max_dv_plus": d_v_ps},
                          "vs_exact": err},
            "cold_start": cold,
        }
        out = HERE / "results" / "impact_oscillator.json"
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(res, indent=2) + "\n")
        print(f"\nsaved {out}")
    return 0 if agree else 2


if __name__ == "__main__":
    sys.exit(main())
