"""Open a built dataset: `load(path_or_url)` -> VtsDataset, its views, samples and batch reads.

Loading reads only meta/info.json and the two parquet indexes; split files are read (and checked
against their sha256 in info.json) when first used, and the Zarr arrays are opened on the first
read in each process. Views therefore pickle small (no open handle), which is what DataLoader
workers need, and reading one split or one object touches only those samples' chunks. Where
the samples are views of the episode store (format 1.3, info.json sample_storage "episodes"),
a static or slip sample's arrays are its frames of that store (index columns episode_index
and frame_row), read through the episodes (`EpisodeData.read_frames`): there is no
data/static.zarr or data/slip.zarr to open.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import zarr

from ...errors import VtsError
from ..format.arrays import depth_to_mm, zarr_problems
from ..format.index import (
    counts_problems,
    ids_problems,
    read_index,
    store_rows,
    view_problems,
)
from ..format.info import DatasetInfo, load_info
from ..format.layout import (
    DECODED_DTYPES,
    DEPTH_SCALE_MM,
    EPISODES,
    INDEX_DIR,
    INFO_PATH,
    KINDS,
    group_path,
    index_path,
    split_path,
)
from ..format.problems import short
from ..format.records import SplitFile, part_key
from ..splits.episodes import EPISODE, split_table
from ..splits.files import dataset_split_limits, read_split
from ..splits.leaks import split_problems
from . import store
from .arrays import check_arrays
from .location import Location
from .view import View

if TYPE_CHECKING:
    import pyarrow as pa

    from .episodes import EpisodeData, Episodes


class KindStore:
    """One kind's index (pyarrow Table) and its Zarr arrays, opened lazily once per process;
    or, where the samples are views of the episode store (format 1.3), the episodes whose
    frames they are (`episodes`, set by the dataset)."""

    def __init__(self, loc: Location, kind: str, info: DatasetInfo, table: pa.Table) -> None:
        self.loc, self.kind, self.info, self.table = loc, kind, info, table
        self.rows = table.column("row").to_numpy().astype(np.int64)
        self.metadata_checked = False
        views = info.views and kind in KINDS and "frame_row" in table.column_names
        #: format 1.3: each sample's first frame row in the episode store, by sample row
        self.frame_row = (table.column("frame_row").to_numpy().astype(np.int64) if views
                          else None)
        self.episodes: EpisodeData | None = None
        self._reset()

    def _reset(self) -> None:
        self._pid: int | None = None
        self._group: Any = None
        self._arrays: dict[str, Any] = {}
        self._cols: dict[str, list[Any]] | None = None
        self._pos_of: dict[str, int] | None = None

    def __getstate__(self) -> dict[str, Any]:
        keep = ("loc", "kind", "info", "table", "rows", "metadata_checked", "frame_row",
                "episodes")
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
        if self.frame_row is not None:
            raise VtsError(f"the {self.kind} samples are views of the episode store (format "
                           f"{self.info.format_version}): no {group_path(self.kind)} to open",
                           self.loc.url)
        if self._pid != os.getpid():
            self._pid, self._group, self._arrays = os.getpid(), None, {}
        if name not in self._arrays:
            if self._group is None:
                group = _open_group(self.loc.url, self.kind, self.loc.storage_options)
                if not self.metadata_checked:
                    self._agrees()
                    self.metadata_checked = True
                strict = store.StrictStore(group.store,
                                           store.group_location(self.loc.url, self.kind))
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
        """Refuse Zarr metadata that contradicts info.json or itself (`zarr_problems`, as
        verify): metadata changed after the build would otherwise read as wrong numbers."""
        from ...jsonio import loads

        base = group_path(self.kind)

        def doc(rel: str) -> Any:
            return loads(self.loc.read_bytes(rel), self.loc.path(rel), "Zarr metadata")

        group = doc(f"{base}/zarr.json")
        arrays = {n: doc(f"{base}/{n}/zarr.json") for n in self.info.arrays}
        bad = zarr_problems(self.info, self.kind, group, arrays)
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
        return sum(int(np.prod(shapes[n][1:])) * np.dtype(DECODED_DTYPES[n]).itemsize
                   for n in names)

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
        if self.frame_row is not None:
            return self._read_views(np.asarray(rows, np.int64), names, frames)
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

    def _read_views(self, rows: np.ndarray, names: Sequence[str],
                    frames: np.ndarray | None) -> dict[str, np.ndarray]:
        """Arrays of samples that are views of the episode store (format 1.3): the store
        rows of their frames (frame_row + 0..T-1, or the `frames` asked for) read in one
        batched call through the episodes, each row once, then shaped (n, [T,] H, W[, 3])."""
        assert self.frame_row is not None
        if self.episodes is None:
            raise VtsError(f"the {self.kind} samples are views of the episode store, and it is "
                           "not open (read them from vtsbench.load)", self.loc.url)
        want = store_rows(self.frame_row[rows], self.kind, self.info.frames_per_sequence, frames)
        data = self.episodes.read_frames(want.reshape(-1), names)
        lead = want.shape if self.kind == "slip" else (len(rows),)
        return {n: a.reshape(*lead, *a.shape[1:]) for n, a in data.items()}



def _open_group(url: str, kind: str, storage_options: dict[str, Any] | None) -> Any:
    """A kind's Zarr group, or the frames store of the episodes (format 1.2)."""
    if kind == EPISODES:
        from .episodes import open_frames_group

        return open_frames_group(url, storage_options)
    return store.open_group(url, kind, storage_options)


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
    mm = depth_to_mm(counts)
    if scale_mm != DEPTH_SCALE_MM:
        mm *= np.float32(scale_mm / DEPTH_SCALE_MM)
    return mm


