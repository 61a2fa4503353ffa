"""Benchmark: Burridge-Knopoff chains of n = 1..10 blocks (one friction contact per block).

Model: ``pwsdyn.burridge_knopoff(n)`` (m = kp = 1, kc = 1, V = 0.2, Fs = 1, 1.1, ..., Fd =
Fs/2, delta = 3), from rest, 1000 time units, ``rtol = atol = 1e-10``. For each n:

* load and compile time, in a fresh process with an empty model cache: building and loading
  the chain (``pwsdyn.burridge_knopoff``: the split into 2**n variants and their switches),
  its hash (``Model.digest``, which names the compiled module), and ``pwsdyn.compile_model``
  (SymPy derivatives, code generation and numba compilation of the sign family);
* the run: events per second of CPU time, CPU time per accepted step, and both as ratios to
  the 1-block chain. A run that stops (the kernel refusing a state it does not support) is
  reported with its status and the time it reached.

The variants are listed one by one (at most ``MAX_FAMILY_MODES`` = 1024) and the kernel
slides on intersections of at most ``MULTI_MAX`` = 10 surfaces, so n <= 10 here
(``pwsdyn.model.chains.MAX_BLOCKS``).
Timings are reported, never asserted.

Run::

    python benchmarks/bench_contacts.py [--blocks 1 2 3 4 5 6 7 8 9 10] [--t-end 1000] [--repeats 3]
        [--save]
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
import time
from datetime import datetime, timezone
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pwsdyn  # noqa: E402

HERE = Path(__file__).resolve().parent

_COMPILE = """
import sys, time
import pwsdyn
t = time.perf_counter()
m = pwsdyn.burridge_knopoff({n})
t1 = time.perf_counter()
m.digest
t2 = time.perf_counter()
pwsdyn.compile_model(m)
print(t1 - t, t2 - t1, time.perf_counter() - t2)
"""


def compile_seconds(n: int) -> tuple[float, float, float]:
    """Wall times of loading the n-block chain, of its hash and of compile_model, in a fresh
    process with an empty model cache."""
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PWSDYN_CACHE_DIR=tmp)
        out = subprocess.run([sys.executable, "-c", _COMPILE.format(n=n)], env=env,
                             capture_output=True, text=True, check=True)
        load, digest, comp = (float(v) for v in out.stdout.strip().splitlines()[-1].split())
        return load, digest, comp


def run_chain(n: int, t_end: float, repeats: int) -> dict:
    model = pwsdyn.burridge_knopoff(n, t_end=t_end)
    pwsdyn.compile_model(model)
    opts = dict(rtol=1e-10, atol=1e-10, dense=False)
    best, traj, error = math.inf, None, None
    for _ in range(repeats):
        c0 = time.process_time()
        try:
            traj = pwsdyn.simulate(model, None, t_end, **opts)
        except pwsdyn.SolveError as exc:
            error = str(exc).split(". Stopped")[0]
            traj = getattr(exc, "result", None)
        best = min(best, time.process_time() - c0)
    out = {"n": n, "modes": len(model.mode_names), "cpu_s": best, "error": error}
    if traj is not None:
        steps = int(traj.stats.get("steps", 0))
        out.update(t_reached=float(traj.t_final), events=len(traj.events), steps=steps,
                   events_per_s=len(traj.events) / best if best > 0 else math.nan,
                   us_per_step=1e6 * best / steps if steps else math.nan)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blocks", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6, 7, 8, 9, 10])
    ap.add_argument("--t-end", type=float, default=1000.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-compile", action="store_true", help="skip the compile timings")
    ap.add_argument("--save", action="store_true", help="write results/contacts.json")
    args = ap.parse_args(argv)
    pwsdyn.simulate(pwsdyn.burridge_knopoff(1), None, 1.0)   # load the integrator
    rows = []
    for n in args.blocks:
        row = run_chain(n, args.t_end, args.repeats)
        if not args.no_compile:
            row["load_s"], row["digest_s"], row["compile_s"] = compile_seconds(n)
        rows.append(row)
    base = rows[0]
    for row in rows:
        for key in ("events_per_s", "us_per_step", "compile_s"):
            if key in row and key in base and base[key]:
                row[f"{key}_ratio"] = row[key] / base[key]
    print(f"{'n':>2} {'modes':>5} {'load s':>6} {'hash s':>6} {'compile s':>9} {'t reached':>9} "
          f"{'events':>7} {'steps':>7} {'events/s':>9} {'us/step':>8} {'x1 us/step':>10}  note")
    for r in rows:
        print(f"{r['n']:>2} {r['modes']:>5} {r.get('load_s', math.nan):>6.2f} "
              f"{r.get('digest_s', math.nan):>6.2f} {r.get('compile_s', math.nan):>9.1f} "
              f"{r.get('t_reached', math.nan):>9.2f} {r.get('events', 0):>7} "
              f"{r.get('steps', 0):>7} {r.get('events_per_s', math.nan):>9.0f} "
              f"{r.get('us_per_step', math.nan):>8.2f} "
              f"{r.get('us_per_step_ratio', math.nan):>10.2f}  {r['error'] or ''}")
    if args.save:
        result = {"benchmark": "contacts", "date": datetime.now(timezone.utc).isoformat(),
                  "pwsdyn": pwsdyn.__version__, "python": platform.python_version(),
                  "machine": platform.processor() or platform.machine(),
                  "t_end": args.t_end, "rows": rows}
        path = HERE / "results" / "contacts.json"
        path.write_text(json.dumps(result, indent=1) + "\n")
        print(f"saved {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
