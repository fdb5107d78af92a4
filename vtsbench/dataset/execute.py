"""Moved to vtsbench.dataset.build.execute; re-exported here so that imports of the old path keep
working."""

from .build.execute import (
    CONNECT_TIMEOUT,
    _malloc_keeps_memory,
    dask_client,
    process_pool,
    run_tasks,
    run_with_progress,
)

__all__ = [
    "CONNECT_TIMEOUT",
    "_malloc_keeps_memory",
    "dask_client",
    "process_pool",
    "run_tasks",
    "run_with_progress",
]
