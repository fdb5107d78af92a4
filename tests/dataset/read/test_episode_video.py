"""Episodes whose RGB is stored as video, read through ds.episodes: ffv1 gives the frames bit
for bit, h264 the frames its codec gives (above its PSNR floor); windows of every kind equal
those of the same takes stored in Zarr, to torch too; runs of frames decoded once; a missing or
damaged video is one line naming it, and verify finds it in one line."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from tests.fixtures.episode_video import LENGTHS, video_takes, write_video_takes
from tests.fixtures.video import psnr
from vtsbench.dataset.format.layout import VIDEOS_DIR
from vtsbench.dataset.read.episode_video import decode_runs
from vtsbench.dataset.read.video import decode_frames, probe
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError

#: PSNR floor (dB) of h264 (crf 18) on these smooth 48x64 frames (as tests/dataset/build/
#: test_video_encode.py: 39.7 measured on moving_blobs; 41.9 on the real takes, docs/benchmarks.md).
H264_FLOOR = 36.0


@pytest.fixture(scope="module")
def stores(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same takes (rgb, depth, contact) stored in Zarr, as ffv1 and as h264."""
    root = tmp_path_factory.mktemp("stores")
    eps = video_takes(depth=True)
    return {name: write_video_takes(root / str(name), eps, name)
            for name in (None, "ffv1", "h264")}


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert np.array_equal(a[k], b[k]), k
        else:
            assert a[k] == b[k], k


def test_ffv1_episodes_are_the_frames_bit_for_bit(stores: dict[str, Path]) -> None:
    ds, zarr = vtsbench.load(stores["ffv1"]), vtsbench.load(stores[None])
    for i, take in enumerate(video_takes(depth=True)):
        ep = ds.episodes[i]
        assert np.array_equal(ep["rgb"], take["frames"])
        _same(ep, zarr.episodes[i])
    assert np.array_equal(ds.episodes.episode(2, ["rgb"])["rgb"], video_takes()[2]["frames"])


@pytest.mark.parametrize("how", [
    {"length": 8, "stride": 8}, {"length": 16, "stride": 1}, {"length": 8, "pad": "edge"},
    {"delta_timestamps": [-0.2, -0.08, -0.04, 0.0], "pad": "edge"},
    {"delta_timestamps": [-0.04, 0.0, 0.04], "stride": 3},
])
def test_windows_equal_those_of_zarr(stores: dict[str, Path], how: dict) -> None:
    arrays = ("rgb", "depth", "contact")
    win = vtsbench.load(stores["ffv1"]).episodes.windows(arrays=arrays, **how)
    ref = vtsbench.load(stores[None]).episodes.windows(arrays=arrays, **how)
    assert len(win) == len(ref) > 0
    order = np.random.default_rng(0).permutation(len(win))
    _same(win.read(order), ref.read(order))  # any order, frames shared between windows
    _same(win[len(win) - 1], ref[len(ref) - 1])
    assert all(np.array_equal(a["rgb"], b["rgb"]) for a, b in zip(win, ref, strict=True))


def test_h264_gives_the_codecs_frames_above_its_floor(stores: dict[str, Path]) -> None:
    ds = vtsbench.load(stores["h264"])
    win = ds.episodes.windows(length=8, stride=5)
    batch = win.read(range(len(win)))
    takes = video_takes()
    for k in range(len(win)):
        e, f = int(win.episode_index[k]), win.frame_index[k]
        source = takes[e]["frames"][f]
        assert psnr(batch["rgb"][k], source) > H264_FLOOR
        video = stores["h264"] / VIDEOS_DIR / f"episode-{e:06d}.mp4"
        assert np.array_equal(batch["rgb"][k], decode_frames(video, int(f[0]), 8))
    assert np.array_equal(ds.episodes[1]["depth"], vtsbench.load(stores[None]).episodes[1]["depth"])


