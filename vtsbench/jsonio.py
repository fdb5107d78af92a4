"""Reading user files safely: JSON through the standard library with its limits turned into
one-line errors, and bytes only from regular files of a bounded size.

Every JSON a user gives (manifests, submissions' metadata, calibration headers, dataset
metadata, split files, leaderboard entries, configs) goes through `loads`, so NaN, Infinity,
numbers of thousands of digits and deeply nested documents are refused the same way everywhere.
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import Any

from .errors import VtsError

#: Largest user file read whole (frames, shards, metadata); a /dev/zero link or a huge file is
#: refused before it is read rather than exhausting memory.
MAX_FILE_BYTES = 2 << 30


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _finite_float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise ValueError(f"number {text[:20]}{'...' if len(text) > 20 else ''} is out of range")
    return v


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """An object whose keys are all different: with a repeated key, one reader would see the
    first value and another the last (Python's json keeps the last)."""
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                shown = key if len(key) <= 40 else key[:40] + "..."
                raise ValueError(f"key {shown!r} appears more than once in one object")
            seen.add(key)
    return out


def loads(data: str | bytes, path: object, what: str = "JSON") -> Any:
    """Parse JSON text; NaN, Infinity, overflowing or over-long numbers, a key repeated in one
    object, deep nesting, bad UTF-8 and syntax errors become one VtsError naming path."""
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
        return json.loads(text, parse_constant=_no_constant, parse_float=_finite_float,
                          object_pairs_hook=_unique_keys)
    except UnicodeDecodeError as e:
        raise VtsError(f"{what} is not UTF-8 text ({e.reason})", path) from None
    except json.JSONDecodeError as e:
        raise VtsError(f"invalid {what} at line {e.lineno} column {e.colno}: {e.msg}",
                       path) from None
    except RecursionError:
        raise VtsError(f"invalid {what}: nested too deeply", path) from None
    except ValueError as e:  # NaN/Infinity, 1e999, an integer over Python's digit limit, a
        # repeated key
        reason = str(e).splitlines()[0][:100]
        raise VtsError(f"invalid {what}: {reason}", path) from None


def dumps(obj: Any, **kwargs: Any) -> str:
    """json.dumps that refuses NaN and infinity instead of writing invalid JSON."""
    try:
        return json.dumps(obj, allow_nan=False, **kwargs)
    except ValueError as e:
        raise VtsError(f"refusing to write invalid JSON ({e})") from None


def regular_file(path: str | os.PathLike, what: str = "file",
                 limit: int = MAX_FILE_BYTES) -> Path:
    """path when it is a regular file of at most `limit` bytes (links followed); else a one-line
    VtsError. A FIFO, a device (/dev/zero) or a socket would block or never end."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise VtsError(f"{what} not found", path) from None
    except OSError as e:
        raise VtsError(f"cannot read {what} ({e.strerror or e})", path) from None
    if stat.S_ISDIR(st.st_mode):
        article = "an" if what[:1].lower() in "aeiou" else "a"
        raise VtsError(f"is a folder, not {article} {what}", path)
    if not stat.S_ISREG(st.st_mode):
        raise VtsError(f"not a regular file but a pipe, device or socket ({what} expected)", path)
    if st.st_size > limit:
        raise VtsError(f"{what} of {st.st_size} bytes is over the limit of {limit}", path)
    return path


def read_bytes(path: str | os.PathLike, what: str = "file", limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of bounded size; one-line VtsError otherwise."""
    path = regular_file(path, what, limit)
    try:
        with open(path, "rb") as fh:  # the size told by stat, +1 to see a file that grew
            data = fh.read(min(limit, os.fstat(fh.fileno()).st_size) + 1)
    except OSError as e:
        raise VtsError(f"cannot read {what} ({e.strerror or e})", path) from None
    if len(data) > limit:
        raise VtsError(f"{what} is over the limit of {limit} bytes", path)
    return data


def read_json(path: str | os.PathLike, what: str = "JSON", limit: int = 256 << 20) -> Any:
    """A JSON file through `loads`, refusing non-regular and over-large files."""
    return loads(read_bytes(path, what, limit), path, what)


def strict_validator(schema: dict[str, Any], **kwargs: Any) -> Any:
    """A JSON Schema (2020-12) validator where "integer" means an integer literal: 3.0 and 1.5
    are refused where a frame index, a count or a size is expected (the standard accepts 3.0,
    which Python then cannot index with)."""
    import jsonschema

    def is_int(_checker: Any, value: Any) -> bool:
        return isinstance(value, int) and not isinstance(value, bool)

    checker = jsonschema.Draft202012Validator.TYPE_CHECKER.redefine("integer", is_int)
    cls = jsonschema.validators.extend(jsonschema.Draft202012Validator, type_checker=checker)
    return cls(schema, **kwargs)


def read_csv(path: str | os.PathLike, what: str = "CSV file", limit: int = 1 << 30
             ) -> list[list[str]]:
    """The non-empty rows of a CSV file (csv module, fields up to its 128 KiB limit); a header
    with a repeated or empty column name, an over-long field, bad UTF-8 or a NUL byte is one
    VtsError naming the file (a repeated name would shift every column after it)."""
    import csv
    import io

    data = read_bytes(path, what, limit)
    try:
        text = data.decode("utf-8-sig")
        rows = [r for r in csv.reader(io.StringIO(text, newline=""))
                if r and any(c.strip() for c in r)]
    except UnicodeDecodeError as e:
        raise VtsError(f"{what} is not UTF-8 text ({e.reason})", path) from None
    except csv.Error as e:
        raise VtsError(f"unreadable {what} ({e})", path) from None
    if rows:
        names = [h.strip() for h in rows[0]]
        seen: set[str] = set()
        for i, n in enumerate(names, start=1):
            if not n:
                raise VtsError(f"{what}: column {i} of the header has no name", path)
            if n.lower() in seen:
                raise VtsError(f"{what}: column name {n!r} appears more than once in the "
                               "header", path)
            seen.add(n.lower())
        rows[0] = names
    return rows
