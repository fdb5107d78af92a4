"""Batches of View.to_torch and Windows.to_torch: a batch's frames are written once into its
tensors (shared memory in a DataLoader worker) and default_collate hands those on, giving the
very batches that stacking the items one by one gives, shuffled, with 0 and 2 workers."""

from __future__ import annotations

import pickle
from typing import Any

import numpy as np
import pytest

from tests.fixtures.batches import assert_same as _same
from vtsbench.dataset.read.loader import VtsDataset

torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader, default_collate  # noqa: E402


def _datasets(ds: VtsDataset, eps: VtsDataset) -> list[Any]:
    wins = eps.episodes.windows(length=5, stride=2, pad="edge")
    return [ds.slip.to_torch("rgbd", targets=("depth", "contact")),
            ds.slip.to_torch("rgb", size=(20, 30), frames=3, targets=("contact",)),
            ds.slip.to_torch("depth", targets=("depth",)),
            ds.static.to_torch("rgbd", size=(30, 20)),
            wins.to_torch("rgbd", targets=("depth", "contact")),
            wins.to_torch("rgb", size=(12, 16))]


def _x(batch: Any) -> torch.Tensor:
    return batch[0]["rgb"] if isinstance(batch[0], dict) else batch[0]


def test_collate_hands_on_the_batch_tensors(loaded_dataset: VtsDataset,
                                            loaded_takes: VtsDataset) -> None:
    """default_collate of one __getitems__ call: the tensors the frames were written into (no
    second copy), equal to stacking the items; items are plain tuples to their users."""
    for data in _datasets(loaded_dataset, loaded_takes):
        n = len(data)
        items = data.__getitems__([3 % n, 0, n - 1, 3 % n, 1])
        got, want = default_collate(items), default_collate([tuple(i) for i in items])
        _same(got, want)
        assert _x(got).untyped_storage().data_ptr() == _x(items[0]).untyped_storage().data_ptr()
        assert isinstance(items[0], tuple) and type(data[1]) is tuple
        assert type(pickle.loads(pickle.dumps(items[0]))) is tuple
        _same(tuple(items[1]), data[0])
        assert data.__getitems__([]) == []


def test_other_lists_of_items_are_stacked(loaded_dataset: VtsDataset) -> None:
    """Items reordered, a part of a batch, or changed: collated as tuples, as before."""
    data = loaded_dataset.slip.to_torch("rgbd", targets=("depth",))
    items = data.__getitems__([4, 1, 2])
    for part in (items[::-1], items[:2]):
        _same(default_collate(part), default_collate([tuple(i) for i in part]))
    items[1][1]["depth"] = torch.zeros_like(items[1][1]["depth"])
    items[2][0]["rgb"] = items[2][0]["rgb"].flip(-1)
    got = default_collate(items)
    _same(got, default_collate([tuple(i) for i in items]))
    assert not got[1]["depth"][1].any() and torch.equal(got[0]["rgb"][2], items[2][0]["rgb"])
    flips = loaded_dataset.slip.to_torch("rgb", transforms=lambda s: s)  # transforms: plain tuples
    assert all(type(i) is tuple for i in flips.__getitems__([0, 1]))


def _probe(batch: list[Any]) -> tuple[Any, bool, bool]:
    """default_collate in the worker, and whether the batch is the items' own shared tensor."""
    out = default_collate(batch)
    x = _x(out)
    return out, x.is_shared(), x.untyped_storage().data_ptr() == \
        _x(batch[0]).untyped_storage().data_ptr()


@pytest.mark.parametrize("workers", [0, 2])
def test_dataloader_batches_are_unchanged(loaded_dataset: VtsDataset, loaded_takes: VtsDataset,
                                          workers: int) -> None:
    """Shuffled DataLoader batches with 0 and 2 workers: each equal to its items stacked by
    default_collate; in a worker the frames are written into shared memory once."""
    for data in _datasets(loaded_dataset, loaded_takes):
        order = np.random.default_rng(len(data)).permutation(len(data)).tolist()
        loader = DataLoader(data, batch_size=3, sampler=order, num_workers=workers,
                            collate_fn=_probe, timeout=120 if workers else 0)
        for k, (batch, shared, same) in enumerate(loader):
            assert same and shared == (workers > 0)
            _same(batch, default_collate([data[i] for i in order[3 * k:3 * k + 3]]))


def test_shared_batch_memory_is_prefaulted_unchanged() -> None:
    """A worker's batch tensor is in shared memory and writable; prefaulting memory already
    written (an unaligned start, part of a page) leaves its bytes as they were."""
    from vtsbench.dataset.read.torch_batch import empty, prefault

    t = empty((3, 5, 700), np.uint8, True)
    assert t.is_shared() and t.shape == (3, 5, 700)
    want = np.arange(t.numel(), dtype=np.int64).astype(np.uint8).reshape(t.shape)
    t.numpy()[:] = want
    prefault(t.data_ptr() + 3, 5000)
    prefault(t.data_ptr(), 0)
    assert np.array_equal(t.numpy(), want)
