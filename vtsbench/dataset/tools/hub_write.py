"""Writing one kind's hub parquet files (`vtsbench export-hf`): the samples grouped into cells
(the samples that share their part in every split scheme of their kind), each cell's files and
row groups, written through temporary names and marked done, so a rerun keeps what is finished."""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ..format.layout import ARRAYS, HUB_DIR
from .hub_layout import HubFile
from .hub_rows import IMAGE_COLUMNS, arrow_schema, extra_columns, rows_table

if TYPE_CHECKING:
    import pyarrow as pa

    from ..read.loader import VtsDataset
    from ..read.view import View

#: Encoded bytes per row group (the Hub viewer reads one row group at a time) and per file.
ROW_GROUP_BYTES = 16 * 2**20
FILE_BYTES = 256 * 2**20


@dataclass(frozen=True)
class Cell:
    """Samples of one kind that share their part in every scheme (None: not in the scheme)."""

    parts: tuple[str | None, ...]
    positions: np.ndarray


def schemes_of(ds: VtsDataset, kind: str) -> list[str]:
    """The split schemes of a kind, by name."""
    return [s for s in ds.splits if ds.split_file(s).kind == kind]


def cells(ds: VtsDataset, kind: str) -> list[Cell]:
    """The cells of a kind in order of their first sample (index order inside each)."""
    n = len(ds.view(kind))
    schemes = schemes_of(ds, kind)
    keys: list[list[str | None]] = [[None] * len(schemes) for _ in range(n)]
    for j, scheme in enumerate(schemes):
        split = ds.split_file(scheme)
        for part in ds.parts(scheme):
            for p in ds._part_positions(split, part):
                keys[int(p)][j] = part
    groups: dict[tuple[str | None, ...], list[int]] = {}
    for p, key in enumerate(keys):
        groups.setdefault(tuple(key), []).append(p)
    return [Cell(k, np.asarray(v, np.int64)) for k, v in groups.items()]


