"""CachedItems: a batch of items is what reading the samples one by one gives, in the order
asked, a repeated position included, whether the items are kept in memory or not."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import vtsbench
from vtsbench.transforms.cache import CachedItems


class Samples(CachedItems):
    """Items that are the samples `make` is given, counting the samples made."""

    made = 0

    def make(self, sample: dict[str, Any]) -> Any:
        self.made += 1
        return sample


def assert_same_sample(got: dict[str, Any], want: dict[str, Any]) -> None:
    """The same index fields (NaN equal to NaN) and the same arrays: shape, dtype and values."""
    assert got.keys() == want.keys()
    for key, w in want.items():
        g = got[key]
        if isinstance(w, np.ndarray):
            assert isinstance(g, np.ndarray) and g.dtype == w.dtype, key
            np.testing.assert_array_equal(g, w, err_msg=key)
        elif isinstance(w, float) and math.isnan(w):
            assert isinstance(g, float) and math.isnan(g), key
        else:
            assert g == w, key


@pytest.mark.parametrize("kind", ["static", "slip"])
@pytest.mark.parametrize("cache_mb", [2048.0, 0.0], ids=["cached", "uncached"])
def test_a_batch_is_the_samples_read_one_by_one(vts_dataset: Path, kind: str,
                                                cache_mb: float) -> None:
    ds = vtsbench.load(vts_dataset)
    view = ds.view(kind)
    arrays = ds.arrays
    order = [3, 0, len(view) - 1, 3, 1, 0]  # out of order, with repeated positions
    items = Samples(view, item_bytes=1.0, arrays=arrays, cache_mb=cache_mb)
    assert (items.cache is not None) == (cache_mb > 0)
    one_by_one = [view.sample(i, arrays) for i in order]
    first = items.__getitems__(order)
    assert items.made == len(set(order))  # each position made once, from one batched read
    again = items.__getitems__(order)
    assert items.made == len(set(order)) * (1 if cache_mb else 2)
    for batch in (first, again, [items[i] for i in order]):
        assert len(batch) == len(order)
        for got, want in zip(batch, one_by_one, strict=True):
            assert_same_sample(got, want)
    assert [s["sample_id"] for s in first] == [view[i]["sample_id"] for i in order]
    assert items.__getitems__([]) == []
