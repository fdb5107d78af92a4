"""Split files on disk (`meta/splits/<name>.json`): written in their canonical bytes at build
time, read back with the limits a dataset's size allows and their sha256 checked."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from ...errors import VtsError
from ..format.layout import KINDS, split_file_name
from ..format.records import SplitFile, schema_errors

if TYPE_CHECKING:
    from ..format.info import DatasetInfo

#: A split file may list each sample of the dataset at most once, and hold at most 1 MiB plus
#: 512 bytes a sample (an id is at most 160 characters).
SPLIT_BASE_BYTES = 1 << 20
SPLIT_BYTES_PER_SAMPLE = 512


def split_limits(n_samples: int) -> tuple[int, int]:
    """(bytes, ids) a split file of a dataset of n_samples samples may hold."""
    return SPLIT_BASE_BYTES + SPLIT_BYTES_PER_SAMPLE * n_samples, n_samples


def dataset_split_limits(info: DatasetInfo) -> tuple[int, int]:
    """`split_limits` of a dataset from its info.json, one size for the loader and verify: its
    samples of every kind plus its episodes (a split lists samples of one kind, or episodes)."""
    n = sum(getattr(info.counts, kind).samples for kind in KINDS)
    return split_limits(n + (info.episodes.episodes if info.episodes is not None else 0))


def write_splits(folder: str | Path, splits: Iterable[SplitFile]) -> dict[str, str]:
    """Write each split to folder/<name>.json (canonical bytes); returns {name: sha256}."""
    from ...atomic import write_bytes_atomic

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out: dict[str, str] = {}
    for sp in splits:
        if sp.name in out:
            raise ValueError(f"two splits named {sp.name!r}")
        errs = schema_errors(sp.to_dict(), "split")
        if errs:
            raise ValueError(f"refusing to write an invalid split {sp.name!r}: {errs[0]}")
        write_bytes_atomic(folder / split_file_name(sp.name), sp.to_bytes())
        out[sp.name] = sp.sha256()
    return out


def read_split(path: str | Path, expected_sha256: str | None = None, *,
               max_bytes: int = 256 << 20, max_ids: int | None = None) -> SplitFile:
    """Read and validate a split file; a checksum other than expected_sha256 is an error, and
    so is a file over max_bytes or listing more than max_ids ids (`split_limits`: a
    split lists each sample of its dataset at most once), refused before any id is looked at."""
    import os

    from ...jsonio import loads, read_bytes, regular_file

    path = Path(path)
    if not os.path.lexists(path):
        raise VtsError("split file not found", path)
    size = regular_file(path, "split file").stat().st_size
    if size > max_bytes:
        raise VtsError(f"split file of {size} bytes, more than a split of this dataset can hold "
                       f"({max_bytes} bytes)", path)
    data = read_bytes(path, "split file", max_bytes)
    got = hashlib.sha256(data).hexdigest()
    if expected_sha256 is not None and got != expected_sha256:
        raise VtsError(f"sha256 mismatch: expected {expected_sha256}, found {got} "
                       "(the split file was changed after the build)", path)
    doc = loads(data, path)
    parts = doc.get("parts") if isinstance(doc, dict) else None
    if max_ids is not None and isinstance(parts, dict):
        n = sum(len(v) for v in parts.values() if isinstance(v, list))
        if n > max_ids:
            raise VtsError(f"lists {n} sample ids, more than the {max_ids} samples of the "
                           "dataset (a split lists each sample at most once)", path)
    errs = schema_errors(doc, "split")
    if errs:
        more = f" (and {len(errs) - 1} more)" if len(errs) > 1 else ""
        raise VtsError(f"{errs[0][:200]}{more}", path)
    return SplitFile.from_dict(doc)
