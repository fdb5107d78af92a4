"""Frame access for the three kinds of source: image file, image folder, video file.

Every function returns RGB uint8 (H, W, 3), whatever OpenCV's BGR order on disk; this is the only
place where the channel order is converted, so it cannot be converted twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import VtsError
from .quiet import quiet_decoding

IMAGE_EXTS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"})
VIDEO_EXTS = frozenset({".mov", ".mp4", ".avi", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg"})


def _cv2():
    from .quiet import quiet_ffmpeg

    quiet_ffmpeg()  # before OpenCV's FFmpeg backend starts
    import cv2

    return cv2


def media_kind(path: Path) -> str:
    """'folder', 'image' or 'video' by what the path is; raises VtsError for anything else."""
    if path.is_dir():
        return "folder"
    ext = path.suffix.lower()
    if ext in IMAGE_EXTS:
        return "image"
    if ext in VIDEO_EXTS:
        return "video"
    raise VtsError(f"unsupported file type '{ext}' (images: {', '.join(sorted(IMAGE_EXTS))}; "
                   f"videos: {', '.join(sorted(VIDEO_EXTS))})", path)


#: Largest image file read (bytes); OpenCV's own pixel limit (CV_IO_MAX_IMAGE_PIXELS, 2**30 by
#: default) refuses images that declare more pixels than that.
MAX_IMAGE_BYTES = 512 << 20


def folder_frames(path: Path) -> list[Path]:
    """Image files of an image folder, in file-name order. An image name that is a folder, a
    FIFO, a device or a broken link is a one-line error saying so: skipped, it would shift
    every later frame and surface as a frame range past the end."""
    from ..jsonio import regular_file

    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_EXTS)
    for f in files:
        regular_file(f, "frame", MAX_IMAGE_BYTES)
    return files


def read_image(path: Path, out: np.ndarray | None = None) -> np.ndarray:
    """One image file as RGB uint8; one-line error if missing, not a regular file (a FIFO or a
    device would block or never end), over MAX_IMAGE_BYTES, or undecodable.

    Decoded by OpenCV (libpng, libjpeg...) with its documented behaviour: straight to RGB
    (IMREAD_COLOR_RGB, OpenCV >= 4.11), EXIF orientation applied, 16-bit samples scaled to 8
    bits, images over its pixel limit refused (`frame_notes` says which of these applies).
    out: unused by the decoder (kept for callers that pass a shard's row); the result is
    returned in a new array."""
    from ..jsonio import read_bytes

    data = read_bytes(path, "image", MAX_IMAGE_BYTES)
    cv2 = _cv2()
    rgb = getattr(cv2, "IMREAD_COLOR_RGB", None)
    if not data:
        raise VtsError("cannot decode image (empty file)", path)
    try:
        with quiet_decoding():
            img = cv2.imdecode(np.frombuffer(data, np.uint8),
                               cv2.IMREAD_COLOR if rgb is None else rgb)
    except cv2.error:
        img = None
    if img is None or not img.size:
        raise VtsError("cannot decode image", path)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB) if rgb is None else img


@dataclass(frozen=True)
class Probe:
    """What a source holds: number of frames and frame size."""

    kind: str
    n_frames: int
    height: int
    width: int


def frame_notes(path: Path) -> list[str]:
    """What decoding does to an image file beyond reading it: 16-bit samples scaled to 8 bits,
    an EXIF orientation applied (OpenCV's documented behaviour); [] for a plain 8-bit frame."""
    return inspect_frame(path)[1]


#: FFmpeg pixel formats' subsampling tags and what they are called.
_SUBSAMPLED = (("420", "4:2:0"), ("422", "4:2:2"), ("411", "4:1:1"), ("410", "4:1:0"))


def chroma_subsampling(path: Path) -> str | None:
    """"4:2:0", "4:2:2", ... when an image or video file (or an image folder's first frame)
    stores its colour at a lower resolution than its brightness, as most JPEG cameras and video
    codecs do; None for full-resolution colour (PNG, JPEG 4:4:4, raw) or when FFmpeg's probe
    (PyAV) cannot tell. Only the header is read."""
    import av

    if path.is_dir():
        files = folder_frames(path)
        if not files:
            return None
        path = files[0]
    try:
        with quiet_decoding(), av.open(str(path)) as c:
            streams = c.streams.video
            fmt = str(streams[0].codec_context.pix_fmt or "") if streams else ""
    except (av.FFmpegError, OSError, ValueError):
        return None
    return next((name for tag, name in _SUBSAMPLED if tag in fmt), None)


def inspect_frame(path: Path) -> tuple[tuple[int, int] | None, list[str]]:
    """The size (H, W) an image file is read at (None when it does not decode) and its
    `frame_notes`, from one read of the file."""
    from ..jsonio import read_bytes

    cv2 = _cv2()
    buf = np.frombuffer(read_bytes(path, "image", MAX_IMAGE_BYTES), np.uint8)
    notes: list[str] = []
    try:
        with quiet_decoding():
            raw = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
            turned = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    except cv2.error:
        return None, notes
    if raw is None or turned is None:
        return None, notes
    size = (int(turned.shape[0]), int(turned.shape[1]))
    if raw.dtype != np.uint8:
        notes.append(f"{raw.dtype.itemsize * 8}-bit samples: decoded to 8 bits (value / 257, "
                     "OpenCV IMREAD_COLOR)")
    if raw.shape[:2] != turned.shape[:2]:
        notes.append("EXIF orientation: the frame is rotated as its EXIF tag says "
                     f"({raw.shape[1]}x{raw.shape[0]} stored, {turned.shape[1]}x"
                     f"{turned.shape[0]} read)")
    else:
        with quiet_decoding():
            plain = cv2.imdecode(buf, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        if plain is not None and not np.array_equal(plain, turned):
            notes.append("EXIF orientation: the frame is flipped or turned as its EXIF tag says")
    return size, notes


def _image_size(path: Path, decode: bool) -> tuple[int, int]:
    img = read_image(path)  # also the one-line error for a missing or undecodable file
    return img.shape[0], img.shape[1]


def probe(path: Path, decode: bool = True) -> Probe:
    """Frame count and size of a source, reading as little as possible.

    Images are decoded by the library either way (decode is kept for callers): no
    hand-written header parsing of a user file."""
    if not path.exists():
        raise VtsError("file not found", path)
    kind = media_kind(path)
    if kind == "video":
        from ..jsonio import regular_file

        regular_file(path, "video")
    if kind == "image":
        return Probe(kind, 1, *_image_size(path, decode))
    if kind == "folder":
        files = folder_frames(path)
        if not files:
            raise VtsError("image folder holds no images", path)
        return Probe(kind, len(files), *_image_size(files[0], decode))
    cv2 = _cv2()
    with quiet_decoding():
        cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise VtsError("cannot open video (unknown codec or corrupt file)", path)
        with quiet_decoding():
            ok, frame = cap.read()
        if not ok or frame is None:
            raise VtsError("cannot decode video (no readable frame)", path)
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        return Probe(kind, n, frame.shape[0], frame.shape[1])
    finally:
        cap.release()


def read_frames(path: Path, start: int = 0, stop: int | None = None,
                out: np.ndarray | None = None) -> np.ndarray:
    """Frames [start, stop) of a source as RGB uint8 (T, H, W, 3).

    out: a uint8 (T, H, W, 3) array to decode into (a shard's rows); it is filled and returned
    when the frames have its shape, else the frames come back in a new array (out then holds
    anything)."""
    kind = media_kind(path) if path.exists() else None
    if kind is None:
        raise VtsError("file not found", path)
    if kind == "image":
        if start != 0 or (stop is not None and stop != 1):
            raise VtsError(f"an image file holds one frame, asked for [{start}, {stop})", path)
        return _into(out, [read_image(path, None if out is None else out[0])])
    if kind == "folder":
        files = folder_frames(path)
        stop = len(files) if stop is None else stop
        if stop > len(files) or start >= stop:
            raise VtsError(f"frame range [{start}, {stop}) outside the {len(files)} images", path)
        if out is None or len(out) != stop - start:
            chosen = files[start:stop]
            return _stack_frames(path, chosen, [read_image(f) for f in chosen])
        for t, f in enumerate(files[start:stop]):
            img = read_image(f, out[t])  # decoded in place when it can be
            if img.shape != out.shape[1:]:  # another size: the caller sees it in the result
                return _stack_frames(path, files[start:stop], [
                    *out[:t], img, *(read_image(g) for g in files[start + t + 1:stop])])
            if not np.shares_memory(img, out[t]):
                out[t] = img  # one copy per frame, not a stack and then a copy into the shard
        return out
    from ..jsonio import regular_file

    regular_file(path, "video")
    frames = _read_video(path, start, stop)
    if out is not None and out.shape == frames.shape:
        out[...] = frames
        return out
    return frames


def _stack_frames(folder: Path, files: list[Path], imgs: list[np.ndarray]) -> np.ndarray:
    """The frames of an image folder stacked; frames of two sizes are a one-line error naming
    the first frame of another size (a sequence is one camera at one resolution)."""
    for t, img in enumerate(imgs):
        if img.shape != imgs[0].shape:
            size = "x".join(map(str, imgs[0].shape[:2]))
            other = "x".join(map(str, img.shape[:2]))
            raise VtsError(f"frames of two sizes: {files[0].name} is {size}, {files[t].name} is "
                           f"{other}", folder)
    return np.stack(imgs)


def _into(out: np.ndarray | None, imgs: list[np.ndarray]) -> np.ndarray:
    """The frames in out when they fit it, else stacked in a new array."""
    if out is not None and out.shape == (len(imgs), *imgs[0].shape):
        for t, img in enumerate(imgs):
            if not np.shares_memory(img, out[t]):  # else decoded there already
                out[t] = img
        return out
    return np.stack(imgs)


def _read_video(path: Path, start: int, stop: int | None) -> np.ndarray:
    cv2 = _cv2()
    with quiet_decoding():
        cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise VtsError("cannot open video (unknown codec or corrupt file)", path)
        if start:
            cap.set(cv2.CAP_PROP_POS_FRAMES, start)
        frames = []
        i = start
        while stop is None or i < stop:
            with quiet_decoding():
                ok, frame = cap.read()
            if not ok:
                break
            frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
            i += 1
    finally:
        cap.release()
    if not frames or (stop is not None and len(frames) < stop - start):
        raise VtsError(f"frame range [{start}, {stop}) past the end of the video "
                       f"({start + len(frames)} frames decoded)", path)
    return np.stack(frames)


class Capture:
    """A camera (by index) or a video file opened through OpenCV, read frame by frame as RGB."""

    def __init__(self, source: str) -> None:
        cv2 = _cv2()
        text = source.strip()
        self.is_camera = text.isdigit()
        self.n_frames: int | None = None
        if self.is_camera:
            self.name = f"camera {int(text)}"
            level = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
            try:
                cap = cv2.VideoCapture(int(text))
            finally:
                cv2.utils.logging.setLogLevel(level)
            if not cap.isOpened():
                raise VtsError("cannot open camera (no device with this index, or it is busy)",
                               self.name)
        else:
            path = Path(text)
            self.name = str(path)
            if path.exists():
                from ..jsonio import regular_file

                regular_file(path, "video")
            info = probe(path)  # missing, unsupported type, or undecodable: one-line errors
            if info.kind != "video":
                raise VtsError(f"not a video file but an {info.kind} (--source takes a camera "
                               "index or a video file)", path)
            with quiet_decoding():
                cap = cv2.VideoCapture(str(path))
            if not cap.isOpened():
                raise VtsError("cannot open video (unknown codec or corrupt file)", path)
            self.n_frames = info.n_frames if info.n_frames > 0 else None
        fps = cap.get(cv2.CAP_PROP_FPS)
        self.fps: float | None = float(fps) if math.isfinite(fps) and 0 < fps < 1e4 else None
        self._cap = cap

    def read(self) -> np.ndarray | None:
        """The next frame as RGB uint8 (H, W, 3), or None at the end of the stream."""
        ok, frame = self._cap.read()
        if not ok or frame is None:
            return None
        return _cv2().cvtColor(frame, _cv2().COLOR_BGR2RGB)

    def close(self) -> None:
        self._cap.release()

    def __enter__(self) -> Capture:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_frame(path: Path, index: int = 0) -> np.ndarray:
    """One frame of a source as RGB uint8 (H, W, 3)."""
    return read_frames(path, index, index + 1)[0]


def write_png(path: Path, rgb: np.ndarray, compression: int = 1) -> None:
    """Write RGB uint8 as PNG (OpenCV writes BGR, so convert here and nowhere else).

    Huffman-only deflate: tactile frames carry sensor noise that defeats LZ matching; measured on
    a noisy 480x640 frame, 14.8 ms and 14 % smaller against 20.1 ms for the default strategy.
    One row filter, Up, instead of libpng choosing one per row: lossless as any filter and quick
    to unfilter. On 48 simulated 480x640 frames (one core of a 2-core AMD EPYC): Up 494 kB,
    written in 8.9 ms, decoded in 4.1 ms by OpenCV; Sub 497 kB, 9.4 and 4.4 ms; libpng's choice
    per row 480 kB and 15.1 ms to write (its Paeth rows take 8.7 ms to decode).
    """
    cv2 = _cv2()
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_PNG_COMPRESSION, compression,
                            cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
                            cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP])
    if not ok:
        raise VtsError("cannot encode PNG", path)
    from ..atomic import write_bytes_atomic

    write_bytes_atomic(path, buf.tobytes())