class VtsDataset:
    """A loaded dataset: info, the static and slip views, and its split files.

    allow_leaks=True uses a split whose parts share samples or values their disjoint rules
    keep apart (refused by default, as `vtsbench verify` reports it)."""

    def __init__(self, loc: Location, info: DatasetInfo, tables: Mapping[str, pa.Table],
                 allow_leaks: bool = False) -> None:
        self.loc, self.info, self.allow_leaks = loc, info, allow_leaks
        self._kinds = {k: KindStore(loc, k, info, tables[k]) for k in KINDS}
        self._splits: dict[str, SplitFile] = {}
        if info.views:  # format 1.3: the samples read their frames from the episodes
            data = self.episodes.data
            for ks in self._kinds.values():
                ks.episodes = data

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
        """A split file, read once and checked as verify checks it (`split_problems`):
        its sha256 in info.json, its size and id count against the index, ids known, part sizes,
        and no leak between parts unless the dataset was loaded with allow_leaks=True."""
        if name not in self.info.splits:
            raise VtsError(f"unknown split {short(name, 80)!r}; splits: "
                           f"{', '.join(self.splits) or 'none'}")
        if name not in self._splits:
            rel = split_path(name)
            max_bytes, max_ids = dataset_split_limits(self.info)
            split = self.loc.checked(rel, functools.partial(
                read_split, expected_sha256=self.info.splits[name], max_bytes=max_bytes,
                max_ids=max_ids))
            tables = {k: ks.table for k, ks in self._kinds.items()}
            if split.kind == EPISODE:  # a split of episodes: their ids, objects, sessions
                tables[EPISODE] = split_table(self.episodes.index)
            bad, leaks = split_problems(split, name, self.info, tables)
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
        return sorted(self.split_file(name).parts, key=part_key)

    def _part_positions(self, split: SplitFile, part: str) -> np.ndarray:
        """Sorted index positions of a split part's samples."""
        if part not in split.parts:
            raise VtsError(f"split {split.name!r} has no part {part!r}; parts: "
                           f"{', '.join(sorted(split.parts, key=part_key))}")
        import pyarrow as pa
        import pyarrow.compute as pc

        ids = pa.array(split.parts[part], pa.string())
        index = self._kinds[split.kind].table.column("sample_id").combine_chunks()
        pos = np.asarray(pc.fill_null(pc.index_in(ids, value_set=index), -1), np.int64)
        missing = ids.filter(pa.array(pos < 0))
        if len(missing):
            raise VtsError(f"split {split.name!r} part {part!r}: {len(missing)} sample id(s) "
                           f"not in {index_path(split.kind)} (first "
                           f"{short(missing[0].as_py(), 80)!r})",
                           self.loc.path(split_path(split.name)))
        return np.sort(pos)

    def split(self, name: str, part: str) -> View:
        """The samples of one part of a split, from the kind the split is made of."""
        split = self.split_file(name)
        if split.kind == EPISODE:
            raise VtsError(f"split {name!r} is a split of episodes: "
                           f"ds.episodes.split({name!r}, {short(part, 80)!r})")
        return View(self, split.kind, self._part_positions(split, part))

    @property
    def episodes(self) -> Episodes:
        """The continuous takes stored once (format 1.2) and their windows, chosen when
        reading (`windows(...)`); none (length 0) in a dataset without episodes."""
        if "_episodes" not in self.__dict__:
            from .episodes import open_episodes

            self._episodes = open_episodes(self.loc, self.info, KindStore, self.split_file)
        return self._episodes

    def by_id(self, sample_id: str, arrays: Sequence[str] | None = None) -> dict[str, Any]:
        """A sample of either kind by id."""
        for kind in KINDS:
            if self._kinds[kind].position(sample_id) is not None:
                return self.view(kind).by_id(sample_id, arrays)
        raise VtsError(f"unknown sample id {sample_id!r}")


