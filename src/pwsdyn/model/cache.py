"""The on-disk cache of generated model modules, and how a module is loaded from it safely.

Generated modules are Python source that numba compiles; numba keeps the machine code next to
them (``__pycache__``, whose index files are pickles). Whoever can write into the cache can
therefore run code as whoever loads from it, so the cache is treated as a trust boundary:

- The directory is private to the user: created with mode 0700, and refused when it (or its
  ``__pycache__``) is owned by someone else or writable by group or others. A refused or
  unwritable cache is replaced, for this process, by a private temporary directory (removed at
  exit) with one warning: the model then compiles again in every new process, nothing is
  loaded from a place another user controls.
- A module is named by the full SHA-256 of its model and carries, on its first line, that hash
  and the SHA-256 of the rest of its text. Before import the file must be a regular file owned
  by the user and not writable by others, with the expected first line and a matching body
  hash; otherwise it is regenerated (written to a temporary file created exclusively, then
  renamed into place).
- A module that fails to import or compile is removed with its numba cache entries and
  dropped from ``sys.modules``, so a later attempt regenerates it instead of finding half a
  module.

No user text ever reaches a generated module: the generators emit only validated identifiers
and numbers, and :func:`write_module` refuses source that is not ASCII or whose first lines are
not the expected header (a ``coding:`` declaration there would change how Python decodes the
file).
"""

from __future__ import annotations

import atexit
import hashlib
import importlib.util
import os
import re
import shutil
import stat
import sys
import tempfile
import threading
import warnings
from pathlib import Path

from ..errors import ModelError

#: What CPython looks for on the first two lines of a source file (PEP 263)
_CODING = re.compile(r"coding[:=]")
_LOCK = threading.Lock()
_LOAD_LOCK = threading.RLock()
_FALLBACK: Path | None = None
_WARNED: set = set()


class CacheWarning(UserWarning):
    """The model cache could not be used; models are compiled in a private temporary
    directory for this process instead."""


def _configured_dir() -> Path:
    env = os.environ.get("PWSDYN_CACHE_DIR")
    if env:
        base = Path(env)
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or (Path.home() / ".cache")) / "pwsdyn"
    return base / "models"


def _private_problem(path: Path) -> str | None:
    """Why ``path`` (an existing directory) is not private to this user, or ``None``."""
    try:
        st = os.lstat(path)
    except OSError as exc:
        return f"cannot inspect it ({exc.strerror})"
    if stat.S_ISLNK(st.st_mode):
        return "it is a symbolic link"
    if not stat.S_ISDIR(st.st_mode):
        return "it is not a directory"
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        return f"it is owned by user id {st.st_uid}, not by you ({os.getuid()})"
    if os.name == "posix" and st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"it is writable by group or others (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def _prepare(path: Path) -> str | None:
    """Create ``path`` (mode 0700) if needed and check that it and its ``__pycache__`` are
    private and writable; the reason it cannot be used, or ``None``."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists():
            path.mkdir(mode=0o700)
    except OSError as exc:
        return f"cannot create it ({exc.strerror or exc})"
    why = _private_problem(path)
    if why:
        return why
    pycache = path / "__pycache__"
    if os.path.lexists(pycache):
        why = _private_problem(pycache)
        if why:
            return f"its __pycache__ is not private: {why}"
    if not os.access(path, os.W_OK | os.X_OK):
        return "it is not writable"
    return None


def _fallback_dir() -> Path:
    global _FALLBACK
    if _FALLBACK is None:
        _FALLBACK = Path(tempfile.mkdtemp(prefix="pwsdyn-models-"))  # mode 0700
        atexit.register(shutil.rmtree, _FALLBACK, ignore_errors=True)
    return _FALLBACK


def cache_dir() -> Path:
    """Directory of generated model modules and their numba caches.

    ``$PWSDYN_CACHE_DIR/models`` if that variable is set, else ``$XDG_CACHE_HOME/pwsdyn/models``
    or ``~/.cache/pwsdyn/models``. When that directory cannot be created or is not private to
    the user (see the module docstring), a private temporary directory for this process is
    used instead, with a :class:`CacheWarning` saying why.
    """
    path = _configured_dir()
    with _LOCK:
        why = _prepare(path)
        if why is None:
            return path
        if str(path) not in _WARNED:
            _WARNED.add(str(path))
            warnings.warn(f"pwsdyn does not use the model cache {str(path)!r}: {why}. Models are "
                          "compiled in a private temporary directory for this process instead "
                          "(set PWSDYN_CACHE_DIR to a directory only you can write).",
                          CacheWarning, stacklevel=3)
        return _fallback_dir()


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("ascii")).hexdigest()


_TAIL = "(generated; do not edit)"


def _header_prefix(kind: str, version: str, model_digest: str) -> str:
    return f"# pwsdyn {kind} codegen v{version} model-sha256 {model_digest}"


def header(kind: str, version: str, model_digest: str, body: str) -> str:
    """First line of a generated module: only fixed words, the codegen version and hex
    digests (nothing a model file chose)."""
    return f"{_header_prefix(kind, version, model_digest)} body-sha256 {_sha256(body)} {_TAIL}"


def _file_problem(path: Path, expected_prefix: str) -> str | None:
    """Why the module file at ``path`` must not be imported, or ``None``.

    ``expected_prefix`` is the header up to the body digest (kind, version, model digest)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return "missing"
    if not stat.S_ISREG(st.st_mode):
        return "not a regular file"
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        return "owned by another user"
    if os.name == "posix" and st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return "writable by others"
    try:
        text = path.read_bytes().decode("ascii")
    except OSError as exc:
        return f"unreadable ({exc.strerror})"
    except UnicodeDecodeError:
        return "not ASCII"
    first, _, body = text.partition("\n")
    if first != f"{expected_prefix} body-sha256 {_sha256(body)} {_TAIL}":
        return "its header does not match this model or its own text"
    return None


