"""Resumable stores (src/pwsdyn/explore/_store.py): the lock, the checksums, the chunk identity
and the errors on damaged stores.

Each test here is the regression test of a defect found by fuzzing:

1. no lock: a second run deleted the first run's half-written chunk and killed it;
2. chunk files swapped or copied over each other were read as the chunk named by the file;
3. flipped bytes were read as data (no checksums);
4. a truncated chunk or manifest gave an error that did not name the file; a manifest holding
   a JSON list gave a traceback;
5. two concurrent runs on one store could lose or corrupt data.

A damaged store must make the resumed run raise ``StoreError`` (or ``StoreMismatchError``)
naming the file, change nothing on disk, and never return wrong values. The runs are tiny maps
(a fraction of a second each); the subprocess tests pay a Python start-up each.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pwsdyn
from pwsdyn.errors import PwsdynError, StoreError
from pwsdyn.explore import StoreMismatchError
from pwsdyn.explore._store import FORMAT, ChunkStore

VALUES = np.linspace(0.01, 0.05, 8).tolist()
KW = dict(params={"lam": 0.1}, transient=50, samples=8, chunk_size=2, direction="up",
          workers=1, progress=False)                        # 4 chunks
N_CHUNKS = 4
BASIN_GRID = {"x": np.linspace(-0.5, 0.5, 9).tolist()}
BASIN_KW = dict(params={"mu": 0.1, "lam": 0.1}, transient=50, samples=8, chunk_size=3,
                workers=1, progress=False)


def _sweep(store=None, **kw):
    return pwsdyn.sweep("sqrt-map", "mu", VALUES, [0.0], store=store, **{**KW, **kw})


def _basins(store=None):
    return pwsdyn.basins("sqrt-map", BASIN_GRID, store=store, **BASIN_KW)


def _snapshot(store: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(store.iterdir())}


def _reseal(store: Path, i: int) -> None:
    """Write chunk ``i``'s checksum file to match whatever its chunk file now holds (a
    tamperer who knows the checksum format)."""
    nc = store / f"chunk-{i:05d}.nc"
    digest = hashlib.sha256(nc.read_bytes()).hexdigest()
    (store / f"chunk-{i:05d}.sha256").write_text(f"{digest}  {nc.name}\n")


@pytest.fixture(scope="module")
def reference():
    """The sweep without a store."""
    return _sweep()


@pytest.fixture(scope="module")
def finished(tmp_path_factory, reference):
    """A finished store of the sweep (copy it before damaging it)."""
    store = tmp_path_factory.mktemp("finished") / "store"
    xr.testing.assert_identical(_sweep(store), reference)
    assert sorted(p.name for p in store.glob("chunk-*")) == sorted(
        f"chunk-{i:05d}.{ext}" for i in range(N_CHUNKS) for ext in ("nc", "sha256"))
    return store


@pytest.fixture
def store(finished, tmp_path):
    dst = tmp_path / "store"
    shutil.copytree(finished, dst)
    return dst


def _refused(store: Path, name: str, match: str, *, error=StoreError, run=_sweep):
    """Resuming into ``store`` raises ``error`` naming the file ``name`` (and matching
    ``match``), changes nothing on disk, and releases the lock (a second try says the same)."""
    before = _snapshot(store)
    for _ in range(2):
        with pytest.raises(error) as info:
            run(store)
        msg = str(info.value)
        assert str(store / name) in msg, msg
        assert re.search(match, msg), msg
        assert "in use by another run" not in msg
    assert _snapshot(store) == before
    return msg


# ======================================================================================
# exceptions
# ======================================================================================

def test_store_exceptions_are_pwsdyn_errors():
    assert issubclass(StoreError, PwsdynError) and issubclass(StoreError, OSError)
    assert issubclass(StoreMismatchError, PwsdynError)
    assert issubclass(StoreMismatchError, ValueError)      # as before
    assert pwsdyn.StoreError is StoreError


def test_resume_from_finished_store_reads_every_chunk(finished, reference, tmp_path):
    """The store round trip is exact, for sweeps and basins, and leaves no temporary files;
    the lock file stays (empty: no holder) and every chunk has its checksum."""
    xr.testing.assert_identical(_sweep(finished), reference)
    bstore = tmp_path / "b"
    a = _basins(bstore)
    xr.testing.assert_identical(_basins(bstore), a)
    xr.testing.assert_identical(_basins(), a)
    for s in (finished, bstore):
        assert not list(s.glob("*.tmp*"))
        assert (s / "lock").read_bytes() == b""
        for nc in s.glob("chunk-*.nc"):
            side = nc.with_suffix(".sha256")
            assert side.read_text() == f"{hashlib.sha256(nc.read_bytes()).hexdigest()}  " \
                                       f"{nc.name}\n"


# ======================================================================================
# 1. the lock
# ======================================================================================

def _open(path, n_chunks=N_CHUNKS):
    return ChunkStore(path, "sweep", "m", "h", {"a": 1}, n_chunks)


def test_lock_refuses_a_second_opener_and_keeps_its_files(tmp_path):
    """While a store is open, opening it again is refused with StoreError naming the store
    and the PID holding it, and the holder's half-written chunk is not deleted. Stale
    temporary files are removed only by the next run that gets the lock."""
    path = tmp_path / "s"
    first = _open(path)
    assert (path / "lock").read_text().split()[0] == str(os.getpid())
    half = path / "chunk-00001.nc.tmp99999"            # the holder's chunk being written
    half.write_bytes(b"half a chunk")
    before = _snapshot(path)
    with pytest.raises(StoreError, match=re.escape(str(path))) as info:
        _open(path)
    assert f"process {os.getpid()}" in str(info.value)
    assert "in use by another run" in str(info.value)
    assert _snapshot(path) == before                   # nothing deleted or changed
    first.close()
    assert (path / "lock").read_bytes() == b""
    with _open(path) as second:                        # free again: the stale file goes
        assert not half.exists()
        assert second.done() == []
    with _open(path):                                  # `with` released it
        pass


@pytest.mark.skipif(sys.platform == "win32", reason="fcntl")
def test_sweep_and_basins_on_a_locked_store_are_refused(store, tmp_path):
    """A store locked by someone else (the lock taken here through another file description,
    as another process would): sweeps and basins are refused before any work, naming the
    store and the holder, and change nothing."""
    import fcntl

    bstore = tmp_path / "b"
    _basins(bstore)
    for path, run in ((store, _sweep), (bstore, _basins)):
        fd = os.open(path / "lock", os.O_RDWR)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.write(fd, b"4242 elsewhere\n")
            before = _snapshot(path)
            with pytest.raises(StoreError) as info:
                run(path)
            msg = str(info.value)
            assert str(path) in msg and "process 4242 on host elsewhere" in msg, msg
            assert _snapshot(path) == before
        finally:
            os.close(fd)
        (path / "lock").write_bytes(b"")
        run(path)                                      # free again


def test_lock_is_released_when_a_run_fails(finished, tmp_path):
    """A run that raises (here: a chunk fails its check) releases the lock."""
    path = tmp_path / "s"
    shutil.copytree(finished, path)
    (path / "chunk-00002.nc").write_bytes(b"")
    with pytest.raises(StoreError, match="chunk-00002.nc"):
        _sweep(path)
    (path / "chunk-00002.nc").unlink()
    (path / "chunk-00002.sha256").unlink()
    # recomputed and stored (it was deleted by the user, as the message says to do)
    xr.testing.assert_identical(_sweep(path), _sweep())
    assert (path / "chunk-00002.nc").exists()


# Runs the sweep in a subprocess and stops it just before the rename onto argv[2] (a file
# name in the store): it creates argv[3] and waits there until argv[4] exists -- or forever
# when argv[4] is "-" (it is then killed). The dataset is pickled into argv[5].
_SCRIPT = textwrap.dedent("""
    import os, pickle, sys, time
    from pathlib import Path
    import pwsdyn

    def main():
        store, pause_at, marker, go, result = sys.argv[1:6]
        real_replace = os.replace
        def replace(src, dst):
            if Path(dst).name == pause_at:
                Path(marker).touch()
                while go == "-" or not Path(go).exists():
                    time.sleep(0.01)
            return real_replace(src, dst)
        os.replace = replace
        ds = pwsdyn.sweep("sqrt-map", "mu", {values!r}, [0.0], store=store, **{kw!r})
        with open(result, "wb") as f:
            pickle.dump(ds, f)

    if __name__ == "__main__":
        main()
