"""`vtsbench verify`: check a built dataset against its own info.json, down to every chunk.

verify = the checks `vtsbench.load` makes (info.json: format/info.py; the index and counts:
format/index.py; split files and leaks: splits/leaks.py; the Zarr metadata: format/arrays.py),
listed all rather than raised first, plus
the expensive ones: every file's sha256 (missing and unlisted files too), the dataset checksum,
and every chunk decoded. Chunks carry a crc32c, so a damaged byte names its array, sample and
shard; a damaged shard index names the samples of the whole shard. Each problem is one line.
Where the samples are views of the episode store (format 1.3), their index columns are checked
against the episodes (every sample's frames inside its episode), split parts sharing a frame
are leaks, and a data/static.zarr or data/slip.zarr is a problem (there is none to check).
Where the episodes' RGB is stored as video, the `rgb` array of data/episodes.zarr holds its
metadata alone (checked as every array's) and no chunk to decode; the videos are probed
(verify_video.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ..format.arrays import MISSING, Layout
from ..format.episode_video import stored_codec
from ..format.info import DatasetInfo, dataset_checksum, load_info
from ..format.layout import (
    EPISODES,
    EPISODES_INDEX,
    INFO_PATH,
    KINDS,
    SPLITS_DIR,
    group_path,
    index_path,
    split_path,
)
from ..format.problems import SHOWN
from ..format.records import SPLIT_NAME
from .verify_video import check_videos

if TYPE_CHECKING:
    import pyarrow as pa


@dataclass
class VerifyReport:
    """Problems found (empty when the dataset is intact) and what was checked."""

    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    files: int = 0
    samples: int = 0
    shards: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems


def shard_index(data: bytes, n_chunks: int) -> tuple[np.ndarray, bool]:
    """(offset, nbytes) of each inner chunk of a shard file, and whether the index's crc32c
    holds (index at the end: n_chunks x 2 uint64 little-endian, then a crc32c)."""
    import google_crc32c

    size = n_chunks * 16
    if len(data) < size + 4:
        return np.zeros((0, 2), np.uint64), False
    raw = data[-size - 4:-4]
    ok = google_crc32c.value(raw) == int.from_bytes(data[-4:], "little")
    return np.frombuffer(raw, "<u8").reshape(n_chunks, 2), ok


def chunk_of_byte(data: bytes, n_chunks: int, offset: int) -> int | None:
    """The inner chunk (sample position in the shard) holding byte `offset` of a shard file."""
    idx, _ = shard_index(data, n_chunks)
    for j, (off, nbytes) in enumerate(idx.tolist()):
        if off != MISSING and off <= offset < off + nbytes:
            return j
    return None


def _reason(e: BaseException) -> str:
    text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    if "checksum" in text.lower():
        return "crc32c mismatch"
    return text if len(text) <= 120 else text[:117] + "..."


def _rows(ids: list[str], rows: range) -> str:
    """`sample ID (row r)` or the samples of a whole shard; '?' where the index is unreadable."""
    def sid(r: int) -> str:
        return ids[r] if r < len(ids) else "?"

    if len(rows) == 1:
        return f"sample {sid(rows[0])} (row {rows[0]})"
    return (f"samples {sid(rows[0])}..{sid(rows[-1])} (rows {rows[0]}-{rows[-1]}, "
            "the whole shard)")


def _not_a_file(path: Path) -> str:
    """Why a listed file is not among the dataset's regular files: missing, a folder, or a
    pipe, device or socket (a link to /dev/zero must not read as "missing")."""
    from ...jsonio import regular_file

    if not (path.exists() or path.is_symlink()):
        return "missing"
    try:
        regular_file(path, "dataset file")
    except VtsError as e:
        return e.reason
    return "missing"


def check_files(root: Path, info: DatasetInfo, report: VerifyReport,
                advance: Callable[[int], None] | None = None) -> None:
    """sha256 of every listed file; missing and unlisted files; the dataset checksum."""
    from ..format.provenance import sha256_file

    on_disk = {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()}
    for rel in sorted(info.files):
        path = root / rel
        if rel not in on_disk:  # missing, or there but no regular file: say which
            report.problems.append(f"{rel}: {_not_a_file(path)}")
        else:
            got = sha256_file(path)
            if got != info.files[rel]:
                report.problems.append(f"{rel}: sha256 mismatch (info.json has "
                                       f"{info.files[rel][:16]}..., the file {got[:16]}...)")
        report.files += 1
        if advance is not None:
            advance(1)
    for rel in sorted(on_disk - set(info.files) - {INFO_PATH}):
        report.problems.append(f"{rel}: not listed in {INFO_PATH}")
    if dataset_checksum(info.files) != info.dataset_sha256:
        report.problems.append(f"{INFO_PATH}: dataset_sha256 does not match the files it lists")


def check_index(root: Path, info: DatasetInfo, report: VerifyReport) -> dict[str, Any]:
    """Both indexes as the loader reads and checks them (`read_index`; `index_problems`:
    schema, rows 0..N-1 in order, objects and class_idx, values), ids unique across kinds,
    counts against info.json; returns the tables that could be read, by kind."""
    return _check_index(root, info, report)[0]


def _check_index(root: Path, info: DatasetInfo, report: VerifyReport
                 ) -> tuple[dict[str, Any], pa.Table | None]:
    """`check_index`, and index/episodes.parquet as it read it (None: no episodes, or a file
    that could not be read, reported here) for the checks after it."""
    from ..format.index import counts_problems, ids_problems, index_problems, read_index

    out: dict[str, Any] = {}
    for kind in KINDS:
        rel = index_path(kind)
        try:
            table = read_index(root / rel, kind)
        except VtsError as e:
            report.problems.append(f"{rel}: {_strip(e, root / rel)}")
            continue
        bad = index_problems(table, kind, info)
        report.problems += [f"{rel}: {b}" for b in bad]
        if not bad:
            out[kind] = table
    report.problems += [f"index: {b}" for b in ids_problems(out)]
    report.problems += [f"{INFO_PATH}: {b}" for b in counts_problems(info, out)]
    report.samples = sum(len(t) for t in out.values())
    episodes: pa.Table | None = None
    if info.episodes is not None:  # format 1.2: the episode and frame indexes
        from ..format.episodes import episodes_problems, read_table
        from ..read.episodes import store_table

        try:
            episodes = read_table(root, "episodes")
            frames = read_table(root, "frames")
        except VtsError as e:
            report.problems.append(str(e).replace(f"{root}/", "", 1))
            return out, episodes
        bad = episodes_problems(episodes, frames, info)
        report.problems += [f"{EPISODES_INDEX}: {b}" for b in bad]
        if not bad:
            out[EPISODES] = store_table(episodes, frames)  # frame ids: `<episode id>/<frame>`
            if info.views:
                report.problems += _view_problems(info, out, episodes)
    return out, episodes


def _view_problems(info: DatasetInfo, index: dict[str, Any], episodes: Any) -> list[str]:
    """Format 1.3: every sample's frames inside its episode (`view_problems`, as the loader)."""
    from ..format.index import view_problems

    starts = episodes.column("frame_start").to_numpy()
    lengths = episodes.column("length").to_numpy()
    return [f"{index_path(kind)}: {b}" for kind in KINDS if kind in index
            for b in view_problems(index[kind], kind, info.frames_per_sequence, starts,
                                   lengths)]


