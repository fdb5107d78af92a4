"""Encoding RGB frames to a video file: each codec's round trip (ffv1 bit-exact, the lossy
ones above a PSNR floor), timestamps, input checks, and the atomic write."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import vtsbench.dataset.build.video as video
from tests.fixtures.video import moving_blobs, psnr
from vtsbench.dataset.build.video import encode_frames, unknown_options
from vtsbench.dataset.format.video import CODECS
from vtsbench.dataset.read.video import decode_frames, probe
from vtsbench.errors import VtsError

#: PSNR floors (dB) on the 24 smooth 48x64 frames of moving_blobs; measured 39.7, 37.1, 39.1
#: and 35.2 with PyAV 18.1 (x264, SVT-AV1 4.1).
FLOORS = {"h264": 36.0, "h264-crf28": 34.0, "av1": 36.0, "av1-crf45": 32.0}


def _left(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("name", sorted(CODECS))
def test_round_trip(name: str, tmp_path: Path) -> None:
    codec = CODECS[name]
    frames = moving_blobs()
    path = tmp_path / f"clip{codec.suffix}"
    size = encode_frames(frames, path, name, fps=25)
    assert size == path.stat().st_size > 0
    assert _left(tmp_path) == [path.name]  # no temporary left beside it
    back = decode_frames(path, 0, len(frames))
    assert back.shape == frames.shape and back.dtype == np.uint8
    if codec.lossless:
        assert np.array_equal(back, frames)
    else:
        assert psnr(back, frames) > FLOORS[name]
        assert not np.array_equal(back, frames)


def test_ffv1_is_bit_exact_on_noise_too(tmp_path: Path) -> None:
    frames = np.random.default_rng(3).integers(0, 256, (5, 30, 46, 3), dtype=np.uint8)
    encode_frames(frames, tmp_path / "n.mkv", "ffv1", fps=30)  # odd sizes: no chroma halving
    assert np.array_equal(decode_frames(tmp_path / "n.mkv", 0, 5), frames)


@pytest.mark.parametrize("name", ["ffv1", "h264", "av1"])
def test_timestamps_are_kept(name: str, tmp_path: Path) -> None:
    frames = moving_blobs(12)
    t = 10.0 + np.cumsum(np.r_[0, np.random.default_rng(0).uniform(0.03, 0.05, 11)])
    path = tmp_path / f"t{CODECS[name].suffix}"
    encode_frames(frames, path, name, fps=25, timestamps=t)
    info = probe(path)
    # seconds from the first frame; Matroska keeps milliseconds, MP4 the 90 kHz clock
    assert np.abs(info.timestamps - (t - t[0])).max() <= 0.0006
    assert np.array_equal(decode_frames(path, 3, 5, info), decode_frames(path, 0, 12)[3:8])


@pytest.mark.parametrize(("frames", "name", "fps", "stamps", "message"), [
    (np.zeros((4, 48, 64, 3), np.float32), "ffv1.mkv", 25, None, "uint8 RGB"),
    (np.zeros((4, 48, 64), np.uint8), "ffv1.mkv", 25, None, "uint8 RGB"),
    (np.zeros((0, 48, 64, 3), np.uint8), "ffv1.mkv", 25, None, "1 to"),
    (np.zeros((4, 5000, 64, 3), np.uint8), "ffv1.mkv", 25, None, "at most 4096"),
    (np.zeros((4, 47, 64, 3), np.uint8), "h264.mp4", 25, None, "must be even"),
    (np.zeros((4, 48, 64, 3), np.uint8), "h264.mkv", 25, None, "stored in a .mp4 file"),
    (np.zeros((4, 48, 64, 3), np.uint8), "ffv1.mp4", 25, None, "stored in a .mkv file"),
    (np.zeros((4, 48, 64, 3), np.uint8), "ffv1.mkv", 0, None, "fps must be above 0"),
    (np.zeros((4, 48, 64, 3), np.uint8), "ffv1.mkv", float("nan"), None, "fps must be"),
    (np.zeros((4, 48, 64, 3), np.uint8), "ffv1.mkv", 25, [0, 1, 2], "4 finite seconds"),
    (np.zeros((4, 48, 64, 3), np.uint8), "ffv1.mkv", 25, [0, 1, 1, 2], "must increase"),
    (np.zeros((4, 48, 64, 3), np.uint8), "ffv1.mkv", 25, [0, 1, np.nan, 2], "finite"),
])
def test_bad_input_is_one_line_and_writes_nothing(frames: np.ndarray, name: str, fps: float,
                                                  stamps: list | None, message: str,
                                                  tmp_path: Path) -> None:
    codec, _, suffix = name.partition(".")
    with pytest.raises(VtsError, match=message) as e:
        encode_frames(frames, tmp_path / f"out.{suffix}", codec, fps, timestamps=stamps)
    assert "\n" not in str(e.value) and f"out.{suffix}" in str(e.value)
    assert _left(tmp_path) == []


@pytest.mark.parametrize("name", ["ffv1", "h264", "av1"])
def test_a_failure_midway_leaves_no_file_and_keeps_the_old_one(
        name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    codec = CODECS[name]
    path = tmp_path / f"clip{codec.suffix}"
    frames = moving_blobs()
    real = video._video_frame
    calls = []

    def failing(*args: object) -> object:
        calls.append(1)
        if len(calls) == 10:
            raise RuntimeError("encoder failed at frame 10")
        return real(*args)

    monkeypatch.setattr(video, "_video_frame", failing)
    with pytest.raises(RuntimeError, match="frame 10"):
        encode_frames(frames, path, name, fps=25)
    assert _left(tmp_path) == []  # neither the video nor its temporary

    monkeypatch.setattr(video, "_video_frame", real)
    encode_frames(frames[:6], path, name, fps=25)
    before = path.read_bytes()
    calls.clear()
    monkeypatch.setattr(video, "_video_frame", failing)
    with pytest.raises(RuntimeError):
        encode_frames(frames, path, name, fps=25)
    assert _left(tmp_path) == [path.name] and path.read_bytes() == before
    assert probe(path).frames == 6


@pytest.mark.parametrize(("change", "message"), [
    ({"pix_fmt": "rgb48le"}, "cannot encode with h264-bad"),
    ({"options": {"crf": "18", "crff": "1"}}, "libx264 has no option crff"),
    ({"codec": "libnosuch"}, "no encoder 'libnosuch'")])
def test_encoder_errors_are_one_line(change: dict, message: str, tmp_path: Path) -> None:
    import dataclasses

    bad = dataclasses.replace(CODECS["h264"], name="h264-bad", **change)
    with pytest.raises(VtsError, match=message) as e:
        encode_frames(moving_blobs(4), tmp_path / "b.mp4", bad, fps=25)
    assert "\n" not in str(e.value) and _left(tmp_path) == []


@pytest.mark.parametrize("name", sorted(CODECS))
def test_every_option_is_one_its_encoder_has(name: str) -> None:
    assert unknown_options(CODECS[name]) == []  # FFmpeg ignores an unknown option silently
