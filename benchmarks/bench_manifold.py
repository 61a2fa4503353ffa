"""Benchmark: growing a one-dimensional manifold of 10^4 points, against map evaluations.

Cases:

* ``nordmark2``: the unstable manifold of the saddle of the square-root map in the plane of
  tests/test_manifolds.py (a piecewise-smooth map model; one evaluation is one iteration);
* ``impact``: the unstable manifold of the impact oscillator's flip saddle at ``omega = 2.8``
  (zoo ``impact-oscillator``) on its stroboscopic section (one evaluation is one kernel run over
  the forcing period; each branch is grown under the second iterate, two runs).

Per case: points, map evaluations (of ``F``: one ``F^2`` counts two), evaluations per point,
the CPU time (``time.process_time``, best of ``--repeat``), the time per evaluation, and the
time per evaluation of a bare loop of the same evaluations (the cost of the growth's own
bookkeeping is the ratio). Timings are reported, never asserted.

Run::

    python benchmarks/bench_manifold.py [--points 10000] [--repeat 3] [--save]

(``--save`` writes ``results/manifold.json``.)
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

import pwsdyn
from pwsdyn.manifolds import find_periodic_point, manifold

NORDMARK = {"name": "nordmark2", "kind": "map", "states": ["x", "y"],
            "parameters": {"tau": 2.5, "delta": 0.5, "gamma": 1.0, "mu": 0.1},
            "pieces": [{"name": "no_impact", "condition": "x <= 0",
                        "map": {"x": "tau*x + y + mu", "y": "-delta*x"}},
                       {"name": "impact",
                        "map": {"x": "-gamma*sqrt(x) + y + mu", "y": "-delta*x"}}]}


def best(f, repeat):
    out, times = None, []
    for _ in range(repeat):
        t = time.process_time()
        out = f()
        times.append(time.process_time() - t)
    return out, min(times)


def case(name, model, point, points, repeat, max_step, single_eval):
    # both branches, points // 2 each, grown with max_step until the points run out
    m, t = best(lambda: manifold(model, point, arclength=1e9, max_points=points // 2,
                                 tol=1e-7, max_step=max_step), repeat)
    n = m.n_points
    evals = m.evaluations
    # the same number of evaluations in a bare loop, at points of the manifold
    P = np.concatenate(m.pieces)
    idx = np.arange(min(len(P), 2000))
    _, tb = best(lambda: [single_eval(P[i]) for i in idx], repeat)
    per_bare = tb / len(idx)
    return {"case": name, "points": int(n), "evaluations": int(evals),
            "evaluations_per_point": evals / n, "cpu_s": t, "us_per_evaluation":
            1e6 * t / evals, "bare_us_per_evaluation": 1e6 * per_bare,
            "overhead_ratio": (t / evals) / per_bare, "status": list(m.status),
            "unresolved": m.unresolved, "pieces": len(m.pieces)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--save", action="store_true")
    a = ap.parse_args(argv)
    from pwsdyn.manifolds._sections import MapSection, StroboscopicSection  # noqa: PLC2701

    rows = []
    pt = find_periodic_point(NORDMARK, [-0.1, 0.05])
    sec = MapSection(pt.model, pt.params)
    rows.append(case("nordmark2", NORDMARK, pt, a.points, a.repeat, 1e-3,
                     lambda x: sec.evaluate(x)))
    orbit = pwsdyn.find_periodic_orbit("impact-oscillator", [-0.29, -0.58],
                                       params={"omega": 2.8})
    ssec = StroboscopicSection(orbit.model, orbit.params, orbit.t0, orbit.period)
    rows.append(case("impact", "impact-oscillator", orbit, a.points, a.repeat, 5e-3,
                     lambda x: ssec.evaluate(x)))
    print(f"{'case':<10} {'points':>7} {'evals':>8} {'evals/pt':>8} {'CPU s':>7} "
          f"{'us/eval':>8} {'bare us/eval':>12} {'ratio':>6}  status")
    for r in rows:
        print(f"{r['case']:<10} {r['points']:>7} {r['evaluations']:>8} "
              f"{r['evaluations_per_point']:>8.2f} {r['cpu_s']:>7.3f} "
              f"{r['us_per_evaluation']:>8.1f} {r['bare_us_per_evaluation']:>12.1f} "
              f"{r['overhead_ratio']:>6.2f}  {r['status']}")
    if a.save:
        out = Path(__file__).parent / "results" / "manifold.json"
        out.write_text(json.dumps({"python": sys.version.split()[0],
                                   "machine": platform.processor() or platform.machine(),
                                   "pwsdyn": pwsdyn.__version__, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
