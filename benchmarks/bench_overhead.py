"""Benchmark: the Python around ``simulate()`` against the integration it wraps.

One forcing period of the built-in ``impact-oscillator`` (from ``x0 = (-0.5, 0)``, the
default options: exact flight, dense output) is short enough that the call's own Python work
-- argument checks, model and parameter resolution, the start-on-constraint checks, building
the :class:`~pwsdyn.Trajectory` and its event log -- is most of it. Rows, CPU time per call
(``time.process_time`` over a batch of calls, best of ``--repeats`` interleaved runs):

* ``kernel``: the compiled kernel's ``run_kernel`` alone, with the arguments ``simulate``
  passed it (captured from one call by wrapping the kernel module's function), one period;
* ``kernel x{P}``: the same over ``--long`` periods, per period: the cost of integrating a
  period;
* ``object dense``, ``object dense=False``: ``simulate(model, x0, (0, T))`` with a loaded
  ``Model``;
* ``name dense``, ``name dense=False``: the same with the model given by its name (after
  its first load the difference is the model file's check, one ``stat``: an edited file is
  read again).

The overhead of a call is its time less the kernel call's, reported in periods of the
integration (the ``kernel x{P}`` time per period). ``--base PATH`` times a second source tree
(a previous version's ``src``) in worker processes alternating with this checkout's, so
before and after come from one run; both must compute the same final state and event times
bit for bit (exit status 2 otherwise). ``--profile`` prints the cProfile breakdown of the
object call in this checkout.

Timings are reported, never asserted. Run::

    python benchmarks/bench_overhead.py [--base /path/to/old/src] [--save]
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import io
import json
import math
import os
import pstats
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"

NAME = "impact-oscillator"
X0 = (-0.5, 0.0)
ROWS = ("kernel", "kernel_long", "object_dense", "object_nodense", "name_dense",
        "name_nodense")


def _capture_kernel_args(pwsdyn, model, t_end):
    """The arguments of the kernel call behind ``simulate(model, X0, (0, t_end))``."""
    from pwsdyn.integrate._load import kernel

    K = kernel()
    orig, seen = K.run_kernel, []

    def spy(*args):
        seen.append(args)
        return orig(*args)

    K.run_kernel = spy
    try:
        pwsdyn.simulate(model, X0, (0.0, t_end))
    finally:
        K.run_kernel = orig
    (args,) = seen
    return orig, args


def worker(repeats: int, batch: int, periods: int) -> dict:
    """Time every row in this process (the ``pwsdyn`` on ``sys.path``); per call, CPU us."""
    import numpy as np

    import pwsdyn

    model = pwsdyn.load_model(NAME)
    T = 2 * math.pi / model.parameters["omega"]
    run, args1 = _capture_kernel_args(pwsdyn, model, T)
    _, argsP = _capture_kernel_args(pwsdyn, model, periods * T)

    def kernel_args(args):
        # the kernel writes into none of its inputs but the state, which it copies first;
        # pass fresh copies anyway so each call starts from the same state
        return lambda: run(*(a.copy() if isinstance(a, np.ndarray) else a for a in args))

    calls = {
        "kernel": (kernel_args(args1), batch),
        "kernel_long": (kernel_args(argsP), max(1, batch // periods)),
        "object_dense": (lambda: pwsdyn.simulate(model, X0, (0.0, T)), batch),
        "object_nodense": (lambda: pwsdyn.simulate(model, X0, (0.0, T), dense=False), batch),
        "name_dense": (lambda: pwsdyn.simulate(NAME, X0, (0.0, T)), batch),
        "name_nodense": (lambda: pwsdyn.simulate(NAME, X0, (0.0, T), dense=False), batch),
    }
    for fn, _ in calls.values():     # first calls: compiled model loaded, caches filled
        fn()
    # the garbage of loading and compiling collected now, not in a timed run
    gc.collect()
    best = {k: math.inf for k in calls}
    for _ in range(repeats):         # interleaved: every row sees the same load
        for k, (fn, n) in calls.items():
            c0 = time.process_time()
            for _ in range(n):
                fn()
            best[k] = min(best[k], (time.process_time() - c0) / n * 1e6)
    best["kernel_long"] /= periods
    # what the rows computed, to compare trees and the two ways of naming the model
    results = {}
    for k in ("object_dense", "name_dense", "object_nodense", "name_nodense"):
        tr = calls[k][0]()
        results[k] = {"x_final": [float(v).hex() for v in tr.x_final],
                      "events": [float(v).hex() for v in tr.events.t],
                      "n_nodes": len(tr.t),
                      "x_mid": ([float(v).hex() for v in tr(T / 3)]
                                if k.endswith("_dense") else None)}
    return {"us": best, "results": results, "pwsdyn": pwsdyn.__file__}


def profile(batch: int, top: int) -> str:
    """cProfile of ``batch`` object calls (dense), by internal time."""
    import pwsdyn

    model = pwsdyn.load_model(NAME)
    T = 2 * math.pi / model.parameters["omega"]
    pwsdyn.simulate(model, X0, (0.0, T))
    gc.collect()
    pr = cProfile.Profile()
    pr.enable()
    for _ in range(batch):
        pwsdyn.simulate(model, X0, (0.0, T))
    pr.disable()
    out = io.StringIO()
    pstats.Stats(pr, stream=out).sort_stats("tottime").print_stats(top)
    out.write("\n")
    pstats.Stats(pr, stream=out).sort_stats("cumulative").print_stats(top)
    return out.getvalue()


def run_worker(src: Path, args) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    cmd = [sys.executable, __file__, "--worker", "--repeats", str(args.repeats), "--batch",
           str(args.batch), "--long", str(args.long)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode:
        sys.stderr.write(out.stderr)
        raise SystemExit(f"worker for {src} failed")
    return json.loads(out.stdout.strip().splitlines()[-1])


def summary(us: dict) -> dict:
    """Overheads in periods of integration, by-name against object."""
    per = us["kernel_long"]
    s = {}
    for k in ("object_dense", "object_nodense", "name_dense", "name_nodense"):
        s[f"{k}_overhead_us"] = us[k] - us["kernel"]
        s[f"{k}_overhead_periods"] = (us[k] - us["kernel"]) / per
    s["name_over_object_dense"] = us["name_dense"] / us["object_dense"]
    s["name_over_object_nodense"] = us["name_nodense"] / us["object_nodense"]
    return s


LABELS = {"kernel": "kernel call, 1 period", "kernel_long": "kernel, per period of {P}",
          "object_dense": "simulate(Model), dense", "object_nodense": "simulate(Model), "
          "dense=False", "name_dense": "simulate(name), dense",
          "name_nodense": "simulate(name), dense=False"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--batch", type=int, default=300, help="calls per timed run")
    ap.add_argument("--long", type=int, default=100, help="periods of the long kernel run")
    ap.add_argument("--rounds", type=int, default=3, help="worker rounds per tree")
    ap.add_argument("--base", type=Path, help="a previous version's src, timed alongside")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--save", action="store_true", help="write results/overhead.json")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.repeats, args.batch, args.long)))
        return 0

    trees = {"after": SRC}
    if args.base is not None:
        trees = {"before": args.base.resolve(), **trees}
    runs = {k: [] for k in trees}
    for _ in range(args.rounds):
        for k, src in trees.items():
            runs[k].append(run_worker(src, args))
    best = {k: {r: min(w["us"][r] for w in runs[k]) for r in ROWS} for k in trees}
    status = 0
    for k in trees:
        res = runs[k][-1]["results"]
        for kind in ("dense", "nodense"):
            if res[f"object_{kind}"] != res[f"name_{kind}"]:
                print(f"{k}: the model by name computed another result than the object")
                status = 2
    if "before" in trees and runs["before"][-1]["results"] != runs["after"][-1]["results"]:
        print("before and after computed different results")
        status = 2

    cols = list(trees)
    head = "| row | " + " | ".join(f"{c} us" for c in cols)
    head += " | after / before |" if len(cols) == 2 else " |"
    print(f"\nimpact-oscillator, one forcing period, CPU us per call (best of "
          f"{args.rounds} x {args.repeats} runs of {args.batch} calls)\n")
    print(head)
    print("|---" * (len(cols) + 1 + (len(cols) == 2)) + "|")
    for r in ROWS:
        vals = [best[c][r] for c in cols]
        line = f"| {LABELS[r].format(P=args.long)} | " + " | ".join(f"{v:.1f}" for v in vals)
        line += f" | {vals[1] / vals[0]:.3f} |" if len(cols) == 2 else " |"
        print(line)
    summ = {c: summary(best[c]) for c in cols}
    print("\nper-call overhead (call less the kernel call), in periods of integration:")
    for c in cols:
        s = summ[c]
        print(f"  {c:6s}: object dense {s['object_dense_overhead_periods']:.1f}, "
              f"object dense=False {s['object_nodense_overhead_periods']:.1f}, "
              f"name dense {s['name_dense_overhead_periods']:.1f}, "
              f"name dense=False {s['name_nodense_overhead_periods']:.1f}; "
              f"name / object {s['name_over_object_dense']:.2f} (dense), "
              f"{s['name_over_object_nodense']:.2f} (dense=False)")
    print("results identical (object / name" + (", before / after)" if len(cols) == 2 else ")")
          + (": yes" if status == 0 else ": NO"))
    prof = None
    if args.profile:
        sys.path.insert(0, str(SRC))
        prof = profile(args.batch, 25)
        print("\n" + prof)
    if args.save:
        sys.path.insert(0, str(HERE))
        from bench_impact_oscillator import machine_info  # noqa: E402

        out = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": machine_info(),
               # (no paths of this machine: the base tree is named by its role)
               "argv": ["<base src>" if args.base is not None and a == str(args.base) else a
                        for a in sys.argv[1:]],
               "us_per_call": best, "summary": summ,
               "trees": {k: ("the src given as --base" if k == "before" else
                             "this checkout's src") for k in trees},
               "identical": status == 0, "profile": prof}
        path = HERE / "results" / "overhead.json"
        path.write_text(json.dumps(out, indent=1) + "\n")
        print(f"saved {path}")
    return status


if __name__ == "__main__":
    sys.exit(main())
