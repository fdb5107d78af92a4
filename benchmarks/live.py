"""The live monitor on frames in memory, as `vtsbench stream --realtime` plays a file: a frame
the model is too slow for is dropped (as from a camera), each call's JSON line made and thrown
away. Shared by the stream benchmark (benchmarks/stream.py) and the results page's live stream
(benchmarks/results_runner.py)."""

from __future__ import annotations

from typing import Any


class Discard:
    """A binary stream that keeps nothing: the JSON lines are made (their cost counts) and
    dropped."""

    def write(self, data: bytes) -> None:
        pass

    def flush(self) -> None:
        pass


def warm_up(monitor: Any, frames: Any) -> None:
    """A window of frames through the monitor, then reset: the first torch call and OpenCV's
    first DIS are not timed."""
    for f in frames[:monitor.frames]:
        monitor.push(f)
    monitor.reset()


def play(monitor: Any, frames: Any, fps: float, name: str) -> dict[str, Any]:
    """The frames fed to the monitor at fps (frame k at k / fps; realtime: drops counted) as
    the video source `name`, on the CPU; the stream's summary line."""
    from vtsbench.recipes.stream import LineWriter, Source, run_stream

    def gen() -> Any:
        for k, f in enumerate(frames):
            yield k, k / fps, f

    return run_stream(monitor, Source("video", name, fps, gen), LineWriter(Discard()),
                      realtime=True, device="cpu")