def _rows_per(view: View, target: int, encoded_ratio: float = 1.0) -> int:
    """Rows per `target` bytes, from the decoded size of a sample (an upper bound of its
    encoded size: PNG and zstd only shrink it)."""
    return max(1, int(target // max(1, view.nbytes() * encoded_ratio)))


def _parquet_options(schema: pa.Schema) -> dict[str, Any]:
    """zstd pages for the labels, with dictionaries and statistics; the image columns stored
    as they are: their TIFFs and PNGs are compressed already, so zstd would gain little and
    leave the parquet smaller than the Arrow cache `load_dataset` makes of it (which holds
    the images' bytes uncompressed)."""
    labels = [f.name for f in schema if f.name not in (*ARRAYS, *IMAGE_COLUMNS)]
    packed = [f.name for f in schema if f.name not in IMAGE_COLUMNS]
    return {"compression": {n: "zstd" if n in packed else "none" for n in schema.names},
            "compression_level": dict.fromkeys(packed, 3), "use_dictionary": labels,
            "write_statistics": labels}


def ordered(jobs: list[Any], make: Callable[[Any], Any], workers: int) -> Iterator[Any]:
    """make(job) for every job, run by `workers` threads at most one job ahead each, yielded in
    job order (so at most 2 x workers batches are in memory)."""
    from collections import deque

    with ThreadPoolExecutor(max(1, workers)) as pool:
        pending: deque[Any] = deque()
        for job in jobs:
            pending.append(pool.submit(make, job))
            if len(pending) > 2 * max(1, workers):
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _fingerprint(ds: VtsDataset, schema: pa.Schema, opts: dict[str, Any], rows: tuple[int, int]
                 ) -> str:
    """sha256 of everything a kind's hub files depend on but their samples: the dataset's
    content, the schema (labels, names, depth unit), the parquet options and rows, this
    version of vtsbench. A finished file is kept by a rerun only when it still matches."""
    import hashlib
    import json

    from ..format.provenance import package_version

    doc = {"dataset_sha256": ds.info.dataset_sha256, "vtsbench": package_version(),
           "schema": hashlib.sha256(schema.serialize().to_pybytes()).hexdigest(),
           "options": repr(sorted(opts.items())), "rows": list(rows)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def done_marker(state: Path | None, rel: str) -> Path | None:
    """The marker a finished hub file gets in the export's state folder."""
    return None if state is None else state / "done" / (rel.replace("/", "~") + ".json")


def kept_marker(root: Path, rel: str, marker: Path | None, fp: str) -> dict[str, Any] | None:
    """The marker of a hub file finished by an earlier run with this fingerprint, when the file
    is still there at its size; None otherwise."""
    import json

    if marker is None:
        return None
    try:
        doc = json.loads(marker.read_text())
        ok = (doc["fingerprint"] == fp and (root / rel).stat().st_size == doc["size"]
              and isinstance(doc["sha256"], str))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return doc if ok else None


def write_failed(e: OSError, path: Path) -> VtsError:
    """One line naming the file being written, for a write that failed (a full disk: pyarrow
    names no file and prints its own detail)."""
    import errno as errnos
    import os

    code = e.errno
    if code is None:  # pyarrow: "... Detail: [errno 28] No space left on device"
        m = re.search(r"\[errno (\d+)\]", str(e), re.IGNORECASE)
        code = int(m.group(1)) if m else None
    reason = os.strerror(code) if code else (str(e).strip().splitlines() or ["write failed"])[0]
    hint = "; the files finished so far are kept for a rerun" \
        if code in (errnos.ENOSPC, errnos.EFBIG, errnos.EDQUOT) else ""
    return VtsError(f"cannot write ({reason}){hint}", path)


def write_kind(ds: VtsDataset, kind: str, root: Path, workers: int = 1,
               advance: Callable[[int], None] | None = None, state: Path | None = None,
               shown: Path | None = None, digests: dict[str, str] | None = None,
               kept: list[str] | None = None) -> list[HubFile]:
    """Write the hub files of one kind under root/hf/<kind>/; returns them in cell order.

    Each file is written through a temporary name and renamed when complete; with a `state`
    folder each finished file then gets a marker there (its fingerprint, size and sha256, which
    go into `digests`), and a rerun keeps the files whose marker still matches (resume, listed
    in `kept`). A
    failed write removes its temporary file and names the file in one line (under `shown`, the
    dataset, rather than root)."""
    import hashlib
    import json

    import pyarrow.parquet as pq

    from ...atomic import TMP_SUFFIX, write_bytes_atomic
    from ..format.provenance import sha256_file

    folder = root / HUB_DIR / kind
    folder.mkdir(parents=True, exist_ok=True)
    view = ds.view(kind)
    schema = arrow_schema(ds.info, kind, extra_columns(view))
    opts = _parquet_options(schema)
    group_rows = _rows_per(view, ROW_GROUP_BYTES, 0.6)
    file_rows = max(group_rows, _rows_per(view, FILE_BYTES, 0.6) // group_rows * group_rows)
    base = _fingerprint(ds, schema, opts, (group_rows, file_rows))
    files: list[tuple[str, int, np.ndarray]] = []  # (path, cell, positions)
    for c, cell in enumerate(cells(ds, kind)):
        for f, start in enumerate(range(0, len(cell.positions), file_rows)):
            files.append((f"{HUB_DIR}/{kind}/{c:03d}-{f:03d}.parquet", c,
                          cell.positions[start:start + file_rows]))
    fps = [hashlib.sha256(f"{base} {rel} ".encode() + pos.astype("<i8").tobytes()).hexdigest()
           for rel, _, pos in files]
    digests = {} if digests is None else digests
    done: dict[int, HubFile] = {}
    for k, (rel, c, pos) in enumerate(files):
        doc = kept_marker(root, rel, done_marker(state, rel), fps[k])
        if doc is not None:
            done[k] = HubFile(rel, c, len(pos), doc["size"])
            digests[rel] = doc["sha256"]
            if kept is not None:
                kept.append(rel)
            if advance is not None:
                advance(len(pos))
    keep = {Path(files[k][0]).name for k in done}
    for p in folder.iterdir():  # files of another plan or unfinished, temporaries of a kill
        if p.is_file() and p.name not in keep:
            p.unlink()
    jobs = [(k, pos[g:g + group_rows]) for k, (_, _, pos) in enumerate(files) if k not in done
            for g in range(0, len(pos), group_rows)]
    writer: Any = None
    current = -1

    def tmp_of(k: int) -> Path:
        path = root / files[k][0]
        return path.with_name(f".{path.name}{TMP_SUFFIX}")

    def close() -> None:
        if writer is not None:
            writer.close()
            rel, c, pos = files[current]
            path = root / rel
            tmp_of(current).replace(path)
            size = path.stat().st_size
            done[current] = HubFile(rel, c, len(pos), size)
            digests[rel] = sha256_file(path)
            marker = done_marker(state, rel)
            if marker is not None:
                marker.parent.mkdir(parents=True, exist_ok=True)
                write_bytes_atomic(marker, json.dumps({"fingerprint": fps[current], "size": size,
                                                       "sha256": digests[rel]}).encode())

    try:
        for k, table in ordered(jobs, lambda job: (job[0], rows_table(
                _view_at(ds, kind, job[1]), schema)), workers):
            try:
                if k != current:
                    close()
                    writer, current = None, k
                    writer = pq.ParquetWriter(tmp_of(k), schema, **opts)
                writer.write_table(table, row_group_size=group_rows)
            except OSError as e:
                raise write_failed(e, (shown or root) / files[current][0]) from None
            if advance is not None:
                advance(table.num_rows)
        try:
            close()
        except OSError as e:
            raise write_failed(e, (shown or root) / files[current][0]) from None
        writer = None
    finally:
        if writer is not None:
            with contextlib.suppress(OSError):
                writer.close()
            tmp_of(current).unlink(missing_ok=True)
    return [done[k] for k in sorted(done)]


def _view_at(ds: VtsDataset, kind: str, positions: np.ndarray) -> View:
    from ..read.view import View

    return View(ds, kind, positions)
