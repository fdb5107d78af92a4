"""`vtsbench stream`: a `Monitor` on a camera, a video file or a dataset episode, its calls
written as JSON lines (schemas/stream.schema.json) and optionally drawn on an annotated video.

A live source (a camera, or a file or episode played at its own pace with `realtime`) is read
in a thread into a one-frame mailbox: the monitor always takes the newest frame, and a frame
replaced before it was taken is counted as dropped, so the monitor never falls behind. A file
or episode read as fast as the monitor goes drops nothing. Every line is written whole and
flushed, the last one a summary, also when the stream ends in an error or is interrupted.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from vtsbench.errors import VtsError

#: The format of the JSON lines (the header's `format` and `format_version`).
FORMAT, FORMAT_VERSION = "vtsbench.stream", 1
#: Seconds a camera may give no frame before the stream ends with an error.
CAMERA_TIMEOUT_S = 5.0
#: The frame rate assumed for a video file that declares none.
DEFAULT_FPS = 25.0
#: Frames of an episode read per batched read.
EPISODE_CHUNK = 32

Frame = tuple[int, float, np.ndarray]  # (frame index in the source, timestamp s, RGB frame)


@dataclass
class Source:
    """Frames of one source: `frames()` yields (index, timestamp s, (H, W, 3) uint8 RGB);
    `live`: the source runs at its own pace (a camera); `episode`: the episode's row."""

    kind: str
    name: str
    fps: float | None
    frames: Callable[[], Iterator[Frame]]
    live: bool = False
    close: Callable[[], None] = lambda: None
    episode: dict[str, Any] = field(default_factory=dict)


def camera_source(index: int) -> Source:
    """An OpenCV camera by index; one that cannot be opened, or stops, is a one-line error."""
    from vtsbench.recordings.media import Capture

    cap = Capture(str(int(index)))

    def frames() -> Iterator[Frame]:
        t0, k = time.monotonic(), 0
        while True:
            rgb = cap.read()
            if rgb is None:
                raise VtsError(f"the camera stopped giving frames after {k} frames", cap.name)
            yield k, time.monotonic() - t0, rgb
            k += 1

    return Source("camera", cap.name, cap.fps, frames, live=True, close=cap.close)


def video_source(path: str | Path) -> Source:
    """A video file decoded by OpenCV (`vtsbench.recordings.media`); one that cannot be
    opened or decoded is a one-line error. Frame k is at k / fps."""
    from vtsbench.recordings.media import Capture

    cap = Capture(str(path))
    fps = cap.fps or DEFAULT_FPS

    def frames() -> Iterator[Frame]:
        k = 0
        while (rgb := cap.read()) is not None:
            yield k, k / fps, rgb
            k += 1

    return Source("video", cap.name, cap.fps, frames, close=cap.close)


def episode_source(dataset: str | Path, episode_id: str, ds: Any = None) -> Source:
    """One episode of a dataset (`ds.episodes`; `ds`: the dataset already loaded from
    `dataset`, or None to load it): its frames in batched reads, with their timestamps and the
    episode's row (slip onset, object) for the header."""
    import vtsbench

    eps = (vtsbench.load(dataset) if ds is None else ds).episodes
    one = eps.where(episode_id=episode_id)
    if len(one) != 1:
        ids = eps.ids
        known = ", ".join(ids[:5]) + (f" ... ({len(ids)} episodes)" if len(ids) > 5 else "")
        raise VtsError(f"no episode {episode_id!r:.80} in the dataset (episodes: "
                       f"{known or 'none'})", dataset)
    row = one.index.to_pylist()[0]
    stamps = np.asarray(one.frames["timestamp"].to_numpy(), np.float64)
    windows = one.windows(length=1, stride=1)

    def frames() -> Iterator[Frame]:
        for a in range(0, len(windows), EPISODE_CHUNK):
            rgb = windows.read(range(a, min(a + EPISODE_CHUNK, len(windows))), ("rgb",))["rgb"]
            for j in range(len(rgb)):
                yield a + j, float(stamps[a + j]), rgb[j, 0]

    keep = ("episode_id", "object", "session", "sensor", "length", "slip_onset_s")
    return Source("episode", f"{dataset}#{episode_id}", float(row["fps"]), frames,
                  episode={k: row.get(k) for k in keep})


