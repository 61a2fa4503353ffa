"""Benchmark: a 200-point branch of periodic orbits with their multipliers, pwsdyn against
doing the same by hand with scipy.

The branch: the one-impact orbit of the forced impact oscillator x'' + eps x' + x =
sin(omega t), x <= sigma, v -> -r v at x = sigma (eps = 0.1, sigma = -0.5, r = 0.8), followed
in omega from 2.8 (through its period doubling at omega = 4.32) -- its closed form is in
``tests/_orbit_cases.py``.

Contenders, timed in one process after a warm-up (compilation and caches excluded):

* ``pwsdyn``: ``pwsdyn.continue_orbit`` from the orbit at omega = 2.8 with a fixed step
  (``ds = ds_max = 0.02``, 200 points), its defaults otherwise (DOP853, rtol = atol = 1e-12,
  multipliers, admissibility and test functions at every point, special points located).
* ``scipy``: what a user writes by hand today: natural-parameter continuation on the same
  omega values -- at each, ``scipy.optimize.fsolve`` (xtol 1e-10) on the stroboscopic map
  ``x(0) -> x(T)`` computed by ``solve_ivp`` (DOP853, same tolerances) restarted at each
  impact with a terminal event, started from the previous point's solution, then the
  multipliers from a central finite-difference Jacobian of the map (relative step 1e-6).

Reported: time per point (wall and CPU, best of ``--repeats``), the ratio scipy / pwsdyn, and
the largest error of each against the closed form (orbit state and multipliers). Timings are
never asserted; exit status 2 if an accuracy check fails (1e-8 pwsdyn, 1e-6 scipy).

Then the breakdown of a pwsdyn point's cost, from one more run with timers around (here only,
never in the library):

* ``kernel``: the compiled integrator's entry points called from Python (``run_kernel``,
  ``dense_coefficients``, ``state_field``, ``chatter_saltation``);
* ``linalg``: ``numpy.linalg`` calls (solves, SVDs, determinants, eigenvalues, norms);
* ``monitors``: the test functions, the orbit's discontinuity-induced-bifurcation monitors and
  its admissibility (their own Python; the kernel runs and linear algebra inside them are
  counted as those);
* ``python``: the rest (the engine, the orbit problem's residual and Jacobian assembly, the
  multipliers' bookkeeping, argument checks, the model's point evaluations from Python).

Each interval of CPU time (``time.process_time``: the machine may be shared, and waiting for
a core is nobody's cost) is charged to the innermost timer open (exclusive times). The timers
cost a little themselves, so the breakdown's total exceeds the plain run's; ``total /
kernel`` is reported both from the timed run alone (``timed_over_kernel``, the steadier
figure: both from one run) and as the plain run's CPU time per point over the timed kernel
time (``total_over_kernel``).

Run::

    python benchmarks/bench_continuation.py [--repeats 3] [--points 200] [--save]
        [--label after] [--base /path/to/old/src [--rounds 3]]

``--base`` also times a previous version's ``src`` and this checkout's in worker processes
that take turns (the load of a shared machine moves in between), best CPU time of each, and
compares their branches bit for bit (points, multipliers, test functions, special points).

``--save`` writes ``results/continuation.json``, keeping the rows of other labels (so that a
run of the code before a change and one after sit side by side, each with its own scipy
baseline, ratios compared); the trees of ``--base`` are named there by their commit, not by
their paths on this machine.
"""

from __future__ import annotations

import argparse
import json
import os
import hashlib
import platform
import subprocess
import sys
import time
from collections import defaultdict
from datetime import datetime, timezone
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.linalg import expm  # noqa: E402
from scipy.optimize import fsolve  # noqa: E402

import pwsdyn  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from _orbit_cases import IO, io_one_impact, io_orbit  # noqa: E402

RTOL = ATOL = 1e-12


def scipy_branch(omegas, x_start):
    """Natural-parameter continuation with fsolve on the stroboscopic map at t = 0."""
    eps, sigma, r = IO["eps"], IO["sigma"], IO["r"]

    def ev(t, y):
        return sigma - y[0]
    ev.terminal, ev.direction = True, -1
    out, x = [], np.asarray(x_start, float)
    for w in omegas:
        T = 2 * np.pi / w

        def rhs(t, y, w=w):
            return [y[1], np.sin(w * t) - eps * y[1] - y[0]]

        def P(z, T=T, rhs=rhs):
            t, y = 0.0, np.asarray(z, float)
            while t < T:
                sol = solve_ivp(rhs, (t, T), y, method="DOP853", rtol=RTOL, atol=ATOL,
                                events=[ev])
                if sol.status != 1:
                    return sol.y[:, -1]
                t = sol.t_events[0][0]
                y = sol.y_events[0][0] * np.array([1.0, -r])
            return y

        x = fsolve(lambda z: P(z) - z, x, xtol=1e-10)
        h = 1e-6
        J = np.column_stack([(P(x + h * e) - P(x - h * e)) / (2 * h) for e in np.eye(2)])
        out.append((w, x.copy(), np.linalg.eigvals(J)))
    return out