""")


def _start(tmp_path: Path, pause_at: str, go: str):
    script = tmp_path / "run.py"
    script.write_text(_SCRIPT.format(values=VALUES, kw=KW))
    store, marker, result = tmp_path / "store", tmp_path / "paused", tmp_path / "result.pkl"
    proc = subprocess.Popen([sys.executable, str(script), str(store), pause_at, str(marker),
                             go, str(result)])
    try:
        while not marker.exists():
            assert proc.poll() is None, f"the run ended (rc {proc.returncode}) before pausing"
            time.sleep(0.01)
    except BaseException:
        proc.kill()
        raise
    return proc, store, result


def test_concurrent_run_is_refused_and_the_first_completes(tmp_path, reference):
    """Regression test of defects 1 and 5 with two processes. The first run is held with a
    chunk half-written (its temporary file and checksum on disk, not yet renamed) while a
    second run on the same store starts: the second is refused with StoreError naming the
    store and the first run's PID and deletes nothing; the first then completes with exactly
    the right dataset, and so does a later resume."""
    go = tmp_path / "go"
    proc, store, result = _start(tmp_path, "chunk-00001.nc", str(go))
    try:
        assert (store / "lock").read_text().split()[0] == str(proc.pid)
        tmps = list(store.glob("chunk-00001.nc.tmp*"))
        assert len(tmps) == 1
        before = _snapshot(store)
        with pytest.raises(StoreError) as info:
            _sweep(store)
        msg = str(info.value)
        assert str(store) in msg and f"process {proc.pid}" in msg, msg
        assert _snapshot(store) == before                  # nothing deleted or written
        go.touch()
        assert proc.wait() == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    with open(result, "rb") as f:
        xr.testing.assert_identical(pickle.load(f), reference)
    xr.testing.assert_identical(_sweep(store), reference)
    assert not list(store.glob("*.tmp*"))


@pytest.mark.parametrize("pause_at, left", [
    ("manifest.json", {"manifest.json.tmp*"}),
    ("chunk-00001.sha256", {"chunk-00001.nc.tmp*", "chunk-00001.sha256.tmp*"}),
    ("chunk-00001.nc", {"chunk-00001.nc.tmp*", "chunk-00001.sha256"}),
])
def test_killed_at_each_write_step_resumes_exactly(tmp_path, reference, pause_at, left):
    """A run SIGKILLed at each step of writing a chunk (and while creating the store) leaves a
    store that the next run resumes from, giving exactly the uninterrupted dataset; the chunk
    finished before the kill is not rewritten, and the leftovers are removed."""
    proc, store, _ = _start(tmp_path, pause_at, "-")
    proc.send_signal(signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL
    for pattern in left:
        assert list(store.glob(pattern)), (pattern, sorted(p.name for p in store.iterdir()))
    done = sorted(store.glob("chunk-*.nc"))
    assert [p.name for p in done] == ([] if pause_at == "manifest.json" else ["chunk-00000.nc"])
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    xr.testing.assert_identical(_sweep(store), reference)
    assert {p.name: p.stat().st_mtime_ns for p in done} == stamps
    assert not list(store.glob("*.tmp*"))
    assert len(list(store.glob("chunk-*.nc"))) == len(list(store.glob("chunk-*.sha256"))) \
        == N_CHUNKS


_KILL_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import pwsdyn

    pwsdyn.sweep("impact-oscillator", "omega", np.linspace(2.3, 3.1, 24), [-0.5, 0.0],
                 transient=300, samples=50, chunk_size=2, warmup=1, direction="up",
                 workers=1, progress=False, store=sys.argv[1])
""")