def open_source(source: str, episode: str | None = None) -> Source:
    """A camera index (`0`), a dataset episode (`DATASET#EPISODE_ID`, or a dataset folder with
    `episode`), or a video file."""
    text = source.strip()
    if text.isdigit():
        if episode is not None:
            raise VtsError("--episode is for a dataset source, not a camera")
        return camera_source(int(text))
    if episode is None and "#" in text:
        folder, _, name = text.rpartition("#")
        if Path(folder).is_dir():
            return episode_source(folder, name)
    if Path(text).is_dir():
        if episode is None:
            raise VtsError("a dataset source needs the episode: DATASET#EPISODE_ID or "
                           "--episode ID", text)
        return episode_source(text, episode)
    if episode is not None:
        raise VtsError("--episode is for a dataset source (a folder)", text)
    return video_source(text)


class Mailbox:
    """The newest frame of a live source, handed from its reading thread to the monitor: a
    frame replaced before it was taken is dropped (counted)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._item: Frame | None = None
        self._done, self._error = False, None
        self.frames = self.dropped = 0

    def put(self, item: Frame) -> None:
        with self._cond:
            if self._item is not None:
                self.dropped += 1
            self._item = item
            self.frames += 1
            self._cond.notify()

    def finish(self, error: BaseException | None = None) -> None:
        with self._cond:
            self._done, self._error = True, error
            self._cond.notify()

    def take(self, timeout: float) -> Frame | None:
        """The newest frame, or None at the end of the source; its error is raised here, and
        no frame within `timeout` seconds is a TimeoutError."""
        with self._cond:
            while self._item is None and not self._done:
                if not self._cond.wait(timeout):
                    raise TimeoutError
            item, self._item = self._item, None
            if item is None and self._error is not None:
                raise self._error
            return item


def _feed(source: Source, box: Mailbox, stop: threading.Event, pace: bool,
          max_frames: int | None) -> None:
    """The reading thread: every frame into the mailbox, at the source's timestamps when
    `pace` (a file played as a camera), until the end, `max_frames` or `stop`."""
    try:
        start = time.monotonic()
        for k, (index, ts, rgb) in enumerate(source.frames()):
            if stop.is_set() or (max_frames is not None and k >= max_frames):
                break
            if pace:
                wait = start + ts - time.monotonic()
                if wait > 0 and stop.wait(wait):
                    break
            box.put((index, ts, rgb))
        box.finish()
    except BaseException as e:  # handed to the monitor's thread, which reports it
        box.finish(e)


@dataclass
class Tally:
    """What the summary line counts."""

    frames: int = 0
    processed: int = 0
    calls: int = 0
    latencies: list[float] = field(default_factory=list)
    start: float = field(default_factory=time.perf_counter)

    def summary(self, dropped: int, end: str, error: str | None) -> dict[str, Any]:
        wall = time.perf_counter() - self.start
        lat = np.asarray(self.latencies, np.float64)

        def pct(q: float) -> float | None:
            return round(float(np.percentile(lat, q)), 3) if len(lat) else None

        return {"type": "summary", "frames": self.frames, "processed": self.processed,
                "calls": self.calls, "dropped": dropped, "wall_s": round(wall, 3),
                "fps_sustained": round(self.processed / wall, 3) if wall > 0 else None,
                "latency_ms_p50": pct(50), "latency_ms_p95": pct(95), "end": end,
                "error": error}


class LineWriter:
    """JSON lines on a binary stream, each written whole in one write and flushed."""

    def __init__(self, out: Any) -> None:
        self.out = out

    def __call__(self, doc: dict[str, Any]) -> None:
        data = (json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n").encode()
        self.out.write(data)
        self.out.flush()


@lru_cache(maxsize=1)
def _line_validator() -> Any:
    """The validator of schemas/stream.schema.json, read once (a submission checks every
    line with it)."""
    from vtsbench.jsonio import strict_validator

    path = Path(__file__).resolve().parent.parent / "schemas" / "stream.schema.json"
    return strict_validator(json.loads(path.read_text(encoding="utf-8")))


def line_errors(doc: Any) -> list[str]:
    """Every violation of schemas/stream.schema.json by one line's object, one line each."""
    return [f"{'/'.join(map(str, e.absolute_path)) or '(line)'}: {e.message}"
            for e in _line_validator().iter_errors(doc)]


