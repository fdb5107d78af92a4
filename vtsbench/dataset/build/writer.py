"""`vtsbench.create(path, ...)`: write continuous takes (episodes) frame by frame into a dataset
of format 1.2, each frame stored once, windows chosen when reading (`ds.episodes.windows`).

    with vtsbench.create("data/takes", fps=25.0, sensor="gelsight-mini") as w:
        for frame, t in camera:
            w.add_frame(frame, timestamp=t)
        w.save_episode(object="mug", session="s0")

The writer works in the build's partial folder (`.OUT.partial` beside OUT, locked) and renames
it to OUT in `finish()` (build/staging.py, build/episode_finish.py): OUT is complete or absent,
and nothing has an info.json before then. Each saved episode is committed by its record
(build/episode_stage.py); `create(..., resume=True)` after a crash keeps every saved episode
and goes on, and a writer killed mid-episode loses that episode alone. Every refusal of bad
input is one line naming the episode and frame (build/episode_check.py); dropped frames
(timestamp gaps over 1.5 frame periods) are counted in the episode's row and warned about.

`add_sample` declares the paper's static frames and slip sequences as views of saved episodes
(build/episode_samples.py): the dataset is then format 1.3, with their indexes and split
files and no arrays of their own. Samples are committed with the next save_episode or at
finish(); a writer killed before that loses the samples added since the last save, and only
those. `vtsbench build --store episodes` is written on this writer (build/episodes_build.py).
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import warnings
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from ...errors import VtsError
from ..format.episodes import EpisodeRecord, dropped_frames, duration_s
from ..format.layout import EPISODES_GROUP, INFO_PATH
from ..splits.given import check_object_list
from .episode_check import (
    FrameSpec,
    check_arrays_choice,
    check_extra,
    check_fps,
    check_labels,
    check_meta,
    check_name,
    check_onset,
    check_sha256,
    check_timestamp,
    frame_arrays,
)
from .episode_finish import finish_episodes, merged_kinds
from .episode_samples import SampleLog, check_frames_per_sequence
from .episode_stage import SAMPLES, holds_files, read_records, read_state, write_record, write_state
from .episode_video import check_video, frame_store
from .staging import WORK, locked_stage, partial_path

#: dataset_version: a semantic version (as info.json's schema says).
SEMVER = re.compile(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(-[0-9A-Za-z.-]+)?"
                    r"(\+[0-9A-Za-z.-]+)?")


class DroppedFramesWarning(UserWarning):
    """An episode whose timestamps skip frames (a gap over 1.5 frame periods)."""


def create(path: str | Path, *, fps: float = 25.0, arrays: Sequence[str] = ("rgb",),
           sensor: str = "unknown", name: str | None = None,
           calibration_sha256: str | None = None, resume: bool = False,
           overwrite: bool = False, dataset_version: str = "1.0.0",
           compression_level: int = 3, shard_mb: float = 32.0, seed: int = 0,
           frames_per_sequence: int = 8, video: str | None = None,
           holdout_objects: Sequence[str] | None = None) -> EpisodeWriter:
    """A writer of episodes into a new dataset at `path` (see EpisodeWriter).

    fps, sensor and calibration_sha256 are each episode's defaults (save_episode may give its
    own); arrays: ("rgb",) or ("rgb", "depth", "contact"); resume=True continues the partial
    dataset a killed writer left (every saved episode kept); overwrite=True replaces an
    existing dataset at `path` when finished; seed: the split schemes' at finish()
    (unseen_objects, unseen_sessions over the episodes, and the fixed schemes over the
    samples); frames_per_sequence: T, the frames of a slip sample (add_sample); video: None
    (RGB in Zarr) or a codec of format/video.py ("ffv1" lossless, "h264", "av1"): each saved
    episode's RGB as one video file (build/episode_video.py), depth and contact in Zarr;
    holdout_objects: a lab's test objects, the split given_objects at finish() (test: their
    episodes, val: whole other objects drawn with `seed`; `episode_given_objects` and the
    samples' `given_objects`, the same objects held out, when there are samples)."""
    return EpisodeWriter(path, fps=fps, arrays=arrays, sensor=sensor, name=name,
                         calibration_sha256=calibration_sha256, resume=resume,
                         overwrite=overwrite, dataset_version=dataset_version,
                         compression_level=compression_level, shard_mb=shard_mb, seed=seed,
                         frames_per_sequence=frames_per_sequence, video=video,
                         holdout_objects=holdout_objects)


