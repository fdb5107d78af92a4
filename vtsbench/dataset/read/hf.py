"""`View.to_hf`: a Hugging Face `datasets` view of a vtsbench view, streamed from the Zarr store.

By default a `datasets.IterableDataset` whose generator reads the view a few samples per zarr
call: nothing is copied, and iterating it yields numpy arrays of the stored dtypes (rgb uint8,
depth float32 mm, contact bool) with the index columns. `copy=True` writes a `datasets.Dataset`
instead (Arrow files under `cache_dir`, a few rows per write because a slip row holds
megabytes); `.with_format("numpy", dtype=None)` reads it back without datasets' widening of
integer arrays to int64.

`hub_arrays(row)` is the other direction: a row of the dataset's own Hugging Face copy
(`vtsbench export-hf`, read by `datasets.load_dataset`) as the loader's arrays, depth in mm.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import datasets
import numpy as np

from ..format.arrays import depth_to_mm
from ..format.layout import DECODED_DTYPES, DEPTH_SCALE_MM
from .arrays import ITER_BYTES

if TYPE_CHECKING:
    from .view import View

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
        feats[name] = _ARRAY_FEATURES[len(shape)](shape=shape, dtype=DECODED_DTYPES[name])
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


def to_hf(view: View, arrays: Sequence[str] | None = None, *, copy: bool = False,
          writer_batch_size: int = 8, cache_dir: str | os.PathLike | None = None
          ) -> datasets.IterableDataset | datasets.Dataset:
    """The view's samples (index columns + arrays, default: every array the dataset has) as a
    datasets.IterableDataset streamed from the Zarr store, or with copy=True a
    datasets.Dataset written offline under cache_dir."""
    arrays = view.arrays if arrays is None else tuple(arrays)
    from .arrays import check_arrays

    check_arrays(view.dataset.info, arrays)
    feats = features(view, arrays)
    per = max(1, view.nbytes(arrays)) if arrays else 1
    batch = max(1, min(writer_batch_size, ITER_BYTES // per))
    kwargs = {"view": view, "arrays": arrays, "batch": batch,
              "dataset_sha256": view.dataset.info.dataset_sha256}
    if not copy:
        return datasets.IterableDataset.from_generator(_rows, features=feats, gen_kwargs=kwargs)
    if not len(view):
        return datasets.Dataset.from_dict({k: [] for k in feats}, features=feats)
    return datasets.Dataset.from_generator(
        _rows, features=feats, writer_batch_size=writer_batch_size,
        cache_dir=None if cache_dir is None else str(cache_dir), gen_kwargs=kwargs)


def hub_arrays(row: Mapping[str, Any], depth_scale_mm: float = DEPTH_SCALE_MM
               ) -> dict[str, np.ndarray]:
    """The arrays of a row of the Hugging Face copy as the loader gives them: rgb uint8
    ((T,) H, W, 3), depth float32 mm (the stored int16 counts x depth_scale_mm, the scale in
    info.json and the card: equal to the loader's, bit for bit), contact bool; from a row in
    the numpy format or with PIL images (the default format), of layout version 2 (depth as
    16-bit images of the counts) or 1 (depth already in mm). Only the arrays the row has."""
    out = {}
    for name in ("rgb", "depth", "contact"):
        if name not in row:
            continue
        v = row[name]
        a = np.stack([np.asarray(f) for f in v]) if isinstance(v, list | tuple) else np.asarray(v)
        if name == "depth" and a.dtype == np.uint16:  # the int16 counts' bits
            a = depth_to_mm(a.view(np.int16))
            if depth_scale_mm != DEPTH_SCALE_MM:
                a *= np.float32(depth_scale_mm / DEPTH_SCALE_MM)
        out[name] = a.astype(DECODED_DTYPES[name], copy=False)
    return out
