"""info.json's `episodes.video`: the codec of episodes whose RGB is stored as video lives in the
episodes block (EpisodeCounts.video), written only when set (other datasets keep their bytes),
mirrored by `$defs/video_codec` of the schema, pickled with the info, never compared as a count;
`build` holds no codec."""

from __future__ import annotations

import json
import pickle
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from tests.fixtures.episode_video import video_takes, write_video_takes
from vtsbench.dataset.format.episode_video import stored_codec
from vtsbench.dataset.format.episodes import episodes_problems, read_table
from vtsbench.dataset.format.info import (
    COUNT_FIELDS,
    EpisodeCounts,
    info_schema_errors,
    load_info,
)
from vtsbench.dataset.format.video import CODECS
from vtsbench.errors import VtsError

COUNTS = EpisodeCounts(2, 20, {"mug": 2}, {"s0": 2}, {"slip": 20}, 1)


@pytest.fixture(scope="module")
def video_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One take of 18 frames, its RGB as ffv1."""
    return write_video_takes(tmp_path_factory.mktemp("info-video") / "ds", video_takes()[:1],
                             "ffv1")


def test_the_codec_is_written_only_when_set_and_comes_back() -> None:
    assert tuple(COUNTS.to_dict()) == COUNT_FIELDS  # a Zarr dataset: no key, its bytes kept
    with_video = replace(COUNTS, video=CODECS["h264"])
    doc = json.loads(json.dumps(with_video.to_dict()))
    assert tuple(doc) == (*COUNT_FIELDS, "video") and doc["video"] == CODECS["h264"].to_dict()
    assert EpisodeCounts.from_dict(doc) == with_video
    assert EpisodeCounts.from_dict(COUNTS.to_dict()).video is None
    assert pickle.loads(pickle.dumps(with_video)) == with_video  # a DataLoader worker's info


def test_a_dataset_records_it_in_the_episodes_block(video_ds: Path) -> None:
    doc = json.loads((video_ds / "meta" / "info.json").read_text())
    assert doc["episodes"]["video"] == CODECS["ffv1"].to_dict()
    assert "video" not in doc["build"]
    assert info_schema_errors(doc) == []
    info = load_info(video_ds)
    assert info.episodes is not None and info.episodes.video == CODECS["ffv1"]
    assert stored_codec(info) == CODECS["ffv1"]
    again = pickle.loads(pickle.dumps(info))
    assert again.episodes.video == CODECS["ffv1"] and again.to_json() == info.to_json()


@pytest.mark.parametrize("change", [{"gop": 0}, {"container": "avi"}, {"decoder": "mpeg4"},
                                    {"extra": 1}])
def test_a_changed_record_is_refused_by_the_schema(change: dict) -> None:
    doc = {"video": {**CODECS["h264"].to_dict(), **change}}
    errs = [e for e in info_schema_errors({"episodes": {**COUNTS.to_dict(), **doc}})
            if e.startswith("episodes")]
    assert errs and all("\n" not in e for e in errs)


def test_a_changed_record_in_a_dataset_is_one_line(video_ds: Path, tmp_path: Path) -> None:
    out = Path(shutil.copytree(video_ds, tmp_path / "ds"))
    path = out / "meta" / "info.json"
    doc = json.loads(path.read_text())
    doc["episodes"]["video"]["container"] = "avi"
    path.write_text(json.dumps(doc, indent=1))
    with pytest.raises(VtsError, match="episodes") as e:
        load_info(out)
    assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_the_codec_is_not_compared_as_a_count(video_ds: Path) -> None:
    info = load_info(video_ds)
    tables = [read_table(video_ds, which) for which in ("episodes", "frames")]
    assert episodes_problems(*tables, info) == []
    assert info.episodes is not None
    info.episodes = replace(info.episodes, video=None)  # another codec, or none: no count
    assert episodes_problems(*tables, info) == []
    info.episodes = replace(info.episodes, video=CODECS["av1"], dropped_frames=3)
    bad = episodes_problems(*tables, info)
    assert len(bad) == 1 and "episodes.dropped_frames" in bad[0]
