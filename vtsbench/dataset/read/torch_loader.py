"""`TorchView.loader` and `TorchWindows.loader`: the DataLoader's batches, bit for bit, through
shared memory that is reused rather than made anew for every batch.

A plain DataLoader worker puts each batch in a fresh shared memory segment (zero-filled, then
faulted in page by page in the worker and again in the main process): on 2 cores that costs more
than reading the batch. Here the main process gives each worker a ring of `prefetch_factor + 1`
slots, each sized for one whole batch (the per-item bytes probed once by reading item 0), and a
counting semaphore of as many permits, from the DataLoader's multiprocessing context. The
DataLoader gets `SlotData`, whose `__getitems__` (what torch's fetcher calls with a batch's
indices) takes a permit, writes the batch's tensors straight into its worker's next slot
(round robin; `torch_batch.slot_memory`) and returns a small `Handle`: the worker, and the
collated batch with each tensor in the slot replaced by its place (`InSlot`) and the small label
tensors as numpy arrays; the DataLoader's collate_fn hands it on unchanged. The main process
copies each batch's tensors out of the slot into ordinary tensors (a memcpy), gives the permit
back, and yields the batch. Ring memory: with the fork start method shared anonymous memory,
its pages allocated by the workers as they first write; with spawn or forkserver torch's shared
memory, sent to each worker once when it starts. A worker maps a slot's pages in one call
(`torch_batch.prefault`) the first time it writes it; the main process, which only reads, maps
them by its first copy (a read fault maps 16 pages: measured 12 ms to copy a fresh 69 MB slot
against 19 with the pages prefaulted first), and keeps its rings for the loader's life, so a
loader iterated again (new workers each epoch) reuses them. The per-item bytes are probed once
per dataset object.

Why it never deadlocks: take the earliest batch of the pass not yet yielded. Its worker does
its tasks in order, so it has either written that batch (the main process copies it out and
gives the permit back) or is on it; were it waiting for a permit there, all its slots would hold
batches of its earlier tasks, which come earlier in the sampler's order and so were already
copied and their permits given back. So the main process always gets its next batch, with any
number of slots of at least one (the `+ 1` keeps a worker from waiting while the main process
copies). The round robin is safe because the main process takes each worker's batches in the
order the worker wrote them (torch's `in_order`, and each worker's tasks sent in the sampler's
order): slots come free in the order they were taken, so the slot a permit admits is free.

Early exit (a `break`, an exception in the consumer or a worker, the iterator collected):
`Epoch.close` gives back one permit for each task the main process has sent and not consumed
(each such task takes or holds exactly one), so no worker stays blocked: a plain DataLoader's
shutdown would otherwise wait 5 s for each blocked worker before terminating it. Then the
workers are shut down (persistent ones: torch drains those tasks at the next epoch, and the
permits balance again). Transforms, dtype="float32", no workers or an empty view: a plain
DataLoader. This module imports torch: import it only where torch is wanted.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import weakref
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, default_collate, get_worker_info

from .torch_batch import Arena, empty, prefault, slot_memory

#: Slots of a worker's ring beyond prefetch_factor: one, so that a worker never waits for the
#: main process to copy a batch out (any number of at least one slot is free of deadlock).
EXTRA_SLOTS = 1
#: A tensor of at most this many bytes not in a slot (the collated labels) goes as numpy in the
#: handle, pickled with it, rather than through a shared memory segment of its own.
SMALL_BYTES = 1 << 16


@dataclass(frozen=True, slots=True)
class InSlot:
    """A batch tensor written into a slot: its byte offset in the ring, dtype, shape, strides."""

    offset: int
    dtype: np.dtype
    shape: tuple[int, ...]
    stride: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class Small:
    """A small tensor of a batch (a collated label), sent as its numpy array."""

    array: np.ndarray


@dataclass(frozen=True, slots=True)
class Handle:
    """What a worker sends for a batch: its id and the batch with `InSlot` for its tensors."""

    worker: int
    batch: Any


def handed_on(handle: Handle) -> Handle:
    """The DataLoader's collate_fn: the handle as `SlotData` made it."""
    return handle


def pack(obj: Any, ring: torch.UntypedStorage, lo: int, hi: int) -> Any:
    """A collated batch with each tensor in ring bytes [lo, hi) as its `InSlot`, each small
    tensor as `Small`; any other tensor (one that did not fit its slot) as it is."""
    if isinstance(obj, torch.Tensor):
        base = ring.data_ptr()
        at = obj.data_ptr() - base
        if obj.untyped_storage().data_ptr() == base and lo <= at < hi:
            return InSlot(at, obj.numpy().dtype, tuple(obj.shape), obj.stride())
        if type(obj) is torch.Tensor and obj.is_contiguous() and obj.device.type == "cpu" \
                and obj.nbytes <= SMALL_BYTES and not obj.requires_grad:
            return Small(obj.numpy())
        return obj
    if type(obj) is dict:
        return {k: pack(v, ring, lo, hi) for k, v in obj.items()}
    if type(obj) in (list, tuple):
        return type(obj)(pack(v, ring, lo, hi) for v in obj)
    return obj


