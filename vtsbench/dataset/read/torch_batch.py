"""Batches of the torch views (`TorchView`, `TorchWindows`): each frame of a batch written once,
resized and channels first, into its place in the batch's tensors (in shared memory inside a
DataLoader worker, as default_collate would make them), its items views of those tensors, and
`default_collate` handing the tensors on instead of stacking the items again (`collate_batch`,
registered in torch's `default_collate_fn_map`, the documented way to extend it). So a worker
writes each frame once, into memory the DataLoader sends without a copy; a batch is what
stacking its items would give, bit for bit. Inside `slot_memory` (the reused shared memory of
`torch_loader`) the batch tensors are taken from a given block instead of a fresh segment. This
module imports torch.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Iterator, Sequence
from contextvars import ContextVar
from typing import Any

import numpy as np
import torch


def put_frames(name: str, src: np.ndarray, dst: np.ndarray) -> None:
    """Frames of a read, src (..., H, W[, 3]), written into their place dst (..., [C,] h, w) of a
    batch tensor in one pass: rgb split plane by plane to channels first (OpenCV, SIMD: about 3x
    numpy's transposing copy), every array resized with OpenCV on the way where (h, w) differs
    (INTER_AREA: pixel-area averaging, the resampling for shrinking; contact nearest), each
    frame bit for bit `cv2.resize` of the stored frame."""
    import cv2

    h, w = dst.shape[-2:]
    if name == "rgb":
        src, dst = src.reshape(-1, *src.shape[-3:]), dst.reshape(-1, *dst.shape[-3:])
        tmp = None if src.shape[1:3] == (h, w) else np.empty((h, w, 3), src.dtype)
        for f in range(len(src)):
            frame = src[f]
            if tmp is not None:
                frame = cv2.resize(frame, (w, h), dst=tmp, interpolation=cv2.INTER_AREA)
            cv2.split(frame, list(dst[f]))
        return
    src, dst = src.reshape(-1, *src.shape[-2:]), dst.reshape(-1, h, w)
    if src.shape[1:] == (h, w):
        np.copyto(dst, src)
        return
    how = cv2.INTER_NEAREST if src.dtype == bool else cv2.INTER_AREA
    if src.dtype == bool:
        src, dst = src.view(np.uint8), dst.view(np.uint8)
    for f in range(len(src)):
        cv2.resize(src[f], (w, h), dst=dst[f], interpolation=how)


#: Alignment of the tensors taken from a block of `slot_memory` (a cache line).
ALIGN = 64


class Arena:
    """A block of memory (`storage` bytes [start, start + nbytes)) that the batch tensors of one
    `__getitems__` call are taken from in turn, each aligned to ALIGN; `used` counts the bytes
    asked for, also past the end and without a block (storage None: a probe of the size)."""

    def __init__(self, storage: torch.UntypedStorage | None, start: int = 0,
                 nbytes: int = 0) -> None:
        self.storage, self.start, self.end = storage, start, start + nbytes
        self.used = 0

    def take(self, shape: tuple[int, ...], dtype: np.dtype) -> torch.Tensor | None:
        """A tensor in the block's next free bytes, or None where it does not fit."""
        itemsize = np.dtype(dtype).itemsize
        nbytes = -(-math.prod(shape) * itemsize // ALIGN) * ALIGN
        at, self.used = self.start + self.used, self.used + nbytes
        if self.storage is None or at + nbytes > self.end:
            return None
        return torch.from_numpy(np.empty(0, dtype)).set_(self.storage, at // itemsize, shape)


_ARENA: ContextVar[Arena | None] = ContextVar("vtsbench_batch_arena", default=None)


@contextlib.contextmanager
def slot_memory(arena: Arena) -> Iterator[Arena]:
    """Within it, `empty` takes the batch tensors from `arena` (where they fit; a fresh tensor
    as before where not)."""
    token = _ARENA.set(arena)
    try:
        yield arena
    finally:
        _ARENA.reset(token)


def empty(shape: tuple[int, ...], dtype: np.dtype, shared: bool) -> torch.Tensor:
    """An uninitialised tensor: from the block of `slot_memory` where one is set and it fits.
    Else `shared`: in shared memory, as default_collate makes a worker's batch, so that the
    DataLoader sends it to the main process without a copy, its pages faulted in by one call
    (`prefault`); else numpy's memory, which asks the kernel for huge pages (a fresh 39 MB
    buffer filled in 5 ms, against 22 ms in torch.empty's 4 KB pages)."""
    arena = _ARENA.get()
    if arena is not None:
        t = arena.take(shape, dtype)
        if t is not None:
            return t
    if not shared:
        return torch.from_numpy(np.empty(shape, dtype))
    nbytes = math.prod(shape) * np.dtype(dtype).itemsize
    t = torch.from_numpy(np.empty(0, dtype))
    t.set_(torch.UntypedStorage._new_shared(nbytes), 0, shape)
    prefault(t.data_ptr(), nbytes)
    return t


_MADV_POPULATE_WRITE = 23  # Linux 5.14+


@functools.cache
def _madvise() -> Any:
    """libc's madvise, or None where there is none (not Linux)."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError):
        return None


def prefault(ptr: int, nbytes: int) -> None:
    """Fault in a fresh mapping's pages in one call (MADV_POPULATE_WRITE) rather than one
    fault per 4 KB page as the frames are written: the shared memory of a worker's batch is
    new for every batch. Best effort: an older kernel refuses it and the writes fault in."""
    madvise = _madvise()
    if madvise is None or nbytes == 0:
        return
    import ctypes

    start = ptr - ptr % 4096
    madvise(ctypes.c_void_p(start), ctypes.c_size_t(nbytes + ptr - start), _MADV_POPULATE_WRITE)


def in_worker() -> bool:
    """Whether this runs in a DataLoader worker (whose batches go through shared memory)."""
    from torch.utils.data import get_worker_info

    return get_worker_info() is not None


def batch_tensors(arrays: dict[str, np.ndarray], n: int, inputs: Sequence[str],
                  size: tuple[int, int] | None, shared: bool) -> dict[str, torch.Tensor]:
    """Empty batch tensors for n items of a read's arrays (m, ..., H, W[, 3]), at `size`: rgb
    (n, ..., 3, h, w) uint8, depth (n, ..., 1, h, w) float32 mm as an input, (n, ..., h, w) as
    a target alone, contact (n, ..., h, w) bool."""
    out = {}
    for name, a in arrays.items():
        dims = 3 if name == "rgb" else 2
        hw = size if size is not None else a.shape[len(a.shape) - dims:][:2]
        chans = (3,) if name == "rgb" else (1,) if name in inputs else ()
        shape = (n, *a.shape[1:len(a.shape) - dims], *chans, *hw)
        out[name] = empty(shape, a.dtype, shared)
    return out


class Batch:
    """The batch tensors that the items of one `__getitems__` call are views of (x: a tensor or
    an rgbd dict; spatial: the target arrays), and what each item held when made, for
    `collate_batch` to check that a list of items is that batch, in order and unchanged."""

    def __init__(self, x: Any, spatial: dict[str, torch.Tensor]) -> None:
        self.x, self.spatial = x, spatial
        self.held: list[list[tuple[str, Any]]] = []

    def add(self, x: Any, target: dict[str, Any]) -> BatchItem:
        """An item of this batch: (x, target) as a tuple that knows its batch."""
        self.held.append(_held(x, target, self.spatial))
        return BatchItem((x, target), self, len(self.held) - 1)

    def owns(self, batch: Sequence[Any]) -> bool:
        """Whether `batch` is this batch's items, all of them, in order and unchanged."""
        return len(batch) == len(self.held) and all(
            type(it) is BatchItem and it.whole is self and it.pos == k
            and _same(_held(it[0], it[1], self.spatial), self.held[k])
            for k, it in enumerate(batch))


def _held(x: Any, target: dict[str, Any], spatial: Sequence[str]) -> list[tuple[str, Any]]:
    xs = list(x.items()) if isinstance(x, dict) else [("", x)]
    return xs + [(n, target.get(n)) for n in spatial]


def _same(a: list[tuple[str, Any]], b: list[tuple[str, Any]]) -> bool:
    return len(a) == len(b) and all(ka == kb and va is vb
                                    for (ka, va), (kb, vb) in zip(a, b, strict=True))


class BatchItem(tuple):
    """An item (x, target) of a batch read together: a plain tuple to its user that also knows
    the batch tensors its tensors are views of (`whole`), for `collate_batch`. Pickles as a plain
    tuple."""

    def __new__(cls, pair: tuple[Any, Any], whole: Batch, pos: int) -> BatchItem:
        item = super().__new__(cls, pair)
        item.whole, item.pos = whole, pos
        return item

    def __reduce__(self) -> tuple[Any, ...]:
        return (tuple, (tuple(self),))


def collate_batch(batch: Sequence[Any], *, collate_fn_map: dict | None = None) -> Any:
    """default_collate of the items of one `__getitems__` call, in order and unchanged: the
    batch tensors they are views of, and the rest of the targets collated as default_collate
    does (ids a list, numbers a tensor): what default_collate would give, without stacking the
    frames again. Other lists of items (reordered, mixed, changed) are collated as tuples."""
    from torch.utils.data._utils.collate import collate

    whole = batch[0].whole
    if not whole.owns(batch):
        return collate([tuple(it) for it in batch], collate_fn_map=collate_fn_map)
    targets = [t for _x, t in batch]
    rest = collate([{k: v for k, v in t.items() if k not in whole.spatial} for t in targets],
                   collate_fn_map=collate_fn_map)
    return [whole.x, {k: whole.spatial[k] if k in whole.spatial else rest[k]
                      for k in targets[0]}]


try:  # torch's documented way to extend default_collate: its map of element types
    from torch.utils.data._utils.collate import default_collate_fn_map

    default_collate_fn_map[BatchItem] = collate_batch
except (ImportError, AttributeError):  # without it, items are collated (stacked) as tuples
    pass


def batch_of(bufs: dict[str, torch.Tensor], inputs: Sequence[str], modality: str,
             targets: Sequence[str], shared: bool) -> Batch:
    """The batch of filled tensors: x (a tensor, or the rgbd dict) and the target arrays, a
    depth target in a tensor of its own when depth is an input too (not one tensor twice)."""
    x = {n: bufs[n] for n in inputs}
    x = x.pop(modality) if modality in x else x
    spatial = {}
    for n in targets:
        t = bufs[n]
        if n in inputs:
            t = empty((*t.shape[:-3], *t.shape[-2:]), t.numpy().dtype, shared).copy_(
                t[..., 0, :, :])
        spatial[n] = t
    return Batch(x, spatial)


def item_at(x: Any, k: int) -> Any:
    """Item k of a batch x: a view of the tensor, or of each tensor of an rgbd dict."""
    return {n: v[k] for n, v in x.items()} if isinstance(x, dict) else x[k]
