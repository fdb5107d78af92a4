"""`vtsbench simulate-episodes`: continuous simulated takes with per-frame labels, written as a
dataset of episodes with the paper's samples as views. Parses its options, calls the library
(imported inside it) and prints the result."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from .. import limits as lim
from .options import choice, finite, parse_size, str_option
from .run import run


def simulate_episodes(
    out: Annotated[Path, typer.Argument(help="Dataset folder to create.")],
    episodes: Annotated[int, typer.Option(min=1, max=lim.MAX_SIM_ENTRIES,
                                          help="Takes to simulate.")] = 24,
    objects: Annotated[int, typer.Option(min=1, max=15,
                                         help="Object classes to use (of 15).")] = 6,
    sessions: Annotated[int, typer.Option(min=1, max=lim.MAX_SIM_SESSIONS,
                                          help="Sessions (camera noise draws).")] = 3,
    fps: Annotated[float, typer.Option(callback=finite, min=1.0, max=1000.0,
                                       help="Frames per second.")] = 25.0,
    seconds: Annotated[float, typer.Option(callback=finite, min=0.1, max=3600.0,
                                           help="Length of each take.")] = 6.0,
    size: Annotated[str, str_option(limit=16, help=(
        f"Frame size HxW, each side 32 to {lim.MAX_SIDE_PX} pixels."))] = "240x320",
    mm_per_px: Annotated[float | None, typer.Option(
        callback=finite, min=1e-4, max=10.0,
        help="Scale of the sensor, mm per pixel (default: 19.2 mm across the width).")] = None,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED,
                                      help="Random seed; the same seed writes the same takes.")
                    ] = 0,
    no_slip: Annotated[float, typer.Option(
        "--no-slip", callback=finite, min=0.0, max=1.0,
        help="Share of the takes without slip (hold, press and release only).")] = 0.25,
    sample_stride: Annotated[int, typer.Option(
        min=1, max=64, help=(
            "Frames between the starts of two 8-frame slip samples in a take (below 8 they "
            "overlap: more windows, near-onset ones included).")
    )] = 4,
    truth: Annotated[bool, typer.Option(
        "--truth", help="Store the simulator's depth and contact per frame too.")] = False,
    gel: Annotated[Literal["markers", "plain"] | None, choice(
        help="The sensor's gel: 'markers' or 'plain' (default).")] = None,
    workers: Annotated[int, typer.Option(min=1, max=lim.MAX_WORKERS,
                                         help="Worker processes rendering takes.")] = 1,
    resume: Annotated[bool, typer.Option(
        "--resume/--no-resume", help="Go on from the takes a killed run saved.")] = True,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace OUT if it exists.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Simulate continuous takes (hold, press, slip onset, slip, release) with exact per-frame
    labels and slip onsets, as a dataset of episodes with 8-frame slip samples as views.

    Example: [bold]vtsbench simulate-episodes data/takes --episodes 24 --objects 6 --fps 25
    --seconds 6 --size 240x320 --workers 2[/]
    """
    from ..sim.episode_dataset import EpisodeOptions
    from ..sim.episode_dataset import simulate_episodes as write

    opts = EpisodeOptions(episodes, objects, sessions, fps, seconds, parse_size(size), seed,
                          mm_per_px, truth, no_slip, gel, sample_stride)
    path = run(write, out, opts, workers=workers, resume=resume, overwrite=overwrite,
               progress=not quiet)
    typer.echo(f"wrote {episodes} takes of {seconds:g} s at {fps:g} fps to {path}")
