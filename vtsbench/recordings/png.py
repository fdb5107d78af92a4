"""Fast decoding of the PNG frames recordings are made of: 8-bit RGB rows sharing one filter.

Why not only OpenCV: `cv2.imdecode` goes through libpng, which inflates row by row with zlib,
checks every chunk's CRC and unfilters in its own loop. On 480x640 simulated frames (one core
of a 2-core AMD EPYC, 48 frames, benchmarks/build.py) `cv2.imread` takes 4.4 ms a frame with
Sub rows and 4.1 ms with Up rows. Here the chunks are parsed in Python, the zlib stream is
inflated in one call by ISA-L (`isal`: 1.4 ms against 3.1 ms for zlib's inflate; zlib when isal
is absent) and the rows are unfiltered with whole-array numpy additions (a prefix sum by
doubling, exact in uint8: 0.3 ms against 2.8 ms for numpy's own cumulative sum): 2.0 ms a
frame with Up rows and 2.9 ms with Sub rows, file reading included.

Only what that covers is decoded here: 8-bit RGB, not interlaced, every row filtered None, every
row Sub, or every row Up (what vtsbench's own writers produce; the DIGIT and GelSight Mini
frames we tested from other labs too, PIL's and OpenCV's defaults not). `decode_rgb` returns
None for any other PNG (palette, grey, alpha, 16-bit, interlaced, Avg or Paeth rows, mixed
filters) and for one it cannot parse, and the caller hands the bytes to OpenCV, so a file
decodes here exactly when and as it decodes there (tests/test_png.py).
"""

from __future__ import annotations

import zlib

import numpy as np

try:  # ISA-L's inflate: the same output as zlib's, 2.3x faster here (see above)
    from isal.isal_zlib import decompress as _inflate
    from isal.isal_zlib import decompressobj as _inflater
    from isal.isal_zlib import error as _isal_error

    _INFLATE_ERRORS: tuple[type[Exception], ...] = (zlib.error, _isal_error)
except ImportError:  # pragma: no cover - isal is a dependency; zlib keeps the reader working
    from zlib import decompress as _inflate
    from zlib import decompressobj as _inflater

    _INFLATE_ERRORS = (zlib.error,)

SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Row filter types (PNG specification, section 9.2).
NONE, SUB, UP = 0, 1, 2
#: Compressed bytes inflated to read the first rows' filters (two 640-pixel rows take about 2 kB).
_PEEK = 1 << 16
#: Critical chunks an RGB image may carry (a suggested palette is allowed and ignored).
_KNOWN_CRITICAL = {b"IHDR", b"PLTE", b"IDAT", b"IEND"}


def decode_rgb(data: bytes | bytearray | memoryview, out: np.ndarray | None = None
               ) -> np.ndarray | None:
    """RGB uint8 (H, W, 3) of a PNG file's bytes, or None when the file is not one this fast
    path decodes (then OpenCV should).

    out: a C-contiguous uint8 (H, W, 3) array to write the image into (a shard's row); used
    when the image has its shape, else a new array is returned.
    """
    mv = memoryview(data).cast("B")
    if len(mv) < 45 or mv[:8] != SIGNATURE or mv[12:16] != b"IHDR":
        return None
    head = bytes(mv[16:29])
    w, h = int.from_bytes(head[:4], "big"), int.from_bytes(head[4:8], "big")
    # bit depth 8, colour type 2 (RGB), deflate, adaptive filtering, no interlace
    if head[8:] != b"\x08\x02\x00\x00\x00" or not 0 < w < 2**31 or not 0 < h < 2**31:
        return None
    if zlib.crc32(mv[12:29]) != int.from_bytes(mv[29:33], "big"):
        return None
    idat = _idat(mv)
    if idat is None:
        return None
    stride = 3 * w + 1
    try:
        # the first rows' filters first: a file with another filter (libpng's choice per row
        # mixes them from the start) goes to OpenCV without being inflated here in full
        # (from the first 64 kB of the stream: the inflater copies the input it leaves over)
        first = _inflater().decompress(memoryview(idat)[:_PEEK], 2 * stride)
        if len(first) >= min(h, 2) * stride and not _one_filter(first[::stride][:2]):
            return None
        raw = _inflate(idat, bufsize=h * stride)
    except _INFLATE_ERRORS:
        return None
    if len(raw) != h * stride:
        return None
    rows = np.frombuffer(raw, np.uint8).reshape(h, stride)
    filters = rows[:, 0]
    pixels = rows[:, 1:]
    if out is None or out.shape != (h, w, 3) or out.dtype != np.uint8 \
            or not out.flags.c_contiguous:
        out = np.empty((h, w, 3), np.uint8)
    flat = out.reshape(h, 3 * w)
    if not filters.any():
        flat[...] = pixels
    elif (filters[1:] == UP).all() and filters[0] in (NONE, UP):  # Up on the first row is None
        _prefix_sum(pixels, flat, axis=0, step=1)
    elif (filters == SUB).all():
        _prefix_sum(pixels, flat, axis=1, step=3)
    else:
        return None
    return out


def _one_filter(types: bytes) -> bool:
    """Whether the first rows' filter types can belong to a file this reader decodes."""
    if len(types) < 2:
        return types[0] in (NONE, SUB, UP)
    return types[1] in (NONE, SUB, UP) and (
        types[0] == types[1] or (types[1] == UP and types[0] == NONE))


def _idat(mv: memoryview) -> bytes | None:
    """The image data (the IDAT chunks joined); None when the chunks do not parse or a critical
    chunk this reader does not know is present."""
    parts = []
    pos, n = 33, len(mv)
    while pos + 12 <= n:
        length = int.from_bytes(mv[pos:pos + 4], "big")
        kind = bytes(mv[pos + 4:pos + 8])
        end = pos + 12 + length
        if end > n:
            return None
        if kind == b"IDAT":
            parts.append(mv[pos + 8:pos + 8 + length])
        elif kind == b"IEND":
            return b"".join(parts) if parts else None
        elif not kind[0] & 0x20 and kind not in _KNOWN_CRITICAL:
            return None
        pos = end
    return None  # no IEND: truncated


def _prefix_sum(src: np.ndarray, out: np.ndarray, axis: int, step: int) -> None:
    """out = the running sum (mod 256) of src along `axis`, elements `step` apart: what
    unfiltering Up (axis 0, step 1) or Sub (axis 1, step 3 bytes a pixel) rows computes.

    By doubling: after the pass with offset k every element holds the sum of the 2k elements
    ending at it, so ceil(log2(n / step)) whole-array additions instead of one per row or
    column. uint8 addition wraps mod 256 and is associative, so the result is exact.
    """
    n = src.shape[axis]
    offsets = []
    k = step
    while k < n:
        offsets.append(k)
        k *= 2
    if not offsets:
        out[...] = src
        return
    tmp = np.empty_like(out)
    # the passes alternate between out and tmp, and the last one must land in out
    bufs = (out, tmp) if len(offsets) % 2 else (tmp, out)
    cur = src
    for i, k in enumerate(offsets):
        dst = bufs[i % 2]
        if axis == 0:
            np.add(cur[k:], cur[:-k], out=dst[k:])
            dst[:k] = cur[:k]
        else:
            np.add(cur[:, k:], cur[:, :-k], out=dst[:, k:])
            dst[:, :k] = cur[:, :k]
        cur = dst