def unpack(obj: Any, ring: torch.UntypedStorage) -> Any:
    """The batch of a handle, each `InSlot` copied out of the ring into an ordinary tensor of
    the same dtype, shape and strides."""
    if isinstance(obj, InSlot):
        size = obj.dtype.itemsize
        src = torch.from_numpy(np.empty(0, obj.dtype)).set_(ring, obj.offset // size, obj.shape,
                                                            obj.stride)
        if src.is_contiguous():
            out = empty(obj.shape, obj.dtype, False)
            np.copyto(out.numpy(), src.numpy())
            return out
        return torch.empty_strided(obj.shape, obj.stride, dtype=src.dtype).copy_(src)
    if isinstance(obj, Small):
        return torch.from_numpy(obj.array)
    if type(obj) is dict:
        return {k: unpack(v, ring) for k, v in obj.items()}
    if type(obj) in (list, tuple):
        return type(obj)(unpack(v, ring) for v in obj)
    return obj


_ITEM_BYTES: weakref.WeakKeyDictionary[Any, int] = weakref.WeakKeyDictionary()


def item_bytes(data: Dataset) -> int:
    """Bytes of slot one item's batch tensors take (each aligned), from reading item 0 once per
    dataset object (a wrong size costs speed, never a batch: what does not fit goes as before)."""
    if data not in _ITEM_BYTES:
        with slot_memory(Arena(None)) as arena:
            default_collate(data.__getitems__([0]))  # type: ignore[attr-defined]
        _ITEM_BYTES[data] = arena.used
    return _ITEM_BYTES[data]


def acquire(sem: Any, parent: int) -> None:
    """A permit of sem; raises if the main process (parent) is gone meanwhile."""
    while not sem.acquire(timeout=1.0):
        if os.getppid() != parent:
            raise RuntimeError("the DataLoader's main process is gone")


class SlotData(Dataset):
    """The dataset a slot DataLoader's workers read: `data`'s batches written into their
    worker's ring (`rings`, `slots` slots of `slot_bytes` each), guarded by `sems`."""

    def __init__(self, data: Dataset, slot_bytes: int, slots: int) -> None:
        self.data, self.slot_bytes, self.slots = data, slot_bytes, slots
        self.rings: list[torch.UntypedStorage] = []
        self.sems: list[Any] = []
        self.parent = os.getpid()
        self._taken = 0  # batches this worker wrote (its next slot: _taken % slots)
        self._mapped: set[int] = set()  # slots this process has mapped

    def __len__(self) -> int:
        return len(self.data)  # type: ignore[arg-type]

    def __getitems__(self, items: Sequence[int]) -> Handle:
        """The batch of `items` written into this worker's next slot, as its handle."""
        info = get_worker_info()
        if info is None:
            raise RuntimeError("SlotData is read in DataLoader workers only")
        ring, sem = self.rings[info.id], self.sems[info.id]
        acquire(sem, self.parent)
        start = (self._taken % self.slots) * self.slot_bytes
        try:
            if start not in self._mapped:
                prefault(ring.data_ptr() + start, self.slot_bytes)
                self._mapped.add(start)
            with slot_memory(Arena(ring, start, self.slot_bytes)):
                batch = default_collate(self.data.__getitems__(items))  # type: ignore[attr-defined]
            handle = Handle(info.id, pack(batch, ring, start, start + self.slot_bytes))
        except BaseException:  # the slot stays next and free: its permit back
            sem.release()
            raise
        self._taken += 1
        return handle


def ring(nbytes: int, fork: bool) -> torch.UntypedStorage:
    """A worker's ring: shared anonymous memory, inherited by forked workers, pages allocated
    as first written; else torch's shared memory (a file descriptor, pickled to the worker)."""
    if fork:
        return torch.frombuffer(mmap.mmap(-1, nbytes), dtype=torch.uint8).untyped_storage()
    return torch.UntypedStorage._new_shared(nbytes)