def test_windows_to_torch_and_pickled(stores: dict[str, Path]) -> None:
    win = vtsbench.load(stores["ffv1"]).episodes.windows(length=8, stride=8)
    ref = vtsbench.load(stores[None]).episodes.windows(length=8, stride=8)
    again = pickle.loads(pickle.dumps(win))  # what a DataLoader worker gets
    _same(again.read([2, 0]), ref.read([2, 0]))
    pytest.importorskip("torch")
    a, b = win.to_torch(), ref.to_torch()
    for i in range(len(win)):
        assert np.array_equal(a[i][0].numpy(), b[i][0].numpy())


def test_runs_decode_once_and_join_within_a_keyframe_interval(stores: dict[str, Path]) -> None:
    vi = probe(stores["h264"] / VIDEOS_DIR / "episode-000002.mp4")
    assert vi.keyframes == (0, 16)
    frames = np.array([0, 1, 2, 5, 6, 17, 18, 23])
    # 17 starts past keyframe 16: a seek; 23 decodes on from 19 (a seek would start at 16)
    assert decode_runs(frames, vi, 1000) == [(0, 7), (17, 24)]
    assert decode_runs(frames, vi, 4) == [(0, 4), (4, 7), (17, 21), (21, 24)]
    ffv1 = probe(stores["ffv1"] / VIDEOS_DIR / "episode-000002.mkv")
    assert decode_runs(frames, ffv1, 1000) == [(0, 3), (5, 7), (17, 19), (23, 24)]


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def test_a_missing_or_damaged_video_is_one_line_naming_it(stores: dict[str, Path],
                                                          tmp_path: Path) -> None:
    out = _copy(stores["ffv1"], tmp_path / "ds")
    (out / VIDEOS_DIR / "episode-000001.mkv").unlink()
    data = (out / VIDEOS_DIR / "episode-000002.mkv").read_bytes()
    (out / VIDEOS_DIR / "episode-000002.mkv").write_bytes(data[:len(data) // 2])
    ds = vtsbench.load(out)
    assert np.array_equal(ds.episodes[0]["rgb"], video_takes()[0]["frames"])  # the others read
    for i, name in ((1, "episode-000001.mkv"), (2, "episode-000002.mkv")):
        with pytest.raises(VtsError, match=name) as e:
            ds.episodes[i]
        assert "\n" not in str(e.value)
    win = ds.episodes.windows(length=8, stride=8)
    with pytest.raises(VtsError, match=r"episode-000002\.mkv: cut short"):
        win.read(np.flatnonzero(win.episode_index == 2))


def test_verify_finds_a_truncated_or_missing_video_in_one_line(stores: dict[str, Path],
                                                               tmp_path: Path) -> None:
    for codec, ext in (("ffv1", "mkv"), ("h264", "mp4")):
        out = _copy(stores[codec], tmp_path / codec)
        cut = out / VIDEOS_DIR / f"episode-000000.{ext}"
        cut.write_bytes(cut.read_bytes()[:-200])
        (out / VIDEOS_DIR / f"episode-000002.{ext}").unlink()
        problems = verify(out).problems
        assert len(problems) == 2, problems
        assert problems[0].startswith(f"{VIDEOS_DIR}/episode-000002.{ext}: missing")
        assert problems[1].startswith(f"{VIDEOS_DIR}/episode-000000.{ext}: ")
        assert "cut short" in problems[1] or "damaged" in problems[1], problems


def test_verify_finds_a_video_of_other_frames(stores: dict[str, Path], tmp_path: Path) -> None:
    out = _copy(stores["ffv1"], tmp_path / "ds")
    videos = out / VIDEOS_DIR
    shutil.copyfile(videos / "episode-000000.mkv", videos / "episode-000001.mkv")
    problems = verify(out).problems
    assert any(p.startswith(f"{VIDEOS_DIR}/episode-000001.mkv: holds 18 frames; the index "
                            f"says {LENGTHS[1]}") for p in problems), problems
    assert len(problems) == 1  # that line alone (not also its sha256 mismatch)