@pytest.mark.slow
def test_killed_at_random_moments_resumes_exactly(tmp_path):
    """SIGKILL at random moments after the first chunk file appears (kill, resume, kill
    again ...): each resumed store gives the dataset of an uninterrupted run."""
    kw = dict(transient=300, samples=50, chunk_size=2, warmup=1, direction="up", workers=1,
              progress=False)
    values = np.linspace(2.3, 3.1, 24)
    full = pwsdyn.sweep("impact-oscillator", "omega", values, [-0.5, 0.0], **kw)
    script = tmp_path / "run.py"
    script.write_text(_KILL_SCRIPT)
    rng = random.Random(1)
    killed = 0
    for trial in range(6):
        store = tmp_path / f"store{trial}"
        for _ in range(2):                     # kill the first run, and the resumed one
            n0 = len(list(store.glob("chunk-*.nc")))
            proc = subprocess.Popen([sys.executable, str(script), str(store)])
            try:
                while proc.poll() is None and len(list(store.glob("chunk-*.nc"))) <= n0:
                    time.sleep(0.002)
                time.sleep(rng.uniform(0.0, 0.05))
                proc.send_signal(signal.SIGKILL)
                killed += proc.wait() == -signal.SIGKILL
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
        resumed = pwsdyn.sweep("impact-oscillator", "omega", values, [-0.5, 0.0],
                               store=store, **kw)
        xr.testing.assert_identical(resumed, full)
        assert not list(store.glob("*.tmp*"))
    assert killed >= 6, "the runs ended before they could be killed"


