"""Benchmark: a periodic orbit with its Floquet multipliers, pwsdyn against the scipy way.

Cases (their closed forms are in ``tests/_orbit_cases.py``):

* ``impact-oscillator, stable`` and ``unstable``: the one-impact orbits of the forced impact
  oscillator x'' + eps x' + x = sin(omega t), x <= sigma, v -> -r v at x = sigma
  (eps = 0.1, sigma = -0.5, omega = 2.8, r = 0.8): a stable orbit (complex multipliers of
  modulus 0.715) and a saddle (multipliers 2.95, 0.173), each from a guess 1e-2 off the
  closed-form orbit;
* ``vdp-wall``: an autonomous impacting cycle (Van der Pol, mu = 1, against a wall at
  x = 1.5 with r = 0.7), period unknown, from the state of a short simulation.

Contenders, timed in one process after a warm-up (compilation and caches excluded):

* ``pwsdyn``: ``pwsdyn.find_periodic_orbit`` (Newton shooting on the compiled kernel with the
  variational equations and saltation matrices; multipliers from the monodromy matrix), with
  its defaults (DOP853, rtol = atol = 1e-12).
* ``scipy``: what a user writes today: a Poincaré map from ``solve_ivp`` (DOP853, same
  tolerances) restarted at each impact with a terminal event -- the stroboscopic map
  ``x(t0) -> x(t0 + T)`` for the forced oscillator, the impact map ``v+ -> v+`` on the wall for
  the autonomous one -- solved by ``scipy.optimize.fsolve`` (MINPACK ``hybrd``: its own
  finite-difference Jacobian and Broyden updates) at ``xtol = 1e-10``, then the multipliers
  from a central finite-difference Jacobian of the map at the solution (``2 n`` more map
  evaluations, relative step 1e-6).

Reported per case: wall and CPU time (best of ``--repeats``), their ratio scipy / pwsdyn,
the number of map evaluations, and the accuracy of both against the closed form (impact
phase and velocity, multipliers) or against each other (vdp-wall). Timings are never
asserted; the script exits with status 2 if a method misses the closed form by more than
1e-6 (orbit) or 1e-4 (multipliers).

Run::

    python benchmarks/bench_orbit.py [--repeats 5] [--save] [--label after]

``--save`` writes ``results/orbit.json``, keeping the rows of other labels (a run of the code
before a change, ``PYTHONPATH`` at its ``src``, and one after sit side by side).

``--base PATH`` times a previous version's ``src`` alongside this checkout's, in one run: worker
processes of the two trees alternate for ``--rounds`` rounds (so both see the same load), each
timing every case with its own scipy baseline; the best times per tree are reported (labels
``before`` and ``after``) with the speed-up of pwsdyn between them, and the orbits the two
trees found are compared bit for bit (state, period, multipliers; exit status 2 if they
differ)::

    python benchmarks/bench_orbit.py --base /path/to/old/src --save
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.optimize import fsolve  # noqa: E402

import pwsdyn  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from _orbit_cases import IO, closed_form_state, io_closed_form  # noqa: E402

RTOL = ATOL = 1e-12
VDP = {
    "name": "vdp-wall", "states": ["x", "v"],
    "parameters": {"mu": 1.0, "sigma": 1.5, "r": 0.7},
    "modes": {"free": {"x": "v", "v": "mu*(1 - x**2)*v - x"}},
    "events": [{"name": "wall", "kind": "impact", "surface": "sigma - x", "reset": {"v": "-r*v"}}],
}


# ======================================================================================
# the scipy way
# ======================================================================================

class ScipyImpactFlow:
    """solve_ivp restarted at each impact (terminal event, direction -1), counting calls."""

    def __init__(self, rhs, surface, reset):
        self.rhs, self.reset = rhs, reset

        def ev(t, y):
            return surface(t, y)
        ev.terminal, ev.direction = True, -1
        self.event = ev
        self.maps = 0

    def flow(self, x, t0, t1, stop_at_impact=False):
        t, y = t0, np.asarray(x, float)
        while t < t1:
            sol = solve_ivp(self.rhs, (t, t1), y, method="DOP853", rtol=RTOL, atol=ATOL,
                            events=[self.event])
            if sol.status != 1:
                return sol.y[:, -1], t1
            t, y = sol.t_events[0][0], self.reset(sol.t_events[0][0], sol.y_events[0][0])
            if stop_at_impact:
                return y, t
        return y, t


def scipy_forced(guess, t0, T):
    fl = ScipyImpactFlow(lambda t, y: [y[1], np.sin(IO["omega"] * t) - IO["eps"] * y[1] - y[0]],
                         lambda t, y: IO["sigma"] - y[0],
                         lambda t, y: np.array([y[0], -IO["r"] * y[1]]))

    def P(x):
        fl.maps += 1
        return fl.flow(x, t0, t0 + T)[0]

    x = fsolve(lambda x: P(x) - x, guess, xtol=1e-10)
    h = 1e-6
    J = np.column_stack([(P(x + h * e) - P(x - h * e)) / (2 * h) for e in np.eye(2)])
    return x, np.linalg.eigvals(J), fl.maps


def scipy_vdp(v_guess):
    """1D impact map v+ -> v+ on the wall x = sigma (the post-impact state (sigma, v+))."""
    mu, sigma, r = 1.0, 1.5, 0.7
    fl = ScipyImpactFlow(lambda t, y: [y[1], mu * (1 - y[0] ** 2) * y[1] - y[0]],
                         lambda t, y: sigma - y[0], lambda t, y: np.array([y[0], -r * y[1]]))

    def P(v):
        fl.maps += 1
        return fl.flow([sigma, float(np.ravel(v)[0])], 0.0, 100.0, stop_at_impact=True)[0][1]

    v = fsolve(lambda v: P(v) - v, [v_guess], xtol=1e-10)[0]
    h = 1e-6 * abs(v)
    mult = (P(v + h) - P(v - h)) / (2 * h)
    T = fl.flow([sigma, v], 0.0, 100.0, stop_at_impact=True)[1]
    return v, mult, T, fl.maps


# ======================================================================================
# cases
# ======================================================================================

def forced_case(which):
    cf = io_closed_form()[which]
    T = cf["T"]
    t0 = cf["t0"] + 0.3 * T
    exact = closed_form_state(cf, IO["sigma"], IO["r"], t0)
    guess = exact + np.array([0.01, -0.01])

    model = pwsdyn.load_model("impact-oscillator")     # loaded once, as in a user's script

    def run_pwsdyn():
        o = pwsdyn.find_periodic_orbit(model, guess, params=IO, t0=t0)
        return o.x0, o.multipliers, len(o.history) - 1, o.t0

    def run_scipy():
        x, mu, maps = scipy_forced(guess, t0, T)
        return x, mu, maps

    def check(pw, sc):
        # pwsdyn may move its base point into a smooth segment: compare at the impact
        o = pwsdyn.find_periodic_orbit("impact-oscillator", guess, params=IO, t0=t0)
        e = o.events[0]
        err_pw = max(abs(((e.t - cf["t0"]) % T + T / 2) % T - T / 2),
                     abs(e.x_before[1] - cf["v"]))
        err_sc = float(np.max(np.abs(sc[0] - exact)))
        mu = np.sort_complex(cf["mu"])
        return dict(orbit_err_pwsdyn=err_pw, orbit_err_scipy=err_sc,
                    mult_err_pwsdyn=float(np.max(np.abs(np.sort_complex(pw[1]) - mu))),
                    mult_err_scipy=float(np.max(np.abs(np.sort_complex(sc[1]) - mu))),
                    multipliers=[str(np.round(m, 10)) for m in mu],
                    newton_iterations=pw[2], scipy_map_evaluations=sc[2])
    return run_pwsdyn, run_scipy, check


def vdp_case():
    model = pwsdyn.load_model(VDP)
    tr = pwsdyn.simulate(model, [0.1, 0.0], (0, 25))
    guess_x, guess_t = tr.x_final, tr.t_final
    v_guess = -0.7 * tr.events[-1].x_before[1]

    def run_pwsdyn():
        o = pwsdyn.find_periodic_orbit(model, guess_x, period=4.9, t0=guess_t)
        return o

    def run_scipy():
        return scipy_vdp(v_guess)

    def check(pw, sc):
        v_pw = pw.events[0].x_after[1]
        return dict(period_pwsdyn=pw.period, period_scipy=sc[2],
                    orbit_diff=abs(v_pw - sc[0]), period_diff=abs(pw.period - sc[2]),
                    multiplier_pwsdyn=float(np.real(pw.multipliers[0])),
                    multiplier_scipy=float(sc[1]),
                    mult_diff=abs(float(np.real(pw.multipliers[0])) - sc[1]),
                    newton_iterations=len(pw.history) - 1, scipy_map_evaluations=sc[3])
    return run_pwsdyn, run_scipy, check


def timed(fn, repeats):
    best_w = best_c = np.inf
    out = None
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        best_w = min(best_w, time.perf_counter() - w)
        best_c = min(best_c, time.process_time() - c)
    return out, best_w, best_c


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str(a.dtype).encode() + repr(a.shape).encode() + a.tobytes())
    return h.hexdigest()[:16]


def _run_tree(src: Path, args) -> list:
    """The rows of one worker process with ``src`` first on the path."""
    env = dict(os.environ, PYTHONPATH=str(src))
    cmd = [sys.executable, __file__, "--worker", "--repeats", str(args.repeats)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode not in (0, 2):
        sys.stderr.write(out.stderr)
        raise SystemExit(f"worker for {src} failed")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main_base(args) -> int:
    """Before (``--base``) and after (this checkout) in one run, alternating workers."""
    trees = {"before": args.base.resolve(), "after": HERE.parent / "src"}
    runs = {k: [] for k in trees}
    for _ in range(args.rounds):
        for k, src in trees.items():
            runs[k].append(_run_tree(src, args))
    rows, status = [], 0
    print(f"{'case':<30} {'tree':<7} {'pwsdyn ms':>10} {'scipy ms':>10} {'ratio':>7} "
          f"{'ratio CPU':>9}")
    for i, case in enumerate(r["case"] for r in runs["after"][0]):
        best = {}
        for k in trees:
            rs = [run[i] for run in runs[k]]
            row = dict(rs[-1], label=k)
            for key in ("pwsdyn_wall_s", "pwsdyn_cpu_s", "scipy_wall_s", "scipy_cpu_s"):
                row[key] = min(r[key] for r in rs)
            row["ratio_wall"] = row["scipy_wall_s"] / row["pwsdyn_wall_s"]
            row["ratio_cpu"] = row["scipy_cpu_s"] / row["pwsdyn_cpu_s"]
            best[k] = row
            rows.append(row)
            print(f"{case:<30} {k:<7} {1e3 * row['pwsdyn_wall_s']:>10.2f} "
                  f"{1e3 * row['scipy_wall_s']:>10.2f} {row['ratio_wall']:>7.1f} "
                  f"{row['ratio_cpu']:>9.1f}")
        same = best["before"]["orbit_digest"] == best["after"]["orbit_digest"]
        status = status if same else 2
        print(f"{'':<30} pwsdyn after / before: wall "
              f"{best['after']['pwsdyn_wall_s'] / best['before']['pwsdyn_wall_s']:.3f}, CPU "
              f"{best['after']['pwsdyn_cpu_s'] / best['before']['pwsdyn_cpu_s']:.3f}; orbits "
              + ("bit-identical" if same else "DIFFER"))
    if args.save:
        meta = dict(date=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    machine=platform.machine(), python=platform.python_version(),
                    numpy=np.__version__, scipy=scipy.__version__, cpus=os.cpu_count(),
                    load=os.getloadavg(), repeats=args.repeats, rounds=args.rounds,
                    trees={"before": "the src given as --base", "after": "this checkout's src"},
                    identical=status == 0)
        (HERE / "results").mkdir(exist_ok=True)
        with open(HERE / "results" / "orbit.json", "w") as fh:
            json.dump(dict(meta=meta, rows=rows), fh, indent=1, default=str)
    return status


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--save", action="store_true", help="write results/orbit.json")
    ap.add_argument("--label", default="current",
                    help="name of this run's rows in the saved file (e.g. before, after)")
    ap.add_argument("--base", type=Path, help="a previous version's src, timed alongside")
    ap.add_argument("--rounds", type=int, default=3, help="worker rounds per tree (--base)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.base is not None:
        return main_base(args)
    cases = {"impact-oscillator, stable": forced_case("stable"),
             "impact-oscillator, unstable": forced_case("unstable"),
             "vdp-wall (autonomous)": vdp_case()}
    rows, ok = [], True
    print(f"{'case':<30} {'pwsdyn ms':>10} {'scipy ms':>10} {'ratio':>7} {'ratio CPU':>9}  "
          f"accuracy")
    for name, (rp, rs, check) in cases.items():
        rp()
        rs()                                    # warm-up: model compilation, caches
        pw, wp, cp = timed(rp, args.repeats)
        sc, ws, cs = timed(rs, max(1, args.repeats // 2))
        acc = check(pw, sc)
        o = pw if isinstance(pw, pwsdyn.PeriodicOrbit) else None
        dig = (_digest(o.x0, o.period, o.multipliers, o.monodromy) if o is not None else
               _digest(pw[0], pw[1], pw[3]))
        row = dict(label=args.label, case=name, pwsdyn_wall_s=wp, pwsdyn_cpu_s=cp, scipy_wall_s=ws,
                   scipy_cpu_s=cs, ratio_wall=ws / wp, ratio_cpu=cs / cp, orbit_digest=dig,
                   **acc)
        rows.append(row)
        if "orbit_err_pwsdyn" in acc:
            txt = (f"orbit err pwsdyn {acc['orbit_err_pwsdyn']:.1e} scipy "
                   f"{acc['orbit_err_scipy']:.1e}; multipliers pwsdyn "
                   f"{acc['mult_err_pwsdyn']:.1e} scipy {acc['mult_err_scipy']:.1e}")
            ok &= acc["orbit_err_pwsdyn"] < 1e-6 and acc["mult_err_pwsdyn"] < 1e-4
            ok &= acc["orbit_err_scipy"] < 1e-6 and acc["mult_err_scipy"] < 1e-4
        else:
            txt = (f"|dv+| {acc['orbit_diff']:.1e}, |dT| {acc['period_diff']:.1e}, "
                   f"|dmu| {acc['mult_diff']:.1e} (pwsdyn vs scipy)")
            ok &= acc["orbit_diff"] < 1e-6 and acc["mult_diff"] < 1e-4
        print(f"{name:<30} {1e3 * wp:>10.2f} {1e3 * ws:>10.2f} {ws / wp:>7.1f} "
              f"{cs / cp:>9.1f}  {txt}")
    meta = dict(date=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                machine=platform.machine(), python=platform.python_version(),
                numpy=np.__version__, scipy=scipy.__version__, pwsdyn=pwsdyn.__version__,
                cpus=os.cpu_count(), load=os.getloadavg(), repeats=args.repeats)
    if args.save:
        (HERE / "results").mkdir(exist_ok=True)
        # the rows of other labels are kept: a run of the code before a change and one after
        # sit side by side, each with its own scipy baseline (ratios compared)
        path = HERE / "results" / "orbit.json"
        old = json.loads(path.read_text()) if path.exists() else {}
        kept = [r for r in old.get("rows", []) if r.get("label", "") not in ("", args.label)]
        for r in rows:
            r["meta"] = meta
        with open(path, "w") as fh:
            json.dump(dict(meta=meta, rows=kept + rows), fh, indent=1, default=str)
    if args.worker:
        print(json.dumps(rows, default=str))
    if not ok:
        print("accuracy check FAILED", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
