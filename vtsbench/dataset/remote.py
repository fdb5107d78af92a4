"""Moved to vtsbench.dataset.read.remote; re-exported here so that imports of the old path keep
working."""

from .read.remote import FETCH_THREADS, local_copy, local_path, remote_info, remote_sizes

__all__ = [
    "FETCH_THREADS",
    "local_copy",
    "local_path",
    "remote_info",
    "remote_sizes",
]
