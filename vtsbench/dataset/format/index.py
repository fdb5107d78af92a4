"""The parquet index of a dataset (`index/<kind>.parquet`): its row format, the bytes a build
writes, THE reader every part of vtsbench uses (`read_index`), and its checks.

Rows are in Zarr row order with the schema of `index_schema(kind)` (its variant with nullable
mm_per_px columns when a sample's scale is unknown, which only a build without depth allows),
followed by the recordings' own string columns; the writer's settings are fixed, so the same
rows give the same bytes. The checks (`index_problems`, `ids_problems`, `counts_problems`) are
what `vtsbench.load` raises the first of and `vtsbench verify` lists.
"""

from __future__ import annotations

import io
import os
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ...labels import STATES
from .info import DatasetInfo, KindCounts
from .layout import KINDS, group_path, index_path
from .problems import first, rows, short
from .records import INDEX_COLUMNS, SLIP_ONLY, SampleMeta, static_columns

if TYPE_CHECKING:
    import pyarrow as pa

#: Parquet settings: zstd pages, one row group (an index is small), statistics on.
PARQUET_OPTIONS: dict[str, Any] = {"compression": "zstd", "compression_level": 3,
                                   "use_dictionary": True, "write_statistics": True,
                                   "row_group_size": 1 << 20}
#: An extra index column's name: a lowercase identifier (the field's name, cleaned).
EXTRA_NAME_RE = re.compile(r"^[a-z_][a-z0-9_]{0,63}$")
DIRECTIONS = 8
#: Format 1.3, samples as views of the episode store (info.json sample_storage "episodes"):
#: two int64 columns after the fixed ones, the sample's episode (its row in
#: index/episodes.parquet) and the store row of its first frame (in data/episodes.zarr); a
#: sample's frames are rows frame_row .. frame_row + T - 1 (T = 1 for a static frame).
VIEW_COLUMNS = ("episode_index", "frame_row")


def index_schema(kind: str, scale_known: bool = True, views: bool = False) -> pa.Schema:
    """The pyarrow schema of index/<kind>.parquet (docs/dataset.md, Index columns).

    scale_known=False: mm_per_px_x and mm_per_px_y may be null, in a dataset built without
    depth from sessions whose scale is unknown (every other dataset has them). views=True:
    followed by VIEW_COLUMNS (format 1.3, samples as views of the episode store).
    """
    import pyarrow as pa

    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    types = {"sample_id": pa.string(), "row": pa.int64(), "object": pa.string(),
             "class_idx": pa.int32(), "session": pa.string(), "sensor": pa.string(),
             "mm_per_px_x": pa.float64(), "mm_per_px_y": pa.float64(),
             "press_depth_mm": pa.float64(), "contact_x_px": pa.float64(),
             "contact_y_px": pa.float64(), "state": pa.string(), "state_idx": pa.int32(),
             "direction": pa.int32(), "motion_dx_mm": pa.float64(), "motion_dy_mm": pa.float64(),
             "source": pa.string()}
    nullable = {"press_depth_mm", "contact_x_px", "contact_y_px", *SLIP_ONLY}
    if not scale_known:
        nullable |= {"mm_per_px_x", "mm_per_px_y"}
    cols = INDEX_COLUMNS if kind == "slip" else static_columns()
    fields = [pa.field(c, types[c], nullable=c in nullable) for c in cols]
    return pa.schema(fields + ([pa.field(c, pa.int64(), nullable=False) for c in VIEW_COLUMNS]
                               if views else []))


def index_schema_of(table_schema: pa.Schema, kind: str) -> pa.Schema | None:
    """The index schema (either scale variant) a read table has, or None if neither.

    The fixed columns may be followed by extra nullable string columns: the recordings' own
    fields (pattern fields, `take`, keys of an entry's meta), see `extra_column_name`; and by
    the int64 VIEW_COLUMNS, each at most once (format 1.3: whether info.json wants them is
    `index_problems`'s check)."""
    import pyarrow as pa

    have = table_schema.remove_metadata()
    for known in (True, False):
        want = index_schema(kind, known)
        n = len(want)
        if len(have) < n or not pa.schema(list(have)[:n]).equals(want):
            continue
        extra = list(have)[n:]
        views = [f.name for f in extra if f.name in VIEW_COLUMNS and f.type == pa.int64()]
        if len(set(views)) == len(views) and all(
                f.name in views or (f.type == pa.string() and f.nullable
                                    and EXTRA_NAME_RE.match(f.name)
                                    and f.name not in INDEX_COLUMNS) for f in extra):
            return have
    return None


