"""An episode writer's partial folder: its state, the frames store written as frames arrive, and
what a rerun after a crash keeps (resume).

The partial folder is the build's (`.OUT.partial`, locked, build/staging.py); its state folder
`.build/` holds the writer's parameters (`writer.json`) and one record per saved episode
(`episodes/<k>.json`: the index row, the frames' timestamps, labels and extra values), written
after the episode's frames: a record is the commit point of its episode. Samples declared on
saved episodes (add_sample) are committed in batches, `samples/<b>.json`, each written at the
next save_episode (before that episode's record) and at finish. Frames go into
`data/episodes.zarr` through the build's shard writer (build/store.py): a shard is written as
soon as it is full, and the partial shard at the end again at each save, with the Zarr metadata
of the frames saved so far. A writer killed mid-episode leaves frames beyond the last record;
a rerun keeps every recorded episode, reads the frames of the last partial shard back and
writes that shard again without the rest.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ...atomic import TMP_SUFFIX, write_bytes_atomic
from ...errors import VtsError
from ..format.arrays import Layout
from ..format.layout import EPISODES, EPISODES_GROUP
from .staging import WORK, WRITER_STATE
from .store import samples_per_shard, write_metadata, write_shard

#: Folder of the per-episode records, in the state folder.
RECORDS = "episodes"
#: Folder of the sample records (batches of EpisodeWriter.add_sample), in the state folder.
SAMPLES = "samples"
#: Bumped whenever what the state files mean changes.
STATE_VERSION = 1


class FrameShards:
    """data/episodes.zarr of the partial folder: frames appended in store order, written a
    whole shard at a time; `save` writes the partial last shard and the metadata of every frame
    so far, `saved` makes them the committed frames, `discard` drops the frames since."""

    def __init__(self, stage: Path, arrays: tuple[str, ...], level: int,
                 shard_bytes: int) -> None:
        self.group_dir = stage / EPISODES_GROUP
        self.arrays, self.level, self.shard_bytes = arrays, level, shard_bytes
        self.layout: Layout | None = None
        self.committed = 0  # frames of the saved episodes
        self.added = 0  # frames since
        self.tail: dict[str, list[np.ndarray]] = {n: [] for n in arrays}  # committed frames
        # of the last, partial shard
        self.buf: dict[str, list[np.ndarray]] = {n: [] for n in arrays}  # frames from
        # buf_start on that no full shard holds yet
        self.buf_start = 0

    def start(self, size: tuple[int, int]) -> Layout:
        """The layout, fixed by the first frame's size."""
        if self.layout is None:
            sps = samples_per_shard(size, None, self.shard_bytes)
            self.layout = Layout(EPISODES, 0, size, None, sps, self.level, self.arrays)
        return self.layout

    @property
    def per_shard(self) -> int:
        return self.layout.samples_per_shard if self.layout is not None else 1

    def add(self, frame: dict[str, np.ndarray]) -> None:
        """Append one frame (its stored arrays); a shard full of frames is written now."""
        for n in self.arrays:
            self.buf[n].append(frame[n])
        self.added += 1
        if len(self.buf[self.arrays[0]]) == self.per_shard:
            self._write(self.buf_start // self.per_shard, self.buf)
            self.buf = {n: [] for n in self.arrays}
            self.buf_start += self.per_shard

    def _write(self, k: int, frames: dict[str, list[np.ndarray]]) -> None:
        assert self.layout is not None
        write_shard(self.group_dir, self.layout, k, {n: np.stack(frames[n]) for n in frames})

    def _metadata(self, n: int) -> None:
        if self.layout is not None:
            write_metadata(self.group_dir, replace(self.layout, n=n))

    def save(self) -> None:
        """Write the partial last shard and the metadata of every frame added so far."""
        if self.buf[self.arrays[0]]:
            self._write(self.buf_start // self.per_shard, self.buf)
        self._metadata(self.committed + self.added)

    def saved(self) -> None:
        """The frames added are committed (their episode's record is written)."""
        self.committed += self.added
        self.added = 0
        self.tail = {n: list(v) for n, v in self.buf.items()}

    def discard(self) -> None:
        """Forget the frames added since the last commit (what they wrote is stale: finalize
        and the next save write over it)."""
        self.buf = {n: list(v) for n, v in self.tail.items()}
        self.buf_start = self.committed - len(self.tail[self.arrays[0]])
        self.added = 0

    def restore(self, committed: int, size: tuple[int, int] | None) -> None:
        """Resume with `committed` frames saved: the partial last shard's frames read back and
        written again alone, shards past them deleted."""
        self.committed, self.added = committed, 0
        if size is None:
            shutil.rmtree(self.group_dir, ignore_errors=True)
            return
        self.start(size)
        self.buf_start = committed - committed % self.per_shard
        self._metadata(committed)
        if committed % self.per_shard:
            import zarr

            try:
                group = zarr.open_group(str(self.group_dir), mode="r")
                self.tail = {n: list(group[n][self.buf_start:committed]) for n in self.arrays}
            except Exception as e:  # a shard the crash damaged: nothing to build on
                raise VtsError(f"cannot resume: the frames of the saved episodes do not read "
                               f"back ({type(e).__name__}); delete the partial folder and start "
                               "again", self.group_dir) from None
        self.buf = {n: list(v) for n, v in self.tail.items()}
        self.finalize()

    def finalize(self) -> None:
        """Make the store hold exactly the committed frames: the partial last shard written
        from memory, later shards deleted, the metadata of `committed` frames."""
        if self.layout is None:
            return
        last = -(-self.committed // self.per_shard)
        if self.tail[self.arrays[0]]:
            self._write(last - 1, self.tail)
        for n in self.arrays:
            chunks = self.group_dir / n / "c"
            for d in chunks.iterdir() if chunks.is_dir() else ():
                if d.is_dir() and (not d.name.isdigit() or int(d.name) >= last):
                    shutil.rmtree(d)
        self._metadata(self.committed)


def _state_dir(stage: Path) -> Path:
    return stage / WORK


def read_state(stage: Path) -> dict[str, Any] | None:
    """writer.json of a partial folder (None when there is none)."""
    path = _state_dir(stage) / WRITER_STATE
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        raise VtsError("unreadable writer state: delete the partial folder and start again",
                       path) from None
    if not isinstance(doc, dict) or doc.get("version") != STATE_VERSION:
        raise VtsError("writer state of another vtsbench version: delete the partial folder "
                       "and start again", path)
    return doc


def write_state(stage: Path, params: dict[str, Any]) -> None:
    """writer.json: the parameters the stored bytes depend on."""
    (_state_dir(stage) / RECORDS).mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(_state_dir(stage) / WRITER_STATE, json.dumps(
        {"version": STATE_VERSION, **params}, sort_keys=True).encode())


def holds_files(stage: Path) -> bool:
    """Whether a partial folder holds any file (an empty state folder does not count)."""
    return stage.is_dir() and any(p.is_file() for p in stage.rglob("*"))


def write_record(stage: Path, k: int, doc: dict[str, Any]) -> None:
    """Episode k's record: the commit point of the episode (its frames are written before)."""
    write_bytes_atomic(_state_dir(stage) / RECORDS / f"{k:06d}.json",
                       json.dumps(doc, allow_nan=True).encode())


def read_records(stage: Path) -> list[dict[str, Any]]:
    """The records of the saved episodes, 0..k-1 each following the previous; any record past
    the first gap or mismatch, and every temporary file a killed writer left, deleted."""
    folder = _state_dir(stage) / RECORDS
    out: list[dict[str, Any]] = []
    total = 0
    while True:
        try:
            doc = json.loads((folder / f"{len(out):06d}.json").read_text())
            rec = doc["record"]
            ok = rec["episode_index"] == len(out) and rec["frame_start"] == total
        except (OSError, ValueError, KeyError, TypeError):
            break
        if not ok:
            break
        out.append(doc)
        total += int(rec["length"])
    for p in folder.glob("*.json") if folder.is_dir() else ():
        if not p.stem.isdigit() or int(p.stem) >= len(out):
            p.unlink()
    for p in stage.rglob(f"*{TMP_SUFFIX}"):
        if p.name.startswith(".") and p.is_file():
            p.unlink()
    return out


def write_samples(stage: Path, b: int, samples: list[dict[str, Any]]) -> None:
    """Batch b of sample records (EpisodeWriter.add_sample): the commit point of the samples
    added since the previous batch; written at each save_episode and at finish."""
    (_state_dir(stage) / SAMPLES).mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(_state_dir(stage) / SAMPLES / f"{b:06d}.json",
                       json.dumps(samples, allow_nan=False).encode())


def read_samples(stage: Path, episodes: int) -> tuple[list[dict[str, Any]], int]:
    """The committed sample records (batches 0..b-1, each following the previous, every sample
    of a saved episode) and how many batches; batches past the first gap or bad one deleted."""
    folder = _state_dir(stage) / SAMPLES
    out: list[dict[str, Any]] = []
    b = 0
    while True:
        try:
            docs = json.loads((folder / f"{b:06d}.json").read_text())
            ok = isinstance(docs, list) and all(0 <= int(d["episode_index"]) < episodes
                                                for d in docs)
        except (OSError, ValueError, KeyError, TypeError):
            break
        if not ok:
            break
        out += docs
        b += 1
    for p in folder.glob("*.json") if folder.is_dir() else ():
        if not p.stem.isdigit() or int(p.stem) >= b:
            p.unlink()
    return out, b
