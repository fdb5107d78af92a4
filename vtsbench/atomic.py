"""Atomic file and folder writes: output appears complete or not at all."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write data to path through a temporary file in the same folder and a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


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
        if out.exists():
            old = out.with_name(f".{out.name}.old-{os.getpid()}-{os.urandom(4).hex()}")
            os.replace(out, old)
            os.replace(stage, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