def closed_form_at_zero(w):
    """The closed-form orbit's state at t = 0 (mod T) and its multipliers."""
    v, t0, M, _ = io_one_impact(w, 1)
    T = 2 * np.pi / w
    eps = IO["eps"]
    A = np.array([[0.0, 1.0], [-1.0, -eps]])
    X, Y = np.linalg.solve(np.array([[1 - w**2, -eps * w], [eps * w, 1 - w**2]]), [1.0, 0.0])

    def zp(t):
        return np.array([X * np.sin(w * t) + Y * np.cos(w * t),
                         w * (X * np.cos(w * t) - Y * np.sin(w * t))])
    z0 = np.array([IO["sigma"], -IO["r"] * v]) - zp(t0)
    return expm(A * (T - t0)) @ z0 + zp(T), np.linalg.eigvals(M)


def timed(fn, repeats):
    best_w = best_c = np.inf
    out = None
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        best_w = min(best_w, time.perf_counter() - w)
        best_c = min(best_c, time.process_time() - c)
    return out, best_w, best_c


class Breakdown:
    """Exclusive CPU time per category: wrappers push their category on entry and pop it on
    exit; the time between two such moments goes to the category on top."""

    def __init__(self):
        self.time = defaultdict(float)
        self.calls = defaultdict(int)
        self._stack = ["python"]
        self._mark = 0.0
        self._undo = []

    def _switch(self):
        now = time.process_time()
        self.time[self._stack[-1]] += now - self._mark
        self._mark = now

    def wrap(self, owner, name, category):
        fn = getattr(owner, name)

        def timed(*args, **kwargs):
            self._switch()
            self._stack.append(category)
            self.calls[category] += 1
            try:
                return fn(*args, **kwargs)
            finally:
                self._switch()
                self._stack.pop()
        self._undo.append((owner, name, fn))
        setattr(owner, name, timed)

    def run(self, fn):
        self._mark = time.process_time()
        try:
            return fn()
        finally:
            self._switch()
            for owner, name, fn_ in reversed(self._undo):
                setattr(owner, name, fn_)
            self._undo.clear()


def breakdown(run):
    """One run of ``run`` with the timers of the module docstring around."""
    from pwsdyn.continuation import engine, problems
    from pwsdyn.integrate._load import kernel
    from pwsdyn.orbits.problem import OrbitProblem

    b = Breakdown()
    K = kernel()
    for name in ("run_kernel", "dense_coefficients", "state_field", "chatter_saltation"):
        if hasattr(K, name):
            b.wrap(K, name, "kernel")
    for name in ("solve", "lstsq", "svd", "slogdet", "det", "eig", "eigvals", "norm", "inv",
                 "qr", "cond"):
        b.wrap(np.linalg, name, "linalg")
    for owner, name in ((OrbitProblem, "dib_monitors"), (OrbitProblem, "admissibility"),
                        (engine.Continuation, "_tests"),
                        (problems.OrbitBranchProblem, "test_functions")):
        b.wrap(owner, name, "monitors")
    br = b.run(run)
    return br, dict(b.time), dict(b.calls)


def branch_digest(br) -> str:
    """The branch's points, multipliers and special points, bit for bit."""
    h = hashlib.sha256()
    for p in br.points:
        h.update(np.asarray(p.u, dtype=float).tobytes())
        h.update(np.float64(p.lam).tobytes())
        h.update(np.asarray(p.data["multipliers"], dtype=complex).tobytes())
        h.update(repr(sorted(p.tests.items())).encode())
    h.update(repr([(s.kind, s.value) for s in br.special_points]).encode())
    return h.hexdigest()


