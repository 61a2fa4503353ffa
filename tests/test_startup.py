"""Start-up: ``import pwsdyn``, ``pwsdyn --help``, ``pwsdyn models`` and argument errors never
load (or compile) the integrator; a real compilation is announced on stderr, a load from
numba's cache is silent; sweeps run on threads by default.

What is loaded is checked in a fresh interpreter (``sys.modules``), never by timing.
"""

from __future__ import annotations

import ast
import io
import json
import os
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

import pwsdyn

SRC = Path(pwsdyn.__file__).resolve().parent
KERNEL = "pwsdyn.integrate._kernel"
MAP_KERNELS = "pwsdyn.model._map_kernels"


def _env(**extra) -> dict:
    env = dict(os.environ)
    # the subprocess imports the same pwsdyn as this process
    env["PYTHONPATH"] = os.pathsep.join([str(SRC.parent)] + [p for p in env.get(
        "PYTHONPATH", "").split(os.pathsep) if p])
    env.update(extra)
    return env


def _run(code: str, cwd=None, **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, cwd=cwd, env=_env(**env))


def _json_tail(proc) -> dict:
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_import_pwsdyn_is_cheap_and_complete():
    """``import pwsdyn`` imports neither numba, SymPy nor the kernel; every public name is
    listed by ``dir`` and ``__all__`` and resolves on access (``from pwsdyn import ...``)."""
    out = _json_tail(_run("""
        import json, sys
        import pwsdyn
        loaded = [m for m in ("numba", "sympy", "xarray", "dask", "pwsdyn.integrate",
                              "pwsdyn.integrate._kernel") if m in sys.modules]
        missing = sorted(set(pwsdyn.__all__) - set(dir(pwsdyn)))
        from pwsdyn import simulate, sweep, basins, PeriodicOrbit, saltation_matrix, Model
        ns = {}
        exec("from pwsdyn import *", ns)
        print(json.dumps({"loaded": loaded, "missing": missing,
                          "star": sorted(set(pwsdyn.__all__) - set(ns)),
                          "kernel": "pwsdyn.integrate._kernel" in sys.modules}))
    """))
    assert out == {"loaded": [], "missing": [], "star": [], "kernel": False}


def test_public_modules_resolve_after_a_bare_import():
    """``import pwsdyn`` then ``pwsdyn.io.load_trajectory`` or ``pwsdyn.plot.plot_scan``
    works without importing the module first (a script that did not failed with an
    AttributeError unless some other import had loaded it), and still loads no kernel."""
    out = _json_tail(_run("""
        import json, sys
        import pwsdyn
        names = {m: hasattr(getattr(pwsdyn, m), attr) for m, attr in (
            ("io", "load_trajectory"), ("plot", "plot_scan"), ("model", "load_model"),
            ("newton", "newton"), ("errors", "Status"), ("continuation", "Branch"))}
        print(json.dumps({"names": names, "in_dir": "io" in dir(pwsdyn),
                          "kernel": "pwsdyn.integrate._kernel" in sys.modules}))
    """))
    assert out["names"] == dict.fromkeys(("io", "plot", "model", "newton", "errors",
                                          "continuation"), True)
    assert out["in_dir"] and not out["kernel"]


def test_public_names_are_the_subpackages_objects():
    import pwsdyn.explore
    import pwsdyn.integrate
    import pwsdyn.model
    import pwsdyn.orbits
    import pwsdyn.stability

    for name in pwsdyn.__all__:
        obj = getattr(pwsdyn, name)
        home = getattr(pwsdyn, pwsdyn._LAZY[name]) if name in pwsdyn._LAZY else pwsdyn.errors
        assert getattr(home, name) is obj, name
    assert {"simulate", "sweep", "basins", "lyapunov_spectrum", "load_model", "Trajectory",
            "PwsdynError", "ArgumentError"} <= set(pwsdyn.__all__)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        pwsdyn.no_such_name


