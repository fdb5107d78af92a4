"""Moved to vtsbench.dataset.tools.verify; re-exported here so that imports of the old path keep
working."""

from .tools.verify import (
    MISSING,
    VerifyReport,
    check_arrays,
    check_files,
    check_index,
    check_splits,
    chunk_of_byte,
    shard_index,
    verify,
)

__all__ = [
    "MISSING",
    "VerifyReport",
    "check_arrays",
    "check_files",
    "check_index",
    "check_splits",
    "chunk_of_byte",
    "shard_index",
    "verify",
]
