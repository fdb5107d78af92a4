"""Episodes (format 1.2): continuous takes stored once. Every frame of every episode lies in one
store, `data/episodes.zarr` (in episode order, one frame per chunk, the layout of the other
groups), with one row per episode in `index/episodes.parquet` and one per frame in
`index/frames.parquet`; windows are chosen when reading (dataset/read/episodes.py).

The typed rows (EpisodeRecord, FrameRecord) mirror schemas/episode.schema.json and
schemas/episode_frame.schema.json; here too are both tables' parquet schemas, the bytes a writer
gives them (fixed settings: the same episodes give the same bytes), their reader and their
checks (`episodes_problems`: what `vtsbench.load` raises the first of and `vtsbench verify`
lists).
"""

from __future__ import annotations

import io
import json
import math
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ...labels import N_DIRECTIONS, STATES
from .index import EXTRA_NAME_RE, PARQUET_OPTIONS
from .info import DatasetInfo, EpisodeCounts
from .layout import EPISODES_INDEX, FRAMES_INDEX
from .problems import first, rows, short
from .records import SCHEMA_DIR, _violations

if TYPE_CHECKING:
    import pyarrow as pa

#: index/episodes.parquet's fixed columns, in table order; the episodes' own metadata follow
#: as nullable strings in name order.
EPISODE_COLUMNS = ("episode_index", "episode_id", "object", "session", "sensor", "fps",
                   "frame_start", "length", "duration_s", "dropped_frames", "slip_onset_s",
                   "calibration_sha256")
EPISODE_NULLABLE = ("slip_onset_s", "calibration_sha256")
#: index/frames.parquet's fixed columns; per-frame values the writer was given follow, in
#: name order (bool, int64, float64 or string, nullable).
FRAME_COLUMNS = ("episode_index", "frame_index", "timestamp", "state", "direction")
#: Keys a read episode or window holds beside the columns: no extra column may take them.
ITEM_KEYS = ("rgb", "depth", "contact", "timestamps", "pad_mask", "kind", "meta", "extra",
             "frames")
RESERVED = frozenset(EPISODE_COLUMNS + FRAME_COLUMNS + ITEM_KEYS)
#: Kinds of a per-frame extra column and their parquet types.
EXTRA_KINDS = ("bool", "int", "float", "string")
#: A gap between two timestamps over this many frame periods means frames were dropped.
DROP_GAP = 1.5
#: The JSON Schemas of this module's records.
EPISODE_SCHEMAS = ("episode", "episode_frame")
SHA256_HEX = frozenset("0123456789abcdef")


@lru_cache(maxsize=len(EPISODE_SCHEMAS))
def episode_schema(name: str) -> dict[str, Any]:
    """schemas/episode.schema.json or schemas/episode_frame.schema.json."""
    if name not in EPISODE_SCHEMAS:
        raise ValueError(f"unknown schema {name!r}; expected one of {EPISODE_SCHEMAS}")
    return json.loads((SCHEMA_DIR / f"{name}.schema.json").read_text())


def episode_schema_errors(doc: Any, name: str) -> list[str]:
    """Every violation of an episode schema by doc, one line each."""
    return _violations(episode_schema(name), doc)


