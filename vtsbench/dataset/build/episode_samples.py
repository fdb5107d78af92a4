"""The paper's samples as views of an episode store (format 1.3): a static frame or a slip
sequence declared on a saved episode (`EpisodeWriter.add_sample`), checked in one line and
kept in the writer's `SampleLog` (committed in batches with its episodes), and at finish
their index rows (index/static.parquet, index/slip.parquet with `episode_index` and
`frame_row`) and the split schemes over them, leak-checked over ids, keys and frame rows."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import VtsError
from ...labels import N_DIRECTIONS, STATES
from ..format.index import VIEW_COLUMNS, extra_column_name, index_bytes
from ..format.layout import KINDS
from ..format.records import SampleMeta, SplitFile, schema_errors
from .episode_check import MAX_NAME, check_name
from .episode_stage import read_samples, write_samples

#: The labels add_sample takes; the slip-only ones are refused on a static frame.
LABELS = ("state", "direction", "motion_mm", "press_depth_mm", "contact_px", "mm_per_px",
          "source", "fields")
SLIP_ONLY = ("state", "direction", "motion_mm")
#: The longest `source` text.
MAX_SOURCE = 1000


def _number(value: Any, what: str, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating) \
            or not math.isfinite(float(value)) or (positive and float(value) <= 0):
        raise VtsError(f"{where}: {what} must be a finite{' positive' if positive else ''} "
                       f"number, got {value!r:.80}")
    return float(value)


def _pair(value: Any, what: str, where: str, positive: bool = False) -> list[float] | None:
    if value is None:
        return None
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != 2:
        raise VtsError(f"{where}: {what} must be a pair (x, y) or None, got {value!r:.80}")
    return [_number(v, what, where, positive) for v in value]


def _fields(value: Any, where: str) -> dict[str, str | None]:
    """The sample's own text columns (the recordings' fields): plain column names."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise VtsError(f"{where}: fields must be a mapping of column name to text, got "
                       f"{type(value).__name__}")
    out: dict[str, str | None] = {}
    for name, v in value.items():
        if not isinstance(name, str) or extra_column_name(name) != name:
            raise VtsError(f"{where}: fields: {name!r:.80} is not a plain column name (lowercase "
                           "letters, digits and _, not a column of the index)")
        if v is not None and not isinstance(v, str):
            raise VtsError(f"{where}: fields: {name!r} is a {type(v).__name__}; values are text "
                           "or None")
        out[name] = v
    return dict(sorted(out.items()))


def check_labels(kind: str, labels: Mapping[str, Any], where: str) -> dict[str, Any]:
    """A sample's labels as stored in its record (JSON values); one line for the first bad."""
    unknown = sorted(set(labels) - set(LABELS))
    if unknown:
        raise VtsError(f"{where}: unknown label {unknown[0]!r:.80} (labels: {', '.join(LABELS)})")
    if kind == "static":
        given = [k for k in SLIP_ONLY if labels.get(k) is not None]
        if given:
            raise VtsError(f"{where}: {given[0]} is a label of slip sequences, not of a static "
                           "frame")
    state = labels.get("state")
    if state is not None and (not isinstance(state, str) or state not in STATES):
        raise VtsError(f"{where}: state {state!r:.80} is none of {', '.join(STATES)} (or None)")
    d = labels.get("direction")
    if d is not None:
        if isinstance(d, bool) or not isinstance(d, int | np.integer) or not (
                0 <= int(d) < N_DIRECTIONS):
            raise VtsError(f"{where}: direction {d!r:.80} is not a bin 0..{N_DIRECTIONS - 1} "
                           "(or None)")
        if state != "slip":
            raise VtsError(f"{where}: a direction ({int(d)}) on a sample whose state is "
                           f"{state or 'unknown'}, not slip")
        d = int(d)
    depth = labels.get("press_depth_mm")
    source = labels.get("source")
    if source is not None and (not isinstance(source, str) or len(source) > MAX_SOURCE
                               or any(ord(c) < 32 for c in source)):
        raise VtsError(f"{where}: source must be text on one line of at most {MAX_SOURCE} "
                       f"characters, got {source!r:.80}")
    return {"state": state, "direction": d,
            "motion_mm": _pair(labels.get("motion_mm"), "motion_mm", where),
            "press_depth_mm": None if depth is None else _number(depth, "press_depth_mm", where),
            "contact_px": _pair(labels.get("contact_px"), "contact_px", where),
            "mm_per_px": _pair(labels.get("mm_per_px"), "mm_per_px", where, positive=True),
            "source": source, "fields": _fields(labels.get("fields"), where)}


