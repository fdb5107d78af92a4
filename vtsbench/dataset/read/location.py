"""Where a dataset lives, and the one place its files are read from a URL.

Every relative path of a dataset is joined here (`Location.path`) and must stay inside the
dataset: metadata naming `../x`, `/etc/x` or `a\\b` is refused in one line naming info.json.
Remote reads (the loader's metadata and Zarr arrays, `vtsbench info` and `verify` of a URL) go
through `read_remote` and, over HTTP(S), through `BoundedHTTPFileSystem`: connect and read
timeouts, a size limit per file (METADATA_BYTES for metadata, a body past it is cut at the limit
plus one byte and refused), and byte ranges taken from the whole file when a server ignores the
`Range` header (as `python -m http.server` does). The limits are read from the environment on
each use: VTSBENCH_REMOTE_CONNECT_TIMEOUT and VTSBENCH_REMOTE_READ_TIMEOUT (seconds),
VTSBENCH_REMOTE_METADATA_MB (MiB).
"""

from __future__ import annotations

import os
import re
import tempfile
from collections import OrderedDict
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ...errors import VtsError
from ...jsonio import MAX_FILE_BYTES
from ..format.layout import INFO_PATH, PREVIEW_DIR

CONNECT_TIMEOUT_ENV = "VTSBENCH_REMOTE_CONNECT_TIMEOUT"
READ_TIMEOUT_ENV = "VTSBENCH_REMOTE_READ_TIMEOUT"
METADATA_MB_ENV = "VTSBENCH_REMOTE_METADATA_MB"
#: Seconds to open a connection, and the longest wait for any bytes of an answer.
CONNECT_TIMEOUT_S = 10.0
READ_TIMEOUT_S = 30.0
#: Largest metadata file read from a URL (info.json, split files, indexes, zarr.json).
METADATA_MB = 64
#: Largest other file (a shard, a preview) read whole from a URL.
DATA_BYTES = MAX_FILE_BYTES
#: Whole files kept in memory per file system when a server ignores byte ranges.
RANGE_CACHE_BYTES = 256 << 20
_CHUNK = 1 << 20
#: Characters no file of a dataset has in its relative path: a backslash, URL syntax, controls.
_UNSAFE = re.compile(r"[\\%?#\x00-\x1f\x7f]")


def _setting(name: str, default: float, what: str) -> float:
    """A positive number from the environment, or the default."""
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise VtsError(f"{name}={text[:40]!r}: {what} must be a positive number")
    return value


def timeouts() -> tuple[float, float]:
    """(connect, read) timeouts in seconds for remote reads."""
    return (_setting(CONNECT_TIMEOUT_ENV, CONNECT_TIMEOUT_S, "the connect timeout (s)"),
            _setting(READ_TIMEOUT_ENV, READ_TIMEOUT_S, "the read timeout (s)"))


def metadata_limit() -> int:
    """Largest metadata file read from a URL, in bytes."""
    return int(_setting(METADATA_MB_ENV, METADATA_MB, "the metadata size limit (MiB)") * 2**20)


def limit_for(rel: str) -> int:
    """Size limit of a dataset file by its path: shards and previews are data, the rest
    metadata."""
    where = f"/{rel}"
    return DATA_BYTES if "/c/" in where or f"/{PREVIEW_DIR}/" in where else metadata_limit()


def safe_rel(rel: Any, info_where: str) -> str:
    """rel when it names a file inside the dataset: relative, '/'-separated, no '', '.' or '..'
    part, no backslash, '%', '?', '#' or control character; else a one-line VtsError naming
    info.json (metadata must never lead a read or a write outside the dataset folder)."""
    ok = (isinstance(rel, str) and 0 < len(rel) <= 1024 and not rel.startswith("/")
          and not _UNSAFE.search(rel) and not re.match(r"[A-Za-z]:", rel)
          and all(p not in ("", ".", "..") for p in rel.split("/")))
    if not ok:
        shown = repr(rel)[:120]
        raise VtsError(f"unsafe file path {shown}: a dataset's files are plain relative paths "
                       "inside it (no absolute path, '..', empty part or backslash); refused",
                       info_where)
    return rel


def _is_http(url: str) -> bool:
    return url.split("://", 1)[0].lower() in ("http", "https")


