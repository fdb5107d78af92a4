"""Moved to vtsbench.dataset.build.finish; re-exported here so that imports of the old path keep
working."""

from .build.finish import build_params, finish, hash_files, shard_digests, write_plan_files

__all__ = [
    "build_params",
    "finish",
    "hash_files",
    "shard_digests",
    "write_plan_files",
]
