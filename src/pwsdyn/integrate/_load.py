"""The one way into the compiled integrator: :func:`kernel`.

Importing :mod:`pwsdyn.integrate._kernel` compiles it (its functions have explicit numba
signatures), about a minute without numba's on-disk cache. Nothing in pwsdyn imports it at
module level: ``import pwsdyn``, ``pwsdyn --help`` and argument checks never wait for it. The
first run that needs the kernel calls :func:`kernel`, which imports it once per process,
under :func:`pwsdyn._compiling.compile_notice`, so a real compilation is announced on stderr
(a load from the cache is silent).
"""

from __future__ import annotations

import threading

_KERNEL = None
_LOCK = threading.Lock()


def kernel():
    """The module :mod:`pwsdyn.integrate._kernel`, compiled (or loaded from numba's cache) on
    the first call in this process; thread-safe."""
    global _KERNEL
    if _KERNEL is None:
        with _LOCK:
            if _KERNEL is None:
                from .._compiling import compile_notice

                with compile_notice("the integrator", __package__ + "._kernel"):
                    from . import _kernel
                _KERNEL = _kernel
    return _KERNEL
