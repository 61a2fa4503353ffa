"""A message on stderr while numba compiles pwsdyn's integrator.

The integrator is compiled by numba with ``cache=True``: the first use on a machine (or after
an upgrade of pwsdyn, numba or Python) compiles it, two to five minutes on two cores
(:data:`KERNEL_COMPILE_TIME`); every later process loads the machine code from numba's cache
next to the module in a fraction of a second. Numba announces a real compilation -- a cache
miss, never a load from the cache -- with its ``numba:compile`` event, so
:func:`compile_notice` listens for that event and prints

    pwsdyn: compiling the integrator (first run only, 2-5 minutes on 2 cores)...
    pwsdyn: still compiling the integrator, 15 s so far
    pwsdyn: still compiling the integrator, 30 s so far
    ...
    pwsdyn: compiled the integrator in 97 s (cached for later runs)

to stderr only when compiling really happens: a line every :data:`PROGRESS_EVERY` seconds
into a log or a pipe, so that a long silence never looks like a hang; on a terminal the first
line counts the seconds in place instead. ``PWSDYN_QUIET=1`` in the environment silences it.

Numba keys each cached function on its own source file only; :func:`check_cache` removes a
compiled module's cached entries when any file it depends on at compile time has changed
since they were written (the integer codes it reads as constants, the interface it is
compiled against), so that an edit there can never run with stale machine code.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
import threading
import time
import warnings
from pathlib import Path

#: Environment variable that silences the message (any value but "", "0", "false", "no").
QUIET_ENV = "PWSDYN_QUIET"

#: How long the first compilation of the integrator takes, measured from fresh caches on
#: 2-core x86-64 virtual machines: 85-92 s of CPU on one (about the wall time when it is idle;
#: 126 s at a load average of 3, 331 s at 4.7), 278 s of CPU on a slower one (idle), where the
#: integrator without the intersections of several switching surfaces took 214 s. Nearly all
#: of it is LLVM's: the message cannot know the machine, so it counts the seconds as well.
KERNEL_COMPILE_TIME = "2-5 minutes on 2 cores"

#: Seconds between two progress lines when stderr is not a terminal.
PROGRESS_EVERY = 15.0


def quiet() -> bool:
    """Whether ``PWSDYN_QUIET`` asks for no compile message."""
    return os.environ.get(QUIET_ENV, "").strip().lower() not in ("", "0", "false", "no")


class _Notice:
    """The state of one :func:`compile_notice` block: prints on the first compilation."""

    def __init__(self, what: str, expected: str, modules: tuple, stream,
                 every: float = PROGRESS_EVERY):
        self.what, self.expected, self.modules = what, expected, modules
        self.every = every
        self.stream = stream
        self.started: float | None = None
        self.tty = False
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None
        self._write_lock = threading.Lock()

    @property
    def head(self) -> str:
        return f"pwsdyn: compiling {self.what} (first run only, {self.expected})..."

    def _write(self, text: str) -> None:
        with self._write_lock:
            try:
                self.stream.write(text)
                self.stream.flush()
            except (OSError, ValueError, AttributeError):   # a closed or odd stderr: say nothing
                pass

    def compiling(self, module: str) -> None:
        """Called by the listener at the start of every real compilation."""
        if self.started is not None or not module.startswith(self.modules):
            return
        self.started = time.perf_counter()
        try:
            self.tty = bool(self.stream.isatty())
        except (AttributeError, ValueError, OSError):
            self.tty = False
        self._write(self.head if self.tty else self.head + "\n")
        self._ticker = threading.Thread(target=self._tick, name="pwsdyn-compile-notice",
                                        daemon=True)
        self._ticker.start()

    def _tick(self) -> None:
        # a terminal: the count in place, every second; a log or a pipe: a line every `every`
        # seconds (one line each second would flood a CI log)
        while not self._stop.wait(1.0 if self.tty else self.every):
            elapsed = time.perf_counter() - self.started
            if self.tty:
                self._write(f"\r{self.head} {elapsed:.0f} s")
            else:
                self._write(f"pwsdyn: still compiling {self.what}, {elapsed:.0f} s so far\n")

    def finish(self, failed: bool) -> None:
        if self.started is None:
            return
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        dt = time.perf_counter() - self.started
        if failed:
            end = f"pwsdyn: compiling {self.what} failed after {dt:.0f} s\n"
        else:
            end = f"pwsdyn: compiled {self.what} in {dt:.0f} s (cached for later runs)\n"
        # on a terminal the counting line is replaced by the result
        self._write("\r\x1b[K" + end if self.tty else end)


@contextlib.contextmanager
def compile_notice(what: str, modules, *, expected: str = KERNEL_COMPILE_TIME, stream=None,
                   every: float = PROGRESS_EVERY):
    """Within this block, announce on ``stream`` (default stderr) the first compilation numba
    really does of a function defined in one of ``modules`` (module names or prefixes), and
    at the end of the block how long it took. Nothing is printed when numba loads everything
    from its cache, or when ``PWSDYN_QUIET`` is set.

    Numba's warning that first-class function types are experimental (the integrator takes
    the model as one) is not shown while compiling inside the block: it is about numba, not
    about anything the user did.
    """
    modules = (modules,) if isinstance(modules, str) else tuple(modules)
    stream = stream if stream is not None else sys.stderr
    # no stderr at all (pythonw, some services): nothing to say it on
    notice = (None if quiet() or stream is None
              else _Notice(what, expected, modules, stream, every))
    from numba.core import event
    from numba.core.errors import NumbaExperimentalFeatureWarning

    class _Listener(event.Listener):
        def on_start(self, ev):
            if notice is not None:
                fn = getattr(ev.data.get("dispatcher"), "py_func", None)
                notice.compiling(getattr(fn, "__module__", None) or "")

        def on_end(self, ev):
            pass

    listener = _Listener()
    failed = True
    event.register("numba:compile", listener)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            yield notice
        failed = False
    finally:
        event.unregister("numba:compile", listener)
        if notice is not None:
            notice.finish(failed)


# ======================================================================================
# numba's cache against the sources the compiled code depends on
# ======================================================================================
#: pwsdyn's package directory (the paths of :func:`check_cache` are relative to it).
PACKAGE = Path(__file__).resolve().parent
#: The file next to numba's cache holding the digest of the sources it was compiled from
#: (one per compiled module: ``<module>.digest``).
STAMP_SUFFIX = ".digest"


def sources_digest(sources, package: Path = PACKAGE) -> str:
    """SHA-256 of the files ``sources`` (relative to ``package``), numba's version and
    Python's."""
    import numba

    h = hashlib.sha256(f"numba {numba.__version__}; python {sys.version}".encode())
    for rel in sources:
        h.update(rel.encode() + b"\0" + (package / rel).read_bytes() + b"\0")
    return h.hexdigest()


