"""Print the Python and the versions of the packages a run depends on, one line, so that a
failure in CI can be traced to the version that brought it."""

from __future__ import annotations

import platform
import sys
from importlib.metadata import PackageNotFoundError, version

PACKAGES = ["numpy", "scipy", "numba", "llvmlite", "sympy", "xarray", "pandas", "dask",
            "distributed", "click", "matplotlib", "h5netcdf", "h5py", "tqdm", "pytest",
            "pytest-xdist", "hypothesis"]


def _version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "missing"


if __name__ == "__main__":
    label = sys.argv[1] if len(sys.argv) > 1 else "versions"
    found = " ".join(f"{name}=={_version(name)}" for name in PACKAGES)
    print(f"{label}: python=={platform.python_version()} {found}", flush=True)