def extra_column_name(key: str) -> str | None:
    """The index column for a recording's own field or meta key: lowercased, other characters
    as '_', prefixed `meta_` where it would shadow a fixed column; None if nothing is left."""
    name = re.sub(r"[^a-z0-9_]+", "_", str(key).strip().lower()).strip("_")[:58]
    if not name:
        return None
    if name[0].isdigit() or name in (*INDEX_COLUMNS, *VIEW_COLUMNS, "kind", "labels", "meta"):
        name = f"meta_{name}"
    return name if EXTRA_NAME_RE.match(name) else None


def index_bytes(kind: str, metas: Sequence[SampleMeta],
                extra: Mapping[str, Sequence[str | None]] | None = None, *,
                views: Mapping[str, Sequence[int]] | None = None) -> bytes:
    """The parquet file of one kind's index; rows must be in row order 0..N-1.

    extra: more string columns (name -> one value per row, None where a row has none), after
    the fixed ones in name order: the recordings' own fields, which `where()` filters on.
    views (format 1.3, samples as views of the episode store): VIEW_COLUMNS name -> one
    integer per row, written right after the fixed columns."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    for i, m in enumerate(metas):
        if m.kind != kind or m.row != i:
            raise ValueError(f"index row {i}: sample {m.sample_id!r} ({m.kind}, row {m.row}) is "
                             f"out of place in the {kind} index")
    known = all(m.mm_per_px_x is not None and m.mm_per_px_y is not None for m in metas)
    table = pa.Table.from_pylist([m.to_row() for m in metas], schema=index_schema(kind, known))
    if views is not None:
        if set(views) != set(VIEW_COLUMNS) or any(len(views[c]) != len(metas)
                                                   for c in VIEW_COLUMNS):
            raise ValueError(f"views: {', '.join(VIEW_COLUMNS)}, one integer per row each")
        for c in VIEW_COLUMNS:
            table = table.append_column(pa.field(c, pa.int64(), nullable=False),
                                        pa.array(np.asarray(views[c], np.int64)))
    for name in sorted(extra or {}):
        values = list((extra or {})[name])
        if len(values) != len(metas) or extra_column_name(name) != name:
            raise ValueError(f"extra index column {name!r}: bad name or {len(values)} values "
                             f"for {len(metas)} rows")
        table = table.append_column(pa.field(name, pa.string(), nullable=True),
                                    pa.array(values, pa.string()))
    buf = io.BytesIO()
    pq.write_table(table, buf, **PARQUET_OPTIONS)
    return buf.getvalue()


def read_index(source: str | os.PathLike | bytes, kind: str, info: DatasetInfo | None = None,
               *, columns: Sequence[str] | None = None,
               where: str | os.PathLike | None = None) -> pa.Table:
    """THE reader of a dataset's index, `index/<kind>.parquet`: the loader, `vtsbench verify`
    and `vtsbench info` read it here, and so should any other reader.

    source: the dataset folder, the parquet file itself, or its bytes (a caller that fetched
    them from a URL, e.g. `Location.read_bytes(index_path(kind))`, names that URL in `where`).
    Checked: the kind's index schema (the fixed columns, then the recordings' own string
    columns); given the dataset's `info`, all that `vtsbench.load` and `verify` check of an
    index (`index_problems`: rows 0..N-1 in order, known objects and their class_idx, values
    in range). columns: read only those columns, unchecked (a summary's counts). Returns the
    rows as a pyarrow Table in row order (`read_metas`: as SampleMeta); a missing, unreadable
    or failing file is a one-line VtsError naming it.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ...jsonio import regular_file

    if isinstance(source, bytes):
        data: Any = pa.BufferReader(source)
        name: Any = where or index_path(kind)
    else:
        path = Path(source)
        if path.is_dir() and not path.as_posix().endswith(index_path(kind)):  # (the file
            # itself a folder is said so below)
            path = path / index_path(kind)
        regular_file(path, "index")  # a folder, a FIFO or a device is said as such
        data, name = path, where or path
    try:
        table = pq.read_table(data, columns=None if columns is None else list(columns))
    except (pa.ArrowException, OSError, KeyError, ValueError) as e:
        text = str(e).strip().splitlines()[0][:150] if str(e).strip() else type(e).__name__
        raise VtsError(f"not a readable parquet file ({text})", name) from None
    if columns is not None:
        return table
    bad = index_problems(table, kind, info) if info is not None else _schema_problems(table, kind)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise VtsError(f"{bad[0]}{more}", name)
    return table


def read_metas(source: str | os.PathLike | bytes, kind: str) -> list[SampleMeta]:
    """The rows of one kind's index as SampleMeta (`read_index`, schema checked)."""
    table = read_index(source, kind)
    try:
        return [SampleMeta.from_row(r, kind) for r in table.to_pylist()]
    except (TypeError, ValueError) as e:
        raise VtsError(f"bad row ({e})", source if not isinstance(source, bytes) else None
                       ) from None


def _schema_problems(table: pa.Table, kind: str) -> list[str]:
    if index_schema_of(table.schema, kind) is None:
        have = ", ".join(f"{f.name}: {f.type}" for f in table.schema)
        return [f"columns differ from the {kind} index schema (found {short(have, 300)})"]
    return []


def column_values(table: pa.Table, name: str) -> np.ndarray:
    """A numeric column as float64, NaN where null."""
    import pyarrow.compute as pc

    return np.asarray(pc.fill_null(pc.cast(table.column(name), "float64"), np.nan))


def _nonfinite(table: pa.Table, name: str) -> np.ndarray:
    """Rows whose value is set but NaN or infinite."""
    import pyarrow.compute as pc

    return np.asarray(pc.fill_null(pc.invert(pc.is_finite(table.column(name))), False))


def _nulls(table: pa.Table, name: str) -> np.ndarray:
    return np.asarray(table.column(name).is_null())


def index_problems(table: pa.Table, kind: str, info: DatasetInfo) -> list[str]:
    """Problems of one kind's index table against its schema and info.json."""
    import pyarrow as pa
    import pyarrow.compute as pc

    schema_bad = _schema_problems(table, kind)
    if schema_bad:
        return schema_bad
    ids = table.column("sample_id").to_pylist()
    ids = [i if i is not None else "?" for i in ids]
    out = []
    n = info.shapes.get(kind, {}).get("rgb", (0,))[0]
    if len(ids) != n:
        out.append(f"{len(ids)} rows, info.json says {n} samples of {group_path(kind)}")
    for f in table.schema:
        if not f.nullable:
            out += rows(_nulls(table, f.name), ids, f"{f.name} is null")
        if f.type == pa.string() and f.name in ("sample_id", "object", "session", "sensor"):
            out += rows(np.asarray(pc.fill_null(pc.equal(pc.utf8_length(table.column(f.name)),
                                                         0), False)), ids, f"{f.name} is empty")
    if out:
        return out
    row = table.column("row").to_numpy()
    off = np.flatnonzero(row != np.arange(len(row)))
    if len(off):
        i = int(off[0])
        out.append(f"sample {short(ids[i])} at position {i} has row {int(row[i])} (rows must be "
                   "0..N-1 in index order)")
    if len(set(ids)) != len(ids):
        dup = [k for k, c in Counter(ids).items() if c > 1]
        out.append(f"{len(dup)} sample id(s) appear more than once: {first(sorted(dup))}")
    objs = table.column("object")
    where = np.asarray(pc.fill_null(pc.index_in(objs, value_set=pa.array(info.objects,
                                                                        pa.string())), -1))
    objects = objs.to_pylist()
    out += rows(where < 0, ids, "object not in info.json objects", lambda i: repr(
        short(objects[i])))
    cls = table.column("class_idx").to_numpy()
    out += rows((where >= 0) & (cls != where), ids,
                "class_idx contradicts the object's place in info.json objects",
                lambda i: f"class_idx {int(cls[i])}, {objects[i]!r} is {int(where[i])}")
    out += _value_problems(table, kind, info, ids)
    return out + _view_column_problems(table, info, ids)


def view_columns(table: pa.Table) -> list[str]:
    """The VIEW_COLUMNS an index table has (int64), in that order."""
    import pyarrow as pa

    names = {f.name for f in table.schema if f.type == pa.int64()}
    return [c for c in VIEW_COLUMNS if c in names]


def _view_column_problems(table: pa.Table, info: DatasetInfo, ids: Sequence[str]) -> list[str]:
    """VIEW_COLUMNS present exactly when info.json says the samples are views of the episode
    store (sample_storage "episodes"), with no nulls and no negative values."""
    have = view_columns(table)
    if info.views and len(have) < len(VIEW_COLUMNS):
        missing = [c for c in VIEW_COLUMNS if c not in have]
        return [f"no {' or '.join(missing)} column, and info.json says sample_storage "
                f"{info.sample_storage!r} (each sample is a view of the episode store)"]
    if not info.views and have:
        return [f"a {have[0]} column, and info.json says no sample_storage (the samples are "
                "stored, not views of the episode store)"]
    out = []
    for c in have:
        out += rows(_nulls(table, c), ids, f"{c} is null")
        vals = column_values(table, c)
        out += rows(vals < 0, ids, f"{c} is negative", lambda i, v=vals: f"{v[i]:.0f}")
    return out


def frame_rows(table: pa.Table, kind: str, frames_per_sequence: int,
               frames: np.ndarray | None = None) -> np.ndarray:
    """The episode-store rows of each sample of a views index (format 1.3), (n, T) int64 in
    index order: frame_row + 0..T-1 for slip (T = frames_per_sequence), frame_row for static
    (T = 1); `frames` keeps those frame numbers of each slip sequence."""
    return store_rows(table.column("frame_row").to_numpy(zero_copy_only=False), kind,
                      frames_per_sequence, frames)


def store_rows(start: np.ndarray, kind: str, frames_per_sequence: int,
               frames: np.ndarray | None = None) -> np.ndarray:
    """frame_rows from the samples' first store rows (`start`, one per sample), (n, T) int64."""
    offsets = np.arange(frames_per_sequence if kind == "slip" else 1, dtype=np.int64)
    if frames is not None:
        offsets = offsets[np.asarray(frames, np.int64)]
    return np.asarray(start, np.int64)[:, None] + offsets[None, :]


def view_problems(table: pa.Table, kind: str, frames_per_sequence: int, starts: np.ndarray,
                  lengths: np.ndarray) -> list[str]:
    """Where a views index (format 1.3) contradicts the episodes it views: an episode_index
    of no episode, and a sample whose frames (frame_row .. frame_row + T - 1) are not all
    inside its episode's [frame_start, frame_start + length); one line per kind of problem.
    starts, lengths: index/episodes.parquet's frame_start and length, by episode row."""
    if len(view_columns(table)) < len(VIEW_COLUMNS):
        return []
    ids = [i if i is not None else "?" for i in table.column("sample_id").to_pylist()]
    starts, lengths = np.asarray(starts, np.int64), np.asarray(lengths, np.int64)
    ep = np.asarray(column_values(table, "episode_index"))
    row = np.asarray(column_values(table, "frame_row"))
    bad = ~np.isfinite(ep) | (ep < 0) | (ep >= len(starts))
    out = rows(bad, ids, f"episode_index is no episode of index/episodes.parquet "
               f"({len(starts)} episodes)", lambda i: f"{ep[i]:.0f}")
    t = frames_per_sequence if kind == "slip" else 1
    e = np.where(bad, 0, ep).astype(np.int64)
    lo = starts[e] if len(starts) else np.zeros(len(e), np.int64)
    hi = lo + (lengths[e] if len(lengths) else 0)
    outside = ~bad & np.isfinite(row) & ((row < lo) | (row + t > hi))
    what = "frame rows" if t > 1 else "frame row"
    out += rows(outside, ids, f"{what} outside the sample's episode",
                lambda i: f"rows {row[i]:.0f}..{row[i] + t - 1:.0f}, episode {e[i]} holds "
                          f"{lo[i]}..{hi[i] - 1}" if t > 1 else
                          f"row {row[i]:.0f}, episode {e[i]} holds {lo[i]}..{hi[i] - 1}")
    return out


def _value_problems(table: pa.Table, kind: str, info: DatasetInfo,
                    ids: Sequence[str]) -> list[str]:
    """Numbers finite and in range, the contact point inside the frame, slip labels valid."""
    out = []
    floats = [f.name for f in table.schema if str(f.type) == "double"]
    vals = {c: column_values(table, c) for c in floats}
    for c in floats:
        out += rows(_nonfinite(table, c), ids, f"{c} is not finite", lambda i, c=c: vals[c][i])
    for c in ("mm_per_px_x", "mm_per_px_y"):
        out += rows(vals[c] <= 0, ids, f"{c} is not positive", lambda i, c=c: vals[c][i])
    out += rows(_nulls(table, "mm_per_px_x") != _nulls(table, "mm_per_px_y"), ids,
                "mm_per_px known on one axis only")
    out += rows(vals["press_depth_mm"] < 0, ids, "press_depth_mm is negative",
                lambda i: vals["press_depth_mm"][i])
    x, y = vals["contact_x_px"], vals["contact_y_px"]
    h, w = info.resolution
    out += rows(_nulls(table, "contact_x_px") != _nulls(table, "contact_y_px"), ids,
                "contact_px known on one axis only")
    out += rows((x < 0) | (x > w) | (y < 0) | (y > h), ids,
                f"contact_px outside the {w}x{h} frame", lambda i: f"{x[i]:.6g}, {y[i]:.6g}")
    if kind != "slip":
        return out
    state = table.column("state").to_pylist()
    sidx = column_values(table, "state_idx")
    dirs = column_values(table, "direction")
    known = np.array([s is None or s in STATES for s in state], bool)
    out += rows(~known, ids, "unknown state", lambda i: repr(short(state[i])))
    want = np.array([np.nan if s not in STATES else STATES.index(s) for s in state], float)
    out += rows(known & ~((want == sidx) | (np.isnan(want) & np.isnan(sidx))), ids,
                "state_idx contradicts state", lambda i: f"{state[i]!r}, {sidx[i]:g}")
    bad_dir = ~np.isnan(dirs) & ((dirs < 0) | (dirs >= DIRECTIONS))
    out += rows(bad_dir, ids, f"direction outside 0..{DIRECTIONS - 1}", lambda i: f"{dirs[i]:g}")
    is_slip = np.array([s == "slip" for s in state], bool)
    out += rows(~np.isnan(dirs) & ~is_slip & ~bad_dir, ids,
                "a direction on a sample whose state is not slip",
                lambda i: f"{state[i]!r}, {dirs[i]:g}")
    return out


def ids_problems(tables: Mapping[str, pa.Table]) -> list[str]:
    """Sample ids found in both indexes."""
    if len(tables) < 2:
        return []
    import pyarrow.compute as pc

    a, b = (tables[k].column("sample_id") for k in KINDS)
    both = pc.filter(a, pc.is_in(a, value_set=b.combine_chunks())).to_pylist()
    if not both:
        return []
    return [f"{len(both)} sample id(s) in both {index_path('static')} and "
            f"{index_path('slip')}: {first(both)}"]


def kind_counts(table: pa.Table, kind: str) -> KindCounts:
    """KindCounts of an index table (as `KindCounts.of` counts its rows)."""
    def tally(values: Sequence[Any]) -> dict[str, int]:
        return dict(sorted(Counter(values).items()))

    objects = table.column("object").to_pylist()
    sessions = table.column("session").to_pylist()
    if kind != "slip":
        return KindCounts(len(objects), tally(objects), tally(sessions))
    state = table.column("state").to_pylist()
    dirs = table.column("direction").to_pylist()
    return KindCounts(len(objects), tally(objects), tally(sessions),
                      tally([s or "unknown" for s in state]),
                      tally(["unknown" if d is None else str(d)
                             for s, d in zip(state, dirs, strict=True) if s == "slip"]))


def counts_problems(info: DatasetInfo, tables: Mapping[str, pa.Table]) -> list[str]:
    """Where info.json's counts of a kind contradict its index."""
    out = []
    for kind, table in tables.items():
        got = kind_counts(table, kind).to_dict()
        want = getattr(info.counts, kind).to_dict()
        diff = [k for k in got if got[k] != want.get(k)]
        if diff:
            out.append(f"counts.{kind}.{diff[0]} contradicts {index_path(kind)} "
                       f"(info.json {short(str(want.get(diff[0])), 120)}, index "
                       f"{short(str(got[diff[0]]), 120)})")
    return out
