"""Reading RGB frames back from a stored video through PyAV: what a file holds (`probe`) and a
window of frames (`decode_frames`), frame-accurate.

A video is a user's file: it is opened as a local file only (no URL, no other protocol),
through the demuxers and decoders vtsbench writes (format/video.py: DEMUXERS, DECODERS), its
frame size, frame count and file size bounded before anything is decoded. A file cut short,
damaged, or holding another number of frames than its header or the index says, is one
VtsError line naming it. Frames are told apart by their presentation timestamps, taken from
the packets (no decoding): frame k is the k-th timestamp in order.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import VtsError
from ...jsonio import regular_file
from ...limits import MAX_SEQUENCE_PIXELS
from ..format.video import (
    DECODERS,
    DEMUXERS,
    MAX_VIDEO_BYTES,
    MAX_VIDEO_FRAMES,
    MAX_VIDEO_SIDE,
    READABLE,
)

#: Bytes and microseconds FFmpeg may read to find the stream when it opens a file.
PROBE_BYTES = 1 << 20
PROBE_US = 1_000_000


@dataclass(frozen=True)
class VideoInfo:
    """What a stored video holds: frames, their rate and size, the decoder, the timestamp of
    each frame (in `time_base` units, in frame order) and which frames are keyframes."""

    path: str
    frames: int
    fps: float
    height: int
    width: int
    codec: str
    pix_fmt: str
    time_base: Fraction
    pts: tuple[int, ...]
    keyframes: tuple[int, ...]

    @property
    def size(self) -> tuple[int, int]:
        """(height, width) of a frame."""
        return self.height, self.width

    @property
    def timestamps(self) -> np.ndarray:
        """Each frame's time in seconds from the first frame."""
        return (np.asarray(self.pts, dtype=np.float64) - self.pts[0]) * float(self.time_base)

    def keyframe_before(self, index: int) -> int:
        """The last keyframe at or before frame `index`: where decoding it starts."""
        k = int(np.searchsorted(np.asarray(self.keyframes), index, side="right")) - 1
        return self.keyframes[max(k, 0)]


@contextlib.contextmanager
def _opened(path: Path) -> Iterator[Any]:
    """The container of a local video file, opened with the limits on; FFmpeg's errors are
    one VtsError line naming the file."""
    import av

    options = {"protocol_whitelist": "file", "format_whitelist": ",".join(DEMUXERS),
               "codec_whitelist": ",".join(DECODERS), "probesize": str(PROBE_BYTES),
               "analyzeduration": str(PROBE_US)}
    try:
        container = av.open(f"file:{path.absolute()}", container_options=options)
    except av.FFmpegError as e:
        raise VtsError(f"not a video vtsbench reads ({READABLE} expected: {_reason(e)})",
                       path) from None
    with container:
        yield container


def _reason(e: Any) -> str:
    return str(getattr(e, "strerror", None) or e).strip().rstrip(".")


def _stream(container: Any, path: Path) -> Any:
    """The one video stream, checked: a decoder vtsbench writes, a bounded frame size."""
    if not container.streams.video:
        raise VtsError("holds no video stream (not a video, or cut short)", path)
    stream = container.streams.video[0]
    name = stream.codec_context.name
    if name not in DECODERS:
        raise VtsError(f"video coded as {name!r}; vtsbench reads {READABLE}", path)
    h, w = stream.codec_context.height, stream.codec_context.width
    if not (1 <= h <= MAX_VIDEO_SIDE and 1 <= w <= MAX_VIDEO_SIDE):
        raise VtsError(f"declares {h}x{w} frames; at most {MAX_VIDEO_SIDE} pixels a side",
                       path)
    return stream


