"""Silence what the decoding libraries print by themselves while a user's file is decoded.

libpng reports a damaged PNG as "libpng error: ..." on C's stderr, FFmpeg a damaged video as
"moov atom not found", OpenCV its own warnings on std::cerr: all before vtsbench's one-line
error that says the same. `quiet_decoding` turns them off for the length of a decode. It swaps
C's `stderr` stream rather than file descriptor 2, so Python's own output (progress, warnings,
other threads) is never lost.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import threading
from collections.abc import Iterator
from typing import Any

_lock = threading.Lock()
_depth = 0
_saved: tuple[Any, int | None, int | None] | None = None  # stderr variable, its value, cv2 level
_null: int | None = None


def quiet_ffmpeg() -> None:
    """FFmpeg's own log off (read by OpenCV when its FFmpeg backend starts), unless the user
    set OPENCV_FFMPEG_LOGLEVEL."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET


def _c_stderr() -> Any | None:
    """C's `stderr` FILE* variable (glibc `stderr`, macOS `__stderrp`), or None."""
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return None
    for name in ("stderr", "__stderrp"):
        with contextlib.suppress(ValueError, AttributeError):
            return ctypes.c_void_p.in_dll(libc, name)
    return None


def _null_stream() -> int | None:
    """A C FILE* writing to the null device, opened once."""
    global _null
    if _null is None:
        try:
            libc = ctypes.CDLL(None)
            libc.fopen.restype = ctypes.c_void_p
            libc.fopen.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
            _null = libc.fopen(os.devnull.encode(), b"w") or None
        except (OSError, AttributeError):
            return None
    return _null


def _enter() -> None:
    global _depth, _saved
    with _lock:
        _depth += 1
        if _depth > 1:
            return
        import cv2

        level = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
        var, null = _c_stderr(), _null_stream()
        old = None
        if var is not None and null is not None:
            old = var.value
            var.value = null
        _saved = (var, old, level)


def _exit() -> None:
    global _depth, _saved
    with _lock:
        _depth -= 1
        if _depth or _saved is None:
            return
        import cv2

        var, old, level = _saved
        if var is not None and old is not None:
            var.value = old
        cv2.utils.logging.setLogLevel(level)
        _saved = None


@contextlib.contextmanager
def quiet_decoding() -> Iterator[None]:
    """Within the block (any thread), C libraries' and OpenCV's own messages are dropped; the
    first block to enter turns them off and the last to leave turns them back on."""
    quiet_ffmpeg()
    _enter()
    try:
        yield
    finally:
        _exit()
