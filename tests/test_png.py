"""The fast PNG reader (vtsbench.recordings.png): exactly OpenCV's pixels where it decodes, and
None (OpenCV's turn) for every PNG it does not cover or cannot parse."""

from __future__ import annotations

import itertools
import struct
import zlib

import cv2
import numpy as np
import pytest

from vtsbench.errors import VtsError
from vtsbench.recordings import png
from vtsbench.recordings.media import read_frames, read_image, write_png


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _png(img: np.ndarray, filters: list[int], *, colour: int = 2, depth: int = 8,
         interlace: int = 0, idat_parts: int = 1, extra: list[bytes] = ()) -> bytes:
    """A PNG of an RGB image with the given filter type per row (0 None, 1 Sub, 2 Up)."""
    h, w = img.shape[:2]
    rows = []
    prev = np.zeros(w * 3, np.uint8)
    for y in range(h):
        cur = img[y].reshape(-1)
        f = filters[y]
        if f == 0:
            enc = cur
        elif f == 1:
            left = np.concatenate([np.zeros(3, np.uint8), cur[:-3]])
            enc = cur - left
        elif f == 2:
            enc = cur - prev
        else:
            raise ValueError(f)
        rows.append(bytes([f]) + enc.astype(np.uint8).tobytes())
        prev = cur
    data = zlib.compress(b"".join(rows), 6)
    cut = np.linspace(0, len(data), idat_parts + 1).astype(int)
    ihdr = struct.pack(">IIBBBBB", w, h, depth, colour, 0, 0, interlace)
    return (png.SIGNATURE + _chunk(b"IHDR", ihdr) + b"".join(extra)
            + b"".join(_chunk(b"IDAT", data[a:b]) for a, b in itertools.pairwise(cut))
            + _chunk(b"IEND", b""))


def _opencv(data: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR_RGB)


def _image(h: int, w: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    smooth = np.linspace(0, 255, h * w * 3).reshape(h, w, 3)
    return (smooth + rng.normal(0, 20, (h, w, 3))).clip(0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (2, 2), (5, 3), (33, 17), (48, 64)])
@pytest.mark.parametrize("flt", ["none", "sub", "up"])
def test_one_filter_decodes_as_opencv(shape: tuple[int, int], flt: str) -> None:
    img = _image(*shape)
    code = {"none": 0, "sub": 1, "up": 2}[flt]
    data = _png(img, [code] * shape[0], idat_parts=3 if shape[0] > 2 else 1)
    got = png.decode_rgb(data)
    assert got is not None and got.dtype == np.uint8
    np.testing.assert_array_equal(got, img)
    np.testing.assert_array_equal(got, _opencv(data))


def test_up_after_a_none_first_row() -> None:
    img = _image(9, 11)
    data = _png(img, [0] + [2] * 8)
    np.testing.assert_array_equal(png.decode_rgb(data), img)


@pytest.mark.parametrize("flag", ["IMWRITE_PNG_FILTER_SUB", "IMWRITE_PNG_FILTER_UP",
                                  "IMWRITE_PNG_FILTER_NONE"])
def test_opencv_written_files(flag: str) -> None:
    img = _image(40, 52, seed=3)
    ok, buf = cv2.imencode(".png", img[..., ::-1], [cv2.IMWRITE_PNG_FILTER, getattr(cv2, flag)])
    assert ok
    np.testing.assert_array_equal(png.decode_rgb(buf.tobytes()), img)


@pytest.mark.parametrize("flag", ["IMWRITE_PNG_FILTER_PAETH", "IMWRITE_PNG_FILTER_AVG"])
def test_other_filters_go_to_opencv(tmp_path, flag: str) -> None:
    img = _image(40, 52, seed=4)
    ok, buf = cv2.imencode(".png", img[..., ::-1], [cv2.IMWRITE_PNG_FILTER, getattr(cv2, flag)])
    assert ok
    assert png.decode_rgb(buf.tobytes()) is None
    path = tmp_path / "f.png"
    path.write_bytes(buf.tobytes())
    np.testing.assert_array_equal(read_image(path), img)


def test_mixed_filters_go_to_opencv() -> None:
    img = _image(6, 5)
    data = _png(img, [1, 2, 1, 2, 0, 1])
    assert png.decode_rgb(data) is None
    np.testing.assert_array_equal(_opencv(data), img)


@pytest.mark.parametrize("kind", ["grey", "rgba", "16bit"])
def test_other_pixel_formats_go_to_opencv(tmp_path, kind: str) -> None:
    img = _image(12, 10, seed=5)
    if kind == "grey":
        arr = img[..., 0]
    elif kind == "rgba":
        arr = np.dstack([img[..., ::-1], np.full(img.shape[:2], 200, np.uint8)])
    else:
        arr = img[..., ::-1].astype(np.uint16) * 257
    ok, buf = cv2.imencode(".png", arr)
    assert ok
    assert png.decode_rgb(buf.tobytes()) is None
    path = tmp_path / "f.png"
    path.write_bytes(buf.tobytes())
    np.testing.assert_array_equal(read_image(path), _opencv(buf.tobytes()))


