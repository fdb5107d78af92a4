"""Labels that live beside the files: a CSV per file, per folder or per frame range, and marker
files whose presence in an entry's folder sets a label (`vtsbench manifest --labels/--marker`).

The CSV is read by the csv module with a field-size limit and a row limit; every value is
checked (states, directions 0..7, finite depths) and a bad row is a one-line error naming it.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath
from typing import Any

from ..errors import VtsError
from ..labels import STATES
from .manifest import Entry

#: The column naming the file or folder, under any of these names.
FILE_COLUMNS = ("file", "path", "folder", "filename", "name")
#: Columns that set the entry's labels; every other column goes into the entry's meta.
LABEL_COLUMNS = ("state", "direction", "press_depth_mm", "object", "take")
RANGE_COLUMNS = ("start", "stop")
MAX_BYTES = 64 << 20
MAX_FIELD = 4096
MAX_COLUMNS = 64


@dataclass(frozen=True)
class LabelRow:
    """One CSV row: which path (file or folder), which frames, which values."""

    line: int
    path: str
    start: int | None
    stop: int | None
    values: dict[str, str]


def _clean_path(text: str) -> str:
    p = text.strip().replace("\\", "/")
    while p.startswith("./"):
        p = p[2:]
    return p.strip("/")


def read_labels(path: str | Path) -> list[LabelRow]:
    """Rows of a labels CSV: a file column (file|path|folder|filename|name), optional start and
    stop (frames, stop exclusive), and label columns; empty cells mean 'not given'."""
    from ..jsonio import regular_file

    path = regular_file(path, "labels file", MAX_BYTES)  # a folder or a FIFO said as such
    old = csv.field_size_limit()
    csv.field_size_limit(MAX_FIELD)
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            header = [(h or "").strip().lower() for h in (reader.fieldnames or [])]
            if len(header) > MAX_COLUMNS:
                raise VtsError(f"{len(header)} columns; at most {MAX_COLUMNS}", path)
            if len(set(header)) != len(header):
                raise VtsError("a column name appears twice", path)
            keys = [h for h in header if h in FILE_COLUMNS]
            if len(keys) > 1:  # which one names the file? the other would become a field
                raise VtsError(f"two file columns, {' and '.join(keys)}: keep one", path)
            key = keys[0] if keys else None
            if key is None:
                raise VtsError(f"no file column (one of {', '.join(FILE_COLUMNS)}); found "
                               f"{', '.join(header) or 'no header'}", path)
            if len(header) < 2:
                raise VtsError("no label column beside the file column", path)
            rows = []
            for i, raw in enumerate(reader, start=2):
                if None in raw:
                    raise VtsError(f"row {i}: more cells than columns", path)
                row = {k.strip().lower(): (v or "").strip() for k, v in raw.items()}
                rows.append(_row(row, key, i, path))
    except csv.Error as e:
        raise VtsError(f"not a readable CSV ({e})", path) from None
    except UnicodeDecodeError as e:
        raise VtsError(f"not UTF-8 text ({e.reason})", path) from None
    finally:
        csv.field_size_limit(old)
    return rows


def _row(row: dict[str, str], key: str, line: int, path: Path) -> LabelRow:
    name = _clean_path(row.pop(key))
    if not name or ".." in PurePosixPath(name).parts:
        raise VtsError(f"row {line}: needs a file or folder inside the recordings", path)
    rng: list[int | None] = []
    for c in RANGE_COLUMNS:
        v = row.pop(c, "")
        if v == "":
            rng.append(None)
            continue
        if not v.isdigit():
            raise VtsError(f"row {line}: {c} must be a frame number, got {v!r}", path)
        rng.append(int(v))
    start, stop = rng
    if (start is None) != (stop is None) or (start is not None and stop <= start):
        raise VtsError(f"row {line}: give both start and stop, stop after start", path)
    values = {k: v for k, v in row.items() if v != ""}
    _check_values(values, line, path)
    return LabelRow(line, name, start, stop, values)


def _check_values(v: dict[str, str], line: int, path: Path) -> None:
    if "state" in v and v["state"] not in STATES:
        raise VtsError(f"row {line}: state {v['state']!r} is not one of {', '.join(STATES)}",
                       path)
    if "direction" in v and not (v["direction"].isdigit() and int(v["direction"]) <= 7):
        raise VtsError(f"row {line}: direction {v['direction']!r} is not 0..7", path)
    if "press_depth_mm" in v:
        try:
            d = float(v["press_depth_mm"])
        except ValueError:
            d = math.nan
        if not (math.isfinite(d) and d >= 0):
            raise VtsError(f"row {line}: press_depth_mm {v['press_depth_mm']!r} is not a "
                           "finite depth >= 0", path)


def row_matches(row: LabelRow, rel: str, start: int | None, stop: int | None) -> bool:
    """Whether a row applies to an entry: its file, or a folder above it (or the folder an
    image-folder entry is), and, for a frame range, frames inside it."""
    if not (rel == row.path or rel.startswith(row.path + "/")):
        return False
    if row.start is None:
        return True
    if start is None:
        return False
    return row.start <= start and (stop if stop is not None else start + 1) <= row.stop


def apply_values(e: Entry, values: dict[str, Any]) -> Entry:
    """The entry with these labels set (later rows win over earlier ones)."""
    lab = e.labels
    meta = dict(e.meta)
    kw: dict[str, Any] = {}
    for k, v in values.items():
        if k == "state":
            lab = replace(lab, state=v, direction=lab.direction if v == "slip" else None)
        elif k == "direction":
            lab = replace(lab, direction=int(v))
        elif k == "press_depth_mm":
            lab = replace(lab, press_depth_mm=float(v))
        elif k in ("object", "take"):
            kw[k] = v
        else:
            meta[k] = v
    return replace(e, labels=lab, meta=meta, **kw)


def entry_frames(e: Entry) -> tuple[int | None, int | None]:
    """The frames an entry covers: (start, stop) of a range, (frame, frame + 1), or Nones."""
    s = e.source
    if s.start is not None:
        return s.start, s.stop
    if s.frame is not None:
        return s.frame, s.frame + 1
    return None, None


def apply_labels(entries: list[tuple[str, Entry]], rows: list[LabelRow]
                 ) -> tuple[list[Entry], list[LabelRow]]:
    """Entries (each with its path relative to the data folder) labelled by the rows, in row
    order; and the rows that match no entry."""
    out, unused = [], []
    hits = [0] * len(rows)
    for rel, e in entries:
        for k, row in enumerate(rows):
            if row_matches(row, rel, *entry_frames(e)):
                e = apply_values(e, row.values)
                hits[k] += 1
        out.append(e)
    unused = [r for r, n in zip(rows, hits, strict=True) if n == 0]
    return out, unused


@dataclass(frozen=True)
class Marker:
    """--marker NAME:FIELD=VALUE (or !NAME:...): the label an entry gets when a file NAME is
    (or is not) in its folder or a folder above it, up to the data folder."""

    name: str
    field: str
    value: str
    absent: bool = False

    @classmethod
    def parse(cls, text: str) -> Marker:
        absent = text.startswith("!")
        body = text[1:] if absent else text
        name, sep, rest = body.partition(":")
        field, eq, value = rest.partition("=")
        name, field, value = name.strip(), field.strip().lower(), value.strip()
        if not (sep and eq and name and field and value) or "/" in name or name in (".", ".."):
            raise VtsError(f"--marker {text!r}: expected FILE:FIELD=VALUE, e.g. "
                           "slip.txt:state=slip (a leading ! for when the file is absent)")
        _check_values({field: value}, 0, Path(name))
        return cls(name, field, value, absent)

    def applies(self, folder: Path, rel: str) -> bool:
        """Whether the marker file is present (absent for !) beside rel or above it."""
        parts = PurePosixPath(rel).parts
        dirs = [folder.joinpath(*parts[:i]) for i in range(len(parts) - 1, -1, -1)]
        # an image-folder entry is itself a folder: look inside it first
        if (folder / rel).is_dir():
            dirs.insert(0, folder / rel)
        found = any((d / self.name).is_file() for d in dirs)
        return found != self.absent


__all__ = ["LabelRow", "Marker", "apply_labels", "apply_values", "read_labels", "row_matches"]
