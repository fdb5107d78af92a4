"""Moved to vtsbench.dataset.read.arrays; re-exported here so that imports of the old path keep
working."""

from .read.arrays import ITER_BYTES, check_arrays

__all__ = [
    "ITER_BYTES",
    "check_arrays",
]
