"""Splits of a dataset: the fixed schemes (schemes), the ones a lab gives (given), the one
leak check (leaks) and split files on disk (files).

The package also re-exports what the module `vtsbench.dataset.splits` held before it became
this package, so that imports of the old path keep working.
"""

from .files import read_split, write_splits
from .leaks import BAND, OUTSIDE, UNKNOWN, leak_check
from .schemes import (
    DEFAULT_BANDS,
    HELD_OUT_DRAWS,
    MAX_ASSIGNMENTS,
    PART_ORDER,
    SCHEMES,
    TEST_FRACTION,
    SplitReport,
    default_unseen_k,
    make_splits,
    object_folds_split,
    rng_for,
    seen_split,
    static_locations_split,
    static_sessions_split,
    unseen_objects_split,
)

__all__ = ["BAND", "DEFAULT_BANDS", "HELD_OUT_DRAWS", "MAX_ASSIGNMENTS", "OUTSIDE", "PART_ORDER",
           "SCHEMES", "TEST_FRACTION", "UNKNOWN", "SplitReport", "default_unseen_k",
           "leak_check", "make_splits", "object_folds_split", "read_split", "rng_for",
           "seen_split", "static_locations_split", "static_sessions_split",
           "unseen_objects_split", "write_splits"]
