"""Writing RGB frames as a video file through PyAV, with a codec of format/video.py.

The file is written under a temporary name beside it and renamed when the encoder has
flushed and the container is closed (vtsbench/atomic.py), so a video that took its name is
complete: an error or a kill midway leaves no file of that name.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ...atomic import replacing
from ...errors import VtsError
from ...limits import MAX_FPS
from ..format.video import MAX_VIDEO_FRAMES, MAX_VIDEO_SIDE, VideoCodec, get_codec

#: The time base of a video written with its own timestamps: the MPEG 90 kHz clock (Matroska
#: keeps milliseconds).
TIMESTAMP_BASE = Fraction(1, 90_000)


def encode_frames(frames: np.ndarray, path: str | os.PathLike, codec: str | VideoCodec,
                  fps: float, timestamps: Sequence[float] | np.ndarray | None = None) -> int:
    """Write (N, H, W, 3) uint8 RGB frames to `path` (its suffix the codec's container: .mkv
    for ffv1, .mp4 otherwise) at `fps`, or at `timestamps` (N seconds, increasing) when given;
    returns the bytes written."""
    codec = get_codec(codec)
    path = Path(path)
    _check(frames, path, codec, fps)
    pts, base = _timing(len(frames), fps, timestamps, path)
    unknown = unknown_options(codec)
    if unknown:
        raise VtsError(f"{codec.name}: {codec.codec} has no option {', '.join(unknown)}", path)
    _quiet_svt()
    import av

    # bitexact: no random ids or library version in the file, so the same frames give the
    # same bytes (a resumed dataset equals one written in one go)
    options = {"fflags": "+bitexact",
               **({"movflags": "+faststart"} if codec.container == "mp4" else {})}
    try:
        # an absolute name is a file to FFmpeg, never a URL or another protocol
        with replacing(path.absolute()) as tmp, \
                av.open(str(tmp), "w", format=codec.container, container_options=options) as out:
            _encode(out, frames, codec, fps, pts, base)
    except av.FFmpegError as e:
        raise VtsError(f"cannot encode with {codec.name} ({e.strerror or e})", path) from None
    return path.stat().st_size


def unknown_options(codec: VideoCodec) -> list[str]:
    """The codec's options its FFmpeg encoder does not have (FFmpeg would ignore them
    silently); a missing encoder is a one-line VtsError."""
    import av

    try:
        ctx = av.codec.CodecContext.create(codec.codec, "w")
    except (av.FFmpegError, ValueError):  # UnknownCodecError is a ValueError
        raise VtsError(f"{codec.name}: this PyAV has no encoder {codec.codec!r}") from None
    known = {o.name for o in (*ctx.supported_options.generic, *ctx.supported_options.private)}
    return [k for k in codec.options if k not in known]


def _check(frames: Any, path: Path, codec: VideoCodec, fps: float) -> None:
    if not isinstance(frames, np.ndarray) or frames.dtype != np.uint8 or frames.ndim != 4 \
            or frames.shape[-1] != 3:
        shape = getattr(frames, "shape", None)
        raise VtsError(f"frames must be (N, H, W, 3) uint8 RGB, got {shape} "
                       f"{getattr(frames, 'dtype', type(frames).__name__)}", path)
    n, h, w, _ = frames.shape
    if not 1 <= n <= MAX_VIDEO_FRAMES or not (1 <= h <= MAX_VIDEO_SIDE
                                              and 1 <= w <= MAX_VIDEO_SIDE):
        raise VtsError(f"{n} frames of {h}x{w}: 1 to {MAX_VIDEO_FRAMES} frames of at most "
                       f"{MAX_VIDEO_SIDE} pixels a side", path)
    if codec.subsampled and (h % 2 or w % 2):
        raise VtsError(f"{codec.name} stores colour at half resolution ({codec.pix_fmt}): "
                       f"height and width must be even, got {h}x{w}", path)
    if path.suffix.lower() != codec.suffix:
        raise VtsError(f"{codec.name} is stored in a {codec.suffix} file", path)
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise VtsError(f"fps must be above 0 and at most {MAX_FPS:g}, got {fps}", path)


def _timing(n: int, fps: float, timestamps: Sequence[float] | np.ndarray | None,
            path: Path) -> tuple[list[int], Fraction]:
    """Each frame's presentation time in units of the time base, and the time base."""
    if timestamps is None:
        return list(range(n)), 1 / _rate(fps)
    t = np.asarray(timestamps, dtype=np.float64)
    if t.shape != (n,) or not np.isfinite(t).all():
        raise VtsError(f"timestamps must be {n} finite seconds, one a frame, got shape "
                       f"{t.shape}", path)
    ticks = np.round((t - t[0]) / float(TIMESTAMP_BASE)).astype(np.int64)
    if n > 1 and (np.diff(ticks) < 1).any():
        raise VtsError("timestamps must increase from frame to frame (at least 1/90000 s)",
                       path)
    return ticks.tolist(), TIMESTAMP_BASE


def _rate(fps: float) -> Fraction:
    """fps as a fraction (25 -> 25/1, 29.97 -> 30000/1001)."""
    return Fraction(fps).limit_denominator(1001)


def _quiet_svt() -> None:
    """SVT-AV1 prints its settings to stderr itself: errors only, unless the user set
    SVT_LOG."""
    os.environ.setdefault("SVT_LOG", "1")


def _encode(out: Any, frames: np.ndarray, codec: VideoCodec, fps: float, pts: list[int],
            base: Fraction) -> None:
    """Encode the frames into the open output container and flush the encoder."""
    stream = out.add_stream(codec.codec, rate=_rate(fps), options=dict(codec.options))
    stream.height, stream.width = frames.shape[1:3]
    stream.pix_fmt = codec.pix_fmt
    cc = stream.codec_context
    cc.time_base = base
    cc.gop_size = codec.gop
    if codec.subsampled:  # what swscale converts with: BT.601, limited range
        cc.colorspace, cc.color_range = 6, 1  # SMPTE 170M (BT.601), MPEG range
    for i, rgb in enumerate(frames):
        for packet in stream.encode(_video_frame(rgb, codec.pix_fmt, pts[i], base)):
            out.mux(packet)
    for packet in stream.encode(None):
        out.mux(packet)


def _video_frame(rgb: np.ndarray, pix_fmt: str, pts: int, base: Fraction) -> Any:
    """One RGB frame as a PyAV frame in the codec's pixel format, with its timestamp."""
    import av

    frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
    frame = frame.reformat(format=pix_fmt)
    frame.pts, frame.time_base = pts, base
    return frame