class SlotLoader:
    """An iterable of a DataLoader's batches through reused shared memory (module docstring):
    `len` and iteration as the DataLoader's, one pass at a time (the passes share the rings:
    starting one ends the one before, whose next batch is then an error)."""

    def __init__(self, data: Dataset, slot_bytes: int, **kw: Any) -> None:
        slots = max(1, kw["prefetch_factor"] + EXTRA_SLOTS)
        self._data = SlotData(data, slot_bytes, slots)
        self._dl = DataLoader(self._data, collate_fn=handed_on, **kw)
        self._ctx = self._dl.multiprocessing_context or torch.multiprocessing
        fork = self._ctx.get_start_method() == "fork"
        self._data.rings = [ring(slots * slot_bytes, fork) for _ in range(kw["num_workers"])]
        self._data.sems = self._sems()
        self._persistent = bool(kw["persistent_workers"])
        self._epoch: weakref.ref[Epoch] | None = None

    def _sems(self) -> list[Any]:
        return [self._ctx.Semaphore(self._data.slots) for _ in self._data.rings]

    def __len__(self) -> int:
        return len(self._dl)

    def __iter__(self) -> Epoch:
        last = self._epoch() if self._epoch is not None else None
        if last is not None:  # its workers' permits back before torch drains or replaces them
            last.close(superseded=True)
        if not self._persistent:  # new workers: new semaphores, all permits free
            self._data.sems = self._sems()
        epoch = Epoch(self, iter(self._dl), self._data.sems)
        self._epoch = weakref.ref(epoch)
        return epoch

    def batch(self, handle: Handle) -> Any:
        """The batch of a handle, copied out of its worker's ring."""
        return unpack(handle.batch, self._data.rings[handle.worker])


class Epoch:
    """One pass of a `SlotLoader`: each batch copied out of its slot, whose permit then goes
    back; `close` (at a break, an error or collection) gives back the permits of the tasks
    sent and not consumed and shuts a non-persistent DataLoader's workers down."""

    def __init__(self, owner: SlotLoader, it: Any, sems: list[Any]) -> None:
        self._owner, self._it, self._sems = owner, it, sems
        self._superseded = False

    def __iter__(self) -> Epoch:
        return self

    def __next__(self) -> Any:
        if self._it is None:
            if self._superseded:
                raise RuntimeError("a newer pass of this loader ended this one (one pass at a "
                                   "time: they share its shared memory)")
            raise StopIteration
        try:
            handle = next(self._it)
        except StopIteration:
            self._it = None  # every task consumed; torch ended non-persistent workers
            raise
        except BaseException:
            self.close()
            raise
        try:
            return self._owner.batch(handle)
        finally:
            self._sems[handle.worker].release()

    def close(self, superseded: bool = False) -> None:
        """Give back the permits of the tasks not consumed, then end the workers (not
        persistent ones); idempotent. superseded: by a newer pass (whose next batch is then
        an error rather than the end)."""
        it, self._it = self._it, None
        if it is None:
            return
        self._superseded = superseded
        for info in list(getattr(it, "_task_info", {}).values()):
            self._sems[info[0]].release()
        if not self._owner._persistent and hasattr(it, "_shutdown_workers"):
            it._shutdown_workers()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # at exit the semaphores or queues may be gone
            self.close()


def make_loader(data: Any, batch_size: int = 1, *, shuffle: bool = False,
                num_workers: int = 0, drop_last: bool = False,
                generator: torch.Generator | None = None, persistent_workers: bool = False,
                prefetch_factor: int = 2, multiprocessing_context: Any = None
                ) -> Iterable[Any]:
    """What `DataLoader(data, batch_size, shuffle=..., ...)` yields: through reused shared
    memory with workers (`SlotLoader`), a plain DataLoader without workers, with transforms
    or with dtype="float32" (outputs of any shape), or for an empty dataset."""
    kw: dict[str, Any] = dict(batch_size=batch_size, shuffle=shuffle, num_workers=num_workers,
                              drop_last=drop_last, generator=generator,
                              persistent_workers=persistent_workers,
                              prefetch_factor=prefetch_factor if num_workers > 0 else None,
                              multiprocessing_context=multiprocessing_context)
    plain = getattr(data, "dtype", "uint8") == "uint8" and all(
        getattr(data, a, None) is None for a in ("transforms", "transform", "target_transform"))
    if num_workers == 0 or not plain or len(data) == 0 or not isinstance(batch_size, int) \
            or batch_size < 1 or not isinstance(prefetch_factor, int) or prefetch_factor < 1:
        return DataLoader(data, **kw)  # also its own errors for bad arguments
    return SlotLoader(data, batch_size * item_bytes(data), **kw)


class Loadable:
    """The `loader` method of the torch views."""

    def loader(self, batch_size: int = 1, *, shuffle: bool = False, num_workers: int = 0,
               drop_last: bool = False, generator: torch.Generator | None = None,
               persistent_workers: bool = False, prefetch_factor: int = 2,
               multiprocessing_context: Any = None) -> Iterable[Any]:
        """The batches `DataLoader(self, batch_size, shuffle=..., num_workers=..., ...)`
        yields, bit for bit and in the same order, the workers' batches passed through
        reused shared memory (vtsbench.dataset.read.torch_loader)."""
        return make_loader(self, batch_size, shuffle=shuffle, num_workers=num_workers,
                           drop_last=drop_last, generator=generator,
                           persistent_workers=persistent_workers,
                           prefetch_factor=prefetch_factor,
                           multiprocessing_context=multiprocessing_context)
