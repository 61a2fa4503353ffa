"""A resumable store of chunk results: a directory with one NetCDF file per finished chunk and
a manifest.

Layout::

    STORE/
      manifest.json        kind, model name and hash, settings, number of chunks, version
      chunk-00000.nc       one file per finished chunk, written atomically
      chunk-00003.nc
      ...

A chunk file is written under a temporary name and renamed when complete, so a run killed
at any moment leaves only whole chunk files (and possibly a ``.tmp`` file, ignored and
removed on the next run). Opening a store that exists checks that its manifest describes the
same analysis -- same kind, model hash, settings and pwsdyn version -- and refuses otherwise,
naming what differs; a finished chunk is never recomputed or overwritten.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import xarray as xr

from .. import __version__

MANIFEST = "manifest.json"


class StoreMismatchError(ValueError):
    """The store on disk belongs to another analysis (model, settings or version)."""


def _canonical(obj):
    """``obj`` through a JSON round trip (tuples become lists, keys strings)."""
    return json.loads(json.dumps(obj, sort_keys=True))


class ChunkStore:
    """See the module docstring.

    Parameters
    ----------
    path : str or Path
        The store directory (created if missing).
    kind : str
        ``"sweep"`` or ``"basins"``.
    model_name, model_hash : str
    settings : dict
        Everything the results depend on (JSON-serialisable); compared on resume.
    n_chunks : int
    """

    def __init__(self, path, kind: str, model_name: str, model_hash: str, settings: dict,
                 n_chunks: int):
        self.path = Path(path)
        self.manifest = _canonical({"kind": kind, "model": model_name, "model_hash": model_hash,
                                    "settings": settings, "n_chunks": int(n_chunks),
                                    "pwsdyn_version": __version__, "format": 1})
        if self.path.exists() and not self.path.is_dir():
            raise FileExistsError(f"store {str(self.path)!r} exists and is not a directory; "
                                  "nothing was overwritten")
        mpath = self.path / MANIFEST
        if self.path.is_dir() and mpath.exists():
            self._check(json.loads(mpath.read_text()))
        elif self.path.is_dir() and any(self.path.iterdir()):
            raise StoreMismatchError(f"store {str(self.path)!r} is a non-empty directory without "
                                     f"{MANIFEST}: not a pwsdyn store; choose another path "
                                     "(nothing was overwritten)")
        else:
            self.path.mkdir(parents=True, exist_ok=True)
            tmp = mpath.with_suffix(f".tmp{os.getpid()}")
            tmp.write_text(json.dumps(self.manifest, indent=1, sort_keys=True))
            os.replace(tmp, mpath)
        for stale in self.path.glob("*.tmp*"):
            try:
                stale.unlink()
            except OSError:
                pass

    def _check(self, old: dict) -> None:
        new = self.manifest
        why = []
        for key, label in (("kind", "analysis"), ("model_hash", "model"),
                           ("pwsdyn_version", "pwsdyn version"), ("n_chunks", "chunking")):
            if old.get(key) != new.get(key):
                extra = (f" ({old.get('model')!r} vs {new.get('model')!r})"
                         if key == "model_hash" else "")
                why.append(f"{label}: stored {old.get(key)!r}, requested {new.get(key)!r}{extra}")
        so, sn = old.get("settings", {}), new.get("settings", {})
        for k in sorted(set(so) | set(sn)):
            if so.get(k) != sn.get(k):
                a, b = json.dumps(so.get(k)), json.dumps(sn.get(k))
                short = lambda s: s if len(s) <= 60 else s[:57] + "..."  # noqa: E731
                why.append(f"setting `{k}`: stored {short(a)}, requested {short(b)}")
        if why:
            raise StoreMismatchError(
                f"refusing to resume into store {str(self.path)!r}: it holds results of a "
                f"different run ({'; '.join(why)}). Use another store path or delete this one; "
                "nothing was overwritten.")

    # ----------------------------------------------------------------------------------
    def chunk_path(self, i: int) -> Path:
        return self.path / f"chunk-{i:05d}.nc"

    def done(self) -> list[int]:
        """Indices of the chunks already stored."""
        out = []
        for f in self.path.glob("chunk-*.nc"):
            try:
                out.append(int(f.stem.split("-")[1]))
            except (IndexError, ValueError):
                continue
        return sorted(i for i in out if 0 <= i < self.manifest["n_chunks"])

    def write(self, i: int, ds: xr.Dataset) -> None:
        """Store chunk ``i`` (atomically; an existing chunk file is never replaced)."""
        path = self.chunk_path(i)
        if path.exists():
            return
        tmp = path.with_name(path.name + f".tmp{os.getpid()}")
        ds.to_netcdf(tmp, engine="h5netcdf")
        os.replace(tmp, path)

    def read(self, i: int) -> xr.Dataset:
        with xr.open_dataset(self.chunk_path(i), engine="h5netcdf") as ds:
            return ds.load()
