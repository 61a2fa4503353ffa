"""A resumable store of chunk results: a directory with one NetCDF file per finished chunk, a
checksum file beside each, a manifest and a lock file.

Layout::

    STORE/
      manifest.json        kind, model name and hash, settings, number of chunks, pwsdyn
                           version, store format; written once, atomically, when the store is
                           created, and never changed
      lock                 taken (exclusively) by the run using the store; holds its PID and host
      chunk-00000.nc       one file per finished chunk
      chunk-00000.sha256   sha256 of chunk-00000.nc, as ``sha256sum`` writes it
      chunk-00003.nc
      chunk-00003.sha256
      ...

**Lock.** A run holds an exclusive lock on ``STORE/lock`` (``fcntl.flock``; ``msvcrt.locking``
on Windows) from the moment it opens the store until :meth:`ChunkStore.close` -- that is, for
the whole sweep or basin computation. The operating system releases it when the process dies,
even by SIGKILL, so a killed run never leaves a store locked. A second run on a store in use is
refused with :class:`~pwsdyn.errors.StoreError` naming the store and the PID holding it; it
changes nothing in the store. Leftover temporary files (``*.tmp*``, from a killed run) are
removed only while holding the lock, so they cannot be another live run's half-written chunk.
The lock file itself is never deleted (deleting it would let two runs lock two different
files). Locks on network file systems are only as good as the file system's ``flock``.

**Writes.** A chunk is written as ``chunk-NNNNN.nc.tmpPID``, flushed to disk, its checksum file
is written (also through a temporary file and a rename), and only then is the chunk renamed to
``chunk-NNNNN.nc``: a chunk counts as done exactly when its ``.nc`` file exists, and then its
checksum exists too. A run killed at any moment leaves whole chunks, temporary files and at
most one checksum file without its chunk (removed on the next run, which recomputes that
chunk). A finished chunk is never recomputed or overwritten.

**Checks.** Opening a store that exists checks that its manifest is a pwsdyn manifest
describing the same analysis -- same kind, model hash, settings, pwsdyn version and store
format -- and refuses otherwise (:class:`StoreMismatchError`, naming what differs; a manifest
that is not valid JSON or not a JSON object raises :class:`~pwsdyn.errors.StoreError`). Every
chunk read back is checked before use:

* its bytes against the sha256 in its checksum file (detects truncation, a flipped bit, a
  chunk file swapped with or copied over another);
* the attributes ``pwsdyn_chunk`` (its chunk index) and ``pwsdyn_store`` (the store identity:
  the sha256 of the manifest's canonical JSON) recorded in the file when it was written
  (detects a chunk file moved together with its checksum file, or taken from the store of
  another analysis).

A chunk that fails a check raises :class:`~pwsdyn.errors.StoreError` naming the file and what
is wrong; nothing is deleted or recomputed silently -- delete the chunk's two files to have it
recomputed, or use another store path.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import socket
from pathlib import Path

import xarray as xr

from .._version import __version__
from ..errors import PwsdynError, StoreError

MANIFEST = "manifest.json"
LOCK = "lock"
#: The store format. 3: the status codes of map runs are those of pwsdyn.Status (no
#: applicable piece -4, non-finite 5; format 2 wrote 2 and 3, the values of MAX_STEPS and
#: MAX_EVENTS), so a store of format 2 is refused rather than resumed with codes misread.
#: 4: a sweep's store holds two slots per chunk (its guess, and its rerun once stitched) and
#: each chunk its start state ``x_start``; a store of format 3 (guesses only) is refused.
FORMAT = 4

try:                                    # POSIX
    import fcntl
except ImportError:                     # pragma: no cover - Windows
    fcntl = None
    import msvcrt


# errno of a lock attempt on a file locked by another run (flock; msvcrt.locking on Windows)
_HELD = (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES, getattr(errno, "EDEADLK", None))


class StoreMismatchError(PwsdynError, ValueError):
    """The store on disk belongs to another analysis (model, settings, version or format)."""


def _canonical(obj):
    """``obj`` through a JSON round trip (tuples become lists, keys strings)."""
    return json.loads(json.dumps(obj, sort_keys=True))


def _identity(manifest: dict) -> str:
    """The store identity recorded in every chunk: sha256 of the manifest's canonical JSON."""
    text = json.dumps(manifest, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:                     # pragma: no cover - Windows cannot open directories
        return
    try:
        os.fsync(fd)
    except OSError:                     # pragma: no cover
        pass
    finally:
        os.close(fd)


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file, flushed, and a rename."""
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _q(path) -> str:
    return repr(str(path))


class ChunkStore:
    """See the module docstring.

    Opening the store takes its lock; call :meth:`close` (or use ``with``) to release it.

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
    attrs : dict, optional
        Global attributes written into every chunk file (CF conventions, model, versions:
        :func:`pwsdyn.io.cf_global_attrs`), with ``date_created`` and ``history``; not part
        of the manifest, so stores written before keep resuming.

    Raises
    ------
    StoreMismatchError
        The store holds another analysis, or the directory is not a pwsdyn store.
    pwsdyn.errors.StoreError
        The store is in use by another run, or its manifest is unreadable.
    FileExistsError
        ``path`` exists and is not a directory.
    """

    def __init__(self, path, kind: str, model_name: str, model_hash: str, settings: dict,
                 n_chunks: int, attrs: dict | None = None):
        self.path = Path(path)
        self.attrs = dict(attrs or {})
        self.manifest = _canonical({"kind": kind, "model": model_name, "model_hash": model_hash,
                                    "settings": settings, "n_chunks": int(n_chunks),
                                    "pwsdyn_version": __version__, "format": FORMAT})
        self.identity = _identity(self.manifest)
        self._lock_fd = None
        if self.path.exists() and not self.path.is_dir():
            raise FileExistsError(f"store {_q(self.path)} exists and is not a directory; "
                                  "nothing was overwritten")
        mpath = self.path / MANIFEST
        # Check before locking, so that a refused run changes nothing at all.
        if mpath.exists():
            self._check(self._read_manifest())
        elif self.path.is_dir():
            foreign = sorted(p.name for p in self.path.iterdir()
                             if p.name != LOCK and not p.name.startswith(MANIFEST + ".tmp"))
            if foreign:
                shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
                raise StoreMismatchError(
                    f"store {_q(self.path)} is a non-empty directory without {MANIFEST} "
                    f"(it holds {shown}): not a pwsdyn store, or its manifest was deleted; "
                    "choose another path (nothing was overwritten)")
        self.path.mkdir(parents=True, exist_ok=True)
        self._lock()
        try:
            if mpath.exists():          # created meanwhile by a run that has finished
                self._check(self._read_manifest())
            else:
                _write_atomic(mpath, json.dumps(self.manifest, indent=1,
                                                sort_keys=True).encode())
                _fsync_dir(self.path)
            self._clean()
        except BaseException:
            self.close()
            raise

    # ---------------------------------------------------------------------------------- lock
    def _lock(self) -> None:
        lpath = self.path / LOCK
        try:
            fd = os.open(lpath, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise StoreError(f"cannot open the lock file {_q(lpath)} of store {_q(self.path)}: "
                             f"{exc.strerror or exc}. A store must be writable (or choose "
                             "another store path).") from exc
        try:
            if fcntl is not None:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            else:                       # pragma: no cover - Windows
                os.lseek(fd, 0, os.SEEK_SET)
                msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError as exc:
            if exc.errno not in _HELD:
                os.close(fd)
                raise StoreError(f"cannot lock store {_q(self.path)} (lock file {_q(lpath)}): "
                                 f"{exc.strerror or exc}. The file system may not support "
                                 "locks; use a store on a local disk.") from exc
            holder = self._holder(lpath)
            os.close(fd)
            raise StoreError(
                f"store {_q(self.path)} is in use by another run ({holder}; lock file "
                f"{_q(lpath)}). Wait for that run to finish, or use another store path; "
                "nothing in the store was changed.") from None
        self._lock_fd, self._lock_pid = fd, os.getpid()
        try:
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
        except OSError:                 # pragma: no cover - the PID is only informative
            pass

    @staticmethod
    def _holder(lpath: Path) -> str:
        try:
            words = lpath.read_text().split()
        except (OSError, UnicodeDecodeError):
            words = []
        if not words:
            return "process ID not known yet"
        return f"process {words[0]}" + (f" on host {words[1]}" if len(words) > 1 else "")

    def close(self) -> None:
        """Release the lock (idempotent)."""
        fd, self._lock_fd = self._lock_fd, None
        if fd is None:
            return
        if self._lock_pid != os.getpid():     # a forked copy: the lock is the parent's
            os.close(fd)
            return
        try:
            os.ftruncate(fd, 0)
        except OSError:                 # pragma: no cover
            pass
        try:
            if fcntl is not None:
                fcntl.flock(fd, fcntl.LOCK_UN)
            else:                       # pragma: no cover - Windows
                os.lseek(fd, 0, os.SEEK_SET)
                msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)
        finally:
            os.close(fd)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:               # pragma: no cover
            pass

    def _clean(self) -> None:
        """Remove what a killed run left (only called while holding the lock): temporary
        files, and checksum files whose chunk was never renamed into place."""
        for stale in self.path.glob("*.tmp*"):
            try:
                stale.unlink()
            except OSError:
                pass
        for side in self.path.glob("chunk-*.sha256"):
            if not side.with_suffix(".nc").exists():
                try:
                    side.unlink()
                except OSError:
                    pass

    # ------------------------------------------------------------------------------ manifest
    def _read_manifest(self) -> dict:
        mpath = self.path / MANIFEST
        advice = ("Nothing was changed. If the chunks are worth keeping, restore the manifest "
                  "from a copy; otherwise delete the store or choose another store path.")
        try:
            text = mpath.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise StoreError(f"cannot read the manifest {_q(mpath)} of store {_q(self.path)}: "
                             f"{exc}. {advice}") from exc
        if not text.strip():
            raise StoreError(f"the manifest {_q(mpath)} is empty (truncated). {advice}")
        try:
            old = json.loads(text)
        except ValueError as exc:
            raise StoreError(f"the manifest {_q(mpath)} is not valid JSON (truncated or "
                             f"corrupted: {exc}). {advice}") from None
        if not isinstance(old, dict):
            raise StoreError(f"the manifest {_q(mpath)} is not a pwsdyn store manifest: it "
                             f"holds a JSON {type(old).__name__}, not an object. {advice}")
        missing = [k for k in ("kind", "model_hash", "settings", "n_chunks", "pwsdyn_version",
                               "format") if k not in old]
        if missing or not isinstance(old.get("settings"), dict):
            what = (f"lacks {', '.join(missing)}" if missing
                    else "has `settings` that are not a JSON object")
            raise StoreError(f"the manifest {_q(mpath)} is not a pwsdyn store manifest: it "
                             f"{what}. {advice}")
        return old

    def _check(self, old: dict) -> None:
        new = self.manifest
        why = []
        for key, label in (("kind", "analysis"), ("model_hash", "model"),
                           ("pwsdyn_version", "pwsdyn version"), ("format", "store format"),
                           ("n_chunks", "chunking")):
            if old.get(key) != new.get(key):
                extra = (f" ({old.get('model')!r} vs {new.get('model')!r})"
                         if key == "model_hash" else "")
                why.append(f"{label}: stored {old.get(key)!r}, requested {new.get(key)!r}{extra}")
        so, sn = old.get("settings", {}), new.get("settings", {})
        short = lambda s: s if len(s) <= 60 else s[:57] + "..."  # noqa: E731
        for k in sorted(set(so) | set(sn)):
            if so.get(k) != sn.get(k):
                a, b = json.dumps(so.get(k)), json.dumps(sn.get(k))
                why.append(f"setting `{k}`: stored {short(a)}, requested {short(b)}")
        for k in sorted((set(old) | set(new)) - {"kind", "model_hash", "pwsdyn_version",
                                                 "format", "n_chunks", "settings"}):
            if old.get(k) != new.get(k):
                a, b = json.dumps(old.get(k)), json.dumps(new.get(k))
                why.append(f"`{k}`: stored {short(a)}, requested {short(b)}")
        if why:
            raise StoreMismatchError(
                f"refusing to resume into store {_q(self.path)}: it holds results of a "
                f"different run ({'; '.join(why)}). Use another store path or delete this one; "
                "nothing was overwritten.")

    # -------------------------------------------------------------------------------- chunks
    def chunk_path(self, i: int) -> Path:
        return self.path / f"chunk-{i:05d}.nc"

    def checksum_path(self, i: int) -> Path:
        return self.path / f"chunk-{i:05d}.sha256"

    def done(self) -> list[int]:
        """Indices of the chunks already stored (a ``chunk-NNNNN.nc`` file exists; it is
        checked when read)."""
        out = []
        for f in self.path.glob("chunk-*.nc"):
            try:
                out.append(int(f.stem.split("-")[1]))
            except (IndexError, ValueError):
                continue
        return sorted(i for i in out if 0 <= i < self.manifest["n_chunks"])

    def write(self, i: int, ds: xr.Dataset) -> None:
        """Store chunk ``i`` with its checksum (crash-safe, see the module docstring; an
        existing chunk file is never replaced)."""
        if self._lock_fd is None:
            raise StoreError(f"store {_q(self.path)} is closed; cannot write chunk {i}")
        path, side = self.chunk_path(i), self.checksum_path(i)
        if path.exists():
            return
        from .._netcdf import stamp

        ds = ds.copy()
        ds.attrs = {**self.attrs, **ds.attrs}
        ds = stamp(ds)
        ds.attrs.update(pwsdyn_chunk=int(i), pwsdyn_store=self.identity)
        tmp = path.with_name(path.name + f".tmp{os.getpid()}")
        ds.to_netcdf(tmp, engine="h5netcdf")
        with open(tmp, "rb+") as f:
            data = f.read()
            os.fsync(f.fileno())
        digest = hashlib.sha256(data).hexdigest()
        _write_atomic(side, f"{digest}  {path.name}\n".encode())
        os.replace(tmp, path)
        _fsync_dir(self.path)

    def read(self, i: int) -> xr.Dataset:
        """Chunk ``i``, checked against its checksum, chunk index and store identity."""
        path, side = self.chunk_path(i), self.checksum_path(i)
        fix = (f"Delete {_q(path)} and {_q(side)} to have chunk {i} recomputed on the next run, "
               "or use another store path; nothing in the store was changed.")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise StoreError(f"cannot read chunk file {_q(path)}: {exc.strerror or exc}. "
                             f"{fix}") from exc
        try:
            text = side.read_text(encoding="ascii")
        except FileNotFoundError:
            raise StoreError(f"chunk file {_q(path)} has no checksum file {_q(side)} (deleted, "
                             "or the chunk was not written by this store). " + fix) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise StoreError(f"cannot read the checksum file {_q(side)}: {exc}. {fix}") from None
        # exactly what write() put there: a flipped bit anywhere in it (the separator and the
        # newline included, which a whitespace split would forgive) is a corrupted file
        words = text[:-1].split("  ") if text.endswith("\n") else []
        if (len(words) != 2 or words[1] != path.name or len(words[0]) != 64
                or any(c not in "0123456789abcdef" for c in words[0])):
            raise StoreError(f"the checksum file {_q(side)} is corrupted (expected "
                             f"'<sha256>  {path.name}'). {fix}")
        if hashlib.sha256(data).hexdigest() != words[0]:
            raise StoreError(f"chunk file {_q(path)} does not match its checksum in {_q(side)}: "
                             "it was corrupted, truncated, or replaced by another file. " + fix)
        try:
            with xr.open_dataset(io.BytesIO(data), engine="h5netcdf", decode_times=False,
                                 decode_timedelta=False) as ds:
                ds = ds.load()
        except Exception as exc:
            raise StoreError(f"chunk file {_q(path)} cannot be read as NetCDF ({exc}). "
                             f"{fix}") from None
        got_i, got_id = ds.attrs.get("pwsdyn_chunk"), ds.attrs.get("pwsdyn_store")
        if got_id != self.identity:
            raise StoreError(f"chunk file {_q(path)} (with its checksum file) belongs to another "
                             "store or analysis (its store identity "
                             f"{str(got_id)[:12]!r}... is not this store's "
                             f"{self.identity[:12]!r}...): copied in from elsewhere? " + fix)
        try:
            got_i = int(got_i)
        except (TypeError, ValueError):
            pass
        if got_i != i:
            raise StoreError(f"chunk file {_q(path)} holds chunk {got_i!r}, not chunk {i}: chunk "
                             "files were swapped, renamed or copied over each other. " + fix)
        return ds
