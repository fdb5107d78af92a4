"""THE leak check of a split (`check_split`): ids of no sample or of the other kind, samples in
two parts, and values of a disjoint rule's key (object, session, location) shared by parts the
rule keeps apart. The build runs it on every split it makes or is given, before any frame is
converted (`leak_check`: one line per offending sample), the loader and `vtsbench verify` on
every split file against the dataset's index (`split_problems`: one line per kind of problem).
Where the samples are views of the episode store (format 1.3), a frame row held by samples of
two parts is a leak too (overlapping windows of one take in train and test): the caller passes
each sample's frame rows (`frames`), so no later stage is imported here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..format.index import column_values, frame_rows, view_columns
from ..format.info import DatasetInfo
from ..format.layout import KINDS, index_path
from ..format.problems import SHOWN, first, short
from ..format.records import SampleMeta, SplitFile, part_key

if TYPE_CHECKING:
    import pyarrow as pa

#: Where a static sample's contact x lies against the held-out bands of a location rule.
BAND, OUTSIDE, UNKNOWN = "held-out band", "outside the band", "unknown"


def location_keys(x: np.ndarray, bands_px: Sequence[Sequence[float]]) -> np.ndarray:
    """For each contact x (px; NaN when unknown): BAND when it lies in a band [lo, hi) of
    bands_px, OUTSIDE when not, UNKNOWN when not finite (an object array of those strings)."""
    x = np.asarray(x, np.float64)
    inband = np.zeros(len(x), bool)
    for lo, hi in bands_px:
        inband |= (x >= lo) & (x < hi)
    return np.where(~np.isfinite(x), UNKNOWN, np.where(inband, BAND, OUTSIDE)).astype(object)


@dataclass
class SplitCheck:
    """What `check_split` found: per part the ids in no index and those of the other kind's
    index (pyarrow string arrays), the rules it cannot check, and the leaks."""

    unknown: dict[str, pa.Array] = field(default_factory=dict)
    other_kind: dict[str, pa.Array] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    leaks: list[str] = field(default_factory=list)


def check_split(split: SplitFile, tables: Mapping[str, pa.Table],
                frames: np.ndarray | None = None) -> SplitCheck:
    """Check a split against the index of each kind (kind -> table with sample_id and, for the
    split's kind, the columns its rules key on: object, session, contact_x_px). Leaks are ids
    repeated in a part or found in two parts, and values of a rule's key shared by two parts
    it keeps apart (location: whether the contact x lies in params.location.bands_px).
    frames: the episode-store rows of each sample of the split's kind, (n, T) in table order,
    where the samples are views of the episode store (format 1.3): a row held by samples of
    two parts is a leak (`frame_leaks`)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    found = SplitCheck()
    table = tables.get(split.kind)
    if table is None:
        return found
    index = table.column("sample_id").combine_chunks()
    other = [t.column("sample_id").combine_chunks() for k, t in tables.items()
             if k != split.kind]
    order = sorted(split.parts, key=part_key)
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
        if pc.any(elsewhere).as_py():
            found.other_kind[part] = missing.filter(elsewhere)
        if not pc.all(elsewhere).as_py():
            found.unknown[part] = missing.filter(pc.invert(elsewhere))
    ids_col = table.column("sample_id")

    def samples(where: np.ndarray, what: str) -> list[str]:
        if len(where) == 1:
            return [f"sample {ids_col[int(where[0])].as_py()!r} {what}"]
        shown = ids_col.take(pa.array(where[:SHOWN + 1])).to_pylist()
        return [f"{len(where)} samples {what}: {first(shown)}"] if len(where) else []

    for part in order:
        values, counts = np.unique(pos[part], return_counts=True)
        found.leaks += samples(values[counts > 1], f"twice in {part}")
    for i, a in enumerate(order):
        for b in order[i + 1:]:
            found.leaks += samples(np.intersect1d(pos[a], pos[b]), f"in both {a} and {b}")
    for rule in split.disjoint:
        bad, leaks = _rule_leaks(split, rule, order, table, pos)
        found.problems += bad
        found.leaks += leaks
    if frames is not None:
        found.leaks += frame_leaks(order, pos, np.asarray(frames, np.int64),
                                   ids_col.to_pylist())
    return found


def frame_leaks(order: Sequence[str], pos: Mapping[str, np.ndarray], frames: np.ndarray,
                ids: Sequence[str]) -> list[str]:
    """Per pair of parts, one line when samples of both hold a frame row of the episode store:
    how many rows, and the first one with a sample of each part holding it. frames: (n, T)
    rows of every sample (by table position); pos: each part's table positions."""
    frames = frames.reshape(len(frames), -1)
    per = {p: np.unique(frames[pos[p]]) for p in order}
    out = []
    for i, a in enumerate(order):
        for b in order[i + 1:]:
            both = np.intersect1d(per[a], per[b], assume_unique=True)
            if not len(both):
                continue
            r = int(both[0])

            def holder(part: str, r: int = r) -> str:
                at = pos[part][(frames[pos[part]] == r).any(axis=1)]
                return short(ids[int(at[0])])

            more = f" and {len(both) - 1} more" if len(both) > 1 else ""
            out.append(f"samples {holder(a)!r} ({a}) and {holder(b)!r} ({b}) share frame row "
                       f"{r}{more} of the episode store (overlapping views of one take in "
                       f"{a} and {b})")
    return out


def sample_frames(table: pa.Table, kind: str, info: DatasetInfo) -> np.ndarray | None:
    """The episode-store rows of each sample of an index table, (n, T), where info.json says the
    samples are views of it (format 1.3); None otherwise (or without the view columns)."""
    if not info.views or "frame_row" not in view_columns(table):
        return None
    return frame_rows(table, kind, info.frames_per_sequence)


def _rule_leaks(split: SplitFile, rule: str, order: list[str], table: pa.Table,
                pos: Mapping[str, np.ndarray]) -> tuple[list[str], list[str]]:
    """([problem], leaks) of one disjoint rule: values of its key shared by parts it keeps
    apart."""
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
            return [f"rule {rule!r} needs params.location.bands_px"], []
        col = location_keys(column_values(table, "contact_x_px"), bands)
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
                leaks += [f"{key} {short(v)!r} in both {a} and {b}" for v in both]
            else:
                leaks.append(f"{len(both)} {key} values in both {a} and {b}: {first(both)}")
    return [], leaks


def leak_check(split: SplitFile, samples: Iterable[SampleMeta],
               frames: np.ndarray | None = None) -> list[str]:
    """The build's check of a split against the samples it makes (`check_split`): every id
    unknown or of the other kind, one line each, then every leak, named by the split; an
    empty list when the split is clean. frames (samples as views of the episode store): the
    store rows of each sample of the split's kind, (n, T), in the order `samples` gives them."""
    by_kind: dict[str, list[SampleMeta]] = {k: [] for k in KINDS}
    for s in samples:
        by_kind[s.kind].append(s)
    found = check_split(split, {k: _table(ss) for k, ss in by_kind.items()}, frames)
    other = next(k for k in KINDS if k != split.kind)
    out = []
    for part in sorted(split.parts, key=part_key):
        for sid in found.unknown[part].to_pylist() if part in found.unknown else ():
            out.append(f"sample {sid!r} in {part} is not in the dataset")
        for sid in found.other_kind[part].to_pylist() if part in found.other_kind else ():
            out.append(f"sample {sid!r} in {part} is a {other} sample in a {split.kind} split")
    return [f"{split.name}: {x}" for x in [*out, *found.leaks, *found.problems]]


def _table(samples: list[SampleMeta]) -> pa.Table:
    """The columns check_split reads, of samples of one kind."""
    import pyarrow as pa

    return pa.table({"sample_id": pa.array([s.sample_id for s in samples], pa.string()),
                     "object": pa.array([s.object for s in samples], pa.string()),
                     "session": pa.array([s.session for s in samples], pa.string()),
                     "contact_x_px": pa.array([s.contact_x_px for s in samples], pa.float64())})


def split_problems(split: SplitFile, name: str, info: DatasetInfo,
                   tables: Mapping[str, pa.Table]) -> tuple[list[str], list[str]]:
    """The loader's and verify's check of a split file listed as `name` in info.json:
    (problems, leaks). Problems: its name, part sizes against info.json counts, ids not in its
    kind's index (`check_split`), rules that cannot be checked; leaks as `check_split` finds
    them."""
    out: list[str] = []
    if split.name != name:
        out.append(f"the file names its split {short(split.name)!r}, info.json {name!r}")
    sizes = {p: len(v) for p, v in split.parts.items()}
    want = info.counts.splits.get(name)
    if want is not None and sizes != want:
        diff = sorted(set(sizes) | set(want), key=str)
        p = next(k for k in diff if sizes.get(k) != want.get(k))
        out.append(f"part {short(p)} has {sizes.get(p, 'no')} samples, info.json counts.splits "
                   f"says {want.get(p, 'none')}")
    if tables.get(split.kind) is None:
        return out, []
    found = check_split(split, tables, sample_frames(tables[split.kind], split.kind, info))
    for part in sorted(split.parts, key=part_key):
        wrong: Any = found.other_kind.get(part)
        unknown: Any = found.unknown.get(part)
        if wrong is not None:
            out.append(f"part {part}: {len(wrong)} id(s) of samples of the other kind in a "
                       f"{split.kind} split: {first(wrong.slice(0, SHOWN + 1).to_pylist())}")
        if unknown is not None:
            out.append(f"part {part}: {len(unknown)} sample id(s) not in "
                       f"{index_path(split.kind)}: "
                       f"{first(unknown.slice(0, SHOWN + 1).to_pylist())}")
    return out + found.problems, found.leaks
