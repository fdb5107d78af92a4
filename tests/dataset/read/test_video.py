"""Reading stored videos: probe figures, frame-accurate windows from the keyframe before them,
and every hostile file as one VtsError line naming it."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

import vtsbench.dataset.read.video as reader
from tests.fixtures.video import moving_blobs
from vtsbench.dataset.build.video import encode_frames
from vtsbench.dataset.format.video import CODECS
from vtsbench.dataset.read.video import decode_frames, probe
from vtsbench.errors import VtsError

N = 24
#: One codec of each kind: lossless intra-only, H.264 and AV1 with a keyframe every 16 frames.
KINDS = ("ffv1", "h264", "av1")


@pytest.fixture(scope="module")
def clips(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The 24-frame moving_blobs clip stored with each of KINDS."""
    folder = tmp_path_factory.mktemp("clips")
    out = {}
    for name in KINDS:
        out[name] = folder / f"{name}{CODECS[name].suffix}"
        encode_frames(moving_blobs(N), out[name], name, fps=25)
    return out


def _one_line(e: pytest.ExceptionInfo[VtsError], path: Path) -> str:
    text = str(e.value)
    assert "\n" not in text and str(path) in text, text
    return text


@pytest.mark.parametrize("name", KINDS)
def test_probe_figures(name: str, clips: dict[str, Path]) -> None:
    info = probe(clips[name])
    assert (info.frames, info.fps, info.size) == (N, 25.0, (48, 64))
    assert info.codec == CODECS[name].decoder
    assert info.pix_fmt == ("bgr0" if name == "ffv1" else "yuv420p")
    assert info.keyframes == (tuple(range(N)) if name == "ffv1" else (0, 16))
    assert np.allclose(info.timestamps, np.arange(N) / 25.0, atol=1e-6)
    assert probe(clips[name], expected_frames=N) == info
    assert info.keyframe_before(15) == (15 if name == "ffv1" else 0)
    assert info.keyframe_before(17) == (17 if name == "ffv1" else 16)


