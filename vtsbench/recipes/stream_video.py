"""The annotated video of `vtsbench stream --video-out`: every frame the monitor took, with the
current call drawn on it with OpenCV (state and its confidence, the slip direction as an arrow,
the latency), encoded by PyAV (H.264 in .mp4 or .mkv, Motion JPEG in .avi) under a temporary
name and renamed when the stream ends (`vtsbench.atomic.replacing`)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from vtsbench.errors import VtsError

#: (container, encoder, pixel format, options) by the video's suffix.
FORMATS = {".mp4": ("mp4", "libx264", "yuv420p", {"crf": "23", "preset": "veryfast"}),
           ".mkv": ("matroska", "libx264", "yuv420p", {"crf": "23", "preset": "veryfast"}),
           ".avi": ("avi", "mjpeg", "yuvj420p", {"q:v": "3"})}
#: Colours (RGB) of the states; grey before the first call.
COLOURS = {"static": (200, 200, 200), "press": (255, 200, 0), "slip": (255, 0, 0)}


def annotate(rgb: np.ndarray, call: Any, index: int, ts: float) -> np.ndarray:
    """A copy of an RGB frame with the call drawn on it."""
    import cv2

    img = np.array(rgb[: rgb.shape[0] // 2 * 2, : rgb.shape[1] // 2 * 2])  # even: 4:2:0
    h, w = img.shape[:2]
    scale = max(0.35, min(h, w) / 480)
    thick = max(1, round(2 * scale))
    if call is None:
        text, colour = "filling window", (160, 160, 160)
    else:
        label = call.state or call.object or "?"
        conf = call.confidences.get("state" if call.state else "object", {}).get(
            call.raw_state or call.object or "", float("nan"))
        text = f"{label} {conf:.2f}"
        colour = COLOURS.get(call.state or "", (255, 255, 255))
        if call.state == "slip" and call.direction is not None:
            a = math.radians(45 * call.direction)  # bins counter-clockwise from +x, y up
            c, r = (w // 2, h // 2), 0.3 * min(h, w)
            tip = (round(c[0] + r * math.cos(a)), round(c[1] - r * math.sin(a)))
            cv2.arrowedLine(img, c, tip, colour, 2 * thick, tipLength=0.25)
        text += f"  {call.latency_ms:.0f} ms"
    y = round(28 * scale)
    for line in (text, f"frame {index}  t={ts:.2f} s"):
        cv2.putText(img, line, (8, y), cv2.FONT_HERSHEY_SIMPLEX, 0.8 * scale, (0, 0, 0),
                    thick + 2, cv2.LINE_AA)
        cv2.putText(img, line, (8, y), cv2.FONT_HERSHEY_SIMPLEX, 0.8 * scale, colour, thick,
                    cv2.LINE_AA)
        y += round(28 * scale)
    return img


class _NoFrame(Exception):
    """Raised inside the temporary file's block when no frame came: no file is left."""


class AnnotatedVideo:
    """The open video: its stream is added at the first frame, whose size it takes."""

    def __init__(self, out: Any, suffix: str, fps: float) -> None:
        self.out, self.suffix, self.fps = out, suffix, fps
        self.video: Any = None

    def write(self, rgb: np.ndarray, call: Any, index: int, ts: float) -> None:
        from fractions import Fraction

        import av

        img = annotate(rgb, call, index, ts)
        if self.video is None:
            _, codec, pix_fmt, options = FORMATS[self.suffix]
            rate = Fraction(self.fps).limit_denominator(1001)
            self.video = self.out.add_stream(codec, rate=rate, options=options)
            self.video.height, self.video.width = img.shape[:2]
            self.video.pix_fmt = pix_fmt
        for packet in self.video.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
            self.out.mux(packet)

    def flush(self) -> None:
        for packet in self.video.encode(None):
            self.out.mux(packet)


@contextmanager
def annotated_video(path: str | Path, fps: float) -> Iterator[AnnotatedVideo]:
    """An `AnnotatedVideo` written under a temporary name beside `path` and renamed to `path`
    when the block ends: the frames shown until then, complete, also after an error the
    stream reports in its summary; removed if the block raises; no file without a frame."""
    import av

    from vtsbench.atomic import replacing

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise VtsError(f"--video-out must end in {', '.join(FORMATS)}", path)
    try:
        # an absolute name is a file to FFmpeg, never a URL or another protocol
        with replacing(path.absolute()) as tmp, \
                av.open(str(tmp), "w", format=FORMATS[suffix][0]) as out:
            video = AnnotatedVideo(out, suffix, float(fps))
            yield video
            if video.video is None:
                raise _NoFrame
            video.flush()
    except _NoFrame:
        pass
