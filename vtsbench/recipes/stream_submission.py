"""A stream submission (`vtsbench predict ... --stream`): a trained recipe's `Monitor` run over
every episode of a split part, frame by frame and none dropped, written as the JSON lines
`vtsbench stream` writes for an episode source (header, calls, summary; schemas/stream.schema
.json), one stream per episode, concatenated. `vtsbench eval` scores it against the episodes'
per-frame labels (vtsbench/evaluation/stream.py)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import VtsError


@dataclass(frozen=True)
class StreamPrediction:
    """What `predict_streams` wrote: episodes, calls, and the file."""

    episodes: int
    calls: int
    submission: Path


def split_episode_ids(ds: Any, dataset: str | Path, split: str, part: str) -> list[str]:
    """The episode ids of a split part of a loaded dataset's episodes (one line naming
    `dataset` if it has none)."""
    if not len(ds.episodes):
        raise VtsError("the dataset holds no episodes: streams are predicted on episodes "
                       "(vtsbench.create, vtsbench simulate-episodes)", dataset)
    ids = ds.episodes.split(split, part).ids
    if not ids:
        raise VtsError(f"split {split!r}, part {part!r} holds no episodes", dataset)
    return list(ids)


def predict_streams(recipe: str | Path, checkpoint: str | Path, dataset: str | Path,
                    split: str, part: str, out: str | Path, *, smoothing: int = 1,
                    device: str = "auto", progress: bool = False) -> StreamPrediction:
    """Run RECIPE's monitor (debounce of `smoothing` calls) over every episode of the split
    part, in episode order, and write the stream submission to `out` atomically (all of it or
    nothing)."""
    from contextlib import nullcontext

    import vtsbench

    from ..atomic import replacing
    from .monitor import Monitor
    from .stream import LineWriter, episode_source, run_stream

    ds = vtsbench.load(dataset)  # once: every episode's frames are read from it
    ids = split_episode_ids(ds, dataset, split, part)
    monitor = Monitor.from_checkpoint(recipe, checkpoint, device=device, smoothing=smoothing)
    calls = 0
    bar_cm = nullcontext(None)
    if progress:
        from rich.progress import BarColumn, MofNCompleteColumn, TimeRemainingColumn

        from ..progress import progress_bar

        bar_cm = progress_bar("[progress.description]{task.description}", BarColumn(),
                              MofNCompleteColumn(), TimeRemainingColumn(), transient=False)
    out = Path(out)
    with replacing(out) as tmp, open(tmp, "wb") as fh, bar_cm as bar:
        task = bar.add_task("streaming episodes", total=len(ids)) if bar is not None else None
        write = LineWriter(fh)
        for eid in ids:
            monitor.reset()
            summary = run_stream(monitor, episode_source(dataset, eid, ds), write, device=device)
            calls += int(summary["calls"])
            if bar is not None:
                bar.advance(task)
    return StreamPrediction(len(ids), calls, out)
