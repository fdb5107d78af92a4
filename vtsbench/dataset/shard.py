"""Moved to vtsbench.dataset.build.shard; re-exported here so that imports of the old path keep
working."""

from .build.shard import (
    ShardResult,
    ShardTask,
    _calibration,
    _maker,
    depth_and_contact,
    limit_threads,
    pool_worker_init,
    run_shard,
)

__all__ = [
    "ShardResult",
    "ShardTask",
    "_calibration",
    "_maker",
    "depth_and_contact",
    "limit_threads",
    "pool_worker_init",
    "run_shard",
]
