"""Moved to vtsbench.dataset.format.arrays (layout, depth), build.store (writing) and read.store
(opening); re-exported here so that imports of the old path keep working."""

from .build.store import (
    SHARD_BYTES,
    encode_shard,
    encode_shard_zarr,
    samples_per_shard,
    write_json,
    write_metadata,
    write_shard,
)
from .format.arrays import DEPTH_MAX_MM, DEPTH_MIN_MM, Layout, depth_to_int16, depth_to_mm
from .format.layout import ARRAYS, DEPTH_SCALE_MM, KINDS, RGB_ONLY
from .format.layout import STORED_DTYPES as DTYPES
from .read.store import group_location, open_group

__all__ = [
    "ARRAYS",
    "DEPTH_MAX_MM",
    "DEPTH_MIN_MM",
    "DEPTH_SCALE_MM",
    "DTYPES",
    "KINDS",
    "RGB_ONLY",
    "SHARD_BYTES",
    "Layout",
    "depth_to_int16",
    "depth_to_mm",
    "encode_shard",
    "encode_shard_zarr",
    "group_location",
    "open_group",
    "samples_per_shard",
    "write_json",
    "write_metadata",
    "write_shard",
]
