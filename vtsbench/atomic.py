"""Atomic file and folder writes: output appears complete or not at all.

The one way the package writes its outputs (tests/project/test_atomic_outputs.py fails on a
module that writes a file by other means): bytes and text through a temporary name and a rename,
a path to hand to a library that writes by name (`replacing`), and staged folders.
"""

from __future__ import annotations

import contextlib
import errno
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


def _process_umask() -> int:
    """This process's umask, read without changing it where Linux shows it (/proc), else by
    setting and restoring it (at import, before any writer thread)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: Permissions of an ordinary new file here: what `open` gives (0o666 less the umask).
ORDINARY_MODE = 0o666 & ~_process_umask()


def _ordinary_permissions(tmp: Path) -> None:
    """Widen a finished temporary file to ORDINARY_MODE where its library made it private:
    safetensors (0.4+) writes 0o600, which leaves a lab's shared checkpoints unreadable to the
    rest of its group. A mode that is not narrower (an executable, a wider one) is kept."""
    try:
        mode = tmp.stat().st_mode & 0o777
    except FileNotFoundError:
        return  # the block wrote nothing: the rename below says so
    if mode != ORDINARY_MODE and mode & ~ORDINARY_MODE == 0:
        os.chmod(tmp, ORDINARY_MODE)


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
        _ordinary_permissions(tmp)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise write_error(e, path, tmp) from e
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_error(err: OSError, path: Path, tmp: Path) -> OSError:
    """The error of a failed write naming its destination: a full disk (ENOSPC, EFBIG) names no
    file, and a failed open or rename names the hidden temporary one. Others pass unchanged."""
    if err.filename is not None and os.fspath(err.filename) != os.fspath(tmp):
        return err  # about another file (an input read inside the block): already named
    if path.is_dir():
        return IsADirectoryError(errno.EISDIR, "is a folder, not a file name", str(path))
    return OSError(err.errno, f"cannot write ({err.strerror or err})", str(path))


#: renameat2's flag that swaps two existing paths, and the "current folder" directory fd.
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def exchange(a: Path, b: Path) -> bool:
    """Swap two existing paths in one step (Linux renameat2 with RENAME_EXCHANGE); False where
    the system or the filesystem cannot (another OS, an old libc, EINVAL/ENOSYS)."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def rename(src: Path, dst: Path) -> None:
    """Rename a file or folder in one step (os.replace): for moves inside an output's own
    hidden names, e.g. a build's state parked beside its stage."""
    os.replace(src, dst)


def old_copy(out: Path) -> Path:
    """A unique hidden name beside `out` for its previous copy while it is replaced:
    `.OUT.old-PID-HEX` (recover_dir reads the process id)."""
    return out.with_name(f".{out.name}.old-{os.getpid()}-{secrets.token_hex(6)}")


def replace_dir(stage: Path, out: Path) -> None:
    """Put a finished folder at `out`, so that `out` is at every instant the previous complete
    copy or the new complete one, never missing nor half old, half new.

    An existing `out` is swapped with the stage in one step (renameat2 RENAME_EXCHANGE); the
    previous copy, then under the stage's name, is renamed to `.OUT.old-*` and deleted. Where
    the swap is not available it takes two renames (`out` to `.OUT.old-*`, the stage to `out`):
    a kill between them leaves `out` missing for a moment, and recover_dir, run by the next
    write of `out`, puts the previous copy back (an error between them does it at once).
    """
    if not (out.exists() or out.is_symlink()):
        os.replace(stage, out)
        return
    old = old_copy(out)
    if exchange(stage, out):
        os.replace(stage, old)
    else:
        os.replace(out, old)
        try:
            os.replace(stage, out)
        except BaseException:
            with contextlib.suppress(OSError):
                os.replace(old, out)
            raise
    shutil.rmtree(old, ignore_errors=True)


def _running(pid: int) -> bool:
    """True when another live process has this id (POSIX; False elsewhere and for this one)."""
    if os.name != "posix" or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def recover_dir(out: Path, marker: str | None = None) -> None:
    """Finish what a replace_dir cut short left beside `out`: with `out` missing, the previous
    copy in `.OUT.old-*` (holding `marker`, so complete) is put back; every other old copy is
    deleted. Copies of a process still running are left to it."""
    import glob
    import re

    if not out.parent.is_dir():
        return
    for old in sorted(out.parent.glob(f".{glob.escape(out.name)}.old-*")):
        m = re.fullmatch(r"\.(?s:.*)\.old-(\d+)-[0-9a-f]+", old.name)
        if m is None or _running(int(m.group(1))) or old.is_symlink() or not old.is_dir():
            continue
        if (not (out.exists() or out.is_symlink())
                and (marker is None or (old / marker).is_file())):
            os.replace(old, out)
        else:
            shutil.rmtree(old, ignore_errors=True)


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
    recover_dir(out, marker)
    check_replaceable(out, overwrite, marker)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        yield stage
        replace_dir(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