def http_options(storage_options: Mapping[str, Any] | None) -> dict[str, Any]:
    """storage_options for an HTTP(S) file system with the timeouts added (a timeout given in
    client_kwargs wins)."""
    import aiohttp

    opts = dict(storage_options or {})
    client = dict(opts.get("client_kwargs") or {})
    if "timeout" not in client:
        connect, read = timeouts()
        client["timeout"] = aiohttp.ClientTimeout(total=None, connect=connect,
                                                  sock_connect=connect, sock_read=read)
    opts["client_kwargs"] = client
    return opts


def filesystem(url: str, storage_options: Mapping[str, Any] | None = None,
               asynchronous: bool = False) -> tuple[Any, str]:
    """The fsspec file system and path of a URL: a BoundedHTTPFileSystem for http(s), else the
    backend fsspec picks; an unknown protocol is a one-line VtsError."""
    if _is_http(url):
        fs_class = http_filesystem_class()
        opts = http_options(storage_options)
        # an asynchronous one (zarr's) keeps what it learnt of the server and the whole files
        # of the range fallback: its own instance, dropped with the store that uses it
        return fs_class(asynchronous=asynchronous, skip_instance_cache=asynchronous,
                        **opts), url
    import fsspec

    try:
        opts = {**(storage_options or {}), **({"asynchronous": True} if asynchronous else {})}
        return fsspec.core.url_to_fs(url, **opts)
    except (ValueError, ImportError) as e:  # an unknown protocol, a backend not installed
        raise VtsError(f"cannot open this URL ({e})", url) from None


def _too_large(limit: int, url: str) -> VtsError:
    return VtsError(f"over the size limit of {limit} bytes for a remote file (set "
                    f"{METADATA_MB_ENV} to raise the limit for metadata); refused", url)


def _failure(e: BaseException, url: str) -> VtsError:
    """A one-line VtsError for a failed remote read."""
    import asyncio

    import aiohttp
    from fsspec.exceptions import FSTimeoutError

    if isinstance(e, VtsError):
        return e
    if isinstance(e, asyncio.TimeoutError | TimeoutError | FSTimeoutError
                  | aiohttp.ServerTimeoutError):
        connect, read = timeouts()
        return VtsError(f"no answer in time (connect timeout {connect:g} s, read timeout "
                        f"{read:g} s; set {READ_TIMEOUT_ENV} or {CONNECT_TIMEOUT_ENV} to wait "
                        "longer)", url)
    msg = str(e).strip().splitlines()[0][:200] if str(e).strip() else ""
    return VtsError(f"cannot read ({type(e).__name__}{': ' + msg if msg else ''})", url)


def stream_remote(url: str, sink: Callable[[bytes], Any], limit: int,
                  storage_options: Mapping[str, Any] | None = None,
                  missing: str = "not found") -> int:
    """Pass the bytes of a remote file to sink in pieces; returns the size. More than `limit`
    bytes, a missing file, a timeout or a network error is a one-line VtsError naming url."""
    fs, path = filesystem(url, storage_options)
    try:
        if isinstance(fs, http_filesystem_class()):
            from fsspec.asyn import sync

            return sync(fs.loop, fs._stream, path, sink, limit)
        n = 0
        with fs.open(path, "rb") as fh:
            while chunk := fh.read(min(_CHUNK, limit + 1 - n)):
                n += len(chunk)
                if n > limit:
                    raise _too_large(limit, url)
                sink(chunk)
        return n
    except FileNotFoundError:
        raise VtsError(missing, url) from None
    except Exception as e:  # network and permission errors of any fsspec backend
        raise _failure(e, url) from None


def read_remote(url: str, storage_options: Mapping[str, Any] | None = None,
                limit: int | None = None, missing: str = "not found") -> bytes:
    """A whole remote file of at most `limit` bytes (default: the metadata limit)."""
    parts: list[bytes] = []
    stream_remote(url, parts.append, metadata_limit() if limit is None else limit,
                  storage_options, missing)
    return b"".join(parts)