_CLI_CASES = [
    ["--help"], ["models"], ["simulate", "--help"], ["sweep", "--help"], ["basins", "--help"],
    ["orbit", "--help"],
    # click's own argument errors
    ["simulate", "bouncing-ball", "--rtol", "abc"], ["sweep", "bouncing-ball"],
    ["no-such-command"],
    # the commands' checks against the model
    ["simulate", "bouncing-ball", "-p", "nosuch=1"], ["simulate", "no-such-model"],
    ["sweep", "bouncing-ball", "--param", "nosuch", "--from", "0", "--to", "1", "--num", "3"],
    # checks made by the API before any run
    ["simulate", "bouncing-ball", "--rtol", "-1"],
    ["sweep", "bouncing-ball", "--param", "A", "--from", "0", "--to", "1", "--num", "3",
     "--transient", "-1"],
    ["basins", "bouncing-ball", "--x", "y", "--x-from", "0", "--x-to", "1", "--x-num", "2",
     "--y", "v", "--y-from", "0", "--y-to", "1", "--y-num", "2", "--samples", "0"],
]


def test_cli_help_models_and_argument_errors_never_load_the_kernel():
    out = _json_tail(_run(f"""
        import json, sys
        from click.testing import CliRunner
        from pwsdyn.cli import main
        res = []
        for args in {_CLI_CASES!r}:
            r = CliRunner().invoke(main, args)
            res.append([args, r.exit_code, type(r.exception).__name__
                        if r.exception and not isinstance(r.exception, SystemExit) else None,
                        [m for m in ("{KERNEL}", "{MAP_KERNELS}") if m in sys.modules]])
        print(json.dumps(res))
    """))
    for args, code, exc, loaded in out:
        assert exc is None, (args, exc)
        assert loaded == [], (args, loaded)
        # help and listings succeed; every other case is an error (2: usage, 1: model/run)
        ok = args[-1] in ("--help", "--version") or args == ["models"]
        assert (code == 0) == ok, (args, code)


def test_cli_runs_without_a_figure_do_not_import_matplotlib():
    out = _json_tail(_run("""
        import json, sys
        from click.testing import CliRunner
        from pwsdyn.cli import main
        codes = [CliRunner().invoke(main, args).exit_code for args in (
            ["simulate", "bouncing-ball", "--t-end", "1"],
            ["sweep", "sqrt-map", "--param", "mu", "--from", "0.01", "--to", "0.05",
             "--num", "4", "--set", "lam=0.8", "--transient", "10", "--samples", "8",
             "--no-progress"])]
        print(json.dumps({"codes": codes, "mpl": "matplotlib" in sys.modules}))
    """))
    assert out == {"codes": [0, 0], "mpl": False}


def test_api_argument_errors_come_before_the_kernel():
    """``simulate``, ``sweep`` and ``basins`` check their arguments before they load the
    integrator: on a machine without numba's cache a wrong argument is reported at once."""
    out = _json_tail(_run(f"""
        import json, sys
        import numpy as np
        import pwsdyn
        calls = [
            lambda: pwsdyn.simulate("bouncing-ball", {{"y": 1, "v": 0}}, (0, 1), rtol=-1),
            lambda: pwsdyn.simulate("bouncing-ball", {{"y": 1}}, (0, 1)),
            lambda: pwsdyn.simulate("bouncing-ball", {{"y": 1, "v": 0}}, (0, 1), method="X"),
            lambda: pwsdyn.sweep("bouncing-ball", "A", [0.1, 0.2], {{"y": 1, "v": 0}},
                                 transient=-1),
            lambda: pwsdyn.basins("bouncing-ball", {{"y": [0.1, 0.2]}}, workers=0),
            lambda: pwsdyn.lyapunov_spectrum("bouncing-ball", {{"y": 1, "v": 0}}, duration=0),
        ]
        res = []
        for f in calls:
            try:
                f()
                res.append("accepted")
            except pwsdyn.ArgumentError:
                res.append("ArgumentError")
        print(json.dumps({{"res": res, "kernel": "{KERNEL}" in sys.modules}}))
    """))
    assert out == {"res": ["ArgumentError"] * 6, "kernel": False}


