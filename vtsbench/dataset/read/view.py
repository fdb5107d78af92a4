"""Views of a loaded dataset: a subset of one kind's samples in index order, filtered by index
columns and split parts without reading arrays, read as samples or stacked batches, and handed
to PyTorch (`to_torch`), Hugging Face datasets (`to_hf`) or matplotlib (`plot`)."""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ..format.layout import DECODED_DTYPES
from .arrays import ITER_BYTES, check_arrays

if TYPE_CHECKING:
    import datasets
    import pyarrow as pa
    import torch.utils.data

    from .loader import VtsDataset


class SampleIndexError(VtsError, IndexError):
    """A position outside a view: a one-line VtsError that is also an IndexError."""


def _as_values(want: Any) -> list[Any]:
    """A filter value or a collection of them, as a list."""
    if want is None or isinstance(want, str | bytes | int | float | np.generic):
        return [want]
    return list(want)


class View:
    """A subset of the samples of one kind, in index order; filtering never reads arrays."""

    def __init__(self, ds: VtsDataset, kind: str, pos: np.ndarray) -> None:
        self._ds, self.kind = ds, kind
        self._kind = ds._kinds[kind]
        self._pos = np.asarray(pos, dtype=np.int64)

    def __len__(self) -> int:
        return len(self._pos)

    def __repr__(self) -> str:
        return (f"View({self.kind}, {len(self)} of {len(self._kind.rows)} samples, "
                f"{self._ds.location})")

    @property
    def dataset(self) -> VtsDataset:
        """The dataset this view belongs to."""
        return self._ds

    @property
    def ids(self) -> list[str]:
        """Sample ids in view order."""
        col = self._kind.columns["sample_id"]
        return [col[p] for p in self._pos]

    @property
    def rows(self) -> np.ndarray:
        """Zarr rows of the samples in view order."""
        return self._kind.rows[self._pos]

    @property
    def index(self) -> pa.Table:
        """The index rows of this view (pyarrow Table)."""
        return self._kind.table.take(self._pos)

    @property
    def arrays(self) -> tuple[str, ...]:
        """The arrays of the dataset: rgb, depth and contact, or rgb alone (--no-depth)."""
        return self._ds.info.arrays

    def nbytes(self, arrays: Sequence[str] | None = None) -> int:
        """Decoded bytes of one sample's arrays (default: all it has; depth as float32 mm)."""
        return self._kind.sample_nbytes(self.arrays if arrays is None else arrays)

    def _positions(self, items: Any) -> np.ndarray:
        """View positions (int, slice, sequence) -> index positions; out of range is an error."""
        n = len(self)
        if isinstance(items, slice):
            return self._pos[items]
        idx = np.asarray(items, dtype=np.int64).reshape(-1)
        bad = (idx < -n) | (idx >= n)
        if bad.any():
            raise SampleIndexError(f"index {int(idx[bad][0])} out of range for a {self.kind} "
                                   f"view of {n} samples")
        return self._pos[idx]

    def __getitem__(self, i: int | slice) -> dict[str, Any] | View:
        """A sample (dict: index fields plus rgb, depth in mm, contact; rgb alone in a dataset
        built with --no-depth), or a sub-view."""
        if isinstance(i, slice):
            return View(self._ds, self.kind, self._pos[i])
        if not isinstance(i, int | np.integer):
            raise TypeError(f"view indices are integers or slices, not {type(i).__name__}")
        return self._sample(int(self._positions([i])[0]), self.arrays)

    def _sample(self, pos: int, names: Sequence[str]) -> dict[str, Any]:
        arrays = self._kind.read(self._kind.rows[[pos]], names)
        return {**self._kind.meta(pos), **{n: a[0] for n, a in arrays.items()}}

    def __iter__(self) -> Iterator[dict[str, Any]]:
        """Samples in view order, read a few contiguous rows per zarr call."""
        step = max(1, ITER_BYTES // max(1, self._kind.sample_nbytes(self.arrays)))
        for start in range(0, len(self), step):
            pos = self._pos[start:start + step]
            arrays = self._kind.read(self._kind.rows[pos], self.arrays)
            for k, p in enumerate(pos):
                yield {**self._kind.meta(int(p)), **{n: a[k] for n, a in arrays.items()}}

    def metas(self, items: Any) -> list[dict[str, Any]]:
        """Index fields of several samples (view positions); reads no array."""
        return [self._kind.meta(int(p)) for p in self._positions(items)]

    def sample(self, i: int, arrays: Sequence[str] | None = None) -> dict[str, Any]:
        """Sample i with only the arrays named (e.g. ("rgb",)), to read less (default: all)."""
        return self._sample(int(self._positions([i])[0]),
                            self.arrays if arrays is None else tuple(arrays))

    def by_id(self, sample_id: str, arrays: Sequence[str] | None = None) -> dict[str, Any]:
        """The sample with this id; an id not in this view is an error."""
        pos = self._kind.position(sample_id)
        if pos is None or not np.any(self._pos == pos):
            where = "this view" if pos is not None else f"the {self.kind} index"
            raise VtsError(f"unknown sample id {sample_id!r} (not in {where})")
        return self._sample(pos, self.arrays if arrays is None else tuple(arrays))

    def read(self, items: Any, arrays: Sequence[str] = ("rgb",),
             frames: Sequence[int] | None = None) -> dict[str, np.ndarray]:
        """Arrays of several samples (view positions: ints or a slice), stacked in that order.

        Rows are sorted and read with one zarr call per contiguous run; depth is float32 mm;
        frames (slip only) keeps those frame numbers of each sequence.
        """
        pos = self._positions(items)
        fr = None if frames is None else self._frame_numbers(frames)
        check_arrays(self._ds.info, arrays)
        if not len(pos):
            return {n: np.empty((0, *self._shape(n, fr)), _dtype(n)) for n in arrays}
        return self._kind.read(self._kind.rows[pos], tuple(arrays), fr)

    def _shape(self, name: str, frames: np.ndarray | None) -> tuple[int, ...]:
        shape = tuple(self._ds.info.shapes[self.kind][name][1:])
        return shape if frames is None else (len(frames), *shape[1:])

    def _frame_numbers(self, frames: Sequence[int]) -> np.ndarray:
        if self.kind != "slip":
            raise VtsError("frames apply to slip sequences only")
        t = self._ds.info.frames_per_sequence
        fr = np.asarray(frames, dtype=np.int64).reshape(-1)
        if not len(fr) or fr.min() < 0 or fr.max() >= t:
            raise VtsError(f"frame numbers must be in 0..{t - 1}, got {fr.tolist()}")
        return fr

    def where(self, **columns: Any) -> View:
        """Samples whose index columns take the given value(s): where(object="gear",
        session=["s00", "s01"], state="slip"). A value found in no sample is an error."""
        keep = self._pos
        cols = self._kind.columns
        for name, want in columns.items():
            if name not in cols:
                raise VtsError(f"unknown {self.kind} index column {name!r}; columns: "
                               f"{', '.join(cols)}")
            values = set(_as_values(want))
            col = cols[name]
            present = values & set(col)
            if not present:
                known = sorted({str(v) for v in col})
                shown = ", ".join(known[:20]) + (", ..." if len(known) > 20 else "")
                raise VtsError(f"no {self.kind} sample has {name} in {sorted(map(str, values))}"
                               f" (values: {shown})")
            keep = keep[[col[p] in present for p in keep]] if len(keep) else keep
        return View(self._ds, self.kind, keep)

    def split(self, name: str, part: str) -> View:
        """The samples of this view in one part of a split (of this view's kind)."""
        split = self._ds.split_file(name)
        if split.kind != self.kind:
            raise VtsError(f"split {name!r} is of {split.kind} samples, this view holds "
                           f"{self.kind} samples")
        part_pos = self._ds._part_positions(split, part)
        return View(self._ds, self.kind, self._pos[np.isin(self._pos, part_pos)])

    def to_torch(self, modality: str = "rgb", size: tuple[int, int] | None = None,
                 frames: int | None = None, transform: Any = None,
                 targets: Sequence[str] = (), *, transforms: Any = None,
                 target_transform: Any = None, dtype: str = "uint8"
                 ) -> torch.utils.data.Dataset:
        """A torch Dataset of (tensor, target dict): uint8 frames resized in the worker
        (OpenCV INTER_AREA), or dtype="float32" for float tensors in [0, 1]; `transforms` sees
        the whole sample as one dict, `transform` the tensor, `target_transform` the target;
        see vtsbench.dataset.read.torch_dataset."""
        try:
            from .torch_dataset import TorchView
        except ModuleNotFoundError as e:
            raise VtsError(f"to_torch needs {e.name!r}: pip install 'vtsbench[torch]'") from None

        return TorchView(self, modality=modality, size=size, frames=frames, transform=transform,
                         targets=targets, transforms=transforms,
                         target_transform=target_transform, dtype=dtype)

    def to_hf(self, arrays: Sequence[str] | None = None, *, copy: bool = False,
              writer_batch_size: int = 8, cache_dir: str | os.PathLike | None = None
              ) -> datasets.IterableDataset | datasets.Dataset:
        """Index rows plus arrays (default: all the dataset has) as a Hugging Face
        datasets.IterableDataset streamed from the Zarr store, or a datasets.Dataset written
        under cache_dir with copy=True; see dataset.read.hf."""
        from .hf import to_hf

        return to_hf(self, arrays=self.arrays if arrays is None else arrays, copy=copy,
                     writer_batch_size=writer_batch_size, cache_dir=cache_dir)

    def plot(self, sample: Mapping[str, Any], frame: int = -1) -> Any:
        """A matplotlib Figure of one sample of this view (a dict as `view[i]` gives): RGB,
        depth and contact of one frame (default the last) with its labels."""
        from .plot import plot_sample

        return plot_sample(sample, self._ds.info, frame=frame)


def _dtype(name: str) -> np.dtype:
    """The dtype a reader gets for an array (depth in float32 mm)."""
    return np.dtype(DECODED_DTYPES[name])
