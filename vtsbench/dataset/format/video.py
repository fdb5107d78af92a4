"""Video storage of RGB frames: each codec's settings as data (encoder, pixel format, options,
keyframe interval, container), and the bounds a stored video keeps; no I/O here.

Only RGB goes to video. Depth and contact stay lossless in Zarr: a lossy codec would move
depth by more than its 1 um step and smear the contact edge. `ffv1` is bit-exact for RGB (its
`bgr0` pixel format holds the three 8-bit channels as they are); the others convert to 4:2:0
YUV and are lossy. A window of frames is read from the keyframe at or before its first frame,
so the keyframe interval (`gop`) bounds the frames decoded in vain: at most `gop - 1`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from ...errors import VtsError
from ...limits import MAX_SIDE_PX, MAX_TAKE_FRAMES

#: A stored video's bounds: a frame's side (as `vtsbench simulate --size`), its frames (a
#: take's), its file size.
MAX_VIDEO_SIDE = MAX_SIDE_PX
MAX_VIDEO_FRAMES = MAX_TAKE_FRAMES
MAX_VIDEO_BYTES = 1 << 40
#: The containers vtsbench writes, by FFmpeg muxer name: the file suffix of each.
SUFFIXES = {"matroska": ".mkv", "mp4": ".mp4"}
#: FFmpeg's demuxers and decoders a stored video may use (everything else is refused before a
#: byte is decoded): Matroska and MP4; FFV1, H.264 and AV1 (dav1d).
DEMUXERS = ("matroska", "mov")
DECODERS = ("ffv1", "h264", "libdav1d")
#: What they read, in words.
READABLE = "Matroska or MP4 of FFV1, H.264 or AV1"
#: Keyframe interval of the lossy codecs: a random 8-frame window decodes at most 15 + 8
#: frames. On the real takes 16 against 64 costs 19-45 % more bytes (still 170-520x smaller
#: than raw RGB) and 1.2-1.8x less CPU a random window (docs/benchmarks.md).
GOP = 16


@dataclass(frozen=True)
class VideoCodec:
    """One way to store RGB frames as video: FFmpeg encoder, the pixel format it codes,
    encoder options, whether decoding gives the frames back bit for bit, keyframe interval
    (frames), container (FFmpeg muxer) and the FFmpeg decoder that reads it back."""

    name: str
    codec: str
    pix_fmt: str
    options: Mapping[str, str] = field(hash=False)
    lossless: bool
    gop: int = GOP
    container: str = "mp4"
    decoder: str = "h264"

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))
        if self.container not in SUFFIXES or self.decoder not in DECODERS or self.gop < 1:
            raise ValueError(f"codec {self.name!r}: container {self.container!r}, decoder "
                             f"{self.decoder!r}, gop {self.gop}")

    @property
    def suffix(self) -> str:
        """The file suffix of its container (.mkv, .mp4)."""
        return SUFFIXES[self.container]

    @property
    def subsampled(self) -> bool:
        """True when chroma is stored at half resolution (4:2:0): height and width must be
        even."""
        return self.pix_fmt.startswith("yuv420")

    def describe(self) -> str:
        """One line: encoder, pixel format, options, keyframe interval, container."""
        opts = " ".join(f"{k}={v}" for k, v in self.options.items())
        return (f"{self.codec} {self.pix_fmt} {opts}, keyframe every {self.gop} frame"
                f"{'s' if self.gop > 1 else ''}, {self.suffix}"
                f"{', lossless' if self.lossless else ''}")

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain JSON values (what a dataset records of how its video was
        made)."""
        return {"name": self.name, "codec": self.codec, "pix_fmt": self.pix_fmt,
                "options": dict(self.options), "lossless": self.lossless, "gop": self.gop,
                "container": self.container, "decoder": self.decoder}


def _x264(name: str, crf: int) -> VideoCodec:
    # scenecut=0: keyframes exactly every GOP frames; open-gop=0: each keyframe starts a
    # closed group, so decoding can start there
    return VideoCodec(name, "libx264", "yuv420p",
                      {"crf": str(crf), "preset": "medium",
                       "x264-params": "scenecut=0:open-gop=0"}, lossless=False)


def _svtav1(name: str, crf: int) -> VideoCodec:
    # irefresh-type=2: closed-GOP key frames (seekable); scd=0: no extra keyframes at scene cuts
    return VideoCodec(name, "libsvtav1", "yuv420p",
                      {"crf": str(crf), "preset": "8", "svtav1-params": "irefresh-type=2:scd=0"},
                      lossless=False, decoder="libdav1d")


#: The codecs by name. `ffv1` (level 3, range coder, large context, 4 slices a frame with
#: CRCs, which FFmpeg's tools check; PyAV decodes past a damaged slice, so damage is found by
#: the file's sha256): every frame a keyframe, lossless. `h264` (crf 18, visually
#: lossless), `h264-crf28` (small); `av1` (crf 30), `av1-crf45` (smaller again, slower
#: to encode).
CODECS: dict[str, VideoCodec] = {
    "ffv1": VideoCodec("ffv1", "ffv1", "bgr0",
                       {"level": "3", "coder": "1", "context": "1", "slices": "4",
                        "slicecrc": "1"}, lossless=True, gop=1, container="matroska",
                       decoder="ffv1"),
    "h264": _x264("h264", 18),
    "h264-crf28": _x264("h264-crf28", 28),
    "av1": _svtav1("av1", 30),
    "av1-crf45": _svtav1("av1-crf45", 45),
}


def get_codec(name: str | VideoCodec) -> VideoCodec:
    """A codec of CODECS by name (a VideoCodec passes through); one-line VtsError listing the
    names otherwise."""
    if isinstance(name, VideoCodec):
        return name
    if name not in CODECS:
        raise VtsError(f"unknown video codec {str(name)[:60]!r}; one of {', '.join(CODECS)}")
    return CODECS[name]