class EpisodeWriter:
    """Episodes written frame by frame (add_frame, then save_episode) or whole (add_episode);
    finish() makes the dataset. As a context manager it finishes when the block succeeds and
    leaves the partial folder (to resume) when it raises."""

    def __init__(self, path: str | Path, *, fps: float, arrays: Sequence[str], sensor: str,
                 name: str | None, calibration_sha256: str | None, resume: bool,
                 overwrite: bool, dataset_version: str, compression_level: int,
                 shard_mb: float, seed: int = 0, frames_per_sequence: int = 8,
                 provenance: Mapping[str, Any] | None = None, video: str | None = None,
                 holdout_objects: Sequence[str] | None = None) -> None:
        self.out = Path(path).resolve()
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise VtsError(f"create: seed must be a non-negative integer, got {seed!r:.80}")
        self.seed = seed
        self.holdout_objects = None if holdout_objects is None else tuple(
            check_object_list(holdout_objects, "create(holdout_objects=...)"))
        self.frames_per_sequence = check_frames_per_sequence(frames_per_sequence)
        #: what a build records of itself in info.json (created_by, calibration, build)
        self.provenance = dict(provenance or {})
        self.fps = check_fps(fps)
        self.arrays = check_arrays_choice(arrays)
        self.video = check_video(video)
        self.sensor = check_name(sensor, "sensor", "create")
        self.name = check_name(name or self.out.name, "name", "create")
        self.calibration_sha256 = check_sha256(calibration_sha256, "create")
        if not isinstance(dataset_version, str) or not SEMVER.fullmatch(dataset_version):
            raise VtsError(f"create: dataset_version {dataset_version!r:.80} is not a semantic "
                           "version such as 1.0.0")
        if isinstance(compression_level, bool) or not isinstance(compression_level, int) or (
                not 0 <= compression_level <= 22):
            raise VtsError(f"create: compression_level must be 0..22, got {compression_level!r}")
        if isinstance(shard_mb, bool) or not isinstance(shard_mb, int | float) or (
                not 0.01 <= shard_mb <= 4096):
            raise VtsError(f"create: shard_mb must be 0.01..4096, got {shard_mb!r}")
        self.overwrite, self.dataset_version = overwrite, dataset_version
        self.level, self.shard_mb = compression_level, float(shard_mb)
        self._stack = ExitStack()
        self._closed = False
        try:
            self._check_out()
            self.stage = self._stack.enter_context(locked_stage(self.out))
            self._check_out()  # another writer may have finished it meanwhile
            self._open(resume)
        except BaseException:
            self._stack.close()
            raise

    # -- setup and state ------------------------------------------------------------------

    def _check_out(self) -> None:
        out = self.out
        if not (out.exists() or out.is_symlink()):
            return
        if not self.overwrite:
            raise VtsError("already exists (vtsbench.create(..., overwrite=True) replaces a "
                           "dataset)", out)
        if not out.is_dir() or (any(out.iterdir()) and not (out / INFO_PATH).is_file()):
            raise VtsError(f"exists and is not a vtsbench dataset (no {INFO_PATH}); overwrite "
                           "replaces only datasets", out)

    def _params(self) -> dict[str, Any]:
        return {"arrays": list(self.arrays), "compression_level": self.level,
                "shard_mb": self.shard_mb, "frames_per_sequence": self.frames_per_sequence,
                "video": None if self.video is None else self.video.name,
                **({"build": hashlib.sha256(json.dumps(  # a build: its options, recordings
                    self.provenance["build"], sort_keys=True).encode()).hexdigest()[:16]}
                   if self.provenance.get("build") else {})}

    def _open(self, resume: bool) -> None:
        """Start afresh, or resume the partial folder's saved episodes."""
        state = read_state(self.stage)
        if state is None and holds_files(self.stage):
            raise VtsError("holds a partial dataset that vtsbench.create did not write (a "
                           "partial `vtsbench build`?): finish it or delete it", self.stage)
        self._records: list[dict[str, Any]] = read_records(self.stage) if state else []
        if state is not None and not resume and not self._records:  # nothing saved to lose
            shutil.rmtree(self.stage / EPISODES_GROUP, ignore_errors=True)
            shutil.rmtree(self.stage / WORK / SAMPLES, ignore_errors=True)
            state = None
        if state is not None and not resume:
            raise VtsError(f"a partial dataset is here ({len(self._records)} episode(s) saved "
                           "by an earlier writer): vtsbench.create(..., resume=True) continues "
                           "it; delete it to start again", self.stage)
        if state is not None:
            given = self._params()
            diff = [k for k in given if state.get(k) != given[k]]
            if "build" in diff:
                raise VtsError("resume: the build's options or recordings differ from those of "
                               "the partial build: rerun it as it was, or delete the partial "
                               "folder to start again", self.stage)
            if diff:
                raise VtsError(f"resume: {diff[0]} {given[diff[0]]!r} differs from the partial "
                               f"dataset's {state.get(diff[0])!r}", self.stage)
        else:
            write_state(self.stage, self._params())
        self._spec = FrameSpec.from_dict(self._records[0]["spec"]) if self._records \
            else FrameSpec()
        self._frames = frame_store(self.stage, self.arrays, self.level,
                                   int(self.shard_mb * 2**20), self.video, len(self._records))
        self._frames.restore(sum(int(r["record"]["length"]) for r in self._records),
                             self._spec.size)
        self._saved_kinds = merged_kinds(self._records)
        self._meta_names = {k for r in self._records for k in EpisodeRecord.from_dict(
            r["record"]).meta}
        self._log = SampleLog(self.stage, self.frames_per_sequence,
                              len(self._records) if state is not None else None)
        self._reset()

    def _reset(self) -> None:
        """Forget the episode being added (its frames, labels and extra values)."""
        self._ts: list[float] = []
        self._ts_given: bool | None = None
        self._states: list[int | None] = []
        self._dirs: list[int | None] = []
        self._extra: dict[str, list[Any]] = {}
        self._kinds = dict(self._saved_kinds)

    def _check_open(self) -> None:
        if self._closed:
            raise VtsError("this writer is finished or closed", self.out)

    @property
    def episodes(self) -> int:
        """Episodes saved so far (resumed ones included)."""
        return len(self._records)

    @property
    def frames(self) -> int:
        """Frames of the saved episodes."""
        return self._frames.committed

    @property
    def pending(self) -> int:
        """Frames added since the last save_episode."""
        return len(self._states)

    @property
    def saved_episodes(self) -> list[dict[str, Any]]:
        """The index rows of the saved episodes (EpisodeRecord fields), in order."""
        return [dict(r["record"]) for r in self._records]

    @property
    def samples(self) -> int:
        """Samples declared so far (add_sample; resumed ones included)."""
        return len(self._log)

    @property
    def sample_ids(self) -> frozenset[str]:
        """The ids of the samples declared so far (a resumed writer: the committed ones)."""
        return frozenset(self._log.ids)

    @property
    def partial(self) -> Path:
        """The partial folder being written (`.OUT.partial` beside OUT)."""
        return partial_path(self.out)

    # -- writing --------------------------------------------------------------------------

    def add_frame(self, rgb: Any, timestamp: float | None = None, state: Any = None,
                  direction: int | None = None, depth: Any = None, contact: Any = None,
                  **extra: Any) -> None:
        """Add a frame to the current episode: rgb (H, W, 3) uint8; timestamp in seconds from
        the episode start (strictly increasing; None for every frame of an episode: frame k
        is at k / fps); state (a name of labels.STATES or its index), direction (0..7, only
        with state slip); depth (H, W) in mm and contact (H, W) bool when the dataset has
        them; extra: per-frame values (None, bool, int, float or str)."""
        self._check_open()
        n = self.pending
        where = f"episode {self.episodes}, frame {n}"
        if n and (timestamp is not None) != self._ts_given:
            had = "one" if self._ts_given else "none"
            raise VtsError(f"{where}: {'a' if timestamp is not None else 'no'} timestamp, where "
                           f"the earlier frames of the episode had {had}: give every frame of "
                           "an episode a timestamp, or none")
        ts = (check_timestamp(timestamp, self._ts[-1] if self._ts else None, where)
              if timestamp is not None else None)
        s, d = check_labels(state, direction, where)
        kinds = dict(self._kinds)
        values = check_extra(extra, kinds, self._meta_names, where)
        frame = frame_arrays(self._spec, self.arrays, where, rgb, depth, contact)
        self._frames.start(self._spec.size or (0, 0))
        self._frames.add(frame)
        self._kinds, self._ts_given = kinds, timestamp is not None
        if ts is not None:
            self._ts.append(ts)
        self._states.append(s)
        self._dirs.append(d)
        for key in sorted(set(self._extra) | set(values)):
            self._extra.setdefault(key, [None] * n).append(values.get(key))

    def discard_episode(self) -> int:
        """Drop the frames added since the last save_episode; returns how many."""
        self._check_open()
        n = self.pending
        self._frames.discard()
        self._reset()
        return n

    def save_episode(self, *, object: str, session: str, slip_onset_s: float | None = None,
                     episode_id: str | None = None, fps: float | None = None,
                     sensor: str | None = None, calibration_sha256: str | None = None,
                     **meta: Any) -> int:
        """Save the frames added since the last save as one episode; returns its index.

        slip_onset_s: when slip starts (seconds, in the clock of the timestamps); episode_id
        (default `episode-<k>`), fps, sensor and calibration_sha256 default to the writer's;
        meta: the episode's own columns (stored as text)."""
        self._check_open()
        k = self.episodes
        where = f"episode {k}"
        n = self.pending
        if not n:
            raise VtsError(f"{where}: no frames (add_frame first): an episode holds at least "
                           "one frame")
        obj = check_name(object, "object", where)
        ses = check_name(session, "session", where)
        eid = check_name(f"episode-{k:06d}" if episode_id is None else episode_id,
                         "episode_id", where)
        if any(r["record"]["episode_id"] == eid for r in self._records):
            raise VtsError(f"{where}: episode_id {eid!r} is already taken by a saved episode")
        rate = check_fps(self.fps if fps is None else fps, f"{where}: fps")
        ts = np.asarray(self._ts, np.float64) if self._ts_given else np.arange(n) / rate
        rec = EpisodeRecord(
            k, eid, obj, ses, check_name(self.sensor if sensor is None else sensor, "sensor",
                                         where),
            rate, self.frames, n, duration_s(ts, rate), dropped_frames(ts, rate)[0],
            check_onset(slip_onset_s, ts, where),
            check_sha256(self.calibration_sha256 if calibration_sha256 is None
                         else calibration_sha256, where),
            check_meta(meta, set(self._extra) | set(self._kinds), where))
        doc = {"record": rec.to_dict(), "timestamps": ts.tolist(), "state": self._states,
               "direction": self._dirs, "extra": self._extra,
               "extra_kinds": {c: self._kinds[c] for c in self._extra if c in self._kinds},
               "spec": self._spec.to_dict()}
        if self.video is not None:  # the episode's RGB as one video file, before its record
            self._frames.save_video(k, rate)
        self._frames.save()  # the frames first, then the record that commits them
        self._log.commit()  # (they view earlier episodes: committed whatever follows)
        write_record(self.stage, k, doc)
        self._frames.saved()
        self._records.append(doc)
        self._saved_kinds = merged_kinds([{"extra_kinds": self._saved_kinds}, doc])
        self._meta_names |= set(rec.meta)
        self._reset()
        if rec.dropped_frames:
            _, at = dropped_frames(ts, rate)
            warnings.warn(DroppedFramesWarning(
                f"{where} ({eid}): {rec.dropped_frames} dropped frame(s): timestamps skip "
                f"{float(ts[at + 1] - ts[at]):.4g} s after frame {at} (more than 1.5 frame "
                f"periods at {rate:g} fps); counted in its dropped_frames"), stacklevel=2)
        return k

    def add_episode(self, frames: Any, timestamps: Sequence[float] | None = None,
                    states: Sequence[Any] | None = None,
                    directions: Sequence[int | None] | None = None, depth: Any = None,
                    contact: Any = None, extra: Mapping[str, Sequence[Any]] | None = None, *,
                    object: str, session: str, **save: Any) -> int:
        """A whole episode at once: frames (T, H, W, 3) uint8 with, per frame, timestamps,
        states, directions, depth (T, H, W) mm, contact (T, H, W) and extra values; the
        keywords of save_episode. Nothing of it is kept when any frame is refused."""
        self._check_open()
        where = f"episode {self.episodes}"
        if self.pending:
            raise VtsError(f"{where}: {self.pending} frame(s) added since the last "
                           "save_episode; save_episode() or discard_episode() them first")
        rgb = np.asarray(frames)
        if rgb.ndim != 4:
            raise VtsError(f"{where}: frames of shape {rgb.shape}, expected (T, H, W, 3)")
        t = len(rgb)
        per_frame = {"timestamps": timestamps, "states": states, "directions": directions,
                     "depth": depth, "contact": contact,
                     **{f"extra {k!r}": v for k, v in (extra or {}).items()}}
        for what, values in per_frame.items():
            if values is not None and len(values) != t:
                raise VtsError(f"{where}: {what} has {len(values)} values for {t} frames")

        def at(values: Any, i: int) -> Any:
            return None if values is None else values[i]

        try:
            for i in range(t):
                self.add_frame(rgb[i], at(timestamps, i), at(states, i), at(directions, i),
                               at(depth, i), at(contact, i),
                               **{k: v[i] for k, v in (extra or {}).items()})
            return self.save_episode(object=object, session=session, **save)
        except BaseException:
            if self.pending:
                self.discard_episode()
            raise

    # -- samples: views of the saved episodes ---------------------------------------------

    def add_sample(self, kind: str, *, episode: int | str, start: int,
                   sample_id: str | None = None, **labels: Any) -> str:
        """Declare a sample of the paper's tasks as a view of a saved episode: kind "static"
        (the frame `start`) or "slip" (frames_per_sequence frames from `start`) of `episode`
        (its episode_id or index); labels: state, direction, motion_mm (dx, dy), press_depth_mm,
        contact_px (x, y), mm_per_px (x, y), source (text; default `<episode_id>[a:b]`) and
        fields (the sample's own text columns); object, session and sensor are the episode's.
        Returns the sample id (default `<episode_id>-s<start>` / `-f<start>`). Committed with
        the next save_episode or at finish(): a writer killed before that loses the samples
        added since the last save_episode (resume keeps all the earlier ones, `sample_ids`)."""
        self._check_open()
        return self._log.add(kind, episode, start, sample_id, labels, self._records)

    def add_split(self, split: Any) -> None:
        """A split given by the caller (a SplitFile of kind static or slip: parts of sample
        ids; or "episode": parts of episode ids), written at finish() beside the fixed schemes
        and leak-checked as they are (ids known, none in two parts, keys, frame rows); not kept
        across a resume: give it again before finish()."""
        self._check_open()
        self._log.add_split(split)

    # -- finishing ------------------------------------------------------------------------

    def finish(self) -> Path:
        """Write the indexes, info.json, card and checksums and rename the partial folder to
        OUT; returns OUT. Refused with frames not saved, or no episode at all."""
        self._check_open()
        if self.pending:
            raise VtsError(f"{self.pending} frame(s) added since the last save_episode: "
                           "save_episode() or discard_episode() them before finish()", self.out)
        if not self._records:
            raise VtsError("no episodes saved: nothing to finish (add_episode, or add_frame "
                           "then save_episode, first)", self.out)
        if any(sp.kind != "episode" for sp in self._log.splits) and not self.samples:
            raise VtsError("splits of samples given (add_split) but no samples (add_sample)",
                          self.out)
        self._check_out()
        self._log.commit()
        finish_episodes(self.stage, self.out, self._frames, self._records, name=self.name,
                        dataset_version=self.dataset_version, shard_mb=self.shard_mb,
                        seed=self.seed, samples=self._log.committed,
                        frames_per_sequence=self.frames_per_sequence, given=self._log.splits,
                        provenance=self.provenance, holdout_objects=self.holdout_objects)
        self.close()
        return self.out

    def close(self) -> None:
        """Stop without finishing: the lock is released and the partial folder stays, to
        resume (`create(..., resume=True)`)."""
        if not self._closed:
            self._closed = True
            self._stack.close()

    def __enter__(self) -> EpisodeWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        try:
            if exc_type is None and not self._closed:
                self.finish()
        finally:
            self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else f"{self.pending} frame(s) pending"
        return (f"EpisodeWriter({self.out}, {self.episodes} episode(s), {self.frames} frames, "
                f"{state})")
