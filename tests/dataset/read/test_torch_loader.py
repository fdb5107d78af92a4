"""`loader()` of the torch views: the batches a DataLoader yields, bit for bit and in order,
with the workers' batches written into reused shared memory; no deadlock with a slow consumer
or many workers, no hang at an early exit, a plain DataLoader where slots cannot apply."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from tests.fixtures.batches import assert_same as _same
from vtsbench.dataset.read.loader import VtsDataset

torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader  # noqa: E402

from vtsbench.dataset.read import torch_loader  # noqa: E402
from vtsbench.dataset.read.torch_batch import Arena, empty, slot_memory  # noqa: E402
from vtsbench.dataset.read.torch_loader import SlotLoader  # noqa: E402


def _same_batches(got: Any, data: Any, **kw: Any) -> None:
    """got (an iterable of batches) is what a DataLoader over data with kw yields."""
    want = list(DataLoader(data, **kw))
    got = list(got)
    assert len(got) == len(want)
    for k, (a, b) in enumerate(zip(got, want, strict=True)):
        _same(a, b, f"batch {k}")


def _seeded(**kw: Any) -> dict[str, Any]:
    return {**kw, "generator": torch.Generator().manual_seed(3)}


def _within(seconds: float, job: Callable[[], Any]) -> Any:
    """job's result, run in a thread that must end within `seconds` (else: a deadlock)."""
    out: list[Any] = []
    t = threading.Thread(target=lambda: out.append(job()), daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"not done in {seconds} s: a deadlock?"
    return out[0]


def test_arena_aligns_counts_and_refuses_past_its_end() -> None:
    """Tensors from a block, each at a 64-byte boundary; one that does not fit is refused (None)
    but counted; inside slot_memory `empty` takes from the block, else from fresh memory."""
    storage = torch.UntypedStorage(1000)
    arena = Arena(storage, 128, 600)
    a = arena.take((3, 5), np.dtype(np.float32))
    b = arena.take((2,), np.dtype(bool))
    assert a.data_ptr() - storage.data_ptr() == 128 and b.data_ptr() - a.data_ptr() == 64
    assert a.shape == (3, 5) and a.dtype == torch.float32 and b.dtype == torch.bool
    assert arena.take((600,), np.dtype(np.uint8)) is None and arena.used == 128 + 640
    with slot_memory(Arena(storage, 0, 1000)):
        t = empty((4, 4), np.dtype(np.uint8), False)
        big = empty((2000,), np.dtype(np.uint8), False)
    assert t.untyped_storage().data_ptr() == storage.data_ptr()
    assert big.untyped_storage().data_ptr() != storage.data_ptr()
    assert empty((4,), np.dtype(np.uint8), False).untyped_storage().data_ptr() \
        != storage.data_ptr()


def _datasets(ds: VtsDataset, eps: VtsDataset) -> list[Any]:
    wins = eps.episodes.windows(length=5, stride=2, pad="edge")
    return [ds.slip.to_torch("rgbd", targets=("depth", "contact")),
            ds.slip.to_torch("rgb", size=(20, 30), frames=3, targets=("contact",)),
            ds.static.to_torch("depth", targets=("depth",)),
            wins.to_torch("rgbd", targets=("depth", "contact")),
            wins.to_torch("rgb", size=(12, 16))]


def test_batches_are_the_dataloaders(loaded_dataset: VtsDataset, loaded_takes: VtsDataset) -> None:
    """Shuffled, 2 workers, a last partial batch: the DataLoader's batches bit for bit, as
    ordinary tensors copied out of the slots; the same with drop_last."""
    for data in _datasets(loaded_dataset, loaded_takes):
        kw = _seeded(batch_size=4, shuffle=True, num_workers=2)
        loader = data.loader(**kw)
        assert isinstance(loader, SlotLoader) and len(data) % 4 != 0
        assert len(loader) == len(DataLoader(data, **kw))
        batches = list(loader)
        _same_batches(batches, data, **_seeded(**kw))
        x = batches[0][0]["rgb"] if isinstance(batches[0][0], dict) else batches[0][0]
        assert not x.is_shared()
        kw = _seeded(batch_size=3, shuffle=True, num_workers=2, drop_last=True)
        _same_batches(data.loader(**kw), data, **_seeded(**kw))


def test_persistent_workers_keep_their_slots_across_epochs(loaded_dataset: VtsDataset) -> None:
    """Persistent workers: every epoch the persistent DataLoader's, also after epochs left
    early (their unconsumed tasks' permits given back, else the fourth would wait forever)."""
    data = loaded_dataset.slip.to_torch("rgbd", targets=("depth",))
    kw: dict[str, Any] = dict(batch_size=2, shuffle=True, num_workers=2,
                              persistent_workers=True)
    loader = data.loader(**_seeded(**kw))
    ref = DataLoader(data, **_seeded(**kw))
    for epoch in range(4):
        if epoch in (1, 2):
            for a, b in zip(loader, ref, strict=False):
                _same(a, b)
                break
            continue
        got, want = _within(60, lambda: list(loader)), list(ref)
        assert len(got) == len(want)
        for a, b in zip(got, want, strict=True):
            _same(a, b)


@pytest.mark.filterwarnings("ignore:This DataLoader will create")
@pytest.mark.parametrize("extra", [1, -1])
def test_slow_consumer_and_many_workers_do_not_deadlock(loaded_dataset: VtsDataset, extra: int,
                                                        monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """Batches of 1 through 4 workers and a consumer slower than the workers: every batch, in
    order, with 2 slots a worker for its prefetch of 1, and with a single slot (workers then
    wait for the consumer at every batch)."""
    monkeypatch.setattr(torch_loader, "EXTRA_SLOTS", extra)
    data = loaded_dataset.slip.to_torch("rgb", size=(16, 16))
    kw = _seeded(batch_size=1, shuffle=True, num_workers=4, prefetch_factor=2 - extra)

    def slow() -> list[Any]:
        out = []
        for b in data.loader(**kw):
            time.sleep(0.05)
            out.append(b)
        return out

    got = _within(120, slow)
    _same_batches(got, data, **_seeded(batch_size=1, shuffle=True))


def test_early_exit_does_not_hang(loaded_dataset: VtsDataset) -> None:
    """A break after one batch, an exception in the consumer, an iterator dropped: each
    returns in well under a second (torch waits 5 s for each blocked worker), and the loader
    gives whole epochs after."""
    data = loaded_dataset.slip.to_torch("rgbd")
    loader = data.loader(batch_size=1, num_workers=2, prefetch_factor=1)
    t0 = time.perf_counter()
    for _b in loader:
        break
    broke = time.perf_counter() - t0
    t0 = time.perf_counter()
    with pytest.raises(KeyError):
        for _b in loader:
            raise KeyError("consumer")
    raised = time.perf_counter() - t0
    t0 = time.perf_counter()
    it = iter(loader)
    next(it)
    del it
    dropped = time.perf_counter() - t0
    assert max(broke, raised, dropped) < 2.5, (broke, raised, dropped)
    _same_batches(_within(60, lambda: list(loader)), data, batch_size=1)


def test_an_error_in_a_worker_ends_the_pass_at_once(loaded_dataset: VtsDataset) -> None:
    """A read failing in a worker: its error in the main process, the workers ended at once,
    the slot it took free again (the next pass whole); one pass at a time."""
    data = loaded_dataset.slip.to_torch("rgb", size=(16, 16))
    loader = data.loader(batch_size=2, num_workers=2, prefetch_factor=1)
    read = data.__getitems__

    def failing(items: list[int]) -> Any:
        if 4 in items:
            raise ValueError("a broken read")
        return read(items)

    data.__getitems__ = failing  # type: ignore[method-assign]
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match="a broken read"):
        list(loader)
    assert time.perf_counter() - t0 < 2.5
    del data.__getitems__
    _same_batches(_within(60, lambda: list(loader)), data, batch_size=2)
    first = iter(loader)
    next(first)
    second = iter(loader)
    with pytest.raises(RuntimeError, match="newer pass"):
        next(first)
    _same_batches(_within(60, lambda: [next(second), *second]), data, batch_size=2)


def test_plain_dataloader_where_slots_do_not_apply(loaded_dataset: VtsDataset,
                                                   loaded_takes: VtsDataset) -> None:
    """No workers, transforms, dtype="float32": a plain DataLoader (outputs of any shape),
    with the same batches."""
    view = loaded_dataset.slip
    cases = [view.to_torch("rgbd").loader(batch_size=2),
             view.to_torch("rgb", transforms=lambda s: s).loader(batch_size=2, num_workers=2),
             view.to_torch("rgb", transform=lambda x: x[:, :1]).loader(num_workers=2),
             view.to_torch("rgb", target_transform=lambda t: t["class_idx"]).loader(
                 num_workers=2),
             view.to_torch("rgb", dtype="float32").loader(batch_size=2, num_workers=2),
             loaded_takes.episodes.windows(length=3).to_torch("rgb", dtype="float32").loader(
                 num_workers=2)]
    assert all(type(c) is DataLoader for c in cases)
    data = view.to_torch("rgb", size=(10, 12), transform=lambda x: x[:, :1])
    _same_batches(data.loader(batch_size=3, num_workers=2), data, batch_size=3)
    with pytest.raises(ValueError):  # the DataLoader's own checks
        view.to_torch("rgb").loader(persistent_workers=True)


def test_a_batch_past_its_slot_goes_as_before(loaded_dataset: VtsDataset,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Slots too small (a wrong probe): the tensors that do not fit go through torch's shared
    memory as a plain DataLoader's, the batches unchanged."""
    monkeypatch.setattr(torch_loader, "item_bytes", lambda data: 64)
    data = loaded_dataset.slip.to_torch("rgbd", targets=("depth",))
    kw = _seeded(batch_size=2, shuffle=True, num_workers=2)
    _same_batches(data.loader(**kw), data, **_seeded(**kw))


def test_spawn_workers(loaded_dataset: VtsDataset) -> None:
    """The spawn start method: the rings and semaphores reach the workers pickled."""
    data = loaded_dataset.slip.to_torch("rgb", size=(12, 16), targets=("contact",))
    got = _within(300, lambda: list(data.loader(batch_size=4, num_workers=1,
                                                multiprocessing_context="spawn")))
    _same_batches(got, data, batch_size=4)