@pytest.mark.parametrize("name", KINDS)
def test_windows_equal_the_sequential_decode(name: str, clips: dict[str, Path],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    path = clips[name]
    info = probe(path)
    full = decode_frames(path, 0, N, info)
    if name == "ffv1":
        assert np.array_equal(full, moving_blobs(N))
    seeks = []
    real = reader._decode_from

    def spy(path: Path, info: object, start: int, out: np.ndarray, seek: int | None) -> bool:
        seeks.append(seek)
        return real(path, info, start, out, seek)

    monkeypatch.setattr(reader, "_decode_from", spy)
    # on a keyframe (0, 16), just before and after one, inside a group, and the end
    for start, length in [(0, 8), (15, 8), (16, 8), (17, 7), (5, 1), (9, 8), (23, 1),
                          (16, 1), (0, N), (20, 4)]:
        seeks.clear()
        got = decode_frames(path, start, length, info)
        assert np.array_equal(got, full[start:start + length]), (start, length)
        key = info.keyframe_before(start)
        assert seeks == [info.pts[key] if key else None]  # from the keyframe, once
    assert decode_frames(path, 7, 0, info).shape == (0, 48, 64, 3)


def test_windows_without_a_probe_and_against_the_index(clips: dict[str, Path]) -> None:
    path = clips["h264"]
    assert np.array_equal(decode_frames(path, 18, 3, expected_frames=N),
                          decode_frames(path, 0, N)[18:21])
    with pytest.raises(VtsError, match="holds 24 frames; the index says 30") as e:
        decode_frames(path, 0, 4, expected_frames=30)
    _one_line(e, path)
    with pytest.raises(VtsError, match="the index says 23"):
        decode_frames(path, 0, 4, probe(path), expected_frames=23)


@pytest.mark.parametrize(("start", "length"), [(-1, 2), (20, 5), (24, 1), (0, 25), (3, -1)])
def test_a_window_outside_the_video_is_refused(start: int, length: int,
                                               clips: dict[str, Path]) -> None:
    path = clips["ffv1"]
    with pytest.raises(VtsError, match=r"the video has frames 0\.\.23") as e:
        decode_frames(path, start, length)
    _one_line(e, path)


@pytest.mark.parametrize("name", KINDS)
@pytest.mark.parametrize("keep", [0.02, 0.3, 0.6, 0.9, 0.99])
def test_a_truncated_file_is_one_line(name: str, keep: float, clips: dict[str, Path],
                                      tmp_path: Path) -> None:
    data = clips[name].read_bytes()
    cut = tmp_path / f"cut{clips[name].suffix}"
    cut.write_bytes(data[:int(len(data) * keep)])
    with pytest.raises(VtsError, match=r"cut short|not a video vtsbench reads") as e:
        probe(cut)
    _one_line(e, cut)


@pytest.mark.parametrize("name", KINDS)
def test_a_frame_count_other_than_the_index_says(name: str, clips: dict[str, Path]) -> None:
    with pytest.raises(VtsError, match="holds 24 frames; the index says 25") as e:
        probe(clips[name], expected_frames=25)
    _one_line(e, clips[name])


def test_a_huge_declared_frame_size_is_refused_before_decoding(tmp_path: Path) -> None:
    path = tmp_path / "wide.mkv"
    encode_frames(np.zeros((2, 16, 320, 3), np.uint8), path, "ffv1", fps=25)
    data = path.read_bytes()
    width = b"\xb0\x82\x01\x40"  # Matroska PixelWidth, 2 bytes: 320
    assert data.count(width) == 1
    huge = tmp_path / "huge.mkv"
    huge.write_bytes(data.replace(width, b"\xb0\x82\xff\xff"))  # 65535
    with pytest.raises(VtsError, match="declares 16x65535 frames; at most 4096") as e:
        probe(huge)
    _one_line(e, huge)


@pytest.mark.parametrize(("name", "content", "message"), [
    ("text.mkv", b"not a video, only text\n" * 50, "not a video vtsbench reads"),
    ("empty.mp4", b"", "not a video vtsbench reads"),
    ("zeros.mp4", bytes(4096), "not a video vtsbench reads"),
    ("json.mkv", b'{"frames": 24}', "not a video vtsbench reads")])
def test_a_non_video_file_is_one_line(name: str, content: bytes, message: str,
                                      tmp_path: Path) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(VtsError, match=message) as e:
        probe(path)
    _one_line(e, path)
    with pytest.raises(VtsError, match=message):
        decode_frames(path, 0, 1)


def test_another_codec_or_container_is_refused(tmp_path: Path) -> None:
    mpeg4 = dataclasses.replace(CODECS["ffv1"], name="mpeg4", codec="mpeg4",
                                pix_fmt="yuv420p", options={}, lossless=False)
    path = tmp_path / "m.mkv"
    encode_frames(moving_blobs(4), path, mpeg4, fps=25)
    with pytest.raises(VtsError, match="coded as 'mpeg4'; vtsbench reads Matroska or MP4") as e:
        probe(path)
    _one_line(e, path)
    avi = tmp_path / "a.avi"  # an AVI container: not a demuxer vtsbench opens
    import av

    with av.open(str(avi), "w", format="avi") as out:
        stream = out.add_stream("mjpeg", rate=25)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuvj420p"
        for f in moving_blobs(2):
            for p in stream.encode(av.VideoFrame.from_ndarray(f, format="rgb24")):
                out.mux(p)
        for p in stream.encode(None):
            out.mux(p)
    with pytest.raises(VtsError, match="not a video vtsbench reads") as e:
        probe(avi)
    _one_line(e, avi)


def test_paths_that_are_not_regular_files(tmp_path: Path) -> None:
    with pytest.raises(VtsError, match="video not found"):
        probe(tmp_path / "missing.mp4")
    with pytest.raises(VtsError, match="is a folder"):
        probe(tmp_path)
    fifo = tmp_path / "pipe.mkv"
    os.mkfifo(fifo)
    with pytest.raises(VtsError, match="not a regular file"):
        probe(fifo)
    with pytest.raises(VtsError, match="video not found"):  # never fetched as a URL
        probe("http://127.0.0.1:9/clip.mp4")
