"""Moved to vtsbench.dataset.read.loader (and read.view, read.store); re-exported here so that
imports of the old path keep working."""

from .format.layout import ARRAYS
from .read.loader import KindStore, VtsDataset, _read_runs, load
from .read.store import StrictStore
from .read.view import SampleIndexError, View

__all__ = [
    "ARRAYS",
    "KindStore",
    "SampleIndexError",
    "StrictStore",
    "View",
    "VtsDataset",
    "_read_runs",
    "load",
]