def worker(args) -> dict:
    """``--repeats`` timed branches of the source tree on ``PYTHONPATH`` (``--base`` mode)."""
    model = pwsdyn.load_model("impact-oscillator")
    orb = io_orbit("stable")

    def run_pwsdyn():
        return pwsdyn.continue_orbit(model, orb, "omega", span=(2.0, 10.0), ds=0.02,
                                     ds_max=0.02, max_points=args.points)
    run_pwsdyn()
    br, wp, cp = timed(run_pwsdyn, args.repeats)
    return dict(wall_s=wp, cpu_s=cp, points=len(br), digest=branch_digest(br),
                pwsdyn=str(Path(pwsdyn.__file__).parent))


def compare_trees(base: Path, args) -> dict:
    """The code before (``base``, a ``src`` directory) and this checkout's, in worker
    processes taking turns (``--rounds`` each), best CPU time of each."""
    trees = {"before": base.resolve(), "after": HERE.parent / "src"}
    runs = {k: [] for k in trees}
    for _ in range(args.rounds):
        for k, src in trees.items():
            env = dict(os.environ, PYTHONPATH=str(src))
            cmd = [sys.executable, __file__, "--worker", "--repeats", str(args.repeats),
                   "--points", str(args.points)]
            out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
            if out.returncode:
                sys.stderr.write(out.stderr)
                raise SystemExit(f"worker for {src} failed")
            runs[k].append(json.loads(out.stdout.strip().splitlines()[-1]))
    return {k: dict(cpu_s=min(w["cpu_s"] for w in v), wall_s=min(w["wall_s"] for w in v),
                    points=v[-1]["points"], digest=v[-1]["digest"], src=str(trees[k]),
                    imported=v[-1]["pwsdyn"], revision=_revision(trees[k]))
            for k, v in runs.items()}


def _revision(src: Path) -> str:
    """The commit of the checkout holding ``src`` (``+`` where its files differ from it), the
    name a saved row gives a tree instead of its path on this machine."""
    def git(*a):
        return subprocess.run(["git", "-C", str(src), *a], capture_output=True, text=True,
                              check=False)
    head = git("rev-parse", "--short", "HEAD")
    if head.returncode:
        return "unknown"
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", ".").stdout.strip()
    return head.stdout.strip() + ("+" if dirty else "")


