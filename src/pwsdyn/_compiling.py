"""A message on stderr while numba compiles pwsdyn's integrator.

The integrator is compiled by numba with ``cache=True``: the first use on a machine (or after
an upgrade of pwsdyn, numba or Python) compiles it, about a minute; every later process loads
the machine code from numba's cache next to the module in a fraction of a second. Numba
announces a real compilation -- a cache miss, never a load from the cache -- with its
``numba:compile`` event, so :func:`compile_notice` listens for that event and prints

    pwsdyn: compiling the integrator (first run only, about a minute)...
    pwsdyn: compiled the integrator in 57 s (cached for later runs)

to stderr only when compiling really happens (on a terminal the first line counts the
seconds as they pass). ``PWSDYN_QUIET=1`` in the environment silences it.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
import warnings

#: Environment variable that silences the message (any value but "", "0", "false", "no").
QUIET_ENV = "PWSDYN_QUIET"


def quiet() -> bool:
    """Whether ``PWSDYN_QUIET`` asks for no compile message."""
    return os.environ.get(QUIET_ENV, "").strip().lower() not in ("", "0", "false", "no")


class _Notice:
    """The state of one :func:`compile_notice` block: prints on the first compilation."""

    def __init__(self, what: str, expected: str, modules: tuple, stream):
        self.what, self.expected, self.modules = what, expected, modules
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
        if self.tty:
            self._write(self.head)
            self._ticker = threading.Thread(target=self._tick, name="pwsdyn-compile-notice",
                                            daemon=True)
            self._ticker.start()
        else:
            self._write(self.head + "\n")

    def _tick(self) -> None:
        while not self._stop.wait(1.0):
            self._write(f"\r{self.head} {time.perf_counter() - self.started:.0f} s")

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
def compile_notice(what: str, modules, *, expected: str = "about a minute", stream=None):
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
    notice = None if quiet() or stream is None else _Notice(what, expected, modules, stream)
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
