"""`vtsbench verify`: check a built dataset against its own info.json, down to every chunk.

Checks, each problem one line: info.json against its schema; every file's sha256 (missing and
unlisted files too) and the dataset checksum; split files (schema, sha256, leaks); the index
(schema, rows 0..N-1, class_idx, counts); the Zarr arrays (shape, dtype, chunking against
info and the index); and decodes every chunk. Chunks carry a crc32c, so a damaged byte names
its array, sample and shard; a damaged shard index names the samples of the whole shard.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VtsError
from .schema import INFO_PATH, KINDS, Counts, DatasetInfo, SampleMeta, dataset_checksum, load_info
from .store import DTYPES, Layout

#: An inner chunk missing from a shard has offset and length 2**64 - 1 in the shard index.
MISSING = 2**64 - 1


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


def check_files(root: Path, info: DatasetInfo, report: VerifyReport,
                advance: Callable[[int], None] | None = None) -> None:
    """sha256 of every listed file; missing and unlisted files; the dataset checksum."""
    from .provenance import sha256_file

    on_disk = {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()}
    for rel in sorted(info.files):
        path = root / rel
        if rel not in on_disk:
            report.problems.append(f"{rel}: missing")
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


def check_index(root: Path, info: DatasetInfo, report: VerifyReport
                ) -> dict[str, list[SampleMeta]]:
    """Both indexes: schema, rows in order, class_idx, unique ids, counts against info."""
    from .index import read_index

    out: dict[str, list[SampleMeta]] = {}
    for kind in KINDS:
        rel = f"index/{kind}.parquet"
        try:
            metas = read_index(root / rel, kind)
        except VtsError as e:
            report.problems.append(f"{rel}: {_strip(e, root / rel)}")
            continue
        out[kind] = metas
        n = info.shapes.get(kind, {}).get("rgb", (0,))[0]
        if len(metas) != n:
            report.problems.append(f"{rel}: {len(metas)} rows, info.json says {n} samples")
        for i, m in enumerate(metas):
            if m.row != i:
                report.problems.append(f"{rel}: sample {m.sample_id} at position {i} has row "
                                       f"{m.row} (rows must be 0..N-1 in order)")
                break
        for m in metas:
            if m.object not in info.objects or info.objects.index(m.object) != m.class_idx:
                report.problems.append(f"{rel}: sample {m.sample_id}: class_idx {m.class_idx} "
                                       f"does not match object {m.object!r}")
                break
    ids = [m.sample_id for ms in out.values() for m in ms]
    if len(ids) != len(set(ids)):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        report.problems.append(f"index: sample id {dup[0]!r} appears more than once")
    report.samples = len(ids)
    return out


def check_splits(root: Path, info: DatasetInfo, index: dict[str, list[SampleMeta]],
                 report: VerifyReport) -> list[Any]:
    """Every split file: schema, sha256 against info.json, and the leak check (for the kinds
    whose index could be read)."""
    import hashlib

    from .splits import leak_check, read_split

    splits = []
    folder = root / "meta" / "splits"
    samples = [m for ms in index.values() for m in ms]
    for name, sha in sorted(info.splits.items()):
        rel, path = f"meta/splits/{name}.json", folder / f"{name}.json"
        try:
            sp = read_split(path)
        except VtsError as e:
            report.problems.append(f"{rel}: {_strip(e, path)}")
            continue
        splits.append(sp)
        got = hashlib.sha256(path.read_bytes()).hexdigest()
        if got != sha and not any(x.startswith(f"{rel}: sha256") for x in report.problems):
            report.problems.append(f"{rel}: sha256 mismatch with info.json splits (the split "
                                   "file was changed after the build)")
        if sp.kind in index:
            report.problems += [f"{rel}: leak: {x}" for x in leak_check(sp, samples)]
    listed = set(info.splits)
    if folder.is_dir():
        report.problems += [f"meta/splits/{p.name}: split file not named in info.json splits"
                            for p in sorted(folder.glob("*.json")) if p.stem not in listed]
    return splits


def _strip(e: VtsError, path: Path) -> str:
    text = str(e)
    return text[len(f"{path}: "):] if text.startswith(f"{path}: ") else text


def check_arrays(root: Path, info: DatasetInfo, index: dict[str, list[SampleMeta]],
                 report: VerifyReport, decode: bool = True,
                 advance: Callable[[int], None] | None = None) -> None:
    """Shapes, dtypes and chunking against info and the index; then decode every chunk."""
    from .store import open_group

    for kind in KINDS:
        where = f"data/{kind}.zarr"
        try:
            group = open_group(root, kind)
        except VtsError as e:
            report.problems.append(f"{where}: {_strip(e, root / where)}")
            continue
        ids = [m.sample_id for m in index.get(kind, [])]
        sps = info.zarr.samples_per_shard.get(kind, 1)
        for name in info.arrays:
            try:
                arr = group[name]
            except KeyError:
                report.problems.append(f"{where}/{name}: array missing")
                continue
            except Exception as e:  # metadata zarr cannot use (a changed zarr.json)
                report.problems.append(f"{where}/{name}: cannot open the array "
                                       f"({type(e).__name__}: {_reason(e)})")
                continue
            want = tuple(info.shapes.get(kind, {}).get(name, ()))
            bad = []
            if tuple(arr.shape) != want:
                bad.append(f"shape {tuple(arr.shape)}, info.json says {want}")
            if str(arr.dtype) != DTYPES[name]:
                bad.append(f"dtype {arr.dtype}, expected {DTYPES[name]}")
            if arr.chunks != (1, *arr.shape[1:]) or arr.shards != (sps, *arr.shape[1:]):
                bad.append(f"chunks {arr.chunks} / shards {arr.shards}, expected one sample "
                           f"per chunk and {sps} per shard")
            if kind in index and arr.shape[0] != len(ids):
                bad.append(f"{arr.shape[0]} rows, the index has {len(ids)}")
            report.problems += [f"{where}/{name}: {b}" for b in bad]
            if bad or not decode:
                continue
            frames = arr.shape[1] if kind == "slip" and len(arr.shape) > 2 else None
            lay = Layout(kind, arr.shape[0], tuple(want[-2:] if name != "rgb" else want[-3:-1]),
                         frames, sps, info.zarr.level, info.arrays)
            for k in range(lay.n_shards):
                report.problems += _decode_shard(root / where, lay, name, k, arr, ids)
                report.shards += 1
                if advance is not None:
                    advance(1)


def _decode_shard(group_dir: Path, lay: Layout, name: str, k: int, arr: Any,
                  ids: list[str]) -> list[str]:
    """Problems of one shard: missing file, damaged index, missing or undecodable chunks."""
    key = lay.shard_key(name, k)
    rel, where = key.removeprefix(f"{name}/"), f"data/{lay.kind}.zarr/{name}"
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
    from .remote import local_copy

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
                           for k, s in info.shapes.items()) * len(info.arrays) if decode else 0
            t = bar.add_task("checking", total=len(info.files) + n_shards)
            advance = lambda n: bar.advance(t, n)  # noqa: E731
        check_files(root, info, report, advance)
        index = check_index(root, info, report)
        samples = [m for ms in index.values() for m in ms]
        splits = check_splits(root, info, index, report)
        if len(index) == len(KINDS):
            counts = Counts.of(samples, splits).to_dict()
            if splits and len(splits) == len(info.splits) and counts != info.counts.to_dict():
                report.problems.append(f"{INFO_PATH}: counts do not match the index and splits")
        check_arrays(root, info, index, report, decode, advance)
    return report


def _bar(enabled: bool) -> Any:
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(None)
    from rich.progress import BarColumn, MofNCompleteColumn

    from ..progress import progress_bar

    return progress_bar("[progress.description]{task.description}", BarColumn(),
                        MofNCompleteColumn())
