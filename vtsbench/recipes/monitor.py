"""The live monitor: a trained recipe on a stream of RGB frames, one frame at a time.

`Monitor.from_checkpoint(recipe, checkpoint)` reads the checkpoint once (the recipe's
`window_predictor`); then `push(frame)` keeps the last `frames` frames in a ring buffer and,
once it is full, returns a `Call` (state, direction, confidences, latency) for the window
ending at that frame. No file is read or written after construction, so it runs inside a
control loop or a ROS node. Decision rules are part of the method: `smoothing` (a debounce of
k calls) is applied here and recorded with the calls.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtsbench.errors import VtsError

#: Frames per window of a checkpoint that does not record the length it was trained on (the
#: paper's 8-frame sequences).
DEFAULT_FRAMES = 8
#: The most calls a debounce may wait for.
MAX_SMOOTHING = 100


def train_window_meta(info: Any, frames: int | None = None) -> dict[str, str]:
    """What a checkpoint records for the monitor: the frame size (H, W) and the frames per
    window of the dataset it was trained on (`info`: a dataset's `info`)."""
    n = info.frames_per_sequence if frames is None else frames
    return {"resolution": json.dumps([int(v) for v in info.resolution]), "frames": str(int(n))}


def checkpoint_window(meta: dict[str, Any], checkpoint: str | Path, default_frames: int
                      ) -> tuple[int, tuple[int, int] | None]:
    """(frames per window, (H, W) or None) a checkpoint's metadata records; a checkpoint
    written before they were recorded: `default_frames` and any size."""
    from vtsbench.jsonio import loads

    frames = meta.get("frames")
    try:
        n = default_frames if frames is None else int(frames)
    except ValueError:
        raise VtsError(f"corrupt checkpoint (frames {frames!r:.40} is not a number)",
                       checkpoint) from None
    size = None
    if isinstance(meta.get("resolution"), str):
        hw = loads(meta["resolution"], checkpoint, "checkpoint metadata 'resolution'")
        if not (isinstance(hw, list) and len(hw) == 2
                and all(isinstance(v, int) and v > 0 for v in hw)):
            raise VtsError("corrupt checkpoint (resolution is not [height, width])", checkpoint)
        size = (hw[0], hw[1])
    if not 1 <= n <= 10_000:
        raise VtsError(f"corrupt checkpoint (frames {n} outside 1..10000)", checkpoint)
    return n, size


@dataclass(frozen=True)
class Call:
    """The monitor's answer for the window ending at one frame: the state (after smoothing;
    `raw_state` before it), the slip direction bin, the object, each task's probabilities by
    class name, and the milliseconds `push` took (copy, prediction and smoothing)."""

    frame_index: int
    timestamp_s: float
    state: str | None
    raw_state: str | None
    direction: int | None
    object: str | None
    confidences: dict[str, dict[str, float]]
    latency_ms: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class Monitor:
    """A recipe's window predictor on a stream of frames (module docstring)."""

    def __init__(self, predictor: Any, *, smoothing: int = 1, recipe: str = "",
                 checkpoint: str = "") -> None:
        if isinstance(smoothing, bool) or not isinstance(smoothing, int | np.integer) \
                or not 1 <= int(smoothing) <= MAX_SMOOTHING:
            raise VtsError(f"smoothing must be a whole number of calls from 1 to "
                           f"{MAX_SMOOTHING}, got {smoothing!r:.40}")
        self.predictor, self.smoothing = predictor, int(smoothing)
        self.recipe, self.checkpoint = recipe, checkpoint
        self.frames = int(predictor.frames)
        self.size: tuple[int, int] | None = predictor.size
        self._buf: np.ndarray | None = None
        if self.size is not None:
            self._buf = np.empty((2 * self.frames, *self.size, 3), np.uint8)
        self.reset()

    @classmethod
    def from_checkpoint(cls, recipe: str | Path, checkpoint: str | Path, *,
                        device: str = "auto", smoothing: int = 1) -> Monitor:
        """RECIPE (a registered name or a .py file) with its CHECKPOINT, read now and only
        now; a recipe without a window predictor, or a checkpoint another recipe wrote, is a
        one-line VtsError."""
        from .checkpoints import check_checkpoint
        from .registry import guarded, load_recipe

        rec = load_recipe(recipe)
        make = getattr(rec, "window_predictor", None)
        if make is None:
            raise VtsError(f"recipe {rec.name!r} has no window_predictor: it cannot run on a "
                           "stream", str(recipe))
        checkpoint = Path(checkpoint)
        if not checkpoint.exists():
            raise VtsError("checkpoint not found", checkpoint)
        check_checkpoint(checkpoint)
        predictor = guarded(make, f"recipe {recipe}")(checkpoint, device)
        return cls(predictor, smoothing=smoothing, recipe=rec.name, checkpoint=str(checkpoint))

    def reset(self) -> None:
        """Forget every frame and the smoothing's state (a new take)."""
        self._count = 0  # frames pushed since the reset
        self._t0: float | None = None
        self._state: str | None = None  # the reported (smoothed) state
        self._candidate: str | None = None
        self._run = 0

    @property
    def ready(self) -> bool:
        """Whether the window is full (the next push returns a call)."""
        return self._count >= self.frames - 1

    def _check(self, frame: Any) -> np.ndarray:
        """The frame as it is, or the one-line refusal of another size or colour layout."""
        want = "x".join(map(str, self.size)) + "x3" if self.size else "HxWx3"
        if not isinstance(frame, np.ndarray):
            raise VtsError(f"frame {self._count}: a {type(frame).__name__}, not a numpy array "
                           f"(the monitor takes {want} uint8 RGB frames)")
        got = "x".join(map(str, frame.shape)) + f" {frame.dtype}"
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise VtsError(f"frame {self._count} is {got}; the monitor takes {want} uint8 RGB "
                           "frames (convert grey, BGRA or float frames to RGB uint8)")
        if self.size is not None and frame.shape[:2] != self.size:
            where = "the checkpoint was trained at" if self.predictor.size else \
                "the stream's first frame was"
            raise VtsError(f"frame {self._count} is {got}; {where} {want}: a stream of "
                           "another size (resize it, or use a checkpoint of that resolution)")
        return frame

    def push(self, frame: np.ndarray, timestamp: float | None = None) -> Call | None:
        """Add one (H, W, 3) uint8 RGB frame (timestamp: seconds; None: seconds since the
        first frame on this process's monotonic clock): None until the window is full, then
        the call on the last `frames` frames."""
        t0 = time.perf_counter()
        frame = self._check(frame)
        if self._buf is None:  # any size: the first frame fixes it
            self.size = (int(frame.shape[0]), int(frame.shape[1]))
            self._buf = np.empty((2 * self.frames, *self.size, 3), np.uint8)
        if self._t0 is None:
            self._t0 = time.monotonic()
        ts = time.monotonic() - self._t0 if timestamp is None else float(timestamp)
        # a mirrored ring: frame k lands at k % T and k % T + T, so the last T frames are
        # always the one contiguous slice buf[k % T + 1 : k % T + 1 + T], oldest first
        k = self._count % self.frames
        self._buf[k] = frame
        self._buf[k + self.frames] = frame
        index = self._count
        self._count += 1
        if self._count < self.frames:
            return None
        window = self._buf[k + 1:k + 1 + self.frames]
        out = self.predictor(window)
        return self._call(out, index, ts, t0)

    def _call(self, out: dict[str, Any], index: int, ts: float, t0: float) -> Call:
        conf: dict[str, dict[str, float]] = {}
        top: dict[str, str] = {}
        for task, names in self.predictor.classes.items():
            probs = out.get(f"{task}_probs")
            if probs is not None:
                p = np.asarray(probs, dtype=np.float64).reshape(-1)
                if len(p) != len(names):
                    raise VtsError(f"the recipe gave {len(p)} {task} probabilities for "
                                   f"{len(names)} classes", self.checkpoint)
                top[task] = names[int(np.argmax(p))]  # the first of a tie, as torch's argmax
                conf[task] = {n: round(float(v), 6) for n, v in zip(names, p, strict=True)}
        direction = out.get("direction")
        if direction is None and "direction" in top:
            direction = int(top["direction"])
        raw = top.get("state")
        state = self._smooth(raw)
        return Call(index, ts, state, raw, None if direction is None else int(direction),
                    top.get("object"), conf, round(1000 * (time.perf_counter() - t0), 3))

    def _smooth(self, raw: str | None) -> str | None:
        """Debounce: the reported state becomes a new state once the raw calls have said it
        `smoothing` times in a row (1: every call as it is)."""
        if raw is None:
            return None
        if raw == self._candidate:
            self._run += 1
        else:
            self._candidate, self._run = raw, 1
        if self._state is None or self._run >= self.smoothing:
            self._state = raw
        return self._state

    def describe(self) -> dict[str, Any]:
        """What the calls depend on: recipe, window, size, classes, smoothing, and what a
        live RGB stream lacks of the checkpoint's inputs."""
        p = self.predictor
        return {"recipe": self.recipe, "window": self.frames,
                "size": None if p.size is None else list(p.size),
                "classes": {k: list(v) for k, v in p.classes.items()},
                "fitted_arrays": list(p.arrays), "note": p.note,
                "smoothing": {"rule": "debounce", "calls": self.smoothing}}

