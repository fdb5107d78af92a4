"""Which arrays a dataset holds, the one-line error for one it lacks, and how much a view
reads per call: shared by the numpy loader, its PyTorch and Hugging Face adapters."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ...errors import VtsError
from ..format.layout import ARRAYS

if TYPE_CHECKING:
    from ..format.info import DatasetInfo

#: Bytes of decoded arrays read per call while iterating over a view.
ITER_BYTES = 64 * 2**20


def check_arrays(info: DatasetInfo, names: Sequence[str], what: str = "") -> None:
    """A one-line error for an array name the dataset does not hold (depth and contact in a
    dataset built with --no-depth); `what` says what asked for it."""
    for n in names:
        if n not in ARRAYS:
            raise VtsError(f"unknown array {n!r}; arrays are {', '.join(ARRAYS)}")
        if n not in info.arrays:
            raise VtsError(f"{what or 'reading ' + repr(n)} needs the {n} array, and this dataset "
                           f"has none (built with --no-depth: {', '.join(info.arrays)} only)")
