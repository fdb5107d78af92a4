"""Items made from a view's samples, read in batches and kept in memory once made.

A model's item (a contact crop, its motion channels) costs far more to make than to hold, so a
training run that draws each sample many times makes it once. The samples are read with only
the arrays the items need, a batch of them per call (`View.read`: one zarr call per contiguous
run of rows), which gives the same arrays as reading them one by one.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any


def read_samples(view: Any, items: Iterable[int], arrays: Sequence[str]) -> list[dict[str, Any]]:
    """The samples at view positions `items` (any order, repeats allowed), each a dict of its
    index fields and the arrays named, as `view[i]` gives them; the arrays of all of them are
    read together."""
    items = [int(i) for i in items]
    if not items:
        return []
    data = view.read(items, tuple(arrays))
    return [{**meta, **{n: a[k] for n, a in data.items()}}
            for k, meta in enumerate(view.metas(items))]


class CachedItems:
    """A map-style dataset over a dataset view whose items (`make(sample)`) are kept in memory
    once made, when all of them together fit in `cache_mb` (`item_bytes` each). `arrays`: the
    arrays `make` reads; a batch (`__getitems__`, what the training loop and DataLoader call)
    reads the samples it has not made yet in one batched read."""

    def __init__(self, view: Any, item_bytes: float, arrays: Sequence[str],
                 cache_mb: float = 2048.0) -> None:
        self.view, self.arrays = view, tuple(arrays)
        self.cache: dict[int, Any] | None = \
            {} if len(view) * item_bytes / 2**20 <= cache_mb else None

    def __len__(self) -> int:
        return len(self.view)

    def make(self, sample: dict[str, Any]) -> Any:
        raise NotImplementedError

    def __getitem__(self, i: int) -> Any:
        return self.__getitems__([i])[0]

    def __getitems__(self, items: Sequence[int]) -> list[Any]:
        """The items at `items` in that order; the missing ones made from one batched read (a
        position repeated in `items` is made once)."""
        items = [int(i) for i in items]
        cache = self.cache if self.cache is not None else {}
        todo = list(dict.fromkeys(i for i in items if i not in cache))
        made = dict(zip(todo, map(self.make, read_samples(self.view, todo, self.arrays)),
                        strict=True))
        if self.cache is not None:
            self.cache.update(made)
        return [made[i] if i in made else cache[i] for i in items]
