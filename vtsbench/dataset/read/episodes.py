"""Episodes of a loaded dataset (format 1.2): `ds.episodes`, the continuous takes stored once,
and `ds.episodes.windows(...)`, clips of them chosen when reading.

A window is T frame numbers of one episode (never two): T consecutive frames every `stride`
frames (`length`), or the frames nearest to offsets in seconds from an anchor frame
(`delta_timestamps`, as LeRobot's): each offset takes the frame within half a frame period of
anchor time + offset, else the nearest frame marked in `pad_mask` (pad="edge") or no window
at that anchor (pad="drop"). Windows are index arithmetic on `index/frames.parquet`'s
timestamps: nothing is read until a window is, and `read(items)` reads many windows' frames
in one batched call (the loader's run-based read of the Zarr store, each frame read once).
Labels come as int8 arrays with -1 where unknown (state: index in labels.STATES).
`split(name, part)` is the episodes of one part of a split of episodes (splits/episodes.py):
its windows are windows of those episodes only, so no window leaks across parts.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ..format.episodes import (
    FRAME_COLUMNS,
    check_tables,
    episodes_arrow_schema,
    frames_arrow_schema,
    read_table,
)
from ..format.layout import DECODED_DTYPES, EPISODES, EPISODES_GROUP, EPISODES_INDEX, FRAMES_INDEX
from ..format.records import part_key
from ..splits.episodes import EPISODE
from .arrays import ITER_BYTES, check_arrays
from .episode_video import episode_videos

if TYPE_CHECKING:
    import pyarrow as pa
    import torch.utils.data

    from ..format.info import DatasetInfo
    from ..format.records import SplitFile
    from .loader import KindStore
    from .location import Location

PADS = ("drop", "edge")
#: Keys of a batch that a single window takes from its episode's row instead.
_ROW_KEYS = ("episode_index", "episode_id")
#: The most frames a window may hold, and offsets one may take.
MAX_WINDOW = 100_000


def open_frames_group(root: str | os.PathLike, storage_options: dict[str, Any] | None = None
                      ) -> Any:
    """data/episodes.zarr of a dataset, read-only, from a path or an fsspec URL (opened as the
    static and slip groups are)."""
    from .store import open_group_at

    return open_group_at(f"{str(root).rstrip('/')}/{EPISODES_GROUP}", storage_options)


def read_tables(loc: Location, info: DatasetInfo) -> tuple[pa.Table, pa.Table]:
    """index/episodes.parquet and index/frames.parquet, checked against each other and
    info.json (empty tables for a dataset without episodes)."""
    import pyarrow as pa

    if info.episodes is None:
        return (episodes_arrow_schema().empty_table(), frames_arrow_schema().empty_table())
    tables = []
    for rel, which in ((EPISODES_INDEX, "episodes"), (FRAMES_INDEX, "frames")):
        source = loc.read_bytes(rel, "index not found") if loc.remote else loc.path(rel)
        tables.append(read_table(source, which, where=loc.path(rel)))
    episodes, frames = tables
    check_tables(episodes, frames, info, loc.path(EPISODES_INDEX))
    assert isinstance(episodes, pa.Table)
    return episodes, frames


def store_table(episodes: pa.Table, frames: pa.Table) -> pa.Table:
    """The frames store's rows as the loader's KindStore takes them: `row` and an id
    `<episode id>/<frame index>` (named in read errors)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    ids = episodes.column("episode_id").take(frames.column("episode_index"))
    names = pc.binary_join_element_wise(ids, pc.cast(frames.column("frame_index"),
                                                     pa.string()), "/")
    return pa.table({"row": pa.array(np.arange(len(frames), dtype=np.int64)),
                     "sample_id": names})


def open_episodes(loc: Location, info: DatasetInfo, store_class: type[KindStore],
                  split_file: Callable[[str], SplitFile] | None = None) -> Episodes:
    """Every episode of a dataset (the loader's `ds.episodes`); store_class: the loader's
    KindStore, which reads the frames store; split_file: the loader's reader of a checked
    split file (for `split`)."""
    episodes, frames = read_tables(loc, info)
    store = store_class(loc, EPISODES, info, store_table(episodes, frames))
    data = EpisodeData(episodes, frames, store)
    data.split_file = split_file
    return Episodes(data, np.arange(len(episodes), dtype=np.int64))