@dataclass(frozen=True)
class EpisodeRecord:
    """One row of index/episodes.parquet; `meta` holds the episode's own string columns."""

    episode_index: int
    episode_id: str
    object: str
    session: str
    sensor: str
    fps: float
    frame_start: int
    length: int
    duration_s: float
    dropped_frames: int = 0
    slip_onset_s: float | None = None
    calibration_sha256: str | None = None
    meta: dict[str, str | None] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The row: fixed columns, then the metadata columns (the schema's document)."""
        return {**{c: getattr(self, c) for c in EPISODE_COLUMNS}, **dict(sorted(
            self.meta.items()))}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EpisodeRecord:
        return cls(**{c: d[c] for c in EPISODE_COLUMNS},
                   meta={k: v for k, v in d.items() if k not in EPISODE_COLUMNS})


@dataclass(frozen=True)
class FrameRecord:
    """One row of index/frames.parquet; `extra` holds the per-frame values a writer was given."""

    episode_index: int
    frame_index: int
    timestamp: float
    state: int | None = None
    direction: int | None = None
    extra: dict[str, bool | int | float | str | None] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {**{c: getattr(self, c) for c in FRAME_COLUMNS}, **dict(sorted(
            self.extra.items()))}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FrameRecord:
        return cls(**{c: d[c] for c in FRAME_COLUMNS},
                   extra={k: v for k, v in d.items() if k not in FRAME_COLUMNS})


def extra_name_problem(name: str) -> str | None:
    """Why a name cannot be an extra column (None when it can): a lowercase identifier of at
    most 64 characters that no fixed column or read item already takes."""
    if not isinstance(name, str) or not EXTRA_NAME_RE.match(name):
        return f"{short(str(name))!r} is not a plain lowercase name (a-z, 0-9, _; at most 64)"
    if name in RESERVED:
        return f"{name!r} is taken by the format (a fixed column or a key of a read item)"
    return None


def _arrow_type(kind: str) -> pa.DataType:
    import pyarrow as pa

    return {"bool": pa.bool_(), "int": pa.int64(), "float": pa.float64(),
            "string": pa.string()}[kind]


def episodes_arrow_schema(meta: Sequence[str] = ()) -> pa.Schema:
    """index/episodes.parquet's schema with these metadata columns (sorted)."""
    import pyarrow as pa

    types = {"episode_index": pa.int64(), "episode_id": pa.string(), "object": pa.string(),
             "session": pa.string(), "sensor": pa.string(), "fps": pa.float64(),
             "frame_start": pa.int64(), "length": pa.int64(), "duration_s": pa.float64(),
             "dropped_frames": pa.int64(), "slip_onset_s": pa.float64(),
             "calibration_sha256": pa.string()}
    fixed = [pa.field(c, types[c], nullable=c in EPISODE_NULLABLE) for c in EPISODE_COLUMNS]
    return pa.schema(fixed + [pa.field(m, pa.string()) for m in sorted(meta)])


def frames_arrow_schema(extra: Mapping[str, str] | None = None) -> pa.Schema:
    """index/frames.parquet's schema with these extra columns (name -> kind, sorted)."""
    import pyarrow as pa

    fixed = [pa.field("episode_index", pa.int64(), nullable=False),
             pa.field("frame_index", pa.int64(), nullable=False),
             pa.field("timestamp", pa.float64(), nullable=False),
             pa.field("state", pa.int8()), pa.field("direction", pa.int8())]
    return pa.schema(fixed + [pa.field(n, _arrow_type(k)) for n, k in sorted(
        (extra or {}).items())])


def table_bytes(table: pa.Table) -> bytes:
    """A table as parquet with the index's fixed settings (the same rows, the same bytes)."""
    import pyarrow.parquet as pq

    buf = io.BytesIO()
    pq.write_table(table, buf, **PARQUET_OPTIONS)
    return buf.getvalue()


def episodes_table(records: Sequence[EpisodeRecord]) -> pa.Table:
    """index/episodes.parquet's rows (episode_index 0..N-1 in order)."""
    import pyarrow as pa

    meta = sorted({k for r in records for k in r.meta})
    schema = episodes_arrow_schema(meta)
    return pa.Table.from_pylist([{**dict.fromkeys(meta), **r.to_dict()} for r in records],
                                schema=schema)


def duration_s(ts: np.ndarray, fps: float) -> float:
    """The span an episode's frames cover: last - first timestamp + one frame period."""
    return float(ts[-1] - ts[0] + 1.0 / fps)


def dropped_frames(ts: np.ndarray, fps: float) -> tuple[int, int]:
    """Frames missing from a take, and after which frame the largest gap lies (-1: none).

    A gap between two timestamps over DROP_GAP frame periods counts round(gap x fps) - 1."""
    gaps = np.diff(np.asarray(ts, np.float64))
    big = gaps > DROP_GAP / fps
    if not big.any():
        return 0, -1
    missing = np.maximum(np.rint(gaps[big] * fps).astype(np.int64) - 1, 1)
    return int(missing.sum()), int(np.argmax(np.where(big, gaps, -np.inf)))


def read_table(source: str | os.PathLike | bytes, which: str,
               where: str | os.PathLike | None = None) -> pa.Table:
    """index/episodes.parquet (which="episodes") or index/frames.parquet ("frames") from the
    dataset folder, the file or its bytes; its schema checked (the fixed columns, then extra
    columns of allowed names and types). A one-line VtsError naming the file otherwise."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ...jsonio import regular_file

    rel = EPISODES_INDEX if which == "episodes" else FRAMES_INDEX
    if isinstance(source, bytes):
        data: Any = pa.BufferReader(source)
        name: Any = where or rel
    else:
        path = Path(source)
        if path.is_dir():
            path = path / rel
        regular_file(path, "index")
        data, name = path, where or path
    try:
        table = pq.read_table(data)
    except (pa.ArrowException, OSError, KeyError, ValueError) as e:
        text = str(e).strip().splitlines()[0][:150] if str(e).strip() else type(e).__name__
        raise VtsError(f"not a readable parquet file ({text})", name) from None
    bad = _schema_problem(table.schema.remove_metadata(), which)
    if bad:
        raise VtsError(bad, name)
    return table


def _schema_problem(have: pa.Schema, which: str) -> str | None:
    import pyarrow as pa

    want = episodes_arrow_schema() if which == "episodes" else frames_arrow_schema()
    n = len(want)
    allowed = ({pa.string()} if which == "episodes"
               else {_arrow_type(k) for k in EXTRA_KINDS})
    ok = len(have) >= n and pa.schema(list(have)[:n]).equals(want)
    extra = list(have)[n:]
    if ok and all(f.type in allowed and f.nullable and extra_name_problem(f.name) is None
                  for f in extra) and len({f.name for f in extra}) == len(extra):
        return None
    found = ", ".join(f"{f.name}: {f.type}" for f in have)
    return f"columns differ from the {which} index schema (found {short(found, 300)})"


def extra_kinds(frames: pa.Table) -> dict[str, str]:
    """The extra columns of a frames table, name -> kind."""
    kinds = {str(_arrow_type(k)): k for k in EXTRA_KINDS}
    return {f.name: kinds[str(f.type)] for f in list(frames.schema)[len(FRAME_COLUMNS):]}


def _col(table: pa.Table, name: str, dtype: Any, fill: Any) -> np.ndarray:
    import pyarrow.compute as pc

    return np.asarray(pc.fill_null(table.column(name), fill)).astype(dtype)


def episodes_problems(episodes: pa.Table, frames: pa.Table, info: DatasetInfo) -> list[str]:
    """Problems of the two episode tables against each other, the frames store's length and
    info.json: rows in order, ids unique, episodes tiling the frames, timestamps finite and
    strictly increasing, labels in range, derived columns and counts as written."""
    out: list[str] = []
    ids = [s if s is not None else "?" for s in episodes.column("episode_id").to_pylist()]
    for t in (episodes, frames):
        for f in t.schema:
            if not f.nullable and t.column(f.name).null_count:
                mask = np.asarray(t.column(f.name).is_null())
                out += rows(mask, ids if t is episodes else _frame_ids(frames, ids),
                            f"{f.name} is null")
    if out:
        return out
    n = len(episodes)
    index = episodes.column("episode_index").to_numpy()
    if not np.array_equal(index, np.arange(n)):
        out.append("episode_index is not 0..N-1 in order")
    if len(set(ids)) != len(ids):
        dup = sorted(k for k, c in Counter(ids).items() if c > 1)
        out.append(f"{len(dup)} episode id(s) appear more than once: {first(dup)}")
    for c in ("episode_id", "object", "session", "sensor"):
        empty = np.array([not v for v in episodes.column(c).to_pylist()], bool)
        out += rows(empty, ids, f"{c} is empty")
    objects = episodes.column("object").to_pylist()
    out += rows(np.array([o not in info.objects for o in objects], bool), ids,
                "object not in info.json objects", lambda i: repr(short(objects[i])))
    fps = episodes.column("fps").to_numpy()
    length = episodes.column("length").to_numpy()
    start = episodes.column("frame_start").to_numpy()
    out += rows(~(np.isfinite(fps) & (fps > 0)), ids, "fps is not a positive number",
                lambda i: fps[i])
    out += rows(length < 1, ids, "length is not positive", lambda i: int(length[i]))
    want_start = np.concatenate([[0], np.cumsum(length)[:-1]]) if n else length
    out += rows(start != want_start, ids, "frame_start does not follow the previous episode",
                lambda i: f"{int(start[i])}, expected {int(want_start[i])}")
    total = int(length.sum()) if n else 0
    stored = info.shapes.get("episodes", {}).get("rgb", (0,))[0]
    if total != len(frames) or total != stored:
        out.append(f"episodes hold {total} frames, {FRAMES_INDEX} {len(frames)} rows, "
                   f"the frames store {stored}")
    if out:
        return out
    return _frame_problems(episodes, frames, ids, info)


def _frame_ids(frames: pa.Table, ids: Sequence[str]) -> list[str]:
    """`<episode id>/<frame index>` of every frame row (for problem lines)."""
    ep = _col(frames, "episode_index", np.int64, -1)
    fr = _col(frames, "frame_index", np.int64, -1)
    return [f"{ids[e] if 0 <= e < len(ids) else '?'}/{k}" for e, k in zip(ep, fr, strict=True)]


def _frame_problems(episodes: pa.Table, frames: pa.Table, ids: Sequence[str],
                    info: DatasetInfo) -> list[str]:
    """The frames against their episodes (which tile them exactly: checked before)."""
    out: list[str] = []
    length = episodes.column("length").to_numpy()
    fps = episodes.column("fps").to_numpy()
    starts = episodes.column("frame_start").to_numpy()
    ep = frames.column("episode_index").to_numpy()
    fr = frames.column("frame_index").to_numpy()
    want_ep = np.repeat(np.arange(len(length)), length)
    want_fr = np.arange(len(fr)) - np.repeat(starts, length)
    lazy: list[list[str]] = []

    def fids() -> list[str]:
        if not lazy:
            lazy.append(_frame_ids(frames, ids))
        return lazy[0]

    if not (np.array_equal(ep, want_ep) and np.array_equal(fr, want_fr)):
        bad = np.flatnonzero((ep != want_ep) | (fr != want_fr))
        out.append(f"{FRAMES_INDEX}: rows out of place (row {int(bad[0])} is episode "
                   f"{int(ep[bad[0]])} frame {int(fr[bad[0]])}, expected episode "
                   f"{int(want_ep[bad[0]])} frame {int(want_fr[bad[0]])})")
        return out
    ts = frames.column("timestamp").to_numpy()
    finite = np.isfinite(ts)
    out += rows(~finite | (ts < 0), fids(), "timestamp is not a finite number >= 0",
                lambda i: ts[i])
    later = np.ones(len(ts), bool)
    later[1:] = (ts[1:] > ts[:-1]) | (fr[1:] == 0)
    out += rows(~later, fids(), "timestamp not after the previous frame's",
                lambda i: f"{float(ts[i])!r} <= {float(ts[i - 1])!r}")
    state = _col(frames, "state", np.int64, -1)
    direction = _col(frames, "direction", np.int64, -1)
    known = np.asarray(frames.column("state").is_valid())
    out += rows(known & ((state < 0) | (state >= len(STATES))), fids(),
                f"state outside 0..{len(STATES) - 1}", lambda i: int(state[i]))
    has_dir = np.asarray(frames.column("direction").is_valid())
    out += rows(has_dir & ((direction < 0) | (direction >= N_DIRECTIONS)), fids(),
                f"direction outside 0..{N_DIRECTIONS - 1}", lambda i: int(direction[i]))
    out += rows(has_dir & (state != STATES.index("slip")), fids(),
                "a direction on a frame whose state is not slip")
    if out:
        return out
    onset = _col(episodes, "slip_onset_s", np.float64, np.nan)
    duration = episodes.column("duration_s").to_numpy()
    drops = episodes.column("dropped_frames").to_numpy()
    for i, (a, n) in enumerate(zip(starts, length, strict=True)):
        t = ts[a:a + n]
        span, rate = duration_s(t, fps[i]), float(fps[i])
        if not math.isclose(duration[i], span, rel_tol=1e-9, abs_tol=1e-12):
            out.append(f"episode {ids[i]}: duration_s {float(duration[i])!r} contradicts its "
                       f"timestamps ({span!r})")
        if drops[i] != dropped_frames(t, rate)[0]:
            out.append(f"episode {ids[i]}: dropped_frames {int(drops[i])} contradicts its "
                       f"timestamps ({dropped_frames(t, rate)[0]})")
        if not np.isnan(onset[i]) and not t[0] <= onset[i] <= t[-1]:
            out.append(f"episode {ids[i]}: slip_onset_s {float(onset[i])!r} outside the take "
                       f"({float(t[0])!r} to {float(t[-1])!r} s)")
    cal = episodes.column("calibration_sha256").to_pylist()
    out += rows(np.array([c is not None and (len(c) != 64 or not set(c) <= SHA256_HEX)
                          for c in cal], bool), ids, "calibration_sha256 is not a sha256")
    if info.episodes is not None:
        got, want = episode_counts(episodes, frames).to_dict(), info.episodes.to_dict()
        diff = [k for k in got if got[k] != want[k]]
        if diff:
            out.append(f"info.json episodes.{diff[0]} contradicts the episode indexes "
                       f"(info.json {short(str(want[diff[0]]), 120)}, indexes "
                       f"{short(str(got[diff[0]]), 120)})")
    return out


def episode_counts(episodes: pa.Table, frames: pa.Table) -> EpisodeCounts:
    """info.json's `episodes` of the two tables."""
    def tally(values: Sequence[Any]) -> dict[str, int]:
        return dict(sorted(Counter(values).items()))

    states = [STATES[s] if s is not None and 0 <= s < len(STATES) else "unknown"
              for s in frames.column("state").to_pylist()]
    return EpisodeCounts(len(episodes), len(frames), tally(episodes.column("object").to_pylist()),
                         tally(episodes.column("session").to_pylist()), tally(states),
                         int(np.sum(episodes.column("dropped_frames").to_numpy())))


def check_tables(episodes: pa.Table, frames: pa.Table, info: DatasetInfo,
                 where: str | os.PathLike) -> None:
    """episodes_problems as a one-line VtsError naming `where` (the index folder)."""
    bad = episodes_problems(episodes, frames, info)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise VtsError(f"{bad[0]}{more}", where)
