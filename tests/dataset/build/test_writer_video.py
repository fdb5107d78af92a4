"""vtsbench.create(..., video=...): each saved episode's RGB as one video file, depth and contact
in Zarr, the codec in info.json; the same bytes each time; a failure at every write and rename
(and a kill mid-encode) leaves no video that looks complete, and resume gives the dataset
written in one go; every bad choice refused in one line."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

import vtsbench
from tests.fixtures.datasets import tree_bytes
from tests.fixtures.episode_video import FPS, SHARD_MB, video_takes, write_video_takes
from tests.fixtures.faults import Crash, FailingOs, count_renames
from vtsbench import atomic
from vtsbench.dataset.build.staging import partial_path
from vtsbench.dataset.format.info import info_schema_errors
from vtsbench.dataset.format.layout import VIDEOS_DIR
from vtsbench.dataset.format.video import CODECS
from vtsbench.dataset.read.video import probe
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError


@pytest.fixture(scope="module")
def ffv1_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_video_takes(tmp_path_factory.mktemp("ffv1") / "ds", video_takes(depth=True),
                             "ffv1", name="ds")


def test_a_video_per_episode_depth_in_zarr_codec_in_info(ffv1_ds: Path) -> None:
    videos = sorted(p.name for p in (ffv1_ds / VIDEOS_DIR).iterdir())
    assert videos == ["episode-000000.mkv", "episode-000001.mkv", "episode-000002.mkv"]
    for name, n in zip(videos, (18, 11, 24), strict=True):
        vi = probe(ffv1_ds / VIDEOS_DIR / name)
        assert (vi.frames, vi.size, vi.codec, round(vi.fps)) == (n, (48, 64), "ffv1", FPS)
    doc = json.loads((ffv1_ds / "meta" / "info.json").read_text())
    assert doc["episodes"]["video"] == CODECS["ffv1"].to_dict()  # beside the counts
    assert "video" not in doc["build"]
    assert info_schema_errors(doc) == []
    assert doc["shapes"]["episodes"]["rgb"] == [53, 48, 64, 3]  # the count and size stay
    assert all(f"{VIDEOS_DIR}/{v}" in doc["files"] for v in videos)  # checksummed as data
    group = ffv1_ds / "data" / "episodes.zarr"
    assert (group / "rgb" / "zarr.json").is_file() and not (group / "rgb" / "c").exists()
    assert (group / "depth" / "c").is_dir() and (group / "contact" / "c").is_dir()
    report = verify(ffv1_ds)
    assert report.ok, report.problems


def test_rgb_only_keeps_the_metadata_alone(tmp_path: Path) -> None:
    out = write_video_takes(tmp_path / "ds", video_takes()[:1], "ffv1")
    group = out / "data" / "episodes.zarr"
    assert sorted(p.relative_to(group).as_posix() for p in group.rglob("*") if p.is_file()) \
        == ["rgb/zarr.json", "zarr.json"]
    assert verify(out).ok


def test_the_same_takes_give_the_same_bytes(ffv1_ds: Path, tmp_path: Path) -> None:
    again = write_video_takes(tmp_path / "ds", video_takes(depth=True), "ffv1", name="ds")
    assert tree_bytes(again) == tree_bytes(ffv1_ds)


def test_a_failure_at_every_write_and_rename_then_resume(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # two takes hold every kind of kill point (a take's shards, its video, its metadata, a
    # shard the next take goes on writing, the finish); a third would repeat them
    eps = video_takes(depth=True)[:2]
    whole = tmp_path / "count" / "ds"
    steps = count_renames(monkeypatch, lambda: write_video_takes(whole, eps, "ffv1", name="ds"))
    assert steps > 10
    ref = tree_bytes(whole)
    for at in range(1, steps + 1):
        out = tmp_path / f"run{at}" / "ds"
        monkeypatch.setattr(atomic, "os", FailingOs(at))
        with pytest.raises(Crash):
            write_video_takes(out, eps, "ffv1", name="ds")
        monkeypatch.setattr(atomic, "os", os)
        assert not out.exists(), f"step {at}: OUT exists after a failed write"
        for p in (partial_path(out) / VIDEOS_DIR).glob("episode-*"):
            probe(p)  # a video under its name is whole
        again = write_video_takes(out, eps, "ffv1", name="ds", resume=True)
        assert tree_bytes(again) == ref, f"step {at}: other bytes"


def test_a_kill_mid_encode_leaves_a_hidden_file_that_resume_deletes(
        ffv1_ds: Path, tmp_path: Path) -> None:
    eps = video_takes(depth=True)
    out = tmp_path / "ds"
    w = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini", name="ds",
                        arrays=("rgb", "depth", "contact"), video="ffv1")
    w.add_episode(**eps[0])
    for i in range(5):
        w.add_frame(eps[1]["frames"][i], timestamp=eps[1]["timestamps"][i],
                    depth=eps[1]["depth"][i], contact=eps[1]["contact"][i])
    w.close()  # killed: what an encoder killed midway leaves, a hidden temporary file
    videos = partial_path(out) / VIDEOS_DIR
    (videos / ".episode-000001.mkv.123.0a1b2c3d.tmp").write_bytes(b"\x1a\x45\xdf\xa3 half")
    (videos / "episode-000001.mkv").write_bytes((videos / "episode-000000.mkv").read_bytes())
    with pytest.raises(VtsError, match="1 episode"):
        vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, video="ffv1",
                        arrays=("rgb", "depth", "contact"))
    again = write_video_takes(out, eps, "ffv1", name="ds", resume=True)
    assert tree_bytes(again) == tree_bytes(ffv1_ds)


@pytest.mark.parametrize(("kw", "match"), [
    ({"video": "mpeg4"}, "video must be None .*ffv1, h264"),
    ({"video": 3}, "video must be None"),
])
def test_bad_codecs_are_refused_in_one_line(tmp_path: Path, kw: dict[str, Any],
                                            match: str) -> None:
    with pytest.raises(VtsError, match=match) as e:
        vtsbench.create(tmp_path / "ds", **kw)
    assert "\n" not in str(e.value) and not (tmp_path / "ds").exists()


def test_odd_frames_refused_for_a_subsampling_codec(tmp_path: Path) -> None:
    import numpy as np

    w = vtsbench.create(tmp_path / "ds", video="h264")
    try:
        with pytest.raises(VtsError, match=r"47x64.*must be even") as e:
            w.add_frame(np.zeros((47, 64, 3), np.uint8))
        assert "\n" not in str(e.value) and w.pending == 0
    finally:
        w.close()


def test_resume_with_another_storage_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    w = vtsbench.create(out, fps=FPS, video="ffv1")
    w.add_episode(**video_takes()[0])
    w.close()
    for other, said in (("h264", "'h264'"), (None, "None")):
        with pytest.raises(VtsError, match=f"resume: video {said} differs .* 'ffv1'"):
            vtsbench.create(out, fps=FPS, video=other, resume=True)
    w = vtsbench.create(out, fps=FPS, video="ffv1", resume=True)
    assert w.episodes == 1
    w.close()
