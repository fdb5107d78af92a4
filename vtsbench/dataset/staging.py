"""Moved to vtsbench.dataset.build.staging; re-exported here so that imports of the old path keep
working."""

from .build.staging import (
    COMMIT,
    FINGERPRINT_VERSION,
    WORK,
    SourceStats,
    check_out,
    commit,
    lock_path,
    locked_stage,
    parked_path,
    partial_path,
    recover,
    recover_stage,
    remove_stale,
    shard_done,
    shard_tasks,
)

__all__ = [
    "COMMIT",
    "FINGERPRINT_VERSION",
    "WORK",
    "SourceStats",
    "check_out",
    "commit",
    "lock_path",
    "locked_stage",
    "parked_path",
    "partial_path",
    "recover",
    "recover_stage",
    "remove_stale",
    "shard_done",
    "shard_tasks",
]