def check_splits(root: Path, info: DatasetInfo, index: dict[str, Any],
                 report: VerifyReport, episodes: pa.Table | None = None) -> list[Any]:
    """Every split file as the loader checks it (`split_problems`: name, size and id count,
    schema, ids known, part sizes, leaks), and its sha256 against info.json. `episodes`:
    index/episodes.parquet already read (None: read here if a split of episodes needs it)."""
    import hashlib

    from ..format.episodes import read_table
    from ..splits.episodes import EPISODE, episode_leaks, split_table
    from ..splits.files import dataset_split_limits, read_split
    from ..splits.leaks import split_problems

    splits = []
    leak_table: Any = None
    folder = root / SPLITS_DIR
    max_bytes, max_ids = dataset_split_limits(info)
    for name, sha in sorted(info.splits.items()):
        rel = split_path(name)
        path = root / rel
        if not SPLIT_NAME.fullmatch(name):
            continue  # refused with info.json
        try:
            sp = read_split(path, max_bytes=max_bytes, max_ids=max_ids)
        except VtsError as e:
            report.problems.append(f"{rel}: {_strip(e, path)}")
            continue
        splits.append(sp)
        got = hashlib.sha256(path.read_bytes()).hexdigest()
        if got != sha and not any(x.startswith(f"{rel}: sha256") for x in report.problems):
            report.problems.append(f"{rel}: sha256 mismatch with info.json splits (the split "
                                   "file was changed after the build)")
        if sp.kind in index:
            bad, leaks = split_problems(sp, name, info, index)
            report.problems += [f"{rel}: {b}" for b in bad]
            report.problems += [f"{rel}: leak: {name}: {x}" for x in leaks]
        elif sp.kind == EPISODE and info.episodes is not None:  # splits over episodes
            if leak_table is None:  # made once for every split of episodes
                try:
                    leak_table = split_table(read_table(root, "episodes") if episodes is None
                                             else episodes)
                except VtsError:
                    continue  # reported with the indexes
            report.problems += [f"{rel}: leak: {name}: {x}"
                                for x in episode_leaks(sp, leak_table)]
    listed = set(info.splits)
    if folder.is_dir():
        extra = [p.name for p in sorted(folder.glob("*.json")) if p.stem not in listed]
        report.problems += [f"{SPLITS_DIR}/{n}: split file not named in info.json splits"
                            for n in extra[:SHOWN]]
        if len(extra) > SHOWN:
            report.problems.append(f"{SPLITS_DIR}: {len(extra) - SHOWN} more split files not "
                                   "named in info.json splits")
    return splits


