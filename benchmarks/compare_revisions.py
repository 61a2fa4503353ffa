"""Before/after in one run: the integrator kernel at two revisions, side by side.

Each revision runs from its own checkout (a git revision is checked out into a temporary
worktree with ``git worktree add --detach``; a directory holding ``src/pwsdyn`` is used as
it is, uncommitted changes included) with its own, initially empty, numba cache
(``NUMBA_CACHE_DIR``: otherwise numba keeps the kernel's machine code in ``__pycache__`` next
to its source) and its own cache of generated model code (``PWSDYN_CACHE_DIR``). Then:

1. **compile time**: a process imports pwsdyn and loads the kernel with the empty cache
   (numba compiles it), then a second one with the cache just written (numba loads it); the
   difference is the kernel's compilation (wall and the process's CPU time);
2. **speed**: one persistent worker process per revision; the workloads run alternately on
   the two (before, after, before, after, ... for ``--rounds``), ``--repeats`` times per
   visit, and the medians over all runs of wall time (``time.perf_counter``) and of the
   process's CPU time (``time.process_time``) are reported with their ratios after / before.
   The machine may be shared and loaded: CPU time is the fairer number, alternation puts
   both revisions under the same load;
3. **instruction counts**, which do not depend on the load, from valgrind's callgrind on a
   short run of each workload (instrumentation switched on and off around the workload by
   callgrind's client requests, from a small C helper built with the system compiler;
   ``perf stat -e instructions`` would need hardware counters, which a VM often lacks: the
   output says whether they were available). Under callgrind the kernel is compiled for a
   fixed CPU (``--ir-cpu``, default ``haswell``) into a cache of its own: valgrind emulates
   no AVX-512, and its virtual CPU would not match the host's cache anyway. Each workload is
   counted at ``P`` and ``2 P`` forcing periods (sweeps: values); the difference over ``P``
   periods is the marginal cost per period, free of the fixed cost of a call.

Workloads (the pwsdyn rows of the two benchmarks; the model definitions are imported from
them, so both revisions run the same models):

* ``impact-exact``, ``impact-exact-dense``, ``impact-rk45``, ``impact-dop853``:
  ``bench_impact_oscillator.py``'s Budd & Dux oscillator (one impact per period), ``simulate``
  from rest over ``--periods`` forcing periods, ``rtol = 1e-10``, ``atol = 1e-12``,
  ``dense=False`` (``-dense``: ``dense=True``), ``exact=True`` or the Runge-Kutta pair;
* ``sweep-exact``, ``sweep-rk45``, ``sweep-dop853``: ``bench_sweep.py``'s serial sweep of the
  built-in ``impact-oscillator`` over ``--sweep-values`` values of omega in [2.4, 3.4] with
  ``--sweep-periods`` periods each (3/4 transient), one direction.

Every result carries a fingerprint of what was computed (the end state's bits, event and step
counts; a digest of a sweep's points): equal fingerprints mean both revisions did the same
arithmetic on that workload. Timings are reported, never asserted.

Run::

    python benchmarks/compare_revisions.py                      # 82e8466 against HEAD
    python benchmarks/compare_revisions.py --before main --after .   # the working tree
    python benchmarks/compare_revisions.py --save               # + results/compare_revisions.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
RESULT_TAG = "@@result "

#: The last commit before the kernel's redesign (one stepper interface, one function per
#: event action: 32fd6fb and the commits after it).
DEFAULT_BEFORE = "82e8466"

IMPACT = ("impact-exact", "impact-exact-dense", "impact-rk45", "impact-dop853")
SWEEP = ("sweep-exact", "sweep-rk45", "sweep-dop853")
WORKLOADS = IMPACT + SWEEP
DEFAULT_WORKLOADS = ("impact-exact", "impact-rk45", "impact-dop853", "sweep-exact",
                     "sweep-rk45", "sweep-dop853")

#: Threads pinned to one in every process: both revisions on one core each.
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
               "NUMBA_NUM_THREADS")

#: The CPU features of the fixed target under callgrind (LLVM names; with NUMBA_CPU_NAME set,
#: numba would otherwise add the host's, AVX-512 included, which valgrind does not emulate).
HASWELL_FEATURES = ("+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+f16c,+fma,+fxsr,+lzcnt,"
                    "+mmx,+movbe,+pclmul,+popcnt,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3")

CALLGRIND_HELPER = r"""
#include <valgrind/callgrind.h>
void cg_start(void) { CALLGRIND_START_INSTRUMENTATION; CALLGRIND_ZERO_STATS; }
void cg_toggle(void) { CALLGRIND_TOGGLE_COLLECT; }
void cg_stop(const char *name) { CALLGRIND_DUMP_STATS_AT(name); CALLGRIND_STOP_INSTRUMENTATION; }
"""


# ------------------------------------------------------------------------------------------
# the workloads (run inside a worker, with the revision's pwsdyn on sys.path)
# ------------------------------------------------------------------------------------------
def _impact_options(name):
    return {"impact-exact": dict(exact=True, dense=False),
            "impact-exact-dense": dict(exact=True, dense=True),
            "impact-rk45": dict(method="RK45", exact=False, dense=False),
            "impact-dop853": dict(method="DOP853", exact=False, dense=False)}[name]


def _sweep_options(name):
    return {"sweep-exact": dict(exact=True), "sweep-rk45": dict(method="RK45", exact=False),
            "sweep-dop853": dict(method="DOP853", exact=False)}[name]


class Workloads:
    """The workloads of one worker process; ``run(name, size)`` returns a fingerprint."""

    def __init__(self):
        import numpy as np

        import pwsdyn
        sys.path.insert(0, str(HERE))
        import bench_impact_oscillator as bio
        import bench_sweep as bsw

        self.np, self.pwsdyn = np, pwsdyn
        self.impact_model = pwsdyn.load_model(bio.make_model(bio.DEFAULT_PARAMS))
        self.impact_x0 = bio.X0
        self.impact_period = 2 * np.pi / bio.DEFAULT_PARAMS["omega"]
        self.sweep_model = pwsdyn.load_model("impact-oscillator")
        self.sweep_x0 = bsw.X0

    def run(self, name, size, sweep_periods=200):
        np, pwsdyn = self.np, self.pwsdyn
        if name in IMPACT:
            tr = pwsdyn.simulate(self.impact_model, self.impact_x0,
                                 (0.0, size * self.impact_period), rtol=1e-10, atol=1e-12,
                                 max_steps=100_000_000, **_impact_options(name))
            end = [float(tr.t[-1])] + np.asarray(tr.x[-1], dtype=float).tolist()
            return {"end": [v.hex() for v in end], "events": len(tr.events),
                    "stats": {k: int(v) for k, v in dict(getattr(tr, "stats", {}) or {}).items()
                              if isinstance(v, (int, np.integer))}}
        transient = sweep_periods * 3 // 4
        ds = pwsdyn.sweep(self.sweep_model, "omega", np.linspace(2.4, 3.4, size), self.sweep_x0,
                          workers=1, transient=transient, samples=sweep_periods - transient,
                          rtol=1e-10, atol=1e-12, direction="up", progress=False,
                          **_sweep_options(name))
        digest = hashlib.sha256()
        for var in sorted(ds.data_vars):
            a = np.ascontiguousarray(ds[var].values)
            if a.dtype.kind in "fiub":
                digest.update(var.encode())
                digest.update(a.tobytes())
        return {"digest": digest.hexdigest()[:16]}


def worker(argv):
    """A persistent worker: one JSON command per line on stdin, one result line on stdout."""
    for var in THREAD_VARS:
        os.environ.setdefault(var, "1")
    wl = Workloads()
    out = sys.stdout
    for line in sys.stdin:
        cmd = json.loads(line)
        if cmd.get("quit"):
            break
        walls, cpus, fp = [], [], None
        for _ in range(cmd["repeats"]):
            w0, c0 = time.perf_counter(), time.process_time()
            fp = wl.run(cmd["workload"], cmd["size"], cmd.get("sweep_periods", 200))
            walls.append(time.perf_counter() - w0)
            cpus.append(time.process_time() - c0)
        out.write(RESULT_TAG + json.dumps({"wall": walls, "cpu": cpus, "fingerprint": fp})
                  + "\n")
        out.flush()


def ir_worker(argv):
    """Under callgrind (collection off at the start): warm each workload up uninstrumented,
    then count it at two sizes, whole (``total``) and inside the kernel's calls only
    (``kernel``: collection toggled around ``run_kernel``, the numba dispatch included)."""
    import ctypes
    lib = ctypes.CDLL(argv[0])
    spec = json.loads(argv[1])
    wl = Workloads()
    from pwsdyn.integrate._load import kernel
    k = kernel()
    real = k.run_kernel
    inside = [False]

    def counted(*a):
        if not inside[0]:
            return real(*a)
        lib.cg_toggle()
        try:
            return real(*a)
        finally:
            lib.cg_toggle()

    k.run_kernel = counted
    for name in spec["workloads"]:
        wl.run(name, spec["warm"][name], spec["sweep_periods"])
        for i, size in enumerate(spec["sizes"][name]):
            for part in ("total", "kernel"):
                inside[0] = part == "kernel"
                lib.cg_start()
                if part == "total":
                    lib.cg_toggle()
                wl.run(name, size, spec["sweep_periods"])
                if part == "total":
                    lib.cg_toggle()
                lib.cg_stop(f"{name}#{i}#{part}".encode())


# ------------------------------------------------------------------------------------------
# the driver
# ------------------------------------------------------------------------------------------
class Revision:
    """One side of the comparison: its checkout, caches and worker process."""

    def __init__(self, label, spec, tmp):
        self.label, self.spec = label, spec
        path = Path(spec)
        if path.is_dir() and (path / "src" / "pwsdyn").is_dir():
            self.root, self.worktree = path.resolve(), None
            self.commit = _git("rev-parse", "HEAD", cwd=self.root) + (
                " + working tree" if _git("status", "--porcelain", "--", "src",
                                          cwd=self.root) else "")
        else:
            self.commit = _git("rev-parse", spec)
            self.root = tmp / f"tree-{label}"
            _git("worktree", "add", "--detach", str(self.root), self.commit)
            self.worktree = self.root
        self.numba_cache = tmp / f"numba-{label}"
        self.model_cache = tmp / f"models-{label}"
        self.proc = None

    def env(self, **extra):
        env = {**os.environ, "PYTHONPATH": str(self.root / "src"),
               "NUMBA_CACHE_DIR": str(self.numba_cache),
               "PWSDYN_CACHE_DIR": str(self.model_cache), "PWSDYN_QUIET": "1"}
        for var in THREAD_VARS:
            env[var] = "1"
        env.update(extra)
        return env

    def load_kernel(self, env=None):
        """Wall and CPU seconds of ``import pwsdyn`` + loading the kernel, in a new process."""
        code = textwrap.dedent("""
            import json, time
            w0, c0 = time.perf_counter(), time.process_time()
            import pwsdyn
            from pwsdyn.integrate._load import kernel
            kernel()
            print(json.dumps([time.perf_counter() - w0, time.process_time() - c0]))
            """)
        res = subprocess.run([sys.executable, "-c", code], env=env or self.env(),
                             capture_output=True, text=True, cwd=self.root)
        if res.returncode != 0:
            raise RuntimeError(f"{self.label}: loading the kernel failed:\n{res.stderr}")
        return json.loads(res.stdout.strip().splitlines()[-1])

    def start(self):
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"],
                                     env=self.env(), stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, cwd=self.root)

    def ask(self, **cmd):
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        for line in self.proc.stdout:
            if line.startswith(RESULT_TAG):
                return json.loads(line[len(RESULT_TAG):])
        raise RuntimeError(f"{self.label}: the worker ended (status {self.proc.wait()})")

    def stop(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.stdin.write(json.dumps({"quit": True}) + "\n")
            self.proc.stdin.flush()
            self.proc.wait(timeout=60)

    def remove(self):
        self.stop()
        if self.worktree is not None:
            _git("worktree", "remove", "--force", str(self.worktree))


def _git(*args, cwd=REPO):
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout.strip()


def _size(name, args):
    return args.sweep_values if name in SWEEP else args.periods


def _periods(name, size, args):
    return size * args.sweep_periods if name in SWEEP else size


def compile_times(revs):
    out = {}
    for rev in revs:
        shutil.rmtree(rev.numba_cache, ignore_errors=True)
        cold = rev.load_kernel()
        warm = rev.load_kernel()
        out[rev.label] = {"cold_wall_s": cold[0], "cold_cpu_s": cold[1], "warm_wall_s": warm[0],
                          "warm_cpu_s": warm[1], "compile_wall_s": cold[0] - warm[0],
                          "compile_cpu_s": cold[1] - warm[1]}
        print(f"  {rev.label:6s} kernel compile {out[rev.label]['compile_wall_s']:6.1f} s wall, "
              f"{out[rev.label]['compile_cpu_s']:6.1f} s CPU (cold import {cold[0]:.1f} s, "
              f"from the cache {warm[0]:.2f} s)", flush=True)
    return out


def speed(revs, args):
    for rev in revs:
        rev.start()
    # warm-up: the model's generated code and the lazily compiled parts of each workload
    for name in args.workloads:
        for rev in revs:
            rev.ask(workload=name, size=2, repeats=1, sweep_periods=args.sweep_periods)
    out = {}
    for name in args.workloads:
        size = _size(name, args)
        runs = {rev.label: {"wall": [], "cpu": [], "fingerprints": []} for rev in revs}
        for _ in range(args.rounds):
            for rev in revs:   # ABAB...: both under the same load
                r = rev.ask(workload=name, size=size, repeats=args.repeats,
                            sweep_periods=args.sweep_periods)
                runs[rev.label]["wall"] += r["wall"]
                runs[rev.label]["cpu"] += r["cpu"]
                runs[rev.label]["fingerprints"].append(r["fingerprint"])
        per = 1e6 / _periods(name, size, args)
        row = {"size": size, "periods": _periods(name, size, args)}
        for label, r in runs.items():
            fps = {json.dumps(f, sort_keys=True) for f in r["fingerprints"]}
            row[label] = {"wall_us_per_period": statistics.median(r["wall"]) * per,
                          "cpu_us_per_period": statistics.median(r["cpu"]) * per,
                          "cpu_min_us_per_period": min(r["cpu"]) * per,
                          "runs": len(r["cpu"]), "fingerprint": r["fingerprints"][-1],
                          "deterministic": len(fps) == 1}
        b, a = row["before"], row["after"]
        row["wall_ratio"] = a["wall_us_per_period"] / b["wall_us_per_period"]
        row["cpu_ratio"] = a["cpu_us_per_period"] / b["cpu_us_per_period"]
        row["same_result"] = b["fingerprint"] == a["fingerprint"]
        out[name] = row
        print(f"  {name:18s} before {b['cpu_us_per_period']:8.2f}  after "
              f"{a['cpu_us_per_period']:8.2f} us/period CPU  (ratio {row['cpu_ratio']:.3f}; "
              f"wall {row['wall_ratio']:.3f})  same result: {row['same_result']}", flush=True)
    for rev in revs:
        rev.stop()
    return out


def _perf_works():
    try:
        res = subprocess.run(["perf", "stat", "-x,", "-e", "instructions", "true"],
                             capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return res.returncode == 0 and "not supported" not in res.stderr \
        and "not counted" not in res.stderr


def instructions(revs, args, tmp):
    """Instructions per workload at two sizes, and the marginal cost per period."""
    # (perf's hardware counters would do as well where the machine exposes them; on a VM
    # they often do not, and callgrind's counts are the same on any x86-64 machine)
    perf = _perf_works()
    if not (shutil.which("valgrind") and shutil.which(os.environ.get("CC", "cc"))):
        print("  no instruction counts: valgrind or a C compiler is missing")
        return None
    sizes = {n: ([args.ir_sweep_values, 2 * args.ir_sweep_values] if n in SWEEP
                 else [args.ir_periods, 2 * args.ir_periods]) for n in args.workloads}
    spec = {"workloads": list(args.workloads), "sizes": sizes, "sweep_periods":
            args.ir_sweep_periods, "warm": {n: 2 for n in args.workloads}}
    out = {"tool": "callgrind", "perf_counters_available": perf, "sizes": sizes,
           "sweep_periods": args.ir_sweep_periods}
    so = tmp / "cgctl.so"
    src = tmp / "cgctl.c"
    src.write_text(CALLGRIND_HELPER)
    subprocess.run([os.environ.get("CC", "cc"), "-O1", "-shared", "-fPIC", "-o", str(so),
                    str(src)], check=True)
    out["cpu_name"] = args.ir_cpu
    for rev in revs:
        extra = {"NUMBA_CPU_NAME": args.ir_cpu, "NUMBA_CPU_FEATURES": HASWELL_FEATURES,
                 "NUMBA_CACHE_DIR": str(tmp / f"numba-{rev.label}-{args.ir_cpu}")}
        env = rev.env(**extra)
        # compile natively for the fixed target (and run each workload once, which compiles
        # what is compiled lazily), so that callgrind only loads machine code from the cache
        _warm_native(rev, env, spec)
        outdir = tmp / f"cg-{rev.label}"
        outdir.mkdir(exist_ok=True)
        t0 = time.perf_counter()
        res = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                              "--collect-atstart=no", f"--callgrind-out-file={outdir}/cg.out",
                              sys.executable, str(Path(__file__).resolve()), "--ir-worker",
                              str(so), json.dumps(spec)], env=env, cwd=rev.root,
                             capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"{rev.label}: callgrind run failed:\n{res.stderr[-3000:]}")
        counts = read_callgrind(outdir)
        out[rev.label] = {}
        for name in args.workloads:
            s1, s2 = sizes[name]
            dp = _periods(name, s2, args_ir(args)) - _periods(name, s1, args_ir(args))
            row = {}
            for part in ("total", "kernel"):
                i1, i2 = counts[f"{name}#0#{part}"], counts[f"{name}#1#{part}"]
                row[part] = {"instructions": [i1, i2], "per_period": (i2 - i1) / dp}
            out[rev.label][name] = row
        print(f"  {rev.label:6s} callgrind done in {time.perf_counter() - t0:.0f} s", flush=True)
    for name in args.workloads:
        row = {}
        for part in ("total", "kernel"):
            b = out["before"][name][part]["per_period"]
            a = out["after"][name][part]["per_period"]
            row[part] = {"before_per_period": b, "after_per_period": a, "ratio": a / b}
        out[name] = row
        t, k = row["total"], row["kernel"]
        print(f"  {name:18s} before {t['before_per_period']:9.0f}  after "
              f"{t['after_per_period']:9.0f} per period (ratio {t['ratio']:.3f}); in the "
              f"kernel {k['before_per_period']:9.0f} / {k['after_per_period']:9.0f} "
              f"({k['ratio']:.3f})", flush=True)
    return out


def read_callgrind(outdir):
    """The instruction totals of callgrind's dumps in ``outdir``, by their trigger name."""
    counts = {}
    for f in Path(outdir).glob("cg.out.*"):
        desc, total = None, None
        for line in f.read_text().splitlines():
            if line.startswith("desc: Trigger: Client Request: "):
                desc = line.split(": ", 3)[-1].strip()
            elif line.startswith(("summary:", "totals:")):
                total = int(line.split()[1])
        if desc and total is not None:
            counts[desc] = total
    return counts