def checkpoint_sha256(path: str | Path) -> str:
    """The sha256 of a checkpoint file, hashed once while the file stays the same (its path,
    size and modification time): a submission streams every episode with one checkpoint."""
    import os

    p = Path(path)
    st = os.stat(p)
    return _file_sha256(p, str(p.resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


@lru_cache(maxsize=8)
def _file_sha256(path: Path, *same: object) -> str:
    """sha256 of the file at `path`, cached on it and `same`, what identifies its bytes (where
    it resolves to, device, inode, size, modification time)."""
    from vtsbench.dataset.format.provenance import sha256_file

    return sha256_file(path)


def header(monitor: Any, source: Source, *, realtime: bool, device: str) -> dict[str, Any]:
    """The first line: the format, recipe, checkpoint and its sha256, the source and its fps,
    window, smoothing, classes, and the environment (torch threads among them)."""
    from vtsbench.environment import environment

    d = monitor.describe()
    return {"type": "header", "format": FORMAT, "format_version": FORMAT_VERSION,
            "recipe": d["recipe"], "checkpoint": monitor.checkpoint,
            "checkpoint_sha256":
                checkpoint_sha256(monitor.checkpoint) if monitor.checkpoint else None,
            "source": {"kind": source.kind, "name": source.name, "fps": source.fps,
                       "realtime": bool(realtime or source.live)},
            "episode": source.episode or None, "fps": source.fps, "window": d["window"],
            "size": d["size"], "smoothing": d["smoothing"], "classes": d["classes"],
            "fitted_arrays": d["fitted_arrays"], "note": d["note"],
            "environment": environment(device)}


def call_line(call: Any, index: int, ts: float) -> dict[str, Any]:
    """A call as its JSON line: the frame's index and timestamp in the source."""
    d = call.to_dict()
    d.pop("frame_index")
    d.pop("timestamp_s")
    return {"type": "call", "frame_index": index, "timestamp_s": round(ts, 6), **d}


def run_stream(monitor: Any, source: Source, write: Callable[[dict[str, Any]], None], *,
               realtime: bool = False, max_frames: int | None = None,
               video_out: str | Path | None = None, device: str = "auto",
               stop: threading.Event | None = None) -> dict[str, Any]:
    """Stream SOURCE through MONITOR, writing the header, one line per call and the summary
    (returned). `stop` set (Ctrl-C) ends it as `interrupted`. An error (a camera that stops,
    a frame of another size, a stream shorter than the window) ends it too: the summary
    names it, then it is raised."""
    from contextlib import ExitStack

    stop = stop or threading.Event()
    write(header(monitor, source, realtime=realtime, device=device))
    tally, box, end, error = Tally(), Mailbox(), "end of stream", None
    live = source.live or realtime
    with ExitStack() as stack:
        stack.callback(source.close)
        video = None
        if video_out is not None:
            from .stream_video import annotated_video

            video = stack.enter_context(annotated_video(video_out, source.fps or DEFAULT_FPS))
        if live:
            feeder = threading.Thread(target=_feed, args=(source, box, stop, not source.live,
                                                          max_frames), daemon=True)
            feeder.start()
            stack.callback(feeder.join, 2.0)
            stack.callback(stop.set)
        try:
            frames = _take(box, source) if live else _direct(source, max_frames, tally)
            for index, ts, rgb in frames:
                tally.processed += 1
                call = monitor.push(rgb, ts)
                if call is not None:
                    tally.calls += 1
                    tally.latencies.append(call.latency_ms)
                    write(call_line(call, index, ts))
                if video is not None:
                    video.write(rgb, call, index, ts)
                if stop.is_set():
                    break
        except Exception as e:  # a camera that stops, a bad frame, a failing model
            end, error = "error", e
        if live:
            tally.frames = box.frames
        if stop.is_set() and end != "error":
            end = "interrupted"
        elif end == "end of stream" and max_frames is not None and tally.frames >= max_frames:
            end = "max frames"
        if error is None and tally.calls == 0 and end != "interrupted":
            error = VtsError(f"the stream ended after {tally.processed} frames, fewer than the "
                             f"recipe's window of {monitor.frames}: no call", source.name)
            end = "error"
        from vtsbench.errors import one_line

        summary = tally.summary(tally.frames - tally.processed, end,
                                None if error is None else one_line(error))
        write(summary)
    if error is not None:
        raise error
    return summary


def _direct(source: Source, max_frames: int | None, tally: Tally) -> Iterator[Frame]:
    """A file's or episode's frames as fast as the monitor takes them (none dropped)."""
    for item in source.frames():
        if max_frames is not None and tally.frames >= max_frames:
            return
        tally.frames += 1
        yield item


def _take(box: Mailbox, source: Source) -> Iterator[Frame]:
    """The newest frame of a live source each time the monitor is ready for one."""
    while True:
        try:
            item = box.take(CAMERA_TIMEOUT_S if source.live else 3600.0)
        except TimeoutError:
            raise VtsError(f"no frame for {CAMERA_TIMEOUT_S:g} s: the camera stopped",
                           source.name) from None
        if item is None:
            return
        yield item
