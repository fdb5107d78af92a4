"""A dataset given as a URL, for `vtsbench info` and `vtsbench verify`: the same locations
`vtsbench.load` takes (a folder, file://, http(s)://, s3://, memory://... through fsspec).

A path or a file:// URL is used in place. For any other URL, `info` reads info.json and the
indexes and asks the file system for sizes (no array data), and `verify`, which reads every
byte anyway, checks a temporary copy of info.json and of every file it lists. Every read goes
through dataset.location (timeouts, size limits, paths that stay inside the copy).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from ...errors import VtsError
from ..format.info import DatasetInfo, load_info
from ..format.layout import INFO_PATH
from .location import Location, filesystem, safe_rel

#: Files fetched at once from a remote dataset.
FETCH_THREADS = 8


def local_path(location: str | os.PathLike) -> Path | None:
    """The local folder of a location (a path or a file:// URL); None for a remote URL."""
    text = str(location)
    if "://" not in text:
        return Path(text)
    from fsspec.implementations.local import LocalFileSystem

    fs, path = filesystem(text)
    return Path(path) if isinstance(fs, LocalFileSystem) else None


def remote_info(loc: Location) -> DatasetInfo:
    """info.json of a remote dataset, validated as a local one is."""
    return loc.checked(INFO_PATH, load_info)


def remote_sizes(loc: Location, info: DatasetInfo) -> dict[str, int]:
    """Size of info.json and of every file it lists (relative path -> bytes)."""
    rels = [INFO_PATH, *sorted(info.files)]
    return dict(zip(rels, loc.sizes(rels), strict=True))


@contextlib.contextmanager
def local_copy(location: str | os.PathLike,
               storage_options: Mapping[str, Any] | None = None) -> Iterator[Path]:
    """A local folder holding the dataset: the folder itself for a path or file:// URL, else a
    temporary copy of info.json and every file it lists (removed on leaving). A listed path
    that would leave the copy's folder is refused before anything is fetched."""
    path = local_path(location)
    if path is not None:
        yield path
        return
    from concurrent.futures import ThreadPoolExecutor

    loc = Location(location, storage_options)
    info = remote_info(loc)
    rels = [INFO_PATH, *sorted(info.files)]
    for rel in rels:
        loc.path(rel)  # no '..', absolute path, backslash...: refused naming info.json
    with tempfile.TemporaryDirectory(prefix="vtsbench-") as tmp:
        root = Path(tmp) / "dataset"
        inside = root.resolve()

        def fetch(rel: str) -> None:
            dest = root / safe_rel(rel, loc.path(INFO_PATH))
            if not dest.resolve().is_relative_to(inside):  # and where it resolves, links too
                raise VtsError(f"file path {rel[:120]!r} leaves the dataset folder; refused",
                               loc.path(INFO_PATH))
            dest.parent.mkdir(parents=True, exist_ok=True)
            loc.copy(rel, dest)

        with ThreadPoolExecutor(FETCH_THREADS) as pool:
            list(pool.map(fetch, rels))
        yield root
