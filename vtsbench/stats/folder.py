"""The windows of a recordings folder and their statistics: which frames make a window, which
reference frame each is compared with, and an even, deterministic sample of at most N windows.

A window is `window` consecutive frames of a sequence entry: an entry of at most `window`
frames is one window; a longer one is cut into consecutive windows of exactly `window` frames
(a shorter rest is left out). The reference is the session's `background` when the manifest
names one, else the frame of the entry's source half a second in (frame round(fps / 2), frame 0
when the frame rate is unknown), which skips a camera's exposure settling at the start of a take
and comes before contact in the clips measured (GelSight Mini press and grasp videos).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import VtsError
from ..recordings.manifest import Entry, Manifest, Session, load_manifest
from .window import WindowStats


@dataclass(frozen=True)
class Window:
    """One window: an entry's frames [start, stop) in its source."""

    entry: str
    session: str
    path: str
    start: int
    stop: int


def plan_windows(root: Path, m: Manifest, window: int) -> list[Window]:
    """Every window of the folder's sequence entries, in manifest order."""
    from ..recordings.media import probe

    out: list[Window] = []
    lengths: dict[str, int] = {}
    for e in m.entries:
        if e.kind != "sequence":
            continue
        start = e.source.start or 0
        stop = e.source.stop
        if stop is None:
            if e.source.path not in lengths:
                lengths[e.source.path] = probe(root / e.source.path, decode=False).n_frames
            stop = lengths[e.source.path]
        out.extend(_cut(e, start, stop, window))
    return out


def _cut(e: Entry, start: int, stop: int, window: int) -> list[Window]:
    if stop - start < 2:
        return []
    if stop - start <= window:
        return [Window(e.id, e.session, e.source.path, start, stop)]
    return [Window(e.id, e.session, e.source.path, a, a + window)
            for a in range(start, stop - window + 1, window)]


def sample(windows: list[Window], n: int) -> list[Window]:
    """At most n windows spread evenly over the list (the same ones every run)."""
    if len(windows) <= n:
        return list(windows)
    idx = np.unique(np.linspace(0, len(windows) - 1, n).round().astype(int))
    return [windows[i] for i in idx]


def read_window(root: Path, w: Window) -> np.ndarray:
    """A window's frames, (T, H, W, 3) uint8 (frames of two sizes in one sequence are the
    reader's one-line error, naming both)."""
    from ..recordings.media import read_frames

    return read_frames(root / w.path, w.start, w.stop)


class References:
    """The reference frame of each window, read once per session or source."""

    def __init__(self, root: Path, m: Manifest) -> None:
        self.root = root
        self.sessions = {s.id: s for s in m.sessions}
        self.cache: dict[tuple[str, int], np.ndarray] = {}

    def where(self, w: Window) -> tuple[str, int]:
        """(path, frame) of a window's reference."""
        s: Session = self.sessions[w.session]
        if s.background:
            return s.background, s.background_frame or 0
        return w.path, round(s.fps / 2) if s.fps else 0

    def get(self, w: Window, shape: tuple[int, ...]) -> np.ndarray:
        """The reference of a window whose frames have `shape` (H, W, 3)."""
        from ..recordings.media import probe, read_frame

        path, frame = self.where(w)
        if (path, frame) not in self.cache:
            if path == w.path and frame:
                frame = min(frame, max(0, probe(self.root / path, decode=False).n_frames - 1))
            self.cache[(path, frame)] = read_frame(self.root / path, frame)
        ref = self.cache[(path, frame)]
        if ref.shape != shape:
            raise VtsError(f"reference frame {frame} is {ref.shape[1]}x{ref.shape[0]} but the "
                           f"frames of entry {w.entry} are {shape[1]}x{shape[0]}: statistics need "
                           "frames of one size", self.root / path)
        return ref


def measure(folder: Path, window: int = 8, max_windows: int = 200, progress: bool = False
            ) -> tuple[list[Window], int, list[WindowStats]]:
    """(sampled windows, number of windows in the folder, their statistics)."""
    from .window import window_stats

    folder = Path(folder)
    m = load_manifest(folder)
    windows = plan_windows(folder, m, window)
    if not windows:
        kinds = sorted({e.kind for e in m.entries})
        held = f" (it holds {len(m.entries)} {'/'.join(kinds)} entries)" if kinds else ""
        raise VtsError("no sequence of 2 frames or more: motion statistics need frame "
                       f"sequences{held}", folder)
    chosen = sample(windows, max_windows)
    refs = References(folder, m)
    out: list[WindowStats] = []
    bar = None
    if progress and len(chosen) > 20:
        from ..progress import progress_bar

        bar = progress_bar(transient=True)
    if bar is not None:
        with bar:
            task = bar.add_task(f"measuring {folder.name}", total=len(chosen))
            for w in chosen:
                out.append(_one(folder, w, refs, window_stats))
                bar.advance(task)
    else:
        out = [_one(folder, w, refs, window_stats) for w in chosen]
    return chosen, len(windows), out


def _one(folder: Path, w: Window, refs: References, fn) -> WindowStats:
    frames = read_window(folder, w)
    return fn(frames, refs.get(w, frames.shape[1:]))