def _strip(e: VtsError, path: Path) -> str:
    text = str(e)
    return text[len(f"{path}: "):] if text.startswith(f"{path}: ") else text


def check_arrays(root: Path, info: DatasetInfo, index: dict[str, Any],
                 report: VerifyReport, decode: bool = True,
                 advance: Callable[[int], None] | None = None) -> None:
    """The Zarr metadata as the loader checks it (`zarr_problems`: shapes, dtypes, chunking and
    depth scale against info.json, each array's zarr.json against the consolidated metadata,
    the format that wrote them); then decode every chunk."""
    from ...jsonio import read_json
    from ..format.arrays import zarr_problems
    from ..read.episodes import open_frames_group
    from ..read.store import open_group

    if info.views:  # format 1.3: the samples' frames are the episode store's, nothing else
        report.problems += [f"{group_path(k)}: present, and info.json says the {k} samples are "
                            "views of the episode store (sample_storage "
                            f"{info.sample_storage!r})" for k in KINDS
                            if (root / group_path(k)).exists()]
    for kind in (k for k in (*KINDS, EPISODES) if k in info.shapes and not _viewed(info, k)):
        where = group_path(kind)
        try:
            group = open_group(root, kind) if kind in KINDS else open_frames_group(root)
            group_doc = read_json(root / where / "zarr.json", "Zarr metadata")
        except VtsError as e:
            report.problems.append(f"{where}: {_strip(e, root / where)}")
            continue
        docs: dict[str, Any] = {}
        for name in info.arrays:
            path = root / where / name / "zarr.json"
            try:
                docs[name] = read_json(path, "Zarr metadata")
            except VtsError as e:
                docs[name] = None
                if path.exists():
                    report.problems.append(f"{where}/{name}/zarr.json: {_strip(e, path)}")
        bad = zarr_problems(info, kind, group_doc, docs)
        report.problems += [f"{where}/{b}" for b in bad]
        if not decode or any(b.startswith("zarr.json") for b in bad):
            continue
        table = index.get(kind)
        ids = [] if table is None else table.column("sample_id").to_pylist()
        sps = info.zarr.samples_per_shard.get(kind, 1)
        for name in chunked_arrays(info, kind):
            if any(b.startswith(f"{name}:") or b.startswith(f"{name}/") for b in bad):
                continue
            try:
                arr = group[name]
            except Exception as e:  # metadata zarr cannot use (a changed zarr.json)
                report.problems.append(f"{where}/{name}: cannot open the array "
                                       f"({type(e).__name__}: {_reason(e)})")
                continue
            want = tuple(info.shapes[kind][name])
            frames = arr.shape[1] if kind == "slip" and len(arr.shape) > 2 else None
            lay = Layout(kind, arr.shape[0], tuple(want[-2:] if name != "rgb" else want[-3:-1]),
                         frames, sps, info.zarr.level, info.arrays)
            for k in range(lay.n_shards):
                report.problems += _decode_shard(root / where, lay, name, k, arr, ids)
                report.shards += 1
                if advance is not None:
                    advance(1)


def chunked_arrays(info: DatasetInfo, kind: str) -> tuple[str, ...]:
    """The arrays of a kind whose chunks hold its frames: every array, but the episodes' `rgb`
    where their RGB is stored as video (its array is metadata alone, by design)."""
    if kind == EPISODES and stored_codec(info) is not None:
        return tuple(a for a in info.arrays if a != "rgb")
    return info.arrays


