"""The checks that decide whether a dataset may be read, shared by `vtsbench.load` (which raises
the first problem) and `vtsbench verify` (which lists them all, then adds the expensive checks:
every file's sha256 and every chunk decoded).

Checked here: info.json beyond its schema (plain split names, file paths inside the dataset),
the index (schema, rows 0..N-1 in order, unique ids, known objects and their class_idx, finite
values in range, contact points inside the frame, slip labels), counts, split files (name, kind,
ids known, parts of the right size, leaks) and the Zarr metadata (shape, dtype, chunks, depth
scale, per-array zarr.json against the consolidated copy, the format that wrote the arrays).
Each function returns one line per kind of problem, with a count and the first few offenders, so
a split of a million unknown ids is one line.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..labels import STATES
from .schema import (
    KINDS,
    DatasetInfo,
    KindCounts,
    SplitFile,
    _minor,
    index_schema_of,
    info_problems,
)
from .store import DTYPES

if TYPE_CHECKING:
    import pyarrow as pa

#: Offenders shown in one problem line.
SHOWN = 3
#: A split file may list each sample of the dataset at most once, and hold at most 1 MiB plus
#: 512 bytes a sample (an id is at most 160 characters).
SPLIT_BASE_BYTES = 1 << 20
SPLIT_BYTES_PER_SAMPLE = 512
DIRECTIONS = 8
SLIP = "slip"


def split_limits(n_samples: int) -> tuple[int, int]:
    """(bytes, ids) a split file of a dataset of n_samples samples may hold."""
    return SPLIT_BASE_BYTES + SPLIT_BYTES_PER_SAMPLE * n_samples, n_samples


def _short(v: Any, n: int = 60) -> Any:
    return v[:n] + "..." if isinstance(v, str) and len(v) > n else v


def _first(values: Sequence[Any]) -> str:
    """The first few values, quoted; '...' when there are more."""
    shown = ", ".join(repr(_short(v)) for v in list(values[:SHOWN]))
    return shown + (", ..." if len(values) > SHOWN else "")


def _rows(mask: np.ndarray, ids: Sequence[str], what: str,
          detail: Any = None) -> list[str]:
    """One line for the rows where mask holds: how many, and the first few by sample id."""
    hit = np.flatnonzero(mask)
    if not len(hit):
        return []
    shown = ", ".join(f"{_short(ids[i])}" + (f" ({detail(i)})" if detail else "")
                      for i in hit[:SHOWN])
    more = ", ..." if len(hit) > SHOWN else ""
    return [f"{what} in {len(hit)} row(s) (first: {shown}{more})"]


def _col(table: pa.Table, name: str) -> Any:
    return table.column(name)


def _nonfinite(table: pa.Table, name: str) -> np.ndarray:
    """Rows whose value is set but NaN or infinite."""
    import pyarrow.compute as pc

    c = _col(table, name)
    return np.asarray(pc.fill_null(pc.invert(pc.is_finite(c)), False))


def _values(table: pa.Table, name: str) -> np.ndarray:
    """A numeric column as float64, NaN where null."""
    import pyarrow.compute as pc

    return np.asarray(pc.fill_null(pc.cast(_col(table, name), "float64"), np.nan))


def _nulls(table: pa.Table, name: str) -> np.ndarray:
    return np.asarray(_col(table, name).is_null())


def index_problems(table: pa.Table, kind: str, info: DatasetInfo) -> list[str]:
    """Problems of one kind's index table against its schema and info.json."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if index_schema_of(table.schema, kind) is None:
        have = ", ".join(f"{f.name}: {f.type}" for f in table.schema)
        return [f"columns differ from the {kind} index schema (found {_short(have, 300)})"]
    ids = table.column("sample_id").to_pylist()
    ids = [i if i is not None else "?" for i in ids]
    out = []
    n = info.shapes.get(kind, {}).get("rgb", (0,))[0]
    if len(ids) != n:
        out.append(f"{len(ids)} rows, info.json says {n} samples of data/{kind}.zarr")
    for f in table.schema:
        if not f.nullable:
            out += _rows(_nulls(table, f.name), ids, f"{f.name} is null")
        if f.type == pa.string() and f.name in ("sample_id", "object", "session", "sensor"):
            out += _rows(np.asarray(pc.fill_null(pc.equal(pc.utf8_length(_col(table, f.name)),
                                                          0), False)), ids, f"{f.name} is empty")
    if out:
        return out
    rows = table.column("row").to_numpy()
    off = np.flatnonzero(rows != np.arange(len(rows)))
    if len(off):
        i = int(off[0])
        out.append(f"sample {_short(ids[i])} at position {i} has row {int(rows[i])} (rows must be "
                   "0..N-1 in index order)")
    if len(set(ids)) != len(ids):
        dup = [k for k, c in Counter(ids).items() if c > 1]
        out.append(f"{len(dup)} sample id(s) appear more than once: {_first(sorted(dup))}")
    objs = table.column("object")
    where = np.asarray(pc.fill_null(pc.index_in(objs, value_set=pa.array(info.objects,
                                                                        pa.string())), -1))
    objects = objs.to_pylist()
    out += _rows(where < 0, ids, "object not in info.json objects", lambda i: repr(
        _short(objects[i])))
    cls = table.column("class_idx").to_numpy()
    out += _rows((where >= 0) & (cls != where), ids,
                 "class_idx contradicts the object's place in info.json objects",
                 lambda i: f"class_idx {int(cls[i])}, {objects[i]!r} is {int(where[i])}")
    out += _value_problems(table, kind, info, ids)
    return out