class Location:
    """Where a dataset lives (a folder or an fsspec URL) and how to read one of its files."""

    def __init__(self, root: str | os.PathLike, storage_options: Mapping[str, Any] | None = None):
        self.url = str(root).rstrip("/") or "/"
        self.remote = "://" in self.url
        self.storage_options = dict(storage_options or {})

    def path(self, rel: str) -> str:
        """The location of a file of the dataset (relative path with '/'); a path that would
        leave the dataset is a one-line VtsError naming info.json."""
        return f"{self.url}/{safe_rel(rel, f'{self.url}/{INFO_PATH}')}"

    def read_bytes(self, rel: str, missing: str = "not found", limit: int | None = None) -> bytes:
        """A whole file of the dataset of at most `limit` bytes (default for a URL by its path:
        metadata or data; for a folder, any regular file of at most DATA_BYTES); missing,
        over-large or unreadable is a one-line VtsError."""
        where = self.path(rel)
        if self.remote:
            return read_remote(where, self.storage_options,
                               limit_for(rel) if limit is None else limit, missing)
        from ...jsonio import read_bytes

        if not os.path.lexists(where):
            raise VtsError(missing, where)
        return read_bytes(where, "file", DATA_BYTES if limit is None else limit)

    def copy(self, rel: str, dest: Path) -> None:
        """Copy a file of a remote dataset to dest (written through a temporary name), within
        the size limit of its path."""
        from ...atomic import replacing

        where = self.path(rel)
        with replacing(dest) as tmp, open(tmp, "xb") as fh:
            stream_remote(where, fh.write, limit_for(rel), self.storage_options)

    def sizes(self, rels: list[str]) -> list[int]:
        """Sizes in bytes of files of a remote dataset (0 when the server tells none)."""
        urls = [self.path(r) for r in rels]
        fs, _ = filesystem(self.url, self.storage_options)
        try:
            paths = [u if _is_http(u) else filesystem(u, self.storage_options)[1] for u in urls]
            return [int(s or 0) for s in fs.sizes(paths)]
        except Exception as e:  # network and permission errors of any fsspec backend
            err = _failure(e, self.url)
            raise VtsError(f"cannot list the dataset's files ({str(err)[len(self.url) + 2:]})",
                           self.url) from None

    def checked(self, rel: str, read: Any, *args: Any) -> Any:
        """Run a reader of local files (read(path, *args)) on one file of the dataset.

        A remote file is copied into a temporary folder first; errors name the URL.
        """
        where = self.path(rel)
        if not self.remote:
            return read(Path(where), *args)
        data = self.read_bytes(rel, "not found (not a vtsbench dataset?)"
                               if rel == INFO_PATH else "not found")
        with tempfile.TemporaryDirectory(prefix="vtsbench-") as tmp:
            local = Path(tmp) / rel
            local.parent.mkdir(parents=True, exist_ok=True)
            local.write_bytes(data)
            try:
                return read(local, *args)
            except VtsError as e:
                text = str(e)
                if e.path and text.startswith(f"{e.path}: "):
                    text = text[len(e.path) + 2:]
                raise VtsError(text, where) from None


def remote_store(url: str, storage_options: Mapping[str, Any] | None = None) -> Any:
    """A read-only zarr store of a remote Zarr group, reading through `filesystem` (timeouts,
    size limits and the byte-range fallback over HTTP)."""
    from zarr.storage import FsspecStore

    fs, path = filesystem(url, storage_options, asynchronous=True)
    if not getattr(fs, "async_impl", False):  # a synchronous backend (zarr wraps it)
        return FsspecStore.from_url(url, storage_options=dict(storage_options or {}),
                                    read_only=True)
    return FsspecStore(fs, read_only=True, path=path)


_HTTP_CLASS: list[type] = []


def http_filesystem_class() -> type:
    """BoundedHTTPFileSystem (defined on first use: fsspec and aiohttp are imported then)."""
    if not _HTTP_CLASS:
        _HTTP_CLASS.append(_define_http_filesystem())
    return _HTTP_CLASS[0]


