"""The one way into the compiled integrator: :func:`kernel`.

Importing :mod:`pwsdyn.integrate._kernel` compiles it (its functions have explicit numba
signatures), 2-5 minutes on two cores without numba's on-disk cache. Nothing in pwsdyn imports it at
module level: ``import pwsdyn``, ``pwsdyn --help`` and argument checks never wait for it. The
first run that needs the kernel calls :func:`kernel`, which imports it once per process,
under :func:`pwsdyn._compiling.compile_notice`, so a real compilation is announced on stderr
(a load from the cache is silent).

Numba keys a cached function on its own source file only. The kernel reads its integer codes
from :mod:`pwsdyn._codes` and the model interface's from :mod:`pwsdyn.model.codegen` as
compile-time constants, so an edit there would leave machine code built with the old values
in the cache. Before the import, :func:`kernel` therefore compares a digest of every file the
compiled code depends on (and numba's and Python's versions) with the one stored next to the
cache, and removes the kernel's cached entries where they differ
(:func:`pwsdyn._compiling.check_cache`).
"""

from __future__ import annotations

import threading

_KERNEL = None
_LOCK = threading.Lock()

#: The kernel's parts: the compiled modules of the package ``integrate/_kernel`` (paths
#: relative to pwsdyn's package).
KERNEL_PARTS = tuple(f"integrate/_kernel/{name}.py" for name in (
    "_base", "fields", "steppers", "watch", "actions", "run"))
#: The other files whose contents the compiled kernel depends on (constants read at compile
#: time, the model interface it is compiled against).
KERNEL_DEPENDS = ("integrate/_kernel/__init__.py", "integrate/_codes.py", "_codes.py",
                  "model/codegen.py")


def kernel():
    """The module :mod:`pwsdyn.integrate._kernel`, compiled (or loaded from numba's cache) on
    the first call in this process; thread-safe."""
    global _KERNEL
    if _KERNEL is None:
        with _LOCK:
            if _KERNEL is None:
                from .._compiling import check_cache, compile_notice, memoize_function_addresses

                check_cache(KERNEL_PARTS, KERNEL_DEPENDS)
                # the model's evaluate is an argument of every kernel call
                memoize_function_addresses()
                with compile_notice("the integrator", __package__ + "._kernel"):
                    from . import _kernel
                _KERNEL = _kernel
    return _KERNEL
