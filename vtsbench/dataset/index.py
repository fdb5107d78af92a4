"""Moved to vtsbench.dataset.format.index; its `read_index` (a pyarrow Table) is the one reader
now, and the former `read_index` (SampleMeta rows) is `read_metas`; re-exported here so that
imports of the old path keep working."""

from .format.index import PARQUET_OPTIONS, index_bytes, read_metas
from .format.index import read_metas as read_index

__all__ = [
    "PARQUET_OPTIONS",
    "index_bytes",
    "read_index",
    "read_metas",
]