def load(path_or_url: str | os.PathLike, *,
         storage_options: Mapping[str, Any] | None = None,
         allow_leaks: bool = False) -> VtsDataset:
    """Open a vtsbench dataset from a folder or an fsspec URL (http://, s3://, memory://, ...).

    Reads meta/info.json (refusing an unknown format major version) and the two indexes
    (`format.index.read_index`, fetched whole from a URL), with format 1.2 the episode and frame
    indexes (`ds.episodes`), with format 1.3 every sample's frames inside its episode
    (`format.index.view_problems`), and checks them as `vtsbench verify` does; split files are
    checked when first used (`splits.leaks.split_problems`), the Zarr metadata on the first
    read (`format.arrays.zarr_problems`). A split that leaks (a sample in two parts, parts
    sharing an object, session or location their rules keep apart, or with format 1.3 a frame
    of the episode store) is refused unless allow_leaks=True. storage_options go to fsspec
    for URLs.
    """
    loc = Location(path_or_url, storage_options)
    if not loc.remote and not Path(loc.url).is_dir():
        raise VtsError("no such dataset folder", loc.url)
    info = loc.checked(INFO_PATH, load_info)
    tables = {}
    for kind in KINDS:
        rel = index_path(kind)
        source = loc.read_bytes(rel, "index not found") if loc.remote else loc.path(rel)
        tables[kind] = read_index(source, kind, info, where=loc.path(rel))
    bad = ids_problems(tables)
    if bad:
        raise VtsError(bad[0], loc.path(INDEX_DIR))
    bad = counts_problems(info, tables)
    if bad:
        raise VtsError(bad[0], loc.path(INFO_PATH))
    ds = VtsDataset(loc, info, tables, allow_leaks)
    if info.episodes is not None:
        ds.episodes  # noqa: B018 (read and checked now, as the indexes are)
    if info.views:  # every sample's frames inside its episode
        data = ds.episodes.data
        for kind in KINDS:
            bad = view_problems(tables[kind], kind, info.frames_per_sequence, data.starts,
                                data.lengths)
            if bad:
                more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
                raise VtsError(f"{bad[0]}{more}", loc.path(index_path(kind)))
    return ds