def test_only_the_loader_imports_the_kernel():
    """Every use of the integrator goes through ``pwsdyn.integrate._load.kernel()`` (which
    announces a compilation), and of the map loops through ``pwsdyn.model.maps``: no other
    module imports them, at module level or inside a function."""
    allowed = {KERNEL: {"pwsdyn.integrate._load"}, MAP_KERNELS: {"pwsdyn.model.maps"}}
    found = []
    for path in SRC.rglob("*.py"):
        mod = ".".join(("pwsdyn",) + path.relative_to(SRC).with_suffix("").parts)
        mod = mod.removesuffix(".__init__")
        pkg = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = pkg.split(".")
                    parts = parts[:len(parts) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                names = [base] + [f"{base}.{a.name}" for a in node.names]
            for name in names:
                for target, ok in allowed.items():
                    if name == target and mod not in ok:
                        found.append((mod, name))
    assert found == []


def test_kernels_release_the_gil():
    """The threaded default relies on it: the integrator and the map loops run with the GIL
    released (numba ``nogil``)."""
    from pwsdyn.integrate._load import kernel
    from pwsdyn.model import maps

    assert kernel().run_kernel.targetoptions.get("nogil") is True
    for name in ("orbit_kernel", "lyapunov_kernel"):
        assert getattr(maps, name).targetoptions.get("nogil") is True, name


# ======================================================================================
# the compile message
# ======================================================================================

_JIT_MODULE = """
from numba import njit, types

@njit(types.float64(types.float64), cache=True)
def twice(x):
    return 2.0 * x
"""

_NOTICE_SCRIPT = """
import sys
sys.path.insert(0, sys.argv[1])
from pwsdyn._compiling import compile_notice
with compile_notice("the test function", sys.argv[2]):
    import jitmod_{tag}
assert jitmod_{tag}.twice(2.0) == 4.0
"""


def _notice(tmp_path, tag: str, watched: str | None = None, **env):
    module = tmp_path / f"jitmod_{tag}.py"
    if not module.exists():
        # written once: numba's cache index is stamped with the source file's modification
        # time, which a rewrite changes (numba 0.59 then compiled again)
        module.write_text(_JIT_MODULE)
    script = tmp_path / f"notice_{tag}.py"
    script.write_text(_NOTICE_SCRIPT.format(tag=tag))
    proc = subprocess.run([sys.executable, str(script), str(tmp_path),
                           watched or f"jitmod_{tag}"], capture_output=True, text=True,
                          env=_env(**env))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stderr


def test_compile_message_only_when_numba_really_compiles(tmp_path):
    """The first import compiles (no cache next to the module): the message and the time;
    the second loads from numba's cache: nothing. (NUMBA_CACHE_DIR empty: numba's default,
    the cache next to the module, whatever the calling environment sets.)"""
    first = _notice(tmp_path, "a", PWSDYN_QUIET="", NUMBA_CACHE_DIR="")
    assert ("pwsdyn: compiling the test function (first run only, 2-5 minutes on 2 cores)..."
            in first)
    assert "pwsdyn: compiled the test function in " in first
    assert list((tmp_path / "__pycache__").glob("jitmod_a.twice-*.nbi"))
    assert _notice(tmp_path, "a", PWSDYN_QUIET="", NUMBA_CACHE_DIR="") == ""


class _Stream(io.StringIO):
    def __init__(self, tty: bool):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


@pytest.mark.parametrize("tty", [False, True])
def test_a_long_compile_shows_progress(tty):
    """Into a log or a pipe, a line every `every` seconds while numba compiles, so that a long
    compile never looks like a hang; on a terminal the count in place on the first line."""
    from pwsdyn._compiling import KERNEL_COMPILE_TIME, PROGRESS_EVERY, _Notice

    # what the README promises: the measured range, and a line every 15 s
    readme = " ".join((Path(__file__).resolve().parents[1] / "README.md")
                      .read_text(encoding="utf-8").split())
    assert PROGRESS_EVERY == 15.0 and "a line every 15 s" in readme
    assert KERNEL_COMPILE_TIME == "2-5 minutes on 2 cores" and "2-5 minutes on two" in readme

    stream = _Stream(tty)
    notice = _Notice("the integrator", "2-5 minutes on 2 cores", ("pwsdyn.",), stream,
                     every=0.05)
    notice.compiling("numpy.core")                 # not one of the modules watched: nothing
    assert stream.getvalue() == ""
    notice.compiling("pwsdyn.integrate._kernel.run")
    deadline = time.monotonic() + 30.0             # a loaded machine may delay the thread
    while stream.getvalue().count("\r" if tty else "\n") < (2 if tty else 3) and \
            time.monotonic() < deadline:
        time.sleep(0.05 if not tty else 0.5)
    notice.finish(failed=False)
    text = stream.getvalue()
    head = "pwsdyn: compiling the integrator (first run only, 2-5 minutes on 2 cores)..."
    assert text.startswith(head)
    assert "pwsdyn: compiled the integrator in " in text.splitlines()[-1]
    if tty:
        assert "still compiling" not in text and "\r" + head in text
    else:
        progress = [ln for ln in text.splitlines() if ln.startswith("pwsdyn: still")]
        assert len(progress) >= 2
        seconds = [float(ln.split(", ")[1].split(" s ")[0]) for ln in progress]
        assert seconds == sorted(seconds)
        assert all(ln.endswith(" s so far") for ln in progress)


def test_compile_message_can_be_silenced_and_is_scoped(tmp_path):
    assert _notice(tmp_path, "b", PWSDYN_QUIET="1") == ""
    # a compilation of a function outside the modules watched is not announced
    assert _notice(tmp_path, "c", watched="pwsdyn.no_such_module", PWSDYN_QUIET="") == ""


# ======================================================================================
# where the chunks run
# ======================================================================================

def _where(task):
    return task, threading.current_thread().name


def _run_chunks(n_tasks: int, **kw):
    from pwsdyn.explore._executor import run_chunks

    got = {}
    run_chunks(_where, list(range(n_tasks)), list(range(n_tasks)),
               lambda i, res: got.__setitem__(i, res), progress=False, **kw)
    assert sorted(got) == list(range(n_tasks))
    assert all(got[i][0] == i for i in got)
    return {name for _, name in got.values()}


def test_chunks_run_on_threads_by_default():
    main = threading.current_thread().name
    names = _run_chunks(8, workers=3)
    assert main not in names and all(n.startswith("pwsdyn") for n in names)
    assert len(names) <= 3
    # one worker, one chunk or the synchronous scheduler: here, one after the other
    assert _run_chunks(4, workers=1) == {main}
    assert _run_chunks(1) == {main}
    assert _run_chunks(4, workers=2, scheduler="synchronous") == {main}


def _fail_on_two(task):
    if task == 2:
        raise ValueError("chunk 2 failed")
    return task


def test_a_failing_chunk_stops_the_threaded_run():
    from pwsdyn.explore._executor import run_chunks

    with pytest.raises(ValueError, match="chunk 2 failed"):
        run_chunks(_fail_on_two, list(range(40)), list(range(40)), lambda i, r: None,
                   workers=2, progress=False)
    assert not [t for t in threading.enumerate() if t.name.startswith("pwsdyn_")]


_NO_GUARD_SCRIPT = """
import numpy as np
import pwsdyn

ds = pwsdyn.sweep("sqrt-map", "mu", np.linspace(0.001, 0.05, 12), [0.1],
                  params={"lam": 0.8}, chunk_size=2, workers=2, progress=False,
                  transient=50, samples=20)
print(int(ds.period.size))   # 12 values, swept up and down (the default direction)
"""


def test_a_sweep_in_a_script_without_main_guard_runs(tmp_path):
    """The default (threads) starts no process, so a script needs no ``__main__`` guard."""
    script = tmp_path / "sweep_script.py"
    script.write_text(_NO_GUARD_SCRIPT)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          cwd=tmp_path, env=_env())
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.strip() == "24"
    assert "Traceback" not in proc.stderr


