"""`View.to_hf`: a Hugging Face `datasets.Dataset` of a view's index rows plus its arrays.

Built offline by `Dataset.from_generator` into Arrow files under `cache_dir`, a few rows per
write (`writer_batch_size`) because a slip row holds megabytes. Arrays are fixed-shape features:
rgb uint8, depth float32 mm, contact bool; `.with_format("numpy")` returns them as arrays
(datasets widens integer arrays to int64 there: `.astype(np.uint8)` restores rgb).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any

import datasets

from .loader import ITER_BYTES

if TYPE_CHECKING:
    from .loader import View

_DTYPES = {"rgb": "uint8", "depth": "float32", "contact": "bool"}
_ARRAY_FEATURES = {2: datasets.Array2D, 3: datasets.Array3D, 4: datasets.Array4D,
                   5: datasets.Array5D}


def features(view: View, arrays: Sequence[str] | None = None) -> datasets.Features:
    """The index columns (as in the parquet) plus one fixed-shape feature per array (default:
    every array the dataset has)."""
    arrays = view.arrays if arrays is None else arrays
    feats = datasets.Features.from_arrow_schema(view.index.schema)
    shapes = view.dataset.info.shapes[view.kind]
    for name in arrays:
        shape = tuple(shapes[name][1:])
        feats[name] = _ARRAY_FEATURES[len(shape)](shape=shape, dtype=_DTYPES[name])
    return feats


def _rows(view: View, arrays: tuple[str, ...], batch: int,
          dataset_sha256: str) -> Iterator[dict[str, Any]]:
    """Index rows with their arrays, read `batch` samples per call (dataset_sha256 only keys
    the datasets cache, so a rebuilt dataset is not mistaken for an old one)."""
    del dataset_sha256
    for start in range(0, len(view), batch):
        part = view[start:start + batch]
        data = part.read(slice(None), arrays) if arrays else {}
        for k, row in enumerate(part.index.to_pylist()):
            yield {**row, **{n: a[k] for n, a in data.items()}}


def to_hf(view: View, arrays: Sequence[str] | None = None, *, writer_batch_size: int = 8,
          cache_dir: str | os.PathLike | None = None) -> datasets.Dataset:
    """A datasets.Dataset of the view's samples (index columns + arrays, default: every array
    the dataset has), built offline."""
    arrays = view.arrays if arrays is None else tuple(arrays)
    from .loader import check_arrays

    check_arrays(view.dataset.info, arrays)
    feats = features(view, arrays)
    if not len(view):
        return datasets.Dataset.from_dict({k: [] for k in feats}, features=feats)
    per = max(1, view.nbytes(arrays)) if arrays else 1
    batch = max(1, min(writer_batch_size, ITER_BYTES // per))
    return datasets.Dataset.from_generator(
        _rows, features=feats, writer_batch_size=writer_batch_size,
        cache_dir=None if cache_dir is None else str(cache_dir),
        gen_kwargs={"view": view, "arrays": arrays, "batch": batch,
                    "dataset_sha256": view.dataset.info.dataset_sha256})
