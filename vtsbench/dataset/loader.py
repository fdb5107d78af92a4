"""Open a built dataset: `load(path_or_url)` -> VtsDataset, its views, samples and batch reads.

Loading reads only meta/info.json and the two parquet indexes; split files are read (and checked
against their sha256 in info.json) when first used, and the Zarr arrays are opened on the first
read in each process. Views therefore pickle small (no open handle), which is what DataLoader
workers need, and reading one split or one object touches only those samples' chunks.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import zarr
from zarr.storage import WrapperStore

from ..errors import VtsError
from . import store, validate
from .arrays import ITER_BYTES, check_arrays
from .location import Location
from .schema import INFO_PATH, KINDS, DatasetInfo, SplitFile, load_info
from .splits import read_split

if TYPE_CHECKING:
    import datasets
    import pyarrow as pa
    import torch.utils.data

ARRAYS = store.ARRAYS


class SampleIndexError(VtsError, IndexError):
    """A position outside a view: a one-line VtsError that is also an IndexError."""


class StrictStore(WrapperStore):
    """A read-only zarr store on which a missing chunk or shard is an error, never fill values
    (an incomplete copy of a dataset must not read as zeros)."""

    def __init__(self, store: Any, location: str) -> None:
        super().__init__(store)
        self.location = location

    def _with_store(self, store: Any) -> StrictStore:
        return type(self)(store, self.location)

    async def get(self, key: str, prototype: Any, byte_range: Any = None) -> Any:
        if "://" not in self.location:  # a local file must be a regular one of bounded size
            import stat

            try:
                st = os.stat(Path(self.location) / key)
            except OSError:
                st = None
            if st is not None and (not stat.S_ISREG(st.st_mode) or st.st_size > 4 << 30):
                raise VtsError("not a regular file of at most 4 GiB (a link to a device?)",
                               f"{self.location}/{key}")
        buf = await self._store.get(key, prototype, byte_range)
        if buf is None and "/c/" in key:
            raise VtsError("missing (an incomplete copy of the dataset?)",
                           f"{self.location}/{key}")
        return buf


class KindStore:
    """One kind's index (pyarrow Table) and its Zarr arrays, opened lazily once per process."""

    def __init__(self, loc: Location, kind: str, info: DatasetInfo, table: pa.Table) -> None:
        self.loc, self.kind, self.info, self.table = loc, kind, info, table
        self.rows = table.column("row").to_numpy().astype(np.int64)
        self.metadata_checked = False
        self._reset()

    def _reset(self) -> None:
        self._pid: int | None = None
        self._group: Any = None
        self._arrays: dict[str, Any] = {}
        self._cols: dict[str, list[Any]] | None = None
        self._pos_of: dict[str, int] | None = None

    def __getstate__(self) -> dict[str, Any]:
        keep = ("loc", "kind", "info", "table", "rows", "metadata_checked")
        return {k: self.__dict__[k] for k in keep}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset()

    @property
    def columns(self) -> dict[str, list[Any]]:
        """The index as Python lists per column (built once)."""
        if self._cols is None:
            self._cols = self.table.to_pydict()
        return self._cols

    def position(self, sample_id: str) -> int | None:
        """Position in the index of a sample id, or None."""
        if self._pos_of is None:
            self._pos_of = {s: i for i, s in enumerate(self.columns["sample_id"])}
        return self._pos_of.get(sample_id)

    def array(self, name: str) -> Any:
        """A zarr array of this kind, opened on first use in this process."""
        if self._pid != os.getpid():
            self._pid, self._group, self._arrays = os.getpid(), None, {}
        if name not in self._arrays:
            if self._group is None:
                group = store.open_group(self.loc.url, self.kind, self.loc.storage_options)
                if not self.metadata_checked:
                    self._agrees()
                    self.metadata_checked = True
                strict = StrictStore(group.store, store.group_location(self.loc.url, self.kind))
                self._group = zarr.open_group(strict, mode="r", use_consolidated=True)
            try:
                arr = self._group[name]
            except Exception as e:  # a changed zarr.json
                raise VtsError(f"cannot open the array ({type(e).__name__}); run `vtsbench "
                               "verify`", f"{store.group_location(self.loc.url, self.kind)}/"
                               f"{name}") from None
            self._arrays[name] = arr
        return self._arrays[name]

    def _agrees(self) -> None:
        """Refuse Zarr metadata that contradicts info.json or itself (`validate.zarr_problems`,
        as verify): metadata changed after the build would otherwise read as wrong numbers."""
        from ..jsonio import loads

        base = f"data/{self.kind}.zarr"

        def doc(rel: str) -> Any:
            return loads(self.loc.read_bytes(rel), self.loc.path(rel), "Zarr metadata")

        group = doc(f"{base}/zarr.json")
        arrays = {n: doc(f"{base}/{n}/zarr.json") for n in self.info.arrays}
        bad = validate.zarr_problems(self.info, self.kind, group, arrays)
        if bad:
            more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
            raise VtsError(f"{bad[0]}{more}; run `vtsbench verify`",
                           store.group_location(self.loc.url, self.kind))

    def _decode_error(self, name: str, runs: list[tuple[int, int]], err: Exception) -> VtsError:
        """The error of a chunk that does not decode, naming the shard file and the sample."""
        arr = self.array(name)
        sps = int(arr.shards[0]) if arr.shards else 1
        for a, b in runs:
            for r in range(a, b):
                try:
                    arr[r]
                except Exception:
                    ids = self.columns["sample_id"]
                    pos = np.flatnonzero(self.rows == r)
                    sid = ids[int(pos[0])] if len(pos) else "?"
                    return VtsError(f"sample {sid} (row {r}) does not decode "
                                    f"({type(err).__name__}: damaged shard; run "
                                    "`vtsbench verify`)",
                                    f"{store.group_location(self.loc.url, self.kind)}/{name}/c/"
                                    f"{r // sps}/" + "/".join("0" * (arr.ndim - 1)))
        return VtsError(f"does not decode ({type(err).__name__})",
                        f"{store.group_location(self.loc.url, self.kind)}/{name}")

    def sample_nbytes(self, names: Sequence[str]) -> int:
        """Decoded bytes of one sample's arrays (depth as float32)."""
        shapes = self.info.shapes[self.kind]
        per = {"rgb": 1, "depth": 4, "contact": 1}
        return sum(int(np.prod(shapes[n][1:])) * per[n] for n in names)

    def meta(self, pos: int) -> dict[str, Any]:
        """The index fields of a sample, named as in schemas/sample.schema.json."""
        c = self.columns
        slip = self.kind == "slip"

        def pair(a: str, b: str) -> tuple[float, float] | None:
            x, y = c[a][pos], c[b][pos]
            return None if x is None or y is None else (x, y)

        return {
            "sample_id": c["sample_id"][pos], "kind": self.kind, "object": c["object"][pos],
            "class_idx": c["class_idx"][pos], "session": c["session"][pos],
            "sensor": c["sensor"][pos], "mm_per_px": pair("mm_per_px_x", "mm_per_px_y"),
            "press_depth_mm": c["press_depth_mm"][pos],
            "contact_px": pair("contact_x_px", "contact_y_px"),
            "state": c["state"][pos] if slip else None,
            "state_idx": c["state_idx"][pos] if slip else None,
            "direction": c["direction"][pos] if slip else None,
            "motion_mm": pair("motion_dx_mm", "motion_dy_mm") if slip else None,
            "source": c["source"][pos],
        }

    def read(self, rows: np.ndarray, names: Sequence[str],
             frames: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Arrays of Zarr rows (any order, repeats allowed), one zarr call per contiguous run."""
        check_arrays(self.info, names)
        if frames is not None and self.kind != "slip":
            raise VtsError("frames apply to slip sequences only")
        uniq, inverse = np.unique(rows, return_inverse=True)
        cuts = np.flatnonzero(np.diff(uniq) != 1) + 1
        runs = [(int(r[0]), int(r[-1]) + 1) for r in np.split(uniq, cuts) if len(r)]
        ordered = len(uniq) == len(rows) and bool(np.all(np.diff(rows) > 0))
        out = {}
        for n in names:
            try:
                data = _read_runs(self.array(n), runs, len(uniq), frames)
            except VtsError:
                raise
            except Exception as e:  # zarr's checksum or codec error, with no file or sample
                raise self._decode_error(n, runs, e) from None
            if not ordered:
                data = data[inverse.reshape(-1)]
            if n == "depth":
                data = _depth_mm(data, self.info.depth_scale_mm)
            out[n] = data
        return out



def _read_runs(arr: Any, runs: list[tuple[int, int]], n: int,
               frames: np.ndarray | None) -> np.ndarray:
    """Rows of a zarr array given as contiguous runs [a, b): one call per run."""
    def get(a: int, b: int) -> np.ndarray:
        # A chunk is a whole sample, so frames cost the same decoding either way; numpy picks
        # them (zarr's orthogonal selection with an index array measured 25x slower).
        return arr[a:b] if frames is None else arr[a:b][:, frames]

    if len(runs) == 1:
        return get(*runs[0])
    first = get(*runs[0])
    out = np.empty((n, *first.shape[1:]), first.dtype)
    out[:len(first)] = first
    i = len(first)
    for a, b in runs[1:]:
        out[i:i + b - a] = get(a, b)
        i += b - a
    return out


def _depth_mm(counts: np.ndarray, scale_mm: float) -> np.ndarray:
    """Stored depth counts -> float32 mm, with the scale info.json gives."""
    mm = store.depth_to_mm(counts)
    if scale_mm != store.DEPTH_SCALE_MM:
        mm *= np.float32(scale_mm / store.DEPTH_SCALE_MM)
    return mm


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
                 target_transform: Any = None) -> torch.utils.data.Dataset:
        """A torch Dataset of (tensor, target dict); `transforms` sees the whole sample as one
        dict, `transform` the tensor, `target_transform` the target; see
        vtsbench.dataset.torch_dataset."""
        try:
            from .torch_dataset import TorchView
        except ModuleNotFoundError as e:
            raise VtsError(f"to_torch needs {e.name!r}: pip install 'vtsbench[torch]'") from None

        return TorchView(self, modality=modality, size=size, frames=frames, transform=transform,
                         targets=targets, transforms=transforms,
                         target_transform=target_transform)

    def to_hf(self, arrays: Sequence[str] | None = None, *, copy: bool = False,
              writer_batch_size: int = 8, cache_dir: str | os.PathLike | None = None
              ) -> datasets.IterableDataset | datasets.Dataset:
        """Index rows plus arrays (default: all the dataset has) as a Hugging Face
        datasets.IterableDataset streamed from the Zarr store, or a datasets.Dataset written
        under cache_dir with copy=True; see dataset.hf."""
        from .hf import to_hf

        return to_hf(self, arrays=self.arrays if arrays is None else arrays, copy=copy,
                     writer_batch_size=writer_batch_size, cache_dir=cache_dir)

    def plot(self, sample: Mapping[str, Any], frame: int = -1) -> Any:
        """A matplotlib Figure of one sample of this view (a dict as `view[i]` gives): RGB,
        depth and contact of one frame (default the last) with its labels."""
        from .plot import plot_sample

        return plot_sample(sample, self._ds.info, frame=frame)


def _part_key(part: str) -> tuple[int, int, str]:
    """Sort key of part names: train, val, test, then folds by number."""
    if part in ("train", "val", "test"):
        return (0, ("train", "val", "test").index(part), part)
    digits = part.removeprefix("fold")
    return (1, int(digits), part) if digits.isdigit() else (2, 0, part)


def _dtype(name: str) -> np.dtype:
    return np.dtype({"rgb": np.uint8, "depth": np.float32, "contact": bool}[name])


class VtsDataset:
    """A loaded dataset: info, the static and slip views, and its split files.

    allow_leaks=True uses a split whose parts share samples or values their disjoint rules
    keep apart (refused by default, as `vtsbench verify` reports it)."""

    def __init__(self, loc: Location, info: DatasetInfo, tables: Mapping[str, pa.Table],
                 allow_leaks: bool = False) -> None:
        self.loc, self.info, self.allow_leaks = loc, info, allow_leaks
        self._kinds = {k: KindStore(loc, k, info, tables[k]) for k in KINDS}
        self._splits: dict[str, SplitFile] = {}

    def __repr__(self) -> str:
        return (f"VtsDataset({self.info.name!r} {self.info.dataset_version}, "
                f"{len(self.static)} static, {len(self.slip)} slip, {self.location})")

    @property
    def location(self) -> str:
        """The folder or URL it was loaded from."""
        return self.loc.url

    @property
    def arrays(self) -> tuple[str, ...]:
        """The arrays it holds: rgb, depth and contact, or rgb alone (built with --no-depth)."""
        return self.info.arrays

    def view(self, kind: str) -> View:
        """Every sample of one kind ("static" or "slip")."""
        if kind not in KINDS:
            raise VtsError(f"unknown kind {kind!r}; kinds are {', '.join(KINDS)}")
        return View(self, kind, np.arange(len(self._kinds[kind].rows)))

    @property
    def static(self) -> View:
        """Every static sample (one frame each)."""
        return self.view("static")

    @property
    def slip(self) -> View:
        """Every slip sample (a sequence of T frames each)."""
        return self.view("slip")

    @property
    def splits(self) -> list[str]:
        """Names of the split files info.json lists."""
        return sorted(self.info.splits)

    def split_file(self, name: str) -> SplitFile:
        """A split file, read once and checked as verify checks it (`validate.split_problems`):
        its sha256 in info.json, its size and id count against the index, ids known, part sizes,
        and no leak between parts unless the dataset was loaded with allow_leaks=True."""
        if name not in self.info.splits:
            raise VtsError(f"unknown split {_short(name)!r}; splits: "
                           f"{', '.join(self.splits) or 'none'}")
        if name not in self._splits:
            rel = f"meta/splits/{name}.json"
            max_bytes, max_ids = validate.split_limits(sum(len(k.rows)
                                                           for k in self._kinds.values()))
            split = self.loc.checked(rel, functools.partial(
                read_split, expected_sha256=self.info.splits[name], max_bytes=max_bytes,
                max_ids=max_ids))
            tables = {k: ks.table for k, ks in self._kinds.items()}
            bad, leaks = validate.split_problems(split, name, self.info, tables)
            if leaks and not self.allow_leaks:
                bad.append(f"leak: {leaks[0]}" + (f" (and {len(leaks) - 1} more)"
                                                  if len(leaks) > 1 else "")
                           + "; vtsbench.load(..., allow_leaks=True) uses it anyway")
            if bad:
                more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
                raise VtsError(f"{bad[0]}{more}", self.loc.path(rel))
            self._splits[name] = split
        return self._splits[name]

    def parts(self, name: str) -> list[str]:
        """Part names of a split: train, val, test, or fold0, fold1, ..."""
        return sorted(self.split_file(name).parts, key=_part_key)

    def _part_positions(self, split: SplitFile, part: str) -> np.ndarray:
        """Sorted index positions of a split part's samples."""
        if part not in split.parts:
            raise VtsError(f"split {split.name!r} has no part {part!r}; parts: "
                           f"{', '.join(sorted(split.parts, key=_part_key))}")
        import pyarrow as pa
        import pyarrow.compute as pc

        ids = pa.array(split.parts[part], pa.string())
        index = self._kinds[split.kind].table.column("sample_id").combine_chunks()
        pos = np.asarray(pc.fill_null(pc.index_in(ids, value_set=index), -1), np.int64)
        missing = ids.filter(pa.array(pos < 0))
        if len(missing):
            raise VtsError(f"split {split.name!r} part {part!r}: {len(missing)} sample id(s) "
                           f"not in index/{split.kind}.parquet (first "
                           f"{_short(missing[0].as_py())!r})",
                           self.loc.path(f"meta/splits/{split.name}.json"))
        return np.sort(pos)

    def split(self, name: str, part: str) -> View:
        """The samples of one part of a split, from the kind the split is made of."""
        split = self.split_file(name)
        return View(self, split.kind, self._part_positions(split, part))

    def by_id(self, sample_id: str, arrays: Sequence[str] | None = None) -> dict[str, Any]:
        """A sample of either kind by id."""
        for kind in KINDS:
            if self._kinds[kind].position(sample_id) is not None:
                return self.view(kind).by_id(sample_id, arrays)
        raise VtsError(f"unknown sample id {sample_id!r}")


def _read_index(loc: Location, kind: str, info: DatasetInfo) -> pa.Table:
    """index/<kind>.parquet as a Table, checked as verify checks it (`validate.index_problems`:
    schema, rows 0..N-1 in order, objects and class_idx, values); read whole for URLs."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..jsonio import regular_file

    rel = f"index/{kind}.parquet"
    if not loc.remote:
        regular_file(loc.path(rel), "index")  # a folder, a FIFO or a device is said as such
    try:
        if loc.remote:
            table = pq.read_table(pa.BufferReader(loc.read_bytes(rel, "index not found")))
        else:
            table = pq.read_table(loc.path(rel))
    except FileNotFoundError:
        raise VtsError("index not found", loc.path(rel)) from None
    except pa.ArrowException as e:
        raise VtsError(f"not a readable parquet file ({e})", loc.path(rel)) from None
    bad = validate.index_problems(table, kind, info)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise VtsError(f"{bad[0]}{more}", loc.path(rel))
    return table


def _short(text: str, n: int = 80) -> str:
    return text if len(text) <= n else text[:n] + "..."


def load(path_or_url: str | os.PathLike, *,
         storage_options: Mapping[str, Any] | None = None,
         allow_leaks: bool = False) -> VtsDataset:
    """Open a vtsbench dataset from a folder or an fsspec URL (http://, s3://, memory://, ...).

    Reads meta/info.json (refusing an unknown format major version) and the two indexes, and
    checks them as `vtsbench verify` does (vtsbench.dataset.validate); split files are checked
    when first used, the Zarr metadata on the first read. A split that leaks (a sample in two
    parts, or parts sharing an object, session or location their rules keep apart) is refused
    unless allow_leaks=True. storage_options go to fsspec for URLs.
    """
    loc = Location(path_or_url, storage_options)
    if not loc.remote and not Path(loc.url).is_dir():
        raise VtsError("no such dataset folder", loc.url)
    info = loc.checked(INFO_PATH, load_info)
    tables = {k: _read_index(loc, k, info) for k in KINDS}
    bad = validate.ids_problems(tables)
    if bad:
        raise VtsError(bad[0], loc.path("index"))
    bad = validate.counts_problems(info, tables)
    if bad:
        raise VtsError(bad[0], loc.path(INFO_PATH))
    return VtsDataset(loc, info, tables, allow_leaks)