# ======================================================================================
# 2. swapped, copied and foreign chunk files
# ======================================================================================

def test_swapped_chunk_files_are_refused(store):
    a, b = store / "chunk-00001.nc", store / "chunk-00002.nc"
    da, db = a.read_bytes(), b.read_bytes()
    a.write_bytes(db)
    b.write_bytes(da)
    _refused(store, "chunk-00001.nc", "does not match its checksum")


def test_swapped_chunk_files_with_their_checksums_are_refused(store):
    """Swapped together with valid checksums: the chunk index recorded in the file tells."""
    a, b = store / "chunk-00001.nc", store / "chunk-00002.nc"
    da, db = a.read_bytes(), b.read_bytes()
    a.write_bytes(db)
    b.write_bytes(da)
    _reseal(store, 1)
    _reseal(store, 2)
    _refused(store, "chunk-00001.nc", "holds chunk 2, not chunk 1")


def test_chunk_copied_over_another_is_refused(store):
    shutil.copyfile(store / "chunk-00000.nc", store / "chunk-00003.nc")
    _refused(store, "chunk-00003.nc", "does not match its checksum")
    shutil.copyfile(store / "chunk-00000.sha256", store / "chunk-00003.sha256")
    _refused(store, "chunk-00003.sha256", "checksum file .* is corrupted")
    _reseal(store, 3)
    _refused(store, "chunk-00003.nc", "holds chunk 0, not chunk 3")


def test_chunk_of_another_analysis_is_refused(store, tmp_path):
    """A chunk (with its checksum) from the store of another analysis with the same chunking
    is refused: the store identity recorded in it differs."""
    other = tmp_path / "other"
    _sweep(other, samples=9)
    for ext in ("nc", "sha256"):
        shutil.copyfile(other / f"chunk-00002.{ext}", store / f"chunk-00002.{ext}")
    _refused(store, "chunk-00002.nc", "belongs to another store or analysis")


def test_basins_store_checks_chunks_too(tmp_path):
    path = tmp_path / "b"
    _basins(path)
    a, b = path / "chunk-00000.nc", path / "chunk-00001.nc"
    da, db = a.read_bytes(), b.read_bytes()
    a.write_bytes(db)
    b.write_bytes(da)
    _reseal(path, 0)
    _reseal(path, 1)
    _refused(path, "chunk-00000.nc", "holds chunk 1, not chunk 0", run=_basins)


# ======================================================================================
# 3. flipped bits
# ======================================================================================

@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(which=st.integers(0, N_CHUNKS - 1), ext=st.sampled_from(["nc", "nc", "nc", "sha256"]),
       where=st.floats(0.0, 1.0, exclude_max=True))
