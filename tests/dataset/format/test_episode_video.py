"""What info.json records of episodes stored as video: the codec's settings (VideoCodec.to_dict)
mirror `$defs/video_codec` of schemas/dataset_info.schema.json, come back as the same codec,
and a changed record is one line; each episode's file is named by its index."""

from __future__ import annotations

import json
from dataclasses import fields

import pytest

from vtsbench.dataset.format.episode_video import CODEC_FIELDS, codec_from_dict, video_paths
from vtsbench.dataset.format.layout import episode_video_path
from vtsbench.dataset.format.records import SCHEMA_DIR, _violations
from vtsbench.dataset.format.video import CODECS
from vtsbench.errors import VtsError


def _schema() -> dict:
    doc = json.loads((SCHEMA_DIR / "dataset_info.schema.json").read_text())
    return {"$defs": doc["$defs"], "$ref": "#/$defs/video_codec"}


def test_the_record_mirrors_its_schema_and_comes_back() -> None:
    sch = _schema()
    assert set(sch["$defs"]["video_codec"]["properties"]) == set(CODEC_FIELDS) \
        == {f.name for f in fields(CODECS["ffv1"])}
    for codec in CODECS.values():
        doc = json.loads(json.dumps(codec.to_dict()))
        assert _violations(sch, doc) == []
        assert codec_from_dict(doc) == codec


@pytest.mark.parametrize("change", [
    {"gop": 0}, {"gop": "16"}, {"container": "avi"}, {"decoder": "mpeg4"}, {"lossless": 1},
    {"extra": 1}, {"options": []},
])
def test_a_changed_record_is_refused_by_schema_and_reader(change: dict) -> None:
    doc = {**CODECS["h264"].to_dict(), **change}
    assert _violations(_schema(), doc)
    with pytest.raises(VtsError, match=r"episodes\.video") as e:
        codec_from_dict(doc, "ds/meta/info.json")
    assert "\n" not in str(e.value)


def test_files_are_named_by_episode_index() -> None:
    assert episode_video_path(3, ".mkv") == "data/videos/episode-000003.mkv"
    assert video_paths(CODECS["av1"], 2) == ["data/videos/episode-000000.mp4",
                                             "data/videos/episode-000001.mp4"]