def probe(path: str | os.PathLike, expected_frames: int | None = None) -> VideoInfo:
    """What the video at `path` holds, read from its packets (nothing is decoded); one-line
    VtsError when it is not a whole video of a kind vtsbench writes, or when it does not hold
    `expected_frames` (what the index says) when given."""
    path = regular_file(path, "video", MAX_VIDEO_BYTES)
    with _opened(path) as container:
        stream = _stream(container, path)
        pts, keys = _scan(container, stream, path)
        cc, base = stream.codec_context, Fraction(stream.time_base)
        codec, pix_fmt = cc.name, cc.format.name if cc.format else "?"
        h, w = cc.height, cc.width
        declared, duration = int(stream.frames or 0), container.duration
        rate = stream.average_rate or stream.guessed_rate
        matroska = container.format.name.startswith("matroska")
    _check_end(path, matroska)
    frames = len(pts)
    if declared and declared != frames:
        raise VtsError(f"cut short or damaged: its header declares {declared} frames, "
                       f"{frames} found", path)
    in_order = tuple(sorted(pts))
    if len(set(in_order)) != frames:
        raise VtsError("two frames share a timestamp (damaged)", path)
    _check_duration(duration, in_order, base, path)
    if expected_frames is not None and expected_frames != frames:
        raise VtsError(f"holds {frames} frames; the index says {expected_frames}", path)
    rank = {p: k for k, p in enumerate(in_order)}
    fps = float(rate) if rate else _fps_of(in_order, base)
    return VideoInfo(str(path), frames, fps, h, w, codec, pix_fmt, base, in_order,
                     tuple(sorted(rank[pts[i]] for i in keys)))


def _scan(container: Any, stream: Any, path: Path) -> tuple[list[int], list[int]]:
    """Every frame's timestamp in decoding order, and the positions of the keyframes."""
    pts: list[int] = []
    keys: list[int] = []
    import av

    try:
        for packet in container.demux(stream):
            if packet.size == 0:  # the demuxer's end-of-stream marker
                continue
            if packet.pts is None or packet.is_corrupt:
                raise VtsError(f"cut short or damaged at frame {len(pts)} (a packet "
                               f"{'without a timestamp' if packet.pts is None else 'cut short'})",
                               path)
            if packet.is_keyframe:
                keys.append(len(pts))
            elif not pts:
                raise VtsError("does not start with a keyframe (damaged)", path)
            pts.append(int(packet.pts))
            if len(pts) > MAX_VIDEO_FRAMES:
                raise VtsError(f"holds more than {MAX_VIDEO_FRAMES} frames", path)
    except av.FFmpegError as e:
        raise VtsError(f"cut short or damaged at frame {len(pts)} ({_reason(e)})",
                       path) from None
    if not pts:
        raise VtsError("holds no frames (empty, or cut short)", path)
    return pts, keys


#: Top-level MP4 boxes read when checking where the file ends (a longer list is not checked).
MAX_BOXES = 10_000


