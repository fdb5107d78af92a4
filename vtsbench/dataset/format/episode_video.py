"""Episodes whose RGB is stored as video (`vtsbench.create(..., video="ffv1")`): what info.json
records of it and where each file lies; no I/O here.

Each episode's RGB is one video file, `data/videos/episode-<index>.<ext>`
(layout.episode_video_path), written with a codec of format/video.py; frame k of the file is
frame k of the episode (the timestamps are index/frames.parquet's: the video runs at the
episode's fps). info.json's `episodes.video` holds the codec's settings (`VideoCodec.to_dict`,
`$defs/video_codec` of schemas/dataset_info.schema.json; format/info.py EpisodeCounts.video,
read back by `codec_from_dict`); `shapes.episodes.rgb` still gives the frames' count and size.
Depth and contact stay lossless in data/episodes.zarr, whose `rgb` array keeps its metadata
(the shape and chunking that readers check against info.json) and holds no chunk. The videos
lie under data/, so their sha256 are in info.json `files` and in dataset_sha256 as every data
file's.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ...errors import VtsError
from .layout import INFO_PATH, episode_video_path
from .video import VideoCodec

if TYPE_CHECKING:
    from .info import DatasetInfo

#: Where info.json records the codec: the `video` key of its `episodes` block.
RECORD_KEY = "episodes.video"
#: The fields of a recorded codec (VideoCodec's, as its to_dict writes them).
CODEC_FIELDS = ("name", "codec", "pix_fmt", "options", "lossless", "gop", "container",
                "decoder")


def codec_from_dict(doc: Any, where: str = INFO_PATH) -> VideoCodec:
    """A recorded codec back as a VideoCodec; one-line VtsError naming `where` when it is not
    one (a field missing or of the wrong type, a container or decoder vtsbench does not
    read)."""
    ok = isinstance(doc, Mapping) and set(doc) == set(CODEC_FIELDS) and all(
        isinstance(doc[k], str) for k in ("name", "codec", "pix_fmt", "container", "decoder")
    ) and isinstance(doc["options"], Mapping) and isinstance(doc["lossless"], bool) and (
        isinstance(doc["gop"], int) and not isinstance(doc["gop"], bool))
    if ok:
        try:
            return VideoCodec(**{k: doc[k] for k in CODEC_FIELDS})
        except ValueError as e:
            raise VtsError(f"{RECORD_KEY}: {e}", where) from None
    raise VtsError(f"{RECORD_KEY} is not a video codec's settings (fields "
                   f"{', '.join(CODEC_FIELDS)})", where)


def stored_codec(info: DatasetInfo) -> VideoCodec | None:
    """The codec a dataset's episodes keep their RGB with; None when the RGB is in Zarr."""
    return None if info.episodes is None else info.episodes.video


def video_paths(codec: VideoCodec, episodes: int) -> list[str]:
    """The video file of each of `episodes` episodes, in episode order."""
    return [episode_video_path(k, codec.suffix) for k in range(episodes)]
