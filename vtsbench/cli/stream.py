"""`vtsbench stream`: a trained recipe on a camera, a video file or a dataset episode, its calls
as JSON lines on stdout. Parses its options, calls `vtsbench.recipes.stream` and prints a
one-line summary on stderr."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from .. import limits as lim
from .options import max_chars, open_choice, str_argument, str_option
from .run import fail


def stream(
    recipe: Annotated[str, str_argument(
        help="Recipe: a registered name (flow, timesformer, resnet) or a file: NAME.py, "
             "./NAME.")],
    checkpoint: Annotated[Path, typer.Argument(help="Checkpoint written by vtsbench train.")],
    source: Annotated[str, str_option(
        "--source", limit=lim.MAX_PATH_TEXT,
        help="A camera index (0), a video file, or a dataset episode DATASET#EPISODE_ID.")],
    episode: Annotated[str | None, str_option(
        help="The episode id when --source is a dataset folder.")] = None,
    realtime: Annotated[bool, typer.Option(
        "--realtime", help="Play a file or episode at its frame rate, dropping the frames the "
                           "model is too slow for, as a camera would (a camera always is).")
                        ] = False,
    smoothing: Annotated[int, typer.Option(
        min=1, max=100, help="Debounce: the reported state changes once the model has said "
                             "the new one this many calls in a row (1: none).")] = 1,
    max_frames: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_TAKE_FRAMES, help="Stop after this many frames of the source.")
                          ] = None,
    video_out: Annotated[Path | None, typer.Option(
        help="Also write an annotated video (.avi, .mp4 or .mkv): each frame with its call.")
                         ] = None,
    device: Annotated[str, open_choice(
        "auto", "cpu", "cuda", callback=max_chars(64),
        help="auto, cpu, cuda, cuda:1... At most 64 characters.")] = "auto",
) -> None:
    """Run a trained recipe on a live stream; one JSON line per call on stdout.

    The first line is a header (recipe, checkpoint sha256, fps, window, smoothing), then one
    line per frame once the window is full (timestamp_s, frame_index, state, direction,
    confidences, latency_ms), and a summary last (frames, calls, dropped, fps sustained,
    p50/p95 latency), also after an error or Ctrl-C. A camera drops the frames the model is
    too slow for and says how many.

    Example: [bold]vtsbench stream flow runs/flow/checkpoint.safetensors --source take.avi
    --video-out take-calls.mp4 > calls.jsonl[/]
    """
    import signal
    import sys
    import threading

    from ..errors import VtsError
    from ..recipes.monitor import Monitor
    from ..recipes.stream import LineWriter, open_source, run_stream

    stop = threading.Event()

    def interrupt(signum: int, frame: object) -> None:
        stop.set()  # the stream ends after this frame, its summary written
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a second Ctrl-C: at once

    out = getattr(sys.stdout, "buffer", None) or _TextSink(sys.stdout)
    old = signal.signal(signal.SIGINT, interrupt) \
        if threading.current_thread() is threading.main_thread() else None
    try:
        monitor = Monitor.from_checkpoint(recipe, checkpoint, device=device,
                                          smoothing=smoothing)
        src = open_source(source, episode)
        summary = run_stream(monitor, src, LineWriter(out), realtime=realtime,
                             max_frames=max_frames, video_out=video_out, device=device,
                             stop=stop)
    except (VtsError, OSError) as e:
        from .run import os_error

        fail(e if isinstance(e, VtsError) else os_error(e))
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
    p50, p95 = summary["latency_ms_p50"], summary["latency_ms_p95"]
    typer.echo(f"{summary['end']}: {summary['frames']} frames, {summary['dropped']} dropped, "
               f"{summary['calls']} calls, {summary['fps_sustained']} frames/s sustained, "
               f"latency p50 {p50} ms, p95 {p95} ms", err=True)
    if summary["end"] == "interrupted":
        raise typer.Exit(130)


class _TextSink:
    """A text stream taking the bytes of whole lines (a stdout without a binary buffer)."""

    def __init__(self, text: Any) -> None:
        self.text = text

    def write(self, data: bytes) -> None:
        self.text.write(data.decode())

    def flush(self) -> None:
        self.text.flush()