def _check_end(path: Path, matroska: bool) -> None:
    """A file shorter than its container says (Matroska: the Segment's size; MP4: the sizes of
    the top-level boxes) was cut short, even where every frame survived (a lost index)."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        end = _matroska_end(fh) if matroska else _mp4_end(fh, size)
    if end is not None and end > size:
        raise VtsError(f"cut short: {size} bytes of the {end} its container declares", path)


def _vint(fh: Any, is_id: bool) -> int | None:
    """An EBML variable-length integer (an element ID keeps its length marker); None for a
    size of all ones (unknown) or a malformed one."""
    first = fh.read(1)
    if not first or first[0] == 0:
        return None
    n = 8 - first[0].bit_length() + 1
    rest = fh.read(n - 1)
    if len(rest) != n - 1:
        return None
    value = int.from_bytes((first if is_id else bytes([first[0] & (0xFF >> n)])) + rest, "big")
    return None if not is_id and value == (1 << (7 * n)) - 1 else value


def _matroska_end(fh: Any) -> int | None:
    """Where the Segment after the EBML header ends, or None when it does not say."""
    for want in (0x1A45DFA3, 0x18538067):  # EBML header, Segment
        ident, length = _vint(fh, True), _vint(fh, False)
        if ident != want or length is None:
            return None
        if want == 0x1A45DFA3:
            fh.seek(length, 1)
    return fh.tell() + length


def _mp4_end(fh: Any, size: int) -> int | None:
    """Where the last top-level box ends (None when a box runs to the end of the file or the
    list is longer than MAX_BOXES)."""
    at = 0
    for _ in range(MAX_BOXES):
        if at >= size:
            return at
        fh.seek(at)
        head = fh.read(16)
        if len(head) < 8:
            return at + 8
        n = int.from_bytes(head[:4], "big")
        if n == 1:
            n = int.from_bytes(head[8:16], "big") if len(head) == 16 else 16
        if n == 0:
            return None
        at += max(n, 8)
    return None


def _fps_of(pts: tuple[int, ...], base: Fraction) -> float:
    """Frames per second from the median step between timestamps (0 for one frame)."""
    if len(pts) < 2:
        return 0.0
    return 1.0 / (float(np.median(np.diff(pts))) * float(base))


def _check_duration(duration_us: int | None, pts: tuple[int, ...], base: Fraction,
                    path: Path) -> None:
    """A container that declares its duration (Matroska) and holds fewer frames than fill it
    was cut short: the last frame must end within half a frame of the declared end."""
    if not duration_us or len(pts) < 2:
        return
    step = float(np.median(np.diff(pts))) * float(base)
    end = (pts[-1] - pts[0]) * float(base) + step
    if end < duration_us / 1e6 - step / 2:
        raise VtsError(f"cut short: its frames end at {end:.3f} s of the {duration_us / 1e6:.3f} "
                       f"s it declares", path)


def decode_frames(path: str | os.PathLike, start: int, length: int,
                  info: VideoInfo | None = None,
                  expected_frames: int | None = None) -> np.ndarray:
    """Frames start..start+length-1 of the video as (length, H, W, 3) uint8 RGB: decoding
    starts at the last keyframe at or before `start`. `info` is the file's probe (probed here
    when not given; a reader of many windows probes once)."""
    path = Path(path)
    if info is None:
        info = probe(path, expected_frames)
    elif expected_frames is not None and expected_frames != info.frames:
        raise VtsError(f"holds {info.frames} frames; the index says {expected_frames}", path)
    if not (isinstance(start, (int, np.integer)) and isinstance(length, (int, np.integer))
            and start >= 0 and length >= 0 and start + length <= info.frames):
        raise VtsError(f"frames {start}..{start + length - 1} asked; the video has frames "
                       f"0..{info.frames - 1}", path)
    if length * info.height * info.width > MAX_SEQUENCE_PIXELS:
        raise VtsError(f"{length} frames of {info.height}x{info.width} at once is over "
                       f"{MAX_SEQUENCE_PIXELS} pixels: read it in windows", path)
    out = np.empty((length, info.height, info.width, 3), np.uint8)
    if length:
        _decode_into(path, info, int(start), out)
    return out


def _decode_into(path: Path, info: VideoInfo, start: int, out: np.ndarray) -> None:
    """Decode from the keyframe at or before `start`; from the first frame instead when the
    container's seek lands past it (a missing or wrong index)."""
    key = info.keyframe_before(start)
    if not _decode_from(path, info, start, out, info.pts[key] if key else None):
        _decode_from(path, info, start, out, None)


def _decode_from(path: Path, info: VideoInfo, start: int, out: np.ndarray,
                 seek: int | None) -> bool:
    """Fill `out` from frame `start` on, after seeking to timestamp `seek` (None: from the
    first frame); False when the seek landed past `start`."""
    import av

    want = info.pts[start:start + len(out)]
    got = 0
    try:
        with _opened(path) as container:
            stream = _stream(container, path)
            if (stream.codec_context.height, stream.codec_context.width) != info.size:
                raise VtsError("changed since it was probed", path)
            if seek is not None:
                container.seek(seek, stream=stream, backward=True, any_frame=False)
            for frame in container.decode(stream):
                if frame.pts is None or frame.pts < want[0]:
                    continue
                if frame.pts != want[got]:
                    if got == 0 and seek is not None:
                        return False
                    raise VtsError(f"frame {start + got} is missing (damaged, or changed "
                                   f"since it was probed)", path)
                out[got] = frame.to_ndarray(format="rgb24")
                got += 1
                if got == len(out):
                    return True
    except av.FFmpegError as e:
        raise VtsError(f"cut short or damaged at frame {start + got} ({_reason(e)})",
                       path) from None
    raise VtsError(f"cut short: frames {start + got}..{start + len(out) - 1} are missing",
                   path)