def refresh_cache(cache_dir, module: str, digest: str) -> bool:
    """Remove numba's cached entries of ``module`` (``<module>.*.nbi`` and ``.nbc``) from
    ``cache_dir`` unless its stamp there holds ``digest``; then store ``digest``. Returns
    whether entries were removed. A directory that cannot be written is left alone (numba
    then caches elsewhere, or not at all)."""
    cache_dir = Path(cache_dir)
    stamp = cache_dir / f"{module}{STAMP_SUFFIX}"
    try:
        if stamp.read_text().strip() == digest:
            return False
    except OSError:
        pass
    removed = False
    try:
        for f in cache_dir.glob(f"{module}.*"):
            if f.suffix in (".nbi", ".nbc"):
                f.unlink(missing_ok=True)
                removed = True
        cache_dir.mkdir(parents=True, exist_ok=True)
        tmp = cache_dir / f"{module}{STAMP_SUFFIX}.{os.getpid()}"
        tmp.write_text(digest + "\n")
        os.replace(tmp, stamp)
    except OSError:
        pass
    return removed


def numba_cache_dir(py_file) -> Path | None:
    """Where numba caches the functions of ``py_file``: asked of numba's own cache locators
    (``NUMBA_CACHE_DIR``, the ``__pycache__`` next to the file, a user-wide directory), in
    numba's order; ``None`` where that cannot be told."""
    try:
        from numba.core.caching import FunctionCache

        def probe():                         # a function of that file, as numba sees one
            pass
        for cls in FunctionCache._impl_class._locator_classes:
            loc = cls.from_function(probe, str(py_file))
            if loc is not None:
                return Path(loc.get_cache_path())
    except Exception:                        # a numba without these internals: no guard
        return None
    return None


def check_cache(compiled, depends=()) -> bool:
    """Before importing compiled modules (``compiled``: their files, relative to the
    package): numba keys each function's cache on its own file alone, so a caller cached in
    one file keeps the machine code of a callee it inlined from another, and every file keeps
    the constants it read (``depends``: the codes, the interface compiled against). Where
    any of these files changed since the entries were written, the entries of every compiled
    module are removed. Returns whether any were."""
    compiled = list(compiled)
    digest = sources_digest(compiled + list(depends))
    removed = False
    for rel in compiled:
        py_file = PACKAGE / rel
        where = numba_cache_dir(py_file)
        if where is not None:
            removed |= refresh_cache(where, py_file.stem, digest)
    return removed