def _without_paths(row: dict) -> dict:
    """A saved row without this machine's paths (a tree is named by its revision)."""
    for tree in row.get("trees", {}).values():
        tree.pop("src", None)
        tree.pop("imported", None)
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--save", action="store_true", help="write results/continuation.json")
    ap.add_argument("--label", default="current",
                    help="name of this run's row in the saved file (e.g. before, after)")
    ap.add_argument("--base", type=Path, help="a previous version's src, timed alongside")
    ap.add_argument("--rounds", type=int, default=3, help="worker rounds per tree (--base)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args)))
        return 0
    model = pwsdyn.load_model("impact-oscillator")
    orb = io_orbit("stable")

    def run_pwsdyn():
        return pwsdyn.continue_orbit(model, orb, "omega", span=(2.0, 10.0), ds=0.02,
                                     ds_max=0.02, max_points=args.points)

    run_pwsdyn()                                      # warm-up: compilation, caches
    trees = compare_trees(args.base, args) if args.base is not None else None
    br, wp, cp = timed(run_pwsdyn, args.repeats)
    omegas = br.values
    x_start = closed_form_at_zero(omegas[0])[0] + 1e-3
    scipy_branch(omegas[:3], x_start)                 # warm-up
    sc, ws, cs = timed(lambda: scipy_branch(omegas, x_start), max(1, args.repeats // 2))

    err_pw = mult_pw = err_sc = mult_sc = 0.0
    for p, x in zip(br.points, br.states):
        v, _, M, _ = io_one_impact(p.lam, 1)
        err_pw = max(err_pw, float(np.max(np.abs(x - [IO["sigma"], -IO["r"] * v]))))
        mult_pw = max(mult_pw, float(np.max(np.abs(
            np.sort_complex(p.data["multipliers"]) - np.sort_complex(np.linalg.eigvals(M))))))
    for w, x, mu in sc:
        ref, mref = closed_form_at_zero(w)
        err_sc = max(err_sc, float(np.max(np.abs(x - ref))))
        mult_sc = max(mult_sc, float(np.max(np.abs(np.sort_complex(mu) -
                                                   np.sort_complex(mref)))))
    n = len(br)
    br2, parts, calls = breakdown(run_pwsdyn)
    assert len(br2) == n
    per = {k: 1e3 * v / n for k, v in parts.items()}
    row_parts = {f"{k}_ms_per_point": per.get(k, 0.0) for k in
                 ("kernel", "linalg", "monitors", "python")}
    row_calls = {f"{k}_calls_per_point": calls.get(k, 0) / n for k in
                 ("kernel", "linalg", "monitors")}
    kern = per.get("kernel", 0.0)
    row = dict(label=args.label, points=n, omega_range=[float(omegas.min()), float(omegas.max())],
               special_points=[f"{s.kind} {s.value:.12g}" for s in br.special_points],
               pwsdyn_wall_s=wp, pwsdyn_cpu_s=cp, scipy_wall_s=ws, scipy_cpu_s=cs,
               pwsdyn_ms_per_point=1e3 * wp / n, scipy_ms_per_point=1e3 * ws / n,
               ratio_wall=ws / wp, ratio_cpu=cs / cp, orbit_err_pwsdyn=err_pw,
               mult_err_pwsdyn=mult_pw, orbit_err_scipy=err_sc, mult_err_scipy=mult_sc,
               **row_parts, **row_calls,
               timed_ms_per_point=sum(per.values()),
               timed_over_kernel=sum(per.values()) / kern if kern else None,
               total_over_kernel=(1e3 * cp / n) / kern if kern else None)
    print(f"{n} points, omega in [{omegas.min():.4f}, {omegas.max():.4f}], special points: "
          f"{', '.join(row['special_points'])}")
    print(f"{'':<8} {'ms/point':>9} {'ms/point CPU':>13} {'orbit err':>10} {'mult err':>9}")
    print(f"{'pwsdyn':<8} {1e3 * wp / n:>9.2f} {1e3 * cp / n:>13.2f} {err_pw:>10.1e} "
          f"{mult_pw:>9.1e}")
    print(f"{'scipy':<8} {1e3 * ws / n:>9.2f} {1e3 * cs / n:>13.2f} {err_sc:>10.1e} "
          f"{mult_sc:>9.1e}")
    print(f"ratio scipy / pwsdyn: {ws / wp:.1f} (wall), {cs / cp:.1f} (CPU)")
    if trees is not None:
        b, a = trees["before"], trees["after"]
        row["trees"] = trees
        row["identical"] = b["digest"] == a["digest"]
        print(f"before / after, worker processes taking turns ({args.rounds} rounds of "
              f"{args.repeats}), best CPU ms / point and scipy / pwsdyn (CPU, this run's "
              f"scipy):")
        for k, w in trees.items():
            print(f"  {k:<7} {1e3 * w['cpu_s'] / w['points']:>7.3f}  "
                  f"{cs / len(sc) / (w['cpu_s'] / w['points']):>6.1f}x   ({w['revision']}, "
                  f"{w['imported']})")
        print(f"  after / before {a['cpu_s'] / b['cpu_s']:.3f}; branches identical bit for "
              f"bit: {'yes' if row['identical'] else 'NO'}")
    print(f"a point's cost (CPU ms, with timers: {sum(per.values()):.3f} per point; calls per "
          f"point in brackets):")
    for k in ("kernel", "linalg", "monitors", "python"):
        c = f" ({calls.get(k, 0) / n:.1f})" if k != "python" else ""
        print(f"  {k:<9} {per.get(k, 0.0):>7.3f}{c}")
    if kern:
        print(f"total / kernel: {sum(per.values()) / kern:.1f} (timed run), "
              f"{(1e3 * cp / n) / kern:.1f} (plain run's CPU time)")
    meta = dict(date=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                machine=platform.machine(), python=platform.python_version(),
                numpy=np.__version__, scipy=scipy.__version__, pwsdyn=pwsdyn.__version__,
                cpus=os.cpu_count(), load=os.getloadavg(), repeats=args.repeats)
    if args.save:
        (HERE / "results").mkdir(exist_ok=True)
        path = HERE / "results" / "continuation.json"
        old = json.loads(path.read_text()) if path.exists() else {}
        rows = [r for r in old.get("rows", []) if r.get("label", "") not in ("", args.label)]
        row["meta"] = meta
        rows = [_without_paths(r) for r in rows + [row]]
        with open(path, "w") as fh:
            json.dump(dict(meta=meta, rows=rows), fh, indent=1, default=str)
    ok = err_pw < 1e-8 and mult_pw < 1e-6 and err_sc < 1e-6 and mult_sc < 1e-4
    if trees is not None and not row["identical"]:
        print("before and after computed different branches", file=sys.stderr)
        ok = False
    if not ok:
        print("accuracy check FAILED", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
