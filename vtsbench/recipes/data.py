"""What a recipe reads: the samples it fits on (`fit_view`, never the test part), a view's
samples or a dataset's items in batched reads, and a progress display."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from vtsbench.errors import VtsError


def progress_iter(items: Iterable[Any], total: int, label: str, enabled: bool = True
                  ) -> Iterable[Any]:
    """Iterate with a progress display on stderr when enabled (a bar on a terminal, lines
    otherwise)."""
    if not enabled:
        yield from items
        return
    from vtsbench.progress import progress_bar

    with progress_bar() as bar:
        task = bar.add_task(label, total=total)
        for item in items:
            yield item
            bar.advance(task)


def fit_view(dataset_path: str | Path, split: str, parts: Sequence[str] = ("train",)) -> Any:
    """The samples a recipe trains on: the union of `parts` of a split (default its `train`
    part; a final model may fold `val` in when nothing is selected on it). Never the test
    part, so that a leaderboard figure stays held out."""
    import numpy as np

    import vtsbench
    from vtsbench.dataset.read.view import View

    if not parts:
        raise VtsError("fit_parts must name at least one part")
    if "test" in parts:
        raise VtsError("fit_parts may not include the test part")
    ds = vtsbench.load(dataset_path)
    views = [ds.split(split, p) for p in parts]
    if len(views) == 1:
        return views[0]
    pos = np.unique(np.concatenate([v._pos for v in views]))
    return View(ds, views[0].kind, pos)


def per_read(view: Any, arrays: Sequence[str] | None = None) -> int:
    """How many samples of a view one batched read takes: about ITER_BYTES of decoded arrays
    (the named ones, default all), the budget of the loader's own iteration."""
    from vtsbench.dataset.read.arrays import ITER_BYTES

    return max(1, ITER_BYTES // max(1, view.nbytes(arrays)))


def iter_samples(view: Any, arrays: Sequence[str]) -> Iterator[dict[str, Any]]:
    """The samples of a view in order, as `for s in view` gives them but with only the arrays
    named, `per_read` of them per batched read (one zarr call per contiguous run of rows)."""
    from vtsbench.transforms.cache import read_samples

    step = per_read(view, arrays)
    for start in range(0, len(view), step):
        yield from read_samples(view, range(start, min(start + step, len(view))), arrays)


def read_items(data: Any, items: Sequence[int]) -> list[Any]:
    """Items of a map-style dataset, in the order of `items`: one call of its `__getitems__`
    when it has one (a batched read: `View.to_torch()`, a torch Subset of one, the crop
    datasets of `vtsbench.transforms.crops`; what DataLoader calls), else one `data[i]` each.
    The same items either way."""
    fetch = getattr(data, "__getitems__", None)
    return fetch(list(items)) if callable(fetch) else [data[i] for i in items]


def iter_items(data: Any, step: int) -> Iterator[Any]:
    """The items of a map-style dataset in order, `step` of them per `read_items`."""
    for start in range(0, len(data), max(1, step)):
        yield from read_items(data, range(start, min(start + step, len(data))))