def _value_problems(table: pa.Table, kind: str, info: DatasetInfo,
                    ids: Sequence[str]) -> list[str]:
    """Numbers finite and in range, the contact point inside the frame, slip labels valid."""
    out = []
    floats = [f.name for f in table.schema if str(f.type) == "double"]
    vals = {c: _values(table, c) for c in floats}
    for c in floats:
        out += _rows(_nonfinite(table, c), ids, f"{c} is not finite",
                     lambda i, c=c: vals[c][i])
    for c in ("mm_per_px_x", "mm_per_px_y"):
        out += _rows(vals[c] <= 0, ids, f"{c} is not positive", lambda i, c=c: vals[c][i])
    out += _rows(_nulls(table, "mm_per_px_x") != _nulls(table, "mm_per_px_y"), ids,
                 "mm_per_px known on one axis only")
    out += _rows(vals["press_depth_mm"] < 0, ids, "press_depth_mm is negative",
                 lambda i: vals["press_depth_mm"][i])
    x, y = vals["contact_x_px"], vals["contact_y_px"]
    h, w = info.resolution
    out += _rows(_nulls(table, "contact_x_px") != _nulls(table, "contact_y_px"), ids,
                 "contact_px known on one axis only")
    out += _rows((x < 0) | (x > w) | (y < 0) | (y > h), ids,
                 f"contact_px outside the {w}x{h} frame", lambda i: f"{x[i]:.6g}, {y[i]:.6g}")
    if kind != SLIP:
        return out
    state = table.column("state").to_pylist()
    sidx = _values(table, "state_idx")
    dirs = _values(table, "direction")
    known = np.array([s is None or s in STATES for s in state], bool)
    out += _rows(~known, ids, "unknown state", lambda i: repr(_short(state[i])))
    want = np.array([np.nan if s not in STATES else STATES.index(s) for s in state], float)
    out += _rows(known & ~((want == sidx) | (np.isnan(want) & np.isnan(sidx))), ids,
                 "state_idx contradicts state", lambda i: f"{state[i]!r}, {sidx[i]:g}")
    bad_dir = ~np.isnan(dirs) & ((dirs < 0) | (dirs >= DIRECTIONS))
    out += _rows(bad_dir, ids, f"direction outside 0..{DIRECTIONS - 1}",
                 lambda i: f"{dirs[i]:g}")
    is_slip = np.array([s == SLIP for s in state], bool)
    out += _rows(~np.isnan(dirs) & ~is_slip & ~bad_dir, ids,
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
    return [f"{len(both)} sample id(s) in both index/static.parquet and index/slip.parquet: "
            f"{_first(both)}"]


def kind_counts(table: pa.Table, kind: str) -> KindCounts:
    """KindCounts of an index table (as `KindCounts.of` counts its rows)."""
    def tally(values: Sequence[Any]) -> dict[str, int]:
        return dict(sorted(Counter(values).items()))

    objects = table.column("object").to_pylist()
    sessions = table.column("session").to_pylist()
    if kind != SLIP:
        return KindCounts(len(objects), tally(objects), tally(sessions))
    state = table.column("state").to_pylist()
    dirs = table.column("direction").to_pylist()
    return KindCounts(len(objects), tally(objects), tally(sessions),
                      tally([s or "unknown" for s in state]),
                      tally(["unknown" if d is None else str(d)
                             for s, d in zip(state, dirs, strict=True) if s == SLIP]))


def counts_problems(info: DatasetInfo, tables: Mapping[str, pa.Table]) -> list[str]:
    """Where info.json's counts of a kind contradict its index."""
    out = []
    for kind, table in tables.items():
        got = kind_counts(table, kind).to_dict()
        want = getattr(info.counts, kind).to_dict()
        diff = [k for k in got if got[k] != want.get(k)]
        if diff:
            out.append(f"counts.{kind}.{diff[0]} contradicts index/{kind}.parquet "
                       f"(info.json {_short(str(want.get(diff[0])), 120)}, index "
                       f"{_short(str(got[diff[0]]), 120)})")
    return out


def split_problems(split: SplitFile, name: str, info: DatasetInfo,
                   tables: Mapping[str, pa.Table]) -> tuple[list[str], list[str]]:
    """(problems, leaks) of a split file listed as `name` in info.json: its name and kind, ids
    not in its kind's index, part sizes against info.json counts; leaks are ids in two parts
    and values of a disjoint rule's key shared by parts it keeps apart."""
    import pyarrow as pa
    import pyarrow.compute as pc

    out: list[str] = []
    if split.name != name:
        out.append(f"the file names its split {_short(split.name)!r}, info.json {name!r}")
    sizes = {p: len(v) for p, v in split.parts.items()}
    want = info.counts.splits.get(name)
    if want is not None and sizes != want:
        diff = sorted(set(sizes) | set(want), key=str)
        p = next(k for k in diff if sizes.get(k) != want.get(k))
        out.append(f"part {_short(p)} has {sizes.get(p, 'no')} samples, info.json counts.splits "
                   f"says {want.get(p, 'none')}")
    table = tables.get(split.kind)
    if table is None:
        return out, []
    index = table.column("sample_id").combine_chunks()
    other = [t.column("sample_id").combine_chunks() for k, t in tables.items()
             if k != split.kind]
    order = sorted(split.parts, key=_part_rank)
    pos: dict[str, np.ndarray] = {}
    for part in order:
        ids = pa.array(split.parts[part], pa.string())
        at = np.asarray(pc.fill_null(pc.index_in(ids, value_set=index), -1), np.int64)
        pos[part] = at[at >= 0]
        missing = ids.filter(pa.array(at < 0))
        if not len(missing):
            continue
        elsewhere = (pc.is_in(missing, value_set=other[0]) if other
                     else pa.array(np.zeros(len(missing), bool)))
        wrong = missing.filter(elsewhere)
        unknown = missing.filter(pc.invert(elsewhere))
        if len(wrong):
            out.append(f"part {part}: {len(wrong)} id(s) of samples of the other kind in a "
                       f"{split.kind} split: {_first(wrong.slice(0, SHOWN + 1).to_pylist())}")
        if len(unknown):
            out.append(f"part {part}: {len(unknown)} sample id(s) not in "
                       f"index/{split.kind}.parquet: "
                       f"{_first(unknown.slice(0, SHOWN + 1).to_pylist())}")
    leaks = []
    ids_col = table.column("sample_id")
    for i, a in enumerate(order):
        for b in order[i + 1:]:
            both = np.intersect1d(pos[a], pos[b])
            if len(both) == 1:
                leaks.append(f"sample {ids_col[int(both[0])].as_py()!r} in both {a} and {b}")
            elif len(both):
                shown = ids_col.take(pa.array(both[:SHOWN + 1])).to_pylist()
                leaks.append(f"{len(both)} samples in both {a} and {b}: {_first(shown)}")
    for rule in split.disjoint:
        bad, found = _rule_leaks(split, rule, order, table, pos)
        out += bad
        leaks += found
    return out, leaks


def _part_rank(part: str) -> tuple[int, int]:
    if part in ("train", "val", "test"):
        return (("train", "val", "test").index(part), 0)
    digits = part[4:] if part.startswith("fold") else ""
    return (3, int(digits) if digits.isdigit() and len(digits) < 18 else 0)


def _rule_leaks(split: SplitFile, rule: str, order: list[str], table: pa.Table,
                pos: Mapping[str, np.ndarray]) -> tuple[list[str], list[str]]:
    """([problem], leaks) of one disjoint rule: values of its key shared by parts it keeps
    apart (location: whether the contact x lies in the held-out band, as `location_key`)."""
    from .splits import BAND, OUTSIDE, UNKNOWN

    key, _, held = rule.partition(":")
    if held and held not in split.parts:
        return [f"rule {rule!r} names a part the split does not have"], []
    if key == "location":
        loc = split.params.get("location")
        bands = loc.get("bands_px") if isinstance(loc, dict) else None
        if not (isinstance(bands, list) and all(
                isinstance(b, list) and len(b) == 2 and all(
                    isinstance(v, int | float) and not isinstance(v, bool) for v in b)
                for b in bands)):
            return [f"rule {rule!r} needs params.location.bands_px: [[lo, hi], ...]"], []
        x = _values(table, "contact_x_px")
        inband = np.zeros(len(x), bool)
        for lo, hi in bands:
            inband |= (x >= lo) & (x < hi)
        col = np.where(~np.isfinite(x), UNKNOWN, np.where(inband, BAND, OUTSIDE)).astype(object)
    elif key in ("object", "session"):
        col = np.asarray(table.column(key).to_pylist(), dtype=object)
    else:
        return [f"unknown disjoint key {key!r}"], []
    values = {p: set(col[pos[p]].tolist()) for p in order}
    leaks = []
    for i, a in enumerate(order):
        for b in order[i + 1:]:
            if held and held not in (a, b):
                continue
            both = sorted(values[a] & values[b], key=str)
            if len(both) <= SHOWN:
                leaks += [f"{key} {_short(v)!r} in both {a} and {b}" for v in both]
            else:
                leaks.append(f"{len(both)} {key} values in both {a} and {b}: {_first(both)}")
    return [], leaks


def _shard_shapes(doc: Mapping[str, Any]) -> tuple[tuple[int, ...], tuple[int, ...]] | None:
    """(inner chunk, shard) shapes of a sharded array's zarr.json, or None if not sharded."""
    try:
        shard = tuple(doc["chunk_grid"]["configuration"]["chunk_shape"])
        codec = doc["codecs"][0]
        if codec["name"] != "sharding_indexed":
            return None
        return tuple(codec["configuration"]["chunk_shape"]), shard
    except (KeyError, IndexError, TypeError):
        return None


def zarr_problems(info: DatasetInfo, kind: str, group: Any,
                  arrays: Mapping[str, Any]) -> list[str]:
    """Problems of one kind's Zarr metadata: `group` is data/<kind>.zarr/zarr.json and
    `arrays` each array's own zarr.json (parsed; None when missing). Every array info.json has
    must be in the consolidated metadata, equal to its own zarr.json, with info.json's shape,
    the format's dtype, one sample per chunk and samples_per_shard per shard; the depth scale
    must be info.json's, and the depth attributes those of the format_version info.json gives
    (1.1 writes the CF scale_factor, 1.0 wrote scale: a 1.0 info.json over arrays written by
    1.1 has been downgraded, which drops its info_sha256)."""
    out = []
    try:
        meta = group["consolidated_metadata"]["metadata"]
        assert isinstance(meta, dict)
    except (KeyError, TypeError, AssertionError):
        return ["zarr.json: no consolidated metadata"]
    sps = info.zarr.samples_per_shard.get(kind, 1)
    for name in info.arrays:
        doc = meta.get(name)
        where = f"{name}"
        if not isinstance(doc, dict):
            out.append(f"{where}: not in the consolidated metadata of zarr.json")
            continue
        own = arrays.get(name)
        if own is None:
            out.append(f"{where}/zarr.json: missing")
        elif own != doc:
            diff = sorted(k for k in set(own) | set(doc) if own.get(k) != doc.get(k))
            out.append(f"{where}/zarr.json contradicts the consolidated metadata in zarr.json "
                       f"({', '.join(map(str, diff[:SHOWN]))})")
        want = tuple(info.shapes.get(kind, {}).get(name, ()))
        shape = doc.get("shape")
        bad = []
        if not isinstance(shape, list) or tuple(shape) != want:
            bad.append(f"shape {_short(str(shape), 80)}, info.json says {list(want)}")
        if doc.get("data_type") != DTYPES[name]:
            bad.append(f"dtype {_short(str(doc.get('data_type')), 40)}, expected {DTYPES[name]}")
        chunks = _shard_shapes(doc)
        if chunks != ((1, *want[1:]), (sps, *want[1:])):
            bad.append(f"chunks / shards {_short(str(chunks), 80)}, expected one sample per "
                       f"chunk and {sps} per shard")
        attrs = doc.get("attributes") if isinstance(doc.get("attributes"), dict) else {}
        if name == "depth":
            bad += _depth_attr_problems(info, attrs)
        out += [f"{where}: {b}" for b in bad]
    return out


def _depth_attr_problems(info: DatasetInfo, attrs: Mapping[str, Any]) -> list[str]:
    new = _minor(info.format_version) >= 1
    key = "scale_factor" if new else "scale"
    stray = "scale" if new else "scale_factor"
    if stray in attrs and key not in attrs:
        return [f"attribute {stray!r} is written by format "
                f"{'1.0' if new else '1.1 and later'}, info.json says format_version "
                f"{info.format_version} (an info.json replaced or downgraded after the build)"]
    scale = attrs.get(key)
    if scale != info.depth_scale_mm:
        return [f"depth scale {_short(str(scale), 40)} mm ({key}) contradicts info.json "
                f"depth_scale_mm {info.depth_scale_mm}"]
    return []


__all__ = ["counts_problems", "ids_problems", "index_problems", "info_problems", "kind_counts",
           "split_limits", "split_problems", "zarr_problems"]