def test_a_flipped_bit_in_a_chunk_is_refused(finished, which, ext, where):
    """One bit flipped anywhere in a chunk file or in its checksum file: refused, naming a
    file of that chunk."""
    with tempfile.TemporaryDirectory() as tmp:
        store = Path(tmp) / "store"
        shutil.copytree(finished, store)
        f = store / f"chunk-{which:05d}.{ext}"
        data = bytearray(f.read_bytes())
        bit = int(where * len(data) * 8)
        data[bit // 8] ^= 1 << (bit % 8)
        f.write_bytes(bytes(data))
        before = _snapshot(store)
        with pytest.raises(StoreError) as info:
            _sweep(store)
        assert str(store / f"chunk-{which:05d}.") in str(info.value)
        assert _snapshot(store) == before


# ======================================================================================
# 4. truncated or damaged chunks, checksums and manifests
# ======================================================================================

@pytest.mark.parametrize("keep", [0, 1, 100, 0.5, -1])
def test_truncated_chunk_is_refused(store, keep):
    f = store / "chunk-00002.nc"
    data = f.read_bytes()
    f.write_bytes(data[:int(keep * len(data)) if isinstance(keep, float) else keep])
    msg = _refused(store, "chunk-00002.nc", "does not match its checksum")
    assert "Delete" in msg and "recomputed" in msg


def test_unreadable_chunk_with_a_matching_checksum_is_refused(store):
    f = store / "chunk-00002.nc"
    f.write_bytes(f.read_bytes()[:1000])
    _reseal(store, 2)
    _refused(store, "chunk-00002.nc", "cannot be read as NetCDF")


def test_missing_or_damaged_checksum_file_is_refused(store):
    side = store / "chunk-00001.sha256"
    text = side.read_text()
    side.unlink()
    _refused(store, "chunk-00001.sha256", "has no checksum file")
    for bad in ("", "garbage", text.replace("00001", "00002"), "0" * 64 + "  chunk-00001.nc"):
        side.write_text(bad)
        _refused(store, "chunk-00001", "checksum")


@pytest.mark.parametrize("content, match", [
    (b"", "is empty"),
    (b"[1, 2, 3]", "holds a JSON list, not an object"),
    (b"\x00\xff garbage \x89", "cannot read the manifest|not valid JSON"),
    (b"{\"kind\": \"sweep\", ", "not valid JSON"),
    (b"\"sweep\"", "holds a JSON str"),
    (b"{}", "lacks kind"),
    (b"{\"kind\": \"sweep\", \"model_hash\": 1, \"settings\": [], \"n_chunks\": 4, "
     b"\"pwsdyn_version\": 1, \"format\": 2}", "settings"),
])
def test_damaged_manifest_is_refused(store, content, match):
    (store / "manifest.json").write_bytes(content)
    msg = _refused(store, "manifest.json", match)
    assert "another store path" in msg


def test_truncated_manifest_is_refused(store):
    m = store / "manifest.json"
    text = m.read_bytes()
    for n in (1, len(text) // 2, len(text) - 2):
        m.write_bytes(text[:n])
        _refused(store, "manifest.json", "not valid JSON")


def test_store_of_the_old_format_is_refused(store):
    """A store written before checksums (format 1) is refused as another run's: its chunks
    cannot be checked."""
    m = store / "manifest.json"
    man = json.loads(m.read_text())
    man["format"] = 1
    m.write_text(json.dumps(man))
    _refused(store, "", f"store format: stored 1, requested {FORMAT}", error=StoreMismatchError)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(where=st.floats(0.0, 1.0, exclude_max=True))
def test_a_flipped_bit_in_the_manifest_never_gives_wrong_values(finished, reference, where):
    """A bit flipped in the manifest is refused (StoreError naming it, or StoreMismatchError
    naming what differs) -- unless the manifest still means the same (say ``1e-09`` became
    ``1E-09``), and then the values are right."""
    with tempfile.TemporaryDirectory() as tmp:
        store = Path(tmp) / "store"
        shutil.copytree(finished, store)
        m = store / "manifest.json"
        data = bytearray(m.read_bytes())
        bit = int(where * len(data) * 8)
        data[bit // 8] ^= 1 << (bit % 8)
        m.write_bytes(bytes(data))
        before = _snapshot(store)
        try:
            ds = _sweep(store)
        except StoreError as exc:
            assert str(m) in str(exc)
        except StoreMismatchError as exc:
            assert "refusing to resume" in str(exc)
        else:
            xr.testing.assert_identical(ds, reference)
        assert _snapshot(store) == before


def test_directory_that_is_not_a_store_is_refused(tmp_path):
    """A directory with chunk files but no manifest is not taken over."""
    d = tmp_path / "d"
    d.mkdir()
    (d / "chunk-00000.nc").write_bytes(b"x")
    with pytest.raises(StoreMismatchError, match="not a pwsdyn store"):
        _sweep(d)
    assert sorted(p.name for p in d.iterdir()) == ["chunk-00000.nc"]    # no lock file made


@pytest.mark.parametrize("pos", [-1, 64, 65])   # the newline and the two separating spaces
@pytest.mark.parametrize("bit", [0, 3, 7])
def test_a_flipped_bit_in_the_checksum_separator_or_newline_is_refused(finished, pos, bit):
    """A whitespace split of the checksum file forgave a newline turned into a vertical tab
    (found by the flipped-bit property): the file must be exactly '<sha256>  <name>\\n'."""
    with tempfile.TemporaryDirectory() as tmp:
        store = Path(tmp) / "store"
        shutil.copytree(finished, store)
        f = store / "chunk-00000.sha256"
        data = bytearray(f.read_bytes())
        data[pos] ^= 1 << bit
        f.write_bytes(bytes(data))
        with pytest.raises(StoreError, match="chunk-00000"):
            _sweep(store)
