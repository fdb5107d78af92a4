"""Opening a dataset's Zarr groups for reading, from a path or any fsspec URL (through
read/location.py: timeouts, size limits, servers without byte ranges), and the strict store
on which a missing chunk is an error rather than fill values."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from zarr.storage import WrapperStore

from ...errors import VtsError
from ..format.layout import KINDS, group_path


class StrictStore(WrapperStore):
    """A read-only zarr store on which a missing chunk or shard is an error, never fill values
    (an incomplete copy of a dataset must not read as zeros)."""

    def __init__(self, store: Any, location: str) -> None:
        super().__init__(store)
        self.location = location

    def _with_store(self, store: Any) -> StrictStore:
        return type(self)(store, self.location)

    async def get(self, key: str, prototype: Any, byte_range: Any = None) -> Any:
        if "://" not in self.location:  # a local file must be a regular one of bounded size
            import stat

            try:
                st = os.stat(Path(self.location) / key)
            except OSError:
                st = None
            if st is not None and (not stat.S_ISREG(st.st_mode) or st.st_size > 4 << 30):
                raise VtsError("not a regular file of at most 4 GiB (a link to a device?)",
                               f"{self.location}/{key}")
        buf = await self._store.get(key, prototype, byte_range)
        if buf is None and "/c/" in key:
            raise VtsError("missing (an incomplete copy of the dataset?)",
                           f"{self.location}/{key}")
        return buf


def _is_url(location: str | os.PathLike) -> bool:
    return "://" in str(location)


def group_location(root: str | os.PathLike, kind: str) -> str:
    """Location of a kind's group under a dataset root (path or URL)."""
    return f"{str(root).rstrip('/')}/{group_path(kind)}"


def open_group(root: str | os.PathLike, kind: str,
               storage_options: dict[str, Any] | None = None) -> Any:
    """Open a dataset's `static` or `slip` group read-only, from a path or an fsspec URL (read
    through read/location.py: timeouts, size limits, servers without byte ranges)."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    return open_group_at(group_location(root, kind), storage_options)


def open_group_at(loc: str, storage_options: dict[str, Any] | None = None) -> Any:
    """Open the Zarr group at a path or URL read-only, its zarr.json checked first (any
    group of a dataset: a kind's, or the episodes' frames)."""
    import zarr
    from zarr.storage import LocalStore

    from ...jsonio import loads, read_json

    if _is_url(loc):
        from .location import read_remote, remote_store

        meta = f"{loc}/zarr.json"  # within the metadata size limit; NaN, deep nesting...
        loads(read_remote(meta, storage_options, missing="no such Zarr group"), meta,
              "Zarr metadata")
        store = remote_store(loc, storage_options)
    else:
        if not Path(loc).is_dir():
            raise VtsError("no such Zarr group", loc)
        store = LocalStore(loc, read_only=True)
        read_json(Path(loc) / "zarr.json", "Zarr metadata")  # NaN, deep nesting, a device...
    try:
        return zarr.open_group(store, mode="r", use_consolidated=True)
    except VtsError:
        raise
    except Exception as e:  # a changed zarr.json: zarr raises TypeError, ValueError, KeyError...
        text = str(e).strip().splitlines()[0][:120] if str(e).strip() else ""
        raise VtsError(f"cannot open the Zarr group ({type(e).__name__}: {text}; its zarr.json "
                       "was changed?)", loc) from None