def check_sample(kind: Any, episode: Any, start: Any, sample_id: Any, labels: Mapping[str, Any],
                 *, records: Sequence[Mapping[str, Any]], taken: set[str],
                 frames_per_sequence: int) -> dict[str, Any]:
    """The record of one sample (kind, id, episode row, first frame, labels), refused in one
    line when its kind or labels are unknown, its episode is not saved, its frames lie
    outside the episode or its id is taken."""
    where = "add_sample"
    if kind not in KINDS:
        raise VtsError(f"{where}: kind {kind!r:.80} is none of {', '.join(KINDS)}")
    if isinstance(episode, str):
        k = next((i for i, r in enumerate(records) if r["record"]["episode_id"] == episode), None)
    elif isinstance(episode, int | np.integer) and not isinstance(episode, bool):
        k = int(episode) if 0 <= int(episode) < len(records) else None
    else:
        k = None
    if k is None:
        raise VtsError(f"{where}: episode {episode!r:.80} is not a saved episode (its "
                       f"episode_id or index; {len(records)} saved): save_episode first")
    rec = records[k]["record"]
    n = frames_per_sequence if kind == "slip" else 1
    if isinstance(start, bool) or not isinstance(start, int | np.integer):
        raise VtsError(f"{where}: start must be a frame number (int), got {start!r:.80}")
    start = int(start)
    sid = (f"{rec['episode_id']}-{'s' if kind == 'slip' else 'f'}{start:06d}"
           if sample_id is None else sample_id)
    sid = check_name(sid, "sample_id", f"{where}: {kind} sample")
    where = f"{where}: {kind} sample {sid!r:.{MAX_NAME}}"
    if not 0 <= start <= int(rec["length"]) - n:
        raise VtsError(f"{where}: frames [{start}, {start + n}) are outside episode "
                       f"{rec['episode_id']!r} ({rec['length']} frames)")
    if sid in taken:
        raise VtsError(f"{where}: the id is already taken by another sample (ids are unique "
                       "across both kinds)")
    labs = check_labels(kind, labels, where)
    if labs["source"] is None:
        labs["source"] = f"{rec['episode_id']}[{start}:{start + n}]"
    return {"kind": kind, "sample_id": sid, "episode_index": k, "start": start, "labels": labs}


def check_frames_per_sequence(value: Any) -> int:
    """create's frames_per_sequence: T, the frames of a slip sample, 1..MAX_FRAMES."""
    from ...limits import MAX_FRAMES

    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_FRAMES:
        raise VtsError(f"create: frames_per_sequence must be 1..{MAX_FRAMES}, got "
                       f"{value!r:.80}")
    return value


class SampleLog:
    """The samples a writer declared: those committed (the partial folder's sample batches,
    written with each save_episode and at finish) and those added since, their ids, and the
    splits given over them (kept in memory: give them again after a resume)."""

    def __init__(self, stage: Path, frames_per_sequence: int, episodes: int | None) -> None:
        """`episodes`: the saved episodes of a resumed writer, whose committed samples are
        read back; None for a fresh writer."""
        self.stage, self.frames_per_sequence = stage, frames_per_sequence
        self.committed, self.batches = (read_samples(stage, episodes) if episodes is not None
                                        else ([], 0))
        self.added: list[dict[str, Any]] = []
        self.ids = {str(s["sample_id"]) for s in self.committed}
        self.splits: list[SplitFile] = []

    def __len__(self) -> int:
        return len(self.committed) + len(self.added)

    def add(self, kind: Any, episode: Any, start: Any, sample_id: Any,
            labels: Mapping[str, Any], records: Sequence[Mapping[str, Any]]) -> str:
        """Check a sample on the saved episodes `records` (check_sample) and keep it until the
        next commit; returns its id."""
        doc = check_sample(kind, episode, start, sample_id, labels, records=records,
                           taken=self.ids, frames_per_sequence=self.frames_per_sequence)
        self.added.append(doc)
        self.ids.add(doc["sample_id"])
        return str(doc["sample_id"])

    def add_split(self, split: Any) -> None:
        """A split given by the caller: a SplitFile valid in schemas/split.schema.json (of
        static or slip samples, or of episodes) whose name no other given split has
        (leak-checked at finish: sample_splits, splits.episodes.check_episode_split)."""
        if not isinstance(split, SplitFile):
            raise VtsError(f"add_split takes a SplitFile, got {type(split).__name__}")
        errs = schema_errors(split.to_dict(), "split")
        if errs:
            raise VtsError(f"add_split: split {split.name!r:.80} is not a valid split file: "
                           f"{errs[0][:200]}")
        if any(s.name == split.name for s in self.splits):
            raise VtsError(f"two splits named {split.name!r}")
        self.splits.append(split)

    def commit(self) -> None:
        """Write the samples added since the last commit as the next batch."""
        if self.added:
            write_samples(self.stage, self.batches, self.added)
            self.committed += self.added
            self.batches += 1
            self.added = []