def write_module(path: Path, first_line: str, body: str) -> None:
    """Write ``first_line`` and ``body`` to ``path`` atomically (an exclusive temporary file,
    mode 0600, renamed into place)."""
    text = first_line + "\n" + body
    second_line = body.partition("\n")[0]
    # a generator bug if this fails: Python honours an encoding declaration on line 1 or 2
    if (not text.isascii() or "\r" in text or "\f" in text or "\0" in text
            or _CODING.search(first_line) or _CODING.search(second_line)):
        raise AssertionError("generated source must be plain ASCII with no encoding declaration")
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _discard(path: Path, modname: str) -> None:
    """Forget a module that failed: its file, numba's cache entries for it, ``sys.modules``."""
    sys.modules.pop(modname, None)
    for f in [path, *(path.parent / "__pycache__").glob(f"{path.stem}.*")]:
        try:
            f.unlink()
        except OSError:
            pass


def load_module(kind: str, version: str, model_digest: str, generate, *, model_name: str,
                attribute: str, warm_up):
    """Import (generating it first if needed) the module of a model and return its compiled
    ``attribute`` and the module's path, after ``warm_up(function)`` forced numba to compile
    or load it.

    ``generate()`` returns the module's text after the header (called only when the module
    must be written); ``model_digest`` is the model's full SHA-256. A failure to import or
    compile removes the module and raises :class:`~pwsdyn.ModelError`. One thread at a time: a
    module is in ``sys.modules`` before its code has run, so a second thread must not find it there
    half made (sweeps run their chunks on threads).
    """
    with _LOAD_LOCK:
        return _load_module(kind, version, model_digest, generate, model_name=model_name,
                            attribute=attribute, warm_up=warm_up)


def _load_module(kind: str, version: str, model_digest: str, generate, *, model_name: str,
                 attribute: str, warm_up):
    prefix_line = _header_prefix(kind, version, model_digest)
    directory = cache_dir()
    prefix = "m" if kind == "model" else kind
    path = directory / f"{prefix}_{model_digest}_v{version}.py"
    modname = f"pwsdyn_models.{path.stem}"
    module = sys.modules.get(modname)
    if module is None or getattr(module, "__file__", None) != str(path):
        why = _file_problem(path, prefix_line)
        if why is not None:
            if why != "missing":
                _discard(path, modname)
            body = generate()
            write_module(path, header(kind, version, model_digest, body), body)
            why = _file_problem(path, prefix_line)
            if why is not None:  # written by us a moment ago: the directory is not ours
                raise ModelError(f"the generated module {str(path)!r} for model "
                                 f"{model_name!r} cannot be trusted after writing it: {why}")
        spec = importlib.util.spec_from_file_location(modname, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[modname] = module
        try:
            # numba compiles (or loads from its cache) here: the signature is explicit
            spec.loader.exec_module(module)
        except Exception as exc:
            _discard(path, modname)
            raise _compile_error(model_name, exc) from None
        except BaseException:
            _discard(path, modname)
            raise
    fn = getattr(module, attribute)
    try:
        warm_up(fn)
    except Exception as exc:
        _discard(path, modname)
        raise _compile_error(model_name, exc) from None
    return fn, path


def _compile_error(model_name: str, exc: Exception) -> ModelError:
    if isinstance(exc, RecursionError):
        return ModelError(f"model {model_name!r} is too deeply nested to compile; simplify its "
                          "expressions (or split them into definitions)")
    # numba's messages carry terminal colour codes and the generated file's path
    msg = re.sub(r"\x1b\[[0-9;]*m", "", str(exc)).strip().splitlines()
    return ModelError(f"model {model_name!r} could not be compiled ({type(exc).__name__}: "
                      f"{msg[0][:300] if msg else ''}). This is a bug in pwsdyn's code "
                      "generation: please report it with the model")
