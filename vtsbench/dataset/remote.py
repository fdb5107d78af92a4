"""A dataset given as a URL, for `vtsbench info` and `vtsbench verify`: the same locations
`vtsbench.load` takes (a folder, file://, http(s)://, s3://, memory://... through fsspec).

A path or a file:// URL is used in place. For any other URL, `info` reads info.json and the
indexes and asks the file system for sizes (no array data), and `verify`, which reads every
byte anyway, checks a temporary copy of info.json and of every file it lists.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from ..errors import VtsError
from .loader import Location
from .schema import INFO_PATH, DatasetInfo, load_info

#: Files fetched at once from a remote dataset.
FETCH_THREADS = 8


def local_path(location: str | os.PathLike) -> Path | None:
    """The local folder of a location (a path or a file:// URL); None for a remote URL."""
    text = str(location)
    if "://" not in text:
        return Path(text)
    import fsspec
    from fsspec.implementations.local import LocalFileSystem

    try:
        fs, path = fsspec.core.url_to_fs(text)
    except (ValueError, ImportError) as e:  # an unknown protocol, a backend not installed
        raise VtsError(f"cannot open this URL ({e})", text) from None
    return Path(path) if isinstance(fs, LocalFileSystem) else None


def remote_info(loc: Location) -> DatasetInfo:
    """info.json of a remote dataset, validated as a local one is."""
    return loc.checked(INFO_PATH, load_info)


def remote_sizes(loc: Location, info: DatasetInfo) -> dict[str, int]:
    """Size of info.json and of every file it lists (relative path -> bytes)."""
    import fsspec

    rels = [INFO_PATH, *sorted(info.files)]
    fs, _ = fsspec.core.url_to_fs(loc.url, **loc.storage_options)
    try:
        sizes = fs.sizes([fsspec.core.url_to_fs(loc.path(r), **loc.storage_options)[1]
                          for r in rels])
    except Exception as e:  # network and permission errors of any fsspec backend
        raise VtsError(f"cannot list the dataset's files ({type(e).__name__})", loc.url) from None
    return {r: int(s or 0) for r, s in zip(rels, sizes, strict=True)}


@contextlib.contextmanager
def local_copy(location: str | os.PathLike,
               storage_options: Mapping[str, Any] | None = None) -> Iterator[Path]:
    """A local folder holding the dataset: the folder itself for a path or file:// URL, else a
    temporary copy of info.json and every file it lists (removed on leaving)."""
    path = local_path(location)
    if path is not None:
        yield path
        return
    from concurrent.futures import ThreadPoolExecutor

    from ..atomic import write_bytes_atomic

    loc = Location(location, storage_options)
    info = remote_info(loc)
    with tempfile.TemporaryDirectory(prefix="vtsbench-") as tmp:
        root = Path(tmp) / "dataset"

        def fetch(rel: str) -> None:
            dest = root / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomic(dest, loc.read_bytes(rel))

        with ThreadPoolExecutor(FETCH_THREADS) as pool:
            list(pool.map(fetch, [INFO_PATH, *sorted(info.files)]))
        yield root