def _labels(frames: pa.Table, name: str) -> np.ndarray:
    import pyarrow.compute as pc

    return np.asarray(pc.fill_null(frames.column(name), -1)).astype(np.int8)


class EpisodeData:
    """What a dataset's episodes are read from: both tables, their columns as numpy arrays
    and the frames store."""

    def __init__(self, episodes: pa.Table, frames: pa.Table, store: KindStore) -> None:
        self.episodes, self.frames, self.store = episodes, frames, store
        self.starts = episodes.column("frame_start").to_numpy().astype(np.int64)
        self.lengths = episodes.column("length").to_numpy().astype(np.int64)
        self.fps = episodes.column("fps").to_numpy().astype(np.float64)
        self.timestamps = frames.column("timestamp").to_numpy().astype(np.float64)
        self.state = _labels(frames, "state")
        self.direction = _labels(frames, "direction")
        self.extra = {n: frames.column(n).to_numpy(zero_copy_only=False)
                      for n in frames.column_names[len(FRAME_COLUMNS):]}
        self.rows = episodes.to_pylist()
        self.split_file: Callable[[str], SplitFile] | None = None
        #: the episodes' videos where their RGB is stored so (None: in the Zarr store)
        self.videos = episode_videos(store, self.starts, self.lengths)

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the loader's split reader (a worker reads windows, not splits)."""
        return {**self.__dict__, "split_file": None}

    def read_frames(self, rows: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
        """Arrays of frame rows of the store (any order, repeats allowed; depth in mm), each
        row read once in one batched call: the one read of frames that the samples viewing
        this store (format 1.3) go through; rgb decoded from the episodes' videos where the
        dataset stores it so (read/episode_video.py)."""
        rows = np.asarray(rows, np.int64).reshape(-1)
        if self.videos is not None and "rgb" in names:
            return self.videos.read_with(self.store, rows, names)
        return self.store.read(rows, names)

    def per_frame(self, rows: np.ndarray) -> dict[str, Any]:
        """Timestamps, labels and extra values of frame rows (any shape)."""
        out = {"timestamps": self.timestamps[rows], "state": self.state[rows],
               "direction": self.direction[rows]}
        return {**out, **{n: v[rows] for n, v in self.extra.items()}}


def _as_int(value: Any, what: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not (
            low <= int(value) <= high):
        raise VtsError(f"{what} must be an integer {low}..{high}, got {value!r:.80}")
    return int(value)


class Episodes:
    """A view of a dataset's episodes, in index order: len, the index rows, `[i]` (one
    episode: every frame, timestamp and label), `where` and `windows`."""

    def __init__(self, data: EpisodeData, pos: np.ndarray) -> None:
        self._data, self._pos = data, np.asarray(pos, np.int64)

    def __len__(self) -> int:
        return len(self._pos)

    @property
    def data(self) -> EpisodeData:
        """What these episodes are read from (both indexes and the frames store)."""
        return self._data

    def __repr__(self) -> str:
        frames = int(self._data.lengths[self._pos].sum())
        return (f"Episodes({len(self)} of {len(self._data.lengths)} episodes, {frames} frames, "
                f"{self._data.store.loc.url})")

    @property
    def index(self) -> pa.Table:
        """The rows of index/episodes.parquet of this view (pyarrow Table)."""
        return self._data.episodes.take(self._pos)

    @property
    def frames(self) -> pa.Table:
        """The rows of index/frames.parquet of this view's episodes (pyarrow Table)."""
        return self._data.frames.take(self._frame_rows(self._pos))

    @property
    def ids(self) -> list[str]:
        return [self._data.rows[p]["episode_id"] for p in self._pos]

    def _frame_rows(self, pos: np.ndarray) -> np.ndarray:
        d = self._data
        if not len(pos):
            return np.zeros(0, np.int64)
        return np.concatenate([np.arange(d.starts[p], d.starts[p] + d.lengths[p])
                               for p in pos])

    def __getitem__(self, i: int | slice) -> dict[str, Any] | Episodes:
        """Episode i (a dict: its index row, frame_index, timestamps, state, direction, the
        per-frame extra values and every array the dataset holds), or a sub-view."""
        if isinstance(i, slice):
            return Episodes(self._data, self._pos[i])
        return self.episode(i)

    def episode(self, i: int, arrays: Sequence[str] | None = None) -> dict[str, Any]:
        """Episode i with only the arrays named (default: all the dataset holds)."""
        if isinstance(i, bool) or not isinstance(i, int | np.integer):
            raise TypeError(f"episode indices are integers or slices, not {type(i).__name__}")
        n = len(self)
        if not -n <= int(i) < n:
            raise IndexError(f"episode {int(i)} out of range for a view of {n} episodes")
        p = int(self._pos[int(i)])
        d = self._data
        rows = np.arange(d.starts[p], d.starts[p] + d.lengths[p])
        names = d.store.info.arrays if arrays is None else tuple(arrays)
        return {**d.rows[p], "frame_index": rows - d.starts[p], **d.per_frame(rows),
                **d.read_frames(rows, names)}

    def where(self, **columns: Any) -> Episodes:
        """Episodes whose index columns take the given value(s), e.g. where(object="mug",
        session=["s0", "s1"]); a column it has not is an error."""
        keep = self._pos
        for name, want in columns.items():
            if name not in self._data.episodes.column_names:
                raise VtsError(f"unknown episode column {name!r}; columns: "
                               f"{', '.join(self._data.episodes.column_names)}")
            values = set(want) if isinstance(want, list | tuple | set) else {want}
            keep = keep[[self._data.rows[p][name] in values for p in keep]] if len(keep) \
                else keep
        return Episodes(self._data, keep)

    def split(self, name: str, part: str) -> Episodes:
        """The episodes of this view in one part of a split of episodes (`ds.splits`), read and
        leak-checked as the loader checks every split file."""
        d = self._data
        if d.split_file is None:
            raise VtsError("splits are read from a loaded dataset's ds.episodes")
        split = d.split_file(name)
        if split.kind != EPISODE:
            raise VtsError(f"split {name!r} is a split of {split.kind} samples: "
                           f"ds.split({name!r}, {part!r:.80})")
        if part not in split.parts:
            raise VtsError(f"split {name!r} has no part {part!r:.80}; parts: "
                           f"{', '.join(sorted(split.parts, key=part_key))}")
        want = set(split.parts[part])
        return Episodes(d, self._pos[[d.rows[p]["episode_id"] in want for p in self._pos]]
                        if len(self._pos) else self._pos)

    def windows(self, length: int = 8, stride: int | None = None, *,
                delta_timestamps: Sequence[float] | None = None, pad: str = "drop",
                arrays: Sequence[str] = ("rgb",)) -> Windows:
        """Windows of this view's episodes, never across two.

        length, stride: T consecutive frames starting every `stride` frames (default: length,
        non-overlapping); pad="drop" keeps the windows inside the episode, "edge" also the
        last ones, repeating the last frame (pad_mask True there). delta_timestamps: offsets
        in seconds from an anchor frame (every `stride`-th, default every frame), each taking
        the frame within half a frame period of anchor time + offset; where none is, "edge"
        takes the nearest frame (pad_mask True) and "drop" leaves that anchor out."""
        if pad not in PADS:
            raise VtsError(f"pad must be one of {', '.join(PADS)}, got {pad!r:.80}")
        check_arrays(self._data.store.info, arrays)
        d = self._data
        if delta_timestamps is None:
            t = _as_int(length, "length", 1, MAX_WINDOW)
            step = _as_int(t if stride is None else stride, "stride", 1, 2**40)
            ep, idx, padm = length_windows(d.lengths[self._pos], t, step, pad)
        else:
            step = _as_int(1 if stride is None else stride, "stride", 1, 2**40)
            offsets = _offsets(delta_timestamps)
            ep, idx, padm = delta_windows(d.timestamps, d.starts[self._pos],
                                          d.lengths[self._pos], d.fps[self._pos], offsets,
                                          step, pad)
        return Windows(d, self._pos[ep], idx, padm, tuple(arrays))


def _offsets(delta: Sequence[float]) -> np.ndarray:
    try:
        out = np.asarray(delta, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise VtsError("delta_timestamps must be numbers (seconds from the anchor frame)"
                       ) from None
    if not 1 <= len(out) <= MAX_WINDOW or not np.isfinite(out).all():
        raise VtsError(f"delta_timestamps must be 1..{MAX_WINDOW} finite numbers of seconds, "
                       f"got {len(out)} value(s)")
    return out


def length_windows(lengths: np.ndarray, length: int, stride: int, pad: str
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Windows of `length` consecutive frames every `stride` frames of each episode: (episode
    position (N,), frame numbers (N, T), pad mask (N, T)); pad="edge" keeps the windows that
    run past an episode's end, its last frame repeated."""
    lengths = np.asarray(lengths, np.int64)
    last = lengths - length if pad == "drop" else lengths - 1
    counts = np.where(last >= 0, last // stride + 1, 0)
    ep = np.repeat(np.arange(len(lengths)), counts)
    first = np.cumsum(counts) - counts
    starts = (np.arange(int(counts.sum())) - np.repeat(first, counts)) * stride
    idx = starts[:, None] + np.arange(length)[None, :]
    end = lengths[ep][:, None]
    return ep, np.minimum(idx, end - 1), idx >= end


def delta_windows(timestamps: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                  fps: np.ndarray, offsets: np.ndarray, stride: int, pad: str
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Windows by time offsets from every `stride`-th frame of each episode: the frame
    nearest to anchor time + offset (the earlier of two as near), padded where it is more than
    half a frame period away."""
    eps, idxs, pads = [], [], []
    for e, (a, n, rate) in enumerate(zip(starts, lengths, fps, strict=True)):
        ts = timestamps[a:a + n]
        anchors = np.arange(0, n, stride)
        want = ts[anchors][:, None] + offsets[None, :]
        right = np.clip(np.searchsorted(ts, want), 0, n - 1)
        left = np.clip(right - 1, 0, n - 1)
        pick = np.where(np.abs(ts[right] - want) < np.abs(ts[left] - want), right, left)
        padm = np.abs(ts[pick] - want) > 0.5 / rate * (1 + 1e-9)
        if pad == "drop":
            keep = ~padm.any(axis=1)
            pick, padm = pick[keep], padm[keep]
        eps.append(np.full(len(pick), e, np.int64))
        idxs.append(pick)
        pads.append(padm)
    t = len(offsets)
    if not eps:
        return np.zeros(0, np.int64), np.zeros((0, t), np.int64), np.zeros((0, t), bool)
    return np.concatenate(eps), np.concatenate(idxs), np.concatenate(pads)


class Windows:
    """Windows of episodes: len, `[i]` (a dict), `read(items, arrays)` (many at once, stacked)
    and iteration; `episode_index`, `frame_index` and `pad_mask` say what each holds."""

    def __init__(self, data: EpisodeData, episodes: np.ndarray, frames: np.ndarray,
                 pad_mask: np.ndarray, arrays: tuple[str, ...]) -> None:
        self._data = data
        self.episode_index = np.asarray(episodes, np.int64)
        self.frame_index = np.asarray(frames, np.int64)
        self.pad_mask = np.asarray(pad_mask, bool)
        self.arrays = arrays

    def __len__(self) -> int:
        return len(self.episode_index)

    def __repr__(self) -> str:
        return (f"Windows({len(self)} of {self.frame_index.shape[1]} frames, arrays "
                f"{', '.join(self.arrays)}, {self._data.store.loc.url})")

    @property
    def length(self) -> int:
        """T, frames per window."""
        return int(self.frame_index.shape[1])

    def _positions(self, items: Any) -> np.ndarray:
        n = len(self)
        if isinstance(items, slice):
            return np.arange(n)[items]
        idx = np.asarray(items, dtype=np.int64).reshape(-1)
        bad = (idx < -n) | (idx >= n)
        if bad.any():
            raise IndexError(f"window {int(idx[bad][0])} out of range for {n} windows")
        return np.where(idx < 0, idx + n, idx)

    def __getitem__(self, i: int | slice) -> dict[str, Any] | Windows:
        """Window i: the episode's index row, frame_index, timestamps, state, direction,
        pad_mask and the per-frame extra values (T each), and the arrays (T, H, W[, 3])."""
        if isinstance(i, slice):
            pos = self._positions(i)
            return Windows(self._data, self.episode_index[pos], self.frame_index[pos],
                           self.pad_mask[pos], self.arrays)
        if isinstance(i, bool) or not isinstance(i, int | np.integer):
            raise TypeError(f"window indices are integers or slices, not {type(i).__name__}")
        batch = self.read([i])
        p = int(self.episode_index[self._positions([i])[0]])
        return {**self._data.rows[p], **{k: v[0] for k, v in batch.items()
                                          if k not in _ROW_KEYS}}

    def read(self, items: Any, arrays: Sequence[str] | None = None) -> dict[str, Any]:
        """Several windows (ints or a slice) stacked in that order: arrays (n, T, H, W[, 3]),
        frame_index, timestamps, state, direction, pad_mask and extra values (n, T),
        episode_index (n,) and episode_id (a list). Their frames are read in one batched
        call, each frame once."""
        names = self.arrays if arrays is None else tuple(arrays)
        check_arrays(self._data.store.info, names)
        pos = self._positions(items)
        d = self._data
        ep = self.episode_index[pos]
        idx = self.frame_index[pos]
        rows = d.starts[ep][:, None] + idx
        out: dict[str, Any] = {"episode_index": ep,
                               "episode_id": [d.rows[int(p)]["episode_id"] for p in ep],
                               "frame_index": idx, "pad_mask": self.pad_mask[pos],
                               **d.per_frame(rows)}
        if not len(pos):
            info = d.store.info
            return {**out, **{n: np.empty((0, self.length, *info.shapes[EPISODES][n][1:]),
                                          DECODED_DTYPES[n]) for n in names}}
        data = d.read_frames(rows.reshape(-1), names)
        return {**out, **{n: a.reshape(len(pos), self.length, *a.shape[1:])
                          for n, a in data.items()}}

    def to_torch(self, modality: str = "rgb", size: tuple[int, int] | None = None,
                 transform: Any = None, targets: Sequence[str] = (), *, transforms: Any = None,
                 target_transform: Any = None, dtype: str = "uint8"
                 ) -> torch.utils.data.Dataset:
        """A torch Dataset of (tensor (T, C, H, W), target dict) over these windows, a batch
        read in one `read` call; as View.to_torch (uint8 resized in the worker with OpenCV
        INTER_AREA, or dtype="float32"); see vtsbench.dataset.read.torch_dataset.TorchWindows."""
        try:
            from .torch_dataset import TorchWindows
        except ModuleNotFoundError as e:
            raise VtsError(f"to_torch needs {e.name!r}: pip install 'vtsbench[torch]'") from None

        return TorchWindows(self, modality=modality, size=size, transform=transform,
                            targets=targets, transforms=transforms,
                            target_transform=target_transform, dtype=dtype)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        """Windows in order, read a batch at a time."""
        per = max(1, self.length * self._data.store.sample_nbytes(self.arrays))
        step = max(1, ITER_BYTES // per)
        for start in range(0, len(self), step):
            batch = self.read(slice(start, start + step))
            for k in range(len(batch["episode_index"])):
                p = int(batch["episode_index"][k])
                yield {**self._data.rows[p], **{n: v[k] for n, v in batch.items()
                                                 if n not in _ROW_KEYS}}