# --------------------------------------------------------------------------------------
# the addresses of a first-class function argument, resolved once
# --------------------------------------------------------------------------------------

_ADDRESSES_LOCK = threading.Lock()
_ADDRESSES_MEMOIZED = False


def memoize_function_addresses() -> bool:
    """Resolve the machine-code addresses of a first-class function argument once per
    function and signature instead of on every call. Returns whether it is in effect.

    The integrator takes the model's compiled ``evaluate`` as a first-class function (one
    kernel for every model). When a compiled function is called with such an argument,
    numba's unboxing calls ``numba.experimental.function_type._get_wrapper_address`` and
    ``_get_jit_address`` (looked up by name on every call): each looks up the dispatcher's
    compile result for the signature and asks LLVM for the symbol's address, ~12 us each --
    about 7 periods of an exact run of the impact oscillator, paid by every short run
    (shooting, Poincare maps, sweeps, basins). A dispatcher's compiled code for a signature
    never moves once it exists, so the two lookups are memoized per dispatcher (held weakly:
    a collected model's entry goes with it) and signature. Only numba ``Dispatcher`` objects
    are memoized; anything else (a ``cfunc``, an object with ``__wrapper_address__``) goes to
    numba's own function each time. If a numba release no longer has these functions, nothing
    is changed and the calls cost what they did.
    """
    global _ADDRESSES_MEMOIZED
    with _ADDRESSES_LOCK:
        if _ADDRESSES_MEMOIZED:
            return True
        try:
            from numba.core.dispatcher import Dispatcher
            from numba.experimental import function_type as ft

            originals = (ft._get_wrapper_address, ft._get_jit_address)
        except (ImportError, AttributeError):
            return False
        import weakref

        memo: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

        def memoized(original, slot):
            def get_address(func, sig):
                if not isinstance(func, Dispatcher):
                    return original(func, sig)
                per_func = memo.get(func)
                if per_func is None:
                    per_func = memo.setdefault(func, {})
                # keyed on the signature object's identity (numba passes the one object it
                # unpickled for the call site each time; hashing a Signature costs ~1.6 us),
                # which the entry keeps alive so that the identity cannot be reused
                entry = per_func.get((slot, id(sig)))
                if entry is None:
                    entry = (sig, original(func, sig))
                    per_func[(slot, id(sig))] = entry
                return entry[1]

            get_address.__wrapped__ = original
            get_address.__doc__ = original.__doc__
            return get_address

        ft._get_wrapper_address = memoized(originals[0], "wrapper")
        ft._get_jit_address = memoized(originals[1], "jit")
        _ADDRESSES_MEMOIZED = True
        return True


# --------------------------------------------------------------------------------------
# the numba type of a function argument, resolved once
# --------------------------------------------------------------------------------------

_TYPED_ONCE: dict = {}


def type_once(dispatcher):
    """``dispatcher`` (a numba ``Dispatcher``), made to give its numba type from a memo.

    Numba types each argument of a call to a compiled function; for an argument that is
    itself a compiled function (the model's ``evaluate``, passed to the kernel on every
    run) it reads the property ``_numba_type_``, which builds ``types.Dispatcher(f)`` anew
    each time (its name from ``repr(f)``, then interned): ~7 us, twice per kernel call, the
    same type every time. The dispatcher's class is replaced by a subclass (same layout,
    nothing else changed) whose ``_numba_type_`` is built once and kept on the instance (the
    type refers to its function weakly, so no cycle keeps a model alive). Returns the same
    object; anything that is not a numba ``Dispatcher``, or one whose class cannot be
    swapped, is returned as it is and costs what it did."""
    try:
        from numba.core import types
        from numba.core.dispatcher import Dispatcher
    except ImportError:
        return dispatcher
    cls = type(dispatcher)
    if not isinstance(dispatcher, Dispatcher) or getattr(cls, "_pwsdyn_typed_once", False):
        return dispatcher
    sub = _TYPED_ONCE.get(cls)
    if sub is None:
        def _numba_type_(self):
            tp = self.__dict__.get("_pwsdyn_numba_type")
            if tp is None:
                tp = self.__dict__["_pwsdyn_numba_type"] = types.Dispatcher(self)
            return tp

        sub = _TYPED_ONCE[cls] = type(cls.__name__, (cls,), {
            "_numba_type_": property(_numba_type_), "_pwsdyn_typed_once": True,
            "__module__": cls.__module__, "__qualname__": cls.__qualname__,
            "__doc__": cls.__doc__})
    try:
        dispatcher.__class__ = sub
    except TypeError:
        pass
    return dispatcher