def _viewed(info: DatasetInfo, kind: str) -> bool:
    """Whether a kind's samples are views of the episode store (no group of their own)."""
    return info.views and kind in KINDS


def _decode_shard(group_dir: Path, lay: Layout, name: str, k: int, arr: Any,
                  ids: list[str]) -> list[str]:
    """Problems of one shard: missing file, damaged index, missing or undecodable chunks."""
    key = lay.shard_key(name, k)
    rel, where = key.removeprefix(f"{name}/"), f"{group_path(lay.kind)}/{name}"
    rows = lay.shard_rows(k)
    path = group_dir / key
    if not path.is_file():
        return [f"{where}: {_rows(ids, rows)}: shard {rel} is missing"]
    idx, ok = shard_index(path.read_bytes(), lay.samples_per_shard)
    if not ok:
        return [f"{where}: {_rows(ids, rows)}: shard {rel} fails to decode (its index fails "
                "its crc32c)"]
    out = []
    for j, r in enumerate(rows):
        if int(idx[j, 0]) == MISSING:
            out.append(f"{where}: {_rows(ids, range(r, r + 1))}: chunk missing from shard {rel}")
    if out:
        return out
    try:
        arr[rows.start:rows.stop]
        return []
    except Exception:  # find the sample(s): each chunk carries its own crc32c
        pass
    for r in rows:
        try:
            arr[r]
        except Exception as e:
            out.append(f"{where}: {_rows(ids, range(r, r + 1))}: shard {rel} fails to decode "
                       f"({_reason(e)})")
    return out or [f"{where}: {_rows(ids, rows)}: shard {rel} fails to decode as a whole"]


def verify(root: str | Path, *, decode: bool = True, progress: bool = False) -> VerifyReport:
    """Verify a built dataset (a folder, or any URL `vtsbench.load` takes: a remote one is
    fetched into a temporary folder first); report.problems is empty when all checks out."""
    from ..read.remote import local_copy

    with local_copy(root) as path:
        return _verify(path, decode, progress)


def _verify(root: Path, decode: bool, progress: bool) -> VerifyReport:
    """verify of a dataset folder."""
    report = VerifyReport()
    if not root.is_dir():
        raise VtsError("no such dataset folder", root)
    try:
        info = load_info(root)
    except VtsError as e:
        report.problems.append(str(e))
        return report
    if not info.info_sha256:
        report.warnings.append(f"{INFO_PATH}: format {info.format_version} carries no "
                               "info_sha256, so a change to info.json itself goes unnoticed; "
                               "rebuild with this vtsbench to protect it")
    with _bar(progress) as bar:
        advance = None
        if bar is not None:
            sps = info.zarr.samples_per_shard
            n_shards = sum(-(-s.get("rgb", (0,))[0] // max(1, sps.get(k, 1)))
                           * len(chunked_arrays(info, k)) for k, s in info.shapes.items()
                           if not _viewed(info, k)) if decode else 0
            t = bar.add_task("checking", total=len(info.files) + n_shards)
            advance = lambda n: bar.advance(t, n)  # noqa: E731
        check_files(root, info, report, advance)
        index, episodes = _check_index(root, info, report)
        check_splits(root, info, index, report, episodes)
        check_arrays(root, info, index, report, decode, advance)
        check_videos(root, info, report, episodes)  # RGB stored as video (verify_video.py)
    report.problems = _one_kind_line_per_file(report.problems)
    return report


def _one_kind_line_per_file(problems: list[str]) -> list[str]:
    """The file checks and the index checks both see a listed file that is a folder, pipe or
    device: of the lines saying so for one file, keep the last (the more specific)."""
    def kind_of(p: str) -> str | None:
        rel, _, reason = p.partition(": ")
        return rel if reason.startswith(("not a regular file", "is a folder")) else None

    last = {kind_of(p): i for i, p in enumerate(problems) if kind_of(p)}
    return [p for i, p in enumerate(problems) if kind_of(p) is None or last[kind_of(p)] == i]


def _bar(enabled: bool) -> Any:
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(None)
    from rich.progress import BarColumn, MofNCompleteColumn

    from ...progress import progress_bar

    return progress_bar("[progress.description]{task.description}", BarColumn(),
                        MofNCompleteColumn())
