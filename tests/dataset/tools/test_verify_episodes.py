"""vtsbench verify and info on a dataset written by vtsbench.create: intact, a flipped byte of a
frame named by its episode and frame, a missing shard, an index changed after the writer, and
the summary of the episodes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.fixtures.cli import run
from tests.fixtures.damage import rehash
from tests.fixtures.episodes import takes, write_takes
from vtsbench.dataset.tools.verify import shard_index, verify


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four takes (48 frames, rgb, depth and contact) in shards of 9 frames (read-only)."""
    return write_takes(tmp_path_factory.mktemp("verify-episodes") / "ds", takes(depth=True))


@pytest.fixture
def copy(written: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(written, tmp_path / "ds"))


def test_a_written_dataset_verifies(written: Path) -> None:
    report = verify(written)
    assert report.ok, report.problems
    assert report.samples == 0 and report.shards == 3 * 6  # 48 frames / 9 a shard, 3 arrays
    res = run("verify", written)
    assert res.exit_code == 0 and "0 problem(s)" in res.output


def test_a_flipped_byte_names_the_episode_and_frame(copy: Path) -> None:
    shard = copy / "data/episodes.zarr/depth/c/1/0/0"  # rows 9..17: frames 9-12 of episode 0
    data = shard.read_bytes()
    idx, ok = shard_index(data, 9)
    assert ok
    off = int(idx[2, 0]) + int(idx[2, 1]) // 2  # row 11
    shard.write_bytes(data[:off] + bytes([data[off] ^ 0x5A]) + data[off + 1:])
    problems = verify(copy).problems
    assert ("data/episodes.zarr/depth: sample episode-000000/11 (row 11): shard c/1/0/0 fails "
            "to decode (crc32c mismatch)") in problems, problems
    assert "data/episodes.zarr/depth/c/1/0/0: sha256 mismatch" in problems[0]


def test_a_missing_shard_and_a_changed_index_are_problems(copy: Path) -> None:
    (copy / "data/episodes.zarr/rgb/c/5/0/0/0").unlink()
    problems = verify(copy).problems
    assert "data/episodes.zarr/rgb/c/5/0/0/0: missing" in problems
    assert any("rows 45-47" in p and "is missing" in p for p in problems), problems
    path = copy / "index/frames.parquet"
    table = pq.read_table(path)
    ts = table.column("timestamp").to_numpy().copy()
    ts[20:22] = ts[21], ts[20]  # two frames of episode 1 swapped in time
    pq.write_table(table.set_column(2, table.schema.field(2), pa.array(ts)), path)
    rehash(copy)
    problems = verify(copy).problems
    assert any(p.startswith("index/episodes.parquet: timestamp not after the previous frame's"
                            " in 1 row(s) (first: episode-000001/8") for p in problems), problems


def test_info_counts_are_checked_against_the_indexes(copy: Path) -> None:
    def edit(doc: dict) -> None:
        doc["episodes"]["dropped_frames"] = 5

    rehash(copy, edit)
    problems = verify(copy).problems
    assert any("episodes.dropped_frames contradicts the episode indexes" in p
               for p in problems), problems


def test_info_shows_the_episodes(written: Path) -> None:
    res = run("info", written)
    assert res.exit_code == 0, res.output
    assert "episodes 4, 48 frames (0 dropped)" in res.output
    doc = json.loads((written / "meta/info.json").read_text())
    assert doc["episodes"]["objects"] == {"box": 1, "cloth": 1, "mug": 2}


def test_verify_reads_the_episode_index_once(tmp_path: Path, monkeypatch) -> None:
    """The index checks, the splits of episodes and the videos' probe share one read of
    index/episodes.parquet; a video removed is still found, by its episode's length."""
    import vtsbench.dataset.format.episodes as fe
    from tests.fixtures.episode_video import video_takes, write_video_takes

    ds = write_video_takes(tmp_path / "ds", video_takes(), "ffv1")
    reads: list[str] = []
    real = fe.read_table

    def counted(source, which, *args, **kwargs):
        reads.append(which)
        return real(source, which, *args, **kwargs)

    monkeypatch.setattr(fe, "read_table", counted)
    report = verify(ds, decode=False)
    assert report.ok, report.problems
    assert reads.count("episodes") == 1 and reads.count("frames") == 1
    (ds / "data" / "videos" / "episode-000001.mkv").unlink()
    reads.clear()
    assert verify(ds, decode=False).problems == ["data/videos/episode-000001.mkv: missing"]
    assert reads.count("episodes") == 1