def _define_http_filesystem() -> type:
    import asyncio
    import weakref

    from fsspec.implementations.http import HTTPFileSystem

    class BoundedHTTPFileSystem(HTTPFileSystem):
        """fsspec's HTTP file system with every body read under a size limit, and byte ranges
        cut from the whole file (read once, kept in a bounded cache) when the server answers a
        ranged request with 200 and the whole file."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.no_ranges: set[str] = set()  # hosts that answered a range with 200
            self._whole: OrderedDict[str, bytes] = OrderedDict()
            self._locks: dict[str, asyncio.Lock] = {}

        async def set_session(self) -> Any:
            """The aiohttp session; one made in an event loop of its own (zarr's) is closed at
            exit too, as fsspec does for its own loop."""
            new = self._session is None
            session = await super().set_session()
            if new and self.asynchronous:
                weakref.finalize(self, self.close_session, asyncio.get_running_loop(), session)
            return session

        async def _stream(self, url: str, sink: Callable[[bytes], Any], limit: int,
                          headers: Mapping[str, str] | None = None) -> int:
            """GET url, passing the body to sink; more than `limit` bytes is refused."""
            n, _ = await self._get(url, sink, limit, headers)
            return n

        async def _get(self, url: str, sink: Callable[[bytes], Any], limit: int,
                       headers: Mapping[str, str] | None = None) -> tuple[int, int]:
            """(bytes read, HTTP status) of a GET whose body goes to sink."""
            kw = self.kwargs.copy()
            kw["headers"] = {**kw.pop("headers", {}), **(headers or {})}
            session = await self.set_session()
            async with session.get(self.encode_url(url), **kw) as r:
                if r.status == 416:  # a range past the end
                    return 0, r.status
                self._raise_not_found_for_status(r, url)
                told = r.headers.get("Content-Length", "")
                if told.isdigit() and int(told) > limit:
                    raise _too_large(limit, url)
                n = 0
                async for chunk in r.content.iter_chunked(_CHUNK):
                    n += len(chunk)
                    if n > limit:
                        raise _too_large(limit, url)
                    sink(chunk)
                return n, r.status

        async def _cat_file(self, url: str, start: int | None = None, end: int | None = None,
                            limit: int | None = None, **kwargs: Any) -> bytes:
            try:
                if start is None and end is None:
                    if url in self._whole:  # read whole already for the range fallback
                        self._whole.move_to_end(url)
                        return self._whole[url]
                    parts: list[bytes] = []
                    await self._get(url, parts.append, _default_limit(url) if limit is None
                                    else limit)
                    return b"".join(parts)
                if start == end:
                    return b""
                host = _host(url)
                if host in self.no_ranges:
                    return (await self._whole_file(url))[start:end]
                parts = []
                rng = await self._process_limits(url, start, end)
                _, status = await self._get(url, parts.append, DATA_BYTES, {"Range": rng})
                data = b"".join(parts)
                if status != 200:  # 206: the range asked for (416: nothing)
                    return data
                self.no_ranges.add(host)  # 200: the whole file
                self._remember(url, data)
                return data[start:end]
            except FileNotFoundError:
                raise
            except Exception as e:  # timeouts and network errors: one line naming the URL
                raise _failure(e, url) from None

        async def _whole_file(self, url: str) -> bytes:
            """The whole file at url, read once while it stays in the cache."""
            if url in self._whole:
                self._whole.move_to_end(url)
                return self._whole[url]
            lock = self._locks.setdefault(url, asyncio.Lock())
            async with lock:
                if url not in self._whole:
                    parts: list[bytes] = []
                    await self._get(url, parts.append, DATA_BYTES)
                    data = b"".join(parts)
                    self._remember(url, data)
                    return data
                return self._whole[url]

        def _remember(self, url: str, data: bytes) -> None:
            """Keep a whole file, dropping the least recently used past RANGE_CACHE_BYTES."""
            if len(data) > RANGE_CACHE_BYTES:
                return
            self._whole[url] = data
            while sum(map(len, self._whole.values())) > RANGE_CACHE_BYTES:
                old, _ = self._whole.popitem(last=False)
                self._locks.pop(old, None)

    return BoundedHTTPFileSystem


def _host(url: str) -> str:
    """scheme://host:port of a URL."""
    scheme, _, rest = url.partition("://")
    return f"{scheme.lower()}://{rest.split('/', 1)[0].lower()}"


def _default_limit(url: str) -> int:
    """Size limit of a whole-file read of url: metadata unless it is a shard or a preview."""
    return limit_for(url.partition("://")[2])