@dataclass
class SampleViews:
    """The samples of one kind as index rows: metas (row order), their own text columns, and
    the view columns (episode row, store row of the first frame)."""

    metas: list[SampleMeta] = field(default_factory=list)
    extra: dict[str, list[str | None]] = field(default_factory=dict)
    views: dict[str, list[int]] = field(default_factory=lambda: {c: [] for c in VIEW_COLUMNS})

    def frames(self, t: int) -> np.ndarray:
        """(n, t) store rows of each sample."""
        start = np.asarray(self.views["frame_row"], np.int64)
        return start[:, None] + np.arange(t, dtype=np.int64)[None, :]

    def index_bytes(self, kind: str) -> bytes:
        return index_bytes(kind, self.metas, self.extra, views=self.views)


def sample_views(samples: Sequence[Mapping[str, Any]], records: Sequence[Mapping[str, Any]],
                 objects: Sequence[str]) -> dict[str, SampleViews]:
    """Index rows of every sample, per kind, in the order they were added; class_idx is the
    object's place in the dataset's sorted objects, object, session and sensor the episode's."""
    out = {k: SampleViews() for k in KINDS}
    per_kind: dict[str, list[Mapping[str, Any]]] = {k: [] for k in KINDS}
    for s in samples:
        per_kind[s["kind"]].append(s)
    for kind, ss in per_kind.items():
        v = out[kind]
        names = sorted({n for s in ss for n in s["labels"]["fields"]})
        v.extra = {n: [] for n in names}
        for row, s in enumerate(ss):
            rec, lab = records[s["episode_index"]]["record"], s["labels"]
            mm, c, mo = lab["mm_per_px"], lab["contact_px"], lab["motion_mm"]
            v.metas.append(SampleMeta(
                s["sample_id"], kind, row, rec["object"], list(objects).index(rec["object"]),
                rec["session"], rec["sensor"], None if mm is None else mm[0],
                None if mm is None else mm[1], lab["source"], lab["press_depth_mm"],
                None if c is None else c[0], None if c is None else c[1], lab["state"], None,
                lab["direction"], None if mo is None else mo[0], None if mo is None else mo[1]))
            v.views["episode_index"].append(int(s["episode_index"]))
            v.views["frame_row"].append(int(rec["frame_start"]) + int(s["start"]))
            for n in names:
                v.extra[n].append(lab["fields"].get(n))
    return out


def sample_splits(views: Mapping[str, SampleViews], frames_per_sequence: int, *, seed: int,
                  resolution: tuple[int, int], given: Sequence[SplitFile] = ()) -> Any:
    """The fixed split schemes over the samples (splits.schemes.make_splits) and the given
    ones, each leak-checked (ids, keys and frame rows: overlapping views of one take in two
    parts). A fixed scheme whose parts share frame rows (its random val cut through the
    overlapping windows of a take) is skipped with the reason; a given split that leaks is an
    error. Returns the SplitReport."""
    from ..splits.leaks import leak_check
    from ..splits.schemes import make_splits

    samples = [m for k in KINDS for m in views[k].metas]
    frames = {k: views[k].frames(frames_per_sequence if k == "slip" else 1) for k in KINDS}
    report = make_splits(samples, seed=seed, resolution=resolution)
    kept = []
    for sp in report.splits:
        leaks = leak_check(sp, samples, frames[sp.kind])
        if leaks:
            report.skipped[sp.name] = leaks[0]
        else:
            kept.append(sp)
    report.splits = kept
    for sp in given:
        if any(s.name == sp.name for s in report.splits):
            raise VtsError(f"two splits named {sp.name!r} (a fixed scheme's and a given one)")
        leaks = leak_check(sp, samples, frames[sp.kind]) if sp.kind in KINDS else [
            f"{sp.name}: kind {sp.kind!r} is not a kind of samples"]
        if leaks:
            raise VtsError(f"split {sp.name} leaks: {leaks[0]}"
                           + (f" (and {len(leaks) - 1} more)" if len(leaks) > 1 else ""))
        report.splits.append(sp)
    return report
