"""Moved to vtsbench.dataset.splits.given; re-exported here so that imports of the old path keep
working."""

from .splits.given import (
    GIVEN,
    MAX_FILE_BYTES,
    check_given,
    given_objects_split,
    read_object_list,
    read_split_file,
)

__all__ = [
    "GIVEN",
    "MAX_FILE_BYTES",
    "check_given",
    "given_objects_split",
    "read_object_list",
    "read_split_file",
]