def args_ir(args):
    """The sizes of the instruction counts, in the shape _periods reads."""
    return argparse.Namespace(sweep_periods=args.ir_sweep_periods)


def _warm_native(rev, env, spec):
    code = textwrap.dedent(f"""
        import json, sys
        sys.argv = [{str(Path(__file__).resolve())!r}]
        sys.path.insert(0, {str(HERE)!r})
        from compare_revisions import Workloads
        spec = json.loads({json.dumps(json.dumps(spec))})
        wl = Workloads()
        for name in spec["workloads"]:
            wl.run(name, 2, spec["sweep_periods"])
        """)
    res = subprocess.run([sys.executable, "-c", code], env=env, cwd=rev.root,
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{rev.label}: compiling for callgrind failed:\n{res.stderr[-3000:]}")


def machine_info():
    import numba
    import numpy as np
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), "numpy": np.__version__,
            "numba": numba.__version__}


def _loadavg():
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return ""


def _saved_spec(spec: str) -> str:
    """A revision as the saved results name it: a git revision as given, a checkout directory
    by its role (its commit is saved next to it), never by this machine's path."""
    return "a checkout directory (uncommitted changes included)" if Path(spec).is_dir() else spec


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(argv[1:])
    if argv[:1] == ["--ir-worker"]:
        return ir_worker(argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", default=DEFAULT_BEFORE,
                    help=f"git revision or checkout directory ({DEFAULT_BEFORE})")
    ap.add_argument("--after", default="HEAD", help="git revision or checkout directory (HEAD)")
    ap.add_argument("--workloads", default=",".join(DEFAULT_WORKLOADS),
                    help=f"comma-separated, of {', '.join(WORKLOADS)}")
    ap.add_argument("--periods", type=int, default=1000, help="impact runs: periods (1000)")
    ap.add_argument("--sweep-values", type=int, default=100, help="sweeps: values (100)")
    ap.add_argument("--sweep-periods", type=int, default=200,
                    help="sweeps: periods per value (200)")
    ap.add_argument("--rounds", type=int, default=5, help="ABAB rounds (5)")
    ap.add_argument("--repeats", type=int, default=3, help="runs per visit (3)")
    ap.add_argument("--skip-compile", action="store_true",
                    help="no cold compile timing (the caches are still filled)")
    ap.add_argument("--skip-speed", action="store_true")
    ap.add_argument("--skip-instructions", action="store_true")
    ap.add_argument("--ir-periods", type=int, default=300,
                    help="instruction counts: periods P of the impact runs (300; and 2P)")
    ap.add_argument("--ir-sweep-values", type=int, default=4,
                    help="instruction counts: values of the sweeps (4; and 8)")
    ap.add_argument("--ir-sweep-periods", type=int, default=100,
                    help="instruction counts: periods per sweep value (100)")
    ap.add_argument("--ir-cpu", default="haswell", help="numba's target CPU under callgrind")
    ap.add_argument("--save", nargs="?", const=str(HERE / "results" / "compare_revisions.json"),
                    help="write the results as JSON (default results/compare_revisions.json)")
    args = ap.parse_args(argv)
    args.workloads = tuple(w.strip() for w in args.workloads.split(",") if w.strip())
    bad = [w for w in args.workloads if w not in WORKLOADS]
    if bad:
        ap.error(f"unknown workloads {bad}; choose from {', '.join(WORKLOADS)}")

    tmp = Path(tempfile.mkdtemp(prefix="pwsdyn-compare-"))
    revs = []
    result = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "machine": machine_info(), "loadavg_start": _loadavg(),
              "settings": {k: _saved_spec(v) if k in ("before", "after") else v
                           for k, v in vars(args).items() if k != "save"}}
    try:
        revs = [Revision("before", args.before, tmp), Revision("after", args.after, tmp)]
        result["revisions"] = {r.label: {"spec": _saved_spec(r.spec), "commit": r.commit}
                               for r in revs}
        for r in revs:
            print(f"{r.label}: {r.spec} = {r.commit}")
        print(f"load average {result['loadavg_start']}", flush=True)
        print("kernel compile time (empty numba cache, then loaded from it):", flush=True)
        if args.skip_compile:
            for r in revs:
                r.load_kernel()
        else:
            result["compile"] = compile_times(revs)
        if not args.skip_speed:
            print(f"speed ({args.rounds} rounds x {args.repeats} runs each, alternating; "
                  f"medians):", flush=True)
            result["speed"] = speed(revs, args)
        if not args.skip_instructions:
            print("instruction counts:", flush=True)
            result["instructions"] = instructions(revs, args, tmp)
        result["loadavg_end"] = _loadavg()
    finally:
        for r in revs:
            r.remove()
        shutil.rmtree(tmp, ignore_errors=True)
        _git("worktree", "prune")
    if args.save:
        Path(args.save).parent.mkdir(parents=True, exist_ok=True)
        Path(args.save).write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {args.save}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