# ======================================================================================
# numba's cache against the sources the compiled code reads at compile time
# ======================================================================================

def test_stale_cache_entries_of_a_compiled_module_are_removed(tmp_path):
    """Numba keys a cached function on its own file only: the kernel's entries must go when
    a file it reads at compile time (its codes) changes, and stay while nothing changed."""
    from pwsdyn._compiling import STAMP_SUFFIX, refresh_cache, sources_digest

    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "sub" / "_kernel.py").write_text("x = 1\n")
    (pkg / "_codes.py").write_text("A = 1\n")
    sources = ("sub/_kernel.py", "_codes.py")
    cache = tmp_path / "cache"
    cache.mkdir()
    mine = [cache / "_kernel.run_kernel-10.py311.nbi", cache / "_kernel.run_kernel-10.py311.1.nbc"]
    other = [cache / "_map_kernels.orbit_kernel-5.py311.nbi", cache / "_kernel_notes.txt"]
    for f in mine + other:
        f.write_bytes(b"x")
    d1 = sources_digest(sources, package=pkg)
    assert refresh_cache(cache, "_kernel", d1)                 # no stamp yet: removed
    assert not any(f.exists() for f in mine) and all(f.exists() for f in other)
    assert (cache / f"_kernel{STAMP_SUFFIX}").read_text().strip() == d1
    for f in mine:
        f.write_bytes(b"x")
    assert not refresh_cache(cache, "_kernel", d1)             # unchanged sources: kept
    assert all(f.exists() for f in mine)
    (pkg / "_codes.py").write_text("A = 2\n")                  # a code changes
    d2 = sources_digest(sources, package=pkg)
    assert d2 != d1 and refresh_cache(cache, "_kernel", d2)
    assert not any(f.exists() for f in mine) and all(f.exists() for f in other)


