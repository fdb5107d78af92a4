"""The RGB of episodes stored as video (format/episode_video.py): frame rows of the episode
store decoded from each episode's file, frame-accurately (read/video.py).

Rows are grouped by episode and each run of consecutive frames is decoded once: one seek to
the keyframe at or before its first frame, then its frames (a window is one run). Two runs of
an episode are decoded as one when seeking would start no later than where the first ends
(frames a lossy codec must decode anyway). Each file is probed once per process, checked
against the index and info.json (frame count = the episode's length, frame size = the
store's, the codec info.json names); a missing, damaged or different file is one VtsError
line naming it. A dataset at a URL has each video copied once into a temporary folder.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ...limits import MAX_SEQUENCE_PIXELS
from ..format.episode_video import codec_from_dict, stored_codec
from ..format.layout import EPISODES, episode_video_path
from .arrays import check_arrays
from .video import VideoInfo, decode_frames, probe

if TYPE_CHECKING:
    from ..format.info import DatasetInfo
    from ..format.video import VideoCodec
    from .loader import KindStore
    from .location import Location


def episode_videos(store: KindStore, starts: np.ndarray, lengths: np.ndarray
                   ) -> EpisodeVideos | None:
    """The videos of a dataset's episodes (None when their RGB is in the Zarr store)."""
    codec = stored_codec(store.info)
    return None if codec is None else EpisodeVideos(store.loc, store.info, codec, starts,
                                                    lengths)


def check_video_info(vi: VideoInfo, size: tuple[int, int], codec: VideoCodec,
                     path: str | os.PathLike) -> None:
    """A probed video against what the dataset says: its frame size and decoder."""
    if vi.size != tuple(size):
        raise VtsError(f"holds frames of {vi.height}x{vi.width}; the dataset's are "
                       f"{size[0]}x{size[1]}", path)
    if vi.codec != codec.decoder:
        raise VtsError(f"coded as {vi.codec!r}; info.json says {codec.name} ({codec.decoder})",
                       path)


class EpisodeVideos:
    """Each episode's video file of a loaded dataset: `read(rows)` gives the RGB of frame rows
    of the episode store; `read_with(store, rows, names)` the other arrays from Zarr too."""

    def __init__(self, loc: Location, info: DatasetInfo, codec: VideoCodec,
                 starts: np.ndarray, lengths: np.ndarray) -> None:
        self.loc, self.info, self.codec = loc, info, codec
        self.starts = np.asarray(starts, np.int64)
        self.lengths = np.asarray(lengths, np.int64)
        self.size = tuple(int(x) for x in info.shapes[EPISODES]["rgb"][1:3])
        self._reset()

    def _reset(self) -> None:
        self._pid = os.getpid()
        self._probes: dict[int, tuple[Path, VideoInfo]] = {}
        self._copies: Any = None  # a TemporaryDirectory of a remote dataset's videos

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the probes (a worker probes the files it reads), the codec as its
        settings."""
        keep = ("loc", "info", "starts", "lengths", "size")
        return {**{k: self.__dict__[k] for k in keep}, "codec": self.codec.to_dict()}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.codec = codec_from_dict(state["codec"])
        self._reset()

    def rel(self, episode: int) -> str:
        """Episode k's video, relative to the dataset."""
        return episode_video_path(episode, self.codec.suffix)

    def _local(self, episode: int) -> Path:
        """A local path of episode k's video (a remote one copied once)."""
        rel = self.rel(episode)
        if not self.loc.remote:
            return Path(self.loc.path(rel))
        if self._copies is None:
            self._copies = tempfile.TemporaryDirectory(prefix="vtsbench-videos-")
        dest = Path(self._copies.name) / Path(rel).name
        if not dest.exists():
            self.loc.copy(rel, dest)
        return dest

    def info_of(self, episode: int) -> tuple[Path, VideoInfo]:
        """Episode k's file and its probe (once per process), checked against the dataset."""
        if self._pid != os.getpid():
            self._reset()
        if episode not in self._probes:
            path = self._local(episode)
            vi = probe(path, int(self.lengths[episode]))
            check_video_info(vi, self.size, self.codec, path)
            self._probes[episode] = (path, vi)
        return self._probes[episode]

    def read(self, rows: np.ndarray) -> np.ndarray:
        """RGB (n, H, W, 3) uint8 of frame rows (any order, repeats allowed)."""
        rows = np.asarray(rows, np.int64).reshape(-1)
        n = int(self.starts[-1] + self.lengths[-1]) if len(self.starts) else 0
        if len(rows) and (rows.min() < 0 or rows.max() >= n):
            raise IndexError(f"frame row outside 0..{n - 1}")
        uniq, inverse = np.unique(rows, return_inverse=True)
        out = np.empty((len(uniq), *self.size, 3), np.uint8)
        episode = np.searchsorted(self.starts, uniq, side="right") - 1
        cuts = np.flatnonzero(np.diff(episode)) + 1
        for sel in np.split(np.arange(len(uniq)), cuts):
            if len(sel):
                e = int(episode[sel[0]])
                self._read_episode(e, uniq[sel] - self.starts[e], out[sel[0]:sel[-1] + 1])
        ordered = len(uniq) == len(rows) and bool(np.all(np.diff(rows) > 0))
        return out if ordered else out[inverse.reshape(-1)]

    def _read_episode(self, e: int, frames: np.ndarray, out: np.ndarray) -> None:
        """Frames (sorted, unique) of episode e into out, a run at a time."""
        path, vi = self.info_of(e)
        for a, b in decode_runs(frames, vi, MAX_SEQUENCE_PIXELS // (vi.height * vi.width)):
            block = decode_frames(path, a, b - a, vi)
            lo, hi = np.searchsorted(frames, [a, b])
            out[lo:hi] = block[frames[lo:hi] - a]

    def read_with(self, store: KindStore, rows: np.ndarray, names: Sequence[str]
                  ) -> dict[str, np.ndarray]:
        """Arrays of frame rows, in the order of `names`: rgb from the videos, the others from
        the Zarr store (`store.read`)."""
        check_arrays(self.info, names)
        rest = [n for n in names if n != "rgb"]
        out = store.read(rows, rest) if rest else {}
        if "rgb" in names:
            out["rgb"] = self.read(rows)
        return {n: out[n] for n in names}


def decode_runs(frames: np.ndarray, vi: VideoInfo, most: int) -> list[tuple[int, int]]:
    """The [a, b) frame ranges to decode for sorted unique frame numbers: runs of consecutive
    frames, a run joined to the previous where its keyframe lies at or before the previous
    run's end (seeking would decode those frames again), each at most `most` frames long."""
    runs: list[list[int]] = []
    for f in np.asarray(frames, np.int64).tolist():
        if runs and (f == runs[-1][1] or vi.keyframe_before(f) <= runs[-1][1]):
            runs[-1][1] = f + 1
        else:
            runs.append([f, f + 1])
    most = max(1, int(most))
    return [(s, min(s + most, b)) for a, b in runs for s in range(a, b, most)]
