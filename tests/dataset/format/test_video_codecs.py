"""The video codecs' settings as data: the registry, its stated settings and lookups."""

from __future__ import annotations

import dataclasses
import json

import pytest

from vtsbench.dataset.format.video import (
    CODECS,
    DECODERS,
    GOP,
    SUFFIXES,
    VideoCodec,
    get_codec,
)
from vtsbench.errors import VtsError


def test_registry_names_the_codecs_under_their_own_names() -> None:
    assert {"ffv1", "h264", "h264-crf28", "av1", "av1-crf45"} <= set(CODECS)
    assert all(name == c.name for name, c in CODECS.items())


def test_ffv1_is_lossless_rgb_in_matroska_every_frame_a_keyframe() -> None:
    c = CODECS["ffv1"]
    assert c.lossless and c.codec == "ffv1" and c.pix_fmt == "bgr0"  # 8-bit RGB as it is
    assert c.gop == 1 and c.container == "matroska" and c.suffix == ".mkv"
    assert not c.subsampled


@pytest.mark.parametrize(("name", "encoder", "crf"), [
    ("h264", "libx264", "18"), ("h264-crf28", "libx264", "28"),
    ("av1", "libsvtav1", "30"), ("av1-crf45", "libsvtav1", "45")])
def test_lossy_codecs_state_crf_gop_and_container(name: str, encoder: str, crf: str) -> None:
    c = CODECS[name]
    assert c.codec == encoder and c.pix_fmt == "yuv420p" and c.subsampled
    assert c.options["crf"] == crf and not c.lossless
    assert c.gop == GOP == 16 and c.suffix == ".mp4"
    assert f"crf={crf}" in c.describe() and "keyframe every 16 frames" in c.describe()


def test_settings_are_frozen_and_round_trip_as_json() -> None:
    c = CODECS["h264"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.gop = 1  # type: ignore[misc]
    with pytest.raises(TypeError):
        c.options["crf"] = "0"  # type: ignore[index]
    doc = json.loads(json.dumps(c.to_dict()))
    assert VideoCodec(**doc) == c
    assert hash(c) == hash(VideoCodec(**doc))


def test_get_codec_by_name_or_object_and_unknown_is_one_line() -> None:
    assert get_codec("av1") is CODECS["av1"]
    assert get_codec(CODECS["ffv1"]) is CODECS["ffv1"]
    with pytest.raises(VtsError, match="unknown video codec 'h265'; one of ffv1, h264") as e:
        get_codec("h265")
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("change", [{"container": "avi"}, {"decoder": "mpeg4"}, {"gop": 0}])
def test_a_codec_outside_what_vtsbench_reads_is_refused(change: dict) -> None:
    with pytest.raises(ValueError):
        dataclasses.replace(CODECS["h264"], **change)


def test_the_installed_pyav_has_every_encoder_and_decoder() -> None:
    import av

    assert {c.codec for c in CODECS.values()} <= av.codecs_available
    assert set(DECODERS) <= av.codecs_available
    assert set(SUFFIXES) == {c.container for c in CODECS.values()}

