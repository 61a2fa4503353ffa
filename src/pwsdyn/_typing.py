"""Type aliases of the public API, for annotations only.

Modules import these under ``typing.TYPE_CHECKING`` (their annotations are strings, ``from
__future__ import annotations``), so importing pwsdyn never imports this module.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Union

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from .model.maps import MapModel
    from .model.spec import Model

#: A model, or what :func:`pwsdyn.load_model` accepts: a built-in name, a TOML file, a dict.
ModelLike = Union["Model", "MapModel", str, "os.PathLike[str]", Mapping[str, Any]]
#: A state: values in state order, or a mapping state name -> value.
StateLike = Union[Mapping[str, float], Sequence[float], npt.NDArray[np.floating]]
#: Parameter values by name.
Params = Mapping[str, float]
#: A file or directory name.
PathLike = Union[str, "os.PathLike[str]"]
#: A state named or numbered.
StateKey = Union[str, int]