def test_interlaced_goes_to_opencv() -> None:
    img = _image(4, 4)
    assert png.decode_rgb(_png(img, [0] * 4, interlace=1)) is None


def test_ancillary_and_palette_chunks_are_skipped() -> None:
    img = _image(8, 9)
    extra = [_chunk(b"gAMA", struct.pack(">I", 45455)), _chunk(b"PLTE", bytes(range(6))),
             _chunk(b"tEXt", b"Comment\x00made here")]
    data = _png(img, [2] * 8, extra=extra)
    np.testing.assert_array_equal(png.decode_rgb(data), img)


def test_unknown_critical_chunk_goes_to_opencv() -> None:
    img = _image(4, 4)
    assert png.decode_rgb(_png(img, [2] * 4, extra=[_chunk(b"ABCD", b"x")])) is None


@pytest.mark.parametrize("damage", ["truncated", "no_iend", "ihdr_crc", "idat_byte", "short_data",
                                    "signature", "empty"])
def test_damaged_files_are_not_decoded_here(tmp_path, damage: str) -> None:
    img = _image(16, 16)
    data = bytearray(_png(img, [2] * 16))
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "no_iend":
        data = data[:-12]
    elif damage == "ihdr_crc":
        data[20] ^= 0x01  # the height: IHDR's CRC no longer matches
    elif damage == "idat_byte":
        data[60] ^= 0xFF
    elif damage == "short_data":
        rows = b"".join(bytes([2]) + bytes(48) for _ in range(15))  # a row short
        ihdr = struct.pack(">IIBBBBB", 16, 16, 8, 2, 0, 0, 0)
        data = bytearray(png.SIGNATURE + _chunk(b"IHDR", ihdr)
                         + _chunk(b"IDAT", zlib.compress(rows)) + _chunk(b"IEND", b""))
    elif damage == "signature":
        data[1] = ord("Q")
    else:
        data = bytearray()
    got = png.decode_rgb(bytes(data))
    if damage == "idat_byte" and got is not None:  # a flip the checks let through decodes as
        np.testing.assert_array_equal(got, _opencv(bytes(data)))  # OpenCV decodes it
    else:
        assert got is None
    path = tmp_path / "bad.png"
    path.write_bytes(bytes(data))
    ref = _opencv(bytes(data)) if data else None
    if ref is None:
        with pytest.raises(VtsError, match="cannot decode image"):
            read_image(path)
    else:
        np.testing.assert_array_equal(read_image(path), ref)


def test_decodes_into_the_given_array() -> None:
    img = _image(10, 12)
    data = _png(img, [2] * 10)
    out = np.zeros((10, 12, 3), np.uint8)
    got = png.decode_rgb(data, out)
    assert got is out
    np.testing.assert_array_equal(out, img)
    other = np.zeros((10, 13, 3), np.uint8)  # another shape: a new array
    got = png.decode_rgb(data, other)
    assert got is not other and not other.any()
    np.testing.assert_array_equal(got, img)


def test_zlib_inflate_gives_the_same(monkeypatch) -> None:
    img = _image(20, 30)
    data = _png(img, [1] * 20)
    fast = png.decode_rgb(data)
    monkeypatch.setattr(png, "_inflate", zlib.decompress)
    np.testing.assert_array_equal(png.decode_rgb(data), fast)


def test_write_png_is_on_the_fast_path(tmp_path) -> None:
    img = _image(30, 40, seed=7)
    path = tmp_path / "f.png"
    write_png(path, img)
    np.testing.assert_array_equal(png.decode_rgb(path.read_bytes()), img)
    np.testing.assert_array_equal(_opencv(path.read_bytes()), img)


def test_folder_frames_decode_into_the_shard_rows(tmp_path) -> None:
    imgs = [_image(12, 16, seed=s) for s in range(4)]
    for t, img in enumerate(imgs):
        write_png(tmp_path / f"{t:03d}.png", img)
    out = np.zeros((3, 12, 16, 3), np.uint8)
    got = read_frames(tmp_path, 1, 4, out=out)
    assert got is out
    np.testing.assert_array_equal(out, np.stack(imgs[1:]))


def test_missing_and_folder_paths(tmp_path) -> None:
    with pytest.raises(VtsError, match="file not found"):
        read_image(tmp_path / "nope.png")
    with pytest.raises(VtsError, match="folder"):
        read_image(tmp_path)
