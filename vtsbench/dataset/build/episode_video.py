"""An episode writer whose RGB goes to video (`vtsbench.create(..., video="ffv1")`): each saved
episode's RGB encoded as one file, `data/videos/episode-<index>.<ext>` (format/episode_video.py),
depth and contact into data/episodes.zarr as without video.

`VideoFrames` stands where the writer's FrameShards stands (build/episode_stage.py: the same
calls): the RGB of the episode being added is kept in memory, and `save_video` encodes it
(build/video.py encode_frames: a temporary name renamed when the file is whole) before the
episode's record commits it. A writer killed mid-encode leaves a hidden temporary file, which
the next writer deletes, never a video under its name; a video whose episode has no record (a
kill between the rename and the record) is deleted on resume, and written again when that
episode is. The Zarr group keeps the metadata of an `rgb` array (what readers check against
info.json) and no chunk of it; with arrays=("rgb",) that metadata is all it holds.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import VtsError
from ..format.arrays import Layout
from ..format.layout import EPISODES, EPISODES_GROUP, VIDEOS_DIR, episode_video_path
from ..format.video import CODECS, MAX_VIDEO_FRAMES, VideoCodec, get_codec
from .episode_stage import FrameShards
from .store import samples_per_shard, write_metadata
from .video import encode_frames, unknown_options


def check_video(video: Any) -> VideoCodec | None:
    """create's `video`: None (RGB in Zarr) or a codec name of format/video.py CODECS whose
    encoder this PyAV has; a one-line VtsError otherwise."""
    if video is None:
        return None
    if not isinstance(video, str) or video not in CODECS:
        raise VtsError(f"create: video must be None (RGB in Zarr) or one of "
                       f"{', '.join(CODECS)}, got {video!r:.80}")
    codec = get_codec(video)
    unknown = unknown_options(codec)  # a missing encoder is refused here, before any frame
    if unknown:
        raise VtsError(f"create: video {codec.name!r}: {codec.codec} has no option "
                       f"{', '.join(unknown)}")
    return codec


def frame_store(stage: Path, arrays: tuple[str, ...], level: int, shard_bytes: int,
                codec: VideoCodec | None, episodes: int) -> FrameShards | VideoFrames:
    """Where a writer puts its frames: FrameShards (all in Zarr) or, with a codec,
    VideoFrames; `episodes`: the saved episodes a resumed writer keeps."""
    if codec is None:
        return FrameShards(stage, arrays, level, shard_bytes)
    return VideoFrames(stage, arrays, level, shard_bytes, codec, episodes)


def frames_codec(frames: Any) -> VideoCodec | None:
    """The codec a writer's frames store their RGB with (info.json `episodes.video`); None
    when the RGB is in Zarr."""
    return frames.codec if isinstance(frames, VideoFrames) else None


class VideoFrames:
    """FrameShards' calls over a writer whose RGB goes to video: depth and contact through a
    FrameShards of those arrays (none with arrays=("rgb",)), RGB of the episode being added in
    memory until `save_video`; `layout` names every array (rgb included: its metadata)."""

    def __init__(self, stage: Path, arrays: tuple[str, ...], level: int, shard_bytes: int,
                 codec: VideoCodec, episodes: int) -> None:
        self.stage, self.arrays, self.level, self.shard_bytes = stage, arrays, level, shard_bytes
        self.codec = codec
        rest = tuple(a for a in arrays if a != "rgb")
        self.inner = FrameShards(stage, rest, level, shard_bytes) if rest else None
        self.layout: Layout | None = None
        self.committed = 0  # frames of the saved episodes
        self.added = 0  # frames since
        self.episodes = episodes  # saved episodes (their videos are kept)
        self.rgb: list[np.ndarray] = []  # the frames of the episode being added

    def start(self, size: tuple[int, int]) -> Layout:
        """The layout, fixed by the first frame's size (a 4:2:0 codec needs it even)."""
        if self.layout is None:
            h, w = size
            if self.codec.subsampled and (h % 2 or w % 2):
                raise VtsError(f"frames of {h}x{w}: video {self.codec.name!r} stores colour at "
                               f"half resolution ({self.codec.pix_fmt}), so height and width "
                               "must be even (or video='ffv1')")
            sps = samples_per_shard(size, None, self.shard_bytes)
            self.layout = Layout(EPISODES, 0, size, None, sps, self.level, self.arrays)
        if self.inner is not None:
            self.inner.start(size)
        return self.layout

    @property
    def per_shard(self) -> int:
        return self.layout.samples_per_shard if self.layout is not None else 1

    def add(self, frame: dict[str, np.ndarray]) -> None:
        """Append one frame: its RGB kept for the episode's video, the rest to Zarr."""
        if len(self.rgb) >= MAX_VIDEO_FRAMES:
            raise VtsError(f"an episode stored as video holds at most {MAX_VIDEO_FRAMES} frames")
        if self.inner is not None:
            self.inner.add(frame)
        self.rgb.append(frame["rgb"])
        self.added += 1

    def video_path(self, k: int) -> Path:
        """Episode k's video file in the partial folder."""
        return self.stage / episode_video_path(k, self.codec.suffix)

    def save_video(self, k: int, fps: float) -> int:
        """Encode the frames added since the last save as episode k's video (atomic), at the
        episode's fps; returns its bytes."""
        if not self.rgb:
            raise VtsError(f"episode {k}: no frames to store as video")
        path = self.video_path(k)
        path.parent.mkdir(parents=True, exist_ok=True)
        return encode_frames(np.stack(self.rgb), path, self.codec, fps)

    def save(self) -> None:
        """Depth and contact of the frames so far to Zarr (the video is save_video's)."""
        if self.inner is not None:
            self.inner.save()

    def saved(self) -> None:
        """The frames added are committed (their episode's record is written)."""
        if self.inner is not None:
            self.inner.saved()
        self.committed += self.added
        self.added = 0
        self.rgb = []
        self.episodes += 1

    def discard(self) -> None:
        """Forget the frames added since the last commit, and a video written for them."""
        if self.inner is not None:
            self.inner.discard()
        self.added = 0
        self.rgb = []
        self.video_path(self.episodes).unlink(missing_ok=True)

    def restore(self, committed: int, size: tuple[int, int] | None) -> None:
        """Resume with `committed` frames of the saved episodes: their videos kept, any other
        deleted."""
        self.committed, self.added, self.rgb = committed, 0, []
        if self.inner is not None:
            self.inner.restore(committed, size)
        if size is not None:
            self.start(size)
        self._keep_saved()

    def _keep_saved(self) -> None:
        """Delete every file of the videos folder but the saved episodes' videos."""
        keep = {self.video_path(k).name for k in range(self.episodes)}
        folder = self.stage / VIDEOS_DIR
        for p in folder.iterdir() if folder.is_dir() else ():
            if p.name not in keep and (p.is_file() or p.is_symlink()):
                p.unlink()

    def finalize(self) -> None:
        """Make the partial folder hold exactly the committed frames: depth and contact as
        FrameShards leaves them, the saved episodes' videos, and the metadata of every array
        (rgb's with no chunk) for `committed` frames."""
        if self.inner is not None:
            self.inner.finalize()
        self._keep_saved()
        if self.layout is not None:
            write_metadata(self.stage / EPISODES_GROUP, replace(self.layout, n=self.committed))
