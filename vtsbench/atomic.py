"""Atomic file and folder writes: output appears complete or not at all.

The one way the package writes its outputs (tests/test_atomic_outputs.py fails on a module that
writes a file by other means): bytes and text through a temporary name and a rename, a path to
hand to a library that writes by name (`replacing`), and staged folders.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

#: Suffix of the temporary files; a build removes the ones a killed process left behind.
TMP_SUFFIX = ".tmp"


def temporary_name(path: Path) -> Path:
    """A unique hidden name beside path for a file being written (ends in TMP_SUFFIX)."""
    return path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}{TMP_SUFFIX}")


def write_bytes_atomic(path: str | os.PathLike, data: bytes | Sequence[bytes]) -> None:
    """Write a file (bytes, or parts written one after the other) through a unique temporary
    name in its folder and a rename.

    Unlike mkstemp the file gets the ordinary permissions (umask), so a shared dataset is
    readable by others; a temporary left by a killed process ends in TMP_SUFFIX.
    """
    with replacing(path) as tmp, open(tmp, "xb") as fh:
        if isinstance(data, (bytes, bytearray, memoryview)):
            fh.write(data)
        else:
            fh.writelines(data)


@contextlib.contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside `path` for a library that writes a file by name (safetensors,
    csv, zipfile): renamed to `path` when the block succeeds, removed when it fails."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def replace_dir(stage: Path, out: Path) -> None:
    """Rename a finished folder to `out`; an existing `out` is swapped out first and then
    deleted, so `out` is never missing a moment nor half old, half new."""
    if out.exists():
        old = out.with_name(f".{out.name}.old-{os.getpid()}-{secrets.token_hex(6)}")
        os.replace(out, old)
        os.replace(stage, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(stage, out)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 text atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


def check_replaceable(out: Path, overwrite: bool, marker: str | None) -> None:
    """Refuse an existing `out` unless overwrite is set and it is an empty folder or a folder
    holding `marker` (what vtsbench writes there): a one-line VtsError otherwise."""
    from .errors import VtsError

    if not (out.exists() or out.is_symlink()):
        return
    if not overwrite:
        raise VtsError("already exists (use --overwrite to replace it)", out)
    if out.is_symlink() or not out.is_dir():
        raise VtsError("exists and is not a folder; --overwrite replaces only folders "
                       "vtsbench wrote", out)
    if any(out.iterdir()) and (marker is None or not (out / marker).is_file()):
        raise VtsError(f"exists and was not written by vtsbench (no {marker or 'marker'}); "
                       "--overwrite replaces only folders vtsbench wrote: remove it "
                       "yourself or choose another name", out)


@contextlib.contextmanager
def staged_dir(out: str | os.PathLike, overwrite: bool = False,
               marker: str | None = None) -> Iterator[Path]:
    """Yield a hidden staging folder beside `out`, renamed to `out` only when the block succeeds.

    An existing `out` is refused unless overwrite is set, and even then unless it is an empty
    folder or holds `marker` (the file vtsbench writes there, e.g. recordings.json): a folder
    vtsbench did not write is never replaced. A failed block removes the staging folder, so a
    half-written output never takes the final name.
    """
    out = Path(out)
    check_replaceable(out, overwrite, marker)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        yield stage
        replace_dir(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
