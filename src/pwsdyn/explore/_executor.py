"""Running chunks of work in-process or on Dask, streaming each result as it finishes.

``workers=1`` (and no ``client``/``scheduler``) runs the chunks one after the other in this
process. Otherwise the chunks are submitted to a Dask cluster: the ``client`` passed in, a
``dask.distributed.Client`` connected to ``scheduler`` (an address such as
``"tcp://10.0.0.5:8786"``), or a ``LocalCluster`` started here with ``workers`` worker
processes (default: one per core) of one thread each and closed at the end. Chunk results
come back to this process as they finish and are handed to ``on_result`` (which stores them),
in completion order; the final result is assembled in chunk order, so it does not depend on
which worker ran which chunk or when.
"""

from __future__ import annotations

import logging
import os
from typing import Callable, Sequence

from ..errors import ArgumentError


def _check_workers(workers):
    if workers is None:
        return None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ArgumentError(f"`workers` must be a positive integer or None, got {workers!r}")
    return workers


def run_chunks(fn: Callable, tasks: Sequence, todo: Sequence[int],
               on_result: Callable[[int, object], None], *, workers=None, client=None,
               scheduler=None, progress: bool = True, desc: str = "chunks",
               n_done: int = 0) -> None:
    """Run ``fn(tasks[i])`` for every ``i`` in ``todo`` and call ``on_result(i, result)``.

    Parameters
    ----------
    fn : callable
        A module-level function (picklable by reference).
    tasks : sequence
        Picklable task descriptions.
    todo : sequence of int
        Indices of the tasks still to run.
    on_result : callable
        Called in this process with each finished result, as soon as it arrives.
    workers : int, optional
        1: in-process. Otherwise the number of local worker processes (default: CPU count).
    client : dask.distributed.Client, optional
    scheduler : str, optional
        Address of a running Dask scheduler.
    progress : bool
        Show a tqdm progress bar (chunks done, rate, ETA).
    n_done : int
        Chunks already done before this call (the bar starts there).
    """
    from tqdm.auto import tqdm

    workers = _check_workers(workers)
    if client is not None and scheduler is not None:
        raise ArgumentError("give either `client` or `scheduler`, not both")
    total = n_done + len(todo)
    bar = tqdm(total=total, initial=n_done, desc=desc, unit="chunk", disable=not progress,
               dynamic_ncols=True)
    try:
        if not todo:
            return
        if workers == 1 and client is None and scheduler is None:
            for i in todo:
                on_result(i, fn(tasks[i]))
                bar.update(1)
            return
        from dask.distributed import Client, LocalCluster, as_completed

        own_cluster = own_client = None
        if client is None:
            if scheduler is not None:
                client = own_client = Client(scheduler)
            else:
                n = workers or os.cpu_count() or 1
                own_cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                           dashboard_address=":0",
                                           silence_logs=logging.ERROR)
                client = own_client = Client(own_cluster)
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
    finally:
        bar.close()
