"""Running chunks of work in-process, on threads or on Dask, streaming each result as it
finishes.

Where the chunks run is chosen by ``scheduler`` (the words Dask uses for the same choice) and
``workers``:

* ``None`` or ``"threads"`` (the default): a pool of ``workers`` threads in this process
  (default: one per core, never more than there are chunks). The compiled kernels release the
  GIL while they integrate (numba ``nogil``), so the threads run in parallel; nothing is
  pickled and nothing is started in another process, so a script needs no
  ``if __name__ == "__main__":`` guard. With one worker, or one chunk, the chunks simply run
  one after the other here.
* ``"synchronous"`` (or ``"sync"``): one after the other in this process (as ``workers=1``).
* ``"processes"``: a Dask ``LocalCluster`` started here with ``workers`` worker processes
  (default: one per core) of one thread each, closed at the end. Python's process start-up
  ("spawn") re-imports the calling script in every worker, so a script that asks for
  processes needs the ``__main__`` guard.
* anything else: the address of a running Dask scheduler (``"tcp://10.0.0.5:8786"``), which
  a ``dask.distributed.Client`` connects to; or pass a ``client`` directly.

Chunk results come back to this process (this thread) as they finish and are handed to
``on_result`` (which stores them), in completion order; the final result is assembled in
chunk order, so it does not depend on which worker ran which chunk or when.
"""

from __future__ import annotations

import logging
import os
from typing import Callable, Sequence

from ..errors import ArgumentError

#: Values of ``scheduler`` that name a way of running here rather than an address.
THREADS, SYNCHRONOUS, PROCESSES = "threads", "synchronous", "processes"
_LOCAL = {THREADS: THREADS, SYNCHRONOUS: SYNCHRONOUS, "sync": SYNCHRONOUS,
          "single-threaded": SYNCHRONOUS, PROCESSES: PROCESSES}


def _check_workers(workers):
    if workers is None:
        return None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ArgumentError(f"`workers` must be a positive integer or None, got {workers!r}")
    return workers


def default_workers() -> int:
    """One worker per core this process may run on (its CPU affinity where the system
    reports it, as in a container or under ``taskset``; else the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def local_scheduler(scheduler) -> str | None:
    """``"threads"``, ``"synchronous"`` or ``"processes"`` for ``scheduler`` (``None``:
    threads), or ``None`` when it is the address of a Dask scheduler."""
    if scheduler is None:
        return THREADS
    if isinstance(scheduler, str):
        return _LOCAL.get(scheduler.strip().lower())
    return None


def run_chunks(fn: Callable, tasks: Sequence, todo: Sequence[int],
               on_result: Callable[[int, object], None], *, workers=None, client=None,
               scheduler=None, progress: bool = True, desc: str = "chunks",
               n_done: int = 0) -> None:
    """Run ``fn(tasks[i])`` for every ``i`` in ``todo`` and call ``on_result(i, result)``.

    Parameters
    ----------
    fn : callable
        A module-level function (picklable by reference, for Dask).
    tasks : sequence
        Task descriptions (picklable, for Dask).
    todo : sequence of int
        Indices of the tasks still to run.
    on_result : callable
        Called in this thread with each finished result, as soon as it arrives.
    workers : int, optional
        Threads (default scheduler) or local worker processes (``scheduler="processes"``);
        default: one per core. 1: one after the other in this process.
    client : dask.distributed.Client, optional
    scheduler : str, optional
        ``"threads"`` (default), ``"synchronous"``, ``"processes"`` or the address of a
        running Dask scheduler (see the module docstring).
    progress : bool
        Show a tqdm progress bar (chunks done, rate, ETA).
    n_done : int
        Chunks already done before this call (the bar starts there).
    """
    from tqdm.auto import tqdm

    workers = _check_workers(workers)
    if client is not None and scheduler is not None:
        raise ArgumentError("give either `client` or `scheduler`, not both")
    local = local_scheduler(scheduler) if client is None else None
    total = n_done + len(todo)
    bar = tqdm(total=total, initial=n_done, desc=desc, unit="chunk", disable=not progress,
               dynamic_ncols=True)
    try:
        if not todo:
            return
        if local == THREADS:
            n = min(workers or default_workers(), len(todo))
            if n > 1:
                _run_threads(fn, tasks, todo, on_result, n, bar)
                return
            local = SYNCHRONOUS
        if local == SYNCHRONOUS:
            for i in todo:
                on_result(i, fn(tasks[i]))
                bar.update(1)
            return
        _run_dask(fn, tasks, todo, on_result, workers, client, scheduler, local, desc, bar)
    finally:
        bar.close()


def _run_threads(fn, tasks, todo, on_result, n: int, bar) -> None:
    """The chunks on a pool of ``n`` threads; results handled in this thread. On an error
    (or Ctrl-C) the chunks not started are cancelled and those running are waited for."""
    from concurrent.futures import ThreadPoolExecutor, as_completed

    pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="pwsdyn")
    try:
        futures = {pool.submit(fn, tasks[i]): i for i in todo}
        for fut in as_completed(futures):
            on_result(futures[fut], fut.result())
            bar.update(1)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(fn, tasks, todo, on_result, workers, client, scheduler, local, desc,
              bar) -> None:
    from dask.distributed import Client, LocalCluster, as_completed

    own_cluster = own_client = None
    if client is None:
        if local == PROCESSES:
            n = workers or default_workers()
            own_cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=logging.ERROR)
            client = own_client = Client(own_cluster)
        else:
            client = own_client = Client(scheduler)
    try:
        futures = {}
        for i in todo:
            fut = client.submit(fn, tasks[i], pure=False, key=f"pwsdyn-{desc}-{i}-"
                                f"{os.getpid()}-{id(tasks)}")
            futures[fut] = i
        for fut in as_completed(list(futures)):
            on_result(futures[fut], fut.result())
            bar.update(1)
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
