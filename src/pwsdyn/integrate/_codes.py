"""The shared integer codes, where the kernel and the integrator's Python side import them
from (their home is :mod:`pwsdyn._codes`, below the model layer, which names the event kinds
from there too)."""

from .._codes import *  # noqa: F401,F403
from .._codes import __all__  # noqa: F401