def test_the_kernel_cache_is_located_where_numba_writes_it():
    """The guard looks where numba's own locators put each part's cache (here: the
    __pycache__ next to the sources, or NUMBA_CACHE_DIR), and the stamps match the sources
    after a load."""
    import numba

    from pwsdyn._compiling import PACKAGE, STAMP_SUFFIX, numba_cache_dir, sources_digest
    from pwsdyn.integrate._load import KERNEL_DEPENDS, KERNEL_PARTS, kernel

    kernel()
    digest = sources_digest(list(KERNEL_PARTS) + list(KERNEL_DEPENDS))
    for rel in KERNEL_PARTS:
        where = numba_cache_dir(PACKAGE / rel)
        stem = Path(rel).stem
        assert where is not None
        assert (where / f"{stem}{STAMP_SUFFIX}").read_text().strip() == digest
        assert numba.config.CACHE_DIR in ("", None) or str(where).startswith(
            numba.config.CACHE_DIR)
    run = Path(kernel().run_kernel._cache._cache_path)
    assert run == numba_cache_dir(PACKAGE / "integrate/_kernel/run.py")
    assert any(run.glob("run.run_kernel-*.nbi"))


def test_function_addresses_are_resolved_once_and_right():
    """The model's evaluate, an argument of every kernel call, has its addresses memoized per
    dispatcher and signature: the memo gives what numba's own lookup gives, keeps two entries
    per model whatever the number of calls, and runs of two models interleaved give each
    model's own results bit for bit (a mixed-up address would run the other model's field).
    A numba without both lookups (0.59 has no ``_get_jit_address``) is left as it is: the runs
    must still give each model's own results."""
    from numba.experimental import function_type as ft

    from pwsdyn.integrate._load import kernel
    from pwsdyn.model.codegen import EVALUATE_TYPE
    from pwsdyn.integrate.compiled import ModelContext

    kernel()
    in_effect = hasattr(ft, "_get_wrapper_address") and hasattr(ft, "_get_jit_address")
    assert hasattr(getattr(ft, "_get_wrapper_address", None), "__wrapped__") == in_effect
    models = {name: pwsdyn.load_model(name) for name in ("impact-oscillator", "bouncing-ball")}
    x0 = {"impact-oscillator": [-0.5, 0.1], "bouncing-ball": [1.0, 0.0]}

    def run(name):
        tr = pwsdyn.simulate(models[name], x0[name], (0.0, 3.0), dense=False)
        return tr.y[-1].tobytes(), len(tr.events)

    first = {name: run(name) for name in models}
    assert first["impact-oscillator"] != first["bouncing-ball"]
    for _ in range(5):
        for name in models:
            assert run(name) == first[name]
    if not in_effect:
        return
    sig = EVALUATE_TYPE.signature
    for name in models:
        ev = ModelContext(name).cm.evaluate
        for get in (ft._get_wrapper_address, ft._get_jit_address):
            assert get(ev, sig) == get.__wrapped__(ev, sig) > 0
    # one entry per call site's signature object and lookup: more calls add none
    memo = next(c.cell_contents for c in ft._get_wrapper_address.__closure__
                if type(c.cell_contents).__name__ == "WeakKeyDictionary")
    sizes = {id(f): len(entries) for f, entries in memo.items()}
    for name in models:
        run(name)
    assert {id(f): len(entries) for f, entries in memo.items()} == sizes
