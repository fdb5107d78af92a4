"""Running the shard tasks: in this process, in a pool of spawned processes or on a Dask
cluster, with the workers' thread and malloc tuning, and progress bars."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from ...errors import VtsError
from .options import BuildOptions
from .shard import ShardResult, ShardTask, limit_threads, pool_worker_init, run_shard

#: The environment of spawned workers: one BLAS/OpenMP thread, and glibc's malloc keeping the
#: memory it frees (large blocks from the heap, never trimmed) instead of mapping fresh pages
#: for every frame-sized array and returning them: the page faults cost about a tenth of a
#: shard task here (480x640 slip shard, one worker: 21.5 -> 19 ms a frame, best of 8 tasks).
#: A worker's memory then stays at its peak (about 0.3 GB at 480x640) until the build ends.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
               "MALLOC_MMAP_THRESHOLD_": str(1 << 30), "MALLOC_TRIM_THRESHOLD_": str(1 << 30)}


@contextmanager
def _worker_env() -> Iterator[None]:
    """Children spawned inside the block start with _WORKER_ENV."""
    old = {k: os.environ.get(k) for k in _WORKER_ENV}
    os.environ.update(_WORKER_ENV)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextmanager
def _malloc_keeps_memory() -> Iterator[None]:
    """_WORKER_ENV's malloc settings for this process (glibc's mallopt), while the shard tasks
    run in it. Afterwards the free memory is released and the thresholds set where glibc's own
    adjustment takes them in a process that frees large arrays (32 MiB, trimming above 64 MiB):
    a setting disables that adjustment, and at the 128 KiB default every decoded array would be
    mapped afresh (reading a dataset in the same process measured 2x slower)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        mallopt, trim = libc.mallopt, libc.malloc_trim
    except (OSError, AttributeError):  # not glibc
        yield
        return
    m_trim, m_mmap = -1, -3  # M_TRIM_THRESHOLD, M_MMAP_THRESHOLD
    mallopt(m_mmap, 1 << 30)
    mallopt(m_trim, 1 << 30)
    try:
        yield
    finally:
        mallopt(m_trim, 64 << 20)
        mallopt(m_mmap, 32 << 20)
        trim(0)


def _in_process(tasks: list[ShardTask]) -> Iterator[ShardResult]:
    import cv2

    threads = cv2.getNumThreads()
    limit_threads()
    try:
        with _malloc_keeps_memory():
            for t in tasks:
                yield run_shard(t)
    finally:
        cv2.setNumThreads(threads)


@contextmanager
def process_pool(workers: int) -> Iterator[Any]:
    """A pool of `workers` spawned processes, started now: each imports what a shard task needs
    while the build process goes on (checking, planning); shut down on leaving."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # Spawned, not forked: a fork copies OpenCV's and the progress bar's threads' locks.
    ctx = multiprocessing.get_context("spawn")
    with _worker_env():
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                   initializer=pool_worker_init, initargs=(os.getpid(),))
        for _ in range(workers):  # a process is spawned per submit while none is idle
            pool.submit(int)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _pool_results(pool: Any, tasks: list[ShardTask]) -> Iterator[ShardResult]:
    """Submits the tasks now; results as they finish."""
    from concurrent.futures import as_completed, wait

    futures = [pool.submit(run_shard, t) for t in tasks]

    def results() -> Iterator[ShardResult]:
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:  # the tasks not started are dropped; those running finish before a new plan
            for fut in futures:
                fut.cancel()
            wait(futures)

    return results()


#: How long to wait for a Dask scheduler given by address.
CONNECT_TIMEOUT = "10s"


@contextmanager
def dask_client(scheduler: str, workers: int) -> Iterator[Any]:
    """A Dask client: on a LocalCluster of `workers` processes ('local') or a scheduler address."""
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise VtsError("--scheduler needs dask.distributed (pip install 'vtsbench[cluster]')"
                       ) from None
    cluster = None
    try:
        if scheduler == "local":
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
            client = Client(cluster)
        else:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as e:
        if cluster is not None:
            cluster.close()
        raise VtsError(f"cannot reach the Dask scheduler at {scheduler} ({e})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _dask(tasks: list[ShardTask], client: Any) -> Iterator[ShardResult]:
    """Submits the tasks now; results as they finish."""
    from distributed import as_completed

    futures = [client.submit(run_shard, t, key=f"vtsbench-{t.kind}-{t.k}-{t.fingerprint[:16]}",
                             pure=False) for t in tasks]

    def results() -> Iterator[ShardResult]:
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            client.cancel([f for f in futures if not f.done()])

    return results()


def run_tasks(tasks: list[ShardTask], opts: BuildOptions, client: Any = None,
              pool: Any = None) -> Iterator[ShardResult]:
    """Shard results as they finish: on a Dask client, in a process pool, or in this process.

    Workers get the tasks largest first (their order changes no byte): the longest tasks do not
    come last, when the other workers would have nothing left to do. In this process they run
    in plan order.
    """
    if not tasks:
        return iter(())
    largest_first = sorted(tasks, key=lambda t: -t.n_frames)
    if client is not None:
        return _dask(largest_first, client)
    if pool is not None:
        return _pool_results(pool, largest_first)
    if opts.workers > 1 and len(tasks) > 1:
        return _temporary_pool(largest_first, min(opts.workers, len(tasks)))
    return _in_process(tasks)


def _temporary_pool(tasks: list[ShardTask], workers: int) -> Iterator[ShardResult]:
    with process_pool(workers) as pool:
        results = _pool_results(pool, tasks)
        try:
            yield from results
        finally:
            results.close()


def _progress(enabled: bool) -> Any:
    """The build's bars (shards, frames) from the package's progress factory; None when off."""
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(None)
    from ...progress import is_terminal, progress_bar

    if not is_terminal():  # a log or a pipe: lines, since a live bar shows nothing until the end
        return progress_bar()
    from rich.progress import BarColumn, MofNCompleteColumn, TaskProgressColumn, TimeRemainingColumn

    return progress_bar("[progress.description]{task.description}", BarColumn(),
                        MofNCompleteColumn(), TaskProgressColumn(), TimeRemainingColumn(),
                        transient=False)


def run_with_progress(todo: list[ShardTask], tasks: list[ShardTask], opts: BuildOptions,
                      client: Any = None, pool: Any = None,
                      meanwhile: Callable[[], None] | None = None,
                      previews: dict[str, Any] | None = None) -> tuple[dict[str, str], int]:
    """Run the shard tasks with progress bars; returns the bad entries found while decoding
    (it stops at the first) and the number of shards written. `meanwhile` runs once the tasks
    are handed to the workers; the preview PNGs the tasks return go into `previews`."""
    late: dict[str, str] = {}
    written = 0
    with _progress(opts.progress) as bar:
        if bar is not None:
            done = [t for t in tasks if t not in todo]
            b_shards = bar.add_task("shards", total=len(tasks), completed=len(done))
            b_frames = bar.add_task("frames", total=sum(t.n_frames for t in tasks),
                                    completed=sum(t.n_frames for t in done))
        results = run_tasks(todo, opts, client, pool)
        try:
            if meanwhile is not None:
                meanwhile()
            for r in results:
                if r.bad:  # stop: the rows after it move, so later shards are planned again
                    late.update(r.bad)
                    break
                written += 1
                if previews is not None:
                    previews.setdefault(r.kind, {}).update(r.previews)
                if bar is not None:
                    bar.advance(b_shards)
                    bar.advance(b_frames, r.frames)
        finally:
            close = getattr(results, "close", None)
            if close is not None:
                close()
    return late, written
